//! KRL syntax with spans: one [`Line`] per source line of a `.src`, `.dat`
//! or `$config.dat` file, each classified, every aggregate with the byte
//! span of each of its numbers (a writer replaces just those bytes).
//!
//! Line-oriented as KRL is: a statement never spans lines. Keywords are
//! case-insensitive; `;` starts a comment outside a string, except the
//! fold markers `;FOLD` and `;ENDFOLD`, which are lines of their own.

use std::ops::Range;

use crate::error::Located;

/// A byte range into the source.
pub type Span = Range<usize>;

/// A numeric literal: its value and the span of its text (sign included).
#[derive(Debug, Clone, PartialEq)]
pub struct Number {
    /// The value.
    pub value: f64,
    /// The literal's bytes.
    pub span: Span,
}

/// One value of an aggregate field.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    /// A number.
    Number(Number),
    /// A bit string `'B010'` (Status/Turn written in binary): its value.
    Bits(u32, Span),
    /// A nested aggregate.
    Aggregate(Aggregate),
    /// Anything else (`#CDIS`, `TRUE`, `" "`, a name): its text.
    Word(Span),
}

/// `{X 1.0, Y 2.0, …}` or `{E6POS: X 1.0, …}`.
#[derive(Debug, Clone, PartialEq)]
pub struct Aggregate {
    /// The type named before a colon inside the braces, if any.
    pub type_name: Option<String>,
    /// Fields in source order: upper-cased name and value.
    pub fields: Vec<(String, Value)>,
    /// From `{` to `}`.
    pub span: Span,
}

impl Aggregate {
    /// The value of field `name` (upper case).
    pub fn get(&self, name: &str) -> Option<&Value> {
        self.fields.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
    /// The number of field `name`.
    pub fn number(&self, name: &str) -> Option<&Number> {
        match self.get(name) {
            Some(Value::Number(n)) => Some(n),
            _ => None,
        }
    }
    /// An integer field written as a number or a bit string (`S 6`,
    /// `S 'B110'`).
    pub fn bits(&self, name: &str) -> Option<u32> {
        match self.get(name)? {
            Value::Number(n) if n.value >= 0.0 && n.value.fract() == 0.0 => Some(n.value as u32),
            Value::Bits(b, _) => Some(*b),
            _ => None,
        }
    }
}

/// The motion keywords.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// `PTP`
    Ptp,
    /// `LIN`
    Lin,
    /// `CIRC`
    Circ,
    /// `SPTP` (KSS 8 spline PTP)
    Sptp,
    /// `SLIN`
    Slin,
    /// `SCIRC`
    Scirc,
}

impl Motion {
    fn from_word(w: &str) -> Option<Motion> {
        Some(match w.to_ascii_uppercase().as_str() {
            "PTP" => Motion::Ptp,
            "LIN" => Motion::Lin,
            "CIRC" => Motion::Circ,
            "SPTP" => Motion::Sptp,
            "SLIN" => Motion::Slin,
            "SCIRC" => Motion::Scirc,
            _ => return None,
        })
    }
    /// Whether this motion has an auxiliary point before its end point.
    pub fn is_circular(self) -> bool {
        matches!(self, Motion::Circ | Motion::Scirc)
    }
}

/// A motion's target.
#[derive(Debug, Clone, PartialEq)]
pub enum Target {
    /// A variable (`XP1`, `HOME`, `XPALLET[3]`): its text.
    Named(String, Span),
    /// An inline aggregate.
    Aggregate(Aggregate),
}

/// An inline form's description on its `;FOLD` line
/// (`PTP P1 CONT Vel=100 % PDAT1 Tool[1] Base[2]`).
#[derive(Debug, Clone, PartialEq)]
pub struct InlineForm {
    /// The motion.
    pub motion: Motion,
    /// Point names: the end point, or the auxiliary and end points of a
    /// circle.
    pub points: Vec<String>,
    /// `CONT` given (approximated).
    pub cont: bool,
    /// `Vel=` value and its unit (`%`, `m/s`).
    pub vel: Option<(Number, String)>,
    /// The motion data set (`PDAT1`, `CPDAT2`).
    pub data: Option<String>,
    /// `Tool[n]`, `Base[n]`.
    pub tool: Option<u32>,
    /// See `tool`.
    pub base: Option<u32>,
}

