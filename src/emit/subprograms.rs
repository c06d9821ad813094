//! Writes a compensated program with its subprograms: the structure the
//! control expects, never a silent inline.
//!
//! The pipeline compensates the program as it runs (every call of every
//! subprogram, [`crate::program::gcode::subprograms`]) and hands over each
//! run line's output. A subprogram (or loop) whose output is the same for
//! every call is written once, as it stands in the program. One whose calls
//! need different corrections is written once per distinct compensated
//! body: the first keeps its number or name, each other is written right
//! after it under a new one (the next number not used in the file, `O2001`;
//! `<name_1>` for an O-word name), and every call points to its copy. A
//! call that ran several times (`M98 P2000 L4`, `o100 repeat [4]`) is
//! written as runs of consecutive calls of one copy, each with its count.
//! Lines that never ran (after `M30`, a subprogram never called) are
//! written as they are.

use std::collections::HashMap;

use crate::program::gcode::subprograms::{DefKind, Expansion, Kept};
use crate::program::gcode::{Block, parse_line, strip_eol};

/// The output of each run line: `bytes`, cut at `marks` (where the output
/// of trace entry `k` ends).
#[derive(Debug, Clone, Copy)]
pub struct Outputs<'a> {
    /// Everything the pipeline wrote.
    pub bytes: &'a [u8],
    /// End of each trace entry's output in `bytes`.
    pub marks: &'a [usize],
}

impl Outputs<'_> {
    fn entry(&self, k: usize) -> &[u8] {
        let start = if k == 0 { 0 } else { self.marks[k - 1] };
        &self.bytes[start..self.marks[k]]
    }
}

/// What [`write`] made of the subprograms.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Written {
    /// Subprograms and loops of the program that ran.
    pub subprograms: usize,
    /// New subprograms (and loops) written because calls needed
    /// different corrections.
    pub copies: usize,
    /// A macro program written out as it runs: its lines written.
    pub flattened: Option<usize>,
}

/// Writes the program `text` followed as `exp`: `compare` is the output
/// the calls are compared by (without annotations), `out` the output
/// written (the same runs, with annotations when asked).
pub fn write(exp: &Expansion, text: &[u8], compare: Outputs, out: Outputs) -> (Vec<u8>, Written) {
    if exp.flat {
        return flat(exp, text, out);
    }
    let mut r = Render::new(exp, text);
    r.keys(compare);
    let written = r.assign();
    let mut buf = Vec::with_capacity(text.len() + text.len() / 4);
    r.range(0, exp.lines.len(), 0, Mode::Final(out), &mut buf);
    (buf, written)
}

#[derive(Clone, Copy)]
enum Mode<'a> {
    /// Bodies as compared: nested calls by their key.
    Key(Outputs<'a>),
    /// Bodies as written.
    Final(Outputs<'a>),
}

struct Render<'a> {
    exp: &'a Expansion,
    text: &'a [u8],
    /// Trace entry of (line, call).
    at: HashMap<(usize, usize), usize>,
    /// Calls made from (call, line), in order.
    children: HashMap<(usize, usize), Vec<usize>>,
    /// Each call's body key (interned per definition).
    key: Vec<usize>,
    /// Each call's copy of its definition.
    copy: Vec<usize>,
    /// Per definition: name and representative call of each copy.
    copies: Vec<Vec<(String, usize)>>,
}

impl<'a> Render<'a> {
    fn new(exp: &'a Expansion, text: &'a [u8]) -> Self {
        let at = exp
            .trace
            .iter()
            .enumerate()
            .map(|(k, &(line, call))| ((line, call), k))
            .collect();
        let mut children: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        for (c, call) in exp.calls.iter().enumerate().skip(1) {
            children
                .entry((call.parent, call.line))
                .or_default()
                .push(c);
        }
        Render {
            exp,
            text,
            at,
            children,
            key: vec![0; exp.calls.len()],
            copy: vec![0; exp.calls.len()],
            copies: vec![Vec::new(); exp.defs.len()],
        }
    }

    /// Each call's key: its body as compared (innermost calls first: a
    /// call comes after the call it is made in).
    fn keys(&mut self, compare: Outputs) {
        let mut interned: Vec<HashMap<Vec<u8>, usize>> = vec![HashMap::new(); self.exp.defs.len()];
        for c in (1..self.exp.calls.len()).rev() {
            let d = self.exp.calls[c].def;
            let def = &self.exp.defs[d];
            let mut body = Vec::new();
            self.range(def.head + 1, def.end, c, Mode::Key(compare), &mut body);
            let ids = &mut interned[d];
            let next = ids.len();
            self.key[c] = *ids.entry(body).or_insert(next);
        }
    }

