//! Which language a program file is written in: ABB RAPID or G-code.
//!
//! A file is RAPID when its extension is one of [`RAPID_EXTENSIONS`] (in
//! any case), G-code when it is one of [`GCODE_EXTENSIONS`]; when the
//! extension says neither (none, `.txt`, …), its first token decides: a
//! RAPID module opens with `MODULE` or a `%%%` header, after blanks and
//! `!` comments (see `grammar/rapid.md`). Only regular files are read for
//! that: a named pipe or a device is never consumed here. A folder and a
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
    match std::fs::metadata(path) {
        Ok(m) if m.is_file() => {}
        _ => return false,
    }
    let mut head = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(SNIFF_BYTES).read_to_end(&mut head))
        .is_ok_and(|_| rapid_text(&head))
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
