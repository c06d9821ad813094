//! Where a machine file's values come from: its top-level `status` key
//! (`example`, `nominal` or `calibrated`) and, for a calibrated file, the
//! `calibrations` list that `calibrate` and `diagnose --write-model` append
//! to (date, kind, observation file and its SHA-256, row count, fit RMS).
//!
//! ```yaml
//! status: calibrated
//! calibrations:
//!   - { date: 2026-11-25, kind: geometry, observations: grid.csv, observations_sha256: 9f…, rows: 242, fit_rms_mm: 0.0012 }
//! ```
//!
//! The keys are read here from the whole document (other keys ignored),
//! apart from the strict raw structs of each machine kind (which only accept
//! them), and written into a file as text so that every comment and the
//! layout of the file are kept.

use serde::Deserialize;

use crate::error::{Error, Located, Result};

use super::{yaml, yaml_write};

/// One calibration recorded in a machine file.
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// Day of the calibration, `YYYY-MM-DD` (UTC).
    pub date: String,
    /// What was identified (`geometry`, `kinematics`, `stiffness`,
    /// `thermal`, `diagnose`).
    pub kind: String,
    /// File name of the observation file.
    pub observations: String,
    /// SHA-256 of the observation file's bytes, lower-case hex.
    pub observations_sha256: String,
    /// Rows of the observation file used.
    pub rows: usize,
    /// RMS of the fit residual, mm.
    pub fit_rms_mm: f64,
}

/// The provenance of a machine file.
#[derive(Debug, Clone, PartialEq)]
pub enum Status {
    /// `status: example`: illustrative values, not measured data.
    Example,
    /// `status: nominal`: the maker's published kinematics of the model
    /// (no measured errors of one robot), the starting point of a
    /// calibration.
    Nominal,
    /// `status: calibrated`: values identified from measurements (oldest
    /// calibration first).
    Calibrated(Vec<Calibration>),
    /// No `status` key.
    Unstated,
}

/// The two keys as written (`status` a word or a map of sections).
#[derive(Debug, Deserialize)]
struct RawStatus {
    #[serde(default)]
    kind: Option<serde_yaml::Value>,
    #[serde(default)]
    status: Option<serde_yaml::Value>,
    #[serde(default)]
    calibrations: Option<Vec<Calibration>>,
    #[serde(flatten)]
    rest: serde_yaml::Mapping,
}

/// A model section of a machine file, calibrated on its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Section {
    /// Machine tool: the axes' component errors and squareness.
    Geometry,
    /// Robot: the DH parameters (`nominal`, `actual`) and the TCP.
    Kinematics,
    /// Stiffness (machine tool `stiffness`, robot `k_nm_per_rad`).
    Stiffness,
    /// Thermal drift (`thermal`).
    Thermal,
    /// Predicted process force (`process_force`).
    ProcessForce,
}

impl Section {
    /// The key of the section in a `status` map.
    pub fn key(self) -> &'static str {
        match self {
            Section::Geometry => "geometry",
            Section::Kinematics => "kinematics",
            Section::Stiffness => "stiffness",
            Section::Thermal => "thermal",
            Section::ProcessForce => "process_force",
        }
    }

    /// The section's name for people.
    pub fn label(self) -> &'static str {
        match self {
            Section::ProcessForce => "process force",
            s => s.key(),
        }
    }

    /// The top-level keys of a machine file that hold the section.
    fn keys(self) -> &'static [&'static str] {
        match self {
            Section::Geometry => &["axes"],
            Section::Kinematics => &["nominal", "actual"],
            Section::Stiffness => &["stiffness", "k_nm_per_rad"],
            Section::Thermal => &["thermal"],
            Section::ProcessForce => &["process_force"],
        }
    }

    /// The section a calibration of `kind` (as recorded) identifies, in a
    /// robot file or a machine tool's: `geometry`, `kinematics` and
    /// `diagnose` the geometric one.
    pub fn of_calibration(kind: &str, robot: bool) -> Option<Section> {
        match kind {
            "geometry" | "kinematics" | "diagnose" if robot => Some(Section::Kinematics),
            "geometry" | "kinematics" | "diagnose" => Some(Section::Geometry),
            "stiffness" => Some(Section::Stiffness),
            "thermal" => Some(Section::Thermal),
            _ => None,
        }
    }

    fn all(robot: bool) -> [Section; 4] {
        [
            if robot {
                Section::Kinematics
            } else {
                Section::Geometry
            },
            Section::Stiffness,
            Section::Thermal,
            Section::ProcessForce,
        ]
    }
}

