//! Fanuc custom macros (Macro B) run offline, within the resolution pass of
//! [`super::subprograms`]: variables the program sets (`#1`–`#33` local to
//! a call level, `#100`–`#199` and `#500`–`#999` common), `G65 P… A… B…`
//! calls with their arguments as locals, `IF`/`WHILE`/`GOTO` on values
//! known before the program runs. A value only the control knows (a system
//! variable such as `#5021`, `#3000`, a probe result, a variable read
//! before it is set) is refused naming the variable and the line.

use std::collections::HashMap;

use super::macros::{Statement, label, substitute};
use super::subprograms::{Kind, Resolver};
use super::{Block, parse_line, strip_eol};
use crate::error::Located;

/// The local variables `#1`–`#33` of a call level (index 0 unused).
pub(super) type Locals = [Option<f64>; 34];

/// Most macro statements a program may run (a loop that does not end).
pub const MAX_STEPS: u64 = 10_000_000;

/// Variables and the line ranges being run.
#[derive(Debug, Clone)]
pub(super) struct State {
    commons: HashMap<u32, f64>,
    pub(super) frames: Vec<Locals>,
    pub(super) ranges: Vec<(usize, usize)>,
    steps: u64,
}

impl Default for State {
    fn default() -> Self {
        State {
            commons: HashMap::new(),
            frames: vec![[None; 34]],
            ranges: Vec::new(),
            steps: 0,
        }
    }
}

impl State {
    fn lookup(&self, n: u32) -> Result<f64, String> {
        match n {
            0 => Err("`#0` (vacant) has no value".into()),
            1..=33 => self
                .frames
                .last()
                .and_then(|f| f[n as usize])
                .ok_or_else(|| format!("local variable `#{n}` is read before it is set")),
            100..=199 | 500..=999 => self.commons.get(&n).copied().ok_or_else(|| {
                format!("`#{n}` is read before the program sets it (its value is the control's)")
            }),
            _ => Err(format!(
                "`#{n}` is a system variable, known only on the control at run time"
            )),
        }
    }

    fn value(&self, text: &[u8]) -> Result<f64, String> {
        super::expr::eval(text, &|n| self.lookup(n))
    }

    /// The value of a word's expression with its sign (`-#1`).
    fn signed(&self, text: &[u8]) -> Result<f64, String> {
        match text.first() {
            Some(b'-') => self.value(&text[1..]).map(|v| -v),
            Some(b'+') => self.value(&text[1..]),
            _ => self.value(text),
        }
    }

    /// Sets variable `n` (as evaluated) to `v`, or says why it cannot be
    /// set.
    fn set(&mut self, n: f64, v: f64) -> Result<(), String> {
        if n.fract() != 0.0 || !(0.0..1e6).contains(&n) {
            return Err(format!("`#{n}` is no variable"));
        }
        let n = n as u32;
        match n {
            1..=33 => {
                if let Some(f) = self.frames.last_mut() {
                    f[n as usize] = Some(v);
                }
                Ok(())
            }
            100..=199 | 500..=999 => {
                self.commons.insert(n, v);
                Ok(())
            }
            _ => Err(format!(
                "`#{n}` is a system variable: setting it acts on the control at run time"
            )),
        }
    }
}

/// The local variable each `G65` argument letter sets (Fanuc argument
/// specification I).
fn argument(letter: u8) -> Option<usize> {
    Some(match letter {
        b'A' => 1,
        b'B' => 2,
        b'C' => 3,
        b'I' => 4,
        b'J' => 5,
        b'K' => 6,
        b'D' => 7,
        b'E' => 8,
        b'F' => 9,
        b'H' => 11,
        b'M' => 13,
        b'Q' => 17,
        b'R' => 18,
        b'S' => 19,
        b'T' => 20,
        b'U' => 21,
        b'V' => 22,
        b'W' => 23,
        b'X' => 24,
        b'Y' => 25,
        b'Z' => 26,
        _ => return None,
    })
}

