//! FANUC TP (ASCII `.ls`) syntax with spans: the sections, the `/ATTR`
//! line count, the `/MN` instructions (motions with their position
//! references, `UFRAME_NUM`, `UTOOL_NUM`) and the `/POS` positions with the
//! span of every number, so a writer can replace only the numbers of
//! `/POS`.

use std::ops::Range;

use crate::error::Located;

/// A byte range into the source.
pub type Span = Range<usize>;

/// A numeric literal: its value and the span of its text.
#[derive(Debug, Clone, PartialEq)]
pub struct Number {
    /// The value.
    pub value: f64,
    /// The literal's bytes (sign included).
    pub span: Span,
}

/// A reference to a position: `P[3]`, `P[3:above pick]`, `PR[2]`.
#[derive(Debug, Clone, PartialEq)]
pub struct PosRef {
    /// `PR[…]` (a position register, set at run time) rather than `P[…]`.
    pub register: bool,
    /// The index.
    pub index: u32,
    /// The comment after `:` inside the brackets.
    pub comment: Option<String>,
    /// From `P`/`PR` to `]`.
    pub span: Span,
}

/// A motion instruction's type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// `J`: joint.
    J,
    /// `L`: linear.
    L,
    /// `C`: circular (via point, then the end point on the next line).
    C,
}

/// What an `/MN` instruction is.
#[derive(Debug, Clone, PartialEq)]
pub enum Instruction {
    /// A motion: the via point of a `C`, the target, and the rest of the
    /// line (speed, termination, options) as written.
    Move {
        /// `J`, `L` or `C`.
        motion: Motion,
        /// The via point of a circle.
        via: Option<PosRef>,
        /// The target (the end point of a circle).
        target: PosRef,
        /// Speed, termination and options as written (of the end point's
        /// line for a circle).
        rest: Span,
    },
    /// `UFRAME_NUM=n`.
    UframeNum(u32),
    /// `UTOOL_NUM=n`.
    UtoolNum(u32),
    /// `UFRAME_NUM=R[i]` (`user`) or `UTOOL_NUM=R[i]`: a frame number
    /// known at run time only.
    FrameNumAtRunTime {
        /// The user frame (`UFRAME_NUM`) rather than the tool frame.
        user: bool,
    },
    /// `UFRAME[i]=…` (`user`) or `UTOOL[i]=…`: the program sets frame `i`
    /// (from a position register: at run time).
    SetFrame {
        /// A user frame rather than a tool frame.
        user: bool,
        /// The frame's number.
        index: u32,
    },
    /// `LBL[i]`: a jump may arrive here with any frame selected.
    Label,
    /// Anything else (`!comment`, `WAIT`, `CALL`, `PR[1]=…`, …).
    Other,
}

/// One `/MN` instruction.
#[derive(Debug, Clone, PartialEq)]
pub struct MnLine {
    /// The line number written before `:`.
    pub number: u32,
    /// The line number and the blanks before it (from the line's start).
    pub number_span: Span,
    /// The source line (1-based) it starts on.
    pub line: usize,
    /// The byte after its last line (after the line end: where a line
    /// inserted after it starts).
    pub end: usize,
    /// What it is.
    pub instruction: Instruction,
}

/// A `/POS` group (`GP1:`): frame numbers, configuration and values.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    /// `GP1`, `GP2`, …
    pub name: String,
    /// `UF : n`.
    pub uf: Option<Number>,
    /// `UT : n`.
    pub ut: Option<Number>,
    /// `CONFIG : '…'`: the text between the quotes and its span.
    pub config: Option<(String, Span)>,
    /// `X`, `Y`, `Z`, `W`, `P`, `R` (Cartesian) or `J1`… (joint), with
    /// their numbers, in source order (extended axes `E1`… too).
    pub values: Vec<(String, Number)>,
}

impl Group {
    /// The number of value `name`.
    pub fn value(&self, name: &str) -> Option<&Number> {
        self.values.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }
    /// Whether the group is in joint form (`J1 = …`).
    pub fn is_joint(&self) -> bool {
        self.values.iter().any(|(n, _)| n == "J1")
    }
}

/// A `/POS` entry: `P[n{:comment}]{ groups };`.
#[derive(Debug, Clone, PartialEq)]
pub struct Position {
    /// The index.
    pub index: u32,
    /// Its comment.
    pub comment: Option<String>,
    /// Its groups.
    pub groups: Vec<Group>,
    /// From `P[` to `};`.
    pub span: Span,
}

