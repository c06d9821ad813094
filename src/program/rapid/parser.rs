//! The RAPID parser proper: nom combinators for the lexical pieces (numbers,
//! identifiers, keywords) and a small recursive-descent driver for modules,
//! declarations, routines and motion instructions. Positions are byte offsets
//! into the source, computed from the remaining input.

use std::sync::Arc;

use nom::IResult;
use nom::error::{ErrorKind, ParseError};

use super::instructions::{
    MotionInstruction, Role, may_start_motion, motion_instruction, plain_move_at,
};
use super::{
    Arg, Assign, DataType, DataValue, Decl, Dim, Field, Index, Module, Move, MoveKind, Number,
    OptArg, Proc, Record, RobTarget, RoutineKind, Scalar, Scope, Span, Stmt, Storage, Target,
    find_placeholder, placeholder_at,
};
use crate::error::Located;

/// A parse failure: where (the remaining input) and what.
#[derive(Debug)]
pub(super) struct PErr<'a> {
    pub(super) at: &'a str,
    pub(super) msg: String,
}

impl<'a> ParseError<&'a str> for PErr<'a> {
    fn from_error_kind(input: &'a str, kind: ErrorKind) -> Self {
        PErr {
            at: input,
            msg: format!("unexpected text ({kind:?})"),
        }
    }
    fn append(_: &'a str, _: ErrorKind, other: Self) -> Self {
        other
    }
}

pub(super) type PResult<'a, T> = IResult<&'a str, T, PErr<'a>>;

/// Generic syntax of a data value, before it is checked against its type.
#[derive(Debug)]
pub(super) enum Val {
    /// `[a, b, …]`.
    List { span: Span, items: Vec<Val> },
    /// A numeric literal.
    Num(Number),
    /// A string literal; `text` is the contents with `""` undoubled.
    Str { span: Span, text: String },
    /// A bare identifier (`TRUE`, `p10`).
    Word { span: Span, text: String },
    /// Any other expression.
    Expr { span: Span },
}

impl Val {
    pub(super) fn span(&self) -> Span {
        match self {
            Val::Num(n) => n.span.clone(),
            Val::List { span, .. }
            | Val::Str { span, .. }
            | Val::Word { span, .. }
            | Val::Expr { span } => span.clone(),
        }
    }
}

/// Words that start a statement; a line starting with one of them cannot be
/// the continuation of the previous statement (this is how a missing `;` is
/// told from a statement spread over several lines).
const STATEMENT_WORDS: &[&str] = &[
    "MoveL",
    "MoveJ",
    "MoveC",
    "MoveAbsJ",
    "ENDPROC",
    "ENDFUNC",
    "ENDTRAP",
    "ENDMODULE",
    "ENDIF",
    "ENDFOR",
    "ENDWHILE",
    "ENDTEST",
    "ELSE",
    "ELSEIF",
    "IF",
    "FOR",
    "WHILE",
    "TEST",
    "PROC",
    "FUNC",
    "TRAP",
    "CONST",
    "VAR",
    "PERS",
    "LOCAL",
    "RETURN",
    "RECORD",
    "ENDRECORD",
];

/// Words that may start a line of a parameter list written over several
/// lines (`PROC weld(robtarget a,` / `VAR robtarget c)`).
const PARAMETER_WORDS: &[&str] = &["VAR", "PERS", "INOUT"];

/// The motion instruction whose name starts `i` (a whole word), and the
/// text after the name.
#[inline]
fn motion_at(i: &str) -> Option<(&'static MotionInstruction, &str)> {
    // Most statements that are not moves are told by their first byte,
    // the plain moves by their first letters.
    let b = i.as_bytes();
    if !b.first().is_some_and(|&c| may_start_motion(c)) {
        return None;
    }
    if let Some((m, n)) = plain_move_at(b) {
        return Some((m, i.get(n..)?));
    }
    let (rest, word) = ident(i).ok()?;
    Some((motion_instruction(word)?, rest))
}

/// A blank of the parser ([`ws`]) at the end of a condition.
fn is_blank_char(c: char) -> bool {
    matches!(c, ' ' | '\t' | '\r' | '\n' | '\u{feff}')
}

fn is_ident_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

/// Matches `word` case-insensitively at the start of `i`, as a whole word.
pub(super) fn kw<'a>(i: &'a str, word: &str) -> Option<&'a str> {
    let head = i.get(..word.len())?;
    if !head.eq_ignore_ascii_case(word) {
        return None;
    }
    let rest = i.get(word.len()..)?;
    if rest.bytes().next().is_some_and(is_ident_byte) {
        return None;
    }
    Some(rest)
}

/// Skips whitespace and `!` comments.
#[inline]
pub(super) fn ws(i: &str) -> &str {
    // Most calls start at a token: nothing to skip.
    if matches!(
        i.as_bytes().first(),
        Some(b' ' | b'\t' | b'\r' | b'\n' | b'!' | 0xef)
    ) {
        ws_skip(i)
    } else {
        i
    }
}

/// [`ws`] when there is something to skip.
fn ws_skip(mut i: &str) -> &str {
    loop {
        // Byte scan of the ASCII blanks (the common case: a few spaces or
        // none), then the byte-order mark, which may come between them.
        let n = i
            .bytes()
            .take_while(|b| matches!(b, b' ' | b'\t' | b'\r' | b'\n'))
            .count();
        let t = i.get(n..).unwrap_or_default();
        if let Some(r) = t.strip_prefix('\u{feff}') {
            i = r;
        } else if let Some(c) = t.strip_prefix('!') {
            i = c.find('\n').map_or("", |p| &c[p..]);
        } else {
            return t;
        }
    }
}

/// [`ws`] by `trim_start_matches` (the reference of its byte scan).
#[cfg(test)]
fn ws_reference(mut i: &str) -> &str {
    loop {
        let t = i.trim_start_matches([' ', '\t', '\r', '\n', '\u{feff}']);
        if let Some(c) = t.strip_prefix('!') {
            i = c.find('\n').map_or("", |p| &c[p..]);
        } else {
            return t;
        }
    }
}

/// An identifier: a letter followed by letters, digits and underscores.
pub(super) fn ident(i: &str) -> PResult<'_, &str> {
    let b = i.as_bytes();
    if !b.first().is_some_and(u8::is_ascii_alphabetic) {
        return Err(no_match(i));
    }
    let n = 1 + b.iter().skip(1).take_while(|&&c| is_ident_byte(c)).count();
    // ASCII bytes only: both ends are char boundaries.
    match (i.get(n..), i.get(..n)) {
        (Some(rest), Some(word)) => Ok((rest, word)),
        _ => Err(no_match(i)),
    }
}

/// The failure of a lexical piece (never shown: callers try the next form).
fn no_match(i: &str) -> nom::Err<PErr<'_>> {
    nom::Err::Error(PErr {
        at: i,
        msg: String::new(),
    })
}

/// Number of ASCII digits at the start of `b`.
fn digits(b: &[u8]) -> usize {
    b.iter().take_while(|c| c.is_ascii_digit()).count()
}

/// The text of a numeric literal: optional sign, digits with an optional
/// fraction (or a fraction alone) and an optional exponent.
pub(super) fn number_text(i: &str) -> PResult<'_, &str> {
    let b = i.as_bytes();
    let mut k = usize::from(matches!(b.first(), Some(b'+' | b'-')));
    let int = digits(b.get(k..).unwrap_or_default());
    if int > 0 {
        k += int;
        if b.get(k) == Some(&b'.') {
            k += 1 + digits(b.get(k + 1..).unwrap_or_default());
        }
    } else if b.get(k) == Some(&b'.') {
        let frac = digits(b.get(k + 1..).unwrap_or_default());
        if frac == 0 {
            return Err(no_match(i));
        }
        k += 1 + frac;
    } else {
        return Err(no_match(i));
    }
    // An exponent only when complete (`1e` is the number `1`, then `e`).
    if matches!(b.get(k), Some(b'e' | b'E')) {
        let sign = usize::from(matches!(b.get(k + 1), Some(b'+' | b'-')));
        let exp = digits(b.get(k + 1 + sign..).unwrap_or_default());
        if exp > 0 {
            k += 1 + sign + exp;
        }
    }
    // ASCII bytes only: both ends are char boundaries.
    match (i.get(k..), i.get(..k)) {
        (Some(rest), Some(text)) => Ok((rest, text)),
        _ => Err(no_match(i)),
    }
}

/// Largest magnitude of a literal: above the `9E9` that marks an unused
/// external axis, far below anything a robot program means.
pub(super) const MAX_NUMBER: f64 = 1e10;

/// Parses a whole string as a numeric literal (`None` beyond
/// [`MAX_NUMBER`]).
pub(super) fn parse_number(text: &str) -> Option<f64> {
    match number_text(text) {
        Ok(("", t)) => number_value(t).filter(|v| v.abs() <= MAX_NUMBER),
        _ => None,
    }
}

/// `t.parse::<f64>().ok()` for the text of a numeric literal
/// ([`number_text`]), with the exact fast path for short literals: at most
/// 15 significant digits `m` (below 2^53, exact in f64) and a decimal
/// exponent `k` with `|k| ≤ 22` (`10^|k|` exact in f64) give the correctly
/// rounded value by one IEEE multiplication or division `m · 10^k`, which
/// is what the full parser returns (it rounds correctly too). Anything
/// else goes to the full parser.
fn number_value(t: &str) -> Option<f64> {
    let b = t.as_bytes();
    let neg = b.first() == Some(&b'-');
    let mut k = usize::from(matches!(b.first(), Some(b'+' | b'-')));
    let mut m: u64 = 0;
    let mut digits = 0usize;
    let mut frac = 0i64;
    let mut seen_dot = false;
    while let Some(&c) = b.get(k) {
        match c {
            b'0'..=b'9' => {
                if m != 0 || c != b'0' {
                    digits += 1;
                }
                m = m.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
                if seen_dot {
                    frac += 1;
                }
            }
            b'.' if !seen_dot => seen_dot = true,
            _ => break,
        }
        k += 1;
    }
    let mut exp = 0i64;
    if matches!(b.get(k), Some(b'e' | b'E')) {
        k += 1;
        let eneg = b.get(k) == Some(&b'-');
        k += usize::from(matches!(b.get(k), Some(b'+' | b'-')));
        let mut n = 0usize;
        while let Some(&c) = b.get(k) {
            if !c.is_ascii_digit() || n >= 4 {
                break;
            }
            exp = exp * 10 + i64::from(c - b'0');
            n += 1;
            k += 1;
        }
        if eneg {
            exp = -exp;
        }
    }
    // Leading zeros do not count; 15 digits stay below 2^53 (no wrap).
    let e10 = exp - frac;
    if k == b.len() && digits <= 15 && (-22..=22).contains(&e10) {
        let m = m as f64;
        let v = match crate::program::EXACT_POW10.get(e10.unsigned_abs() as usize) {
            Some(p) if e10 >= 0 => m * p,
            Some(p) => m / p,
            None => return t.parse::<f64>().ok(),
        };
        return Some(if neg { -v } else { v });
    }
    t.parse::<f64>().ok()
}