/// Where the values of one model section come from.
#[derive(Debug, Clone, PartialEq)]
pub struct SectionStatus {
    /// The section.
    pub section: Section,
    /// `example`, `nominal`, `calibrated` or `unstated`.
    pub word: &'static str,
    /// The latest calibration that identified it (`calibrated`), with its
    /// date and observation file.
    pub calibration: Option<Calibration>,
}

impl SectionStatus {
    /// Still illustrative or published values: `example` or `nominal`.
    pub fn unmeasured(&self) -> bool {
        matches!(self.word, "example" | "nominal")
    }

    /// One phrase for people: `geometry calibrated 2026-11-25 from
    /// grid.csv`, `stiffness example`.
    pub fn describe(&self) -> String {
        match &self.calibration {
            Some(c) => format!(
                "{} calibrated {} from {}",
                self.section.label(),
                c.date,
                c.observations
            ),
            None => format!("{} {}", self.section.label(), self.word),
        }
    }
}

/// The words of a `status` key.
const WORDS: [&str; 3] = ["example", "nominal", "calibrated"];

fn word_of(w: &str) -> Option<&'static str> {
    WORDS.iter().copied().find(|x| *x == w)
}

/// What a machine file says of each of its model sections (those it
/// holds: the geometric one always, the others when their key is there),
/// from its `status` key — a word for the whole file or a map of
/// sections — and its `calibrations` list.
pub fn sections(src: &yaml::Source) -> Result<Vec<SectionStatus>> {
    let raw = raw_status(src)?;
    sections_of(&raw, src)
}

fn raw_status(src: &yaml::Source) -> Result<RawStatus> {
    let empty = src
        .text()
        .lines()
        .all(|l| l.trim().is_empty() || l.trim_start().starts_with('#'));
    if empty {
        return Ok(RawStatus {
            kind: None,
            status: None,
            calibrations: None,
            rest: serde_yaml::Mapping::new(),
        });
    }
    src.deserialize()
}

fn sections_of(raw: &RawStatus, src: &yaml::Source) -> Result<Vec<SectionStatus>> {
    let robot = matches!(&raw.kind, Some(serde_yaml::Value::String(k)) if k == "robot");
    let bad = |path: &str, msg: &str| yaml::located(src.text(), src.file(), path, msg);
    let held = |s: Section| {
        matches!(s, Section::Geometry | Section::Kinematics)
            || s.keys().iter().any(|k| raw.rest.contains_key(*k))
    };
    let list = raw.calibrations.as_deref().unwrap_or(&[]);
    let latest = |s: Section| {
        list.iter()
            .rev()
            .find(|c| Section::of_calibration(&c.kind, robot) == Some(s))
            .cloned()
    };
    let mut map = std::collections::BTreeMap::new();
    match &raw.status {
        None => {}
        Some(serde_yaml::Value::String(_)) => {}
        Some(serde_yaml::Value::Mapping(m)) => {
            for (k, v) in m {
                let key = k.as_str().unwrap_or("");
                let Some(section) = Section::all(robot).into_iter().find(|s| s.key() == key) else {
                    let names: Vec<&str> = Section::all(robot).iter().map(|s| s.key()).collect();
                    return Err(bad(
                        &format!("status.{}", crate::error::clip(key)),
                        &format!("unknown model section (expected {})", names.join(", ")),
                    ));
                };
                let Some(word) = v.as_str().and_then(word_of) else {
                    return Err(bad(
                        &format!("status.{key}"),
                        "expected `example`, `nominal` or `calibrated`",
                    ));
                };
                if word == "calibrated" && latest(section).is_none() {
                    return Err(bad(
                        &format!("status.{key}"),
                        &format!(
                            "`calibrated`, but no entry of `calibrations` identified the {} section",
                            section.label()
                        ),
                    ));
                }
                map.insert(section, word);
            }
        }
        Some(_) => {
            return Err(bad(
                "status",
                "expected a word (`example`, `nominal`, `calibrated`) or a map of model sections",
            ));
        }
    }
    let whole = match &raw.status {
        Some(serde_yaml::Value::String(w)) => word_of(w).unwrap_or("unstated"),
        _ => "unstated",
    };
    Ok(Section::all(robot)
        .into_iter()
        .filter(|s| held(*s) || map.contains_key(s))
        .map(|section| {
            let word = map.get(&section).copied().unwrap_or(whole);
            let calibration = (word == "calibrated").then(|| latest(section)).flatten();
            SectionStatus {
                section,
                word,
                calibration,
            }
        })
        .collect())
}