    /// Copies in order of their first call, with their names.
    fn assign(&mut self) -> Written {
        let mut names = self.exp.names.clone();
        let mut first: Vec<HashMap<usize, usize>> = vec![HashMap::new(); self.exp.defs.len()];
        for c in 1..self.exp.calls.len() {
            let d = self.exp.calls[c].def;
            let n = first[d].len();
            let copy = *first[d].entry(self.key[c]).or_insert(n);
            self.copy[c] = copy;
            if copy == self.copies[d].len() {
                let name = if copy == 0 {
                    self.exp.defs[d].name.clone()
                } else {
                    fresh_name(&self.exp.defs[d].name, &mut names)
                };
                self.copies[d].push((name, c));
            }
        }
        Written {
            subprograms: self.copies.iter().filter(|c| !c.is_empty()).count(),
            copies: self.copies.iter().map(|c| c.len().saturating_sub(1)).sum(),
            flattened: None,
        }
    }

    /// Writes lines `from..to` as they run in `call`.
    fn range(&self, from: usize, to: usize, call: usize, mode: Mode, buf: &mut Vec<u8>) {
        let mut i = from;
        while i < to {
            let site = self.exp.sites.get(&i);
            let def_here = self
                .exp
                .defs
                .iter()
                .position(|d| d.head == i && d.kind != DefKind::Repeat);
            if let (Some(d), 0) = (def_here, call) {
                self.definition(d, mode, buf);
                i = self.exp.defs[d].end + 1;
                continue;
            }
            let kids = self.children.get(&(call, i)).map_or(&[][..], Vec::as_slice);
            match site {
                Some(s) if self.exp.defs[s.def].kind == DefKind::Repeat => {
                    let end = self.exp.defs[s.def].end;
                    if kids.is_empty() {
                        for j in i..=end {
                            buf.extend_from_slice(self.exp.line(self.text, j));
                        }
                    } else {
                        for run in runs(kids, |c| self.copy_or_key(c, mode)) {
                            self.repeat_run(i, run, mode, buf);
                        }
                    }
                    i = end + 1;
                    continue;
                }
                Some(_) if !kids.is_empty() => {
                    for run in runs(kids, |c| self.copy_or_key(c, mode)) {
                        match mode {
                            Mode::Key(_) => key_mark(
                                buf,
                                self.exp.calls[run[0]].def,
                                self.key[run[0]],
                                run.len(),
                            ),
                            Mode::Final(_) => self.site_line(i, run[0], run.len(), buf),
                        }
                    }
                }
                _ => self.plain(i, call, mode, buf),
            }
            i += 1;
        }
    }

    fn copy_or_key(&self, c: usize, mode: Mode) -> usize {
        match mode {
            Mode::Key(_) => self.key[c],
            Mode::Final(_) => self.copy[c],
        }
    }

    /// A line that is no call: its output in `call`, or its text when it
    /// did not run there.
    fn plain(&self, i: usize, call: usize, mode: Mode, buf: &mut Vec<u8>) {
        let line = self.exp.line(self.text, i);
        let Some(&k) = self.at.get(&(i, call)) else {
            buf.extend_from_slice(line);
            return;
        };
        let (Mode::Key(o) | Mode::Final(o)) = mode;
        let mut bytes = o.entry(k);
        // The stream gave a last line without an end of line one.
        if !line.ends_with(b"\n") {
            bytes = bytes.strip_suffix(b"\n").unwrap_or(bytes);
        }
        buf.extend_from_slice(bytes);
    }

    /// A subprogram definition: each copy with the body of its first call.
    fn definition(&self, d: usize, mode: Mode, buf: &mut Vec<u8>) {
        let def = &self.exp.defs[d];
        if self.copies[d].is_empty() {
            for j in def.head..=def.end {
                buf.extend_from_slice(self.exp.line(self.text, j));
            }
            return;
        }
        for (name, rep) in &self.copies[d] {
            self.renamed(def.head, def.head_name, name, None, buf);
            self.range(def.head + 1, def.end, *rep, mode, buf);
            match def.end_name {
                Some(span) => self.renamed(def.end, span, name, None, buf),
                None => buf.extend_from_slice(self.exp.line(self.text, def.end)),
            }
        }
    }

