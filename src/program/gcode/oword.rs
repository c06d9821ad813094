//! LinuxCNC O-word lines: `o<name> sub`, `o100 repeat [4]`, `o<name> call
//! [1] [2]` — syntax only.
//!
//! An O-word line names a subroutine or a loop (a number, `o100`, or a name
//! in angle brackets, `o<pocket>`), then a keyword, then its arguments
//! (bracketed expressions) and comments. This pass records where each part
//! sits so that the resolution pass ([`super::subprograms`]) can follow the
//! control flow and the emitter can rename a subroutine in place; it
//! evaluates nothing.

use super::{Block, Comment};
use crate::error::Located;

/// What an O-word line does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Keyword {
    /// `sub`: a subroutine definition opens.
    Sub,
    /// `endsub`: it closes.
    Endsub,
    /// `call`: the subroutine runs.
    Call,
    /// `return`: the subroutine ends here.
    Return,
    /// `repeat [n]`: the lines up to `endrepeat` run n times.
    Repeat,
    /// `endrepeat`.
    Endrepeat,
    /// `while [cond]`.
    While,
    /// `endwhile`.
    Endwhile,
    /// `do` (of a `do … while` loop).
    Do,
    /// `if [cond]`.
    If,
    /// `elseif [cond]`.
    Elseif,
    /// `else`.
    Else,
    /// `endif`.
    Endif,
    /// `break`.
    Break,
    /// `continue`.
    Continue,
}

/// The keywords as written (any case), with their meaning.
const KEYWORDS: [(&str, Keyword); 15] = [
    ("sub", Keyword::Sub),
    ("endsub", Keyword::Endsub),
    ("call", Keyword::Call),
    ("return", Keyword::Return),
    ("repeat", Keyword::Repeat),
    ("endrepeat", Keyword::Endrepeat),
    ("while", Keyword::While),
    ("endwhile", Keyword::Endwhile),
    ("do", Keyword::Do),
    ("if", Keyword::If),
    ("elseif", Keyword::Elseif),
    ("else", Keyword::Else),
    ("endif", Keyword::Endif),
    ("break", Keyword::Break),
    ("continue", Keyword::Continue),
];

impl Keyword {
    /// The keyword as LinuxCNC writes it.
    pub fn as_str(self) -> &'static str {
        KEYWORDS
            .iter()
            .find(|(_, k)| *k == self)
            .map_or("", |(s, _)| s)
    }
}

/// The parts of an O-word line, as byte ranges of the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OWord {
    /// What the line does.
    pub keyword: Keyword,
    /// The name as written: the digits of `o100`, or `<pocket>` with its
    /// brackets.
    pub name: (u32, u32),
    /// The arguments after the keyword (bracketed expressions), up to the
    /// first comment; empty when there are none.
    pub args: (u32, u32),
}

impl OWord {
    /// The name's text within `line`.
    pub fn name_text<'a>(&self, line: &'a [u8]) -> &'a [u8] {
        line.get(self.name.0 as usize..self.name.1 as usize)
            .unwrap_or(b"")
    }

    /// The arguments' text within `line`, spaces trimmed.
    pub fn args_text<'a>(&self, line: &'a [u8]) -> &'a [u8] {
        line.get(self.args.0 as usize..self.args.1 as usize)
            .unwrap_or(b"")
            .trim_ascii()
    }

    /// The name compared as LinuxCNC compares it (case folded).
    pub fn key(&self, line: &[u8]) -> String {
        String::from_utf8_lossy(self.name_text(line)).to_ascii_lowercase()
    }
}

fn show(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(bytes);
    let s: String = s.chars().take(40).collect();
    s.trim_end().to_string()
}

