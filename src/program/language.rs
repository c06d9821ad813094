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
//!
//! A file in a robot or control language that postproc does not read
//! here ([`Unread`]: KUKA KRL and FANUC TP outside their `.src` and `.ls`
//! files, which their own front ends read first, Yaskawa JBI, URScript, Stäubli VAL3,
//! native Siemens 840D, Heidenhain conversational) is named by [`unread`]
//! before any reader sees it, from its extension and its head: the first
//! line that is not blank or a `;` comment, and for Siemens any line of
//! the head. A KRL `DEF MAIN()` (a name and its parameter list) is KRL;
//! a Siemens `DEF REAL X` (a type and a name) is Siemens.

use std::io::Read;
use std::path::Path;

use crate::error::{Located, clip_to};

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
            b'(' => i = crate::program::gcode::comment_close(line, i)? + 1,
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

/// A language postproc recognises in a file but does not read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unread {
    /// KUKA Robot Language: `.src` programs and `.dat` data lists.
    Krl,
    /// FANUC Teach Pendant programs: `.ls` (ASCII) and `.tp` (binary).
    FanucTp,
    /// Yaskawa Motoman INFORM jobs: `.jbi`.
    Jbi,
    /// Universal Robots URScript: `.script`.
    UrScript,
    /// Stäubli VAL3: `.pgx` programs, `.dtx` data, `.pjx` projects.
    Val3,
    /// Native Siemens 840D (Sinumerik) part programs (`.mpf`) and
    /// subprograms (`.spf`).
    Siemens,
    /// Heidenhain conversational (Klartext) programs: `.h`.
    Heidenhain,
}

impl Unread {
    /// The language's name, as messages give it.
    pub fn name(self) -> &'static str {
        match self {
            Unread::Krl => "KUKA KRL",
            Unread::FanucTp => "FANUC TP",
            Unread::Jbi => "Yaskawa JBI (INFORM)",
            Unread::UrScript => "Universal Robots URScript",
            Unread::Val3 => "Stäubli VAL3",
            Unread::Siemens => "Siemens 840D (Sinumerik)",
            Unread::Heidenhain => "Heidenhain conversational (Klartext)",
        }
    }

    /// The language an extension (lower case) alone names: only extensions
    /// that no readable program and no common other file carries.
    fn of_extension(ext: &str) -> Option<Unread> {
        Some(match ext {
            "src" => Unread::Krl,
            "ls" | "tp" => Unread::FanucTp,
            "jbi" => Unread::Jbi,
            "script" => Unread::UrScript,
            "pgx" | "dtx" | "pjx" => Unread::Val3,
            _ => return None,
        })
    }
}

/// What told a file's [`Unread`] language: the language, and the line of
/// the file that shows it, or none when the extension alone told.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Named {
    /// The language.
    pub language: Unread,
    /// The telling line: its number (1-based) and text.
    pub line: Option<(usize, String)>,
    /// The file's extension, lower case.
    pub extension: Option<String>,
}

impl Named {
    /// The one message of the file `file` in this language:
    /// ``file:line:1: KUKA KRL program (`&ACCESS RVP`): …``, or
    /// `file: KUKA KRL program (a .src file): …` when the extension told.
    pub fn error(&self, file: &str) -> Located {
        let lang = self.language.name();
        let rest = match self.language {
            // Only `batch` meets a `.src`: check, compensate and report read it.
            Unread::Krl if self.extension.as_deref() == Some("src") => {
                "batch does not read KRL programs yet: run postproc compensate on the .src"
            }
            Unread::Krl => {
                "postproc reads a KRL program from its .src (with the .dat beside it): give the .src"
            }
            Unread::FanucTp => {
                "postproc reads a TP program in its ASCII form, a .ls file (with a robot machine file)"
            }
            _ => {
                "a language postproc does not read (it reads ISO G-code, ABB RAPID, KUKA KRL and FANUC TP .ls)"
            }
        };
        match &self.line {
            Some((n, text)) => Located::new(
                file,
                *n,
                1,
                format!("{lang} program (`{}`): {rest}", clip_to(text, 40)),
            ),
            None => Located::whole_file(
                file,
                format!(
                    "{lang} program (a .{} file): {rest}",
                    self.extension.as_deref().unwrap_or_default()
                ),
            ),
        }
    }
}

/// The [`Unread`] language of the file at `path`, told by its extension
/// and its head ([`unread_text`]); `None` for a file of a language
/// postproc reads or of none it knows, for a RAPID module or program (by
/// extension, a folder, a `.pgf`) and for standard input. A file that
/// cannot be read, or is not a regular file, is told by its extension
/// alone.
pub fn unread(path: &Path) -> Option<Named> {
    if path == Path::new("-")
        || rapid_extension(path)
        || path.is_dir()
        || crate::program::rapid::program::is_pgf(path)
    {
        return None;
    }
    let ext = extension(path);
    let head = head(path).unwrap_or_default();
    unread_text(ext.as_deref(), &head)
}