impl Resolver<'_> {
    /// The program numbers `G65 P…` lines call (literal `P`).
    pub(super) fn g65_targets(&self) -> Vec<u32> {
        let mut out = Vec::new();
        for &(s, e) in &self.exp.lines {
            let t = &self.text[s..e];
            let Some(g) = t.windows(3).position(|w| w.eq_ignore_ascii_case(b"G65")) else {
                continue;
            };
            if let Some(p) = t[g..].iter().position(|c| c.eq_ignore_ascii_case(&b'P')) {
                let digits: String = t[g + p + 1..]
                    .iter()
                    .skip_while(|c| **c == b' ')
                    .take_while(|c| c.is_ascii_digit())
                    .map(|&c| c as char)
                    .collect();
                out.extend(digits.parse::<u32>().ok());
            }
        }
        out
    }

    /// Runs the macro statement `st` of line `i` in call `call`: the next
    /// line to run.
    pub(super) fn statement(
        &mut self,
        i: usize,
        st: Statement,
        call: usize,
        depth: usize,
    ) -> Result<usize, Located> {
        self.exp.flat = true;
        self.tick(i)?;
        let line = strip_eol(self.exp.line(self.text, i)).to_vec();
        let span = |r: (u32, u32)| &line[r.0 as usize..r.1 as usize];
        match st {
            Statement::Assign { var, value } => {
                let (n, v) = self.assign(i, span(var), span(value))?;
                if self.control_assigns((span(var), span(value)), n, v) {
                    self.write_statement(i);
                }
                Ok(i + 1)
            }
            Statement::IfThen { cond, var, value } => {
                let on_control = self.control.value(span(cond)).map(|c| c != 0.0);
                if self.truth(i, span(cond))? {
                    let (n, v) = self.assign(i, span(var), span(value))?;
                    if on_control == Ok(true)
                        && self.control_assigns((span(var), span(value)), n, v)
                    {
                        self.write_statement(i);
                    }
                } else if on_control == Ok(false) {
                    self.write_statement(i);
                }
                Ok(i + 1)
            }
            Statement::IfGoto { cond, target } => {
                if self.truth(i, span(cond))? {
                    self.goto(i, span(target))
                } else {
                    Ok(i + 1)
                }
            }
            Statement::Goto { target } => self.goto(i, span(target)),
            Statement::While { cond, id } => {
                if self.truth(i, span(cond))? {
                    Ok(i + 1)
                } else {
                    Ok(self.find_loop(i, id, true)? + 1)
                }
            }
            Statement::End { id } => self.find_loop(i, id, false),
            Statement::Words => {
                let (text, values) =
                    substitute(&line, &|e| self.macros.value(e)).map_err(|m| self.err(i, m))?;
                let mut block = Block::default();
                parse_line(&text, i + 1, self.file, &mut block)?;
                if block
                    .words
                    .iter()
                    .any(|w| w.letter == b'G' && w.code10() == 650)
                {
                    self.g65(i, &text, call, depth)?;
                } else {
                    if block
                        .words
                        .iter()
                        .any(|w| w.letter == b'M' && matches!(w.code10(), 980 | 990))
                    {
                        return Err(self.err(
                            i,
                            "M98/M99 with macro values are not followed offline".into(),
                        ));
                    }
                    let k = self.exp.trace.len();
                    self.push(i, call)?;
                    self.exp.synth.insert(k, text);
                    // Expressions the control evaluates to the same value
                    // in the program written out as it runs.
                    let kept: Vec<_> = values
                        .iter()
                        .filter_map(|v| {
                            let expr = &line[v.expr.0 as usize..v.expr.1 as usize];
                            let same = self.control.signed(expr).is_ok_and(|c| c == v.value);
                            same.then(|| (v.out, expr.to_vec()))
                        })
                        .collect();
                    if !kept.is_empty() {
                        self.exp.kept.insert(k, kept);
                    }
                }
                Ok(i + 1)
            }
        }
    }

    /// Counts one statement run at line `i`, refusing a program that runs
    /// more than [`MAX_STEPS`] (a loop that does not end).
    pub(super) fn tick(&mut self, i: usize) -> Result<(), Located> {
        self.macros.steps += 1;
        if self.macros.steps > MAX_STEPS {
            return Err(self.err(
                i,
                format!("the macro statements do not end within {MAX_STEPS} steps"),
            ));
        }
        Ok(())
    }

    /// The condition `cond` of line `i`, evaluated with the program's
    /// variables (non-zero is true).
    pub(super) fn truth(&self, i: usize, cond: &[u8]) -> Result<bool, Located> {
        self.macros
            .value(cond)
            .map(|v| v != 0.0)
            .map_err(|m| self.err(i, m))
    }

    /// Runs `#var = value` of line `i`: the variable and its value.
    fn assign(&mut self, i: usize, var: &[u8], value: &[u8]) -> Result<(f64, f64), Located> {
        let n = self.macros.value(var).map_err(|m| self.err(i, m))?;
        let v = self.macros.value(value).map_err(|m| self.err(i, m))?;
        self.macros.set(n, v).map_err(|m| self.err(i, m))?;
        Ok((n, v))
    }

    /// Whether the control, running the program written out as it runs,
    /// finds `#n = v` in the words `#var = value` (its variables those
    /// the written assignment lines set); when it does, it sets it.
    fn control_assigns(&mut self, (var, value): (&[u8], &[u8]), n: f64, v: f64) -> bool {
        self.control.value(var).is_ok_and(|c| c == n)
            && self.control.value(value).is_ok_and(|c| c == v)
            && self.control.set(n, v).is_ok()
    }

    /// An assignment line `i` written out with the program as it runs,
    /// before the next block.
    fn write_statement(&mut self, i: usize) {
        self.exp.statements.push((self.exp.trace.len(), i));
    }

    /// The line of block number `target` in the range being run.
    fn goto(&self, i: usize, target: &[u8]) -> Result<usize, Located> {
        let n = self.macros.value(target).map_err(|m| self.err(i, m))?;
        let (from, to) = self.macros.ranges.last().copied().unwrap_or((0, 0));
        (from..to)
            .find(|&j| {
                let t = self.exp.line(self.text, j);
                label(t).1.is_some_and(|l| f64::from(l) == n)
            })
            .ok_or_else(|| self.err(i, format!("GOTO {n}: no block N{n} in this program")))
    }

    /// The `ENDm` after (`forward`) or the `WHILE … DOm` before line `i`.
    fn find_loop(&self, i: usize, id: u32, forward: bool) -> Result<usize, Located> {
        let (from, to) = self.macros.ranges.last().copied().unwrap_or((0, 0));
        let is = |j: usize| match self.kinds[j] {
            Kind::Macro(Statement::End { id: e }) => forward && e == id,
            Kind::Macro(Statement::While { id: w, .. }) => !forward && w == id,
            _ => false,
        };
        let found = if forward {
            (i + 1..to).find(|&j| is(j))
        } else {
            (from..i).rev().find(|&j| is(j))
        };
        found.ok_or_else(|| {
            self.err(
                i,
                if forward {
                    format!("WHILE … DO{id} has no END{id}")
                } else {
                    format!("END{id} without its WHILE … DO{id}")
                },
            )
        })
    }

    /// `G65 P… L… A… B…` on line `i` (as `text`, its values numbers).
    pub(super) fn g65(
        &mut self,
        i: usize,
        text: &[u8],
        call: usize,
        depth: usize,
    ) -> Result<(), Located> {
        let mut block = Block::default();
        parse_line(text, i + 1, self.file, &mut block)?;
        let p = block.word(b'P').and_then(|w| w.whole());
        let Some(&def) = p.and_then(|p| self.by_number.get(&p)) else {
            return Err(self.err(
                i,
                "G65 calls a program that is not in this file (macros are read from the program's own file)".into(),
            ));
        };
        let times = block.word(b'L').and_then(|w| w.whole()).unwrap_or(1);
        let mut locals: Locals = [None; 34];
        for w in &block.words {
            if let Some(slot) = argument(w.letter) {
                locals[slot] = Some(w.value);
            }
        }
        self.call_with(def, i, times, call, depth + 1, Some(locals))
    }
}
