//! A RAPID module read a window at a time, for modules too large to hold
//! whole (syntax only: where the pieces of the file are, not what they
//! mean).
//!
//! A module of the common shape — header and module-level declarations
//! first, then routines whose bodies hold statements without data
//! declarations of their own — is cut into:
//!
//! * the *prologue*: every byte before the first routine (the `%%%` header,
//!   `MODULE`, the declarations), held for the whole run;
//! * *windows*: runs of whole lines of one routine body, cut only after a
//!   line whose code ends with `;` (a statement ends there), at most about
//!   `max_lines` lines or `max_bytes` bytes each;
//! * *verbatim* text: routine headers and end lines, the blank and comment
//!   lines between routines, `ENDMODULE` and what follows.
//!
//! [`Windows::window_text`] gives each window as a module of its own (the
//! prologue, the routine's header, the window's lines and the end words),
//! for the one module parser to read. The scan is line-based and
//! conservative: anything it does not recognise ends it with
//! [`Unsupported`], and the caller reads the module whole instead (which is
//! also where every syntax error is reported). So does an editor
//! placeholder in a routine (the routine is left as written as a whole,
//! which a window of it cannot tell) and text that is not UTF-8.

use std::io::BufRead;

/// Prologues from this size on make windows [`PROLOGUE_WINDOWS`] times as
/// long as themselves (at least).
pub const BIG_PROLOGUE_BYTES: usize = 64 << 10;

/// How many times its prologue a window is at least, for a big prologue:
/// parsing the prologue again then costs at most an eighth of a window's
/// parse.
pub const PROLOGUE_WINDOWS: usize = 8;

/// Why a module cannot be read a window at a time (the caller then reads
/// it whole).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Unsupported(pub String);

/// One piece of a module read a window at a time, in file order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Piece {
    /// Text written out unchanged (routine header and end lines, the
    /// lines between routines, `ENDMODULE` and after).
    Verbatim {
        /// The text.
        text: String,
        /// 1-based line of its first byte.
        line: usize,
    },
    /// Lines of one routine body, starting and ending at statement
    /// boundaries.
    Window {
        /// The lines, line breaks included.
        body: String,
        /// 1-based line of its first byte.
        line: usize,
        /// The header line of its routine (`PROC main()` and its line
        /// break).
        header: std::rc::Rc<str>,
        /// The routine's end keyword (`ENDPROC`, `ENDFUNC`, `ENDTRAP`).
        end_word: &'static str,
    },
}

/// Where the scan is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between routines (or before the first one, after the prologue).
    Between,
    /// In a routine body.
    Body,
    /// After `ENDMODULE`.
    Tail,
    /// The end of the file was reached.
    Done,
}

/// A module file read a window at a time.
pub struct Windows<R> {
    reader: R,
    prologue: String,
    /// Lines of the prologue.
    prologue_lines: usize,
    /// 1-based number of the next line to read.
    next_line: usize,
    state: State,
    header: std::rc::Rc<str>,
    end_word: &'static str,
    /// A line read but not yet handed out (the first routine line after
    /// the prologue, or a line that ends a body).
    pending: Option<String>,
    max_lines: usize,
    max_bytes: usize,
    /// Routines met so far.
    routines: usize,
    /// Windows handed out of the current routine.
    windows_in_routine: usize,
    /// Bytes below which a window does not end: a large prologue (a module
    /// of declared targets) is parsed again with every window, so windows
    /// are made several times as long as it.
    min_bytes: usize,
}

/// The first word of a line's code (after blanks), if it starts with a
/// letter.
fn first_word(code: &str) -> &str {
    let t = code.trim_start_matches(is_blank);
    let end = t
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(t.len());
    t.get(..end).unwrap_or("")
}

/// The blanks of the module parser: ASCII space, tab and line breaks, and
/// the byte-order mark (other Unicode spaces are not blanks to it).
fn is_blank(c: char) -> bool {
    matches!(c, ' ' | '\t' | '\r' | '\n' | '\u{feff}')
}

/// `code` without the parser's blanks at either end.
fn trim_blanks(code: &str) -> &str {
    code.trim_matches(is_blank)
}

