//! Fanuc custom macro (Macro B) lines — syntax only: assignments
//! (`#100 = 25.`), `IF [cond] GOTO n`, `IF [cond] THEN #1 = …`, `WHILE
//! [cond] DOm` … `ENDm`, `GOTO n`, and blocks whose word values are
//! expressions (`G1 X#24 Y[#25 + 5.]`).
//!
//! A line the word syntax ([`super::parse_line`]) refuses is looked at here;
//! the resolution pass ([`super::subprograms`]) evaluates what this finds,
//! with the values of the program's own variables, and hands the
//! interpreter the block with every value written as a number
//! ([`substitute`]).

/// A macro statement, as byte ranges of its line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Statement {
    /// `#100 = expr`: the variable (after `#`) and the value.
    Assign {
        /// The variable's number or bracketed expression, after `#`.
        var: (u32, u32),
        /// The value expression.
        value: (u32, u32),
    },
    /// `IF [cond] GOTO n`.
    IfGoto {
        /// The bracketed condition.
        cond: (u32, u32),
        /// The block number expression.
        target: (u32, u32),
    },
    /// `IF [cond] THEN #1 = expr`.
    IfThen {
        /// The bracketed condition.
        cond: (u32, u32),
        /// The variable after `#`.
        var: (u32, u32),
        /// The value expression.
        value: (u32, u32),
    },
    /// `WHILE [cond] DOm`.
    While {
        /// The bracketed condition.
        cond: (u32, u32),
        /// The loop's number `m` (1 to 3).
        id: u32,
    },
    /// `ENDm`.
    End {
        /// The loop's number.
        id: u32,
    },
    /// `GOTO n`.
    Goto {
        /// The block number expression.
        target: (u32, u32),
    },
    /// A block with expressions as word values.
    Words,
}

fn ws(t: &[u8], mut i: usize) -> usize {
    while matches!(t.get(i), Some(b' ' | b'\t')) {
        i += 1;
    }
    i
}

fn keyword(t: &[u8], i: usize, k: &[u8]) -> Option<usize> {
    let end = i + k.len();
    t.get(i..end)
        .is_some_and(|w| w.eq_ignore_ascii_case(k))
        .then_some(end)
}

/// Where the line's statement starts: after an optional block number
/// `N120`; and that number.
pub fn label(t: &[u8]) -> (usize, Option<u32>) {
    let i = ws(t, 0);
    if t.get(i).is_some_and(|c| c.eq_ignore_ascii_case(&b'N')) {
        let d = t[i + 1..].iter().take_while(|c| c.is_ascii_digit()).count();
        if d > 0 {
            let n = std::str::from_utf8(&t[i + 1..i + 1 + d])
                .ok()
                .and_then(|s| s.parse().ok());
            return (ws(t, i + 1 + d), n);
        }
    }
    (i, None)
}

/// The end of the text before a comment (`(` or `;`), spaces trimmed.
fn code_end(t: &[u8], from: usize) -> usize {
    let mut depth = 0usize;
    let mut end = t.len();
    for (i, &c) in t.iter().enumerate().skip(from) {
        match c {
            b'[' => depth += 1,
            b']' => depth = depth.saturating_sub(1),
            b'(' | b';' if depth == 0 => {
                end = i;
                break;
            }
            _ => {}
        }
    }
    let mut e = end;
    while e > from && matches!(t[e - 1], b' ' | b'\t') {
        e -= 1;
    }
    e
}

/// `#var = value` from `i`.
fn assignment(t: &[u8], i: usize) -> Option<((u32, u32), (u32, u32))> {
    if t.get(i) != Some(&b'#') {
        return None;
    }
    let eq = i + t[i..].iter().position(|&c| c == b'=')?;
    let v = ws(t, eq + 1);
    let mut var_end = eq;
    while var_end > i + 1 && matches!(t[var_end - 1], b' ' | b'\t') {
        var_end -= 1;
    }
    Some((
        ((i + 1) as u32, var_end as u32),
        (v as u32, code_end(t, v) as u32),
    ))
}

