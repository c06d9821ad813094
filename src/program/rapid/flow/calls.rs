//! Which data a call of a procedure may change: the arguments bound to the
//! procedure's `INOUT`, `VAR` and `PERS` parameters. A parameter without
//! one of those words is passed by value, so the call cannot change the
//! caller's data. A procedure whose parameters are not known (an
//! instruction of the controller, a procedure of no module of the
//! program) may change every name passed to it.

use super::super::{Module, RoutineKind, Scope, words};

/// One parameter of a procedure, or one group of alternatives
/// (`\switch On | switch Off`).
#[derive(Debug, Clone)]
struct Param {
    /// Optional (`\`): its argument names it.
    optional: bool,
    /// The alternatives: name (lower case), whether it is passed by
    /// reference (`INOUT`, `VAR`, `PERS`) and whether the procedure's body
    /// names it (a move to it, or to a value computed from it, is left as
    /// written: a parameter is known at run time only).
    alternatives: Vec<(String, bool, bool)>,
}

/// The procedures whose parameters are known, by name.
#[derive(Debug, Clone, Default)]
pub struct Procedures {
    /// Name (lower case) and parameters of each.
    procs: Vec<(String, Vec<Param>)>,
}

impl Procedures {
    /// The procedures of `module` (parsed from `src`): every one when
    /// `local` (the module's own view), else those other modules see (not
    /// `LOCAL`).
    pub fn of_module(module: &Module, src: &str, local: bool) -> Self {
        let mut out = Procedures::default();
        for p in &module.procs {
            if p.kind != RoutineKind::Proc || (!local && p.scope == Scope::Local) {
                continue;
            }
            let text = p.params.as_ref().and_then(|s| src.get(s.clone()));
            let mut ps = params(&super::without_comments(text.unwrap_or("")));
            if !ps.is_empty() {
                // The routine's text after its parameter list.
                let from = p.params.as_ref().map_or(p.span.start, |s| s.end);
                let body: Vec<&str> = words(src.get(from..p.span.end).unwrap_or("")).collect();
                for alt in ps.iter_mut().flat_map(|p| &mut p.alternatives) {
                    alt.2 = body.iter().any(|w| w.eq_ignore_ascii_case(&alt.0));
                }
            }
            out.add(&p.name, ps);
        }
        out
    }

    /// Adds the procedures of `other` whose names are not known yet.
    pub fn extend(&mut self, other: &Procedures) {
        for (name, params) in &other.procs {
            self.add(name, params.clone());
        }
    }

    fn add(&mut self, name: &str, params: Vec<Param>) {
        let lower = name.to_ascii_lowercase();
        if !self.procs.iter().any(|(n, _)| *n == lower) {
            self.procs.push((lower, params));
        }
    }