/// [`number_text`] then [`number_value`] in one pass over the bytes: the
/// rest after the literal and its value (`None` where either gives none).
/// The fast path takes the same significant digits and decimal exponent
/// as [`number_value`]; every other literal goes to `str::parse` too.
#[inline]
fn number_at(i: &str) -> Option<(&str, f64)> {
    let b = i.as_bytes();
    let neg = b.first() == Some(&b'-');
    let mut k = usize::from(matches!(b.first(), Some(b'+' | b'-')));
    let (mut m, mut sig, mut int, mut frac) = (0u64, 0usize, 0usize, 0i64);
    while let Some(&c) = b.get(k) {
        if !c.is_ascii_digit() {
            break;
        }
        sig += usize::from(m != 0 || c != b'0');
        m = m.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
        int += 1;
        k += 1;
    }
    if b.get(k) == Some(&b'.') {
        let mut j = k + 1;
        while let Some(&c) = b.get(j) {
            if !c.is_ascii_digit() {
                break;
            }
            sig += usize::from(m != 0 || c != b'0');
            m = m.wrapping_mul(10).wrapping_add(u64::from(c - b'0'));
            frac += 1;
            j += 1;
        }
        if int == 0 && frac == 0 {
            return None;
        }
        k = j;
    } else if int == 0 {
        return None;
    }
    // An exponent only when complete; more than four digits go to the
    // full parser.
    let (mut exp, mut short) = (0i64, true);
    if matches!(b.get(k), Some(b'e' | b'E')) {
        let sign = usize::from(matches!(b.get(k + 1), Some(b'+' | b'-')));
        let from = k + 1 + sign;
        let n = digits(b.get(from..).unwrap_or_default());
        if n > 0 {
            short = n <= 4;
            for &c in b.get(from..from + n.min(4)).unwrap_or_default() {
                exp = exp * 10 + i64::from(c - b'0');
            }
            if b.get(k + 1) == Some(&b'-') {
                exp = -exp;
            }
            k = from + n;
        }
    }
    // ASCII bytes only: both ends are char boundaries.
    let (text, rest) = (i.get(..k)?, i.get(k..)?);
    let e10 = exp - frac;
    if short && sig <= 15 && (-22..=22).contains(&e10) {
        let m = m as f64;
        let v = match crate::program::EXACT_POW10.get(e10.unsigned_abs() as usize) {
            Some(p) if e10 >= 0 => m * p,
            Some(p) => m / p,
            None => return Some((rest, text.parse::<f64>().ok()?)),
        };
        return Some((rest, if neg { -v } else { v }));
    }
    Some((rest, text.parse::<f64>().ok()?))
}

/// The parser state: the source, for positions and messages.
pub(super) struct Parser<'a> {
    src: &'a str,
    file: &'a str,
    line_starts: std::sync::Arc<[usize]>,
    /// Current nesting of aggregates and `Offs`/`RelTool` calls.
    depth: std::cell::Cell<usize>,
    /// Smallest routine rest (bytes) whose statements are parsed ahead in
    /// parallel ([`Parser::parse_ahead`]).
    ahead_min: usize,
    /// The argument texts met last (`v100`, `z1`, `tool1`: a module repeats
    /// a few of them), shared instead of allocated per move.
    texts: std::cell::RefCell<Vec<Arc<str>>>,
    /// The module's `ALIAS` types met so far: (alias, the type it names),
    /// lower case.
    aliases: std::cell::RefCell<Vec<(String, String)>>,
    /// The module's `CONST num` declarations with a literal value met so
    /// far (name lower case, value): a number of a literal may be written
    /// as one of them (`[[0,0,safeHeight],…]`).
    pub(super) consts: std::cell::RefCell<Vec<(String, f64)>>,
}

/// Argument texts [`Parser::text`] keeps to share.
const SHARED_TEXTS: usize = 16;

/// Source bytes after a routine header from which its statements are parsed
/// ahead in parallel: below, the serial loop is as fast.
const AHEAD_MIN_BYTES: usize = 1 << 18;

/// A statement parsed ahead: its start, where its parse ended, the statement.
type Ahead = Option<(usize, usize, Stmt)>;

/// Deepest nesting of aggregates / target functions accepted (a robtarget
/// array needs 3); deeper input is rejected instead of exhausting the stack.
const MAX_NESTING: usize = 16;

/// How a body statement ends (for the statement scanner).
struct Scan {
    /// Offset (within the scanned text) of the stop.
    stop: usize,
    /// Offset just after the last significant (non-blank, non-comment) byte.
    last: usize,
}

impl<'a> Parser<'a> {
    pub(super) fn new(src: &'a str, file: &'a str) -> Self {
        Self::with_ahead_min(src, file, AHEAD_MIN_BYTES)
    }