/// The bracketed condition at `i`: its range and the position after it.
fn condition(t: &[u8], i: usize) -> Option<((u32, u32), usize)> {
    let i = ws(t, i);
    let len = super::expr::bracket_len(t.get(i..)?)?;
    Some(((i as u32, (i + len) as u32), i + len))
}

/// The macro statement of line `text` (without its end of line), or
/// `None` when it holds none.
pub fn statement(text: &[u8]) -> Option<Statement> {
    let (i, _) = label(text);
    // Output statements run on the controller (named by the dialect
    // pass).
    for k in [&b"DPRNT"[..], b"BPRNT", b"POPEN", b"PCLOS", b"SETVN"] {
        if keyword(text, i, k).is_some() {
            return None;
        }
    }
    if let Some((var, value)) = assignment(text, i) {
        return Some(Statement::Assign { var, value });
    }
    if let Some(j) = keyword(text, i, b"IF") {
        let (cond, after) = condition(text, j)?;
        let k = ws(text, after);
        if let Some(g) = keyword(text, k, b"GOTO") {
            let s = ws(text, g);
            return Some(Statement::IfGoto {
                cond,
                target: (s as u32, code_end(text, s) as u32),
            });
        }
        let th = keyword(text, k, b"THEN")?;
        let (var, value) = assignment(text, ws(text, th))?;
        return Some(Statement::IfThen { cond, var, value });
    }
    if let Some(j) = keyword(text, i, b"WHILE") {
        let (cond, after) = condition(text, j)?;
        let d = keyword(text, ws(text, after), b"DO")?;
        let id = digit(text, d)?;
        return Some(Statement::While { cond, id });
    }
    if let Some(j) = keyword(text, i, b"GOTO") {
        let s = ws(text, j);
        return Some(Statement::Goto {
            target: (s as u32, code_end(text, s) as u32),
        });
    }
    if let Some(j) = keyword(text, i, b"END") {
        if let Some(id) = digit(text, j) {
            return Some(Statement::End { id });
        }
    }
    let code = &text[..code_end(text, 0)];
    (code.contains(&b'#') || code.contains(&b'[')).then_some(Statement::Words)
}

/// The loop number `1`…`9` at `i` (alone).
fn digit(t: &[u8], i: usize) -> Option<u32> {
    let c = *t.get(i)?;
    let next = t.get(i + 1);
    (c.is_ascii_digit() && !next.is_some_and(u8::is_ascii_digit)).then(|| u32::from(c - b'0'))
}

/// One expression word value replaced by [`substitute`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Value {
    /// Byte range of the number written in the output.
    pub out: (u32, u32),
    /// Byte range of the expression in the input, its sign included
    /// (`-#1`).
    pub expr: (u32, u32),
    /// Its value.
    pub value: f64,
}

/// `text` with every expression word value (`#24`, `-#1`, `[#1 + 2]`,
/// `#[#1 + 1]`) replaced by its value from `eval`, written as a number the
/// word syntax reads; comments and everything else left as they are. With
/// it, where each value was and where its number is.
pub fn substitute(
    text: &[u8],
    eval: &dyn Fn(&[u8]) -> Result<f64, String>,
) -> Result<(Vec<u8>, Vec<Value>), String> {
    let mut values = Vec::new();
    let mut out = Vec::with_capacity(text.len() + 8);
    let mut i = 0;
    let mut letter = b' ';
    while i < text.len() {
        let c = text[i];
        match c {
            b'(' => {
                let close = super::comment_close(text, i).map_or(text.len(), |p| p + 1);
                out.extend_from_slice(&text[i..close]);
                i = close;
                continue;
            }
            b';' => {
                out.extend_from_slice(&text[i..]);
                break;
            }
            _ if c.is_ascii_alphabetic() => letter = c.to_ascii_uppercase(),
            _ => {}
        }
        // A sign opens a value right after a letter (`X-#1`).
        let after_letter = out
            .iter()
            .rev()
            .find(|b| !matches!(b, b' ' | b'\t'))
            .is_some_and(u8::is_ascii_alphabetic);
        let sign = usize::from(matches!(c, b'-' | b'+') && after_letter);
        if !matches!(text.get(i + sign), Some(b'#' | b'[')) {
            out.push(c);
            i += 1;
            continue;
        }
        let start = i + sign;
        let len = value_len(&text[start..]).ok_or("an expression does not close")?;
        let mut v = eval(&text[start..start + len])?;
        if c == b'-' {
            v = -v;
        }
        let at = out.len() as u32;
        out.extend_from_slice(number(letter, v).as_bytes());
        values.push(Value {
            out: (at, out.len() as u32),
            expr: (i as u32, (start + len) as u32),
            value: v,
        });
        i = start + len;
    }
    Ok((out, values))
}