/// A parsed `.ls` program.
#[derive(Debug, Clone, PartialEq)]
pub struct Program {
    /// The name after `/PROG` and its modifier (`Macro`) as written.
    pub name: String,
    /// `LINE_COUNT = n;` of `/ATTR`: the value and its span.
    pub line_count: Option<(u32, Span)>,
    /// The `/MN` instructions.
    pub mn: Vec<MnLine>,
    /// The `/POS` positions.
    pub positions: Vec<Position>,
    /// Section keywords in order (`PROG`, `ATTR`, `APPL`, `MN`, `POS`, `END`)
    /// with their 1-based lines.
    pub sections: Vec<(String, usize)>,
}

impl Program {
    /// The position `P[index]`.
    pub fn position(&self, index: u32) -> Option<&Position> {
        self.positions.iter().find(|p| p.index == index)
    }
}

/// A located error at byte `at` of `src`.
fn error(src: &str, file: &str, at: usize, what: &str) -> Located {
    let at = at.min(src.len());
    let before = &src[..at];
    let line = before.matches('\n').count() + 1;
    let start = before.rfind('\n').map_or(0, |k| k + 1);
    let end = src[start..].find('\n').map_or(src.len(), |k| start + k);
    let text = src[start..end].trim_end_matches('\r').trim();
    Located::new(file, line, at - start + 1, format!("{what}: `{text}`"))
}

/// Parses a `.ls` program; `file` is used in error messages.
pub fn parse(src: &str, file: &str) -> Result<Program, Located> {
    let mut prog = Program {
        name: String::new(),
        line_count: None,
        mn: Vec::new(),
        positions: Vec::new(),
        sections: Vec::new(),
    };
    let mut section = String::new();
    let mut offset = 0;
    let mut pos_start = None;
    for (i, raw) in src.split_inclusive('\n').enumerate() {
        let at = offset;
        offset += raw.len();
        let text = raw.trim_end_matches(['\n', '\r']);
        let t = text.trim_start();
        if let Some(head) = t.strip_prefix('/') {
            let word = head
                .split_whitespace()
                .next()
                .unwrap_or("")
                .to_ascii_uppercase();
            if word == "PROG" {
                prog.name = head[4..].trim().to_string();
            }
            if section == "POS" {
                let s = pos_start.take().unwrap_or(at);
                positions(src, file, s, at, &mut prog.positions)?;
            }
            if word == "POS" {
                pos_start = Some(offset);
            }
            prog.sections.push((word.clone(), i + 1));
            section = word;
            continue;
        }
        match section.as_str() {
            "ATTR" => {
                if let Some(rest) = t.strip_prefix("LINE_COUNT") {
                    let v = rest.trim_start().trim_start_matches('=').trim_start();
                    let digits = v.len() - v.trim_start_matches(|c: char| c.is_ascii_digit()).len();
                    let s = at + (text.len() - v.len());
                    let n = v[..digits]
                        .parse()
                        .map_err(|_| error(src, file, s, "LINE_COUNT without a number"))?;
                    prog.line_count = Some((n, s..s + digits));
                }
            }
            "MN" => mn_line(src, file, (at, raw.len()), text, i + 1, &mut prog.mn)?,
            _ => {}
        }
    }
    if prog.sections.first().map(|(s, _)| s.as_str()) != Some("PROG") {
        return Err(error(src, file, 0, "a TP program starts with `/PROG name`"));
    }
    if section == "POS" {
        positions(
            src,
            file,
            pos_start.unwrap_or(src.len()),
            src.len(),
            &mut prog.positions,
        )?;
    }
    Ok(prog)
}

