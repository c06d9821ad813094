//! G-code syntax: one line (block) at a time into words with byte spans.
//!
//! This pass knows nothing of modal state: it splits a line into an optional
//! block-delete slash, words (a letter and a number, spaces allowed between
//! them), comments in parentheses or after `;`, and the `%` tape marks. Every
//! word keeps the byte range of its text and the number of decimals it was
//! written with, so the emitter can rewrite a coordinate at the program's own
//! precision and leave every other byte alone. Numbers are parsed to `f64`
//! from their original text. The accepted dialect is documented in
//! `grammar/gcode.md`.

use crate::error::Located;

/// One word: a letter and its number, e.g. `X-12.5`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Word {
    /// Upper-case letter; [`CHAMFER`] or [`CORNER_RADIUS`] for the corner
    /// words `,C` and `,R` (`start` is then the comma's offset).
    pub letter: u8,
    /// The value parsed from the original text.
    pub value: f64,
    /// Byte offset of the letter within the line.
    pub start: u32,
    /// Byte offset of the first byte of the number (sign included).
    pub num_start: u32,
    /// Byte offset one past the last byte of the number.
    pub end: u32,
    /// Digits written after the decimal point; `None` when there is no point.
    pub decimals: Option<u8>,
}

impl Word {
    /// The number's original text within `line`.
    pub fn number_text<'a>(&self, line: &'a [u8]) -> &'a [u8] {
        line.get(self.num_start as usize..self.end as usize)
            .unwrap_or(b"")
    }

    /// G and M codes compare as integers times ten (`G90.1` → 901), so
    /// decimal sub-codes are exact; a number that is not a whole number or
    /// a whole number and one decimal digit as written (`G2.95`, `G-1`)
    /// gives −1, which is no code.
    pub fn code10(&self) -> i64 {
        self.exact_code10().unwrap_or(-1)
    }

    /// The code times ten when the number is a code as written: a whole
    /// number ≥ 0, or one with one decimal digit (`G54.1`); further decimal
    /// digits must be zeros (`G1.0` = `G1`, `G54.10` = `G54.1`). `None`
    /// for anything else (`G2.95`, `G0.96`, `G-1`).
    pub fn exact_code10(&self) -> Option<i64> {
        let d = i32::from(self.decimals.unwrap_or(0));
        if self.value.is_sign_negative() || !self.value.is_finite() || d > MAX_CODE_DECIMALS {
            return None;
        }
        // Exact: the value has at most `d` decimals and is at most 1e9.
        let m = (self.value * 10f64.powi(d)).round() as i64;
        match d {
            0 => Some(m * 10),
            _ => {
                let unit = 10i64.pow(d as u32 - 1);
                (m % unit == 0).then_some(m / unit)
            }
        }
    }

    /// The number as a whole number ≥ 0 (`H1`, `T12`, `D1.`), or `None`
    /// (`H1.96`, `H-1`).
    pub fn whole(&self) -> Option<u32> {
        (self.value >= 0.0 && self.value.fract() == 0.0 && self.value <= f64::from(u32::MAX))
            .then_some(self.value as u32)
    }
}

/// Where a comment sits in the line and how it is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Comment {
    /// Byte offset of `(` or `;`.
    pub start: u32,
    /// Byte offset one past the comment (after `)`, or the end of the text).
    pub end: u32,
    /// True for `;` comments, false for `( )`.
    pub semicolon: bool,
}

/// The syntax of one line. Reused between lines to avoid allocation.
#[derive(Debug, Default, Clone)]
pub struct Block {
    /// 1-based line number.
    pub line_no: usize,
    /// Words in order of appearance.
    pub words: Vec<Word>,
    /// Comments in order of appearance.
    pub comments: Vec<Comment>,
    /// The line starts with the block-delete slash `/`.
    pub block_delete: bool,
    /// The line is a `%` tape mark.
    pub percent: bool,
    /// Length of the line's text without its end-of-line bytes.
    pub text_len: u32,
    /// Letters were written in lower case.
    pub lower_case: bool,
    /// Words are separated by spaces.
    pub spaced: bool,
    /// The line is a LinuxCNC O-word line (`o<name> sub`, `o100 repeat
    /// [4]`): its parts; it has no words then.
    pub oword: Option<oword::OWord>,
}

