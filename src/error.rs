//! Typed errors of the library, by kind: input text, machine file,
//! measured data, command-line usage, unachievable targets, I/O, and
//! internal invariants (bugs). `main` prints one error chain and
//! [`Error::exit_code`] maps the kind to the process exit code in one match
//! (2 for every kind but [`ErrorKind::Internal`], which gets 3; 1 is for
//! findings, not errors).

use std::fmt;
use std::path::PathBuf;

/// A problem located in an input text: `file:line:column: message`.
///
/// Lines and columns are 1-based; the column counts bytes of the line.
/// A problem of the file as a whole ([`Located::whole_file`]) has line and
/// column 0 and shows as `file: message`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Located {
    /// File name as the user gave it (`-` for standard input).
    pub file: String,
    /// 1-based line number.
    pub line: usize,
    /// 1-based byte column.
    pub column: usize,
    /// What is wrong, including the offending text where there is one.
    pub message: String,
}

impl Located {
    /// Builds a located message.
    pub fn new(
        file: impl Into<String>,
        line: usize,
        column: usize,
        message: impl Into<String>,
    ) -> Self {
        Located {
            file: file.into(),
            line,
            column,
            message: message.into(),
        }
    }

    /// A problem of the file as a whole, at no particular line:
    /// `file: message`.
    pub fn whole_file(file: impl Into<String>, message: impl Into<String>) -> Self {
        Located::new(file, 0, 0, message)
    }
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 && self.column == 0 {
            return write!(f, "{}: {}", Escaped(&self.file), Escaped(&self.message));
        }
        write!(
            f,
            "{}:{}:{}: {}",
            Escaped(&self.file),
            self.line,
            self.column,
            Escaped(&self.message)
        )
    }
}

/// Text for a message with its control characters (C0, DEL, C1; tab and
/// line breaks included) written as `\u{..}` escapes, so that no input can
/// move the cursor, clear the terminal or forge lines of output.
pub struct Escaped<'a>(pub &'a str);

impl fmt::Display for Escaped<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut rest = self.0;
        while let Some(pos) = rest.find(char::is_control) {
            f.write_str(&rest[..pos])?;
            let c = rest[pos..].chars().next().unwrap_or(' ');
            write!(f, "\\u{{{:x}}}", c as u32)?;
            rest = &rest[pos + c.len_utf8()..];
        }
        f.write_str(rest)
    }
}

impl std::error::Error for Located {}

/// A validation failure found while turning a raw (deserialized) model into a
/// validated one. `path` is the YAML key path such as `axes[1].travel_mm`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Invalid {
    /// Key path of the offending value, dotted with `[i]` indices.
    pub path: String,
    /// What is wrong with it.
    pub message: String,
}

impl Invalid {
    /// Builds a validation failure for a key path.
    pub fn new(path: impl Into<String>, message: impl Into<String>) -> Self {
        Invalid {
            path: path.into(),
            message: message.into(),
        }
    }
}

impl fmt::Display for Invalid {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path, self.message)
    }
}

impl std::error::Error for Invalid {}

/// Every error the library reports. The variant is its kind
/// ([`Error::kind`]); the message is the same whatever the kind.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Malformed or unsupported input text (a program, an observation
    /// file, a force table) at a known place.
    #[error(transparent)]
    Input(#[from] Located),
    /// A machine file that does not give a valid model: YAML syntax,
    /// unknown, missing or duplicate keys, values out of range or
    /// inconsistent. The message names the key path where there is one.
    #[error(transparent)]
    Machine(Located),
    /// Measured data that cannot answer the question asked: too few rows,
    /// an ill-conditioned or rank-deficient fit, parameters the data does
    /// not identify.
    #[error("{}", Escaped(.0))]
    Data(String),
    /// Bad command-line usage or an inconsistent request (flags that do
    /// not apply, conflicting or missing options, a file of the wrong
    /// kind for the command).
    #[error("{}", Escaped(.0))]
    Usage(String),
    /// A file could not be read or written. The message includes the
    /// cause, so it is not repeated as an error source.
    #[error("{}: {}", Escaped(&path.display().to_string()), cause)]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying I/O error.
        cause: std::io::Error,
    },
    /// The engine could not do what the input asks (a target out of travel,
    /// a solve that did not converge). It names the block or target.
    #[error("{0}")]
    Unachievable(Located),
    /// An invariant of the engine does not hold: a bug in postproc, not a
    /// problem of the input.
    #[error("{}", Escaped(.0))]
    Internal(String),
}