/// One `/MN` source line: `  12:L P[3] 500mm/sec CNT50 ;`, or the
/// continuation `    :  P[4] 100mm/sec FINE ;` of a `C` move.
fn mn_line(
    src: &str,
    file: &str,
    (at, raw_len): (usize, usize),
    text: &str,
    line: usize,
    out: &mut Vec<MnLine>,
) -> Result<(), Located> {
    let Some(colon) = text.find(':') else {
        return Ok(());
    };
    let head = text[..colon].trim();
    let body_at = at + colon + 1;
    let body = &text[colon + 1..];
    let code_end = body.rfind(';').unwrap_or(body.len());
    if head.is_empty() {
        // Continuation: the end point of the last `C` move.
        if let Some(MnLine {
            instruction:
                Instruction::Move {
                    motion: Motion::C,
                    via,
                    target,
                    rest,
                },
            ..
        }) = out.last_mut()
        {
            let t = body.trim_start();
            let ts = body_at + (body.len() - t.len());
            let (r, n) = pos_ref(t, ts)
                .ok_or_else(|| error(src, file, ts, "expected the end point of the circle"))?;
            *via = Some(std::mem::replace(target, r));
            *rest = ts + n..body_at + code_end;
        }
        if let Some(last) = out.last_mut() {
            last.end = at + raw_len;
        }
        return Ok(());
    }
    let number: u32 = head
        .parse()
        .map_err(|_| error(src, file, at, "an /MN line starts with its number and `:`"))?;
    let t = body.trim_start();
    let ts = body_at + (body.len() - t.len());
    let upper = t.to_ascii_uppercase();
    let instruction = if let Some(m) = motion_of(t) {
        let after = &t[1..];
        let a = after.trim_start();
        let as_ = ts + 1 + (after.len() - a.len());
        let (target, n) = pos_ref(a, as_)
            .ok_or_else(|| error(src, file, as_, "expected P[n] or PR[n] after the motion"))?;
        Instruction::Move {
            motion: m,
            via: None,
            target,
            rest: as_ + n..(body_at + code_end).max(as_ + n),
        }
    } else if let Some(v) = upper.strip_prefix("UFRAME_NUM") {
        match frame_number(v) {
            Some(n) => Instruction::UframeNum(n),
            None if is_register(v) => Instruction::FrameNumAtRunTime { user: true },
            None => return Err(error(src, file, ts, "UFRAME_NUM needs a number")),
        }
    } else if let Some(v) = upper.strip_prefix("UTOOL_NUM") {
        match frame_number(v) {
            Some(n) => Instruction::UtoolNum(n),
            None if is_register(v) => Instruction::FrameNumAtRunTime { user: false },
            None => return Err(error(src, file, ts, "UTOOL_NUM needs a number")),
        }
    } else if upper.starts_with("LBL[") {
        Instruction::Label
    } else if let Some(index) = set_frame(&upper, "UFRAME[") {
        Instruction::SetFrame { user: true, index }
    } else if let Some(index) = set_frame(&upper, "UTOOL[") {
        Instruction::SetFrame { user: false, index }
    } else {
        Instruction::Other
    };
    out.push(MnLine {
        number,
        number_span: at..at + colon,
        line,
        end: at + raw_len,
        instruction,
    });
    Ok(())
}

/// `J`, `L` or `C` followed by a blank.
fn motion_of(t: &str) -> Option<Motion> {
    let mut c = t.chars();
    let m = match c.next()? {
        'J' => Motion::J,
        'L' => Motion::L,
        'C' => Motion::C,
        _ => return None,
    };
    c.next().filter(|c| *c == ' ' || *c == '\t').map(|_| m)
}

/// `=n` of `UFRAME_NUM=n` (a register form `=R[1]` is not a number).
fn frame_number(v: &str) -> Option<u32> {
    let v = v.trim_start().strip_prefix('=')?.trim();
    v.trim_end_matches(';').trim().parse().ok()
}

/// Whether `=…` of `UFRAME_NUM=…` names a register (`=R[1]`, `=AR[1]`).
fn is_register(v: &str) -> bool {
    v.trim_start()
        .strip_prefix('=')
        .is_some_and(|r| r.trim_start().starts_with(['R', 'A']))
}

/// `i` of `UFRAME[i]=…` (upper-case `t`, `head` is `UFRAME[` or `UTOOL[`).
fn set_frame(t: &str, head: &str) -> Option<u32> {
    let r = t.strip_prefix(head)?;
    let (i, after) = r.split_once(']')?;
    after.trim_start().starts_with('=').then_some(())?;
    i.trim().parse().ok()
}

/// `P[n]`, `P[n:comment]`, `PR[n]` at the start of `t` (which starts at
/// byte `at`): the reference and its length.
fn pos_ref(t: &str, at: usize) -> Option<(PosRef, usize)> {
    let (register, rest) = if let Some(r) = t.strip_prefix("PR[") {
        (true, r)
    } else {
        (false, t.strip_prefix("P[")?)
    };
    let close = rest.find(']')?;
    let inner = &rest[..close];
    let (idx, comment) = match inner.split_once(':') {
        Some((i, c)) => (i, Some(c.to_string())),
        None => (inner, None),
    };
    let index = idx.trim().parse().ok()?;
    let len = t.len() - rest.len() + close + 1;
    Some((
        PosRef {
            register,
            index,
            comment,
            span: at..at + len,
        },
        len,
    ))
}

