//! Subprograms resolved offline: Fanuc/Haas `M98 P… L…` / `M99` in the same
//! file, and LinuxCNC `o<name> sub` / `call` / `endsub` and `o100 repeat
//! [n]` / `endrepeat`.
//!
//! The syntax pass ([`super::parse_line`]) reads each line by itself; this
//! pass reads the whole program, finds the subprogram definitions, and
//! follows every call in the order the control runs them. The result is an
//! [`Expansion`]: the lines of the program in the order they run (the
//! *trace*; each entry names its line and the call it runs in), which the
//! modal interpreter takes block by block, and the structure (definitions,
//! calls, call sites) that the writer ([`crate::emit::subprograms`]) needs
//! to write the compensated program with its subprograms, renumbered where
//! calls need different corrections. Definition, call and return lines
//! themselves are not in the trace: they move nothing.
//!
//! What the structure cannot hold is refused by name, at its line: a call
//! to a program not in the file, a subprogram without its `M99`, a call
//! sharing its line with other words, recursion, O-word arguments and
//! conditions (which need the macro values).

use std::collections::HashMap;

use super::oword::{Keyword, OWord};
use super::{Block, parse_line, strip_eol};
use crate::error::Located;

/// Deepest nesting of calls (Fanuc controls take 4 to 10 levels).
pub const MAX_DEPTH: usize = 16;

/// Most lines a program may run once expanded.
pub const MAX_TRACE: usize = 20_000_000;

/// An expression kept as written: the byte range of its number in a
/// synthesised block and the expression's text.
pub type Kept = ((u32, u32), Vec<u8>);

/// What a definition is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DefKind {
    /// `O2000` … `M99` (Fanuc, Haas).
    Numbered,
    /// `o<name> sub` … `o<name> endsub`, or `o100 sub` (LinuxCNC).
    OSub,
    /// `o100 repeat [n]` … `o100 endrepeat` (LinuxCNC), run in place.
    Repeat,
}

/// A subprogram definition or a loop: the lines from `head` to `end`
/// (both included; the body is between them).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Def {
    /// What it is.
    pub kind: DefKind,
    /// Index of its first line (`O2000`, `o<x> sub`, `o100 repeat`).
    pub head: usize,
    /// Index of its last line (`M99`, `o<x> endsub`, `o100 endrepeat`).
    pub end: usize,
    /// The name's byte range in the head line (the digits of `O2000`, the
    /// `<x>` of `o<x> sub`).
    pub head_name: (u32, u32),
    /// The name's byte range in the end line (O-words only).
    pub end_name: Option<(u32, u32)>,
    /// The name as written (`2000`, `<pocket>`).
    pub name: String,
}

/// Where a program calls a subprogram or opens a loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Site {
    /// The definition it runs.
    pub def: usize,
    /// Byte range of the name (`M98 P2000`: the digits after `P`).
    pub name: (u32, u32),
    /// Byte range of the repeat count as written (`L4`: `4`; `repeat
    /// [4]`: `[4]`), when written.
    pub count: Option<(u32, u32)>,
    /// The number of calls written with the name (`L4`, `repeat [4]`,
    /// Fanuc's `M98 P41000`).
    pub times: u32,
    /// Fanuc's packed form `M98 P41000`: the count written before a
    /// four-digit program number.
    pub packed: bool,
    /// Where to write an `L` count when there is none: after the name.
    pub after_name: u32,
}

/// One call as it runs: the definition, the line it is called from and
/// the call it is called in (`calls[0]` is the main program).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Call {
    /// The definition (`usize::MAX` for the main program).
    pub def: usize,
    /// The calling line (the head of a loop).
    pub line: usize,
    /// The call this one runs in.
    pub parent: usize,
}