    /// [`Parser::new`] parsing ahead from routines with at least
    /// `ahead_min` bytes after their header (`usize::MAX`: never).
    pub(super) fn with_ahead_min(src: &'a str, file: &'a str, ahead_min: usize) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(memchr::memchr_iter(b'\n', src.as_bytes()).map(|k| k + 1));
        Parser {
            src,
            file,
            line_starts: line_starts.into(),
            depth: std::cell::Cell::new(0),
            texts: std::cell::RefCell::new(Vec::new()),
            aliases: std::cell::RefCell::new(Vec::new()),
            consts: std::cell::RefCell::new(Vec::new()),
            ahead_min,
        }
    }

    /// The statements of a routine body, parsed ahead in parallel (each
    /// task with a parser of its own): `i` is the body after the routine
    /// header. One pass over the body, up to the first line that opens with
    /// a routine or module end, takes as candidates the body's first
    /// statement and every line start whose last significant byte before it
    /// (outside strings and `!` comments) is a `;` at bracket depth 0, the
    /// end of a statement; so every byte belongs to at most one candidate's
    /// statement and the work stays linear in the body, and a statement
    /// after a control line (`IF … THEN`) is left to the body loop. The
    /// loop takes a statement from here only when it reaches exactly its
    /// start, where its own parse would give the same result (a statement's
    /// parse depends on its position alone), so the module is the same as
    /// parsed in order. Bodies shorter than `ahead_min` bytes are left to
    /// the loop.
    fn parse_ahead(&self, i: &'a str) -> Vec<Ahead> {
        use rayon::prelude::*;
        let body_start = self.pos(ws(i));
        let (starts, k) = statement_starts(self.src, self.pos(i), body_start);
        if k.saturating_sub(body_start) < self.ahead_min {
            return Vec::new();
        }
        let (src, file, line_starts) = (self.src, self.file, &self.line_starts);
        let aliases = self.aliases.borrow().clone();
        let consts = self.consts.borrow().clone();
        starts
            .par_iter()
            .map_init(
                || Parser {
                    src,
                    file,
                    line_starts: std::sync::Arc::clone(line_starts),
                    depth: std::cell::Cell::new(0),
                    texts: std::cell::RefCell::new(Vec::new()),
                    aliases: std::cell::RefCell::new(aliases.clone()),
                    consts: std::cell::RefCell::new(consts.clone()),
                    ahead_min: usize::MAX,
                },
                |p, &at| {
                    p.depth.set(0);
                    let (rest, stmt) = p.stmt(p.at(at)).ok()?;
                    Some((at, p.pos(rest), stmt))
                },
            )
            .collect()
    }

    /// The source text at `span`, shared with an equal text met lately.
    fn text(&self, span: Span) -> Arc<str> {
        let t = self.src.get(span).unwrap_or("");
        let mut texts = self.texts.borrow_mut();
        if let Some(k) = texts.iter().position(|s| **s == *t) {
            return Arc::clone(&texts[k]);
        }
        let a: Arc<str> = Arc::from(t);
        if texts.len() >= SHARED_TEXTS {
            texts.remove(0);
        }
        texts.push(Arc::clone(&a));
        a
    }

    pub(super) fn parse(&self) -> Result<Module, Located> {
        self.parse_from(0)
    }

    /// [`Parser::parse`] of the module that starts at byte `start`.
    pub(super) fn parse_from(&self, start: usize) -> Result<Module, Located> {
        match self.module(self.src.get(start..).unwrap_or("")) {
            Ok((_, m)) => Ok(m),
            Err(nom::Err::Error(e)) | Err(nom::Err::Failure(e)) => Err(self.located(&e)),
            Err(nom::Err::Incomplete(_)) => Err(Located::new(
                self.file,
                1,
                1,
                "incomplete input".to_string(),
            )),
        }
    }

    // ----- positions and messages -------------------------------------

    pub(super) fn pos(&self, rest: &str) -> usize {
        self.src.len().saturating_sub(rest.len())
    }

    pub(super) fn at(&self, pos: usize) -> &'a str {
        self.src.get(pos..).unwrap_or("")
    }

    pub(super) fn line_of(&self, pos: usize) -> usize {
        self.line_starts.partition_point(|&s| s <= pos).max(1)
    }

    fn located(&self, e: &PErr) -> Located {
        let pos = self.pos(e.at);
        let line = self.line_of(pos);
        let start = self.line_starts.get(line - 1).copied().unwrap_or(0);
        Located::new(self.file, line, pos - start + 1, e.msg.clone())
    }

    /// The error "what, found `text at pos`".
    pub(super) fn err_found(&self, pos: usize, what: &str) -> nom::Err<PErr<'a>> {
        let rest = self.at(pos);
        let line = rest.split(['\r', '\n']).next().unwrap_or("");
        let msg = if rest.is_empty() {
            format!("{what}, found end of file")
        } else if line.trim().is_empty() {
            format!("{what}, found end of line")
        } else {
            format!("{what}, found `{}`", clip(line, 40))
        };
        nom::Err::Failure(PErr { at: rest, msg })
    }

    /// The error "what after `text before pos`" located at `pos`.
    pub(super) fn err_after(&self, pos: usize, what: &str) -> nom::Err<PErr<'a>> {
        let line_start = self
            .line_starts
            .get(self.line_of(pos) - 1)
            .copied()
            .unwrap_or(0);
        let before = self.src.get(line_start..pos).unwrap_or("").trim();
        let msg = format!("{what} after `{}`", clip_end(before, 40));
        nom::Err::Failure(PErr {
            at: self.at(pos),
            msg,
        })
    }

    /// A failure at `pos`: "what, found `text at pos`".
    pub(super) fn fail_found<T>(&self, pos: usize, what: &str) -> PResult<'a, T> {
        Err(self.err_found(pos, what))
    }

    /// A failure at `pos`, quoting the text of the line before it.
    pub(super) fn fail_after<T>(&self, pos: usize, what: &str) -> PResult<'a, T> {
        Err(self.err_after(pos, what))
    }

    // ----- module ----------------------------------------------------------

    fn module(&self, i: &'a str) -> PResult<'a, Module> {
        let mut i = ws(i);
        let mut header = None;
        if let Some(body) = i.strip_prefix("%%%") {
            let start = self.pos(i);
            match body.find("%%%") {
                Some(k) => {
                    i = &body[k + 3..];
                    header = Some(start..self.pos(i));
                }
                None => return self.fail_found(start, "unterminated `%%%` header"),
            }
            i = ws(i);
        }
        let start = self.pos(i);
        let Some(r) = kw(i, "MODULE") else {
            return self.fail_found(start, "expected `MODULE name`");
        };
        let r = ws(r);
        let Ok((r, name)) = ident(r) else {
            return self.fail_found(self.pos(r), "expected a module name after MODULE");
        };
        let mut i = ws(r);
        let mut attributes = None;
        if let Some(a) = i.strip_prefix('(') {
            let Some(k) = a.find(')') else {
                return self.fail_found(self.pos(i), "unterminated module attribute list");
            };
            let a0 = self.pos(a);
            attributes = Some(a0..a0 + k);
            i = &a[k + 1..];
        }
        let mut decls: Vec<Decl> = Vec::new();
        let mut records = Vec::new();
        let mut placeholders = Vec::new();
        let mut procs = Vec::new();
        loop {
            i = ws(i);
            if i.is_empty() {
                return self.fail_found(
                    start,
                    &format!("unterminated MODULE {name}: end of file reached without ENDMODULE"),
                );
            }
            if let Some(r) = kw(i, "ENDMODULE") {
                i = r;
                break;
            }
            let (scope, r) = scope_prefix(i);
            let r = ws(r);
            if storage_kw(r).is_some() {
                let (rest, mut d) = self.decl(i)?;
                self.evaluate_dims(&mut d, &decls)?;
                if let (Storage::Const, Some(DataValue::Num(n))) = (d.storage, &d.value) {
                    self.consts
                        .borrow_mut()
                        .push((d.name.to_ascii_lowercase(), n.value));
                }
                decls.push(d);
                i = rest;
            } else if let Some(r) = kw(r, "RECORD") {
                let (rest, rec) = self.record(i, r, scope)?;
                records.push(rec);
                i = rest;
            } else if let Some(r) = kw(r, "ALIAS") {
                i = self.alias(r)?;
            } else if let Some((rest, span)) = self.alone_placeholder(i) {
                placeholders.push(span);
                i = rest;
            } else if routine_kw(r).is_some() {
                let (rest, p) = self.routine(i, scope)?;
                procs.push(p);
                i = rest;
            } else {
                return self.fail_found(
                    self.pos(i),
                    "expected a declaration (CONST, PERS, VAR, RECORD), a routine (PROC, FUNC, TRAP) or ENDMODULE",
                );
            }
        }
        let span = start..self.pos(i);
        let rest = ws(i);
        if !rest.is_empty() {
            return self.fail_found(self.pos(rest), "unexpected text after ENDMODULE");
        }
        Ok((
            rest,
            Module {
                name: name.to_string(),
                span,
                header,
                attributes,
                decls,
                records,
                placeholders,
                procs,
            },
        ))
    }

    /// The rest of an `ALIAS type name;` declaration after its keyword:
    /// declarations of type `name` are then read as of `type` (RAPID's
    /// alias of a data type).
    fn alias(&self, r: &'a str) -> Result<&'a str, nom::Err<PErr<'a>>> {
        let r = ws(r);
        let Ok((r, base)) = ident(r) else {
            return Err(self.err_found(self.pos(r), "expected a data type name after ALIAS"));
        };
        let r = ws(r);
        let Ok((r, name)) = ident(r) else {
            return Err(self.err_found(self.pos(r), "expected the alias name"));
        };
        let r = ws(r);
        let Some(r) = r.strip_prefix(';') else {
            return Err(self.err_after(self.pos(r), "expected `;` to end the ALIAS declaration"));
        };
        // An alias of an alias names the type the first one names.
        let base = self.type_of(base);
        self.aliases
            .borrow_mut()
            .push((name.to_ascii_lowercase(), base));
        Ok(r)
    }

    /// The type a declared type name stands for: an alias's type, else
    /// the name itself.
    fn type_of(&self, type_name: &str) -> String {
        let lower = type_name.to_ascii_lowercase();
        self.aliases
            .borrow()
            .iter()
            .find(|(a, _)| *a == lower)
            .map_or(type_name.to_string(), |(_, b)| b.clone())
    }

    /// A placeholder that stands alone for a statement or declaration
    /// (`<SMT>`, `<DDN>`, …), with its `;` when one follows on its line:
    /// the rest and its span. `None` when `i` starts otherwise, or when
    /// more code follows the placeholder on its line (`<VAR> := <EXP>;`).
    fn alone_placeholder(&self, i: &'a str) -> Option<(&'a str, Span)> {
        let p = placeholder_at(i)?;
        let start = self.pos(i);
        let after = i.get(p.len()..)?;
        let r = inline_ws(after);
        if let Some(r) = r.strip_prefix(';') {
            return Some((r, start..self.pos(r)));
        }
        let line_end = matches!(r.as_bytes().first(), None | Some(b'\r' | b'\n' | b'!'));
        line_end.then(|| (after, start..self.pos(after)))
    }

    /// `[LOCAL] RECORD name { type field; } ENDRECORD`; `i` starts at the
    /// first keyword, `r` just after `RECORD`.
    fn record(&self, i: &'a str, r: &'a str, scope: Scope) -> PResult<'a, Record> {
        let start = self.pos(i);
        let r = ws(r);
        let name = match ident(r) {
            Ok((_, name)) if name.eq_ignore_ascii_case("ENDRECORD") => None,
            Ok(found) => Some(found),
            Err(_) => None,
        };
        let Some((mut r, name)) = name else {
            return self.fail_found(self.pos(r), "expected a record name after RECORD");
        };
        let mut fields = Vec::new();
        loop {
            r = ws(r);
            if let Some(rest) = kw(r, "ENDRECORD") {
                return Ok((
                    rest,
                    Record {
                        scope,
                        name: name.to_string(),
                        fields,
                        span: start..self.pos(rest),
                        line: self.line_of(start),
                    },
                ));
            }
            let field_start = self.pos(r);
            if r.is_empty() || ends_routine(r) || kw(r, "RECORD").is_some() {
                return self.fail_found(
                    start,
                    &format!("unterminated RECORD {name}: expected ENDRECORD"),
                );
            }
            let Ok((r1, type_name)) = ident(r) else {
                return self.fail_found(field_start, "expected a field `type name;` or ENDRECORD");
            };
            let r1 = ws(r1);
            let Ok((r2, field)) = ident(r1) else {
                return self.fail_found(self.pos(r1), "expected a field name after its type");
            };
            let last = self.pos(r2);
            let Some(r3) = ws(r2).strip_prefix(';') else {
                return self.fail_after(last, &format!("expected `;` to end the field {field}"));
            };
            fields.push(Field {
                data_type: DataType::from_name(type_name),
                type_name: type_name.to_string(),
                name: field.to_string(),
                span: field_start..self.pos(r3),
            });
            r = r3;
        }
    }

    /// Gives the array sizes of `d` that are constant expressions their
    /// value from the `CONST num` declarations `before` it, and checks an
    /// array value against them.
    fn evaluate_dims(&self, d: &mut Decl, before: &[Decl]) -> Result<(), nom::Err<PErr<'a>>> {
        if d.dims.iter().all(|x| x.value.is_some()) {
            return Ok(());
        }
        for dim in &mut d.dims {
            if dim.value.is_none() {
                let text = self.src.get(dim.span.clone()).unwrap_or("");
                if let Some(v) = super::typed::const_int(text, before) {
                    match usize::try_from(v).ok().filter(|&n| n > 0) {
                        Some(n) => dim.value = Some(n),
                        None => {
                            return Err(
                                self.err_found(dim.span.start, "array size must be at least 1")
                            );
                        }
                    }
                }
            }
        }
        match &d.value {
            Some(value) => self.check_array(value, &d.dims),
            None => Ok(()),
        }
    }

    /// Checks that `value` and every array in it has the number of
    /// elements its size in `dims` gives (where known).
    fn check_array(&self, value: &DataValue, dims: &[Dim]) -> Result<(), nom::Err<PErr<'a>>> {
        let (Some((dim, inner)), DataValue::Array { span, items }) = (dims.split_first(), value)
        else {
            return Ok(());
        };
        if let Some(n) = dim.value.filter(|&n| n != items.len()) {
            return Err(self.err_found(
                span.start,
                &format!(
                    "array declared with {n} elements has {} in its value",
                    items.len()
                ),
            ));
        }
        items
            .iter()
            .try_for_each(|item| self.check_array(item, inner))
    }

    // ----- declarations ------------------------------------------------

    /// `[LOCAL|TASK] CONST|PERS|VAR type name[{n}] [:= value];` starting at `i`.
    pub(super) fn decl(&self, i: &'a str) -> PResult<'a, Decl> {
        let start = self.pos(i);
        let (scope, r) = scope_prefix(i);
        let r = ws(r);
        let Some((storage, r)) = storage_kw(r) else {
            return self.fail_found(self.pos(r), "expected CONST, PERS or VAR");
        };
        let r = ws(r);
        let Ok((r, type_name)) = ident_or_placeholder(r) else {
            return self.fail_found(self.pos(r), "expected a data type name");
        };
        let r = ws(r);
        let Ok((r, name)) = ident_or_placeholder(r) else {
            return self.fail_found(self.pos(r), "expected a data name");
        };
        let name_span = self.pos(r) - name.len()..self.pos(r);
        let mut last = self.pos(r);
        let mut r = ws(r);
        let mut dims = Vec::new();
        if let Some(d) = r.strip_prefix('{') {
            let mut d = d;
            loop {
                let d1 = ws(d);
                if d1.starts_with([',', '}']) {
                    return self.fail_found(self.pos(d1), "expected an array size inside `{…}`");
                }
                let (d2, span) = self.expr(d1, b",}")?;
                let text = self.src.get(span.clone()).unwrap_or("");
                let value = if !text.is_empty() && text.bytes().all(|b| b.is_ascii_digit()) {
                    match text.parse::<usize>().ok().filter(|&n| n > 0) {
                        Some(n) => Some(n),
                        None => {
                            return self.fail_found(span.start, "array size must be at least 1");
                        }
                    }
                } else {
                    None
                };
                dims.push(Dim { span, value });
                let d3 = ws(d2);
                if let Some(d4) = d3.strip_prefix(',') {
                    d = d4;
                } else if let Some(d4) = d3.strip_prefix('}') {
                    r = d4;
                    last = self.pos(r);
                    break;
                } else {
                    return self.fail_found(self.pos(d3), "expected `,` or `}` in array size");
                }
            }
            r = ws(r);
        }
        let data_type = if self.aliases.borrow().is_empty() {
            DataType::from_name(type_name)
        } else {
            DataType::from_name(&self.type_of(type_name))
        };
        let mut value = None;
        if let Some(v) = r.strip_prefix(":=") {
            let (v, val) = self.val(v, b",;")?;
            last = self.pos(v);
            value = Some(self.typed_value(&data_type, &dims, &val)?);
            r = ws(v);
        }
        let Some(r) = r.strip_prefix(';') else {
            return self.fail_after(
                last,
                &format!("expected `;` to end the declaration of {name}"),
            );
        };
        Ok((
            r,
            Decl {
                scope,
                storage,
                data_type,
                type_name: type_name.to_string(),
                name: name.to_string(),
                name_span,
                dims,
                value,
                span: start..self.pos(r),
                line: self.line_of(start),
            },
        ))
    }

    /// A generic value; `stops` are the bytes that end an expression at depth 0.
    pub(super) fn val(&self, i: &'a str, stops: &[u8]) -> PResult<'a, Val> {
        self.nested(i, |p| p.val_inner(i, stops))
    }

    /// The common robtarget literal `[[x,y,z],[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],
    /// [e1,…,e6]]` (numbers only, whitespace and comments anywhere) scanned
    /// directly, without the generic value tree: the same `RobTarget` and
    /// rest as [`Parser::val`] then `rob_target`. `None` for anything else
    /// (another shape, a name, an absurd number, a nesting limit in reach):
    /// the general path then parses it, or reports its error.
    fn scan_rob_target(&self, i: &'a str) -> Option<(&'a str, RobTarget)> {
        // `val` nests three levels for a robtarget's numbers.
        if self.depth.get() + 3 > MAX_NESTING {
            return None;
        }
        let i = ws(i);
        let start = self.pos(i);
        let mut r = i.strip_prefix('[')?;
        let group = |r: &mut &'a str, out: &mut [Number]| -> Option<()> {
            let mut at = ws(r).strip_prefix('[')?;
            let n = out.len();
            for (k, slot) in out.iter_mut().enumerate() {
                let i = ws(at);
                let (rest, value) = number_at(i)?;
                let after = ws(rest);
                if !value.is_finite() || value.abs() > MAX_NUMBER {
                    return None;
                }
                *slot = Number {
                    value,
                    span: self.pos(i)..self.pos(rest),
                };
                at = after.strip_prefix(if k + 1 < n { ',' } else { ']' })?;
            }
            *r = at;
            Some(())
        };
        let zero = || Number {
            value: 0.0,
            span: 0..0,
        };
        let mut trans: [Number; 3] = std::array::from_fn(|_| zero());
        let mut rot: [Number; 4] = std::array::from_fn(|_| zero());
        let mut robconf: [Number; 4] = std::array::from_fn(|_| zero());
        let mut extax: [Number; 6] = std::array::from_fn(|_| zero());
        group(&mut r, &mut trans)?;
        r = ws(r).strip_prefix(',')?;
        group(&mut r, &mut rot)?;
        r = ws(r).strip_prefix(',')?;
        group(&mut r, &mut robconf)?;
        r = ws(r).strip_prefix(',')?;
        group(&mut r, &mut extax)?;
        r = ws(r).strip_prefix(']')?;
        Some((
            r,
            RobTarget {
                span: start..self.pos(r),
                trans,
                rot,
                robconf,
                extax,
            },
        ))
    }

    /// Runs `f` one nesting level deeper, failing past [`MAX_NESTING`].
    fn nested<T>(&self, i: &'a str, f: impl FnOnce(&Self) -> PResult<'a, T>) -> PResult<'a, T> {
        let d = self.depth.get();
        if d >= MAX_NESTING {
            return self.fail_found(self.pos(ws(i)), "nested too deeply");
        }
        self.depth.set(d + 1);
        let out = f(self);
        self.depth.set(d);
        out
    }

    fn val_inner(&self, i: &'a str, stops: &[u8]) -> PResult<'a, Val> {
        let i = ws(i);
        let start = self.pos(i);
        if let Some(mut r) = i.strip_prefix('[') {
            let mut items = Vec::new();
            loop {
                let (r1, item) = self.val(r, b",]")?;
                items.push(item);
                let r2 = ws(r1);
                if let Some(r3) = r2.strip_prefix(',') {
                    r = r3;
                } else if let Some(r3) = r2.strip_prefix(']') {
                    return Ok((
                        r3,
                        Val::List {
                            span: start..self.pos(r3),
                            items,
                        },
                    ));
                } else {
                    return self.fail_found(self.pos(r2), "expected `,` or `]` in aggregate value");
                }
            }
        }
        if i.starts_with('"') {
            let (r, text) = self.string(i)?;
            return Ok((
                r,
                Val::Str {
                    span: start..self.pos(r),
                    text,
                },
            ));
        }
        let ends_here = |r: &str| {
            let r = ws(r);
            r.is_empty() || r.bytes().next().is_some_and(|b| stops.contains(&b))
        };
        if let Ok((r, t)) = number_text(i) {
            if ends_here(r) {
                let parsed = number_value(t);
                if parsed
                    .as_ref()
                    .is_some_and(|v| v.is_nan() || v.abs() > MAX_NUMBER)
                {
                    return self.fail_found(
                        start,
                        &format!(
                            "absurd number `{}` (|value| above 1e10; 9E9 marks an unused external axis)",
                            crate::error::clip(t)
                        ),
                    );
                }
                if let Some(value) = parsed.filter(|v| v.is_finite()) {
                    return Ok((
                        r,
                        Val::Num(Number {
                            value,
                            span: start..self.pos(r),
                        }),
                    ));
                }
            }
        }
        if let Ok((r, t)) = ident(i) {
            if ends_here(r) {
                return Ok((
                    r,
                    Val::Word {
                        span: start..self.pos(r),
                        text: t.to_string(),
                    },
                ));
            }
        }
        let (r, span) = self.expr(i, stops)?;
        Ok((r, Val::Expr { span }))
    }

    /// A string literal starting at `"`; `""` stands for one quote.
    fn string(&self, i: &'a str) -> PResult<'a, String> {
        let start = self.pos(i);
        let body = i.get(1..).unwrap_or("");
        let mut text = String::new();
        let mut rest = body;
        loop {
            match rest.find('"') {
                None => return self.fail_found(start, "unterminated string"),
                Some(k) => {
                    text.push_str(&rest[..k]);
                    let after = &rest[k + 1..];
                    if let Some(a) = after.strip_prefix('"') {
                        text.push('"');
                        rest = a;
                    } else {
                        return Ok((after, text));
                    }
                }
            }
        }
    }

    /// An expression up to (not including) a depth-0 byte in `stops`;
    /// returns its trimmed span. Fails when it is empty.
    pub(super) fn expr(&self, i: &'a str, stops: &[u8]) -> PResult<'a, Span> {
        let i = ws(i);
        let start = self.pos(i);
        let scan = self.scan(i, stops, &[], false)?;
        if scan.last == 0 {
            return self.fail_found(start, "expected a value");
        }
        let rest = i.get(scan.stop..).unwrap_or("");
        Ok((rest, start..start + scan.last))
    }

    /// Walks `i` skipping strings, comments and bracketed groups, and stops
    /// at the first depth-0 byte in `stops`, word in `words`, `:` (not `:=`)
    /// when `colon`, an unbalanced closing bracket, or the end of input. A
    /// new line that starts with a statement keyword means the statement
    /// lacks its `;`: that is reported after the last significant byte.
    fn scan(
        &self,
        i: &'a str,
        stops: &[u8],
        words: &[&str],
        colon: bool,
    ) -> Result<Scan, nom::Err<PErr<'a>>> {
        self.scan_continued(i, stops, words, colon, &[])
    }

    /// [`Parser::scan`], where a new line may also start with one of the
    /// words `continues` (a parameter list's `VAR`, `PERS`, `INOUT`).
    fn scan_continued(
        &self,
        i: &'a str,
        stops: &[u8],
        words: &[&str],
        colon: bool,
        continues: &[&str],
    ) -> Result<Scan, nom::Err<PErr<'a>>> {
        let b = i.as_bytes();
        let mut k = 0;
        let mut depth = 0usize;
        let mut last = 0;
        while let Some(&c) = b.get(k) {
            if depth == 0 && stops.contains(&c) {
                return Ok(Scan { stop: k, last });
            }
            match c {
                b'"' => {
                    let sub = i.get(k..).unwrap_or("");
                    let (r, _) = self.string(sub)?;
                    k = i.len() - r.len();
                    last = k;
                }
                b'!' => {
                    k = i
                        .get(k..)
                        .and_then(|s| s.find('\n'))
                        .map_or(i.len(), |p| k + p);
                }
                b'(' | b'[' | b'{' => {
                    depth += 1;
                    k += 1;
                    last = k;
                }
                b')' | b']' | b'}' => {
                    if depth == 0 {
                        return Ok(Scan { stop: k, last });
                    }
                    depth -= 1;
                    k += 1;
                    last = k;
                }
                b':' if depth == 0 && colon && b.get(k + 1) != Some(&b'=') => {
                    return Ok(Scan { stop: k, last });
                }
                b'\n' => {
                    let next = ws_inline(i.get(k + 1..).unwrap_or(""));
                    if STATEMENT_WORDS.iter().any(|w| kw(next, w).is_some())
                        && !continues.iter().any(|w| kw(next, w).is_some())
                    {
                        let pos = self.pos(i) + last;
                        return Err(self.err_after(pos, "missing `;` at the end of the statement"));
                    }
                    k += 1;
                }
                c if c.is_ascii_alphabetic() && (k == 0 || !is_ident_byte(b[k - 1])) => {
                    let sub = i.get(k..).unwrap_or("");
                    if depth == 0 && words.iter().any(|w| kw(sub, w).is_some()) {
                        return Ok(Scan { stop: k, last });
                    }
                    let n = sub.bytes().take_while(|&c| is_ident_byte(c)).count();
                    k += n.max(1);
                    last = k;
                }
                c if c.is_ascii_whitespace() => k += 1,
                _ => {
                    k += 1;
                    // Keep `last` on a char boundary for multi-byte characters.
                    while k < b.len() && !i.is_char_boundary(k) {
                        k += 1;
                    }
                    last = k;
                }
            }
        }
        Ok(Scan {
            stop: i.len(),
            last,
        })
    }

    // ----- routines ------------------------------------------------------

    fn routine(&self, i: &'a str, scope: Scope) -> PResult<'a, Proc> {
        let start = self.pos(i);
        let (_, r) = scope_prefix(i);
        let r = ws(r);
        let Some((kind, r)) = routine_kw(r) else {
            return self.fail_found(self.pos(r), "expected PROC, FUNC or TRAP");
        };
        let (word, end_word) = match kind {
            RoutineKind::Proc => ("PROC", "ENDPROC"),
            RoutineKind::Func => ("FUNC", "ENDFUNC"),
            RoutineKind::Trap => ("TRAP", "ENDTRAP"),
        };
        let mut r = ws(r);
        if kind == RoutineKind::Func {
            let Ok((r1, _)) = ident_or_placeholder(r) else {
                return self.fail_found(self.pos(r), "expected the return type after FUNC");
            };
            r = ws(r1);
        }
        let Ok((r1, name)) = ident_or_placeholder(r) else {
            return self.fail_found(
                self.pos(r),
                &format!("expected a routine name after {word}"),
            );
        };
        let mut r = ws(r1);
        let mut params = None;
        if let Some(p) = r.strip_prefix('(') {
            let scan = self.scan_continued(p, b")", &[], false, PARAMETER_WORDS)?;
            let p0 = self.pos(p);
            let rest = p.get(scan.stop..).unwrap_or("");
            let Some(rest) = rest.strip_prefix(')') else {
                return self.fail_found(self.pos(r), "unterminated parameter list");
            };
            params = Some(p0..p0 + scan.stop);
            r = rest;
        } else if kind != RoutineKind::Trap {
            return self.fail_found(self.pos(r), &format!("expected `(` after {word} {name}"));
        }
        let mut body = Vec::new();
        let mut ahead = self.parse_ahead(r);
        let mut next = 0;
        loop {
            r = ws(r);
            let here = self.pos(r);
            if r.is_empty() {
                return self.fail_found(
                    start,
                    &format!("unterminated {word} {name}: end of file reached without {end_word}"),
                );
            }
            if let Some(rest) = kw(r, end_word) {
                let span = start..self.pos(rest);
                let text = self.src.get(span.clone()).unwrap_or("");
                return Ok((
                    rest,
                    Proc {
                        kind,
                        scope,
                        name: name.to_string(),
                        params,
                        body,
                        span,
                        line: self.line_of(start),
                        placeholder: find_placeholder(text).is_some(),
                    },
                ));
            }
            if ends_routine(r) {
                return self.fail_found(
                    here,
                    &format!(
                        "expected {end_word} to close {word} {name} (line {})",
                        self.line_of(start)
                    ),
                );
            }
            // The statement parsed ahead at exactly this position, if any
            // (positions only grow), else parsed now.
            while ahead
                .get(next)
                .is_some_and(|a| a.as_ref().is_none_or(|(at, _, _)| *at < here))
            {
                next += 1;
            }
            let parsed = ahead
                .get_mut(next)
                .and_then(|slot| slot.take_if(|(at, _, _)| *at == here));
            let (rest, stmt) = match parsed {
                Some((_, end, stmt)) => (self.at(end), stmt),
                None => self.stmt(r)?,
            };
            body.push(stmt);
            r = rest;
        }
    }

    /// One statement of a routine body.
    fn stmt(&self, i: &'a str) -> PResult<'a, Stmt> {
        let start = self.pos(i);
        let line = self.line_of(start);
        let (_, r) = scope_prefix(i);
        if storage_kw(ws(r)).is_some() {
            let (r, d) = self.decl(i)?;
            return Ok((r, Stmt::Decl(Box::new(d))));
        }
        if let Some((instr, r)) = motion_at(i) {
            return match self.move_stmt(i, r, instr) {
                Ok((r, Some(m))) => Ok((r, Stmt::Move(Box::new(m)))),
                // Another version's form of a process instruction.
                Ok((r, None)) => Ok((
                    r,
                    Stmt::Opaque {
                        span: start..self.pos(r),
                        line,
                    },
                )),
                // An unfinished move (`MoveL <ARG>;`) is kept as written.
                Err(e) => self.opaque_with_placeholder(i).ok_or(e),
            };
        }
        if let Some((r, span)) = self.alone_placeholder(i) {
            return Ok((r, Stmt::Opaque { span, line }));
        }
        let control = |r: &'a str, keyword: &str| -> PResult<'a, Stmt> {
            Ok((
                r,
                Stmt::Control {
                    keyword: keyword.to_string(),
                    span: start..self.pos(r),
                    line,
                },
            ))
        };
        if let Some(r) = kw(i, "ERROR") {
            // An error handler for the listed error numbers only:
            // `ERROR (ERR_SOCK_TIMEOUT, ERR_SOCK_CLOSED)`.
            let r1 = inline_ws(r);
            if let Some(list) = r1.strip_prefix('(') {
                let after = self.error_list(list)?;
                return control(after, "ERROR");
            }
            return control(r, "ERROR");
        }
        for word in [
            "ELSE", "ENDIF", "ENDFOR", "ENDWHILE", "ENDTEST", "BACKWARD", "UNDO",
        ] {
            if let Some(r) = kw(i, word) {
                return control(r, word);
            }
        }
        // Headers that end at a keyword: `IF … THEN`, `ELSEIF … THEN`, `FOR … DO`, `WHILE … DO`.
        for (word, until) in [
            ("IF", "THEN"),
            ("ELSEIF", "THEN"),
            ("FOR", "DO"),
            ("WHILE", "DO"),
        ] {
            if let Some(r) = kw(i, word) {
                let scan = match self.scan(r, b";", &[until], false) {
                    Ok(scan) => scan,
                    Err(e) if word == "IF" => {
                        return self.compact_if_next_line(i, r).ok_or(e);
                    }
                    Err(e) => return Err(e),
                };
                let rest = r.get(scan.stop..).unwrap_or("");
                if let Some(after) = kw(rest, until) {
                    return control(after, word);
                }
                if let Some(after) = rest.strip_prefix(';') {
                    // A compact `IF cond stmt;`.
                    if let Some(found) = self.compact_if_move(i, r.get(..scan.stop).unwrap_or("")) {
                        return found;
                    }
                    return Ok((
                        after,
                        Stmt::Opaque {
                            span: start..self.pos(after),
                            line,
                        },
                    ));
                }
                let end = self.pos(r) + scan.last;
                return self.fail_after(end, &format!("expected {until} or `;` to end {word}"));
            }
        }
        if let Some(r) = kw(i, "TEST") {
            let n = r.find('\n').unwrap_or(r.len());
            let head = r.get(..n).unwrap_or("");
            let head = head.split('!').next().unwrap_or("").trim_end();
            return control(r.get(head.len()..).unwrap_or(""), "TEST");
        }
        for word in ["CASE", "DEFAULT"] {
            if let Some(r) = kw(i, word) {
                let scan = self.scan(r, b";", &[], true)?;
                let rest = r.get(scan.stop..).unwrap_or("");
                let Some(after) = rest.strip_prefix(':') else {
                    let end = self.pos(r) + scan.last;
                    return self.fail_after(end, &format!("expected `:` after {word}"));
                };
                return control(after, word);
            }
        }
        // A label `name:`.
        if let Ok((r, _)) = ident(i) {
            let r1 = inline_ws(r);
            if r1.starts_with(':') && !r1.starts_with(":=") {
                return control(&r1[1..], "LABEL");
            }
        }
        if let Some(found) = self.assignment(i, start, line) {
            return Ok(found);
        }
        // Anything else: up to its `;`.
        let scan = self.scan(i, b";", &[], false)?;
        let rest = i.get(scan.stop..).unwrap_or("");
        match rest.strip_prefix(';') {
            Some(after) => Ok((
                after,
                Stmt::Opaque {
                    span: start..self.pos(after),
                    line,
                },
            )),
            None if scan.last == 0 => self.fail_found(start, "unexpected text"),
            None => self.fail_after(start + scan.last, "missing `;` at the end of the statement"),
        }
    }

    /// An assignment `name[{index}][.field…] := value;` at `i` (its first
    /// byte at `start`, on `line`); `None` when `i` does not start with
    /// one, or when its end is not found (the statement is then read as
    /// any other, which reports the error).
    fn assignment(&self, i: &'a str, start: usize, line: usize) -> Option<(&'a str, Stmt)> {
        let (r, name) = ident(i).ok()?;
        let mut r = inline_ws(r);
        let mut index = None;
        if let Some(x) = r.strip_prefix('{') {
            let scan = self.scan(x, b"}", &[], false).ok()?;
            let after = x.get(scan.stop..)?.strip_prefix('}')?;
            let x0 = self.pos(ws(x));
            let x_end = (self.pos(x) + scan.last).max(x0);
            let text = self.src.get(x0..x_end)?.to_string();
            index = Some(Index {
                value: text.parse::<usize>().ok(),
                text,
                span: x0..x_end,
            });
            r = inline_ws(after);
        }
        let mut component = false;
        while let Some(f) = r.strip_prefix('.') {
            let (after, _) = ident(inline_ws(f)).ok()?;
            component = true;
            r = inline_ws(after);
        }
        let v = r.strip_prefix(":=")?;
        let scan = self.scan(v, b";", &[], false).ok()?;
        let after = v.get(scan.stop..)?.strip_prefix(';')?;
        let v0 = self.pos(ws(v));
        let end = self.pos(v) + scan.last;
        if end <= v0 {
            return None;
        }
        let value = match self.target(v, false) {
            Ok((rest, t)) if self.pos(ws(rest)) == self.pos(v) + scan.stop => t,
            _ => Target::Other {
                text: self.src.get(v0..end)?.to_string(),
                span: v0..end,
            },
        };
        let assign = Assign {
            name: name.to_string(),
            index,
            component,
            value,
            span: start..self.pos(after),
            line,
        };
        Some((after, Stmt::Assign(Box::new(assign))))
    }

    /// The list of error numbers of an `ERROR (…)` handler: names or
    /// integers separated by commas, at least one; `list` starts just after
    /// the `(`. Gives the text after the `)`.
    fn error_list(&self, list: &'a str) -> Result<&'a str, nom::Err<PErr<'a>>> {
        let mut r = list;
        loop {
            let item = ws(r);
            let n = digits(item.as_bytes());
            let after = if n > 0 {
                item.get(n..)
                    .filter(|t| !t.bytes().next().is_some_and(is_ident_byte))
            } else {
                ident(item).ok().map(|(t, _)| t)
            };
            let Some(after) = after else {
                return Err(self.err_found(
                    self.pos(item),
                    "expected an error number (a name or an integer) in the ERROR list",
                ));
            };
            let sep = ws(after);
            if let Some(t) = sep.strip_prefix(',') {
                r = t;
            } else if let Some(t) = sep.strip_prefix(')') {
                return Ok(t);
            } else {
                return Err(self.err_found(self.pos(sep), "expected `,` or `)` in the ERROR list"));
            }
        }
    }

    /// A compact `IF cond` whose one statement is on the next line
    /// (`IF bFlag` then `MoveL p1, v100, fine, tool0;`): a move whose
    /// `condition` is the `IF` line's code, or else one opaque statement.
    /// `i` starts at `IF`, `r` just after it. `None` unless the
    /// condition is the rest of the `IF` line and the next line holds a
    /// statement other than a control line.
    fn compact_if_next_line(&self, i: &'a str, r: &'a str) -> Option<(&'a str, Stmt)> {
        let start = self.pos(i);
        let line_end = r.find('\n')?;
        let head = r.get(..line_end)?;
        let code = head.get(..super::comment_start(head).unwrap_or(head.len()))?;
        if code.trim().is_empty() {
            return None;
        }
        let next = ws(r.get(line_end..)?);
        // One level deeper for each compact IF before the statement.
        let (rest, inner) = self.nested(next, |p| p.stmt(next)).ok()?;
        match inner {
            Stmt::Move(mut m) => {
                let end = self.pos(r) + code.trim_end_matches(is_blank_char).len();
                let end = m.condition.as_ref().map_or(end, |c| c.end);
                m.condition = Some(start..end);
                Some((rest, Stmt::Move(m)))
            }
            // A conditional assignment is kept whole, as written.
            Stmt::Opaque { .. } | Stmt::Assign(_) => Some((
                rest,
                Stmt::Opaque {
                    span: start..self.pos(rest),
                    line: self.line_of(start),
                },
            )),
            Stmt::Decl(_) | Stmt::Control { .. } => None,
        }
    }

    /// The move that is the statement of a compact `IF cond stmt;` on one
    /// line: `i` starts at `IF`, `text` is what follows it up to the `;`.
    /// `None` when the statement is not a move (the first word of code,
    /// outside strings and comments, that names a move instruction).
    fn compact_if_move(&self, i: &'a str, text: &'a str) -> Option<PResult<'a, Stmt>> {
        let base = self.pos(i) + 2;
        let b = text.as_bytes();
        let (mut k, mut in_string) = (0, false);
        while let Some(&c) = b.get(k) {
            if in_string || c == b'"' {
                in_string = (c == b'"') != in_string;
            } else if c == b'!' {
                k += text.get(k..)?.find('\n')?;
                continue;
            } else if c.is_ascii_alphabetic() && (k == 0 || !is_ident_byte(b[k - 1])) {
                let word = text.get(k..)?;
                if let Some((instr, _)) = motion_at(word) {
                    // From the source: `text` ends before the `;`.
                    let start = base + k;
                    let (at, r) = (self.at(start), self.at(start + instr.name.len()));
                    let (rest, mut m) = match self.move_stmt(at, r, instr) {
                        Ok((rest, Some(m))) => (rest, m),
                        // Another version's form of a process instruction, or
                        // an unfinished move, is kept as written, as the IF.
                        Ok((_, None)) => return None,
                        Err(_) if find_placeholder(word).is_some() => return None,
                        Err(e) => return Some(Err(e)),
                    };
                    let cond = text.get(..k).unwrap_or("").trim_end_matches(is_blank_char);
                    m.condition = Some(self.pos(i)..base + cond.len());
                    return Some(Ok((rest, Stmt::Move(Box::new(m)))));
                }
            }
            k += 1;
        }
        None
    }

    /// The statement at `i` up to its `;` as an opaque statement, when it
    /// holds an editor placeholder (an unfinished statement is kept as
    /// written).
    fn opaque_with_placeholder(&self, i: &'a str) -> Option<(&'a str, Stmt)> {
        let scan = self.scan(i, b";", &[], false).ok()?;
        let text = i.get(..scan.stop)?;
        find_placeholder(text)?;
        let rest = i.get(scan.stop..)?.strip_prefix(';')?;
        let start = self.pos(i);
        Some((
            rest,
            Stmt::Opaque {
                span: start..self.pos(rest),
                line: self.line_of(start),
            },
        ))
    }

    // ----- motion instructions -------------------------------------------

    /// A motion instruction; `i` starts at its name, `r` just after it.
    /// `None` for a well-formed statement of an instruction with
    /// [`MotionInstruction::other_forms`] whose positional arguments are
    /// not those of its row (another software version's form).
    fn move_stmt(
        &self,
        i: &'a str,
        mut r: &'a str,
        instr: &'static MotionInstruction,
    ) -> PResult<'a, Option<Move>> {
        let start = self.pos(i);
        let (name, kind) = (instr.name, instr.kind);
        // The arguments in their roles (more positional ones than the
        // instruction takes are only counted, for the error): no vectors.
        let mut via = None;
        let mut target = None;
        let (mut speed, mut zone, mut tool) = (None, None, None);
        let mut found = 0;
        let mut optional = Vec::new();
        loop {
            r = ws(r);
            if let Some(o) = r.strip_prefix('\\') {
                let (o, arg) = self.opt_arg(r, o, b",;\\")?;
                optional.push(arg);
                r = o;
            } else if r.starts_with([';', ',']) || r.is_empty() {
                return self.fail_found(self.pos(r), &format!("expected an argument of {name}"));
            } else {
                let role = (instr.args.get(found).copied(), kind == MoveKind::MoveAbsJ);
                let targets = [&mut via, &mut target];
                r = self.move_arg(r, role, targets, [&mut speed, &mut zone, &mut tool])?;
                found += 1;
            }
            let last = self.pos(r);
            let r1 = ws(r);
            if let Some(r2) = r1.strip_prefix(',') {
                r = r2;
            } else if r1.starts_with('\\') {
                r = r1;
            } else if let Some(r2) = r1.strip_prefix(';') {
                r = r2;
                break;
            } else {
                return self.fail_after(
                    last,
                    &format!("expected `,` or `;` after an argument of {name}"),
                );
            }
        }
        if found != instr.args.len() && instr.other_forms {
            return Ok((r, None));
        }
        if found != instr.args.len() {
            return self.fail_found(
                start,
                &format!(
                    "{name} takes {} arguments ({}), {found} given",
                    instr.args.len(),
                    instr.signature()
                ),
            );
        }
        let (Some(speed), Some(tool)) = (speed, tool) else {
            return self.fail_found(start, &format!("{name}: missing arguments"));
        };
        let Some(target) = target else {
            return self.fail_found(start, &format!("{name}: missing target"));
        };
        let value_of = |n: &str| -> Option<Arg> {
            optional
                .iter()
                .find(|o: &&OptArg| o.name.eq_ignore_ascii_case(n))
                .and_then(|o| o.value.clone())
        };
        let wobj = value_of("WObj");
        let tload = value_of("TLoad");
        let conc = optional.iter().any(|o| o.name.eq_ignore_ascii_case("Conc"));
        Ok((
            r,
            Some(Move {
                name,
                kind,
                via: via.map(Box::new),
                target,
                speed,
                zone,
                tool,
                wobj,
                tload,
                conc,
                optional,
                span: start..self.pos(r),
                line: self.line_of(start),
                condition: None,
            }),
        ))
    }

    /// One positional argument of a motion instruction, stored by its
    /// `role` (`None` past the last one: parsed and dropped); `joint` for
    /// a jointtarget. `targets` are the via and the target; `plain` the
    /// speed, zone and tool.
    fn move_arg(
        &self,
        r: &'a str,
        (role, joint): (Option<Role>, bool),
        targets: [&mut Option<Target>; 2],
        plain: [&mut Option<Arg>; 3],
    ) -> Result<&'a str, nom::Err<PErr<'a>>> {
        let [via, target] = targets;
        let slot = match role {
            Some(Role::CirPoint) => via,
            Some(Role::ToPoint) => target,
            _ => {
                let (o, span) = self.expr(r, b",;\\")?;
                let [speed, zone, tool] = plain;
                let slot = match role {
                    Some(Role::Speed) => speed,
                    Some(Role::Zone) => zone,
                    Some(Role::Tool) => tool,
                    _ => return Ok(o),
                };
                *slot = Some(Arg {
                    text: self.text(span.clone()),
                    span,
                });
                return Ok(o);
            }
        };
        let (o, t) = self.target(r, joint)?;
        *slot = Some(t);
        Ok(o)
    }

    /// `\Name[:=value]`; `i` starts at the backslash, `o` after it.
    fn opt_arg(&self, i: &'a str, o: &'a str, stops: &[u8]) -> PResult<'a, OptArg> {
        let start = self.pos(i);
        let Ok((o, name)) = ident(o) else {
            return self.fail_found(self.pos(o), "expected an optional argument name after `\\`");
        };
        let mut end = self.pos(o);
        let mut value = None;
        let o1 = ws(o);
        let o = if let Some(v) = o1.strip_prefix(":=") {
            let (v, span) = self.expr(v, stops)?;
            end = span.end;
            value = Some(Arg {
                text: self.text(span.clone()),
                span,
            });
            v
        } else {
            o
        };
        Ok((
            o,
            OptArg {
                name: name.to_string(),
                value,
                span: start..end,
            },
        ))
    }

    /// A move target: inline literal, `Offs(…)`, `RelTool(…)`, a name with
    /// an optional `{index}`, or any other expression.
    fn target(&self, i: &'a str, joint: bool) -> PResult<'a, Target> {
        self.nested(i, |p| p.target_inner(i, joint))
    }

    fn target_inner(&self, i: &'a str, joint: bool) -> PResult<'a, Target> {
        let i = ws(i);
        let start = self.pos(i);
        let terminated = |r: &str| {
            let r = ws(r);
            r.is_empty() || r.starts_with([',', ';', '\\', ')'])
        };
        if i.starts_with('[') {
            if !joint {
                if let Some((r, rt)) = self.scan_rob_target(i) {
                    return Ok((r, Target::Inline(rt)));
                }
            }
            let (r, v) = self.val(i, b",]")?;
            let t = if joint {
                Target::InlineJoint(self.joint_target(&v)?)
            } else {
                Target::Inline(self.rob_target(&v)?)
            };
            return Ok((r, t));
        }
        for (word, rel) in [("Offs", false), ("RelTool", true)] {
            if let Some(r) = kw(i, word) {
                let r = ws(r);
                if let Some(r) = r.strip_prefix('(') {
                    return self.offs(start, r, word, rel, joint);
                }
            }
        }
        if let Ok((r, name)) = ident(i) {
            let mut end = self.pos(r);
            let mut index = None;
            let mut rest = r;
            let r1 = ws(r);
            if let Some(x) = r1.strip_prefix('{') {
                let scan = self.scan(x, b"}", &[], false)?;
                let after = x.get(scan.stop..).unwrap_or("");
                if let Some(after) = after.strip_prefix('}') {
                    let x0 = self.pos(ws(x));
                    let x_end = self.pos(x) + scan.last;
                    let text = self.src.get(x0..x_end.max(x0)).unwrap_or("").to_string();
                    index = Some(Index {
                        value: text.parse::<usize>().ok(),
                        text,
                        span: x0..x_end.max(x0),
                    });
                    rest = after;
                    end = self.pos(after);
                }
            }
            if terminated(rest) {
                return Ok((
                    rest,
                    Target::Named {
                        name: name.to_string(),
                        index,
                        span: start..end,
                    },
                ));
            }
        }
        let (r, span) = self.expr(i, b",;\\")?;
        Ok((
            r,
            Target::Other {
                text: self.src.get(span.clone()).unwrap_or("").to_string(),
                span,
            },
        ))
    }

    /// The arguments of `Offs(` / `RelTool(`; `r` is just after the `(`.
    fn offs(
        &self,
        start: usize,
        r: &'a str,
        word: &str,
        rel: bool,
        joint: bool,
    ) -> PResult<'a, Target> {
        let (r, base) = self.target(r, joint)?;
        let mut r = r;
        let mut scalars = Vec::new();
        for _ in 0..3 {
            let r1 = ws(r);
            let Some(r2) = r1.strip_prefix(',') else {
                return self.fail_found(
                    self.pos(r1),
                    &format!("{word} takes a point and three offsets dx, dy, dz: expected `,`"),
                );
            };
            let (r3, s) = self.scalar(r2, b",)\\")?;
            scalars.push(s);
            r = r3;
        }
        let (mut rx, mut ry, mut rz) = (None, None, None);
        loop {
            let r1 = ws(r);
            let r1 = if rel {
                r1.strip_prefix(',').map(ws).unwrap_or(r1)
            } else {
                r1
            };
            if let Some(a) = r1.strip_prefix(')') {
                r = a;
                break;
            }
            if rel {
                if let Some(o) = r1.strip_prefix('\\') {
                    let Ok((o, name)) = ident(o) else {
                        return self.fail_found(self.pos(o), "expected Rx, Ry or Rz after `\\`");
                    };
                    let o = ws(o);
                    let Some(o) = o.strip_prefix(":=") else {
                        return self
                            .fail_found(self.pos(o), &format!("expected `:=` after \\{name}"));
                    };
                    let (o, s) = self.scalar(o, b",)\\")?;
                    let slot = match name.to_ascii_lowercase().as_str() {
                        "rx" => &mut rx,
                        "ry" => &mut ry,
                        "rz" => &mut rz,
                        _ => {
                            return self.fail_found(
                                self.pos(r1),
                                "RelTool accepts only the optional arguments \\Rx, \\Ry, \\Rz",
                            );
                        }
                    };
                    *slot = Some(s);
                    r = o;
                    continue;
                }
            }
            return self.fail_found(self.pos(r1), &format!("expected `)` to close {word}"));
        }
        let [dx, dy, dz]: [Scalar; 3] = match scalars.try_into() {
            Ok(a) => a,
            Err(_) => return self.fail_found(start, &format!("{word}: three offsets expected")),
        };
        let span = start..self.pos(r);
        let offsets = [dx, dy, dz];
        let base = Box::new(base);
        let t = if rel {
            Target::RelTool {
                base,
                offsets,
                rx,
                ry,
                rz,
                span,
            }
        } else {
            Target::Offs {
                base,
                offsets,
                span,
            }
        };
        Ok((r, t))
    }

    fn scalar(&self, i: &'a str, stops: &[u8]) -> PResult<'a, Scalar> {
        let (r, span) = self.expr(i, stops)?;
        let text = self.src.get(span.clone()).unwrap_or("").to_string();
        Ok((
            r,
            Scalar {
                value: parse_number(&text),
                text,
                span,
            },
        ))
    }
}

/// An identifier, or an editor placeholder standing for one (`<ID>`).
fn ident_or_placeholder(i: &str) -> PResult<'_, &str> {
    match placeholder_at(i) {
        Some(p) => match (i.get(p.len()..), i.get(..p.len())) {
            (Some(rest), Some(word)) => Ok((rest, word)),
            _ => Err(no_match(i)),
        },
        None => ident(i),
    }
}

