//! Expressions of Fanuc custom macros (Macro B) and LinuxCNC, evaluated
//! where every value is known before the program runs.
//!
//! `[#1 + 2.5] * SIN[30]`, `ATAN[#2]/[#3]`, `[#1 LT 5] AND [#2 NE 0]`: numbers,
//! `#` variables (looked up by the caller, which refuses those only the
//! control knows), `+ - * / MOD`, the comparisons `EQ NE GT GE LT LE`
//! (true is 1, false 0), `AND OR XOR`, and the functions `SIN COS TAN ASIN
//! ACOS ATAN` (degrees), `SQRT ABS ROUND FIX FUP LN EXP`. Keywords are
//! read in any case. Errors are messages for the caller to locate.

/// A variable's value for the evaluator: `Err` with the reason when it is
/// not known offline.
pub type Lookup<'a> = &'a dyn Fn(u32) -> Result<f64, String>;

/// Most nested brackets and unary signs an expression may hold.
const MAX_DEPTH: usize = 64;

/// The value of `text`, a whole expression.
pub fn eval(text: &[u8], vars: Lookup) -> Result<f64, String> {
    let mut p = Parser {
        s: text,
        i: 0,
        vars,
        depth: 0,
    };
    let v = p.or()?;
    p.ws();
    if p.i < p.s.len() {
        return Err(format!("unexpected `{}` in an expression", p.rest()));
    }
    Ok(v)
}

/// The number of a `#` variable reference starting at `text[0] == b'#'`
/// and its length (`#100` → 100, 4; `#[#1+1]` evaluated), or `None` when
/// it is not one.
pub fn variable(text: &[u8], vars: Lookup) -> Result<(u32, usize), String> {
    let mut p = Parser {
        s: text,
        i: 0,
        vars,
        depth: 0,
    };
    if !p.eat(b"#") {
        return Err("not a variable".into());
    }
    let n = p.index()?;
    Ok((n, p.i))
}

/// The length of the bracketed group opening `text` (`[` … matching `]`),
/// or `None` when it does not close.
pub fn bracket_len(text: &[u8]) -> Option<usize> {
    let mut depth = 0usize;
    for (i, &c) in text.iter().enumerate() {
        match c {
            b'[' => depth += 1,
            b']' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    return Some(i + 1);
                }
            }
            _ if depth == 0 => return None,
            _ => {}
        }
    }
    None
}

struct Parser<'a> {
    s: &'a [u8],
    i: usize,
    vars: Lookup<'a>,
    depth: usize,
}

