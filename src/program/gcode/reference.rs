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

/// The file and line of the text being parsed, for located errors.
#[derive(Clone, Copy)]
struct Place<'a> {
    file: &'a str,
    line_no: usize,
}

impl Place<'_> {
    fn err(self, pos: usize, msg: String) -> Located {
        Located::new(self.file, self.line_no, pos + 1, msg)
    }
}

/// Keywords after a leading O word that open subroutines and loops.
const O_CONTROL: [&str; 15] = [
    "sub",
    "endsub",
    "call",
    "while",
    "endwhile",
    "do",
    "if",
    "else",
    "elseif",
    "endif",
    "repeat",
    "endrepeat",
    "return",
    "break",
    "continue",
];

fn scan_line(line: &[u8], line_no: usize, file: &str, out: &mut Block) -> Result<(), Located> {
    out.clear();
    out.line_no = line_no;
    let text = strip_eol(line);
    out.text_len = text.len() as u32;
    let place = Place { file, line_no };
    // A CR is only ever the first byte of a CR LF line end.
    let lone = line
        .windows(2)
        .position(|w| w[0] == b'\r' && w[1] != b'\n')
        .or_else(|| (line.last() == Some(&b'\r')).then(|| line.len() - 1));
    if let Some(p) = lone {
        return Err(place.err(
            p,
            "carriage return (CR) without a line feed: lines end in LF or CR LF (a file with CR-only line ends must be converted)".into(),
        ));
    }

    let bom: &[u8] = b"\xEF\xBB\xBF";
    let start = if line_no == 1 && text.starts_with(bom) {
        bom.len()
    } else {
        0
    };
    let mut pos = skip_ws(text, start);
    if text.get(pos) == Some(&b'%') {
        out.percent = true;
        // Anything after `%` on the same line is ignored by controllers; keep it verbatim.
        return Ok(());
    }
    if text.get(pos) == Some(&b'/') {
        out.block_delete = true;
        let level = text.get(pos + 1).is_some_and(|c| matches!(c, b'1'..=b'9'));
        pos = skip_ws(text, pos + 1 + usize::from(level));
    }
    if super::oword::scan(text, pos, file, line_no, out)? {
        return Ok(());
    }
    let mut saw_space = false;
    let mut lower = 0usize;
    let mut upper = 0usize;
    while pos < text.len() {
        let b = text[pos];
        if b == b' ' || b == b'\t' {
            saw_space = true;
            pos += 1;
        } else if b == b'(' || b == b';' {
            pos = comment(text, pos, out, place)?;
        } else if b.is_ascii_alphabetic()
            || (b == b':' && out.words.is_empty() && out.comments.is_empty())
        {
            if b.is_ascii_lowercase() {
                lower += 1;
            } else {
                upper += 1;
            }
            pos = word(text, pos, out, place)?;
        } else if b == b',' && corner(text, pos).is_some() {
            pos = corner_word(text, pos, out, place)?;
        } else {
            return Err(not_a_word(text, pos, place));
        }
    }
    out.lower_case = lower > upper;
    out.spaced = saw_space && out.words.len() > 1;
    Ok(())
}

/// The comment opening at `pos` (`(` to `)`, or `;` to the end of the
/// line), recorded in `out`; the position after it.
fn comment(text: &[u8], pos: usize, out: &mut Block, place: Place) -> Result<usize, Located> {
    let (end, semicolon) = if text[pos] == b';' {
        (text.len(), true)
    } else {
        match closing(&text[pos..]) {
            Some(off) => (pos + off + 1, false),
            None => {
                return Err(place.err(
                    pos,
                    format!(
                        "unterminated comment, no `)` before the end of the line: `{}`",
                        show(&text[pos..])
                    ),
                ));
            }
        }
    };
    out.comments.push(Comment {
        start: pos as u32,
        end: end as u32,
        semicolon,
    });
    Ok(end)
}

/// The offset in `from` (which opens with `(`) of the `)` that ends the
/// comment: where the parentheses balance, else the last `)`; the first
/// `)` when no `(` comes before it.
fn closing(from: &[u8]) -> Option<usize> {
    let closes: Vec<usize> = (0..from.len()).filter(|&i| from[i] == b')').collect();
    let first = *closes.first()?;
    if from[1..first].iter().all(|&c| c != b'(') {
        return Some(first);
    }
    let balanced = closes.iter().copied().find(|&c| {
        let opens = from[..=c].iter().filter(|&&b| b == b'(').count();
        let shut = from[..=c].iter().filter(|&&b| b == b')').count();
        opens == shut
    });
    balanced.or(closes.last().copied())
}

