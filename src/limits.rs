//! Resource limits on inputs, in one place (documented in docs/limits.md).
//!
//! Every reader refuses an input beyond these limits with a located error
//! instead of letting memory or time grow without bound.

use std::io::Read;
use std::path::Path;

use crate::error::{Error, Located};

/// Convergence of the inverse solve on the tool-tip position, mm.
pub const SOLVE_TOL_MM: f64 = 1e-7;

/// Smallest accepted tolerance of the attained path, mm: ten times the
/// solver's convergence ([`SOLVE_TOL_MM`]), which bounds the gap at the
/// solved ends of every piece; below it no piece could be proven within
/// the tolerance.
pub const MIN_TOLERANCE_MM: f64 = 10.0 * SOLVE_TOL_MM;

/// Largest accepted tolerance of the attained path, mm.
pub const MAX_TOLERANCE_MM: f64 = 1.0;

/// A tolerance of the attained path (`compensation.tolerance_mm`,
/// `--tolerance`): within [[`MIN_TOLERANCE_MM`], [`MAX_TOLERANCE_MM`]]; the
/// message otherwise, without the key or flag name.
pub fn tolerance_mm(v: f64) -> Result<f64, String> {
    if v.is_finite() && (MIN_TOLERANCE_MM..=MAX_TOLERANCE_MM).contains(&v) {
        Ok(v)
    } else {
        Err(format!(
            "{}: must be within [{MIN_TOLERANCE_MM}, {MAX_TOLERANCE_MM}] mm (the solver converges to {SOLVE_TOL_MM} mm)",
            crate::error::show_number(v)
        ))
    }
}

/// Longest input line, bytes (end of line excluded): G-code, RAPID and
/// observation CSV alike. Memory held for a line is bounded by it.
pub const LINE_MAX_BYTES: usize = 1 << 20;

/// Largest machine file, bytes.
pub const YAML_MAX_BYTES: u64 = 16 << 20;

/// Deepest nesting of a machine file (block levels and flow brackets).
pub const YAML_MAX_DEPTH: usize = 32;

/// Most decimals of a rewritten coordinate word: a program's own decimals
/// are kept up to this many (as many as a machine file's
/// `output.decimals_mm` may ask for).
pub const EMIT_MAX_DECIMALS: usize = 9;

/// Most data rows in an observation (or poses) file. Identification holds
/// every row and a sensitivity matrix of a few kilobytes per row in memory.
pub const OBSERVATION_MAX_ROWS: usize = 100_000;

/// Most worker threads per core that `--threads` accepts.
pub const THREADS_PER_CORE: usize = 4;

/// The largest `--threads`: [`THREADS_PER_CORE`] per core of this machine.
pub fn max_threads() -> usize {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    cores.saturating_mul(THREADS_PER_CORE)
}

/// Parses `--threads N`: at least 1, at most [`max_threads`].
pub fn parse_threads(s: &str) -> Result<usize, String> {
    let n: usize = s.trim().parse().map_err(|_| {
        format!(
            "`{}`: expected a whole number of threads",
            crate::error::clip(s)
        )
    })?;
    let max = max_threads();
    if n == 0 {
        return Err("must be at least 1".into());
    }
    if n > max {
        return Err(format!(
            "{n} is more than {max} ({THREADS_PER_CORE} per core of this machine)"
        ));
    }
    Ok(n)
}

/// Follows the length of the current line over chunks of input, so that a
/// line beyond [`LINE_MAX_BYTES`] is refused as soon as it is seen.
#[derive(Debug, Clone, Copy, Default)]
pub struct LineLength {
    /// Completed lines so far.
    lines: usize,
    /// Bytes of the current (unfinished) line so far.
    current: usize,
}

impl LineLength {
    /// A tracker at the start of a file.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes the next `chunk` of the input; an error naming the line when
    /// the current line grows beyond [`LINE_MAX_BYTES`].
    pub fn feed(&mut self, chunk: &[u8], file: &str) -> Result<(), Located> {
        let mut rest = chunk;
        while let Some(nl) = memchr::memchr(b'\n', rest) {
            self.check(self.current + nl, file)?;
            self.lines += 1;
            self.current = 0;
            rest = &rest[nl + 1..];
        }
        self.current += rest.len();
        self.check(self.current, file)
    }

