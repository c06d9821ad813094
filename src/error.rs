//! Typed errors of the library. `main` prints one error chain and maps the
//! variant to the process exit code (2 = bad input or usage, 1 = findings).

use std::fmt;
use std::path::PathBuf;

/// A problem located in an input text: `file:line:column: message`.
///
/// Lines and columns are 1-based; the column counts bytes of the line.
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
}

impl fmt::Display for Located {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
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

/// Every error the library reports.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Malformed or unsupported input at a known place.
    #[error(transparent)]
    Input(#[from] Located),
    /// Bad command-line usage or an inconsistent request.
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
}

impl Error {
    /// The process exit code this error maps to: 2 for every error (bad
    /// input, usage, unreadable files, unachievable targets).
    pub fn exit_code(&self) -> i32 {
        2
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
}