/// The [`Unread`] language of a file with extension `ext` (lower case)
/// whose first bytes are `head`:
///
/// * the first line that is not blank, a `%` tape mark or a `;` comment
///   opens like one of those languages (see [`opening`]), whatever the
///   extension, since no G-code block or RAPID module opens so;
/// * else an extension only they use (`.src`, `.ls`, `.tp`, `.jbi`,
///   `.script`, `.pgx`, `.dtx`, `.pjx`);
/// * else, for `.mpf`, `.spf`, or a file of another extension whose first
///   block is G-code ([`gcode_text`]), a line of the head that only native
///   Siemens 840D writes (as the G-code reader names it); a `.mpf` in
///   plain ISO G-code is G-code.
pub fn unread_text(ext: Option<&str>, head: &[u8]) -> Option<Named> {
    if ext.is_some_and(|e| RAPID_EXTENSIONS.contains(&e)) {
        return None;
    }
    let named = |language, line| Named {
        language,
        line,
        extension: ext.map(str::to_string),
    };
    let head = head.strip_prefix(b"\xef\xbb\xbf").unwrap_or(head);
    let mut lines = head
        .split(|&b| b == b'\n')
        .enumerate()
        .map(|(i, l)| (i + 1, trim_blanks(l)));
    let first = lines
        .by_ref()
        .find(|(_, l)| !(l.is_empty() || *l == b"%" || l.starts_with(b";")));
    if let Some((n, line)) = first {
        if let Some(language) = opening(line, head) {
            return Some(named(language, Some((n, shown(line)))));
        }
    }
    if let Some(language) = ext.and_then(Unread::of_extension) {
        return Some(named(language, None));
    }
    let siemens_ext = ext.is_some_and(|e| matches!(e, "mpf" | "spf"));
    let other_ext = !ext.is_some_and(|e| GCODE_EXTENSIONS.contains(&e));
    if siemens_ext || (other_ext && gcode_text(head)) {
        let siemens = first.into_iter().chain(lines).find(|(_, l)| {
            !krl_def(l)
                && crate::program::gcode::dialect::dialect_of(l)
                    .is_some_and(|d| d.contains("Siemens"))
        });
        if let Some((n, line)) = siemens {
            return Some(named(Unread::Siemens, Some((n, shown(line)))));
        }
    }
    None
}

/// A line of a file, as text for a message.
fn shown(line: &[u8]) -> String {
    String::from_utf8_lossy(line).into_owned()
}

/// The word that opens `line` (letters, digits, `_`, `$`; maybe empty)
/// and what follows it, blanks skipped.
fn word_at(line: &[u8]) -> (&[u8], &[u8]) {
    let n = line
        .iter()
        .take_while(|b| b.is_ascii_alphanumeric() || **b == b'_' || **b == b'$')
        .count();
    let (w, rest) = line.split_at(n);
    (w, rest.trim_ascii_start())
}

/// True when the word `w` is the keyword `k`, in any case.
fn is_word(w: &[u8], k: &str) -> bool {
    w.eq_ignore_ascii_case(k.as_bytes())
}

/// True when `line` opens a KRL routine or data list: `DEF name(`,
/// `DEFFCT type name(`, `DEFDAT name`, each maybe after `GLOBAL`. A
/// Siemens `DEF REAL X` (a type, then a name) does not, nor a URScript or
/// Python `def name():` (ending with `:`).
pub fn krl_def(line: &[u8]) -> bool {
    let line = line.trim_ascii();
    if line.ends_with(b":") {
        return false;
    }
    let (mut w, mut rest) = word_at(line);
    if is_word(w, "GLOBAL") {
        (w, rest) = word_at(rest);
    }
    let named = |rest: &[u8]| {
        let (name, after) = word_at(rest);
        !name.is_empty() && after.starts_with(b"(")
    };
    if is_word(w, "DEF") {
        named(rest)
    } else if is_word(w, "DEFFCT") {
        let (ty, after) = word_at(rest);
        !ty.is_empty() && named(after)
    } else if is_word(w, "DEFDAT") {
        !word_at(rest).0.is_empty()
    } else {
        false
    }
}

/// Types of Siemens 840D variable definitions (`DEF REAL X`).
const SIEMENS_TYPES: [&str; 7] = ["REAL", "INT", "BOOL", "CHAR", "STRING", "AXIS", "FRAME"];

/// Calls of URScript moves, one of which a URScript program's head shows.
const UR_MOVES: [&[u8]; 6] = [
    b"movel(", b"movej(", b"movep(", b"movec(", b"servoj(", b"speedl(",
];