/// Whether a body line's code (trimmed) ends a statement: a `;`, a control
/// keyword that stands alone (`ENDIF`, `ENDWHILE`, …), or the header of an
/// `IF … THEN`, `ELSEIF … THEN`, `FOR … DO`, `WHILE … DO` (the module parser
/// keeps control lines as statements of their own).
fn ends_statement(code: &str) -> bool {
    if code.ends_with(';') {
        return true;
    }
    const ALONE: [&str; 8] = [
        "ELSE", "ENDIF", "ENDFOR", "ENDWHILE", "ENDTEST", "ERROR", "BACKWARD", "UNDO",
    ];
    if ALONE.iter().any(|w| code.eq_ignore_ascii_case(w)) {
        return true;
    }
    let first = first_word(code);
    // An error handler with its list of error numbers.
    if first.eq_ignore_ascii_case("ERROR") && code.ends_with(')') {
        return code
            .get(first.len()..)
            .is_some_and(|r| r.trim_start_matches(is_blank).starts_with('('));
    }
    let last = code
        .rsplit(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .next()
        .unwrap_or("");
    let before_last = code.len() > last.len()
        && code
            .as_bytes()
            .get(code.len() - last.len() - 1)
            .is_some_and(|b| *b == b' ' || *b == b'\t');
    before_last
        && ((["IF", "ELSEIF"]
            .iter()
            .any(|w| first.eq_ignore_ascii_case(w))
            && last.eq_ignore_ascii_case("THEN"))
            || (["FOR", "WHILE"]
                .iter()
                .any(|w| first.eq_ignore_ascii_case(w))
                && last.eq_ignore_ascii_case("DO")))
}

/// The code of a line: the text before a `!` comment outside strings.
fn code_of(line: &str) -> &str {
    match super::comment_start(line) {
        Some(bang) => line.get(..bang).unwrap_or(""),
        None => line,
    }
}

/// The routine keyword of a routine's first line (`[LOCAL] PROC|FUNC|TRAP`)
/// and its end word.
fn routine_start(code: &str) -> Option<&'static str> {
    let mut w = first_word(code);
    if w.eq_ignore_ascii_case("LOCAL") {
        w = first_word(code.trim_start().get(w.len()..).unwrap_or(""));
    }
    match w.to_ascii_uppercase().as_str() {
        "PROC" => Some("ENDPROC"),
        "FUNC" => Some("ENDFUNC"),
        "TRAP" => Some("ENDTRAP"),
        _ => None,
    }
}

/// The names of the module read from `reader`, of the routines it declares
/// (a line whose code opens with `[LOCAL] PROC|FUNC|TRAP`) and of its
/// record types: a scan of lines that parses nothing else, for names a
/// compensation must not give to new data before it has seen the routines
/// of later windows.
pub fn routine_names<R: BufRead>(mut reader: R) -> std::io::Result<Vec<String>> {
    let mut names = Vec::new();
    let mut buf = Vec::new();
    loop {
        buf.clear();
        if reader.read_until(b'\n', &mut buf)? == 0 {
            return Ok(names);
        }
        let line = String::from_utf8_lossy(&buf);
        let code = code_of(&line).trim_start_matches(is_blank);
        let mut words = code
            .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .filter(|w| !w.is_empty());
        let mut w = words.next().unwrap_or("");
        if w.eq_ignore_ascii_case("LOCAL") {
            w = words.next().unwrap_or("");
        }
        let name = match w.to_ascii_uppercase().as_str() {
            "MODULE" | "PROC" | "TRAP" | "RECORD" => words.next(),
            // `FUNC type name`.
            "FUNC" => words.nth(1),
            _ => None,
        };
        if let Some(n) = name {
            names.push(n.to_string());
        }
    }
}

/// Whether a routine's first line (its code, trimmed) is its whole
/// header: `[LOCAL] PROC name(…)`, `[LOCAL] FUNC type name(…)` with
/// nothing after the parameter list, or `[LOCAL] TRAP name` alone (a
/// statement after it would be parsed with every window).
fn whole_header(code: &str, end_word: &str) -> bool {
    if end_word == "ENDTRAP" {
        let words: Vec<&str> = code.split(is_blank).filter(|w| !w.is_empty()).collect();
        let ident = |w: &&str| {
            w.bytes().next().is_some_and(|b| b.is_ascii_alphabetic())
                && w.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
        };
        return match words.as_slice() {
            [t, n] => t.eq_ignore_ascii_case("TRAP") && ident(n),
            [l, t, n] => {
                l.eq_ignore_ascii_case("LOCAL") && t.eq_ignore_ascii_case("TRAP") && ident(n)
            }
            _ => false,
        };
    }
    match (code.find('('), code.find(')')) {
        (Some(open), Some(close)) => open < close && close + 1 == code.len() && !code.contains(';'),
        _ => false,
    }
}