/// The word whose letter is at `pos`, pushed to `out`; the position after
/// its number.
fn word(text: &[u8], pos: usize, out: &mut Block, place: Place) -> Result<usize, Located> {
    let b = text[pos];
    // `:` opens the ISO program number, `O`'s other spelling.
    let letter = if b == b':' {
        b'O'
    } else {
        b.to_ascii_uppercase()
    };
    let after_letter = skip_ws(text, pos + 1);
    if !LETTERS.contains(&letter) {
        return Err(place.err(
            pos,
            format!(
                "unknown word letter `{}`: `{}`",
                b as char,
                show(&text[pos..])
            ),
        ));
    }
    let rest = &text[after_letter..];
    let Ok((_, num)) = number(rest) else {
        return Err(letter_alone(text, pos, after_letter, place));
    };
    let num_start = after_letter;
    let num_end = after_letter + num.len();
    let num_str = std::str::from_utf8(num).unwrap_or("");
    let value: f64 = num_str.parse().map_err(|_| {
        place.err(
            num_start,
            format!("malformed number `{}`", crate::error::clip(num_str)),
        )
    })?;
    if !value.is_finite() || value.abs() > 1e9 {
        return Err(place.err(
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
        if next == b'.' || next.is_ascii_digit() || next == b'-' || next == b'+' {
            return Err(place.err(
                num_end,
                format!("two numbers in one word: `{}`", show(&text[pos..])),
            ));
        }
    }
    if letter == b'O' && out.words.is_empty() {
        // `O100 sub`, `o100 while …`: subroutines and loops.
        let tail = skip_ws(text, num_end);
        let kw: String = text[tail..]
            .iter()
            .take_while(|c| c.is_ascii_alphabetic())
            .map(|&c| char::from(c.to_ascii_lowercase()))
            .collect();
        if O_CONTROL.contains(&kw.as_str()) {
            return Err(place.err(
                pos,
                format!(
                    "O-word subroutines and loops cannot be compensated offline: `{}`",
                    show(text)
                ),
            ));
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
    Ok(num_end)
}

/// The letter of the corner word whose comma is at `pos` (`,C2.`, `,R5.`)
/// and the offset of its number, when one is written there.
fn corner(text: &[u8], pos: usize) -> Option<(u8, usize, &[u8])> {
    let letter = match text.get(pos + 1)?.to_ascii_uppercase() {
        b'C' => super::CHAMFER,
        b'R' => super::CORNER_RADIUS,
        _ => return None,
    };
    let at = skip_ws(text, pos + 2);
    let (_, num) = number(text.get(at..)?).ok()?;
    Some((letter, at, num))
}

/// The corner word at `pos`, pushed to `out`; the position after it.
fn corner_word(text: &[u8], pos: usize, out: &mut Block, place: Place) -> Result<usize, Located> {
    let Some((letter, num_start, num)) = corner(text, pos) else {
        return Err(not_a_word(text, pos, place));
    };
    let num_end = num_start + num.len();
    let num_str = std::str::from_utf8(num).unwrap_or("");
    let value: f64 = num_str.parse().map_err(|_| {
        place.err(
            num_start,
            format!("malformed number `{}`", crate::error::clip(num_str)),
        )
    })?;
    if !value.is_finite() || value.abs() > 1e9 {
        return Err(place.err(
            num_start,
            format!("absurd number `{}`", crate::error::clip(num_str)),
        ));
    }
    if let Some(&next) = text.get(num_end) {
        if next == b'.' || next.is_ascii_digit() || next == b'-' || next == b'+' {
            return Err(place.err(
                num_end,
                format!("two numbers in one word: `{}`", show(&text[pos..])),
            ));
        }
    }
    out.words.push(Word {
        letter,
        value,
        start: pos as u32,
        num_start: num_start as u32,
        end: num_end as u32,
        decimals: num
            .iter()
            .position(|&c| c == b'.')
            .map(|d| (num.len() - d - 1).min(255) as u8),
    });
    Ok(num_end)
}

/// The error for the letter at `pos` with no number at `after_letter`.
fn letter_alone(text: &[u8], pos: usize, after_letter: usize, place: Place) -> Located {
    let b = text[pos];
    let from = &text[pos..];
    match text.get(after_letter) {
        Some(b'#') => place.err(after_letter, parameters(from)),
        Some(b'[') => place.err(after_letter, expressions(from)),
        // `X=10.`, `R1=5` (Siemens-style assignments).
        Some(b'=') => place.err(after_letter, assignments(from)),
        None => place.err(
            pos,
            format!(
                "truncated word: letter `{}` with no number at the end of the line",
                b as char
            ),
        ),
        Some(_) => place.err(
            pos,
            format!("letter `{}` without a number: `{}`", b as char, show(from)),
        ),
    }
}

/// The error for the byte at `pos`: neither space, comment nor letter.
fn not_a_word(text: &[u8], pos: usize, place: Place) -> Located {
    let b = text[pos];
    let from = &text[pos..];
    let msg = match b {
        b'#' => parameters(from),
        b'[' | b']' => expressions(from),
        b'=' => assignments(from),
        b',' if from.len() > 1 && from[1].eq_ignore_ascii_case(&b'C') => format!(
            "a chamfer word `,C` is not read: the control inserts the chamfer between this move and the next; write the corner as moves: `{}`",
            show(from)
        ),
        b',' if from.len() > 1 && from[1].eq_ignore_ascii_case(&b'R') => format!(
            "a corner-radius word `,R` is not read: the control inserts the rounding between this move and the next; write the corner as an arc: `{}`",
            show(from)
        ),
        _ if b.is_ascii_digit() || b == b'.' || b == b'-' || b == b'+' => {
            format!("number without a letter: `{}`", show(from))
        }
        _ if b.is_ascii_graphic() => {
            format!("unexpected character `{}` outside a comment", b as char)
        }
        _ => format!("unexpected character byte 0x{b:02X} outside a comment"),
    };
    place.err(pos, msg)
}

fn parameters(from: &[u8]) -> String {
    format!(
        "`#` parameters cannot be compensated offline (expand them in CAM): `{}`",
        show(from)
    )
}

fn expressions(from: &[u8]) -> String {
    format!(
        "`[ ]` expressions cannot be compensated offline (expand them in CAM): `{}`",
        show(from)
    )
}

fn assignments(from: &[u8]) -> String {
    format!(
        "assignments cannot be compensated offline: `{}`",
        show(from)
    )
}

fn skip_ws(text: &[u8], mut pos: usize) -> usize {
    while let Ok((rest, _)) = spaces(&text[pos.min(text.len())..]) {
        pos = text.len() - rest.len();
    }
    pos
}