/// The language whose files open with `line` (the first line that is not
/// blank or a `;` comment), `head` being the first bytes of the file:
/// KRL `&ACCESS`, `&REL`, `&PARAM` headers and [`krl_def`] openings; a
/// FANUC `/PROG name`; a Yaskawa `/JOB`; a URScript `def name():` with a
/// move in the head; a VAL3 XML document ([`val3`]); a Siemens `%_N_…`
/// file header, `PROC name` or `DEF type name`; a Heidenhain
/// `0 BEGIN PGM name MM`.
fn opening(line: &[u8], head: &[u8]) -> Option<Unread> {
    if line.first() == Some(&b'&') && line.get(1).is_some_and(u8::is_ascii_alphabetic) {
        return Some(Unread::Krl);
    }
    if krl_def(line) {
        return Some(Unread::Krl);
    }
    let section = |k: &[u8]| {
        line.get(..k.len())
            .is_some_and(|u| u.eq_ignore_ascii_case(k))
            && line.get(k.len()).is_none_or(|b| !b.is_ascii_alphanumeric())
    };
    if section(b"/PROG") {
        return Some(Unread::FanucTp);
    }
    if section(b"/JOB") {
        return Some(Unread::Jbi);
    }
    if line.starts_with(b"<") {
        return val3(head).then_some(Unread::Val3);
    }
    let (w, rest) = word_at(line);
    if w == b"def" {
        let (name, after) = word_at(rest);
        let moves = UR_MOVES
            .iter()
            .any(|m| head.windows(m.len()).any(|x| x == *m));
        if !name.is_empty() && after.starts_with(b"(") && line.ends_with(b":") && moves {
            return Some(Unread::UrScript);
        }
    }
    if line.starts_with(b"%_N_") || (is_word(w, "PROC") && !word_at(rest).0.is_empty()) {
        return Some(Unread::Siemens);
    }
    if is_word(w, "DEF") && SIEMENS_TYPES.iter().any(|t| is_word(word_at(rest).0, t)) {
        return Some(Unread::Siemens);
    }
    // `0 BEGIN PGM PART MM`: a block number, then the program's opening.
    let numbered = !w.is_empty() && w.iter().all(u8::is_ascii_digit);
    let (w, rest) = if numbered { word_at(rest) } else { (w, rest) };
    if is_word(w, "BEGIN") && is_word(word_at(rest).0, "PGM") {
        return Some(Unread::Heidenhain);
    }
    None
}