    fn check(&self, len: usize, file: &str) -> Result<(), Located> {
        if len > LINE_MAX_BYTES {
            return Err(line_too_long(file, self.lines + 1));
        }
        Ok(())
    }
}

/// The error of a line longer than [`LINE_MAX_BYTES`].
pub fn line_too_long(file: &str, line: usize) -> Located {
    Located::new(
        file,
        line,
        LINE_MAX_BYTES + 1,
        format!("line longer than {LINE_MAX_BYTES} bytes"),
    )
}

/// A reader that fails (with an [`std::io::ErrorKind::InvalidData`] error
/// holding the located message) when a line grows beyond
/// [`LINE_MAX_BYTES`]; see [`io_error`].
pub struct LineLimited<R> {
    inner: R,
    lines: LineLength,
    file: String,
}

impl<R> LineLimited<R> {
    /// Wraps `inner`; `file` names it in errors.
    pub fn new(inner: R, file: impl Into<String>) -> Self {
        LineLimited {
            inner,
            lines: LineLength::new(),
            file: file.into(),
        }
    }
}

impl<R: Read> Read for LineLimited<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.lines
            .feed(&buf[..n], &self.file)
            .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))?;
        Ok(n)
    }
}

/// An I/O error of `file` as a library error: the located message when it
/// comes from [`LineLimited`], else [`Error::Io`].
pub fn io_error(file: impl Into<std::path::PathBuf>, e: std::io::Error) -> Error {
    if let Some(located) = e.get_ref().and_then(|r| r.downcast_ref::<Located>()) {
        return Error::Input(located.clone());
    }
    Error::io(file, e)
}

/// Reads a whole input of at most `max` bytes whose lines are at most
/// [`LINE_MAX_BYTES`] long; `file` names it in errors.
pub fn read_bounded<R: Read>(mut input: R, max: u64, file: &str) -> Result<Vec<u8>, Error> {
    let mut out = Vec::new();
    let mut lines = LineLength::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = match input.read(&mut buf) {
            Ok(0) => return Ok(out),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(Error::io(file, e)),
        };
        lines.feed(&buf[..n], file)?;
        if (out.len() + n) as u64 > max {
            return Err(Error::Input(Located::new(
                file,
                lines.lines + 1,
                1,
                format!("file larger than {max} bytes"),
            )));
        }
        out.extend_from_slice(&buf[..n]);
    }
}

/// Reads a whole file with [`read_bounded`].
pub fn read_file_bounded(path: &Path, max: u64) -> Result<Vec<u8>, Error> {
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    read_bounded(f, max, &path.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_line_is_refused_at_its_line_over_chunks() {
        let mut t = LineLength::new();
        t.feed(b"G1 X1\nG1 X2\n", "p.nc").unwrap();
        let chunk = vec![b'X'; LINE_MAX_BYTES / 2 + 1];
        t.feed(&chunk, "p.nc").unwrap();
        let err = t.feed(&chunk, "p.nc").unwrap_err();
        assert_eq!(err.line, 3);
        assert!(err.message.contains(&LINE_MAX_BYTES.to_string()));
    }

    #[test]
    fn a_line_at_the_limit_is_accepted() {
        let mut t = LineLength::new();
        let mut line = vec![b'X'; LINE_MAX_BYTES];
        line.push(b'\n');
        t.feed(&line, "p.nc").unwrap();
        t.feed(&line, "p.nc").unwrap();
    }

    #[test]
    fn an_endless_input_is_refused_in_bounded_memory() {
        let err = read_bounded(std::io::repeat(0), u64::MAX, "/dev/zero").unwrap_err();
        assert!(err.to_string().starts_with("/dev/zero:1:"), "{err}");
        let err = read_bounded(std::io::repeat(b'\n'), 1000, "z").unwrap_err();
        assert!(err.to_string().contains("larger than 1000 bytes"), "{err}");
    }
}
