//! The provenance header of a compensated program: a few comment lines, in
//! the program's own comment syntax, that say which postproc, which machine
//! file (name, SHA-256, status), which effects and gains and which tolerance
//! made the program, and what its annotations mean. The first line marks
//! the program as compensated, so that it is not compensated twice
//! ([`find_marker`]).
//!
//! Placement (everything after the header is the program as written,
//! byte for byte):
//! - G-code: after the leading `%` lines (tape start, also `%_N_…` and
//!   `%PM` names) and the program-number line (`O1234 (NAME)`, `O 0815`,
//!   `:1234`) that follows them, because controllers want those first and
//!   take a comment block anywhere after. The comments are in parentheses,
//!   or after `;` when the program's own first comment is a `;` comment
//!   (ISO dialects where parentheses are not comments). The text is ASCII
//!   without parentheses or semicolons, lines of at most 76 characters.
//! - RAPID: after the `MODULE` line, as `!` comment lines indented like a
//!   module's declarations (a module file may hold nothing but the module
//!   before it, after the optional `%%%` header block).
//!
//! The header's lines end like the program's first line (CRLF or LF).

use std::io::Write;

use crate::machine::Status;

/// The words that open the header's first line, after the version: what
/// [`find_marker`] looks for.
pub const MARKER: &str = "compensated program - do not compensate it again";

/// The UTF-8 byte-order mark some editors put first in a file: it stays
/// first, the header goes after it.
const BOM: &[u8] = b"\xEF\xBB\xBF";

/// Lines of a program searched for a header and for the place of a new
/// one; a header is always within them.
pub const HEAD_LINES: usize = 200;

/// The bytes of a program searched at most (the head of a long line).
pub const HEAD_BYTES: usize = 64 << 10;

/// The comment syntax of a program.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Syntax {
    /// G-code, comments in parentheses.
    GcodeParens,
    /// G-code, comments after `;`.
    GcodeSemicolon,
    /// ABB RAPID, comments after `!`.
    Rapid,
}

/// What made a compensated program.
#[derive(Debug, Clone)]
pub struct Provenance {
    /// postproc's version.
    pub version: &'static str,
    /// The machine file's name, without folders.
    pub machine_file: String,
    /// The machine file is the copy bundled in the binary.
    pub machine_bundled: bool,
    /// SHA-256 of the machine file's bytes, hex.
    pub machine_sha256: String,
    /// The machine file's `status`.
    pub status: Status,
    /// Effects and their gains, in breakdown order (those with gain 0
    /// included); `reported` marks an effect that is predicted but not
    /// compensated.
    pub effects: Vec<EffectGain>,
    /// Tolerance of the compensation, mm (G-code compensation; `None` for
    /// RAPID and dry runs).
    pub tolerance_mm: Option<f64>,
    /// Compensated blocks carry `dev` annotations.
    pub annotated: bool,
    /// The uncertainty of the predictions, from the machine file's
    /// parameter covariance (`None`: the file carries none).
    pub uncertainty: Option<std::sync::Arc<crate::predict::uncertainty::BlockUncertainty>>,
    /// `--gain-auto`: the factor each effect's gain was scaled by (empty:
    /// not asked for).
    pub auto_gains: Vec<(&'static str, f64)>,
}

/// One effect of a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EffectGain {
    /// Effect name (`geometric`, `kinematic`, …).
    pub effect: &'static str,
    /// Gain (0 = off).
    pub gain: f64,
    /// Reported only, never compensated (vibration).
    pub reported_only: bool,
}