/// True when `head` is an XML document of Stäubli VAL3: its root element
/// is `Programs`, or a `Database` or `Project` of Stäubli's namespace.
fn val3(head: &[u8]) -> bool {
    const NAMESPACE: &[u8] = b"staubli.com/robotics";
    let mut rest = head;
    // The first element that is not a declaration, instruction or comment.
    while let Some(p) = rest.iter().position(|&b| b == b'<') {
        rest = rest.get(p + 1..).unwrap_or_default();
        if matches!(rest.first(), Some(b'?' | b'!')) {
            continue;
        }
        let (root, _) = word_at(rest);
        let staubli = head
            .windows(NAMESPACE.len())
            .any(|w| w.eq_ignore_ascii_case(NAMESPACE));
        return root == b"Programs" || (staubli && matches!(root, b"Database" | b"Project"));
    }
    false
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

    /// The language `unread_text` names, and the line that told it.
    fn named(ext: Option<&str>, text: &str) -> Option<(Unread, usize)> {
        unread_text(ext, text.as_bytes()).map(|n| (n.language, n.line.map_or(0, |l| l.0)))
    }

    #[test]
    fn unread_languages_are_named_by_their_head() {
        use Unread::*;
        for (ext, text, want) in [
            (
                Some("src"),
                "&ACCESS RVP\r\n&REL 3\r\nDEF PALLET( )\r\n",
                (Krl, 1),
            ),
            (None, "&ACCESS RVP\nDEF PALLET( )\n", (Krl, 1)),
            (
                Some("txt"),
                "\n; cell 4\nDEF MAIN()\n  PTP HOME\nEND\n",
                (Krl, 3),
            ),
            (
                Some("dat"),
                "DEFDAT  PALLET\nDECL E6POS XP1={X 10.0}\nENDDAT\n",
                (Krl, 1),
            ),
            (Some("sub"), "GLOBAL DEF SPS_LOOP ( )\n", (Krl, 1)),
            (Some("src"), "DEFFCT REAL AREA(W:IN, H:IN)\n", (Krl, 1)),
            (Some("mpf"), "DEF MAIN()\nEND\n", (Krl, 1)),
            (Some("ls"), "/PROG  BIN_1_DROP\n/ATTR\n", (FanucTp, 1)),
            (None, "/PROG PICK\t  Macro\n/MN\n", (FanucTp, 1)),
            (Some("jbi"), "/JOB\r\n//NAME WELD01\r\n//POS\r\n", (Jbi, 1)),
            (None, "/JOB\n//NAME WELD01\n", (Jbi, 1)),
            (
                Some("script"),
                "def pick():\n  movel(p[0.4, 0.1, 0.2, 0, 3.14, 0], a=1.2, v=0.25)\nend\n",
                (UrScript, 1),
            ),
            (
                None,
                "def Prog():\n  set_tcp(p[0,0,0.1,0,0,0])\n  movej([0,-1.57,1.57,0,0,0])\nend\n",
                (UrScript, 1),
            ),
            (
                Some("pgx"),
                "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<Programs xmlns=\"http://www.staubli.com/robotics/VAL3/Program/2\">\n",
                (Val3, 1),
            ),
            (
                None,
                "<?xml version=\"1.0\"?>\n<!-- data -->\n<Database xmlns=\"http://www.staubli.com/robotics/VAL3/Data/2\">\n",
                (Val3, 1),
            ),
            (
                Some("mpf"),
                "%_N_POCKET_MPF\n;$PATH=/_N_MPF_DIR\nN10 G17 G90\n",
                (Siemens, 1),
            ),
            (
                Some("spf"),
                "PROC CONTOUR(REAL DEPTH)\nN10 G1 X0\nRET\n",
                (Siemens, 1),
            ),
            (None, "DEF REAL DEPTH=5\nG0 X0\n", (Siemens, 1)),
            (
                Some("mpf"),
                "; roughing\nN10 G90 G54\nN20 G0 X0 Y0\nN30 CYCLE81(10,0,2,-5)\n",
                (Siemens, 4),
            ),
            (None, "N10 G90 G54\nN20 R1=5\n", (Siemens, 2)),
            (
                Some("h"),
                "0 BEGIN PGM PART MM\n1 BLK FORM 0.1 Z X+0 Y+0 Z-20\n",
                (Heidenhain, 1),
            ),
            (None, "BEGIN PGM 12 INCH\n", (Heidenhain, 1)),
        ] {
            assert_eq!(named(ext, text), Some(want), "{ext:?} {text}");
        }
        // By the extension alone: a binary TP, an empty KRL program.
        for (ext, want) in [("tp", FanucTp), ("src", Krl), ("jbi", Jbi), ("pjx", Val3)] {
            assert_eq!(
                named(Some(ext), "\u{1}\u{2}\u{0}"),
                Some((want, 0)),
                "{ext}"
            );
        }
    }

    #[test]
    fn readable_programs_and_other_files_are_not_named() {
        for (ext, text) in [
            (Some("mod"), "&ACCESS RVP\n"),
            (None, "MODULE M\nENDMODULE\n"),
            (Some("nc"), "%\nO1001\nG0 X1\n"),
            (Some("mpf"), "; plain ISO\nN10 G90 G54\nN20 G0 X0 Y0\nM30\n"),
            (Some("nc"), "G0 X0\nN30 CYCLE81(10,0,2,-5)\n"),
            (Some("txt"), "costs $5 and R1=3\n"),
            (Some("py"), "def main():\n    print(1)\n"),
            (Some("xml"), "<?xml version=\"1.0\"?>\n<svg>\n"),
            (Some("h"), "#include <stdio.h>\n"),
            (Some("dat"), "1.0 2.0 3.0\n"),
            (None, ""),
        ] {
            assert_eq!(named(ext, text), None, "{ext:?} {text}");
        }
    }

    #[test]
    fn a_krl_def_is_never_a_siemens_definition() {
        for l in [
            "DEF MAIN()",
            "def main ( )",
            "GLOBAL DEF X(A:IN)",
            "DEFDAT MAIN PUBLIC",
        ] {
            assert!(krl_def(l.as_bytes()), "{l}");
        }
        for l in [
            "DEF REAL X",
            "DEF INT N=3",
            "DEF",
            "DEFINE X AS G1",
            "DEF X",
        ] {
            assert!(!krl_def(l.as_bytes()), "{l}");
        }
    }

    #[test]
    fn the_message_names_the_language_and_the_line() {
        let n = unread_text(Some("dat"), b"&ACCESS RVP\nDEFDAT A\n").unwrap();
        assert_eq!(
            n.error("a.dat").to_string(),
            "a.dat:1:1: KUKA KRL program (`&ACCESS RVP`): postproc reads a KRL program from its .src (with the .dat beside it): give the .src"
        );
        let n = unread_text(Some("tp"), b"").unwrap();
        assert_eq!(
            n.error("p.tp").to_string(),
            "p.tp: FANUC TP program (a .tp file): postproc reads a TP program in its ASCII form, a .ls file (with a robot machine file)"
        );
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