impl Parser<'_> {
    fn rest(&self) -> String {
        let r = String::from_utf8_lossy(self.s.get(self.i..).unwrap_or(b""));
        r.chars().take(20).collect()
    }

    fn ws(&mut self) {
        while matches!(self.s.get(self.i), Some(b' ' | b'\t')) {
            self.i += 1;
        }
    }

    /// Consumes `word` (any case) when it comes next.
    fn eat(&mut self, word: &[u8]) -> bool {
        self.ws();
        let end = self.i + word.len();
        let hit = self
            .s
            .get(self.i..end)
            .is_some_and(|t| t.eq_ignore_ascii_case(word));
        // A keyword is not the start of a longer word (`OR` in `ORIGIN`).
        let alpha = word.first().is_some_and(u8::is_ascii_alphabetic);
        if hit && !(alpha && self.s.get(end).is_some_and(u8::is_ascii_alphabetic)) {
            self.i = end;
            true
        } else {
            false
        }
    }

    fn deeper(&mut self) -> Result<(), String> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err("expression nested too deeply".into());
        }
        Ok(())
    }

    fn or(&mut self) -> Result<f64, String> {
        let mut v = self.and()?;
        loop {
            if self.eat(b"OR") {
                let r = self.and()?;
                v = f64::from(u8::from(v != 0.0 || r != 0.0));
            } else if self.eat(b"XOR") {
                let r = self.and()?;
                v = f64::from(u8::from((v != 0.0) != (r != 0.0)));
            } else {
                return Ok(v);
            }
        }
    }

    fn and(&mut self) -> Result<f64, String> {
        let mut v = self.cmp()?;
        while self.eat(b"AND") {
            let r = self.cmp()?;
            v = f64::from(u8::from(v != 0.0 && r != 0.0));
        }
        Ok(v)
    }

    fn cmp(&mut self) -> Result<f64, String> {
        let v = self.add()?;
        type Cmp = fn(f64, f64) -> bool;
        let ops: [(&[u8], Cmp); 6] = [
            (b"EQ", |a, b| a == b),
            (b"NE", |a, b| a != b),
            (b"GT", |a, b| a > b),
            (b"GE", |a, b| a >= b),
            (b"LT", |a, b| a < b),
            (b"LE", |a, b| a <= b),
        ];
        for (word, op) in ops {
            if self.eat(word) {
                let r = self.add()?;
                return Ok(f64::from(u8::from(op(v, r))));
            }
        }
        Ok(v)
    }

    fn add(&mut self) -> Result<f64, String> {
        let mut v = self.mul()?;
        loop {
            if self.eat(b"+") {
                v += self.mul()?;
            } else if self.eat(b"-") {
                v -= self.mul()?;
            } else {
                return Ok(v);
            }
        }
    }

    fn mul(&mut self) -> Result<f64, String> {
        let mut v = self.unary()?;
        loop {
            if self.eat(b"*") {
                v *= self.unary()?;
            } else if self.eat(b"/") {
                let r = self.unary()?;
                if r == 0.0 {
                    return Err("division by zero".into());
                }
                v /= r;
            } else if self.eat(b"MOD") {
                let r = self.unary()?;
                if r == 0.0 {
                    return Err("MOD by zero".into());
                }
                v %= r;
            } else {
                return Ok(v);
            }
        }
    }

    fn unary(&mut self) -> Result<f64, String> {
        self.deeper()?;
        let v = if self.eat(b"-") {
            -self.unary()?
        } else if self.eat(b"+") {
            self.unary()?
        } else {
            self.primary()?
        };
        self.depth -= 1;
        Ok(v)
    }

    fn bracketed(&mut self) -> Result<f64, String> {
        if !self.eat(b"[") {
            return Err(format!("`[` expected at `{}`", self.rest()));
        }
        let v = self.or()?;
        if !self.eat(b"]") {
            return Err(format!("`]` expected at `{}`", self.rest()));
        }
        Ok(v)
    }

    /// The number after `#`: digits, or a bracketed expression.
    fn index(&mut self) -> Result<u32, String> {
        self.ws();
        let v = if self.s.get(self.i) == Some(&b'[') {
            self.bracketed()?
        } else {
            self.number()?
        };
        if v < 0.0 || v.fract() != 0.0 || v > 1e6 {
            return Err(format!("`#` of {v} is no variable"));
        }
        Ok(v as u32)
    }

    fn number(&mut self) -> Result<f64, String> {
        self.ws();
        let start = self.i;
        while self
            .s
            .get(self.i)
            .is_some_and(|c| c.is_ascii_digit() || *c == b'.')
        {
            self.i += 1;
        }
        std::str::from_utf8(&self.s[start..self.i])
            .ok()
            .and_then(|t| t.parse::<f64>().ok())
            .ok_or_else(|| format!("number expected at `{}`", self.rest()))
    }

    fn primary(&mut self) -> Result<f64, String> {
        self.ws();
        match self.s.get(self.i) {
            Some(b'[') => self.bracketed(),
            Some(b'#') => {
                self.i += 1;
                let n = self.index()?;
                (self.vars)(n)
            }
            Some(c) if c.is_ascii_digit() || *c == b'.' => self.number(),
            Some(c) if c.is_ascii_alphabetic() => self.function(),
            _ => Err(format!("value expected at `{}`", self.rest())),
        }
    }

    fn function(&mut self) -> Result<f64, String> {
        type Fun = fn(f64) -> f64;
        let funs: [(&[u8], Fun); 12] = [
            (b"SIN", |x| x.to_radians().sin()),
            (b"COS", |x| x.to_radians().cos()),
            (b"TAN", |x| x.to_radians().tan()),
            (b"ASIN", |x| x.asin().to_degrees()),
            (b"ACOS", |x| x.acos().to_degrees()),
            (b"SQRT", f64::sqrt),
            (b"ABS", f64::abs),
            (b"ROUND", f64::round),
            (b"FIX", f64::trunc),
            (b"FUP", |x| if x < 0.0 { x.floor() } else { x.ceil() }),
            (b"LN", f64::ln),
            (b"EXP", f64::exp),
        ];
        if self.eat(b"ATAN") {
            let a = self.bracketed()?;
            // `ATAN[y]/[x]`: the angle of the point (x, y), 0 to 360°.
            let save = self.i;
            if self.eat(b"/") {
                self.ws();
                if self.s.get(self.i) == Some(&b'[') {
                    let b = self.bracketed()?;
                    return Ok(a.atan2(b).to_degrees().rem_euclid(360.0));
                }
                self.i = save;
            }
            return Ok(a.atan().to_degrees());
        }
        for (name, f) in funs {
            if self.eat(name) {
                let v = f(self.bracketed()?);
                if !v.is_finite() {
                    return Err(format!(
                        "{} outside its domain",
                        String::from_utf8_lossy(name)
                    ));
                }
                return Ok(v);
            }
        }
        Err(format!("unknown function or word `{}`", self.rest()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn none(n: u32) -> Result<f64, String> {
        match n {
            1 => Ok(3.0),
            100 => Ok(25.0),
            _ => Err(format!("#{n} is not set")),
        }
    }

    fn ev(s: &str) -> Result<f64, String> {
        eval(s.as_bytes(), &none)
    }

    #[test]
    fn arithmetic_functions_and_logic() {
        assert_eq!(ev("[1 + 2] * 3"), Ok(9.0));
        assert_eq!(ev("1 + 2 * 3"), Ok(7.0));
        assert_eq!(ev("-#1 + #100"), Ok(22.0));
        assert_eq!(ev("#[#1 - 2]"), Ok(3.0));
        assert_eq!(ev("7 MOD 4"), Ok(3.0));
        assert!((ev("SIN[30]").unwrap() - 0.5).abs() < 1e-12);
        assert!((ev("ATAN[1]/[-1]").unwrap() - 135.0).abs() < 1e-12);
        assert_eq!(ev("FIX[-2.7]"), Ok(-2.0));
        assert_eq!(ev("FUP[2.1]"), Ok(3.0));
        assert_eq!(ev("ROUND[2.5]"), Ok(3.0));
        assert_eq!(ev("SQRT[16] + ABS[-1]"), Ok(5.0));
        assert_eq!(ev("[#1 LT 5] AND [#100 EQ 25]"), Ok(1.0));
        assert_eq!(ev("[#1 GT 5] or [1 NE 1]"), Ok(0.0));
    }

    #[test]
    fn unknown_values_and_bad_text_are_refused() {
        assert_eq!(ev("#5021 + 1"), Err("#5021 is not set".into()));
        assert!(ev("1 / 0").unwrap_err().contains("division"));
        assert!(ev("SQRT[-1]").unwrap_err().contains("domain"));
        assert!(ev("[1 + 2").unwrap_err().contains("`]`"));
        assert!(ev("FOO[1]").unwrap_err().contains("unknown"));
        assert!(ev(&"[".repeat(200)).unwrap_err().contains("deeply"));
        assert_eq!(bracket_len(b"[1 + [2]] X"), Some(9));
        assert_eq!(bracket_len(b"[1"), None);
    }
}