impl Provenance {
    /// The header's lines without comment delimiters.
    pub fn lines(&self) -> Vec<String> {
        let mut lines = vec![format!("postproc {} {MARKER}", self.version)];
        lines.push(format!(
            "machine {}{}",
            ascii(&self.machine_file),
            if self.machine_bundled {
                " - bundled with postproc"
            } else {
                ""
            }
        ));
        lines.push(format!("sha256 {}", self.machine_sha256));
        match &self.status {
            Status::Example => {
                lines.push("machine status example - illustrative values, not measured data".into())
            }
            Status::Nominal => lines
                .push("machine status nominal - published kinematics, no measured errors".into()),
            Status::Unstated => lines.push("machine status not stated".into()),
            Status::Calibrated(list) => {
                let c = list.last().expect("a calibrated status has a calibration");
                lines.push(format!(
                    "machine status calibrated {} - {}, {} rows, fit rms {} mm",
                    c.date,
                    ascii(&c.kind),
                    c.rows,
                    fmt_mm(c.fit_rms_mm)
                ));
                lines.push(format!("observations {}", ascii(&c.observations)));
            }
        }
        lines.push(format!("effects {}", self.effects_text()));
        if let Some(t) = self.tolerance_mm {
            lines.push(format!("tolerance {} mm", fmt_mm(t)));
        }
        if let Some(u) = &self.uncertainty {
            lines.push(format!(
                "uncertainty U(k=2) from the parameter covariance of {}",
                ascii(&u.sources.join(", "))
            ));
        }
        if !self.auto_gains.is_empty() {
            lines.push(format!("gain auto {}", self.auto_gains_text()));
        }
        if self.annotated {
            lines.push(
                "note: dev = deviation predicted without compensation, mm, then per effect".into(),
            );
            if self.uncertainty.is_some() {
                lines.push("note: U = expanded uncertainty (k=2) of dev, mm".into());
            }
            lines.push(
                "note: takeup = block first moves onto its start, solved for its new motion".into(),
            );
        }
        lines
    }

    /// The provenance as a JSON object (the `provenance` of reports and
    /// batch summaries; schema: `schemas/report.schema.json`).
    pub fn to_json(&self) -> serde_json::Value {
        let calibrations = match &self.status {
            Status::Calibrated(list) => serde_json::to_value(list).unwrap_or_default(),
            _ => serde_json::Value::Array(Vec::new()),
        };
        let mut o = serde_json::json!({
            "postproc": self.version,
            "machine": {
                "file": self.machine_file,
                "bundled": self.machine_bundled,
                "sha256": self.machine_sha256,
                "status": self.status.word(),
                "calibrations": calibrations,
            },
            "effects": self.effects,
            "tolerance_mm": self.tolerance_mm,
        });
        if let (Some(u), Some(map)) = (&self.uncertainty, o.as_object_mut()) {
            map.insert(
                "uncertainty".into(),
                serde_json::json!({ "k": crate::predict::uncertainty::COVERAGE_K, "covariance_of": u.sources }),
            );
        }
        if let (false, Some(map)) = (self.auto_gains.is_empty(), o.as_object_mut()) {
            let g: serde_json::Map<String, serde_json::Value> = self
                .auto_gains
                .iter()
                .map(|(e, g)| ((*e).to_string(), serde_json::json!(g)))
                .collect();
            map.insert("gain_auto".into(), serde_json::Value::Object(g));
        }
        o
    }

    /// `geometric x0.93`: the factors of `--gain-auto`, by how well the
    /// parameter covariance knows each effect.
    pub fn auto_gains_text(&self) -> String {
        let parts: Vec<String> = self
            .auto_gains
            .iter()
            .map(|(e, g)| format!("{e} x{}", fmt_gain(*g)))
            .collect();
        format!("{} (by the parameter covariance)", parts.join(", "))
    }

    /// The provenance on one line (the comment line of CSV and table
    /// reports).
    pub fn one_line(&self) -> String {
        let mut line = format!(
            "postproc {}; machine {}{} sha256 {}; status {}; effects {}",
            self.version,
            self.machine_file,
            if self.machine_bundled {
                " (bundled)"
            } else {
                ""
            },
            self.machine_sha256,
            self.status.describe(),
            self.effects_text(),
        );
        if let Some(t) = self.tolerance_mm {
            line.push_str(&format!("; tolerance {} mm", fmt_mm(t)));
        }
        if let Some(u) = &self.uncertainty {
            line.push_str(&format!("; uncertainty U(k=2) of {}", u.sources.join(", ")));
        }
        if !self.auto_gains.is_empty() {
            line.push_str(&format!("; gain auto {}", self.auto_gains_text()));
        }
        line
    }