impl Block {
    /// Clears the block for reuse.
    pub fn clear(&mut self) {
        self.line_no = 0;
        self.words.clear();
        self.comments.clear();
        self.block_delete = false;
        self.percent = false;
        self.text_len = 0;
        self.lower_case = false;
        self.spaced = false;
        self.oword = None;
    }

    /// The first word with this (upper-case) letter.
    pub fn word(&self, letter: u8) -> Option<&Word> {
        self.words.iter().find(|w| w.letter == letter)
    }

    /// True when the block has no words (blank, comment-only or `%`).
    pub fn is_empty(&self) -> bool {
        self.words.is_empty() && self.oword.is_none()
    }
}

/// Most decimal digits a G or M code may be written with (`G54.100`).
const MAX_CODE_DECIMALS: i32 = 6;

/// The letter of a chamfer word `,C` in [`Word::letter`] (lower case, so
/// that no word address compares equal to it): Fanuc's and Haas' corner
/// chamfer, read where the machine file's `corner_words` says the control
/// reads it (grammar/gcode.md, "Chamfer and corner-radius words").
pub const CHAMFER: u8 = b'c';

/// The letter of a corner-radius word `,R` in [`Word::letter`] (see
/// [`CHAMFER`]).
pub const CORNER_RADIUS: u8 = b'r';

/// Letters this dialect accepts as word addresses.
pub const LETTERS: &[u8] = b"ABCDEFGHIJKLMNOPQRSTXYZ";

/// Strips the end-of-line bytes (`\n`, `\r\n`, or a lone `\r`) from a line.
pub fn strip_eol(line: &[u8]) -> &[u8] {
    let mut end = line.len();
    if end > 0 && line[end - 1] == b'\n' {
        end -= 1;
    }
    if end > 0 && line[end - 1] == b'\r' {
        end -= 1;
    }
    &line[..end]
}

/// Scans the number at the start of `input` in one pass: its length (as
/// [`number_len`]) and its value when the exact fast path of
/// [`fast_decimal`] applies (`None`: parse the text in full).
#[inline]
fn scan_number(input: &[u8]) -> Option<(usize, Option<f64>)> {
    let neg = input.first() == Some(&b'-');
    let mut i = usize::from(matches!(input.first(), Some(b'+' | b'-')));
    // Wraps beyond 19 digits, where it is not used.
    let mut mant: u64 = 0;
    let int_start = i;
    while let Some(&c) = input.get(i) {
        if !c.is_ascii_digit() {
            break;
        }
        mant = mant.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
        i += 1;
    }
    let int_digits = i - int_start;
    let mut frac_digits = 0;
    if input.get(i) == Some(&b'.') && (int_digits > 0 || digits_len(input, i + 1) > 0) {
        i += 1;
        let frac_start = i;
        while let Some(&c) = input.get(i) {
            if !c.is_ascii_digit() {
                break;
            }
            mant = mant.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
            i += 1;
        }
        frac_digits = i - frac_start;
    } else if int_digits == 0 {
        return None;
    }
    let fast = (int_digits + frac_digits <= 19 && mant <= (1u64 << 53))
        .then(|| super::EXACT_POW10.get(frac_digits))
        .flatten()
        .map(|p| {
            let v = mant as f64 / p;
            if neg { -v } else { v }
        });
    Some((i, fast))
}

#[cfg(test)]
/// Length of the number at the start of `input`: an optional sign, then
/// digits with an optional point and more digits, or a point and digits
/// (`12`, `-1.`, `+.5`, `3.25`); `None` when there is none.
fn number_len(input: &[u8]) -> Option<usize> {
    let mut i = usize::from(matches!(input.first(), Some(b'+' | b'-')));
    let int = digits_len(input, i);
    if int > 0 {
        i += int;
        if input.get(i) == Some(&b'.') {
            i += 1;
            i += digits_len(input, i);
        }
        Some(i)
    } else if input.get(i) == Some(&b'.') && digits_len(input, i + 1) > 0 {
        Some(i + 1 + digits_len(input, i + 1))
    } else {
        None
    }
}