/// A program with its subprograms followed.
#[derive(Debug, Clone, Default)]
pub struct Expansion {
    /// Byte range of every line of the text (end-of-line bytes included).
    pub lines: Vec<(usize, usize)>,
    /// Definitions and loops.
    pub defs: Vec<Def>,
    /// Call sites by line.
    pub sites: HashMap<usize, Site>,
    /// Every call as it runs, in order (`calls[0]`: the main program).
    pub calls: Vec<Call>,
    /// The lines in the order they run: (line index, call index).
    pub trace: Vec<(usize, usize)>,
    /// Every program number and O-word name of the file (for new ones).
    pub names: std::collections::BTreeSet<String>,
    /// The text a trace entry runs as, when it is not its line's: a block
    /// with macro values, each written as its number.
    pub synth: HashMap<usize, Vec<u8>>,
    /// Where a trace entry of [`Expansion::synth`] may keep an expression
    /// as the program wrote it: the number's byte range in the synthesised
    /// text and the expression (the control, running the program written
    /// out, finds the same value there).
    pub kept: HashMap<usize, Vec<Kept>>,
    /// Assignment lines written out with the program as it runs: (trace
    /// entry they come before, line).
    pub statements: Vec<(usize, usize)>,
    /// Macro statements ran: a compensated program is written out as it
    /// runs.
    pub flat: bool,
    /// The main program's last line (`M30`), when it ended there.
    pub main_end: Option<usize>,
}

impl Expansion {
    /// The bytes of the lines in the order they run, each ending in an
    /// end-of-line (one is added to a last line without), and the 1-based
    /// line number of each.
    pub fn stream(&self, text: &[u8]) -> (Vec<u8>, Vec<usize>) {
        let mut bytes = Vec::new();
        let mut numbers = Vec::with_capacity(self.trace.len());
        for k in 0..self.trace.len() {
            bytes.extend_from_slice(&self.input(text, k));
            numbers.push(self.trace[k].0 + 1);
        }
        (bytes, numbers)
    }

    /// What trace entry `k` hands the interpreter: its line, or its text
    /// with macro values, with an end of line.
    pub fn input(&self, text: &[u8], k: usize) -> std::borrow::Cow<'_, [u8]> {
        let line = self.trace[k].0;
        let (s, e) = self.lines[line];
        let body: &[u8] = match self.synth.get(&k) {
            Some(t) => t,
            None => &text[s..e],
        };
        if body.ends_with(b"\n") {
            std::borrow::Cow::Owned(body.to_vec())
        } else {
            let mut v = body.to_vec();
            v.push(b'\n');
            std::borrow::Cow::Owned(v)
        }
    }

    /// The text of line `i`.
    pub fn line<'t>(&self, text: &'t [u8], i: usize) -> &'t [u8] {
        let (s, e) = self.lines[i];
        &text[s..e]
    }
}

/// What a line is to this pass.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Kind {
    Plain,
    /// `O2000` (with comments only).
    Number(u32, (u32, u32)),
    /// `M98 P… L…`: program, P's number range, L's count and range.
    M98(u32, (u32, u32), Option<(u32, (u32, u32))>),
    M99,
    /// `M30`, `M2`.
    End,
    OWord(OWord),
    /// A macro statement.
    Macro(super::macros::Statement),
    /// `G65 P… ` with literal arguments.
    G65,
}

fn classify(block: &Block, text: &[u8], file: &str) -> Result<Kind, Located> {
    if let Some(o) = block.oword {
        return Ok(Kind::OWord(o));
    }
    let at =
        |w: &super::Word, msg: String| Located::new(file, block.line_no, w.start as usize + 1, msg);
    let mut kind = Kind::Plain;
    for w in &block.words {
        match (w.letter, w.code10()) {
            (b'M', 980) => {
                let p = block.word(b'P').and_then(|p| p.whole().map(|v| (v, p)));
                let Some((p, pw)) = p else {
                    return Err(at(w, "M98 without a program number `P`".into()));
                };
                let l = block
                    .word(b'L')
                    .map(|l| {
                        l.whole().map(|v| (v, (l.num_start, l.end))).ok_or_else(|| {
                            at(l, "M98 repeat count `L` is not a whole number".into())
                        })
                    })
                    .transpose()?;
                if let Some(other) = block.words.iter().find(|o| {
                    !matches!(
                        (o.letter, o.code10()),
                        (b'N', _) | (b'P' | b'L', _) | (b'M', 980)
                    )
                }) {
                    return Err(at(
                        other,
                        format!(
                            "a subprogram call shares its line with `{}`: write `M98 P… L…` on a line of its own",
                            String::from_utf8_lossy(
                                &text[other.start as usize..other.end as usize]
                            )
                        ),
                    ));
                }
                kind = Kind::M98(p, (pw.num_start, pw.end), l);
            }
            (b'M', 990) => {
                if block.word(b'P').is_some() {
                    return Err(at(
                        w,
                        "M99 P… (return to a block number) is not followed offline".into(),
                    ));
                }
                if let Some(other) = block
                    .words
                    .iter()
                    .find(|o| !matches!((o.letter, o.code10()), (b'N', _) | (b'M', 990)))
                {
                    return Err(at(
                        other,
                        format!(
                            "M99 shares its line with `{}`: write `M99` on a line of its own",
                            String::from_utf8_lossy(
                                &text[other.start as usize..other.end as usize]
                            )
                        ),
                    ));
                }
                kind = Kind::M99;
            }
            (b'M', 970 | 1980) => {
                return Err(at(
                    w,
                    format!(
                        "`M{}` subprogram calls are not followed offline (use M98 with the subprogram in the same file)",
                        w.code10() / 10
                    ),
                ));
            }
            (b'M', 300 | 20) => kind = Kind::End,
            (b'G', 650) => kind = Kind::G65,
            _ => {}
        }
    }
    if kind == Kind::Plain {
        if let (Some(o), 1) = (block.word(b'O'), block.words.len()) {
            if let Some(n) = o.whole() {
                kind = Kind::Number(n, (o.num_start, o.end));
            }
        }
    }
    Ok(kind)
}