    /// A run of loop iterations of one copy from the loop at line `i`.
    fn repeat_run(&self, i: usize, run: &[usize], mode: Mode, buf: &mut Vec<u8>) {
        let c = run[0];
        let d = self.exp.calls[c].def;
        if let Mode::Key(_) = mode {
            key_mark(buf, d, self.key[c], run.len());
            return;
        }
        let def = &self.exp.defs[d];
        let site = self.exp.sites[&i];
        let name = &self.copies[d][self.copy[c]].0;
        let count = (run.len() as u32 != site.times)
            .then(|| site.count.map(|span| (span, format!("[{}]", run.len()))))
            .flatten();
        self.renamed(i, def.head_name, name, count, buf);
        self.range(def.head + 1, def.end, c, mode, buf);
        if let Some(span) = def.end_name {
            self.renamed(def.end, span, name, None, buf);
        }
    }

    /// Line `i` calling copy of call `c`, `times` times.
    fn site_line(&self, i: usize, c: usize, times: usize, buf: &mut Vec<u8>) {
        let site = self.exp.sites[&i];
        let d = self.exp.calls[c].def;
        let name = &self.copies[d][self.copy[c]].0;
        let line = self.exp.line(self.text, i);
        let times32 = times as u32;
        if site.packed {
            let written = if times > 1 {
                format!("{times}{:0>4}", name)
            } else {
                format!("{:0>4}", name)
            };
            self.renamed(i, site.name, &written, None, buf);
            return;
        }
        let count = match site.count {
            Some(span) if times32 != site.times => Some((span, times.to_string())),
            None if times > 1 => {
                let spaced = line.contains(&b' ');
                let at = site.after_name;
                Some((
                    (at, at),
                    format!("{}L{times}", if spaced { " " } else { "" }),
                ))
            }
            _ => None,
        };
        self.renamed(i, site.name, name, count, buf);
    }

    /// Line `i` with the name at `span` replaced by `name` (a program
    /// number with as many digits as written there; unchanged when it is
    /// the same) and `extra` written in its span.
    fn renamed(
        &self,
        i: usize,
        span: (u32, u32),
        name: &str,
        extra: Option<((u32, u32), String)>,
        buf: &mut Vec<u8>,
    ) {
        let line = self.exp.line(self.text, i);
        let here = &line[span.0 as usize..span.1 as usize];
        let name = match (
            std::str::from_utf8(here)
                .ok()
                .and_then(|h| h.parse::<u64>().ok()),
            name.parse::<u64>(),
        ) {
            (Some(a), Ok(b)) if a == b => String::from_utf8_lossy(here).to_string(),
            (Some(_), Ok(b)) => format!("{b:0w$}", w = here.len()),
            _ => name.to_string(),
        };
        let mut edits: Vec<((u32, u32), &[u8])> = Vec::new();
        if here != name.as_bytes() {
            edits.push((span, name.as_bytes()));
        }
        if let Some((s, t)) = &extra {
            // A bracketed count keeps the spaces before it.
            let written = &line[s.0 as usize..s.1 as usize];
            let lead = written.len() - written.trim_ascii_start().len();
            edits.push(((s.0 + lead as u32, s.1), t.as_bytes()));
        }
        edits.sort_by_key(|e| e.0);
        let mut pos = 0usize;
        for ((s, e), t) in edits {
            buf.extend_from_slice(&line[pos..s as usize]);
            buf.extend_from_slice(t);
            pos = e as usize;
        }
        // An edit reaching past the text keeps the end of the line.
        let text_end = strip_eol(line).len();
        if pos > text_end {
            buf.extend_from_slice(&line[text_end..]);
        } else {
            buf.extend_from_slice(&line[pos..]);
        }
    }
}

/// A program with macro statements: as written when no line moved;
/// else written out as it runs, every line with its values as numbers
/// (compensated where a correction applies), the loops and macro calls
/// run through and their statements left out, then the lines after the
/// main program's end (its subprograms) as they are.
fn flat(exp: &Expansion, text: &[u8], out: Outputs) -> (Vec<u8>, Written) {
    let same = (0..exp.trace.len()).all(|k| out.entry(k) == &exp.input(text, k)[..]);
    if same {
        return (text.to_vec(), Written::default());
    }
    let mut buf = Vec::with_capacity(out.bytes.len() + text.len() / 4);
    let mut lines = 0;
    let mut statements = exp.statements.iter().peekable();
    for k in 0..=exp.trace.len() {
        // The assignment lines that ran before this block.
        while let Some(&(_, i)) = statements.next_if(|s| s.0 <= k) {
            let line = exp.line(text, i);
            buf.extend_from_slice(line);
            if !line.ends_with(b"\n") {
                buf.push(b'\n');
            }
            lines += 1;
        }
        if k == exp.trace.len() {
            break;
        }
        let e = out.entry(k);
        let e = match (exp.kept.get(&k), exp.synth.get(&k)) {
            (Some(kept), Some(synth)) => with_expressions(e, synth, kept)
                .map_or(std::borrow::Cow::Borrowed(e), std::borrow::Cow::Owned),
            _ => std::borrow::Cow::Borrowed(e),
        };
        lines += e.iter().filter(|&&c| c == b'\n').count();
        buf.extend_from_slice(&e);
    }
    if let Some(end) = exp.main_end {
        for i in end + 1..exp.lines.len() {
            buf.extend_from_slice(exp.line(text, i));
        }
    }
    if !text.ends_with(b"\n")
        && exp.main_end.is_none_or(|e| e + 1 == exp.lines.len())
        && buf.ends_with(b"\n")
    {
        buf.pop();
    }
    (
        buf,
        Written {
            flattened: Some(lines),
            ..Written::default()
        },
    )
}