/// Skips spaces and tabs only.
fn inline_ws(i: &str) -> &str {
    i.trim_start_matches([' ', '\t'])
}

/// Skips blank characters (not comments) at the start of a line.
fn ws_inline(i: &str) -> &str {
    i.trim_start_matches([' ', '\t', '\r'])
}

fn scope_prefix(i: &str) -> (Scope, &str) {
    if let Some(r) = kw(i, "LOCAL") {
        (Scope::Local, r)
    } else if let Some(r) = kw(i, "TASK") {
        (Scope::Task, r)
    } else {
        (Scope::Global, i)
    }
}

fn storage_kw(i: &str) -> Option<(Storage, &str)> {
    kw(i, "CONST")
        .map(|r| (Storage::Const, r))
        .or_else(|| kw(i, "PERS").map(|r| (Storage::Pers, r)))
        .or_else(|| kw(i, "VAR").map(|r| (Storage::Var, r)))
}

/// True when `t` (at a token) ends a routine body: a routine or module end,
/// or the header of the next routine.
/// The candidate statement starts of a routine body for
/// [`Parser::parse_ahead`]: `body_start` (its first statement) and every
/// line start after `from` whose last significant byte before it (outside
/// strings and `!` comments) is a `;` at bracket depth 0, up to the first
/// line that opens with a routine or module end; with the byte where the
/// scan stopped. A function of its own, not inlined: the byte loop keeps
/// its state in registers instead of the parser's frame.
#[inline(never)]
fn statement_starts(src: &str, from: usize, body_start: usize) -> (Vec<usize>, usize) {
    let mut starts = vec![body_start];
    let (mut depth, mut in_string, mut closed, mut at_line_start) = (0usize, false, false, false);
    let mut k = from;
    let bytes = src.as_bytes();
    while let Some(&b) = bytes.get(k) {
        if at_line_start {
            at_line_start = false;
            // The line's first token, if it has one (blank and comment
            // lines are passed over byte by byte below).
            let t = src
                .get(k..)
                .unwrap_or("")
                .trim_start_matches([' ', '\t', '\r']);
            if !matches!(t.as_bytes().first(), None | Some(b'!' | b'\n')) {
                if ends_routine(t) {
                    break;
                }
                let at = src.len() - t.len();
                if closed && at > starts.last().copied().unwrap_or(0) {
                    starts.push(at);
                }
            }
        }
        match b {
            b'\n' => {
                // Strings do not span lines.
                in_string = false;
                at_line_start = true;
            }
            b'"' => {
                in_string = !in_string;
                closed = false;
            }
            _ if in_string => {}
            b'!' => {
                // A comment to the end of the line.
                k = bytes
                    .get(k..)
                    .and_then(|t| memchr::memchr(b'\n', t))
                    .map_or(bytes.len(), |n| k + n);
                continue;
            }
            b'[' | b'(' | b'{' => {
                depth += 1;
                closed = false;
            }
            b']' | b')' | b'}' => {
                depth = depth.saturating_sub(1);
                closed = false;
            }
            b';' => closed = depth == 0,
            b' ' | b'\t' | b'\r' => {}
            _ => closed = false,
        }
        k += 1;
    }
    (starts, k)
}