/// True when `text` may hold a subprogram or O-word construct: the cheap
/// test before [`expand`] reads the program as a whole.
pub fn may_have_subprograms(text: &[u8]) -> bool {
    let has = |needle: &[u8]| memchr::memmem::find(text, needle).is_some();
    has(b"M98")
        || has(b"m98")
        || has(b"#")
        || has(b"G65")
        || has(b"g65")
        || has(b"GOTO")
        || has(b"WHILE")
        || text.split(|&c| c == b'\n').any(oword_like)
}

/// True when `line` opens with an O-word (`o<name>`, or `o100` and a
/// keyword), after spaces and a block-delete slash.
fn oword_like(line: &[u8]) -> bool {
    let t = line.trim_ascii_start();
    let t = t.strip_prefix(b"/").unwrap_or(t).trim_ascii_start();
    match t.split_first() {
        Some((o, rest)) if o.eq_ignore_ascii_case(&b'o') => {
            if rest.first() == Some(&b'<') {
                return true;
            }
            let digits = rest.iter().take_while(|c| c.is_ascii_digit()).count();
            digits > 0
                && rest[digits..]
                    .trim_ascii_start()
                    .first()
                    .is_some_and(u8::is_ascii_alphabetic)
        }
        _ => false,
    }
}

/// Follows the subprograms of `text`: `None` when it has none (the
/// program runs as written, line by line).
pub fn expand(text: &[u8], file: &str) -> Result<Option<Expansion>, Located> {
    if !may_have_subprograms(text) {
        return Ok(None);
    }
    let mut lines = Vec::new();
    let mut start = 0;
    for nl in memchr::memchr_iter(b'\n', text) {
        lines.push((start, nl + 1));
        start = nl + 1;
    }
    if start < text.len() {
        lines.push((start, text.len()));
    }
    let mut kinds = Vec::with_capacity(lines.len());
    let mut block = Block::default();
    for (i, &(s, e)) in lines.iter().enumerate() {
        // A line that does not parse is left to the interpretation, which
        // reports it where it runs.
        kinds.push(match parse_line(&text[s..e], i + 1, file, &mut block) {
            Ok(()) => classify(&block, &text[s..e], file)?,
            Err(_) => {
                super::macros::statement(strip_eol(&text[s..e])).map_or(Kind::Plain, Kind::Macro)
            }
        });
    }
    if !kinds.iter().any(|k| {
        matches!(
            k,
            Kind::M98(..) | Kind::OWord(_) | Kind::Macro(_) | Kind::G65
        )
    }) {
        return Ok(None);
    }
    let mut r = Resolver {
        text,
        file,
        kinds,
        exp: Expansion {
            lines,
            ..Expansion::default()
        },
        by_number: HashMap::new(),
        by_key: HashMap::new(),
        skip: HashMap::new(),
        repeats: HashMap::new(),
        stop: false,
        macros: super::macros_run::State::default(),
        control: super::macros_run::State::default(),
    };
    r.definitions()?;
    r.exp.calls.push(Call {
        def: usize::MAX,
        line: 0,
        parent: 0,
    });
    r.run_main()?;
    Ok(Some(r.exp))
}

