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
//! also where every syntax error is reported).

use std::io::BufRead;

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
}

/// The first word of a line's code (after blanks), if it starts with a
/// letter.
fn first_word(code: &str) -> &str {
    let t = code.trim_start();
    let end = t
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
        .unwrap_or(t.len());
    t.get(..end).unwrap_or("")
}

/// The code of a line: the text before a `!` comment outside strings.
fn code_of(line: &str) -> &str {
    let mut in_string = false;
    for (i, b) in line.bytes().enumerate() {
        match b {
            b'"' => in_string = !in_string,
            b'!' if !in_string => return line.get(..i).unwrap_or(""),
            _ => {}
        }
    }
    line
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
                    let code = code_of(&line);
                    if self.state == State::Tail {
                        if !code.trim().is_empty() {
                            return Err(Unsupported("text after ENDMODULE".into()));
                        }
                    } else if let Some(end_word) = routine_start(code) {
                        // A header on one line, its parameter list closed, nothing
                        // after it.
                        let after = code.find('(').map(|p| code.get(p..).unwrap_or(""));
                        let closed = match after {
                            Some(a) => a.find(')').is_some_and(|q| {
                                a.get(q + 1..).is_some_and(|r| r.trim().is_empty())
                            }),
                            None => end_word == "ENDTRAP",
                        };
                        if !closed {
                            return Err(Unsupported(format!(
                                "routine header on line {line_no} is not one whole line"
                            )));
                        }
                        self.routines += 1;
                        self.header = std::rc::Rc::from(line.as_str());
                        self.end_word = end_word;
                        self.state = State::Body;
                    } else if first_word(code).eq_ignore_ascii_case("ENDMODULE") {
                        self.state = State::Tail;
                    } else if !code.trim().is_empty() {
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
            let code = code_of(line);
            let word = first_word(code);
            let ends_body = !open && word.eq_ignore_ascii_case(self.end_word);
            if !ends_body && BODY_STOP_WORDS.iter().any(|k| word.eq_ignore_ascii_case(k)) {
                return Err(Unsupported(format!(
                    "line {line_no}: `{word}` in a routine body"
                )));
            }
            let code = code.trim_end();
            let (blank, ends_statement) = (code.is_empty(), code.ends_with(';'));
            if ends_body {
                let line = body.split_off(start);
                if body.is_empty() {
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
                open = !ends_statement;
            }
            if !open && (lines >= self.max_lines || body.len() >= self.max_bytes) {
                break;
            }
        }
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
    match r.read_line(out) {
        Ok(0) => Ok(false),
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
        // The IF line and the two-line move stay with the statement that
        // ends them; the comment line ends no statement but opens none.
        assert_eq!(
            windows,
            vec![
                ("    MoveL p, v100, z1, tool0;\n", 4),
                (
                    "    IF TRUE THEN\n      MoveL\n        p, v100, z1, tool0;\n",
                    5
                ),
                (
                    "    ENDIF\n    ! a comment; PROC x()\n    TPWrite \"a!b\";\n",
                    8
                ),
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
        for (src, why) in cases {
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