impl Status {
    /// Reads and checks the `status` and `calibrations` keys of machine
    /// YAML `text` (`file` names it in errors). Other keys are left to the
    /// machine's own loader.
    pub fn from_yaml_str(text: &str, file: &str) -> Result<Status> {
        Self::from_source(&yaml::Source::read(text, file)?)
    }

    /// The `status` and `calibrations` keys of a machine file read by
    /// [`yaml::Source::read`].
    pub fn from_source(src: &yaml::Source) -> Result<Status> {
        let (text, file) = (src.text(), src.file());
        // Only the two keys are read (the struct ignores the others, which
        // the strict loader of the file's kind checks), whatever the layout.
        let raw = raw_status(src)?;
        let bad = |path: &str, msg: &str| yaml::located(text, file, path, msg);
        // A map of sections stands for the word of the whole file: calibrated
        // when one section is, else nominal when one is, else example.
        let word = match &raw.status {
            None => None,
            Some(serde_yaml::Value::String(w)) => Some(w.clone()),
            Some(serde_yaml::Value::Mapping(_)) => {
                let words: Vec<&str> = sections_of(&raw, src)?.iter().map(|s| s.word).collect();
                ["calibrated", "nominal", "example"]
                    .into_iter()
                    .find(|w| words.contains(w))
                    .map(str::to_string)
            }
            Some(_) => {
                sections_of(&raw, src)?;
                None
            }
        };
        let status = match (word.as_deref(), raw.calibrations) {
            (None, None) => Status::Unstated,
            (None, Some(_)) => {
                return Err(bad("calibrations", "needs `status: calibrated` beside it"));
            }
            (Some("example"), None) => Status::Example,
            (Some("example"), Some(_)) => {
                return Err(bad(
                    "status",
                    "`example`, but the file records calibrations: set `status: calibrated`",
                ));
            }
            (Some("nominal"), None) => Status::Nominal,
            (Some("nominal"), Some(_)) => {
                return Err(bad(
                    "status",
                    "`nominal`, but the file records calibrations: set `status: calibrated`",
                ));
            }
            (Some("calibrated"), Some(list)) if !list.is_empty() => Status::Calibrated(list),
            (Some("calibrated"), _) => {
                return Err(bad(
                    "status",
                    "`calibrated` needs a `calibrations` list (date, kind, observations, observations_sha256, rows, fit_rms_mm)",
                ));
            }
            (Some(other), _) => {
                return Err(bad(
                    "status",
                    &format!(
                        "unknown status `{other}` (expected `example`, `nominal` or `calibrated`)"
                    ),
                ));
            }
        };
        if let Status::Calibrated(list) = &status {
            for (i, c) in list.iter().enumerate() {
                check_calibration(c)
                    .map_err(|(key, msg)| bad(&format!("calibrations[{i}].{key}"), &msg))?;
            }
        }
        Ok(status)
    }

    /// One line for people: `example (not measured data)`, `calibrated
    /// 2026-11-25 (geometry, 242 rows of grid.csv, fit RMS 0.0012 mm)` or
    /// `not stated`.
    pub fn describe(&self) -> String {
        match self {
            Status::Example => "example (not measured data)".into(),
            Status::Nominal => {
                "nominal (published kinematics of the model, no measured errors)".into()
            }
            Status::Unstated => "not stated (no `status` key)".into(),
            Status::Calibrated(list) => {
                let last = list.last().expect("a calibrated status has a calibration");
                format!(
                    "calibrated {} ({}, {} rows of {}, fit RMS {:.4} mm)",
                    last.date, last.kind, last.rows, last.observations, last.fit_rms_mm
                )
            }
        }
    }