/// Number of ASCII digits from `at` on.
fn digits_len(input: &[u8], at: usize) -> usize {
    input
        .get(at..)
        .map_or(0, |s| s.iter().take_while(|c| c.is_ascii_digit()).count())
}

/// The value of a number recognised by `number_len`, exactly as
/// `str::parse::<f64>` gives it, without going through `str`: when the
/// digits form an integer of at most 2^53 and there are at most 22 decimals,
/// both the integer and the power of ten are exact `f64`s and their
/// (correctly rounded) quotient is the correctly rounded value of the
/// decimal. `None` for longer numbers (the caller parses them in full).
pub fn fast_decimal(num: &[u8]) -> Option<f64> {
    let (neg, body) = match num.split_first() {
        Some((b'-', rest)) => (true, rest),
        Some((b'+', rest)) => (false, rest),
        _ => (false, num),
    };
    let mut mant: u64 = 0;
    let mut digits = 0usize;
    let mut frac: Option<usize> = None;
    for &c in body {
        if c == b'.' {
            if frac.is_some() {
                return None;
            }
            frac = Some(0);
            continue;
        }
        if !c.is_ascii_digit() || digits >= 19 {
            return None;
        }
        mant = mant * 10 + u64::from(c - b'0');
        digits += 1;
        if let Some(f) = frac.as_mut() {
            *f += 1;
        }
    }
    if digits == 0 || mant > (1u64 << 53) {
        return None;
    }
    let v = mant as f64 / *super::EXACT_POW10.get(frac.unwrap_or(0))?;
    Some(if neg { -v } else { v })
}

/// The value of a recognised number: the fast path, else `str::parse`.
fn decimal(num: &[u8]) -> Option<f64> {
    fast_decimal(num).or_else(|| std::str::from_utf8(num).ok()?.parse().ok())
}

/// Word letters as a table: `IS_LETTER[b]` for upper-case `b` in [`LETTERS`].
const IS_LETTER: [bool; 256] = {
    let mut t = [false; 256];
    let mut i = 0;
    while i < LETTERS.len() {
        t[LETTERS[i] as usize] = true;
        i += 1;
    }
    t
};

fn show(bytes: &[u8]) -> String {
    let s = String::from_utf8_lossy(bytes);
    let s: String = s.chars().take(40).collect();
    s.trim_end().to_string()
}

/// Parses one line (without or with its end-of-line bytes) into `out`.
///
/// Errors are located at `file:line:column` and quote the offending text;
/// a line of a dialect this reader does not take (native Siemens,
/// Heidenhain conversational, lathe) has the dialect named in front.
#[inline]
pub fn parse_line(line: &[u8], line_no: usize, file: &str, out: &mut Block) -> Result<(), Located> {
    scan_line(line, line_no, file, out).map_err(|e| dialect::refine(line, e))
}

/// Where the line being scanned sits, for located errors.
#[derive(Clone, Copy)]
struct At<'a> {
    file: &'a str,
    line_no: usize,
}

impl At<'_> {
    /// The error at byte `pos` (0-based) of the line.
    #[cold]
    fn err(self, pos: usize, msg: String) -> Located {
        Located::new(self.file, self.line_no, pos + 1, msg)
    }
}

/// Refuses a carriage return (CR) that is not the first byte of a CR LF
/// line end: lines end in LF or CR LF, and a CR alone (a file with
/// CR-only line ends, or one such line end among others) would join lines
/// the control reads apart.
fn lone_cr(line: &[u8], at: At) -> Result<(), Located> {
    for p in memchr::memchr_iter(b'\r', line) {
        if line.get(p + 1) != Some(&b'\n') {
            return Err(at.err(
                p,
                "carriage return (CR) without a line feed: lines end in LF or CR LF (a file with CR-only line ends must be converted)".into(),
            ));
        }
    }
    Ok(())
}

