//! Programs written in a dialect this reader does not take: native Siemens
//! 840D (Sinumerik), Heidenhain conversational (Klartext) and lathe G-code.
//!
//! Their lines fail the syntax of `grammar/gcode.md` in many different ways
//! (`DEF REAL` is a `D` without a number, `0 BEGIN PGM` a number without a
//! letter, `U-1.5` an unknown letter). When a line fails, `refine` looks
//! at the whole line and, when it is recognisably one of those dialects,
//! names the dialect in front of the syntax message, so that the user
//! learns what is wrong with the program as a whole and not only with its
//! first unreadable word.

use crate::error::Located;

/// Keywords of native Siemens 840D programs that no ISO G-code line holds
/// (compared without case). `CYCLE…` and `POCKET…` are matched as prefixes.
const SIEMENS: &[&str] = &[
    "DEF",
    "MCALL",
    "TRANS",
    "ATRANS",
    "AROT",
    "ASCALE",
    "MIRROR",
    "AMIRROR",
    "MSG",
    "GOTOF",
    "GOTOB",
    "GOTOC",
    "PROC",
    "TRAORI",
    "TRAFOOF",
    "TRANSMIT",
    "TRACYL",
    "CFTCP",
    "CFC",
    "CFIN",
    "SUPA",
    "DIAMON",
    "DIAMOF",
    "WORKPIECE",
    "SOFT",
    "BRISK",
    "FFWON",
    "FFWOF",
    "SPOS",
    "STOPRE",
    "ORIWKS",
    "ORIAXES",
    "COMPCAD",
    "COMPCURV",
    "COMPOF",
    "EXTCALL",
    "LONGHOLE",
    "SLOT1",
    "SLOT2",
    "HOLES1",
    "HOLES2",
    "CYCLE",
    "POCKET",
];

/// Keywords that follow the block number of a Heidenhain conversational
/// line (`5 L X+10 Y+5 R0 FMAX`, `0 BEGIN PGM PART MM`).
const HEIDENHAIN: &[&str] = &[
    "BEGIN", "END", "BLK", "TOOL", "L", "LP", "LN", "C", "CC", "CP", "CR", "CT", "CTP", "CYCL",
    "LBL", "FN", "RND", "CHF", "APPR", "DEP", "CALL", "PLANE", "FUNCTION", "STOP", "POLARKIN",
];

/// Statements of Fanuc Macro B (custom macro) that open a line: control
/// flow and output, run by the controller, never by an offline reader.
const MACRO_B: &[&str] = &[
    "IF", "WHILE", "GOTO", "END", "DPRNT", "BPRNT", "POPEN", "PCLOS", "SETVN",
];

/// The Macro B statement that opens `text` (`IF [#1 GT 0] GOTO 100`,
/// `WHILE [#1 LT 5] DO1`, `GOTO 100`, `DPRNT[…]`), after an optional block
/// number.
fn macro_statement(text: &[u8]) -> Option<&'static str> {
    let mut t = text.trim_ascii_start();
    if t.first().is_some_and(|c| c.eq_ignore_ascii_case(&b'N')) {
        let digits = t[1..].iter().take_while(|c| c.is_ascii_digit()).count();
        if digits > 0 {
            t = t[1 + digits..].trim_ascii_start();
        }
    }
    let (word, next) = runs(t).next()?;
    if word.as_ptr() != t.as_ptr() {
        return None;
    }
    let opens = next.is_none_or(|c| matches!(c, b' ' | b'\t' | b'[' | b'0'..=b'9'));
    MACRO_B
        .iter()
        .find(|k| opens && word.eq_ignore_ascii_case(k.as_bytes()))
        .copied()
}

/// Names the dialect of a line that failed to parse, in front of the
/// syntax message; the error is returned unchanged for a line of no
/// recognised dialect.
pub(crate) fn refine(line: &[u8], mut e: Located) -> Located {
    if let Some(k) = macro_statement(super::strip_eol(line)) {
        e.message = format!(
            "Fanuc custom macro statement `{k}` (control flow runs on the controller): \
             cannot be compensated offline, expand the macro in CAM: {}",
            e.message
        );
        return e;
    }
    if let Some(d) = dialect_of(super::strip_eol(line)) {
        e.message = format!(
            "{d} programs are not supported, only ISO (Fanuc-style) milling G-code: {}",
            e.message
        );
    }
    e
}

/// The dialect a line is written in, when it is one this reader does not
/// take.
pub fn dialect_of(text: &[u8]) -> Option<&'static str> {
    // Comments: `;` to the end of the line in every dialect here.
    let text = match text.iter().position(|&c| c == b';') {
        Some(p) => &text[..p],
        None => text,
    };
    if heidenhain(text) {
        return Some("Heidenhain conversational (Klartext)");
    }
    if text.trim_ascii_end().ends_with(b"*") {
        // Every block of a Heidenhain DIN/ISO program ends with `*`.
        return Some("Heidenhain DIN/ISO");
    }
    if crate::program::language::krl_def(text) {
        // `DEF MAIN()`: a KRL routine, not a Siemens definition.
        return Some("KUKA KRL");
    }
    if siemens(text) {
        return Some("native Siemens 840D (Sinumerik)");
    }
    if lathe(text) {
        return Some("lathe (turning; `U`/`W` incremental axis words)");
    }
    None
}