    /// The word of the `status` key: `example`, `nominal`, `calibrated` or
    /// `unstated`.
    pub fn word(&self) -> &'static str {
        match self {
            Status::Example => "example",
            Status::Nominal => "nominal",
            Status::Calibrated(_) => "calibrated",
            Status::Unstated => "unstated",
        }
    }

    /// The latest calibration, when calibrated.
    pub fn latest(&self) -> Option<&Calibration> {
        match self {
            Status::Calibrated(list) => list.last(),
            _ => None,
        }
    }
}

fn check_calibration(c: &Calibration) -> std::result::Result<(), (&'static str, String)> {
    if !is_date(&c.date) {
        return Err(("date", format!("`{}` is not a date YYYY-MM-DD", c.date)));
    }
    if c.kind.trim().is_empty() {
        return Err(("kind", "must not be empty".into()));
    }
    if c.observations_sha256.len() != 64
        || !c
            .observations_sha256
            .bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    {
        return Err((
            "observations_sha256",
            "expected 64 lower-case hex digits (the SHA-256 of the observation file)".into(),
        ));
    }
    if c.rows == 0 {
        return Err(("rows", "must be at least 1".into()));
    }
    if !c.fit_rms_mm.is_finite() || c.fit_rms_mm < 0.0 {
        return Err(("fit_rms_mm", "must be a finite number ≥ 0".into()));
    }
    Ok(())
}

fn is_date(s: &str) -> bool {
    let b = s.as_bytes();
    b.len() == 10
        && b[4] == b'-'
        && b[7] == b'-'
        && b.iter()
            .enumerate()
            .all(|(i, c)| i == 4 || i == 7 || c.is_ascii_digit())
        && (1..=12).contains(&s[5..7].parse::<u32>().unwrap_or(0))
        && (1..=31).contains(&s[8..10].parse::<u32>().unwrap_or(0))
}

/// SHA-256 of `bytes`, lower-case hex: the content hash of machine and
/// observation files (the same as `sha256sum` prints).
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    let digest = sha2::Sha256::digest(bytes);
    let mut s = String::with_capacity(64);
    for b in digest {
        s.push_str(&format!("{b:02x}"));
    }
    s
}

/// Today's date, `YYYY-MM-DD` in UTC; `SOURCE_DATE_EPOCH` (seconds since
/// 1970), when set, stands for the current time so that a run can be
/// reproduced byte for byte.
pub fn today() -> String {
    let secs = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|s| s.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs() as i64)
        });
    civil_date(secs.div_euclid(86_400))
}

/// The proleptic Gregorian date of a day number (days since 1970-01-01),
/// `YYYY-MM-DD` (the days-from-civil inverse of H. Hinnant's
/// "chrono-compatible low-level date algorithms").
fn civil_date(days: i64) -> String {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}")
}