/// What a line holds.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    /// Empty or comment only.
    Blank,
    /// `&ACCESS RVP`, `&REL 12`, `&PARAM …`: the word and its text.
    Header(String, Span),
    /// `DEF name(…)` / `GLOBAL DEF` / `DEFFCT type name(…)`.
    Def(String),
    /// `END` / `ENDFCT`.
    End,
    /// `DEFDAT name [PUBLIC]`.
    DefDat(String),
    /// `ENDDAT`.
    EndDat,
    /// `;FOLD text`, with its inline form when it describes a motion.
    Fold(Span, Option<InlineForm>),
    /// `;ENDFOLD`.
    EndFold,
    /// `DECL [GLOBAL] [CONST] TYPE name[[n]] [= value]`, also without
    /// `DECL` for the data types of [`DATA_TYPES`].
    Decl {
        /// Upper-cased type.
        type_name: String,
        /// The name as written (index text left off).
        name: String,
        /// The initial aggregate, if any.
        value: Option<Aggregate>,
    },
    /// A motion statement (`PTP XP1 C_PTP`, `CIRC XAUX, XEND`).
    Move {
        /// The keyword.
        motion: Motion,
        /// The auxiliary point of a circle.
        aux: Option<Target>,
        /// The end point.
        target: Target,
        /// The rest (approximation `C_DIS`, `WITH …`), as written.
        rest: Span,
    },
    /// `$BASE = …`, `$TOOL = …`, `TOOL_DATA[1] = {…}`: the target's text and
    /// the value's aggregate when it is one.
    Assign(String, Option<Aggregate>, Span),
    /// Any other statement, kept as written.
    Other,
}

/// The data types a `.dat` may declare without `DECL`.
pub const DATA_TYPES: [&str; 10] = [
    "E6POS", "POS", "FRAME", "E6AXIS", "AXIS", "PDAT", "LDAT", "FDAT", "LOAD", "INT",
];

/// One source line.
#[derive(Debug, Clone, PartialEq)]
pub struct Line {
    /// 1-based line number.
    pub number: usize,
    /// The line's bytes without its end of line.
    pub span: Span,
    /// What it holds.
    pub kind: Kind,
}

/// A parsed KRL file.
#[derive(Debug, Clone, PartialEq)]
pub struct File {
    /// Every line, in order.
    pub lines: Vec<Line>,
}

/// Parses a KRL file; `name` is used in error messages.
pub fn parse(src: &str, name: &str) -> Result<File, Located> {
    let mut lines = Vec::new();
    let mut start = 0;
    for (i, raw) in src.split_inclusive('\n').enumerate() {
        let text = raw.trim_end_matches(['\n', '\r']);
        let mut p = LineParser {
            base: start,
            text,
            pos: 0,
            file: name,
            line: i + 1,
        };
        let kind = p.line()?;
        lines.push(Line {
            number: i + 1,
            span: start..start + text.len(),
            kind,
        });
        start += raw.len();
    }
    Ok(File { lines })
}

struct LineParser<'a> {
    base: usize,
    text: &'a str,
    pos: usize,
    file: &'a str,
    line: usize,
}

impl<'a> LineParser<'a> {
    fn err(&self, what: &str) -> Located {
        Located::new(
            self.file,
            self.line,
            self.pos + 1,
            format!("{what}: `{}`", self.text.trim()),
        )
    }

