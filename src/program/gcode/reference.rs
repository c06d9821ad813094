//! A second, independent G-code line parser written for clarity rather than
//! speed (nom grammar for numbers and spaces, `str::parse` for values): the
//! reference the property tests compare the hand-written scanner
//! [`super::parse_line`] with.

use nom::IResult;
use nom::branch::alt;
use nom::bytes::complete::take_while1;
use nom::character::complete::{char, digit0, digit1, one_of};
use nom::combinator::{opt, recognize};
use nom::sequence::{pair, tuple};

use super::{Block, Comment, LETTERS, Word, strip_eol};
use crate::error::Located;

fn number(input: &[u8]) -> IResult<&[u8], &[u8]> {
    recognize(tuple((
        opt(one_of("+-")),
        alt((
            recognize(pair(digit1, opt(pair(char('.'), digit0)))),
            recognize(pair(char('.'), digit1)),
        )),
    )))(input)
}

fn spaces(input: &[u8]) -> IResult<&[u8], &[u8]> {
    take_while1(|b| b == b' ' || b == b'\t')(input)
}

fn show(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(bytes);
    let s: String = s.chars().take(40).collect();
    s.trim_end().to_string()
}

/// The reference parser.
///
/// Errors are located at `file:line:column` and quote the offending text.
pub fn parse_line(line: &[u8], line_no: usize, file: &str, out: &mut Block) -> Result<(), Located> {
    scan_line(line, line_no, file, out).map_err(|e| super::dialect::refine(line, e))
}