/// The output `e` of a block the program wrote with expressions, run as
/// `synth` (its values as numbers): the expressions of `kept` written
/// back on the block's own line (the first of `e` with every word letter
/// of the block, as often) where its number is still the one `synth`
/// wrote, that is where the compensation does not move the word (the
/// `n`-th word of a letter in `synth` is the `n`-th of the line). `None`
/// when no line of `e` is the block's own.
fn with_expressions(e: &[u8], synth: &[u8], kept: &[Kept]) -> Option<Vec<u8>> {
    let synth = strip_eol(synth);
    let mut written = Block::default();
    parse_line(synth, 1, "", &mut written).ok()?;
    // The `n`-th word of its letter: (letter, n).
    let nth = |b: &Block| {
        let mut seen = [0u32; 256];
        b.words
            .iter()
            .map(|w| {
                seen[w.letter as usize] += 1;
                (w.letter, seen[w.letter as usize])
            })
            .collect::<Vec<_>>()
    };
    let want = nth(&written);
    let mut start = 0;
    for line in e.split_inclusive(|&c| c == b'\n') {
        let own = strip_eol(line);
        let mut block = Block::default();
        let words = if parse_line(own, 1, "", &mut block).is_ok() {
            nth(&block)
        } else {
            Vec::new()
        };
        if want.iter().all(|k| words.contains(k)) {
            let mut out = e[..start].to_vec();
            let mut at = 0;
            for (w, key) in written.words.iter().zip(&want) {
                let expr = kept.iter().find(|(r, _)| *r == (w.num_start, w.end));
                let Some((_, expr)) = expr else { continue };
                let Some(o) = words.iter().position(|k| k == key).map(|p| &block.words[p]) else {
                    continue;
                };
                // Words in their order: one written before the last
                // written back stays as it is.
                if w.number_text(synth) == o.number_text(own) && o.num_start as usize >= at {
                    out.extend_from_slice(&own[at..o.num_start as usize]);
                    out.extend_from_slice(expr);
                    at = o.end as usize;
                }
            }
            out.extend_from_slice(&line[at..]);
            out.extend_from_slice(&e[start + line.len()..]);
            return Some(out);
        }
        start += line.len();
    }
    None
}

/// A nested call in a compared body: its definition, key and count.
fn key_mark(buf: &mut Vec<u8>, def: usize, key: usize, times: usize) {
    buf.extend_from_slice(format!("\0{def}:{key}:{times}\0").as_bytes());
}

/// Consecutive runs of `items` with the same `value`.
fn runs(items: &[usize], value: impl Fn(usize) -> usize) -> Vec<&[usize]> {
    let mut out = Vec::new();
    let mut start = 0;
    for k in 1..=items.len() {
        if k == items.len() || value(items[k]) != value(items[start]) {
            out.push(&items[start..k]);
            start = k;
        }
    }
    out
}

/// A name not used in the file for a copy of `name`: the next free number
/// above it (written with as many digits), or `<name_1>`, `<name_2>`, ….
fn fresh_name(name: &str, used: &mut std::collections::BTreeSet<String>) -> String {
    if let Ok(n) = name.parse::<u64>() {
        let width = name.len();
        let mut k = n + 1;
        while used.contains(&k.to_string()) {
            k += 1;
        }
        used.insert(k.to_string());
        return format!("{k:0width$}");
    }
    let stem = name.trim_start_matches('<').trim_end_matches('>');
    let mut k = 1;
    loop {
        let candidate = format!("<{stem}_{k}>");
        if used.insert(candidate.to_ascii_lowercase()) {
            return candidate;
        }
        k += 1;
    }
}