    /// The data names the call statement `text` (`Drill pHole, 30;`) of
    /// procedure `name` may change: the first name of each argument bound
    /// to a parameter passed by reference. `None` when the procedure is
    /// not known, or its arguments do not match its parameters (every name
    /// passed may then change).
    pub fn written<'t>(&self, name: &str, text: &'t str) -> Option<Vec<&'t str>> {
        let mut out = Vec::new();
        for (by_ref, _, value) in self.bound(name, text)? {
            if by_ref {
                let n = ident_len(value);
                let called = value.get(n..).unwrap_or("").trim_start().starts_with('(');
                if n > 0 && !called {
                    out.extend(value.get(..n));
                }
            }
        }
        Some(out)
    }

    /// The arguments of the call statement `text` of procedure `name`
    /// bound to parameters its body names (whole argument texts: `pHole`,
    /// `Offs(p, 0, 0, 5)`): a move of the procedure to such a parameter is
    /// left as written, so it reads what the argument reads. `None` as for
    /// [`Self::written`].
    pub fn named_by_body<'t>(&self, name: &str, text: &'t str) -> Option<Vec<&'t str>> {
        let bound = self.bound(name, text)?;
        Some(
            bound
                .into_iter()
                .filter(|(_, named, _)| *named)
                .map(|(_, _, value)| value)
                .collect(),
        )
    }

    /// The place of parameter `param` (lower case) of procedure `name`
    /// among its positional parameters, when it is one passed by value.
    pub fn by_value_position(&self, name: &str, param: &str) -> Option<usize> {
        let (_, params) = self
            .procs
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))?;
        let k = params
            .iter()
            .filter(|p| !p.optional)
            .position(|p| p.alternatives.iter().any(|a| a.0 == param))?;
        let p = params.iter().filter(|p| !p.optional).nth(k)?;
        (!p.alternatives.iter().any(|a| a.1)).then_some(k)
    }

    /// The positional arguments of the call statement `text` of procedure
    /// `name`, in order, when they match its positional parameters.
    pub fn positional<'t>(&self, name: &str, text: &'t str) -> Option<Vec<&'t str>> {
        let (_, params) = self
            .procs
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))?;
        let rest = after_name(text, name)?;
        let args: Vec<&str> = arguments(rest)
            .into_iter()
            .filter(|(optional, _)| !optional)
            .map(|(_, a)| a)
            .collect();
        (args.len() == params.iter().filter(|p| !p.optional).count()).then_some(args)
    }

    /// Each argument of the call statement `text` of procedure `name`:
    /// whether its parameter is passed by reference, whether the body
    /// names it, and the argument's value text. `None` as for
    /// [`Self::written`].
    fn bound<'t>(&self, name: &str, text: &'t str) -> Option<Vec<(bool, bool, &'t str)>> {
        let (_, params) = self
            .procs
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))?;
        let rest = after_name(text, name)?;
        let mut required = params.iter().filter(|p| !p.optional);
        let mut out = Vec::new();
        for (optional, arg) in arguments(rest) {
            if optional {
                let n = ident_len(arg);
                let word = arg.get(..n)?;
                let &(_, by_ref, named) = params
                    .iter()
                    .filter(|p| p.optional)
                    .flat_map(|p| &p.alternatives)
                    .find(|(a, ..)| a.eq_ignore_ascii_case(word))?;
                let value = arg.get(n..)?.trim_start();
                // `\Name` alone passes the data of that name.
                let value = value.strip_prefix(":=").map_or(word, str::trim_start);
                out.push((by_ref, named, value));
            } else {
                let p = required.next()?;
                let by_ref = p.alternatives.iter().any(|a| a.1);
                let named = p.alternatives.iter().any(|a| a.2);
                out.push((by_ref, named, arg));
            }
        }
        Some(out)
    }
}

/// The parameters of a parameter list (`robtarget p, INOUT num n,
/// \switch a | switch b, num t{*,*}`).
fn params(text: &str) -> Vec<Param> {
    split_top(text, b',')
        .into_iter()
        .filter(|g| !g.trim().is_empty())
        .map(|g| {
            let g = g.trim();
            let optional = g.starts_with('\\');
            let alternatives = g
                .split('|')
                .map(|alt| {
                    let alt = alt.split('{').next().unwrap_or("");
                    let words: Vec<&str> = alt
                        .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                        .filter(|w| !w.is_empty())
                        .collect();
                    let by_ref = words.iter().any(|w| {
                        ["INOUT", "VAR", "PERS"]
                            .iter()
                            .any(|k| k.eq_ignore_ascii_case(w))
                    });
                    let name = words
                        .last()
                        .map_or(String::new(), |w| w.to_ascii_lowercase());
                    (name, by_ref, false)
                })
                .collect();
            Param {
                optional,
                alternatives,
            }
        })
        .collect()
}

/// The text of a call statement after the procedure's name (without the
/// final `;`), when the statement starts with that name.
fn after_name<'t>(text: &'t str, name: &str) -> Option<&'t str> {
    let t = text.trim_start();
    let head = t.get(..name.len())?;
    if !head.eq_ignore_ascii_case(name) {
        return None;
    }
    let rest = t.get(name.len()..)?;
    if rest.starts_with(|c: char| c.is_ascii_alphanumeric() || c == '_') {
        return None;
    }
    let rest = rest.trim_end();
    Some(rest.strip_suffix(';').unwrap_or(rest))
}