fn scan_line(line: &[u8], line_no: usize, file: &str, out: &mut Block) -> Result<(), Located> {
    out.clear();
    out.line_no = line_no;
    let text = strip_eol(line);
    out.text_len = text.len() as u32;
    let err = |pos: usize, msg: String| Located::new(file, line_no, pos + 1, msg);

    let mut pos = skip_ws(text, 0);
    if text.get(pos) == Some(&b'%') {
        out.percent = true;
        // Anything after `%` on the same line is ignored by controllers; keep it verbatim.
        return Ok(());
    }
    if text.get(pos) == Some(&b'/') {
        out.block_delete = true;
        pos = skip_ws(text, pos + 1);
    }
    let mut saw_space = false;
    let mut lower = 0usize;
    let mut upper = 0usize;
    while pos < text.len() {
        let b = text[pos];
        match b {
            b' ' | b'\t' => {
                saw_space = true;
                pos += 1;
            }
            b'(' => {
                let close = text[pos..].iter().position(|&c| c == b')');
                match close {
                    Some(off) => {
                        out.comments.push(Comment {
                            start: pos as u32,
                            end: (pos + off + 1) as u32,
                            semicolon: false,
                        });
                        pos += off + 1;
                    }
                    None => {
                        return Err(err(
                            pos,
                            format!(
                                "unterminated comment, no `)` before the end of the line: `{}`",
                                show(&text[pos..])
                            ),
                        ));
                    }
                }
            }
            b';' => {
                out.comments.push(Comment {
                    start: pos as u32,
                    end: text.len() as u32,
                    semicolon: true,
                });
                pos = text.len();
            }
            b'#' => {
                return Err(err(
                    pos,
                    format!(
                        "`#` parameters cannot be compensated offline (expand them in CAM): `{}`",
                        show(&text[pos..])
                    ),
                ));
            }
            b'[' | b']' => {
                return Err(err(
                    pos,
                    format!(
                        "`[ ]` expressions cannot be compensated offline (expand them in CAM): `{}`",
                        show(&text[pos..])
                    ),
                ));
            }
            b'=' => {
                return Err(err(
                    pos,
                    format!(
                        "assignments cannot be compensated offline: `{}`",
                        show(&text[pos..])
                    ),
                ));
            }
            _ if b.is_ascii_alphabetic() => {
                let letter = b.to_ascii_uppercase();
                if b.is_ascii_lowercase() {
                    lower += 1;
                } else {
                    upper += 1;
                }
                let after_letter = skip_ws(text, pos + 1);
                if !LETTERS.contains(&letter) {
                    return Err(err(
                        pos,
                        format!(
                            "unknown word letter `{}`: `{}`",
                            b as char,
                            show(&text[pos..])
                        ),
                    ));
                }
                let rest = &text[after_letter..];
                match number(rest) {
                    Ok((_, num)) => {
                        let num_start = after_letter;
                        let num_end = after_letter + num.len();
                        let num_str = std::str::from_utf8(num).unwrap_or("");
                        let value: f64 = match num_str.parse() {
                            Ok(v) => v,
                            Err(_) => {
                                return Err(err(
                                    num_start,
                                    format!("malformed number `{}`", crate::error::clip(num_str)),
                                ));
                            }
                        };
                        if !value.is_finite() || value.abs() > 1e9 {
                            return Err(err(
                                num_start,
                                format!("absurd number `{}`", crate::error::clip(num_str)),
                            ));
                        }
                        let decimals = num
                            .iter()
                            .position(|&c| c == b'.')
                            .map(|d| (num.len() - d - 1).min(255) as u8);
                        // A second number glued to this one (`X1.2.3`, `X1-2`).
                        if let Some(&next) = text.get(num_end) {
                            if next == b'.' || next.is_ascii_digit() || next == b'-' || next == b'+'
                            {
                                return Err(err(
                                    num_end,
                                    format!("two numbers in one word: `{}`", show(&text[pos..])),
                                ));
                            }
                        }
                        if letter == b'O' && out.words.is_empty() {
                            // `O100 sub`, `o100 while …`: subroutines and loops.
                            let tail = skip_ws(text, num_end);
                            if text.get(tail).is_some_and(|c| c.is_ascii_alphabetic()) {
                                let kw: Vec<u8> = text[tail..]
                                    .iter()
                                    .take_while(|c| c.is_ascii_alphabetic())
                                    .copied()
                                    .collect();
                                let kw = String::from_utf8_lossy(&kw).to_ascii_lowercase();
                                if matches!(
                                    kw.as_str(),
                                    "sub"
                                        | "endsub"
                                        | "call"
                                        | "while"
                                        | "endwhile"
                                        | "do"
                                        | "if"
                                        | "else"
                                        | "elseif"
                                        | "endif"
                                        | "repeat"
                                        | "endrepeat"
                                        | "return"
                                        | "break"
                                        | "continue"
                                ) {
                                    return Err(err(
                                        pos,
                                        format!(
                                            "O-word subroutines and loops cannot be compensated offline: `{}`",
                                            show(text)
                                        ),
                                    ));
                                }
                            }
                        }
                        out.words.push(Word {
                            letter,
                            value,
                            start: pos as u32,
                            num_start: num_start as u32,
                            end: num_end as u32,
                            decimals,
                        });
                        pos = num_end;
                    }
                    Err(_) => {
                        match rest.first() {
                            Some(b'#') => {
                                return Err(err(
                                    after_letter,
                                    format!(
                                        "`#` parameters cannot be compensated offline (expand them in CAM): `{}`",
                                        show(&text[pos..])
                                    ),
                                ));
                            }
                            Some(b'[') => {
                                return Err(err(
                                    after_letter,
                                    format!(
                                        "`[ ]` expressions cannot be compensated offline (expand them in CAM): `{}`",
                                        show(&text[pos..])
                                    ),
                                ));
                            }
                            Some(b'=') => {
                                // `X=10.`, `R1=5` (Siemens-style assignments).
                                return Err(err(
                                    after_letter,
                                    format!(
                                        "assignments cannot be compensated offline: `{}`",
                                        show(&text[pos..])
                                    ),
                                ));
                            }
                            _ => {}
                        }
                        if after_letter >= text.len() {
                            return Err(err(
                                pos,
                                format!(
                                    "truncated word: letter `{}` with no number at the end of the line",
                                    b as char
                                ),
                            ));
                        }
                        return Err(err(
                            pos,
                            format!(
                                "letter `{}` without a number: `{}`",
                                b as char,
                                show(&text[pos..])
                            ),
                        ));
                    }
                }
            }
            _ if b.is_ascii_digit() || b == b'.' || b == b'-' || b == b'+' => {
                return Err(err(
                    pos,
                    format!("number without a letter: `{}`", show(&text[pos..])),
                ));
            }
            _ => {
                let shown = if b.is_ascii_graphic() {
                    format!("`{}`", b as char)
                } else {
                    format!("byte 0x{b:02X}")
                };
                return Err(err(
                    pos,
                    format!("unexpected character {shown} outside a comment"),
                ));
            }
        }
    }
    out.lower_case = lower > upper;
    out.spaced = saw_space && out.words.len() > 1;
    Ok(())
}

fn skip_ws(text: &[u8], mut pos: usize) -> usize {
    while let Ok((rest, _)) = spaces(&text[pos.min(text.len())..]) {
        pos = text.len() - rest.len();
    }
    pos
}