impl<R: BufRead> Windows<R> {
    /// Reads the prologue of the module in `reader`; windows of at most
    /// about `max_lines` lines or `max_bytes` bytes (a window ends at the
    /// first statement boundary after either).
    pub fn new(mut reader: R, max_lines: usize, max_bytes: usize) -> Result<Self, Unsupported> {
        let mut prologue = String::new();
        let mut lines = 0;
        let pending = loop {
            let Some(line) = read_line(&mut reader)? else {
                return Err(Unsupported("no routine in the module".into()));
            };
            let code = code_of(&line);
            if routine_start(code).is_some() {
                break line;
            }
            if first_word(code).eq_ignore_ascii_case("ENDMODULE") {
                return Err(Unsupported("no routine in the module".into()));
            }
            prologue.push_str(&line);
            lines += 1;
        };
        let prologue_len = prologue.len();
        Ok(Windows {
            reader,
            prologue,
            prologue_lines: lines,
            next_line: lines + 1,
            state: State::Between,
            header: std::rc::Rc::from(""),
            end_word: "ENDPROC",
            pending: Some(pending),
            max_lines: max_lines.max(1),
            max_bytes,
            routines: 0,
            windows_in_routine: 0,
            min_bytes: if prologue_len >= BIG_PROLOGUE_BYTES {
                PROLOGUE_WINDOWS * prologue_len
            } else {
                0
            },
        })
    }

    /// The prologue: every byte before the first routine.
    pub fn prologue(&self) -> &str {
        &self.prologue
    }

    /// Lines of the prologue (it ends with a line break).
    pub fn prologue_lines(&self) -> usize {
        self.prologue_lines
    }

    /// Routines met so far (all of them once the scan is done).
    pub fn routines(&self) -> usize {
        self.routines
    }

    /// The module text that gives `body` (a window of the routine with
    /// `header` and `end_word`) to the module parser: prologue, header,
    /// body, end words. The body starts at byte `prologue().len() +
    /// header.len()` and on line `prologue_lines() + 2` of it.
    pub fn window_text(&self, header: &str, body: &str, end_word: &str) -> String {
        let mut t = String::with_capacity(
            self.prologue.len() + header.len() + body.len() + end_word.len() + 12,
        );
        t.push_str(&self.prologue);
        t.push_str(header);
        t.push_str(body);
        t.push_str(end_word);
        t.push_str("\nENDMODULE\n");
        t
    }

    fn take_line(&mut self) -> Result<Option<String>, Unsupported> {
        let line = match self.pending.take() {
            Some(l) => Some(l),
            None => read_line(&mut self.reader)?,
        };
        Ok(line)
    }

    /// The next piece, `None` at the end of the file.
    pub fn next_piece(&mut self) -> Result<Option<Piece>, Unsupported> {
        loop {
            match self.state {
                State::Done => return Ok(None),
                State::Between | State::Tail => {
                    let line_no = self.next_line;
                    let Some(line) = self.take_line()? else {
                        if self.state == State::Between {
                            return Err(Unsupported("end of file before ENDMODULE".into()));
                        }
                        self.state = State::Done;
                        continue;
                    };
                    self.next_line += 1;
                    let code = trim_blanks(code_of(&line));
                    if self.state == State::Tail {
                        if !code.is_empty() {
                            return Err(Unsupported("text after ENDMODULE".into()));
                        }
                    } else if let Some(end_word) = routine_start(code) {
                        if super::find_placeholder(code).is_some() {
                            return Err(Unsupported(format!(
                                "line {line_no}: an editor placeholder in a routine header"
                            )));
                        }
                        if !whole_header(code, end_word) {
                            return Err(Unsupported(format!(
                                "routine header on line {line_no} is not one whole line"
                            )));
                        }
                        self.routines += 1;
                        self.header = std::rc::Rc::from(line.as_str());
                        self.end_word = end_word;
                        self.state = State::Body;
                        self.windows_in_routine = 0;
                    } else if code.eq_ignore_ascii_case("ENDMODULE") {
                        self.state = State::Tail;
                    } else if !code.is_empty() {
                        return Err(Unsupported(format!(
                            "line {line_no}: text between routines (module data after the first routine)"
                        )));
                    }
                    return Ok(Some(Piece::Verbatim {
                        text: line,
                        line: line_no,
                    }));
                }
                State::Body => return self.window().map(Some),
            }
        }
    }