pub(super) struct Resolver<'t> {
    pub(super) text: &'t [u8],
    pub(super) file: &'t str,
    pub(super) kinds: Vec<Kind>,
    pub(super) exp: Expansion,
    /// Numbered definitions by program number.
    pub(super) by_number: HashMap<u32, usize>,
    /// O-word subroutines by name (case folded).
    by_key: HashMap<String, usize>,
    /// Definition heads: the line after their end.
    skip: HashMap<usize, usize>,
    /// Loops by head line.
    repeats: HashMap<usize, usize>,
    /// `M30` ran.
    pub(super) stop: bool,
    /// Macro variables and the ranges being run.
    pub(super) macros: super::macros_run::State,
    /// The variables as the control has them running the program written
    /// out as it runs (its assignment lines, at one call level).
    pub(super) control: super::macros_run::State,
}

impl Resolver<'_> {
    pub(super) fn err(&self, line: usize, msg: String) -> Located {
        let text = String::from_utf8_lossy(strip_eol(self.exp.line(self.text, line)));
        Located::new(
            self.file,
            line + 1,
            1,
            format!("{msg}: `{}`", crate::error::clip(text.trim())),
        )
    }

    /// Finds the subprogram definitions: every `O` number that an `M98`
    /// calls (to its `M99`), every `o… sub` (to its `endsub`).
    fn definitions(&mut self) -> Result<(), Located> {
        let called: std::collections::BTreeSet<u32> = self
            .kinds
            .iter()
            .filter_map(|k| match k {
                Kind::M98(p, ..) => Some(*p),
                _ => None,
            })
            .chain(self.g65_targets())
            .collect();
        let mut i = 0;
        while i < self.kinds.len() {
            match self.kinds[i] {
                Kind::Number(n, span) => {
                    self.exp.names.insert(n.to_string());
                    if called.contains(&n) || called.iter().any(|p| p % 10000 == n && *p > 9999) {
                        let end = (i + 1..self.kinds.len())
                            .find(|&j| matches!(self.kinds[j], Kind::M99 | Kind::Number(..)))
                            .filter(|&j| self.kinds[j] == Kind::M99)
                            .ok_or_else(|| self.err(i, format!("subprogram O{n} has no M99 before the next program or the end of the file")))?;
                        self.define(DefKind::Numbered, i, end, span, None);
                        self.by_number.insert(n, self.exp.defs.len() - 1);
                        i = end;
                    }
                }
                Kind::OWord(o) if o.keyword == Keyword::Sub => {
                    let line = self.exp.line(self.text, i);
                    let key = o.key(line);
                    let end = (i + 1..self.kinds.len())
                        .find(|&j| match self.kinds[j] {
                            Kind::OWord(e) => {
                                e.keyword == Keyword::Endsub
                                    && e.key(self.exp.line(self.text, j)) == key
                            }
                            _ => false,
                        })
                        .ok_or_else(|| {
                            self.err(i, format!("O-word subroutine o{key} has no `endsub`"))
                        })?;
                    let Kind::OWord(e) = self.kinds[end] else {
                        unreachable!("found as an O-word line")
                    };
                    if let Some(j) = (i + 1..end).find(
                        |&j| matches!(self.kinds[j], Kind::OWord(s) if s.keyword == Keyword::Sub),
                    ) {
                        return Err(
                            self.err(j, "an O-word subroutine defined inside another".into())
                        );
                    }
                    self.define(DefKind::OSub, i, end, o.name, Some(e.name));
                    self.by_key.insert(key, self.exp.defs.len() - 1);
                    i = end;
                }
                Kind::OWord(o) => {
                    self.exp.names.insert(o.key(self.exp.line(self.text, i)));
                }
                _ => {}
            }
            i += 1;
        }
        Ok(())
    }

    pub(super) fn define(
        &mut self,
        kind: DefKind,
        head: usize,
        end: usize,
        head_name: (u32, u32),
        end_name: Option<(u32, u32)>,
    ) -> usize {
        let line = self.exp.line(self.text, head);
        let name =
            String::from_utf8_lossy(&line[head_name.0 as usize..head_name.1 as usize]).to_string();
        self.exp.names.insert(name.to_ascii_lowercase());
        if let Ok(n) = name.parse::<u32>() {
            self.exp.names.insert(n.to_string());
        }
        self.exp.defs.push(Def {
            kind,
            head,
            end,
            head_name,
            end_name,
            name,
        });
        if kind != DefKind::Repeat {
            self.skip.insert(head, end + 1);
        }
        self.exp.defs.len() - 1
    }

    fn run_main(&mut self) -> Result<(), Located> {
        self.macros.ranges.push((0, self.kinds.len()));
        let mut i = 0;
        while i < self.kinds.len() && !self.stop {
            if let Some(&next) = self.skip.get(&i) {
                i = next;
                continue;
            }
            i = self.step(i, self.kinds.len(), 0, 0)?;
        }
        Ok(())
    }

    /// Runs the lines `from..to` in call `call`.
    pub(super) fn run(
        &mut self,
        from: usize,
        to: usize,
        call: usize,
        depth: usize,
    ) -> Result<(), Located> {
        self.macros.ranges.push((from, to));
        let done = self.run_range(from, to, call, depth);
        self.macros.ranges.pop();
        done
    }

    fn run_range(
        &mut self,
        from: usize,
        to: usize,
        call: usize,
        depth: usize,
    ) -> Result<(), Located> {
        let mut i = from;
        while i < to && !self.stop {
            if self.skip.contains_key(&i) {
                return Err(self.err(i, "a subprogram defined inside another".into()));
            }
            match self.kinds[i] {
                Kind::M99 => return Ok(()),
                Kind::OWord(o) if matches!(o.keyword, Keyword::Return | Keyword::Endsub) => {
                    return Ok(());
                }
                _ => {}
            }
            i = self.step(i, to, call, depth)?;
        }
        Ok(())
    }

    /// Runs line `i` (of a range ending at `to`) in call `call`: the next
    /// line to run.
    fn step(&mut self, i: usize, to: usize, call: usize, depth: usize) -> Result<usize, Located> {
        match self.kinds[i] {
            Kind::M98(p, name, l) => {
                let (def, times, packed) = match self.by_number.get(&p) {
                    Some(&d) => (d, l.map_or(1, |l| l.0), false),
                    None => match self.by_number.get(&(p % 10000)) {
                        Some(&d) if p > 9999 && l.is_none() => (d, p / 10000, true),
                        _ => {
                            return Err(self.err(
                                i,
                                format!("M98 calls O{p}, which is not in this file (subprograms are read from the program's own file)"),
                            ));
                        }
                    },
                };
                self.exp.sites.insert(
                    i,
                    Site {
                        def,
                        name,
                        count: l.map(|l| l.1),
                        times,
                        packed,
                        after_name: name.1,
                    },
                );
                self.call(def, i, times, call, depth)?;
                Ok(i + 1)
            }
            Kind::OWord(o) => self.oword(i, o, to, call, depth),
            Kind::Macro(st) => self.statement(i, st, call, depth),
            Kind::G65 => {
                let line = strip_eol(self.exp.line(self.text, i)).to_vec();
                self.g65(i, &line, call, depth)?;
                Ok(i + 1)
            }
            Kind::End => {
                self.push(i, call)?;
                self.stop = true;
                if call == 0 {
                    self.exp.main_end = Some(i);
                }
                Ok(i + 1)
            }
            Kind::M99 if call == 0 => {
                // `M99` ending the main program: the control starts it
                // again; one run is compensated (the line is written as
                // it is).
                self.stop = true;
                Ok(i + 1)
            }
            _ => {
                self.push(i, call)?;
                Ok(i + 1)
            }
        }
    }

    pub(super) fn push(&mut self, line: usize, call: usize) -> Result<(), Located> {
        if self.exp.trace.len() >= MAX_TRACE {
            return Err(self.err(
                line,
                format!(
                    "the program runs more than {MAX_TRACE} lines once its subprograms are followed"
                ),
            ));
        }
        self.exp.trace.push((line, call));
        Ok(())
    }

    /// Runs definition `def` `times` times from line `line` of call `parent`.
    fn call(
        &mut self,
        def: usize,
        line: usize,
        times: u32,
        parent: usize,
        depth: usize,
    ) -> Result<(), Located> {
        self.call_with(def, line, times, parent, depth, None)
    }

    /// [`Resolver::call`], with a new level of local variables for a
    /// macro call (`G65`).
    pub(super) fn call_with(
        &mut self,
        def: usize,
        line: usize,
        times: u32,
        parent: usize,
        depth: usize,
        locals: Option<super::macros_run::Locals>,
    ) -> Result<(), Located> {
        if depth >= MAX_DEPTH {
            return Err(self.err(
                line,
                format!("calls nested deeper than {MAX_DEPTH} levels (recursion?)"),
            ));
        }
        let (head, end) = (self.exp.defs[def].head, self.exp.defs[def].end);
        for _ in 0..times {
            self.exp.calls.push(Call { def, line, parent });
            let c = self.exp.calls.len() - 1;
            if let Some(l) = locals {
                self.macros.frames.push(l);
            }
            let done = self.run(head + 1, end, c, depth + 1);
            if locals.is_some() {
                self.macros.frames.pop();
            }
            done?;
            if self.stop {
                break;
            }
        }
        Ok(())
    }

    fn oword(
        &mut self,
        i: usize,
        o: OWord,
        to: usize,
        call: usize,
        depth: usize,
    ) -> Result<usize, Located> {
        let line = self.exp.line(self.text, i);
        let key = o.key(line);
        match o.keyword {
            Keyword::Call => {
                let Some(&def) = self.by_key.get(&key) else {
                    return Err(self.err(
                        i,
                        format!("o{key} call: the subroutine is not defined in this file"),
                    ));
                };
                if !o.args_text(line).is_empty() {
                    return Err(self.err(i, format!("o{key} call with arguments: arguments set the subroutine's `#1`… parameters, which this reader does not evaluate")));
                }
                self.exp.sites.insert(
                    i,
                    Site {
                        def,
                        name: o.name,
                        count: None,
                        times: 1,
                        packed: false,
                        after_name: o.name.1,
                    },
                );
                self.call(def, i, 1, call, depth)?;
                Ok(i + 1)
            }
            Keyword::Repeat => {
                let end = self.loop_end(i, &key, to)?;
                let times = self.count(i, o.args_text(line))?;
                let def = match self.repeats.get(&i) {
                    Some(&d) => d,
                    None => {
                        let Kind::OWord(e) = self.kinds[end] else {
                            unreachable!("an O-word line")
                        };
                        let d = self.define(DefKind::Repeat, i, end, o.name, Some(e.name));
                        self.repeats.insert(i, d);
                        d
                    }
                };
                self.exp.sites.insert(
                    i,
                    Site {
                        def,
                        name: o.name,
                        count: Some(o.args),
                        times,
                        packed: false,
                        after_name: o.name.1,
                    },
                );
                self.call(def, i, times, call, depth)?;
                Ok(end + 1)
            }
            Keyword::Endrepeat => {
                Err(self.err(i, format!("o{key} endrepeat without its `repeat`")))
            }
            Keyword::Endsub | Keyword::Return | Keyword::Sub => Err(self.err(
                i,
                format!("o{key} {} outside a subroutine", o.keyword.as_str()),
            )),
            _ => self.oword_flow(i, o, &key, to),
        }
    }

    /// The `endrepeat` of the loop opened at line `i`, before `to`.
    fn loop_end(&self, i: usize, key: &str, to: usize) -> Result<usize, Located> {
        (i + 1..to)
            .find(|&j| match self.kinds[j] {
                Kind::OWord(e) => {
                    e.keyword == Keyword::Endrepeat && e.key(self.exp.line(self.text, j)) == key
                }
                _ => false,
            })
            .ok_or_else(|| self.err(i, format!("o{key} repeat has no `o{key} endrepeat`")))
    }

    /// The repeat count written as `args` (`[4]`) on line `i`.
    fn count(&self, i: usize, args: &[u8]) -> Result<u32, Located> {
        let unknown = |n: u32| Err(format!("`#{n}` is not known before the program runs"));
        let v = super::expr::eval(args, &unknown)
            .map_err(|m| self.err(i, format!("repeat count: {m}")))?;
        if v < 0.0 || v.fract() != 0.0 || v > 1e6 {
            return Err(self.err(
                i,
                format!("repeat count {v} is not a whole number from 0 to 1000000"),
            ));
        }
        Ok(v as u32)
    }
}