    /// The provenance as `key: value` lines, for the end of a table report:
    /// the fields of [`Provenance::one_line`], one per line, so that none
    /// is wider than the machine file's name or the effects need.
    pub fn key_lines(&self) -> Vec<String> {
        let mut lines = vec![
            format!("postproc: {}", self.version),
            format!(
                "machine: {}{}",
                self.machine_file,
                if self.machine_bundled {
                    " (bundled)"
                } else {
                    ""
                }
            ),
            format!("machine sha256: {}", self.machine_sha256),
            format!("machine status: {}", self.status.describe()),
            format!("effects: {}", self.effects_text()),
        ];
        if let Some(t) = self.tolerance_mm {
            lines.push(format!("tolerance: {} mm", fmt_mm(t)));
        }
        if let Some(u) = &self.uncertainty {
            lines.push(format!("uncertainty U(k=2): {}", u.sources.join(", ")));
        }
        if !self.auto_gains.is_empty() {
            lines.push(format!("gain auto: {}", self.auto_gains_text()));
        }
        lines
    }

    /// `geometric 1, static 1, thermal 0.8, dynamic 1 reported only`.
    pub fn effects_text(&self) -> String {
        let parts: Vec<String> = self
            .effects
            .iter()
            .map(|e| {
                let g = if e.gain == 0.0 {
                    "off".to_string()
                } else {
                    fmt_gain(e.gain)
                };
                if e.reported_only && e.gain != 0.0 {
                    format!("{} {g} reported only", e.effect)
                } else {
                    format!("{} {g}", e.effect)
                }
            })
            .collect();
        parts.join(", ")
    }

    /// The header in `syntax`, each line ended by `eol`.
    pub fn render(&self, syntax: Syntax, eol: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        for line in self.lines() {
            match syntax {
                Syntax::GcodeParens => {
                    out.push(b'(');
                    out.extend_from_slice(line.as_bytes());
                    out.push(b')');
                }
                Syntax::GcodeSemicolon => {
                    out.extend_from_slice(b"; ");
                    out.extend_from_slice(line.as_bytes());
                }
                Syntax::Rapid => {
                    out.extend_from_slice(b"  ! ");
                    out.extend_from_slice(line.as_bytes());
                }
            }
            out.extend_from_slice(eol);
        }
        out
    }
}