/// Words of the sections after a calibration of `kind`: the one it
/// identified `calibrated`, the others as `before` said them. `None` when
/// the whole file's word stays right (`status: calibrated`): the file was
/// calibrated or unstated as a whole, or no section is left unmeasured.
fn words_after(before: &[SectionStatus], kind: &str) -> Option<Vec<(Section, &'static str)>> {
    let robot = before.first()?.section == Section::Kinematics;
    let section = Section::of_calibration(kind, robot)?;
    let words: Vec<(Section, &'static str)> = before
        .iter()
        .filter(|s| s.word != "unstated")
        .map(|s| {
            let w = if s.section == section {
                "calibrated"
            } else {
                s.word
            };
            (s.section, w)
        })
        .collect();
    let unmeasured = words.iter().any(|(_, w)| *w != "calibrated");
    (before.iter().any(SectionStatus::unmeasured) && unmeasured).then_some(words)
}

/// The phrase of an example file's comments that `calibrate` rewrites
/// in the comments of the section it identified.
pub const EXAMPLE_PHRASE: &str = "EXAMPLE CALIBRATION, NOT MEASURED DATA";

/// The suffix of an example file's `name` that `calibrate` rewrites.
const EXAMPLE_NAME: &str = "(example calibration)";

/// After a calibration of `kind` was recorded in `after` (the edited
/// `before`, by the writer's
/// [`Edit::Calibrated`](crate::machine::yaml_write::Edit::Calibrated),
/// which writes `status: calibrated`), says per model section what is calibrated: when
/// sections are left at example or nominal values, `status` becomes a map
/// of sections (`{ geometry: calibrated, stiffness: example, … }`); the
/// `(example calibration)` of the `name` names the sections still at
/// example values (or goes when none is); and the
/// [`EXAMPLE_PHRASE`] of the comments above the identified section's keys
/// (and of the file's leading comments, for the geometric section) says
/// when and from what it was calibrated. Read back before it is returned.
pub fn mark_calibrated(before: &str, after: &str, file: &str, kind: &str) -> Result<String> {
    let secs = sections(&yaml::Source::read(before, file)?)?;
    let Some(words) = words_after(&secs, kind) else {
        return Ok(after.to_string());
    };
    let status = Status::from_yaml_str(after, file)?;
    let Some(cal) = status.latest().cloned() else {
        return Ok(after.to_string());
    };
    let map: Vec<String> = words
        .iter()
        .map(|(s, w)| format!("{}: {w}", s.key()))
        .collect();
    let out = yaml_write::set_status(
        after,
        file,
        &format!("{{ {} }}", map.join(", ")),
        "   # per model section: example, nominal or calibrated",
    )?;
    let left: Vec<&str> = words
        .iter()
        .filter(|(_, w)| *w == "example")
        .map(|(s, _)| s.label())
        .collect();
    let out = rename(&out, &left);
    let eol = if out.contains("\r\n") { "\r\n" } else { "\n" };
    let mut lines: Vec<String> = out.lines().map(str::to_string).collect();
    let section = Section::of_calibration(kind, words[0].0 == Section::Kinematics);
    if let Some(section) = section {
        let note = format!(
            "{} CALIBRATED {} FROM {} (the notes below describe the example values it replaced)",
            section.label().to_uppercase(),
            cal.date,
            cal.observations
        );
        for i in owned_comments(&lines, section) {
            lines[i] = lines[i].replace(EXAMPLE_PHRASE, &note);
        }
    }
    let mut out = lines.join(eol);
    if after.ends_with('\n') {
        out.push_str(eol);
    }
    let back: Vec<(Section, &'static str)> = sections(&yaml::Source::read(&out, file)?)?
        .iter()
        .map(|s| (s.section, s.word))
        .collect();
    if back != words {
        return Err(Error::Machine(Located::whole_file(
            file,
            "cannot record the calibrated section: the edited `status` does not read back",
        )));
    }
    Ok(out)
}

/// `text` with the example suffix of its top-level `name` naming the
/// sections `left` at example values (none: the suffix goes); the name's
/// scalar found on the syntax tree, every other byte kept.
fn rename(text: &str, left: &[&str]) -> String {
    let root = yaml::tree_root(text).ok();
    let flow = root
        .as_ref()
        .and_then(|r| r.as_mapping())
        .is_some_and(|m| m.is_flow_style());
    let name = root.and_then(|r| yaml::child(&r, &yaml::Seg::Key("name".into())));
    let Some(name) = name else {
        return text.to_string();
    };
    let (a, b) = yaml::range(&name);
    let l = &text[a..b];
    let start = l
        .find(EXAMPLE_NAME)
        .or_else(|| l.find("(example values in "));
    let Some(start) = start else {
        return text.to_string();
    };
    let Some(len) = l[start..].find(')').map(|e| e + 1) else {
        return text.to_string();
    };
    let new = if left.is_empty() {
        String::new()
    } else {
        format!("(example values in {})", left.join(", "))
    };
    let (from, to) = if new.is_empty() && l[..start].ends_with(' ') {
        (start - 1, start + len)
    } else {
        (start, start + len)
    };
    let value = format!("{}{new}{}", &l[..from], &l[to..]);
    // In a flow mapping a plain scalar ends at its first `,`: the new name
    // (`… in stiffness, thermal`) is written double-quoted there.
    let plain = !l.starts_with(['"', '\'']);
    let value = if flow && plain && value.contains([',', '[', ']', '{', '}']) {
        format!("\"{}\"", value.replace('\\', "\\\\").replace('"', "\\\""))
    } else {
        value
    };
    format!("{}{value}{}", &text[..a], &text[b..])
}

/// The comment lines that belong to `section`: the comment block right
/// above each of its top-level keys, and for the geometric section the
/// file's leading comments.
fn owned_comments(lines: &[String], section: Section) -> Vec<usize> {
    let mut owned = Vec::new();
    let comment = |l: &String| l.starts_with('#');
    if matches!(section, Section::Geometry | Section::Kinematics) {
        owned.extend(
            lines
                .iter()
                .take_while(|l| comment(l) || l.trim().is_empty())
                .enumerate()
                .filter(|(_, l)| comment(l))
                .map(|(i, _)| i),
        );
    }
    for (i, l) in lines.iter().enumerate() {
        if section
            .keys()
            .iter()
            .any(|k| l.starts_with(&format!("{k}:")))
        {
            let mut j = i;
            while j > 0 && comment(&lines[j - 1]) {
                j -= 1;
                owned.push(j);
            }
        }
    }
    owned
}

/// One `calibrations` entry as a one-line flow map.
pub(crate) fn calibration_flow(c: &Calibration) -> String {
    format!(
        "{{ date: {}, kind: {}, observations: {}, observations_sha256: {}, rows: {}, fit_rms_mm: {} }}",
        c.date,
        yaml_scalar(&c.kind),
        yaml_scalar(&c.observations),
        c.observations_sha256,
        c.rows,
        fmt_rms(c.fit_rms_mm)
    )
}

/// The calibration as it reads back from [`calibration_flow`] (its RMS
/// rounded as written).
pub(crate) fn as_written(c: &Calibration) -> Calibration {
    Calibration {
        fit_rms_mm: fmt_rms(c.fit_rms_mm).parse().unwrap_or(c.fit_rms_mm),
        ..c.clone()
    }
}

/// `s` as a YAML flow scalar: plain when safe, else double-quoted.
fn yaml_scalar(s: &str) -> String {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '/'))
        && !s.starts_with(['-', '.'])
        && s.parse::<f64>().is_err()
        && !matches!(
            s,
            "true" | "false" | "null" | "yes" | "no" | "on" | "off" | "~"
        );
    if plain {
        s.to_string()
    } else {
        serde_json::to_string(s).unwrap_or_else(|_| "\"\"".into())
    }
}