/// Length of the value at the start of `t`: `#digits`, `#[…]` or `[…]`.
fn value_len(t: &[u8]) -> Option<usize> {
    match t.first()? {
        b'[' => super::expr::bracket_len(t),
        b'#' => {
            if t.get(1) == Some(&b'[') {
                super::expr::bracket_len(&t[1..]).map(|n| n + 1)
            } else {
                let d = t[1..].iter().take_while(|c| c.is_ascii_digit()).count();
                (d > 0).then_some(d + 1)
            }
        }
        _ => None,
    }
}

/// `v` as the word of `letter` is written: whole codes and numbers
/// (`G`, `M`, `N`, `T`, `H`, `D`, `P`, `L`, `O`) without a point, other
/// values with a point and at most four decimals.
pub fn number(letter: u8, v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    if b"GMNTHDPLO".contains(&letter) && v.fract() == 0.0 {
        return format!("{v:.0}");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0');
    if s == "-0." {
        "0.".into()
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statements_are_found_with_their_parts() {
        let t = b"N10 #101 = #101 + 1. (NEXT)";
        let Some(Statement::Assign { var, value }) = statement(t) else {
            panic!("an assignment")
        };
        assert_eq!(&t[var.0 as usize..var.1 as usize], b"101");
        assert_eq!(&t[value.0 as usize..value.1 as usize], b"#101 + 1.");
        let t = b"WHILE [#1 LT 6] DO1";
        assert!(matches!(statement(t), Some(Statement::While { id: 1, .. })));
        assert_eq!(statement(b"END1"), Some(Statement::End { id: 1 }));
        assert!(matches!(
            statement(b"IF [#1 GT 2] GOTO 20"),
            Some(Statement::IfGoto { .. })
        ));
        assert!(matches!(
            statement(b"IF [#1 EQ 0] THEN #2 = 5"),
            Some(Statement::IfThen { .. })
        ));
        assert!(matches!(
            statement(b"GOTO 99"),
            Some(Statement::Goto { .. })
        ));
        assert_eq!(statement(b"G1 X#24 Y[#25 + 1]"), Some(Statement::Words));
        assert_eq!(statement(b"G1 X1 (#1)"), None);
    }

    #[test]
    fn values_are_written_as_numbers() {
        let vars = |e: &[u8]| -> Result<f64, String> {
            super::super::expr::eval(e, &|n| {
                if n == 1 {
                    Ok(2.5)
                } else {
                    Err(format!("#{n}"))
                }
            })
        };
        let text = b"G1 X#1 Y-#1 Z[#1 * 2] F100. (AT #1)";
        let (got, values) = substitute(text, &vars).unwrap();
        assert_eq!(got, b"G1 X2.5 Y-2.5 Z5. F100. (AT #1)");
        let spans: Vec<(&[u8], &[u8], f64)> = values
            .iter()
            .map(|v| {
                (
                    &got[v.out.0 as usize..v.out.1 as usize],
                    &text[v.expr.0 as usize..v.expr.1 as usize],
                    v.value,
                )
            })
            .collect();
        assert_eq!(
            spans,
            [
                (&b"2.5"[..], &b"#1"[..], 2.5),
                (b"-2.5", b"-#1", -2.5),
                (b"5.", b"[#1 * 2]", 5.0)
            ]
        );
        let (got, _) = substitute(b"G[#1 - 1.5]", &vars).unwrap();
        assert_eq!(got, b"G1");
        assert_eq!(substitute(b"X#7", &vars).unwrap_err(), "#7");
        assert_eq!(number(b'X', 1.0 / 3.0), "0.3333");
        assert_eq!(number(b'X', -0.00001), "0.");
    }
}