    /// The next window of the current routine body, or its end line.
    /// Lines are read straight into the window's text.
    fn window(&mut self) -> Result<Piece, Unsupported> {
        let first = self.next_line;
        let mut body = String::new();
        let mut lines = 0;
        // True inside a statement (the last code line did not end it).
        let mut open = false;
        loop {
            let line_no = self.next_line;
            let start = body.len();
            match self.pending.take() {
                Some(l) => body.push_str(&l),
                None => {
                    if !read_line_into(&mut self.reader, &mut body)? {
                        return Err(Unsupported("end of file inside a routine".into()));
                    }
                }
            }
            let line = body.get(start..).unwrap_or("");
            let code = trim_blanks(code_of(line));
            let word = first_word(code);
            let at_end = word.eq_ignore_ascii_case(self.end_word);
            if at_end && (open || !code.eq_ignore_ascii_case(self.end_word)) {
                return Err(Unsupported(format!(
                    "line {line_no}: `{code}` does not end the routine alone"
                )));
            }
            if !at_end && BODY_STOP_WORDS.iter().any(|k| word.eq_ignore_ascii_case(k)) {
                return Err(Unsupported(format!(
                    "line {line_no}: `{word}` in a routine body"
                )));
            }
            if super::find_placeholder(code).is_some() {
                // The routine is left as written as a whole.
                return Err(Unsupported(format!(
                    "line {line_no}: an editor placeholder in a routine body"
                )));
            }
            let (blank, ends) = (code.is_empty(), ends_statement(code));
            if at_end {
                let line = body.split_off(start);
                // Every routine gives at least one window, so that its
                // header is parsed.
                if body.is_empty() && self.windows_in_routine > 0 {
                    self.next_line += 1;
                    self.state = State::Between;
                    return Ok(Piece::Verbatim {
                        text: line,
                        line: line_no,
                    });
                }
                self.pending = Some(line);
                break;
            }
            self.next_line += 1;
            lines += 1;
            if !blank {
                open = !ends;
            }
            let long = (lines >= self.max_lines && body.len() >= self.min_bytes)
                || body.len() >= self.max_bytes.max(self.min_bytes);
            if !open && long {
                break;
            }
        }
        self.windows_in_routine += 1;
        Ok(Piece::Window {
            body,
            line: first,
            header: std::rc::Rc::clone(&self.header),
            end_word: self.end_word,
        })
    }
}

/// First words that a routine body of a module read a window at a time
/// may not hold (data declarations, routine and module keywords).
const BODY_STOP_WORDS: [&str; 13] = [
    "CONST",
    "VAR",
    "PERS",
    "LOCAL",
    "TASK",
    "PROC",
    "FUNC",
    "TRAP",
    "ENDPROC",
    "ENDFUNC",
    "ENDTRAP",
    "MODULE",
    "ENDMODULE",
];

/// Appends one line with its line break to `out`; false at the end of the
/// file. Text that is not UTF-8 is left to the whole-module reader (which
/// locates it).
fn read_line_into<R: BufRead>(r: &mut R, out: &mut String) -> Result<bool, Unsupported> {
    let cap = crate::limits::LINE_MAX_BYTES as u64 + 2;
    match std::io::Read::take(&mut *r, cap).read_line(out) {
        Ok(0) => Ok(false),
        Ok(n) if n as u64 == cap && !out.ends_with('\n') => {
            Err(Unsupported("a line longer than the line limit".into()))
        }
        Ok(_) => Ok(true),
        Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
            Err(Unsupported("text that is not UTF-8".into()))
        }
        Err(e) => Err(Unsupported(format!("read error: {e}"))),
    }
}