fn scan_line(line: &[u8], line_no: usize, file: &str, out: &mut Block) -> Result<(), Located> {
    out.clear();
    out.line_no = line_no;
    let text = strip_eol(line);
    out.text_len = text.len() as u32;
    let at = At { file, line_no };
    lone_cr(line, at)?;

    // A UTF-8 byte-order mark (an editor's) opens the file: blank.
    let start = if line_no == 1 && text.starts_with(b"\xEF\xBB\xBF") {
        3
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
        pos += 1;
        // `/2` … `/9`: the optional block skip levels of Fanuc controls,
        // read as `/`.
        if text.get(pos).is_some_and(|c| (b'1'..=b'9').contains(c)) {
            pos += 1;
        }
        pos = skip_ws(text, pos);
    }
    if oword::scan(text, pos, file, line_no, out)? {
        return Ok(());
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
            b'(' => pos = paren_comment(text, pos, out, at)?,
            b';' => {
                out.comments.push(Comment {
                    start: pos as u32,
                    end: text.len() as u32,
                    semicolon: true,
                });
                pos = text.len();
            }
            // `:1000`, the ISO form of the program number `O1000`.
            b':' if out.words.is_empty() && out.comments.is_empty() => {
                upper += 1;
                pos = word(text, pos, out, at)?;
            }
            _ if b.is_ascii_alphabetic() => {
                if b.is_ascii_lowercase() {
                    lower += 1;
                } else {
                    upper += 1;
                }
                pos = word(text, pos, out, at)?;
            }
            b',' => pos = corner_word(text, pos, out, at)?,
            _ => return Err(stray(text, pos, at)),
        }
    }
    out.lower_case = lower > upper;
    out.spaced = saw_space && out.words.len() > 1;
    Ok(())
}

/// The `( … )` comment opening at `pos`: recorded in `out`; the position
/// after its `)`.
#[inline]
fn paren_comment(text: &[u8], pos: usize, out: &mut Block, at: At) -> Result<usize, Located> {
    let Some(off) = comment_close(text, pos).map(|close| close - pos) else {
        return Err(at.err(
            pos,
            format!(
                "unterminated comment, no `)` before the end of the line: `{}`",
                show(&text[pos..])
            ),
        ));
    };
    out.comments.push(Comment {
        start: pos as u32,
        end: (pos + off + 1) as u32,
        semicolon: false,
    });
    Ok(pos + off + 1)
}

/// The index of the `)` that closes the comment opened by the `(` at
/// `open`: the first `)`, unless the comment holds parentheses of its own
/// (`(outer (inner) still comment)`, `($MESSAGE("DONE") )`); then the one
/// that balances them, or, where they do not balance, the last `)` of the
/// line. `None` when no `)` follows.
pub fn comment_close(text: &[u8], open: usize) -> Option<usize> {
    let inside = text.get(open + 1..)?;
    let first = open + 1 + inside.iter().position(|&c| c == b')')?;
    if !text[open + 1..first].contains(&b'(') {
        return Some(first);
    }
    let mut depth = 0usize;
    let mut last = first;
    for (i, &c) in text.iter().enumerate().skip(open) {
        match c {
            b'(' => depth += 1,
            b')' => {
                depth -= 1;
                last = i;
                if depth == 0 {
                    return Some(i);
                }
            }
            _ => {}
        }
    }
    Some(last)
}

/// The word whose letter is at `pos`: pushed to `out`; the position after
/// its number.
#[inline]
fn word(text: &[u8], pos: usize, out: &mut Block, at: At) -> Result<usize, Located> {
    let b = text[pos];
    let letter = if b == b':' {
        b'O'
    } else {
        b.to_ascii_uppercase()
    };
    let after_letter = skip_ws(text, pos + 1);
    if !IS_LETTER[letter as usize] {
        return Err(at.err(
            pos,
            format!(
                "unknown word letter `{}`: `{}`",
                b as char,
                show(&text[pos..])
            ),
        ));
    }
    let rest = text.get(after_letter..).unwrap_or(b"");
    let Some((len, fast)) = scan_number(rest) else {
        return Err(no_number(text, pos, after_letter, at));
    };
    let num = &rest[..len];
    let num_end = after_letter + len;
    let Some(value) = fast.or_else(|| decimal(num)) else {
        return Err(bad_number(num, after_letter, "malformed", at));
    };
    if !value.is_finite() || value.abs() > 1e9 {
        return Err(bad_number(num, after_letter, "absurd", at));
    }
    let decimals = num
        .iter()
        .position(|&c| c == b'.')
        .map(|d| (num.len() - d - 1).min(255) as u8);
    // A second number glued to this one (`X1.2.3`, `X1-2`).
    if let Some(&next) = text.get(num_end) {
        if next == b'.' || next.is_ascii_digit() || next == b'-' || next == b'+' {
            return Err(at.err(
                num_end,
                format!("two numbers in one word: `{}`", show(&text[pos..])),
            ));
        }
    }
    if letter == b'O' && out.words.is_empty() {
        o_word_control(text, pos, num_end, at)?;
    }
    out.words.push(Word {
        letter,
        value,
        start: pos as u32,
        num_start: after_letter as u32,
        end: num_end as u32,
        decimals,
    });
    Ok(num_end)
}

