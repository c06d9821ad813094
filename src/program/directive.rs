//! `POSTPROC MILLING KEY=VALUE …` directive comments: the axial depth and
//! radial width of cut (and, in RAPID, the spindle speed) that the
//! process-force models use from the directive's line on, over the machine
//! file's values. One reader for both languages: G-code carries the
//! directive in a comment (`(…)` or `;…`), RAPID after `!`. Any other
//! comment, including other text after `POSTPROC`, is no directive.

use crate::process::CutSettings;
use crate::process::limits::{CUT_MAX_MM, SPINDLE_MAX_RPM};

/// A refused directive: where and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Refused {
    /// Byte offset in the comment body of the word at fault; `None` for the
    /// directive as a whole (located at its comment).
    pub word_at: Option<usize>,
    /// What is wrong, with the word.
    pub message: String,
}

/// Reads the body of one comment (the text after its opener, without a
/// closing `)`). `Ok(None)` when it is no directive; otherwise the settings
/// `cur` with the directive's keys set. Lengths are given in program units
/// and multiplied by `scale` (mm per unit). `rpm`: the language takes the
/// spindle speed from the directive (RAPID); G-code has its `S` word.
pub fn read(
    body: &str,
    rpm: bool,
    scale: f64,
    mut cur: CutSettings,
) -> Result<Option<CutSettings>, Refused> {
    let mut words = word_spans(body);
    let is_directive = matches!(
        (words.next(), words.next()),
        (Some((_, a)), Some((_, b)))
            if a.eq_ignore_ascii_case("POSTPROC") && b.eq_ignore_ascii_case("MILLING")
    );
    if !is_directive {
        return Ok(None);
    }
    let keys = if rpm {
        "DEPTH, WIDTH, RPM"
    } else {
        "DEPTH, WIDTH"
    };
    let mut any = false;
    for (off, word) in words {
        let refuse = |message: String| Refused {
            word_at: Some(off),
            message,
        };
        let (key, value) = word
            .split_once('=')
            .ok_or_else(|| refuse(format!("`{word}`: expected KEY=VALUE ({keys})")))?;
        let v: f64 = value
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite())
            .ok_or_else(|| refuse(format!("`{word}`: `{value}` is not a number")))?;
        let key = key.to_ascii_uppercase();
        match key.as_str() {
            "DEPTH" | "WIDTH" if v < 0.0 => {
                return Err(refuse(format!("`{word}`: must be a length of 0 or more")));
            }
            "DEPTH" | "WIDTH" if v * scale > CUT_MAX_MM => {
                return Err(refuse(format!(
                    "`{word}`: more than {CUT_MAX_MM} mm of cut"
                )));
            }
            "DEPTH" => cur.depth_mm = Some(v * scale),
            "WIDTH" => cur.width_mm = Some(v * scale),
            "RPM" if rpm && !(v > 0.0 && v <= SPINDLE_MAX_RPM) => {
                return Err(refuse(format!(
                    "`{word}`: must be a spindle speed in (0, {SPINDLE_MAX_RPM}] 1/min"
                )));
            }
            "RPM" if rpm => cur.spindle_rpm = Some(v),
            _ => {
                return Err(refuse(format!(
                    "unknown key `{key}` (expected {keys})",
                    key = word.split_once('=').map_or(word, |(k, _)| k)
                )));
            }
        }
        any = true;
    }
    if !any {
        return Err(Refused {
            word_at: None,
            message: format!("POSTPROC MILLING directive without a key ({keys})"),
        });
    }
    Ok(Some(cur))
}

/// Whitespace-separated words of `s` with their byte offsets.
fn word_spans(s: &str) -> impl Iterator<Item = (usize, &str)> {
    s.split_ascii_whitespace().map(move |w| {
        let off = w.as_ptr() as usize - s.as_ptr() as usize;
        (off, w)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn refused(body: &str, rpm: bool) -> Refused {
        match read(body, rpm, 1.0, CutSettings::default()) {
            Err(r) => r,
            Ok(s) => panic!("`{body}` read as {s:?}"),
        }
    }

    #[test]
    fn only_postproc_milling_is_a_directive() {
        for body in [
            "",
            "POSTPROC",
            "POSTPROC other DEPTH=1",
            "MILLING DEPTH=1",
            "roughing",
        ] {
            assert_eq!(read(body, true, 1.0, CutSettings::default()), Ok(None));
        }
    }

    #[test]
    fn keys_are_read_in_either_case_and_scaled() {
        let start = CutSettings {
            depth_mm: Some(7.0),
            ..CutSettings::default()
        };
        let got = read(" postproc Milling width=0.25 ", false, 25.4, start);
        assert_eq!(
            got,
            Ok(Some(CutSettings {
                depth_mm: Some(7.0),
                width_mm: Some(6.35),
                spindle_rpm: None
            }))
        );
        let got = read("POSTPROC MILLING DEPTH=2 RPM=12000", true, 1.0, start);
        assert_eq!(
            got,
            Ok(Some(CutSettings {
                depth_mm: Some(2.0),
                width_mm: None,
                spindle_rpm: Some(12000.0)
            }))
        );
    }

    #[test]
    fn bad_words_are_refused_at_their_offset() {
        // Offsets count from the body's first byte.
        let r = refused("POSTPROC MILLING DEPTH=2 SPEED=4", true);
        assert_eq!(r.word_at, Some(25));
        assert_eq!(
            r.message,
            "unknown key `SPEED` (expected DEPTH, WIDTH, RPM)"
        );
        let r = refused("POSTPROC MILLING RPM=9000", false);
        assert_eq!(r.message, "unknown key `RPM` (expected DEPTH, WIDTH)");
        let r = refused("POSTPROC MILLING", true);
        assert_eq!(r.word_at, None);
        for (body, msg) in [
            ("POSTPROC MILLING DEPTH", "`DEPTH`: expected KEY=VALUE"),
            ("POSTPROC MILLING DEPTH=-1", "`DEPTH=-1`: must be a length"),
            ("POSTPROC MILLING WIDTH=x", "`WIDTH=x`: `x` is not a number"),
            (
                "POSTPROC MILLING WIDTH=inf",
                "`WIDTH=inf`: `inf` is not a number",
            ),
            (
                "POSTPROC MILLING DEPTH=101",
                "`DEPTH=101`: more than 100 mm",
            ),
            ("POSTPROC MILLING RPM=0", "`RPM=0`: must be a spindle speed"),
            (
                "POSTPROC MILLING RPM=300000",
                "`RPM=300000`: must be a spindle",
            ),
        ] {
            let r = refused(body, true);
            assert_eq!(r.word_at, Some(17), "{body}");
            assert!(r.message.starts_with(msg), "{body}: {}", r.message);
        }
        // The limit holds in millimetres: 4 inches is 101.6 mm.
        let r = read(
            "POSTPROC MILLING DEPTH=4",
            false,
            25.4,
            CutSettings::default(),
        );
        assert!(
            r.as_ref()
                .is_err_and(|r| r.message.starts_with("`DEPTH=4`: more than 100 mm of cut")),
            "{r:?}"
        );
    }
}