    fn rest(&self) -> &'a str {
        &self.text[self.pos..]
    }

    fn skip_blanks(&mut self) {
        let r = self.rest();
        self.pos += r.len() - r.trim_start_matches([' ', '\t']).len();
    }

    /// The end of code on this line: a `;` outside a string.
    fn code_end(&self) -> usize {
        let mut in_str = None;
        for (i, c) in self.text.char_indices().skip_while(|(i, _)| *i < self.pos) {
            match (c, in_str) {
                ('"', None) => in_str = Some('"'),
                ('\'', None) => in_str = Some('\''),
                (q, Some(open)) if q == open => in_str = None,
                (';', None) => return i,
                _ => {}
            }
        }
        self.text.len()
    }

    fn word(&mut self) -> &'a str {
        self.skip_blanks();
        let r = self.rest();
        let n = r
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '$' || c == '&'))
            .unwrap_or(r.len());
        let text: &'a str = self.text;
        let w = &text[self.pos..self.pos + n];
        self.pos += n;
        w
    }

    fn abs(&self, r: Range<usize>) -> Span {
        self.base + r.start..self.base + r.end
    }

    fn line(&mut self) -> Result<Kind, Located> {
        self.skip_blanks();
        let r = self.rest();
        if r.is_empty() {
            return Ok(Kind::Blank);
        }
        if let Some(after) = strip_word(r, ";FOLD") {
            let at = self.text.len() - after.len();
            let end = after.find(";%").map_or(self.text.len(), |k| at + k);
            let desc = self.text[at..end].trim();
            let lead = self.text[at..end].len() - self.text[at..end].trim_start().len();
            let inline = inline_form(desc, self.base + at + lead);
            return Ok(Kind::Fold(self.abs(at..end), inline));
        }
        if strip_word(r, ";ENDFOLD").is_some() {
            return Ok(Kind::EndFold);
        }
        if r.starts_with(';') {
            return Ok(Kind::Blank);
        }
        if r.starts_with('&') {
            let w = self.word().to_ascii_uppercase();
            let s = self.pos;
            return Ok(Kind::Header(w, self.abs(s..self.text.len())));
        }
        self.statement()
    }

    fn statement(&mut self) -> Result<Kind, Located> {
        let save = self.pos;
        let mut w = self.word().to_ascii_uppercase();
        if w == "GLOBAL" {
            w = self.word().to_ascii_uppercase();
        }
        match w.as_str() {
            "DEF" | "DEFFCT" => {
                if w == "DEFFCT" {
                    self.word();
                }
                Ok(Kind::Def(self.word().to_string()))
            }
            "END" | "ENDFCT" => Ok(Kind::End),
            "DEFDAT" => Ok(Kind::DefDat(self.word().to_string())),
            "ENDDAT" => Ok(Kind::EndDat),
            "DECL" => self.decl(None),
            _ if DATA_TYPES.contains(&w.as_str())
                && self
                    .rest()
                    .trim_start()
                    .starts_with(|c: char| c.is_ascii_alphabetic() || c == '_') =>
            {
                self.decl(Some(w))
            }
            _ => {
                if let Some(m) = Motion::from_word(&w) {
                    return self.motion(m);
                }
                self.pos = save;
                self.assign_or_other()
            }
        }
    }

    fn decl(&mut self, type_name: Option<String>) -> Result<Kind, Located> {
        let mut t = match type_name {
            Some(t) => t,
            None => self.word().to_ascii_uppercase(),
        };
        while t == "GLOBAL" || t == "CONST" {
            t = self.word().to_ascii_uppercase();
        }
        let name = self.word().to_string();
        if name.is_empty() {
            return Err(self.err("expected a name after the type"));
        }
        self.skip_index()?;
        self.skip_blanks();
        let value = if self.rest().starts_with('=') {
            self.pos += 1;
            self.skip_blanks();
            if self.rest().starts_with('{') {
                Some(self.aggregate()?)
            } else {
                None
            }
        } else {
            None
        };
        Ok(Kind::Decl {
            type_name: t,
            name,
            value,
        })
    }

    fn skip_index(&mut self) -> Result<(), Located> {
        if self.rest().starts_with('[') {
            let close = self
                .rest()
                .find(']')
                .ok_or_else(|| self.err("`[` without `]`"))?;
            self.pos += close + 1;
        }
        Ok(())
    }

    fn motion(&mut self, motion: Motion) -> Result<Kind, Located> {
        let first = self.target()?;
        let (aux, target) = if motion.is_circular() {
            self.skip_blanks();
            if self.rest().starts_with(',') {
                self.pos += 1;
            }
            (Some(first), self.target()?)
        } else {
            (None, first)
        };
        self.skip_blanks();
        let s = self.pos;
        let e = self.code_end().max(s);
        Ok(Kind::Move {
            motion,
            aux,
            target,
            rest: self.abs(s..e),
        })
    }

    fn target(&mut self) -> Result<Target, Located> {
        self.skip_blanks();
        if self.rest().starts_with('{') {
            return Ok(Target::Aggregate(self.aggregate()?));
        }
        let s = self.pos;
        let w = self.word();
        if w.is_empty() {
            return Err(self.err("expected a target after the motion keyword"));
        }
        self.skip_index()?;
        // A field or component access (`XP1.POS`) stays part of the name.
        while self.rest().starts_with('.') {
            self.pos += 1;
            self.word();
        }
        let text = self.text[s..self.pos].to_string();
        Ok(Target::Named(text, self.abs(s..self.pos)))
    }

    fn assign_or_other(&mut self) -> Result<Kind, Located> {
        let end = self.code_end();
        let code = &self.text[self.pos..end];
        let Some(eq) = code.find('=') else {
            return Ok(Kind::Other);
        };
        let lhs = code[..eq].trim();
        let plain = !lhs.is_empty()
            && lhs
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "_$[],.".contains(c));
        if !plain || code[eq..].starts_with("==") {
            return Ok(Kind::Other);
        }
        let lhs = lhs.to_string();
        self.pos += eq + 1;
        self.skip_blanks();
        let s = self.pos;
        let agg = if self.rest().starts_with('{') {
            Some(self.aggregate()?)
        } else {
            None
        };
        Ok(Kind::Assign(lhs, agg, self.abs(s..end)))
    }

    /// `{[TYPE:] NAME value, …}` starting at `{`.
    fn aggregate(&mut self) -> Result<Aggregate, Located> {
        let open = self.pos;
        self.pos += 1;
        let mut fields = Vec::new();
        let mut type_name = None;
        loop {
            self.skip_blanks();
            if self.rest().starts_with('}') {
                self.pos += 1;
                break;
            }
            let name = self.word().to_ascii_uppercase();
            if name.is_empty() {
                return Err(self.err("expected a field name or `}` in the aggregate"));
            }
            self.skip_blanks();
            if self.rest().starts_with(':') && fields.is_empty() && type_name.is_none() {
                self.pos += 1;
                type_name = Some(name);
                continue;
            }
            if self.rest().starts_with("[]") {
                self.pos += 2;
                self.skip_blanks();
            }
            let value = self.value()?;
            fields.push((name, value));
            self.skip_blanks();
            if self.rest().starts_with(',') {
                self.pos += 1;
            } else if !self.rest().starts_with('}') {
                return Err(self.err("expected `,` or `}` in the aggregate"));
            }
        }
        Ok(Aggregate {
            type_name,
            fields,
            span: self.abs(open..self.pos),
        })
    }

    fn value(&mut self) -> Result<Value, Located> {
        let r = self.rest();
        if r.starts_with('{') {
            return Ok(Value::Aggregate(self.aggregate()?));
        }
        let s = self.pos;
        if let Some(n) = number_len(r) {
            self.pos += n;
            let text = &self.text[s..self.pos];
            let value: f64 = text.parse().map_err(|_| self.err("a number"))?;
            return Ok(Value::Number(Number {
                value,
                span: self.abs(s..self.pos),
            }));
        }
        if let Some(q @ ('"' | '\'')) = r.chars().next() {
            let close = r[1..]
                .find(q)
                .ok_or_else(|| self.err("a string without its closing quote"))?;
            self.pos += close + 2;
            let inner = &r[1..close + 1];
            if q == '\'' {
                if let Some(b) = inner.strip_prefix(['B', 'b']) {
                    if let Ok(v) = u32::from_str_radix(b, 2) {
                        return Ok(Value::Bits(v, self.abs(s..self.pos)));
                    }
                }
            }
            return Ok(Value::Word(self.abs(s..self.pos)));
        }
        let n = r
            .find([',', '}'])
            .ok_or_else(|| self.err("an aggregate without its closing `}`"))?;
        let end = s + r[..n].trim_end().len();
        self.pos = end;
        Ok(Value::Word(self.abs(s..end)))
    }
}