/// The corner word (`,C2.`, `,R5.`) whose comma is at `pos`: pushed to
/// `out` with the letter [`CHAMFER`] or [`CORNER_RADIUS`]; the position
/// after its number. A comma that opens no such word is refused.
fn corner_word(text: &[u8], pos: usize, out: &mut Block, at: At) -> Result<usize, Located> {
    let letter = match text.get(pos + 1) {
        Some(b'C' | b'c') => CHAMFER,
        Some(b'R' | b'r') => CORNER_RADIUS,
        _ => return Err(stray(text, pos, at)),
    };
    let after_letter = skip_ws(text, pos + 2);
    let rest = text.get(after_letter..).unwrap_or(b"");
    let Some((len, fast)) = scan_number(rest) else {
        return Err(stray(text, pos, at));
    };
    let num = &rest[..len];
    let num_end = after_letter + len;
    let Some(value) = fast.or_else(|| decimal(num)) else {
        return Err(bad_number(num, after_letter, "malformed", at));
    };
    if !value.is_finite() || value.abs() > 1e9 {
        return Err(bad_number(num, after_letter, "absurd", at));
    }
    if let Some(&next) = text.get(num_end) {
        if next == b'.' || next.is_ascii_digit() || next == b'-' || next == b'+' {
            return Err(at.err(
                num_end,
                format!("two numbers in one word: `{}`", show(&text[pos..])),
            ));
        }
    }
    out.words.push(Word {
        letter,
        value,
        start: pos as u32,
        num_start: after_letter as u32,
        end: num_end as u32,
        decimals: num
            .iter()
            .position(|&c| c == b'.')
            .map(|d| (num.len() - d - 1).min(255) as u8),
    });
    Ok(num_end)
}

/// `what` (`malformed`, `absurd`) number `num` starting at `pos`.
#[cold]
fn bad_number(num: &[u8], pos: usize, what: &str, at: At) -> Located {
    let shown = crate::error::clip(&String::from_utf8_lossy(num));
    at.err(pos, format!("{what} number `{shown}`"))
}

