//! Which language a program file is written in: ABB RAPID or G-code.
//!
//! A file is RAPID when its extension is one of [`RAPID_EXTENSIONS`] (in
//! any case), G-code when it is one of [`GCODE_EXTENSIONS`]; when the
//! extension says neither (none, `.txt`, …), its first token decides: a
//! RAPID module opens with `MODULE` or a `%%%` header, after blanks and
//! `!` comments (see `grammar/rapid.md`). Only regular files are read for
//! that: a named pipe or a device is never consumed here. [`gcode_text`]
//! recognises a G-code program by its first block, for `batch`, which
//! takes a file without a program extension found in a folder only when
//! its content is a program. A folder and a
//! `.pgf` program file are RAPID programs of several modules.

use std::io::Read;
use std::path::Path;

/// Extensions of RAPID modules: program modules (`.mod`, `.modx`), system
/// modules (`.sys`) and the older program files (`.prg`).
pub const RAPID_EXTENSIONS: [&str; 4] = ["mod", "modx", "sys", "prg"];

/// Extensions of G-code programs.
pub const GCODE_EXTENSIONS: [&str; 5] = ["nc", "ngc", "tap", "gcode", "cnc"];

/// Bytes read from the start of a file to find its first token.
const SNIFF_BYTES: u64 = 64 << 10;

/// The extension of `path`, lower case.
fn extension(path: &Path) -> Option<String> {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
}

/// True when the extension of `path` is one of [`RAPID_EXTENSIONS`].
pub fn rapid_extension(path: &Path) -> bool {
    extension(path).is_some_and(|e| RAPID_EXTENSIONS.contains(&e.as_str()))
}

/// True when the extension of `path` is one of [`GCODE_EXTENSIONS`].
pub fn gcode_extension(path: &Path) -> bool {
    extension(path).is_some_and(|e| GCODE_EXTENSIONS.contains(&e.as_str()))
}

/// True when `head`, the first bytes of a file, opens like a RAPID module:
/// its first token after blanks (space, tab, line breaks, a UTF-8
/// byte-order mark) and `!` comments is `MODULE` (any case, as a whole
/// word) or `%%%`.
pub fn rapid_text(head: &[u8]) -> bool {
    let mut i = head.strip_prefix(b"\xef\xbb\xbf").unwrap_or(head);
    loop {
        let n = i
            .iter()
            .take_while(|b| matches!(b, b' ' | b'\t' | b'\r' | b'\n'))
            .count();
        i = i.get(n..).unwrap_or_default();
        if i.first() == Some(&b'!') {
            let end = i.iter().position(|&b| b == b'\n').unwrap_or(i.len());
            i = i.get(end..).unwrap_or_default();
            continue;
        }
        break;
    }
    if i.starts_with(b"%%%") {
        return true;
    }
    let word = i
        .get(..6)
        .is_some_and(|w| w.eq_ignore_ascii_case(b"MODULE"));
    let ends = i
        .get(6)
        .is_none_or(|b| !(b.is_ascii_alphanumeric() || *b == b'_'));
    word && ends
}

/// True when `head`, the first bytes of a file, opens like a G-code
/// program. Conservative, for files found without a program extension:
/// after blank lines, `%` tape marks and lines that are only `(…)` or `;`
/// comments, the first block (after an optional `/`) starts with a program
/// number (`O1001`, `:1001`), a block number (`N10`), a G, M or T code,
/// any case, and the whole line reads as words (a letter of the dialect, a
/// number with at least one digit) and comments. A byte-order mark, text,
/// or a line with anything else (`#` parameters, macro statements) is
/// not taken.
pub fn gcode_text(head: &[u8]) -> bool {
    let mut rest = head;
    while !rest.is_empty() {
        let end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
        let line = rest.get(..end).unwrap_or_default();
        rest = rest.get(end + 1..).unwrap_or_default();
        let line = trim_blanks(line);
        if line.is_empty() || line == b"%" {
            continue;
        }
        match gcode_line(line) {
            Some(true) => return true,
            // Only comments: read on.
            Some(false) => continue,
            None => return false,
        }
    }
    false
}

fn trim_blanks(mut line: &[u8]) -> &[u8] {
    while let [b' ' | b'\t' | b'\r', r @ ..] = line {
        line = r;
    }
    while let [r @ .., b' ' | b'\t' | b'\r'] = line {
        line = r;
    }
    line
}

/// Reads one line of G-code: `Some(true)` for a block whose first word
/// opens a program ([`gcode_text`]), `Some(false)` for a line of comments
/// only, `None` for anything else.
fn gcode_line(line: &[u8]) -> Option<bool> {
    let mut i = usize::from(line.first() == Some(&b'/'));
    let mut words = 0;
    while let Some(&b) = line.get(i) {
        match b {
            b' ' | b'\t' => i += 1,
            b';' => break,
            b'(' => i += line.get(i..)?.iter().position(|&c| c == b')')? + 1,
            _ => {
                let letter = b.to_ascii_uppercase();
                let first = words == 0;
                if first && !matches!(letter, b'O' | b'N' | b'G' | b'M' | b'T' | b':') {
                    return None;
                }
                if !first && !crate::program::gcode::LETTERS.contains(&letter) {
                    return None;
                }
                i += 1;
                while line.get(i) == Some(&b' ') {
                    i += 1;
                }
                if !first && matches!(line.get(i), Some(b'+' | b'-')) {
                    i += 1;
                }
                let digits = line
                    .get(i..)?
                    .iter()
                    .take_while(|c| c.is_ascii_digit() || **c == b'.')
                    .count();
                let number = line.get(i..i + digits)?;
                // The first word is a code or number: digits, no point first.
                let ok = number.iter().any(u8::is_ascii_digit)
                    && (!first || number.first().is_some_and(u8::is_ascii_digit));
                if !ok {
                    return None;
                }
                i += digits;
                words += 1;
            }
        }
    }
    Some(words > 0)
}