/// An RMS in mm with 7 significant decimals at most (0.1 nm), trailing
/// zeros removed.
fn fmt_rms(v: f64) -> String {
    let s = format!("{v:.7}");
    let t = s.trim_end_matches('0');
    if t.ends_with('.') {
        format!("{t}0")
    } else {
        t.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `text` with `calibration` recorded by the machine-file writer.
    fn set_calibrated(text: &str, file: &str, calibration: &Calibration) -> Result<String> {
        let edit = yaml_write::Edit::Calibrated(calibration.clone());
        yaml_write::apply(text, file, "test", &[edit])
    }

    fn cal() -> Calibration {
        Calibration {
            date: "2026-11-25".into(),
            kind: "geometry".into(),
            observations: "grid measured.csv".into(),
            observations_sha256: "ab".repeat(32),
            rows: 242,
            fit_rms_mm: 0.00125,
        }
    }

    #[test]
    fn civil_dates_of_known_days() {
        // Day numbers from the definition: 1970-01-01 is day 0, 2000-03-01
        // is 30 years (7 leap days) plus Jan and Feb of a leap year later.
        assert_eq!(civil_date(0), "1970-01-01");
        assert_eq!(civil_date(-1), "1969-12-31");
        assert_eq!(civil_date(30 * 365 + 7 + 31 + 29), "2000-03-01");
        assert_eq!(civil_date(30 * 365 + 7 + 31 + 28), "2000-02-29");
    }

    #[test]
    fn sha256_of_a_known_text() {
        // FIPS 180-2 example "abc".
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn statuses_read_and_checked() {
        assert_eq!(
            Status::from_yaml_str("kind: robot\n", "m.yaml").unwrap(),
            Status::Unstated
        );
        assert_eq!(
            Status::from_yaml_str("kind: robot\nstatus: example\n", "m.yaml").unwrap(),
            Status::Example
        );
        let err = Status::from_yaml_str("kind: robot\nstatus: measured\n", "m.yaml")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("m.yaml:2:"), "{err}");
        assert!(err.contains("unknown status `measured`"), "{err}");
        assert_eq!(
            Status::from_yaml_str("kind: robot\nstatus: nominal\n", "m.yaml").unwrap(),
            Status::Nominal
        );
        let err = Status::from_yaml_str(
            "kind: robot\nstatus: nominal\ncalibrations:\n  - { date: 2026-11-25, kind: k, observations: o.csv, observations_sha256: 0000000000000000000000000000000000000000000000000000000000000000, rows: 3, fit_rms_mm: 0.1 }\n",
            "m.yaml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("`nominal`, but the file records calibrations"),
            "{err}"
        );
        let err = Status::from_yaml_str("kind: robot\nstatus: calibrated\n", "m.yaml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("needs a `calibrations` list"), "{err}");
        let bad_date = "kind: robot\nstatus: calibrated\ncalibrations:\n  - { date: 2026-13-01, kind: k, observations: o.csv, observations_sha256: 0000000000000000000000000000000000000000000000000000000000000000, rows: 3, fit_rms_mm: 0.1 }\n";
        let err = Status::from_yaml_str(bad_date, "m.yaml")
            .unwrap_err()
            .to_string();
        assert!(err.contains("calibrations[0].date"), "{err}");
    }

    #[test]
    fn calibration_written_into_text_keeps_comments_and_reads_back() {
        let text =
            "# comment kept\nkind: machine_tool\nname: Mill\nstatus: example # was\naxes: []\n";
        let once = set_calibrated(text, "m.yaml", &cal()).unwrap();
        assert!(once.starts_with("# comment kept\nkind: machine_tool\nname: Mill\nstatus: calibrated\ncalibrations:\n  - { date: 2026-11-25"));
        assert!(once.ends_with("axes: []\n"), "{once}");
        let mut second = cal();
        second.kind = "diagnose".into();
        let twice = set_calibrated(&once, "m.yaml", &second).unwrap();
        match Status::from_yaml_str(&twice, "m.yaml").unwrap() {
            Status::Calibrated(list) => assert_eq!(list, vec![cal(), second]),
            other => panic!("{other:?}"),
        }
        // A file without the key gets it after `name:`.
        let bare = set_calibrated("kind: robot\nname: R\nnominal: []\n", "r.yaml", &cal()).unwrap();
        assert!(bare.starts_with("kind: robot\nname: R\nstatus: calibrated\ncalibrations:\n"));
    }

    #[test]
    fn one_section_calibrated_leaves_the_others_named() {
        let before = "# EXAMPLE CALIBRATION, NOT MEASURED DATA. Header.\nkind: machine_tool\nname: Mill (example calibration)\nstatus: example # was\naxes: []\n# Forces - EXAMPLE CALIBRATION, NOT MEASURED DATA.\nprocess_force: { model: constant }\nthermal: {}\n";
        let after = set_calibrated(before, "m.yaml", &cal()).unwrap();
        let marked = mark_calibrated(before, &after, "m.yaml", "geometry").unwrap();
        let src = yaml::Source::read(&marked, "m.yaml").unwrap();
        let got: Vec<(&str, &str)> = sections(&src)
            .unwrap()
            .iter()
            .map(|s| (s.section.key(), s.word))
            .collect();
        // No stiffness key in the file: no stiffness section.
        assert_eq!(
            got,
            [
                ("geometry", "calibrated"),
                ("thermal", "example"),
                ("process_force", "example")
            ]
        );
        assert!(
            marked.starts_with(
                "# GEOMETRY CALIBRATED 2026-11-25 FROM grid measured.csv (the notes below describe the example values it replaced). Header.\n"
            ),
            "{marked}"
        );
        assert!(marked.contains("\nname: Mill (example values in thermal, process force)\n"));
        assert!(marked.contains("# Forces - EXAMPLE CALIBRATION, NOT MEASURED DATA.\n"));
        assert!(matches!(
            Status::from_source(&src).unwrap(),
            Status::Calibrated(_)
        ));
        // A file calibrated as a whole stays so.
        let whole = set_calibrated("kind: robot\nname: R\n", "r.yaml", &cal()).unwrap();
        let again = set_calibrated(&whole, "r.yaml", &cal()).unwrap();
        assert_eq!(
            mark_calibrated(&whole, &again, "r.yaml", "stiffness").unwrap(),
            again
        );
        // A calibrated section needs a calibration of its kind.
        let err = Status::from_yaml_str(
            "kind: machine_tool\nstatus: { geometry: example, thermal: calibrated }\nthermal: {}\n",
            "m.yaml",
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("status.thermal: `calibrated`, but no entry"),
            "{err}"
        );
        let err = Status::from_yaml_str("kind: robot\nstatus: { geometry: example }\n", "r.yaml")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("status.geometry: unknown model section (expected kinematics"),
            "{err}"
        );
    }
}