/// Keywords of O-word subroutines and loops (LinuxCNC), any case.
const O_WORD_CONTROL: [&str; 15] = [
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

/// Refuses `O100 sub`, `o100 while …` (subroutines and loops) when the O
/// word at `pos`, ending at `num_end`, opens the line.
fn o_word_control(text: &[u8], pos: usize, num_end: usize, at: At) -> Result<(), Located> {
    let tail = skip_ws(text, num_end);
    if !text.get(tail).is_some_and(|c| c.is_ascii_alphabetic()) {
        return Ok(());
    }
    let len = text[tail..]
        .iter()
        .take_while(|c| c.is_ascii_alphabetic())
        .count();
    let kw = &text[tail..tail + len];
    if O_WORD_CONTROL
        .iter()
        .any(|k| kw.eq_ignore_ascii_case(k.as_bytes()))
    {
        return Err(at.err(
            pos,
            format!(
                "O-word subroutines and loops cannot be compensated offline: `{}`",
                show(text)
            ),
        ));
    }
    Ok(())
}

/// The letter at `pos` has no number after it (at `after_letter`).
#[cold]
fn no_number(text: &[u8], pos: usize, after_letter: usize, at: At) -> Located {
    let b = text[pos];
    let rest = text.get(after_letter..).unwrap_or(b"");
    if let Some(msg) = rest.first().and_then(|&c| offline_only(c, &text[pos..])) {
        // `X#1`, `X[1+2]`, `X=10.`, `R1=5` (Siemens-style assignments).
        return at.err(after_letter, msg);
    }
    if after_letter >= text.len() {
        return at.err(
            pos,
            format!(
                "truncated word: letter `{}` with no number at the end of the line",
                b as char
            ),
        );
    }
    at.err(
        pos,
        format!(
            "letter `{}` without a number: `{}`",
            b as char,
            show(&text[pos..])
        ),
    )
}

/// The message for a byte that opens a construct (parameter, expression,
/// assignment) only the controller can evaluate, quoting `from`; `None`
/// for other bytes.
fn offline_only(c: u8, from: &[u8]) -> Option<String> {
    let shown = show(from);
    Some(match c {
        b'#' => {
            format!("`#` parameters cannot be compensated offline (expand them in CAM): `{shown}`")
        }
        b'[' => format!(
            "`[ ]` expressions cannot be compensated offline (expand them in CAM): `{shown}`"
        ),
        b'=' => format!("assignments cannot be compensated offline: `{shown}`"),
        b',' if matches!(from.get(1), Some(b'C' | b'c')) => format!(
            "a chamfer word `,C` is not read: the control inserts the chamfer between this move and the next; write the corner as moves: `{shown}`"
        ),
        b',' if matches!(from.get(1), Some(b'R' | b'r')) => format!(
            "a corner-radius word `,R` is not read: the control inserts the rounding between this move and the next; write the corner as an arc: `{shown}`"
        ),
        _ => return None,
    })
}

/// The error for the byte at `pos`, which starts neither a word nor a
/// comment.
#[cold]
fn stray(text: &[u8], pos: usize, at: At) -> Located {
    let b = text[pos];
    let c = if b == b']' { b'[' } else { b };
    if let Some(msg) = offline_only(c, &text[pos..]) {
        return at.err(pos, msg);
    }
    if b.is_ascii_digit() || b == b'.' || b == b'-' || b == b'+' {
        return at.err(
            pos,
            format!("number without a letter: `{}`", show(&text[pos..])),
        );
    }
    let shown = if b.is_ascii_graphic() {
        format!("`{}`", b as char)
    } else {
        format!("byte 0x{b:02X}")
    };
    at.err(
        pos,
        format!("unexpected character {shown} outside a comment"),
    )
}

fn skip_ws(text: &[u8], mut pos: usize) -> usize {
    while matches!(text.get(pos), Some(b' ' | b'\t')) {
        pos += 1;
    }
    pos
}

pub mod dialect;
pub mod expr;
pub mod macros;
mod macros_run;
pub mod oword;
mod oword_run;
#[cfg(test)]
mod reference;
pub mod subprograms;

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Both parsers on one line: the same block, or the same error.
    fn same_as_reference(line: &[u8]) -> std::result::Result<(), TestCaseError> {
        // Line 1 (where a byte-order mark may open the file) and another.
        same_as_reference_at(line, 1)?;
        same_as_reference_at(line, 3)
    }

    fn same_as_reference_at(line: &[u8], line_no: usize) -> std::result::Result<(), TestCaseError> {
        let mut fast = Block::default();
        let mut slow = Block::default();
        let a = parse_line(line, line_no, "p.nc", &mut fast);
        let b = reference::parse_line(line, line_no, "p.nc", &mut slow);
        prop_assert_eq!(&a, &b, "line {:?}", String::from_utf8_lossy(line));
        if a.is_ok() {
            prop_assert_eq!(&fast.words, &slow.words);
            prop_assert_eq!(&fast.comments, &slow.comments);
            prop_assert_eq!(&fast.oword, &slow.oword);
            prop_assert_eq!(
                (
                    fast.block_delete,
                    fast.percent,
                    fast.text_len,
                    fast.lower_case,
                    fast.spaced
                ),
                (
                    slow.block_delete,
                    slow.percent,
                    slow.text_len,
                    slow.lower_case,
                    slow.spaced
                )
            );
            for (w, v) in fast.words.iter().zip(&slow.words) {
                // `==` takes -0 for 0: compare the bits.
                prop_assert_eq!(w.value.to_bits(), v.value.to_bits());
            }
        }
        Ok(())
    }

    /// A number as CAM systems and people write it, with the odd long one.
    fn number_text() -> impl Strategy<Value = String> {
        (
            prop_oneof![Just(""), Just("-"), Just("+")],
            "[0-9]{0,22}",
            prop_oneof![Just(""), Just(".")],
            "[0-9]{0,24}",
        )
            .prop_map(|(s, i, p, f)| format!("{s}{i}{p}{f}"))
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(4000))]

        #[test]
        fn scanner_agrees_with_the_reference_on_words(
            words in prop::collection::vec(
                ("[A-Za-z]", prop_oneof![Just(""), Just(" "), Just("\t")], number_text(),
                 prop_oneof![Just(""), Just(" "), Just("  ")]),
                0..6,
            ),
            head in prop_oneof![Just(""), Just("/"), Just(" "), Just("%"), Just("N10 "),
                                Just(":"), Just("/2"), Just("\u{feff}"), Just("(c):")],
            tail in prop_oneof![Just(""), Just("\n"), Just("\r\n"), Just(" (c)"), Just(";x"),
                                Just("(open"), Just("#1"), Just("=2"), Just("[1]"), Just(" sub")],
        ) {
            let mut line = String::from(head);
            for (l, gap, n, sep) in &words {
                line.push_str(l);
                line.push_str(gap);
                line.push_str(n);
                line.push_str(sep);
            }
            line.push_str(tail);
            same_as_reference(line.as_bytes())?;
        }

        #[test]
        fn scanner_agrees_with_the_reference_on_any_bytes(
            line in prop::collection::vec(
                prop_oneof![
                    4 => prop::sample::select(b"GXYZFIJKRNOMST0123456789.-+ ".to_vec()),
                    1 => any::<u8>(),
                ],
                0..40,
            )
        ) {
            same_as_reference(&line)?;
        }

        #[test]
        fn fast_decimals_are_those_of_str_parse(text in number_text()) {
            if let Some(len) = number_len(text.as_bytes()) {
                let num = &text.as_bytes()[..len];
                let want: f64 = std::str::from_utf8(num).unwrap_or("").parse().unwrap_or(f64::NAN);
                let got = decimal(num).unwrap_or(f64::NAN);
                prop_assert_eq!(got.to_bits(), want.to_bits(), "{}", text);
            }
        }
    }

    proptest! {
        #[test]
        fn one_pass_scan_is_length_and_fast_value(text in number_text(), tail in "[ X.0-9]{0,2}") {
            let t = format!("{text}{tail}");
            let b = t.as_bytes();
            let want = number_len(b).map(|n| (n, fast_decimal(&b[..n]).map(f64::to_bits)));
            let got = scan_number(b).map(|(n, v)| (n, v.map(f64::to_bits)));
            prop_assert_eq!(got, want, "{}", t);
        }
    }

    #[test]
    fn fast_decimals_on_edge_cases() {
        for t in [
            "0",
            "-0",
            "-0.000",
            "+0.",
            ".5",
            "-.5",
            "9007199254740992",
            "9007199254740993",
            "0.1",
            "0.3",
            "123456.789012",
            "1.0000000000000000000001",
            "4503599627370497.5",
            "99999999999999999999",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "1e5",
        ] {
            let want: Option<f64> = t.parse().ok();
            if let Some(f) = fast_decimal(t.as_bytes()) {
                assert_eq!(Some(f.to_bits()), want.map(f64::to_bits), "{t}");
            }
            if number_len(t.as_bytes()) == Some(t.len()) {
                assert_eq!(
                    decimal(t.as_bytes()).map(f64::to_bits),
                    want.map(f64::to_bits),
                    "{t}"
                );
            }
        }
    }

    fn parse(s: &str) -> Result<Block, Located> {
        let mut b = Block::default();
        parse_line(s.as_bytes(), 7, "t.nc", &mut b).map(|_| b)
    }

    #[test]
    fn words_keep_spans_and_decimals() {
        let line = "N10 G01 X-12.500 y3. Z.5 (cut) ; tail";
        let b = parse(line).unwrap();
        let letters: Vec<u8> = b.words.iter().map(|w| w.letter).collect();
        assert_eq!(letters, b"NGXYZ");
        let x = b.word(b'X').unwrap();
        assert_eq!(x.number_text(line.as_bytes()), b"-12.500");
        assert_eq!(x.value, -12.5);
        assert_eq!(x.decimals, Some(3));
        assert_eq!(b.word(b'Y').unwrap().decimals, Some(0));
        assert_eq!(b.word(b'Z').unwrap().value, 0.5);
        assert_eq!(b.word(b'G').unwrap().decimals, None);
        assert_eq!(b.comments.len(), 2);
        assert!(b.comments[1].semicolon);
        assert!(b.spaced);
    }

    #[test]
    fn space_between_letter_and_number() {
        let b = parse("G 1 X 10.0").unwrap();
        assert_eq!(b.word(b'X').unwrap().value, 10.0);
        assert_eq!(b.word(b'G').unwrap().code10(), 10);
    }

    #[test]
    fn block_delete_percent_and_crlf() {
        let b = parse("/G0X1\r\n").unwrap();
        assert!(b.block_delete);
        assert_eq!(b.text_len, 5);
        assert!(parse("%").unwrap().percent);
        assert_eq!(parse("G90.1").unwrap().word(b'G').unwrap().code10(), 901);
        // Optional block skip levels and the ISO program number.
        let b = parse("/2 G1 Z-1.").unwrap();
        assert!(b.block_delete);
        assert_eq!(b.word(b'Z').unwrap().value, -1.0);
        let b = parse(":1000 (PLATE)").unwrap();
        assert_eq!(b.word(b'O').unwrap().value, 1000.0);
        assert!(parse("G1 :1000").is_err());
    }

    #[test]
    fn errors_are_located() {
        let e = parse("G1 X").unwrap_err();
        assert_eq!((e.line, e.column), (7, 4));
        assert!(e.message.contains("truncated"), "{}", e.message);
        let e = parse("G1 X Y2").unwrap_err();
        assert!(e.message.contains("without a number"), "{}", e.message);
        let e = parse("G1 X1.2.3").unwrap_err();
        assert_eq!(e.column, 8);
        assert!(e.message.contains("two numbers"));
        let e = parse("G1 U5").unwrap_err();
        assert!(e.message.contains("unknown word letter"));
        let e = parse("G1 X#1").unwrap_err();
        assert!(e.message.contains("parameters"));
        let b = parse("o100 sub").unwrap();
        assert_eq!(b.oword.map(|o| o.keyword), Some(oword::Keyword::Sub));
        assert!(b.words.is_empty());
        let e = parse("G1 X[1+2]").unwrap_err();
        assert!(e.message.contains("expressions"));
        let e = parse("G1 (open").unwrap_err();
        assert!(e.message.contains("unterminated"));
        let e = parse("G1 12").unwrap_err();
        assert!(e.message.contains("without a letter"));
    }

    /// Parentheses inside a comment nest; an unbalanced one inside ends
    /// the comment at the line's last `)`.
    #[test]
    fn nested_comments_are_one_comment() {
        let spans = |line: &str| -> Vec<String> {
            let b = parse(line).unwrap_or_else(|e| panic!("{line}: {e}"));
            b.comments
                .iter()
                .map(|c| line[c.start as usize..c.end as usize].to_string())
                .collect()
        };
        assert_eq!(
            spans("(outer (inner) still comment)"),
            ["(outer (inner) still comment)"]
        );
        assert_eq!(
            spans("G0 X1. ($MESSAGE(\"DONE\") ) Y2."),
            ["($MESSAGE(\"DONE\") )"]
        );
        let b = parse("G0 X1. ($MESSAGE(\"DONE\") ) Y2.").unwrap();
        assert_eq!(b.word(b'Y').unwrap().value, 2.0);
        assert_eq!(
            spans("(USE 1/2 (12.7 MM CUTTER)"),
            ["(USE 1/2 (12.7 MM CUTTER)"]
        );
        assert_eq!(spans("(A) G1 (B)"), ["(A)", "(B)"]);
        let e = parse("G1 (a (b) c").unwrap_err();
        assert!(e.message.contains("letter `c` with no number"), "{e}");
        let e = parse("G1 (a (b c").unwrap_err();
        assert!(e.message.contains("unterminated"), "{e}");
    }
}