/// The first bytes of the regular file at `path` (at most 64 KiB), where
/// its language is told; `None` for anything else (a folder, a named
/// pipe, a device) or a file that cannot be read.
pub fn head(path: &Path) -> Option<Vec<u8>> {
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => {}
        _ => return None,
    }
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(SNIFF_BYTES).read_to_end(&mut head))
        .ok()
        .map(|_| head)
}

/// True when `path` holds a RAPID module: by its extension, or, when the
/// extension is neither RAPID's nor G-code's, by the first token of a
/// regular file ([`rapid_text`]). A file that cannot be read is not
/// RAPID here (its reader reports the error).
pub fn is_rapid(path: &Path) -> bool {
    // A folder or a `.pgf` program file: a RAPID program of several
    // modules (`crate::program::rapid::program`).
    if rapid_extension(path) || path.is_dir() || crate::program::rapid::program::is_pgf(path) {
        return true;
    }
    if gcode_extension(path) || path == Path::new("-") {
        return false;
    }
    head(path).is_some_and(|h| rapid_text(&h))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_token_tells_a_module() {
        for (text, rapid) in [
            (&b"MODULE Main\nENDMODULE\n"[..], true),
            (b"module m", true),
            (b"\xef\xbb\xbf  ! a comment\r\n\t! another\nMODULE x", true),
            (b"%%%\n  VERSION:1\n%%%\nMODULE M", true),
            (b"! G\xf6\xdfe\nMODULE M", true),
            (b"MODULEX", false),
            (b"MODULE_1", false),
            (b"MODULE", true),
            (b"G0 X1\n", false),
            (b"(MODULE)\n", false),
            (b"%\nO1000\n", false),
            (b"", false),
            (b"! only a comment", false),
        ] {
            assert_eq!(rapid_text(text), rapid, "{}", String::from_utf8_lossy(text));
        }
    }

    #[test]
    fn the_first_block_tells_a_gcode_program() {
        for (text, gcode) in [
            (&b"%\nO1001\nG21\n"[..], true),
            (b"O1001 (PART 7)\r\nN10 G90\r\n", true),
            (b":1001\n", true),
            (b"\n\n(HEADER)\n(T1 D10)\n; note\nN10 G21 G90 G54\n", true),
            (b"g0 x10 y-5.25 z+.5\n", true),
            (b"G 1 X 12.000 F 500\n", true),
            (b"G01X15.Y-5.25\n", true),
            (b"/N20 G0 X1.\n", true),
            (b"T1 M6\n", true),
            (b"M3 S3000\n", true),
            (b"%\n   \t\n%\n", false),
            (b"(only a comment)\n", false),
            (b"", false),
            (b"not a program\n", false),
            (b"Notes for the job\nG0 X1\n", false),
            (b"G-code notes\n", false),
            (b"M5 bolts\n", false),
            (b"Total 3\n", false),
            (b"X10 Y20\n", false),
            (b"O.5\n", false),
            (b"#1 = 5\nG0 X#1\n", false),
            (b"G0 X[#1+2]\n", false),
            (b"(open comment\nG0 X1\n", false),
            (b"\xef\xbb\xbfG0 X1\n", false),
            (b"MODULE M\nENDMODULE\n", false),
            (b"<?xml version=\"1.0\"?>\n", false),
            (b"%PDF-1.4\n", false),
            (b"N10 G0 X1 Y\n", false),
        ] {
            assert_eq!(gcode_text(text), gcode, "{}", String::from_utf8_lossy(text));
        }
    }

    #[test]
    fn program_text_reads_regular_files_only() {
        let program_text = |p: &Path| head(p).is_some_and(|h| rapid_text(&h) || gcode_text(&h));
        let dir = tempfile::tempdir().unwrap();
        for (name, text, program) in [
            ("O1001", "%\nO1001\nG0 X1.\n%\n", true),
            ("prog.eia", "N10 G21\n", true),
            ("cell.txt", "MODULE M\nENDMODULE\n", true),
            ("notes.txt", "not a program\n", false),
        ] {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            assert_eq!(program_text(&path), program, "{name}");
        }
        assert!(!program_text(dir.path()));
        assert!(!program_text(&dir.path().join("missing")));
    }

    #[test]
    fn extensions_decide_before_the_content() {
        let dir = tempfile::tempdir().unwrap();
        let module = "MODULE M\nENDMODULE\n";
        for (name, text, rapid) in [
            ("a.sys", "G0 X1\n", true),
            ("a.SYS", module, true),
            ("a.modx", module, true),
            ("a.prg", module, true),
            ("a.Mod", module, true),
            ("a.nc", module, false),
            ("a", module, true),
            ("a.txt", "  ! cell\n%%%\n  VERSION:1\n%%%\nMODULE M\n", true),
            ("b.txt", "G0 X1\n", false),
            ("b", "", false),
        ] {
            let path = dir.path().join(name);
            std::fs::write(&path, text).unwrap();
            assert_eq!(is_rapid(&path), rapid, "{name}");
        }
        assert!(!is_rapid(&dir.path().join("missing")));
        // A folder and a `.pgf` program file are programs of several modules.
        assert!(is_rapid(dir.path()));
        assert!(is_rapid(Path::new("cell/Cell.PGF")));
        assert!(!is_rapid(Path::new("-")));
    }
}