/// One line with its line break (`None` at the end of the file).
fn read_line<R: BufRead>(r: &mut R) -> Result<Option<String>, Unsupported> {
    let mut line = String::new();
    Ok(read_line_into(r, &mut line)?.then_some(line))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pieces(src: &str, max_lines: usize) -> Result<(String, Vec<Piece>), Unsupported> {
        let mut w = Windows::new(src.as_bytes(), max_lines, usize::MAX)?;
        let mut out = Vec::new();
        while let Some(p) = w.next_piece()? {
            out.push(p);
        }
        Ok((w.prologue().to_string(), out))
    }

    fn join(prologue: &str, pieces: &[Piece]) -> String {
        let mut s = prologue.to_string();
        for p in pieces {
            match p {
                Piece::Verbatim { text, .. } | Piece::Window { body: text, .. } => s.push_str(text),
            }
        }
        s
    }

    const MODULE: &str = "MODULE M\n  CONST robtarget p := [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n  PROC main()\n    MoveL p, v100, z1, tool0;\n    IF TRUE THEN\n      MoveL\n        p, v100, z1, tool0;\n    ENDIF\n    ! a comment; PROC x()\n    TPWrite \"a!b\";\n  ENDPROC\n\n  LOCAL PROC two()\n    MoveJ p, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n";

    #[test]
    fn the_pieces_put_back_together_are_the_file() {
        for max in [1, 2, 3, 100] {
            let (pro, ps) = pieces(MODULE, max).unwrap();
            assert_eq!(join(&pro, &ps), MODULE, "max_lines {max}");
            assert!(pro.ends_with(";\n") && pro.starts_with("MODULE M"));
        }
    }

    #[test]
    fn windows_end_at_statement_boundaries_and_know_their_lines() {
        let (_, ps) = pieces(MODULE, 1).unwrap();
        let windows: Vec<(&str, usize)> = ps
            .iter()
            .filter_map(|p| match p {
                Piece::Window { body, line, .. } => Some((body.as_str(), *line)),
                Piece::Verbatim { .. } => None,
            })
            .collect();
        // A control line is a statement of its own; the two-line move
        // stays whole; the comment line ends no statement but opens none.
        assert_eq!(
            windows,
            vec![
                ("    MoveL p, v100, z1, tool0;\n", 4),
                ("    IF TRUE THEN\n", 5),
                ("      MoveL\n        p, v100, z1, tool0;\n", 6),
                ("    ENDIF\n", 8),
                ("    ! a comment; PROC x()\n", 9),
                ("    TPWrite \"a!b\";\n", 10),
                ("    MoveJ p, v100, fine, tool0;\n", 14),
            ]
        );
    }

    #[test]
    fn a_window_text_is_a_module_the_parser_reads() {
        let mut w = Windows::new(MODULE.as_bytes(), 1, usize::MAX).unwrap();
        let mut moves = 0;
        while let Some(p) = w.next_piece().unwrap() {
            if let Piece::Window {
                body,
                header,
                end_word,
                ..
            } = p
            {
                let text = w.window_text(&header, &body, end_word);
                let m = crate::program::rapid::parse_module(&text, "w.mod").unwrap();
                assert_eq!(m.decls.len(), 1);
                moves += m.moves().count();
            }
        }
        assert_eq!(moves, 3);
        assert_eq!(w.routines(), 2);
    }

    /// A routine without statements still gives a window (its header is
    /// parsed with it), and a control line ends a statement: a main loop
    /// `WHILE … DO … ENDWHILE` before `ENDPROC` is taken.
    #[test]
    fn routine_and_record_names_are_found_by_their_lines() {
        let src = "MODULE M\n  RECORD pt\n    num x;\n  ENDRECORD\n  CONST num n := 1;\n\
                   PROC main()\n    p1_c2;\n  ENDPROC\n  LOCAL FUNC num Twice(num x)\n    RETURN 2*x;\n\
                   ENDFUNC\n  ! PROC commented()\n  TRAP onStop\n  ENDTRAP\nENDMODULE\n";
        let names = routine_names(src.as_bytes()).expect("read");
        assert_eq!(names, ["M", "pt", "main", "Twice", "onStop"]);
    }

    #[test]
    fn empty_routines_and_control_lines_are_taken() {
        let src = "MODULE M\nPROC a()\nENDPROC\nPROC b()\n  WHILE TRUE DO\n    MoveL p, v1, z1, t0;\n  ENDWHILE\nENDPROC\nLOCAL TRAP t\nENDTRAP\nENDMODULE\n";
        let (pro, ps) = pieces(src, 1).unwrap();
        assert_eq!(join(&pro, &ps), src);
        let windows: Vec<&str> = ps
            .iter()
            .filter_map(|p| match p {
                Piece::Window { body, .. } => Some(body.as_str()),
                Piece::Verbatim { .. } => None,
            })
            .collect();
        assert_eq!(
            windows,
            vec![
                "",
                "  WHILE TRUE DO\n",
                "    MoveL p, v1, z1, t0;\n",
                "  ENDWHILE\n",
                ""
            ]
        );
        for (code, ends) in [
            ("ENDIF", true),
            ("endwhile", true),
            ("IF a > 1 THEN", true),
            ("ELSEIF a THEN", true),
            ("FOR i FROM 1 TO 3 DO", true),
            ("WHILE TRUE DO", true),
            ("IF a > 1", false),
            ("MoveL p,", false),
            ("x := THEN", false),
            ("WHILE TRUEDO", false),
            ("ERROR (ERR_SOCK_TIMEOUT, ERR_SOCK_CLOSED)", true),
            ("error(ERR_A)", true),
            ("ERROR (ERR_A,", false),
            ("ERRORS(1)", false),
        ] {
            assert_eq!(ends_statement(code), ends, "{code}");
        }
    }

    #[test]
    fn shapes_it_does_not_take_are_refused() {
        let cases = [
            ("MODULE M\nENDMODULE\n", "no routine"),
            (
                "MODULE M\nPROC a()\nVAR num n := 1;\nENDPROC\nENDMODULE\n",
                "`VAR` in a routine body",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC\nCONST num n := 1;\nENDMODULE\n",
                "text between routines",
            ),
            (
                "MODULE M\nPROC a(\n num x)\nENDPROC\nENDMODULE\n",
                "not one whole line",
            ),
            (
                "MODULE M\nPROC a()\nMoveL p,v1,z1,t;\n",
                "end of file inside",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC\nENDMODULE\nx\n",
                "after ENDMODULE",
            ),
        ];
        // Lines written out unchanged are never parsed: anything but
        // blanks (the parser's: no form feed, no Unicode space) and the bare
        // end words is left to the whole-module parse.
        let more = [
            (
                "MODULE M\nPROC a()\nENDPROC;\nENDMODULE\n",
                "does not end the routine alone",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC x\nENDMODULE\n",
                "does not end the routine alone",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC\nENDMODULE garbage\n",
                "text between routines",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC\n\u{c}\nENDMODULE\n",
                "text between routines",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC\n\u{a0}\nENDMODULE\n",
                "text between routines",
            ),
            (
                "MODULE M\nPROC a()\nENDPROC\nENDMODULE\n\u{3000}\n",
                "after ENDMODULE",
            ),
            (
                "MODULE M\nPROC a()\n\u{a0}ENDPROC\nENDMODULE\n",
                "in a routine body",
            ),
            (
                "MODULE M\nTRAP t MoveL p, v1, z1, t0;\nENDTRAP\nENDMODULE\n",
                "not one whole line",
            ),
            (
                "MODULE M\nPROC a() MoveL p,v1,z1,t;\nENDPROC\nENDMODULE\n",
                "not one whole",
            ),
            (
                "MODULE M\nPROC a()\n  MoveL p,v1,z1,t;\n  <SMT>\nENDPROC\nENDMODULE\n",
                "placeholder in a routine body",
            ),
            (
                "MODULE M\nPROC <ID>()\nENDPROC\nENDMODULE\n",
                "placeholder in a routine header",
            ),
        ];
        for (src, why) in cases.into_iter().chain(more) {
            let got = pieces(src, 10).map(|_| ()).unwrap_err();
            assert!(got.0.contains(why), "{src:?}: {got:?}");
        }
        let bad = b"MODULE M\nPROC a()\n\xff;\nENDPROC\nENDMODULE\n";
        let mut w = Windows::new(&bad[..], 10, usize::MAX).unwrap();
        let mut r = Ok(None);
        for _ in 0..5 {
            r = w.next_piece();
            if r.is_err() {
                break;
            }
        }
        assert!(r.unwrap_err().0.contains("UTF-8"));
    }
}