/// Reads the positions of `src[start..end]` (the `/POS` section).
fn positions(
    src: &str,
    file: &str,
    start: usize,
    end: usize,
    out: &mut Vec<Position>,
) -> Result<(), Located> {
    let mut c = Cursor {
        src,
        file,
        pos: start,
        end,
    };
    loop {
        c.blanks();
        if c.pos >= end {
            return Ok(());
        }
        let p_at = c.pos;
        let head = &src[c.pos..end];
        let (r, n) = pos_ref(head, p_at)
            .filter(|(r, _)| !r.register)
            .ok_or_else(|| c.err("expected `P[n]{` in /POS"))?;
        c.pos += n;
        c.expect("{")?;
        let mut groups = Vec::new();
        loop {
            c.blanks();
            if c.eat("}") {
                break;
            }
            groups.push(c.group()?);
        }
        c.blanks();
        c.expect(";")?;
        out.push(Position {
            index: r.index,
            comment: r.comment,
            groups,
            span: p_at..c.pos,
        });
    }
}

struct Cursor<'a> {
    src: &'a str,
    file: &'a str,
    pos: usize,
    end: usize,
}

impl<'a> Cursor<'a> {
    fn rest(&self) -> &'a str {
        &self.src[self.pos..self.end]
    }
    fn err(&self, what: &str) -> Located {
        error(self.src, self.file, self.pos, what)
    }
    fn blanks(&mut self) {
        let r = self.rest();
        self.pos += r.len() - r.trim_start().len();
    }
    fn eat(&mut self, s: &str) -> bool {
        self.blanks();
        let hit = self.rest().starts_with(s);
        if hit {
            self.pos += s.len();
        }
        hit
    }
    fn expect(&mut self, s: &str) -> Result<(), Located> {
        if self.eat(s) {
            Ok(())
        } else {
            Err(self.err(&format!("expected `{s}`")))
        }
    }
    fn word(&mut self) -> &'a str {
        self.blanks();
        let r = self.rest();
        let n = r
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(r.len());
        self.pos += n;
        &r[..n]
    }
    fn number(&mut self) -> Result<Number, Located> {
        self.blanks();
        let r = self.rest();
        let n = r
            .find(|c: char| !(c.is_ascii_digit() || "+-.eE".contains(c)))
            .unwrap_or(r.len());
        let value = r[..n].parse().map_err(|_| self.err("expected a number"))?;
        let span = self.pos..self.pos + n;
        self.pos += n;
        Ok(Number { value, span })
    }
    /// `GP1: UF : 1, UT : 2, CONFIG : '…', X = 1.0 mm, …` up to the next
    /// group or the closing `}`.
    fn group(&mut self) -> Result<Group, Located> {
        let name = self.word().to_string();
        if !name.starts_with("GP") {
            return Err(self.err("expected a group `GP1:`"));
        }
        self.expect(":")?;
        let mut g = Group {
            name,
            uf: None,
            ut: None,
            config: None,
            values: Vec::new(),
        };
        loop {
            self.blanks();
            let r = self.rest();
            if r.starts_with('}') || r.starts_with("GP") {
                return Ok(g);
            }
            let key = self.word().to_string();
            match key.as_str() {
                "UF" | "UT" => {
                    self.expect(":")?;
                    let n = self.number()?;
                    *(if key == "UF" { &mut g.uf } else { &mut g.ut }) = Some(n);
                }
                "CONFIG" => {
                    self.expect(":")?;
                    self.expect("'")?;
                    let close = self
                        .rest()
                        .find('\'')
                        .ok_or_else(|| self.err("a CONFIG without its closing quote"))?;
                    let s = self.pos;
                    g.config = Some((self.rest()[..close].to_string(), s..s + close));
                    self.pos += close + 1;
                }
                "" => return Err(self.err("expected a position field")),
                _ => {
                    self.expect("=")?;
                    let n = self.number()?;
                    g.values.push((key, n));
                    self.word(); // the unit: mm, deg
                }
            }
            self.eat(",");
        }
    }
}