/// The kind of an [`Error`], for matching and for the exit code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ErrorKind {
    /// [`Error::Input`].
    Input,
    /// [`Error::Machine`].
    Machine,
    /// [`Error::Data`].
    Data,
    /// [`Error::Usage`].
    Usage,
    /// [`Error::Io`].
    Io,
    /// [`Error::Unachievable`].
    Unachievable,
    /// [`Error::Internal`].
    Internal,
}

/// Exit code of every error but an internal one: bad input, machine file,
/// data or usage, an unreadable file, an unachievable target.
pub const EXIT_ERROR: i32 = 2;
/// Exit code of an internal error (a bug).
pub const EXIT_INTERNAL: i32 = 3;

impl Error {
    /// The kind of this error.
    pub fn kind(&self) -> ErrorKind {
        match self {
            Error::Input(_) => ErrorKind::Input,
            Error::Machine(_) => ErrorKind::Machine,
            Error::Data(_) => ErrorKind::Data,
            Error::Usage(_) => ErrorKind::Usage,
            Error::Io { .. } => ErrorKind::Io,
            Error::Unachievable(_) => ErrorKind::Unachievable,
            Error::Internal(_) => ErrorKind::Internal,
        }
    }

    /// The process exit code of this error, by kind: [`EXIT_INTERNAL`] for
    /// a bug, [`EXIT_ERROR`] for everything else (nothing is written
    /// either way).
    pub fn exit_code(&self) -> i32 {
        match self.kind() {
            ErrorKind::Input
            | ErrorKind::Machine
            | ErrorKind::Data
            | ErrorKind::Usage
            | ErrorKind::Io
            | ErrorKind::Unachievable => EXIT_ERROR,
            ErrorKind::Internal => EXIT_INTERNAL,
        }
    }

    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            cause: source,
        }
    }
}

/// `bytes` as text, or the line and column of the first byte that is not
/// valid UTF-8 in `file`.
pub fn utf8_text<'a>(bytes: &'a [u8], file: &str) -> std::result::Result<&'a str, Located> {
    std::str::from_utf8(bytes).map_err(|e| {
        let good = bytes.get(..e.valid_up_to()).unwrap_or_default();
        let line = 1 + good.iter().filter(|&&b| b == b'\n').count();
        let line_start = good.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
        let column = good.len() - line_start + 1;
        let byte = bytes.get(e.valid_up_to()).copied().unwrap_or(0);
        Located::new(
            file,
            line,
            column,
            format!("invalid UTF-8: byte 0x{byte:02X} is not valid text"),
        )
    })
}

/// A number for an error message: plain when of ordinary size, in exponent
/// notation when huge or tiny, so an absurd input cannot flood the message.
pub fn show_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e9).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Longest quoted cell or number in a message, characters.
pub const QUOTE_MAX: usize = 24;

/// A piece of input text for a message, shortened with `…` beyond
/// [`QUOTE_MAX`] characters.
pub fn clip(text: &str) -> String {
    clip_to(text, QUOTE_MAX)
}

/// A piece of input text for a message, shortened with `…` beyond `max`
/// characters.
pub fn clip_to(text: &str, max: usize) -> String {
    if text.chars().count() <= max {
        text.to_string()
    } else {
        format!("{}…", text.chars().take(max).collect::<String>())
    }
}

/// Result type of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_are_escaped_in_messages() {
        let e = Located::new("a\x1b[2Jb.mod", 3, 4, "unknown `\x1b]0;x\x07\r\n\u{85}é\t`");
        let shown = e.to_string();
        assert_eq!(
            shown,
            "a\\u{1b}[2Jb.mod:3:4: unknown `\\u{1b}]0;x\\u{7}\\u{d}\\u{a}\\u{85}é\\u{9}`"
        );
        let u = Error::Usage("bad \x1b[31m".into()).to_string();
        assert_eq!(u, "bad \\u{1b}[31m");
    }

    #[test]
    fn a_problem_of_the_whole_file_shows_without_line_and_column() {
        let e = Located::whole_file("m\x1b.yaml", "cannot edit \x07");
        assert_eq!(e.to_string(), "m\\u{1b}.yaml: cannot edit \\u{7}");
        let m = Error::Machine(e);
        assert_eq!(m.kind(), ErrorKind::Machine);
        assert_eq!(m.to_string(), "m\\u{1b}.yaml: cannot edit \\u{7}");
    }
}