/// A gain with up to 3 decimals, trailing zeros removed.
fn fmt_gain(g: f64) -> String {
    let s = format!("{g:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// A length in mm with up to 6 decimals, trailing zeros removed.
fn fmt_mm(v: f64) -> String {
    let s = format!("{v:.6}");
    let t = s.trim_end_matches('0');
    t.strip_suffix('.').unwrap_or(t).to_string()
}

/// `s` in printable ASCII without the comment delimiters of any syntax
/// (others become `_`).
fn ascii(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_graphic() && !matches!(c, '(' | ')' | ';' | '!') || c == ' ' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The lines of `head`, each with its line end.
fn head_lines(head: &[u8]) -> impl Iterator<Item = &[u8]> {
    head.split_inclusive(|&b| b == b'\n').take(HEAD_LINES)
}

/// The 1-based line of a postproc header's first line in the head of a
/// program, if it has one: a comment line (`(`, `;` or `!`) that holds
/// `postproc`, a version and [`MARKER`], in any letter case.
pub fn find_marker(head: &[u8]) -> Option<usize> {
    let marker = MARKER.as_bytes();
    for (i, line) in head_lines(head).enumerate() {
        let t = line.trim_ascii();
        let Some(body) = t
            .strip_prefix(b"(")
            .or_else(|| t.strip_prefix(b";"))
            .or_else(|| t.strip_prefix(b"!"))
        else {
            continue;
        };
        let body = body.trim_ascii_start();
        if body.len() >= 9
            && body[..9].eq_ignore_ascii_case(b"postproc ")
            && body
                .windows(marker.len())
                .any(|w| w.eq_ignore_ascii_case(marker))
        {
            return Some(i + 1);
        }
    }
    None
}

/// The line end of the program's first line (LF when it has none).
pub fn line_end(head: &[u8]) -> &'static [u8] {
    match memchr::memchr(b'\n', head) {
        Some(i) if i > 0 && head[i - 1] == b'\r' => b"\r\n",
        _ => b"\n",
    }
}

/// The comment syntax of a G-code program: `;` when the first comment in
/// its head is a `;` comment, else parentheses.
pub fn gcode_syntax(head: &[u8]) -> Syntax {
    for line in head_lines(head) {
        let paren = memchr::memchr(b'(', line);
        let semi = memchr::memchr(b';', line);
        match (paren, semi) {
            (Some(p), Some(s)) if s < p => return Syntax::GcodeSemicolon,
            (None, Some(_)) => return Syntax::GcodeSemicolon,
            (Some(_), _) => return Syntax::GcodeParens,
            (None, None) => {}
        }
    }
    Syntax::GcodeParens
}

/// Byte offset in a program's head where its header goes (see the module
/// documentation), or `None` when the head does not yet show it (more of
/// the program is needed).
pub fn insert_at(head: &[u8], syntax: Syntax, complete: bool) -> Option<usize> {
    let mut at = if head.starts_with(BOM) { BOM.len() } else { 0 };
    let mut lines = head_lines(&head[at..]).peekable();
    if syntax == Syntax::Rapid {
        for line in lines {
            if !line.ends_with(b"\n") && !complete {
                return None;
            }
            at += line.len();
            let t = line.trim_ascii_start();
            if t.len() > 6 && t[..6].eq_ignore_ascii_case(b"MODULE") && t[6].is_ascii_whitespace() {
                return Some(at);
            }
        }
        // No module line (a file of routines): the header opens the file,
        // after its byte-order mark.
        return if complete || at >= HEAD_BYTES || head.len() >= HEAD_BYTES {
            Some(if head.starts_with(BOM) { BOM.len() } else { 0 })
        } else {
            None
        };
    }
    // Leading `%` lines, then one program-number line.
    let mut seen_percent = false;
    while let Some(line) = lines.peek() {
        if !line.ends_with(b"\n") && !complete {
            return None;
        }
        let t = line.trim_ascii();
        if t.starts_with(b"%") || (t.is_empty() && !seen_percent) {
            seen_percent |= t.starts_with(b"%");
            at += line.len();
            lines.next();
        } else {
            break;
        }
    }
    if let Some(line) = lines.peek() {
        if !line.ends_with(b"\n") && !complete {
            return None;
        }
        if is_program_number(line.trim_ascii()) {
            at += line.len();
        }
    } else if !complete {
        return None;
    }
    Some(at)
}

/// `O1234`, `O 0815 …`, `o12 (NAME)`, `:1234`: a program-number line.
fn is_program_number(t: &[u8]) -> bool {
    let rest = match t.first() {
        Some(b'O' | b'o' | b':') => &t[1..],
        _ => return false,
    };
    rest.trim_ascii_start()
        .first()
        .is_some_and(u8::is_ascii_digit)
}

/// A writer that puts the header into a program as it is written: it
/// holds the program's first bytes until the header's place is known
/// ([`insert_at`]), writes the header there and passes everything else
/// through unchanged. [`HeaderWriter::finish`] must be called once the
/// program is written.
pub struct HeaderWriter<'w> {
    inner: &'w mut dyn Write,
    provenance: Provenance,
    rapid: bool,
    /// Bytes held until the header is written; `None` once it is.
    held: Option<Vec<u8>>,
}

impl<'w> HeaderWriter<'w> {
    /// Writes into `inner`; `rapid` for a RAPID module, else G-code.
    pub fn new(inner: &'w mut dyn Write, provenance: Provenance, rapid: bool) -> Self {
        HeaderWriter {
            inner,
            provenance,
            rapid,
            held: Some(Vec::new()),
        }
    }

    /// Writes the header into the held bytes when its place is known (or
    /// `complete`: the program is all there), then the held bytes.
    fn try_place(&mut self, complete: bool) -> std::io::Result<()> {
        let Some(held) = self.held.as_ref() else {
            return Ok(());
        };
        let enough = complete || held.len() >= HEAD_BYTES || bytecount_lines(held) >= HEAD_LINES;
        let syntax = if self.rapid {
            Syntax::Rapid
        } else if enough {
            gcode_syntax(held)
        } else {
            // The comment syntax needs the program's first comment.
            match first_comment_seen(held) {
                true => gcode_syntax(held),
                false => return Ok(()),
            }
        };
        let Some(at) = insert_at(held, syntax, enough) else {
            return Ok(());
        };
        let held = self.held.take().unwrap_or_default();
        let eol = line_end(&held);
        let (before, after) = held.split_at(at.min(held.len()));
        self.inner.write_all(before)?;
        if !before.is_empty() && !before.ends_with(b"\n") && before != BOM {
            self.inner.write_all(eol)?;
        }
        self.inner.write_all(&self.provenance.render(syntax, eol))?;
        self.inner.write_all(after)
    }

    /// Writes whatever is held (with the header) and flushes.
    pub fn finish(mut self) -> std::io::Result<()> {
        self.try_place(true)?;
        self.inner.flush()
    }
}

fn bytecount_lines(b: &[u8]) -> usize {
    memchr::memchr_iter(b'\n', b).count()
}

/// Whether a complete line of `held` holds a comment character.
fn first_comment_seen(held: &[u8]) -> bool {
    let end = memchr::memrchr(b'\n', held).map_or(0, |i| i + 1);
    memchr::memchr2(b'(', b';', &held[..end]).is_some()
}

impl Write for HeaderWriter<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.held.as_mut() {
            Some(held) => {
                held.extend_from_slice(buf);
                self.try_place(false)?;
                Ok(buf.len())
            }
            None => self.inner.write(buf),
        }
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        match self.held.as_mut() {
            Some(held) => {
                held.extend_from_slice(buf);
                self.try_place(false)
            }
            None => self.inner.write_all(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        // Held bytes wait for the header's place; the rest is passed on.
        self.inner.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn provenance() -> Provenance {
        Provenance {
            version: "9.9.9",
            machine_file: "mill (A);1.yaml".into(),
            machine_bundled: false,
            machine_sha256: "0".repeat(64),
            uncertainty: None,
            auto_gains: Vec::new(),
            status: Status::Example,
            effects: vec![
                EffectGain {
                    effect: "geometric",
                    gain: 1.0,
                    reported_only: false,
                },
                EffectGain {
                    effect: "thermal",
                    gain: 0.0,
                    reported_only: false,
                },
                EffectGain {
                    effect: "dynamic",
                    gain: 0.5,
                    reported_only: true,
                },
            ],
            tolerance_mm: Some(0.001),
            annotated: true,
        }
    }

    #[test]
    fn key_lines_hold_the_one_line_fields_one_per_line() {
        let p = provenance();
        let lines = p.key_lines();
        let keys: Vec<&str> = lines
            .iter()
            .map(|l| l.split_once(": ").map_or("", |(k, _)| k))
            .collect();
        assert_eq!(
            keys,
            [
                "postproc",
                "machine",
                "machine sha256",
                "machine status",
                "effects",
                "tolerance"
            ]
        );
        // The same values as the one-line form.
        let one = p.one_line();
        for l in &lines {
            let (_, value) = l.split_once(": ").unwrap_or_default();
            assert!(one.contains(value), "{value} not in {one}");
        }
        let mut p = p;
        p.tolerance_mm = None;
        assert!(p.key_lines().iter().all(|l| !l.starts_with("tolerance")));
    }

    fn through(program: &[u8], rapid: bool, chunk: usize) -> Vec<u8> {
        let mut out = Vec::new();
        let mut w = HeaderWriter::new(&mut out, provenance(), rapid);
        for part in program.chunks(chunk.max(1)) {
            w.write_all(part).unwrap();
        }
        w.finish().unwrap();
        out
    }

    fn header(syntax: Syntax, eol: &[u8]) -> Vec<u8> {
        provenance().render(syntax, eol)
    }

    #[test]
    fn gcode_header_after_percent_and_program_number_whatever_the_chunks() {
        let program = b"%\nO1001 (PLATE)\n(T1 D50)\nG0 X1\n%\n";
        let mut want = b"%\nO1001 (PLATE)\n".to_vec();
        want.extend(header(Syntax::GcodeParens, b"\n"));
        want.extend_from_slice(b"(T1 D50)\nG0 X1\n%\n");
        for chunk in [1, 3, 7, 1000] {
            assert_eq!(through(program, false, chunk), want, "chunk {chunk}");
        }
    }

    #[test]
    fn semicolon_programs_crlf_and_spaced_program_numbers() {
        let program = b"%\r\nO 0815 ; FLANGE\r\nG0 X1\r\n";
        let mut want = b"%\r\nO 0815 ; FLANGE\r\n".to_vec();
        want.extend(header(Syntax::GcodeSemicolon, b"\r\n"));
        want.extend_from_slice(b"G0 X1\r\n");
        assert_eq!(through(program, false, 4), want);
        // No `%` and no program number: the header opens the file.
        let mut want = header(Syntax::GcodeParens, b"\n");
        want.extend_from_slice(b"G0 X1\n");
        assert_eq!(through(b"G0 X1\n", false, 2), want);
        // A byte-order mark stays first.
        let mut want = b"\xEF\xBB\xBF%\nO1001\n".to_vec();
        want.extend(header(Syntax::GcodeParens, b"\n"));
        want.extend_from_slice(b"G0 X1\n%\n");
        assert_eq!(through(b"\xEF\xBB\xBF%\nO1001\nG0 X1\n%\n", false, 2), want);
        let mut want = BOM.to_vec();
        want.extend(header(Syntax::GcodeParens, b"\n"));
        want.extend_from_slice(b"G0 X1\n");
        assert_eq!(through(b"\xEF\xBB\xBFG0 X1\n", false, 2), want);
        // An empty program is the header alone.
        assert_eq!(through(b"", false, 1), header(Syntax::GcodeParens, b"\n"));
    }

    #[test]
    fn rapid_header_after_the_module_line() {
        let program = b"%%%\n  VERSION:1\n%%%\n\nMODULE Drill\n  CONST num n := 1;\nENDMODULE\n";
        let mut want = b"%%%\n  VERSION:1\n%%%\n\nMODULE Drill\n".to_vec();
        want.extend(header(Syntax::Rapid, b"\n"));
        want.extend_from_slice(b"  CONST num n := 1;\nENDMODULE\n");
        assert_eq!(through(program, true, 5), want);
    }

    #[test]
    fn rapid_header_after_the_module_line_of_a_file_with_a_byte_order_mark() {
        let program = b"\xEF\xBB\xBFMODULE Drill\r\n  CONST num n := 1;\r\nENDMODULE\r\n";
        let mut want = b"\xEF\xBB\xBFMODULE Drill\r\n".to_vec();
        want.extend(header(Syntax::Rapid, b"\r\n"));
        want.extend_from_slice(b"  CONST num n := 1;\r\nENDMODULE\r\n");
        assert_eq!(through(program, true, 5), want);
        // Without a module line the header still follows the mark.
        let program = b"\xEF\xBB\xBFPROC p()\nENDPROC\n";
        let mut want = BOM.to_vec();
        want.extend(header(Syntax::Rapid, b"\n"));
        want.extend_from_slice(b"PROC p()\nENDPROC\n");
        assert_eq!(through(program, true, 5), want);
    }

    #[test]
    fn header_text_is_plain_ascii_without_delimiters_and_marks_the_program() {
        let h = header(Syntax::GcodeParens, b"\n");
        for line in h.split(|&b| b == b'\n').filter(|l| !l.is_empty()) {
            assert!(line.len() <= 78, "{}", String::from_utf8_lossy(line));
            let inner = &line[1..line.len() - 1];
            assert!(
                inner.iter().all(|&b| b.is_ascii_graphic() || b == b' ')
                    && !inner.contains(&b'(')
                    && !inner.contains(&b')')
                    && !inner.contains(&b';'),
                "{}",
                String::from_utf8_lossy(line)
            );
        }
        let text = String::from_utf8(h.clone()).unwrap();
        assert!(text.contains("effects geometric 1, thermal off, dynamic 0.5 reported only"));
        assert!(text.contains("machine mill _A__1.yaml"), "{text}");
        let mut marked = b"%\nO1 (X)\n".to_vec();
        marked.extend(h);
        assert_eq!(find_marker(&marked), Some(3));
        assert_eq!(
            find_marker(&through(b"MODULE M\nENDMODULE\n", true, 64)),
            Some(2)
        );
        // A program that merely names postproc is not marked.
        assert_eq!(
            find_marker(b"%\nO1001 (POSTPROC SAMPLE - POCKET PLATE)\n"),
            None
        );
        assert_eq!(
            find_marker(b"(postproc 1.0 COMPENSATED PROGRAM - DO NOT COMPENSATE IT AGAIN)\n"),
            Some(1)
        );
    }
}