/// The arguments of a call: each trimmed, with `true` for an optional one
/// (its text after the `\`: `WObj:=w`, `Conc`). Arguments are cut at the
/// commas and backslashes outside parentheses, brackets, braces, strings
/// and comments.
fn arguments(text: &str) -> Vec<(bool, &str)> {
    let mut out = Vec::new();
    let b = text.as_bytes();
    let (mut depth, mut k, mut from, mut optional) = (0usize, 0, 0, false);
    fn cut<'t>(
        text: &'t str,
        from: usize,
        to: usize,
        optional: bool,
        out: &mut Vec<(bool, &'t str)>,
    ) {
        let arg = text.get(from..to).unwrap_or("").trim();
        if !arg.is_empty() {
            out.push((optional, arg));
        }
    }
    while let Some(&c) = b.get(k) {
        match c {
            b'"' => {
                k += 1;
                while b.get(k).is_some_and(|&c| c != b'"') {
                    k += 1;
                }
            }
            b'!' => {
                cut(text, from, k, optional, &mut out);
                while b.get(k).is_some_and(|&c| c != b'\n') {
                    k += 1;
                }
                from = k;
                continue;
            }
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            b',' | b'\\' if depth == 0 => {
                cut(text, from, k, optional, &mut out);
                from = k + 1;
                optional = c == b'\\';
            }
            _ => {}
        }
        k += 1;
    }
    cut(text, from, text.len(), optional, &mut out);
    out
}

/// `text` cut at the bytes `sep` outside parentheses, brackets and braces.
fn split_top(text: &str, sep: u8) -> Vec<&str> {
    let mut out = Vec::new();
    let (mut depth, mut from) = (0usize, 0);
    for (k, c) in text.bytes().enumerate() {
        match c {
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' => depth = depth.saturating_sub(1),
            c if c == sep && depth == 0 => {
                out.extend(text.get(from..k));
                from = k + 1;
            }
            _ => {}
        }
    }
    out.extend(text.get(from..));
    out
}

/// The length of the identifier `text` starts with (0 when none).
fn ident_len(text: &str) -> usize {
    if !text.starts_with(|c: char| c.is_ascii_alphabetic()) {
        return 0;
    }
    text.bytes()
        .take_while(|b| b.is_ascii_alphanumeric() || *b == b'_')
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn procedures(module: &str) -> Procedures {
        let m = super::super::super::parse_module(module, "m.mod").expect("parses");
        Procedures::of_module(&m, module, true)
    }

    const MODULE: &str = "MODULE M\n  PROC Drill(robtarget pHole, num nDepth)\n  ENDPROC\n  PROC Shift(INOUT robtarget p, num dz, \\VAR num n | switch Fast, PERS num grid{*,*})\n  ENDPROC\nENDMODULE\n";

    #[test]
    fn arguments_by_value_are_not_written() {
        let p = procedures(MODULE);
        assert_eq!(p.written("Drill", "Drill pHole, 30;"), Some(vec![]));
        assert_eq!(
            p.written("drill", "drill Offs(p, 0, 0, n), n;"),
            Some(vec![])
        );
    }

    #[test]
    fn arguments_by_reference_are_written() {
        let p = procedures(MODULE);
        assert_eq!(
            p.written("Shift", "Shift pA, nZ\\n:=nCount, gGrid;"),
            Some(vec!["pA", "nCount", "gGrid"])
        );
        assert_eq!(
            p.written("Shift", "Shift pB{2}, 5, \\Fast, g;"),
            Some(vec!["pB", "g"])
        );
        assert_eq!(
            p.written("Shift", "Shift p, 1 \\n, g;"),
            Some(vec!["p", "n", "g"])
        );
    }

    #[test]
    fn unknown_procedures_and_mismatched_calls_are_not_known() {
        let p = procedures(MODULE);
        assert_eq!(p.written("Incr", "Incr n;"), None);
        assert_eq!(p.written("Drill", "Drill p, 1, 2;"), None);
        assert_eq!(p.written("Drill", "Drill p \\Fast;"), None);
    }
}
