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

use super::yaml;

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

/// The two keys as written.
#[derive(Debug, Deserialize)]
struct RawStatus {
    #[serde(default)]
    status: Option<String>,
    #[serde(default)]
    calibrations: Option<Vec<Calibration>>,
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
        let empty = text
            .lines()
            .all(|l| l.trim().is_empty() || l.trim_start().starts_with('#'));
        let raw: RawStatus = if empty {
            RawStatus {
                status: None,
                calibrations: None,
            }
        } else {
            src.deserialize()?
        };
        let bad = |path: &str, msg: &str| yaml::located(text, file, path, msg);
        let status = match (raw.status.as_deref(), raw.calibrations) {
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

/// Sets `status: calibrated` in machine YAML `text` and appends
/// `calibration` to its `calibrations` list, editing the text so that
/// every comment and the layout are kept: an existing top-level `status:`
/// line is replaced (else the key is added after the `name:` or `kind:`
/// line), and the entry is added as a one-line flow map after the last
/// entry of an existing block list (else a list is started after the
/// `status:` line).
pub fn set_calibrated(text: &str, file: &str, calibration: &Calibration) -> Result<String> {
    let eol = if text.contains("\r\n") { "\r\n" } else { "\n" };
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let entry = format!("  - {}", calibration_flow(calibration));
    let top =
        |lines: &[String], key: &str| lines.iter().position(|l| l.starts_with(&format!("{key}:")));
    let status_at = match top(&lines, "status") {
        Some(i) => {
            lines[i] = "status: calibrated".into();
            i
        }
        None => {
            let after = top(&lines, "name")
                .or_else(|| top(&lines, "kind"))
                .ok_or_else(|| {
                    Error::Machine(Located::whole_file(
                        file,
                        "cannot record the calibration: no top-level `kind:` line",
                    ))
                })?;
            lines.insert(after + 1, "status: calibrated".into());
            after + 1
        }
    };
    match top(&lines, "calibrations") {
        Some(i) => {
            if lines[i].trim_end() != "calibrations:" {
                return Err(Error::Machine(Located::whole_file(
                    file,
                    "cannot record the calibration: `calibrations` must be a block list (one `  - { … }` line per calibration)",
                )));
            }
            let mut end = i + 1;
            while end < lines.len() && lines[end].starts_with("  - ") {
                end += 1;
            }
            lines.insert(end, entry);
        }
        None => {
            lines.insert(status_at + 1, "calibrations:".into());
            lines.insert(status_at + 2, entry);
        }
    }
    let mut out = lines.join(eol);
    if text.ends_with('\n') || !text.is_empty() {
        out.push_str(eol);
    }
    // The edited file must read back with the new entry (its RMS as
    // written).
    match Status::from_yaml_str(&out, file)? {
        Status::Calibrated(list) if list.last() == Some(&as_written(calibration)) => Ok(out),
        _ => Err(Error::Machine(Located::whole_file(
            file,
            "cannot record the calibration: the edited `status`/`calibrations` keys do not read back",
        ))),
    }
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
}