/// The alphabetic runs of `text` outside `( )` comments (nested ones
/// read as the scanner reads them), each with the byte
/// after it.
fn runs(text: &[u8]) -> impl Iterator<Item = (&[u8], Option<u8>)> {
    let mut i = 0;
    std::iter::from_fn(move || {
        while i < text.len() {
            let c = text[i];
            if c == b'(' {
                i = super::comment_close(text, i).unwrap_or(text.len()) + 1;
                continue;
            }
            if c.is_ascii_alphabetic() {
                let start = i;
                while text.get(i).is_some_and(u8::is_ascii_alphabetic) {
                    i += 1;
                }
                return Some((&text[start..i], text.get(i).copied()));
            }
            i += 1;
        }
        None
    })
}

fn heidenhain(text: &[u8]) -> bool {
    // A block number, spaces, and a conversational keyword.
    let t = text.trim_ascii_start();
    let digits = t.iter().take_while(|c| c.is_ascii_digit()).count();
    let rest = &t[digits..];
    let spaced = rest.first().is_some_and(|&c| c == b' ' || c == b'\t');
    if digits > 0 && spaced {
        if let Some((word, _)) = runs(rest).next() {
            return HEIDENHAIN
                .iter()
                .any(|k| word.eq_ignore_ascii_case(k.as_bytes()));
        }
    }
    false
}

fn siemens(text: &[u8]) -> bool {
    if text.contains(&b'$') {
        // System variables (`$P_UIFR`, `$AA_IM`).
        return true;
    }
    let mut prev_r: Option<usize> = None;
    for (i, &c) in text.iter().enumerate() {
        // `R1=5`: an R parameter assignment.
        if c == b'R' || c == b'r' {
            prev_r = Some(i);
        } else if c == b'=' {
            if let Some(r) = prev_r {
                let between = &text[r + 1..i];
                let between = between.trim_ascii();
                if !between.is_empty() && between.iter().all(u8::is_ascii_digit) {
                    return true;
                }
            }
        } else if !(c.is_ascii_digit() || c == b' ') {
            prev_r = None;
        }
    }
    runs(text).any(|(word, _)| {
        word.len() >= 2
            && SIEMENS.iter().any(|k| {
                let k = k.as_bytes();
                if matches!(k, b"CYCLE" | b"POCKET") {
                    word.len() >= k.len() && word[..k.len()].eq_ignore_ascii_case(k)
                } else {
                    word.eq_ignore_ascii_case(k)
                }
            })
    })
}

fn lathe(text: &[u8]) -> bool {
    runs(text).any(|(word, next)| {
        matches!(word, b"U" | b"W" | b"u" | b"w")
            && next.is_some_and(|c| c.is_ascii_digit() || matches!(c, b'-' | b'+' | b'.' | b' '))
    })
}

#[cfg(test)]
mod tests {
    use super::dialect_of;