/// The length of a decimal number at the start of `s` (sign, digits,
/// point, exponent), `None` when there is none.
fn number_len(s: &str) -> Option<usize> {
    let b = s.as_bytes();
    let mut i = usize::from(matches!(b.first(), Some(b'-' | b'+')));
    let digits = |i: &mut usize| {
        let s0 = *i;
        while b.get(*i).is_some_and(u8::is_ascii_digit) {
            *i += 1;
        }
        *i - s0
    };
    let mut n = digits(&mut i);
    if b.get(i) == Some(&b'.') {
        i += 1;
        n += digits(&mut i);
    }
    if n == 0 {
        return None;
    }
    if matches!(b.get(i), Some(b'e' | b'E')) {
        let mut j = i + 1;
        if matches!(b.get(j), Some(b'-' | b'+')) {
            j += 1;
        }
        if digits(&mut j) > 0 {
            i = j;
        }
    }
    Some(i)
}

/// `s` after the case-insensitive word `w` and a word boundary.
fn strip_word<'s>(s: &'s str, w: &str) -> Option<&'s str> {
    let head = s.get(..w.len())?;
    let tail = &s[w.len()..];
    (head.eq_ignore_ascii_case(w) && !tail.starts_with(|c: char| c.is_ascii_alphanumeric()))
        .then_some(tail)
}

