//! The `! POSTPROC MILLING …` directives of a RAPID module, in line order
//! (each read by [`crate::program::directive`]): the depth, width and
//! spindle speed in force at every line.

use super::comment_start;
use crate::error::{Error, Located, Result};
use crate::process::CutSettings;
use crate::program::directive;

/// `! POSTPROC MILLING KEY=VALUE …` directive comments of a RAPID module, in
/// line order: each sets the axial depth (`DEPTH`, mm), radial width
/// (`WIDTH`, mm) and spindle speed (`RPM`, 1/min) that the process-force
/// models use from its line on, over the machine file's values.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Directives {
    /// Settings in force from each directive's line on (cumulative).
    at: Vec<(usize, CutSettings)>,
}

impl Directives {
    /// Finds the directives of a module's text. Errors (`file:line:col`)
    /// for an unknown key, a bad value or a directive without keys.
    pub fn parse(src: &str, file: &str) -> Result<Directives> {
        Self::parse_lines(src, file, 1, CutSettings::default())
    }

    /// [`Directives::parse`] of a piece of a module whose first line is
    /// line `first_line` of the file, with the settings `start` in force
    /// before it (those of the pieces before, for a module read a window at
    /// a time). The settings in force at its end are [`Directives::last`].
    pub fn parse_lines(
        src: &str,
        file: &str,
        first_line: usize,
        start: CutSettings,
    ) -> Result<Directives> {
        let mut at = Vec::new();
        if start != CutSettings::default() {
            at.push((0, start));
        }
        let mut cur = start;
        for (k, line) in bang_lines(src, first_line.saturating_sub(1)) {
            let Some(bang) = comment_start(line) else {
                continue;
            };
            let body = line.get(bang + 1..).unwrap_or("");
            match directive::read(body, true, 1.0, cur) {
                Ok(None) => {}
                Ok(Some(set)) => {
                    cur = set;
                    at.push((k + 1, cur));
                }
                Err(r) => {
                    // Columns are 1-based: the `!` is at `bang + 1`.
                    let col = r.word_at.map_or(bang + 1, |off| bang + 2 + off);
                    return Err(Error::Input(Located::new(file, k + 1, col, r.message)));
                }
            }
        }
        Ok(Directives { at })
    }

    /// The settings in force on 1-based `line` (a directive on the same
    /// line counts).
    pub fn at(&self, line: usize) -> CutSettings {
        let n = self.at.partition_point(|(l, _)| *l <= line);
        n.checked_sub(1)
            .and_then(|i| self.at.get(i))
            .map_or_else(CutSettings::default, |(_, s)| *s)
    }

    /// The settings in force after the last directive (the defaults
    /// without one).
    pub fn last(&self) -> CutSettings {
        self.at
            .last()
            .map_or_else(CutSettings::default, |(_, s)| *s)
    }

    /// True without directives.
    pub fn is_empty(&self) -> bool {
        self.at.is_empty()
    }
}

/// The lines of `src` (as [`str::lines`] gives them) that hold a `!`, with
/// their 0-based numbers counted from `first`: a directive is in a comment,
/// and the lines without one are passed over by a byte search.
fn bang_lines(src: &str, first: usize) -> impl Iterator<Item = (usize, &str)> {
    let bytes = src.as_bytes();
    // Where the search goes on, and the number and start of the line there.
    let (mut from, mut k, mut counted) = (0, first, 0);
    std::iter::from_fn(move || {
        let bang = from + memchr::memchr(b'!', bytes.get(from..)?)?;
        let start = memchr::memrchr(b'\n', bytes.get(..bang)?).map_or(0, |n| n + 1);
        k += memchr::memchr_iter(b'\n', bytes.get(counted..start)?).count();
        counted = start;
        let line = match memchr::memchr(b'\n', bytes.get(bang..)?) {
            Some(n) => {
                from = bang + n + 1;
                let line = src.get(start..bang + n)?;
                line.strip_suffix('\r').unwrap_or(line)
            }
            None => {
                from = bytes.len();
                src.get(start..)?
            }
        };
        Some((k, line))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lines found by the byte search are those of `str::lines` that
    /// hold a `!`, with the same numbers and text: line breaks of both
    /// kinds, a last line with and without a break, a lone `\r`, several
    /// `!` on a line, blank lines and a `!` on the first and last byte.
    #[test]
    fn bang_lines_are_the_lines_holding_a_bang() {
        let texts = [
            "",
            "!",
            "a\nb\n",
            "! first\nMoveL p, v, z, t;\n\n  ! POSTPROC MILLING DEPTH=1\nx ! y ! z\n!",
            "a\r\n! b\r\n\r\nc \"!\" d\r\n! e\r",
            "\n\n!\n\n! x\r\n!\n",
            "x\r! y\nz",
        ];
        for src in texts {
            for first in [0, 41] {
                let want: Vec<(usize, &str)> = (first..)
                    .zip(src.lines())
                    .filter(|(_, l)| l.contains('!'))
                    .collect();
                let got: Vec<(usize, &str)> = bang_lines(src, first).collect();
                assert_eq!(got, want, "{src:?} from {first}");
            }
        }
    }
}