fn ends_routine(t: &str) -> bool {
    let (_, after_scope) = scope_prefix(t);
    ["ENDMODULE", "ENDPROC", "ENDFUNC", "ENDTRAP", "ENDRECORD"]
        .iter()
        .any(|w| kw(t, w).is_some())
        || routine_kw(ws(after_scope)).is_some()
        || kw(ws(after_scope), "RECORD").is_some()
}

fn routine_kw(i: &str) -> Option<(RoutineKind, &str)> {
    kw(i, "PROC")
        .map(|r| (RoutineKind::Proc, r))
        .or_else(|| kw(i, "FUNC").map(|r| (RoutineKind::Func, r)))
        .or_else(|| kw(i, "TRAP").map(|r| (RoutineKind::Trap, r)))
}

/// The first `n` characters of `s`, with `…` when cut.
fn clip(s: &str, n: usize) -> String {
    let mut out: String = s.chars().take(n).collect();
    if s.chars().count() > n {
        out.push('…');
    }
    out
}

/// The last `n` characters of `s`, with `…` when cut.
fn clip_end(s: &str, n: usize) -> String {
    let count = s.chars().count();
    if count <= n {
        return s.to_string();
    }
    let tail: String = s.chars().skip(count - n).collect();
    format!("…{tail}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Moves that repeat an argument text share one allocation of it (in
    /// the parse ahead, within each parallel task), and the texts read as
    /// written.
    #[test]
    fn repeated_argument_texts_are_shared() {
        for ahead_min in [usize::MAX, 0] {
            let mut src = String::from("MODULE M\n  PROC main()\n");
            for k in 0..40 {
                let speed = if k % 2 == 0 { "v100" } else { "V200" };
                src += &format!("    MoveL p{k},{speed},z1,tool1\\WObj:=wobj1;\n");
            }
            src += "  ENDPROC\nENDMODULE\n";
            let m = Parser::with_ahead_min(&src, "m.mod", ahead_min)
                .parse()
                .unwrap();
            let moves: Vec<&crate::program::rapid::Move> = m.moves().collect();
            assert_eq!(moves.len(), 40);
            for (k, mv) in moves.iter().enumerate() {
                assert_eq!(&*mv.tool.text, "tool1");
                assert_eq!(&*mv.zone.as_ref().unwrap().text, "z1");
                assert_eq!(&*mv.speed.text, if k % 2 == 0 { "v100" } else { "V200" });
                assert_eq!(mv.wobj.as_ref().map(|w| &*w.text), Some("wobj1"));
            }
            if ahead_min == usize::MAX {
                let (a, b) = (moves[10], moves[30]);
                assert!(Arc::ptr_eq(&a.tool.text, &b.tool.text));
                assert!(Arc::ptr_eq(
                    &a.zone.as_ref().unwrap().text,
                    &b.zone.as_ref().unwrap().text
                ));
                assert!(Arc::ptr_eq(&a.speed.text, &b.speed.text));
                let wobj =
                    |m: &crate::program::rapid::Move| m.wobj.as_ref().map(|w| Arc::clone(&w.text));
                assert!(matches!((wobj(a), wobj(b)), (Some(x), Some(y)) if Arc::ptr_eq(&x, &y)));
            }
        }
    }

    proptest::proptest! {
        /// The fast path of [`number_value`] against `str::parse`: the same
        /// f64 bits (or the same failure) for literals of every shape the
        /// lexer accepts, short and long, with and without exponents.
        #[test]
        fn number_value_equals_str_parse(
            sign in proptest::sample::select(vec!["", "+", "-"]),
            int in "[0-9]{0,20}",
            frac in proptest::option::of("[0-9]{0,20}"),
            exp in proptest::option::of((proptest::sample::select(vec!["e", "E"]),
                proptest::sample::select(vec!["", "+", "-"]), "[0-9]{1,4}")),
        ) {
            let mut t = format!("{sign}{int}");
            if let Some(f) = &frac {
                t.push('.');
                t.push_str(f);
            }
            if let Some((e, s, d)) = &exp {
                t.push_str(e);
                t.push_str(s);
                t.push_str(d);
            }
            if let Ok(("", lexed)) = number_text(&t) {
                let fast = number_value(lexed).map(f64::to_bits);
                let slow = lexed.parse::<f64>().ok().map(f64::to_bits);
                proptest::prop_assert_eq!(fast, slow, "{}", lexed);
            }
        }

        /// The one-pass [`number_at`] against [`number_text`] then
        /// [`number_value`]: the same rest and f64 bits (or the same
        /// failure) for literals of every shape followed by any text.
        #[test]
        fn number_at_equals_text_then_value(
            text in "[-+]?[0-9]{0,18}(\\.[0-9]{0,18})?([eE][-+]?[0-9]{0,6})?",
            tail in "[ ,\\].eE0-9a-z+-]{0,3}",
        ) {
            let t = format!("{text}{tail}");
            let fused = number_at(&t).map(|(r, v)| (r, v.to_bits()));
            let split = number_text(&t)
                .ok()
                .and_then(|(r, lexed)| number_value(lexed).map(|v| (r, v.to_bits())));
            proptest::prop_assert_eq!(fused, split, "{}", t);
        }

        /// The byte scan of [`ws`] against `trim_start_matches`: the same
        /// rest for any mix of blanks, byte-order marks, comments and text.
        #[test]
        fn ws_equals_the_trim_reference(
            parts in proptest::collection::vec(
                proptest::sample::select(vec![
                    " ", "\t", "\r", "\n", "\u{feff}", "! note", "!", "x", "[1,", "é", "\u{a0}",
                ]),
                0..12,
            )
        ) {
            let text: String = parts.concat();
            proptest::prop_assert_eq!(ws(&text), ws_reference(&text));
        }
    }

    /// The direct robtarget scanner against the generic value tree: the same
    /// literal and rest wherever it accepts, and it declines every other
    /// shape (which the general path then parses or reports).
    #[test]
    fn robtarget_scanner_equals_the_value_tree() {
        let accepted = [
            "[[650.0,50.0,300.0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200",
            "[ [ -1.5e-3 , +2 , .5 ] ,[1,0,0,0],[-1,0,-2,5],[9E+09,9e9,0,0,0,0]] ;",
            "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9] ! comment\n ]\n,v1",
            "[[1,2,3],\r\n  [0.7071068,0,0.7071068,0],[0,0,0,1],[1,2,3,4,5,6]]",
            "[[0,0,0],[1,0,0,0],[0,0,0,0],[1e10,-1e10,0,0,0,0]]",
        ];
        let declined = [
            "[[1,2],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]",
            "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9]]",
            "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9],[1]]",
            "[[x,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]",
            "[[1+1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]",
            "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E99,9E9,9E9,9E9,9E9,9E9]]",
            "[[1,2,3],[1,0,0,0],[0,0,0,0],[1e400,9E9,9E9,9E9,9E9,9E9]]",
            "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]",
            "[[1,2,3][1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]",
            "[p1,[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]",
        ];
        for text in accepted.iter().chain(&declined) {
            let p = Parser::new(text, "t.mod");
            let fast = p.scan_rob_target(text);
            let slow = p
                .val(text, b",]")
                .ok()
                .and_then(|(r, v)| p.rob_target(&v).ok().map(|rt| (r, rt)));
            if accepted.contains(text) {
                assert!(fast.is_some(), "scanner declined {text}");
                assert_eq!(fast, slow, "{text}");
            } else {
                assert!(fast.is_none(), "scanner accepted {text}");
            }
        }
    }

    /// Parsing ahead changes nothing: the module (or the error) is the one
    /// of the serial parse, for the repository's modules, the bad-input
    /// corpus, generated bodies with statements over several lines,
    /// comments, control lines, local declarations, several routines and
    /// errors at many places, and, when `POSTPROC_RAPID_CORPUS` names a
    /// folder (the fuzz corpus, say), every file in it.
    #[test]
    fn parsing_ahead_gives_the_serial_result() {
        let check = |text: &str, name: &str| {
            let serial = Parser::with_ahead_min(text, "t.mod", usize::MAX).parse();
            let ahead = Parser::with_ahead_min(text, "t.mod", 0).parse();
            assert_eq!(serial, ahead, "{name}");
            serial.is_ok()
        };
        let root = concat!(env!("CARGO_MANIFEST_DIR"), "/");
        let mut files = vec![
            format!("{root}samples/drilling.mod"),
            format!("{root}samples/milling.mod"),
        ];
        for dir in [
            format!("{root}tests/bad/programs"),
            std::env::var("POSTPROC_RAPID_CORPUS").unwrap_or_default(),
        ] {
            if let Ok(entries) = std::fs::read_dir(&dir) {
                for e in entries.flatten() {
                    files.push(e.path().display().to_string());
                }
            }
        }
        let mut parsed = 0;
        for f in &files {
            if let Ok(bytes) = std::fs::read(f) {
                if let Ok(text) = std::str::from_utf8(&bytes) {
                    check(text, f);
                    parsed += 1;
                }
            }
        }
        assert!(parsed >= 2);
        let mut rnd = crate::machine::robot::test_sequence(5);
        let pieces = [
            "    MoveL [[650.0,50.0,300.0],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tool0;\n",
            "    MoveL [[650.0,50.0,300.0],[0,0,1,0],\n      [0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v200,z1,tool0;\n",
            "    MoveJ p10,v100,fine,tool0\\WObj:=wobj0;\n",
            "    MoveC Offs(p10,1,2,3),RelTool(p20,0,0,5\\Rz:=10),v100,z5,tool0;\n",
            "    ! a comment ; with MoveL in it\n",
            "\n",
            "    IF a > 1 THEN\n",
            "    ENDIF\n",
            "    FOR i FROM 1 TO 3 DO\n      MoveL p{i},v10,z1,tool0;\n    ENDFOR\n",
            "    TPWrite \"MoveL; ENDPROC\";\n",
            "    VAR num k := 2;\n",
            "    MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,tool0; ! done\n",
            "    MoveL [[1,2,3],[1,0,0,0]],v100,z1,tool0;\n",
            "    MoveL [[1,2,3,[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,z1,tool0;\n",
            "    MoveAbsJ [[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]],v100,fine,tool0;\n",
            "    MoveL p1,\n      v100,\n      z1,\n      tool0;\n",
            "    IF a > 1\n      MoveL p1,v100,z1,tool0;\n",
            "    IF a > 1\n      SetDO do1, 1;\n",
            "  ERROR (ERR_A,\n    ERR_B)\n",
            "    <SMT>\n",
            "    MoveL <EXP>, v100, z1, tool0;\n",
            "    VAR robtarget buf{MAX_N + 1};\n",
        ];
        let mut outcomes = [0usize; 2];
        for case in 0..60 {
            let mut text = String::from(
                "MODULE T\n  CONST robtarget p10 := [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n",
            );
            for routine in 0..1 + case % 3 {
                text.push_str(&format!("  PROC r{routine}()\n"));
                for _ in 0..(rnd().abs() * 40.0) as usize {
                    let k = ((rnd().abs() * pieces.len() as f64) as usize).min(pieces.len() - 1);
                    // The two malformed pieces only now and then.
                    if (k == 12 || k == 13) && case % 4 != 0 {
                        continue;
                    }
                    text.push_str(pieces[k]);
                }
                text.push_str("  ENDPROC\n");
            }
            if case % 7 != 3 {
                text.push_str("ENDMODULE\n");
            }
            outcomes[usize::from(check(&text, &format!("case {case}:\n{text}")))] += 1;
        }
        // Both well-formed modules and errors were compared.
        assert!(outcomes[0] > 5 && outcomes[1] > 5, "{outcomes:?}");
    }

    /// Candidates for parsing ahead follow a `;` at bracket depth 0, not
    /// every line start: a statement of many lines (a local array of one
    /// number per line) would otherwise be parsed from each of its lines to
    /// its end, quadratic in its length. Here the candidates are the first
    /// statement and the one after the array, and the module is the serial
    /// one.
    #[test]
    fn parsing_ahead_tries_each_statement_once() {
        let mut text = String::from("MODULE T\n  PROC main()\n    VAR num a{20000} := [\n");
        for k in 0..20000 {
            text.push_str(&format!(
                "      {k}.5{}\n",
                if k < 19999 { "," } else { "];" }
            ));
        }
        text.push_str("    MoveL p1,v100,z1,tool0;\n    ! done\n  ENDPROC\nENDMODULE\n");
        let p = Parser::with_ahead_min(&text, "t.mod", 0);
        let body = text.find("    VAR").unwrap_or(0);
        let ahead = p.parse_ahead(p.at(body));
        assert_eq!(ahead.len(), 2);
        assert!(ahead.iter().all(Option::is_some));
        assert_eq!(
            p.parse(),
            Parser::with_ahead_min(&text, "t.mod", usize::MAX).parse()
        );
    }
}