    fn of(s: &str) -> Option<&'static str> {
        dialect_of(s.as_bytes())
    }

    #[test]
    fn heidenhain_iso_blocks_are_named_by_their_end() {
        for l in [
            "%PLATTE G71 *",
            "N10 G30 G17 X+0 Y+0 Z-20 *",
            "N70 G01 Z-5 F200*",
        ] {
            assert_eq!(of(l), Some("Heidenhain DIN/ISO"), "{l}");
        }
        assert_eq!(of("G1 X1 (a * in a comment)"), None);
    }

    #[test]
    fn macro_statements_are_named() {
        use super::macro_statement;
        for (l, k) in [
            ("IF [#1 GT 0] GOTO 100", "IF"),
            ("N20 WHILE [#1 LT 5] DO1", "WHILE"),
            ("GOTO 100", "GOTO"),
            ("DPRNT[X#5021[44]]", "DPRNT"),
            ("END1", "END"),
        ] {
            assert_eq!(macro_statement(l.as_bytes()), Some(k), "{l}");
        }
        for l in ["G1 X1", "ENDIF", "IFX", "N10 G0 X1"] {
            assert_eq!(macro_statement(l.as_bytes()), None, "{l}");
        }
    }

    #[test]
    fn siemens_lines_are_named() {
        for l in [
            "DEF REAL DEPTH",
            "N10 R1=5",
            "R12 = 3.5",
            "CYCLE81(10,0,2,-5)",
            "N20 MCALL CYCLE83(1,2)",
            "TRANS X10 Y20",
            "G0 X=$P_UIFR[1]",
            "MSG(\"ROUGHING\")",
            "GOTOF LABEL1",
        ] {
            assert_eq!(of(l), Some("native Siemens 840D (Sinumerik)"), "{l}");
        }
    }

    #[test]
    fn a_krl_def_is_not_siemens() {
        for l in ["DEF MAIN()", "DEF Corte_JP ( )", "GLOBAL DEF PICK(P:IN)"] {
            assert_eq!(of(l), Some("KUKA KRL"), "{l}");
        }
        assert_eq!(
            of("DEF REAL DEPTH"),
            Some("native Siemens 840D (Sinumerik)")
        );
    }

    #[test]
    fn heidenhain_lines_are_named() {
        for l in [
            "0 BEGIN PGM PART MM",
            "1 BLK FORM 0.1 Z X+0 Y+0 Z-20",
            "3 TOOL CALL 1 Z S5000",
            "5 L X+10 Y+5 R0 FMAX",
            "7 CC X+50 Y+50",
            "9 END PGM PART MM",
        ] {
            assert_eq!(of(l), Some("Heidenhain conversational (Klartext)"), "{l}");
        }
    }

    #[test]
    fn lathe_lines_are_named() {
        for l in ["G1 U-1.5 F0.2", "G0 W2.", "G1 X20. W-5."] {
            assert!(of(l).is_some_and(|d| d.starts_with("lathe")), "{l}");
        }
    }

    #[test]
    fn iso_lines_and_other_errors_name_no_dialect() {
        for l in [
            "G1 X10 Y#1",
            "o100 while [#1 LT 5]",
            "G1 X=10.",
            "G1 X1 * Y2",
            "G0 X1 (DEF REAL IN A COMMENT",
            "(MSG) G0 X1",
            "G1 V5",
            "#100 = 5.",
            "IF [#1 GT 0] GOTO 10",
        ] {
            assert_eq!(of(l), None, "{l}");
        }
    }
}

/// A turning (lathe) program, recognised by its content: `G18` (the XZ
/// plane of a lathe) together with `G96` (constant surface speed), `G50 S…`
/// (the lathe's spindle speed clamp; a mill's `G50` cancels scaling and
/// has no `S`) or `G99` without drilling cycles (feed per revolution; a
/// mill's `G99` is the R-plane return of its cycles). Its X words would be
/// diameters and its F words feeds per revolution: read as a milling
/// program it would be misread in silence, so it is refused by name at the
/// line that shows it.
pub fn lathe_program(text: &[u8], file: &str) -> Option<Located> {
    let has = |n: &[u8]| memchr::memmem::find(text, n).is_some();
    if !(has(b"G18") || has(b"g18")) {
        return None;
    }
    let mut block = super::Block::default();
    let mut g18 = None;
    let mut sign: Option<(usize, &str)> = None;
    let mut per_rev = None;
    let mut cycles = false;
    for (i, line) in text.split_inclusive(|&c| c == b'\n').enumerate() {
        if super::parse_line(line, i + 1, file, &mut block).is_err() {
            continue;
        }
        for w in block.words.iter().filter(|w| w.letter == b'G') {
            match w.code10() {
                180 => {
                    g18.get_or_insert(i + 1);
                }
                960 => {
                    sign.get_or_insert((i + 1, "`G96` constant surface speed"));
                }
                500 if block.word(b'S').is_some() => {
                    sign.get_or_insert((i + 1, "`G50 S…` spindle speed clamp"));
                }
                990 => {
                    per_rev.get_or_insert(i + 1);
                }
                730 | 740 | 760 | 810..=890 => cycles = true,
                _ => {}
            }
        }
    }
    let g18 = g18?;
    let per_rev = per_rev
        .filter(|_| !cycles)
        .map(|l| (l, "`G99` feed per revolution"));
    let (line, what) = sign.or(per_rev)?;
    Some(Located::new(
        file,
        line,
        1,
        format!(
            "lathe (turning) program: {what} with `G18` (line {g18}); its X words are diameters and its feeds per revolution, and postproc reads milling programs only"
        ),
    ))
}

#[cfg(test)]
mod lathe_tests {
    use super::lathe_program;

    #[test]
    fn lathe_programs_are_named_and_mills_are_not() {
        let lathe = b"G18 G21\nG50 S3000\nG96 S180 M3\nG99 G1 X20. F0.2\n";
        let e = lathe_program(lathe, "t.nc").expect("a lathe program");
        assert_eq!(e.line, 2, "{}", e.message);
        assert!(
            e.message.contains("lathe (turning) program"),
            "{}",
            e.message
        );
        // A mill: G18 for arcs, G99 with a drilling cycle, G50 cancels scaling.
        let mill = b"G18 G2 X10 Z0 I5\nG50\nG99 G81 X0 Y0 Z-3 R1 F100\n";
        assert!(lathe_program(mill, "t.nc").is_none());
        assert!(lathe_program(b"G96 S100\n", "t.nc").is_none());
    }
}
