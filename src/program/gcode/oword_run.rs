//! LinuxCNC O-word conditions and loops run offline, within the resolution
//! pass of [`super::subprograms`]: `o1 while [cond]` … `o1 endwhile`,
//! `o1 do` … `o1 while [cond]`, `o1 if [cond]` … `o1 elseif [cond]` …
//! `o1 else` … `o1 endif`, `o1 break` and `o1 continue`, their conditions
//! evaluated with the program's variables as the Fanuc macros are
//! ([`super::macros_run`]). A condition only the control can evaluate (a
//! system variable, a probe result, a variable read before it is set) is
//! refused naming the variable and the line; the lines of one construct
//! share its O-word number or name, as LinuxCNC requires.

use super::oword::{Keyword, OWord};
use super::subprograms::{Kind, Resolver};
use crate::error::Located;

impl Resolver<'_> {
    /// Runs the O-word condition or loop line `i` (keyword `o.keyword`,
    /// key `key`) of a range ending at `to`: the next line to run.
    pub(super) fn oword_flow(
        &mut self,
        i: usize,
        o: OWord,
        key: &str,
        to: usize,
    ) -> Result<usize, Located> {
        self.exp.flat = true;
        self.tick(i)?;
        let line = self.exp.line(self.text, i).to_vec();
        let cond = |r: &Self| -> Result<bool, Located> {
            let args = o.args_text(&line);
            if args.is_empty() {
                return Err(r.err(i, format!("o{key} {}: no condition", o.keyword.as_str())));
            }
            r.truth(i, args)
        };
        match o.keyword {
            Keyword::While => match self.loop_do(i, key) {
                // `o1 do` … `o1 while [cond]`: back to the line after `do`.
                Some(d) => Ok(if cond(self)? { d + 1 } else { i + 1 }),
                None => {
                    // The loop must close whether or not its body runs.
                    let end = self.same_key(i, key, to, &[Keyword::Endwhile], "endwhile")?;
                    Ok(if cond(self)? { i + 1 } else { end + 1 })
                }
            },
            Keyword::Endwhile => self.loop_while(i, key),
            Keyword::Do | Keyword::Endif => Ok(i + 1),
            Keyword::If => {
                // The condition must close whichever branch runs.
                self.same_key(i, key, to, &[Keyword::Endif], "endif")?;
                if cond(self)? {
                    return Ok(i + 1);
                }
                self.next_branch(i, key, to)
            }
            // Reached from a branch that ran: on after `endif`.
            Keyword::Elseif | Keyword::Else => {
                Ok(self.same_key(i, key, to, &[Keyword::Endif], "endif")? + 1)
            }
            Keyword::Break => match self.do_end(i, key, to) {
                Some(w) => Ok(w + 1),
                None => Ok(self.same_key(i, key, to, &[Keyword::Endwhile], "endwhile")? + 1),
            },
            Keyword::Continue => match self.do_end(i, key, to) {
                Some(w) => Ok(w),
                None => self.loop_while(i, key),
            },
            k => Err(self.err(
                i,
                format!("o{key} {} is not a condition or loop", k.as_str()),
            )),
        }
    }

    /// The branch after the false condition of the `if` or `elseif` at
    /// line `i`: the line after the first `elseif` whose condition holds,
    /// after `else`, or after `endif`.
    fn next_branch(&mut self, mut i: usize, key: &str, to: usize) -> Result<usize, Located> {
        loop {
            let j = self.same_key(
                i,
                key,
                to,
                &[Keyword::Elseif, Keyword::Else, Keyword::Endif],
                "endif",
            )?;
            let Kind::OWord(b) = self.kinds[j] else {
                return Ok(j + 1);
            };
            if b.keyword != Keyword::Elseif {
                return Ok(j + 1);
            }
            let line = self.exp.line(self.text, j).to_vec();
            if self.truth(j, b.args_text(&line))? {
                return Ok(j + 1);
            }
            i = j;
        }
    }

    /// The first line after `i` and before `to` with key `key` and one of
    /// `keywords`, or the error naming the missing `end`.
    fn same_key(
        &self,
        i: usize,
        key: &str,
        to: usize,
        keywords: &[Keyword],
        end: &str,
    ) -> Result<usize, Located> {
        let head = match self.kinds[i] {
            Kind::OWord(o) => o.keyword.as_str(),
            _ => "",
        };
        (i + 1..to)
            .find(|&j| self.is_key(j, key, keywords))
            .ok_or_else(|| self.err(i, format!("o{key} {head} has no `o{key} {end}`")))
    }

    /// Whether line `j` is an O-word line of key `key` and one of
    /// `keywords`.
    fn is_key(&self, j: usize, key: &str, keywords: &[Keyword]) -> bool {
        match self.kinds[j] {
            Kind::OWord(o) => {
                keywords.contains(&o.keyword) && o.key(self.exp.line(self.text, j)) == key
            }
            _ => false,
        }
    }

    /// The `do` that the `while` at line `i` ends, if it ends one: the
    /// nearest line of its key before it is a `do` (or a `break` or
    /// `continue` inside it).
    fn loop_do(&self, i: usize, key: &str) -> Option<usize> {
        let from = self.macros.ranges.last().map_or(0, |r| r.0);
        let loops = [Keyword::Do, Keyword::While, Keyword::Endwhile];
        let j = (from..i).rev().find(|&j| self.is_key(j, key, &loops))?;
        self.is_key(j, key, &[Keyword::Do]).then_some(j)
    }

    /// The `while` that ends the `do` loop of key `key` that line `i` is
    /// in (the first `while` of the key after it that ends a `do`).
    fn do_end(&self, i: usize, key: &str, to: usize) -> Option<usize> {
        let w = (i + 1..to).find(|&j| self.is_key(j, key, &[Keyword::While, Keyword::Endwhile]))?;
        self.loop_do(w, key).map(|_| w)
    }

    /// The `while` before line `i` (an `endwhile` or `continue`) that opens
    /// its loop: run again from there.
    fn loop_while(&self, i: usize, key: &str) -> Result<usize, Located> {
        let from = self.macros.ranges.last().map_or(0, |r| r.0);
        (from..i)
            .rev()
            .find(|&j| self.is_key(j, key, &[Keyword::While]) && self.loop_do(j, key).is_none())
            .ok_or_else(|| {
                let head = match self.kinds[i] {
                    Kind::OWord(o) => o.keyword.as_str(),
                    _ => "",
                };
                self.err(i, format!("o{key} {head} without its `o{key} while`"))
            })
    }
}