/// The inline form a fold's description holds, if it is a motion's; `at`
/// is the absolute offset of `desc` in the source.
fn inline_form(desc: &str, at: usize) -> Option<InlineForm> {
    // Words with their offsets in `desc` (subslices of it).
    let offset = |w: &str| w.as_ptr() as usize - desc.as_ptr() as usize;
    let mut words = desc.split_whitespace().peekable();
    let motion = Motion::from_word(words.next()?)?;
    let mut f = InlineForm {
        motion,
        points: Vec::new(),
        cont: false,
        vel: None,
        data: None,
        tool: None,
        base: None,
    };
    let bracket = |w: &str, key: &str| -> Option<u32> {
        // `Tool[1]`, or `Tool[1]:GRIPPER` with the tool's name.
        let inner = strip_word(w, key)?.strip_prefix('[')?.split(']').next()?;
        inner.parse().ok()
    };
    while let Some(w) = words.next() {
        if w.eq_ignore_ascii_case("CONT") {
            f.cont = true;
        } else if let Some(v) = strip_word(w, "Vel") {
            let v = v.trim_start_matches('=');
            let v = if v.is_empty() {
                words.next()?.trim_start_matches('=')
            } else {
                v
            };
            let n = number_len(v)?;
            let (num, unit_inline) = v.split_at(n);
            let unit = if unit_inline.is_empty() {
                words.next()?
            } else {
                unit_inline
            };
            let start = at + offset(num);
            f.vel = Some((
                Number {
                    value: num.parse().ok()?,
                    span: start..start + num.len(),
                },
                unit.to_string(),
            ));
            if let Some(d) = words.next_if(|d| !d.contains('[')) {
                f.data = Some(d.to_string());
            }
        } else if let Some(n) = bracket(w, "Tool") {
            f.tool = Some(n);
        } else if let Some(n) = bracket(w, "Base") {
            f.base = Some(n);
        } else if f.vel.is_none() {
            f.points.push(w.to_string());
        }
    }
    Some(f)
}