/// Reads the O-word line whose `o` is at `pos` of `text` into `out`:
/// `Ok(true)` when the line is one, `Ok(false)` when it is an ordinary
/// line (`O1000` program number); an error for an O-word line that does
/// not hold together (`o<name>` with no keyword, an unclosed `<` or `[`).
pub(crate) fn scan(
    text: &[u8],
    pos: usize,
    file: &str,
    line_no: usize,
    out: &mut Block,
) -> Result<bool, Located> {
    let err = |at: usize, msg: String| Located::new(file, line_no, at + 1, msg);
    if !text.get(pos).is_some_and(|c| c.eq_ignore_ascii_case(&b'o')) {
        return Ok(false);
    }
    let name_start = pos + 1;
    let name_end = match text.get(name_start) {
        Some(b'<') => match text[name_start..].iter().position(|&c| c == b'>') {
            Some(off) => name_start + off + 1,
            None => {
                return Err(err(
                    pos,
                    format!("O-word name without its closing `>`: `{}`", show(text)),
                ));
            }
        },
        Some(c) if c.is_ascii_digit() => {
            name_start
                + text[name_start..]
                    .iter()
                    .take_while(|c| c.is_ascii_digit())
                    .count()
        }
        _ => return Ok(false),
    };
    let kw_start = skip_ws(text, name_end);
    let kw_len = text[kw_start..]
        .iter()
        .take_while(|c| c.is_ascii_alphabetic())
        .count();
    let kw = &text[kw_start..kw_start + kw_len];
    let keyword = KEYWORDS
        .iter()
        .find(|(k, _)| kw.eq_ignore_ascii_case(k.as_bytes()))
        .map(|(_, k)| *k);
    let named = text[name_start] == b'<';
    let Some(keyword) = keyword else {
        if named {
            return Err(err(
                pos,
                format!(
                    "O-word `{}` without a keyword (sub, endsub, call, repeat, …): `{}`",
                    show(&text[pos..name_end]),
                    show(text)
                ),
            ));
        }
        // `O1000`, `O1000 (NAME)`: a program number.
        return Ok(false);
    };
    let args_start = kw_start + kw_len;
    let args_end = args_and_comments(text, args_start, out)
        .map_err(|at| err(at, format!("unclosed `[` or `(`: `{}`", show(text))))?;
    out.oword = Some(OWord {
        keyword,
        name: (name_start as u32, name_end as u32),
        args: (args_start as u32, args_end as u32),
    });
    Ok(true)
}

/// Scans the arguments from `pos` to the end of `text`: bracketed groups,
/// then comments (recorded in `out`). The end of the arguments, or the
/// position of a bracket or parenthesis that does not close.
fn args_and_comments(text: &[u8], pos: usize, out: &mut Block) -> Result<usize, usize> {
    let mut depth = 0usize;
    let mut open = pos;
    let mut i = pos;
    let mut args_end = text.len();
    while i < text.len() {
        match text[i] {
            b'[' => {
                if depth == 0 {
                    open = i;
                }
                depth += 1;
            }
            b']' if depth > 0 => depth -= 1,
            b'(' if depth == 0 => {
                let close = super::comment_close(text, i).ok_or(i)? - i;
                args_end = args_end.min(i);
                out.comments.push(Comment {
                    start: i as u32,
                    end: (i + close + 1) as u32,
                    semicolon: false,
                });
                i += close;
            }
            b';' if depth == 0 => {
                args_end = args_end.min(i);
                out.comments.push(Comment {
                    start: i as u32,
                    end: text.len() as u32,
                    semicolon: true,
                });
                break;
            }
            _ => {}
        }
        i += 1;
    }
    if depth > 0 {
        return Err(open);
    }
    Ok(args_end)
}

fn skip_ws(text: &[u8], mut pos: usize) -> usize {
    while matches!(text.get(pos), Some(b' ' | b'\t')) {
        pos += 1;
    }
    pos
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scan_str(s: &str) -> Result<Option<OWord>, Located> {
        let mut b = Block::default();
        scan(s.as_bytes(), 0, "t.ngc", 1, &mut b).map(|hit| hit.then(|| b.oword.unwrap()))
    }

    #[test]
    fn names_keywords_and_arguments() {
        let line = "o<Pocket> call [10] [2.5] (corner)";
        let o = scan_str(line).unwrap().unwrap();
        assert_eq!(o.keyword, Keyword::Call);
        assert_eq!(o.name_text(line.as_bytes()), b"<Pocket>");
        assert_eq!(o.key(line.as_bytes()), "<pocket>");
        assert_eq!(o.args_text(line.as_bytes()), b"[10] [2.5]");
        let o = scan_str("O100 REPEAT [4]").unwrap().unwrap();
        assert_eq!(o.keyword, Keyword::Repeat);
        assert_eq!(o.name_text(b"O100 REPEAT [4]"), b"100");
        assert_eq!(scan_str("O1000 (PLATE)").unwrap(), None);
        assert_eq!(scan_str("G1 X1").unwrap(), None);
    }

    #[test]
    fn broken_lines_are_named() {
        let e = scan_str("o<pocket>").unwrap_err();
        assert!(e.message.contains("without a keyword"), "{}", e.message);
        assert!(
            scan_str("o<pocket sub")
                .unwrap_err()
                .message
                .contains("closing `>`")
        );
        assert!(
            scan_str("o100 repeat [4")
                .unwrap_err()
                .message
                .contains("unclosed")
        );
    }
}
