//! The character set of a program file: UTF-8, or ISO-8859-1 (Latin-1),
//! the character set of ABB robot controllers, for text that is not valid
//! UTF-8 (a comment `! Größe` or a string with `é` saved by a controller).
//!
//! Latin-1 maps every byte to the character of the same number (U+0000 to
//! U+00FF), so any bytes decode, and text decoded from Latin-1 encodes back
//! to the same bytes: a module is read as text and written back byte for
//! byte whichever its character set. The writer ([`Latin1Writer`]) takes
//! the UTF-8 text the program writers make and writes Latin-1.

use std::borrow::Cow;
use std::io::Write;

/// The character set of a program's text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Charset {
    /// UTF-8 (ASCII included).
    #[default]
    Utf8,
    /// ISO-8859-1: one byte per character.
    Latin1,
}

/// The text of `bytes`: UTF-8 when they are valid UTF-8, else Latin-1
/// (every byte one character), and which of the two it was.
pub fn decode(bytes: Vec<u8>) -> (String, Charset) {
    match String::from_utf8(bytes) {
        Ok(text) => (text, Charset::Utf8),
        Err(e) => (
            e.as_bytes().iter().map(|&b| char::from(b)).collect(),
            Charset::Latin1,
        ),
    }
}

/// The bytes of `text` in `charset`. In Latin-1 a character beyond U+00FF
/// (none in text decoded from Latin-1) is written `?`.
pub fn encode(text: &str, charset: Charset) -> Cow<'_, [u8]> {
    match charset {
        Charset::Utf8 => Cow::Borrowed(text.as_bytes()),
        Charset::Latin1 if text.is_ascii() => Cow::Borrowed(text.as_bytes()),
        Charset::Latin1 => Cow::Owned(text.chars().map(latin1_byte).collect()),
    }
}

/// The Latin-1 byte of `c`, `?` when it has none.
fn latin1_byte(c: char) -> u8 {
    u8::try_from(u32::from(c)).unwrap_or(b'?')
}

/// A writer that takes UTF-8 text and writes it to `inner` in Latin-1
/// ([`encode`]); a character cut between two writes is joined again.
/// Bytes that are not UTF-8 are written `?`.
pub struct Latin1Writer<'w> {
    inner: &'w mut dyn Write,
    /// The start of a character cut at the end of the last write.
    pending: Vec<u8>,
}

impl<'w> Latin1Writer<'w> {
    /// Writes into `inner`.
    pub fn new(inner: &'w mut dyn Write) -> Self {
        Latin1Writer {
            inner,
            pending: Vec::new(),
        }
    }

    fn put(&mut self, buf: &[u8]) -> std::io::Result<()> {
        let mut out = Vec::with_capacity(buf.len());
        let mut rest = buf;
        loop {
            match std::str::from_utf8(rest) {
                Ok(t) => {
                    out.extend(t.chars().map(latin1_byte));
                    break;
                }
                Err(e) => {
                    let (good, bad) = rest.split_at(e.valid_up_to());
                    let good = std::str::from_utf8(good).unwrap_or_default();
                    out.extend(good.chars().map(latin1_byte));
                    match e.error_len() {
                        // A character cut at the end: kept for the next write.
                        None => {
                            self.pending.extend_from_slice(bad);
                            break;
                        }
                        Some(n) => {
                            out.push(b'?');
                            rest = bad.get(n..).unwrap_or_default();
                        }
                    }
                }
            }
        }
        self.inner.write_all(&out)
    }
}

impl Write for Latin1Writer<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.write_all(buf)?;
        Ok(buf.len())
    }

    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        if self.pending.is_empty() {
            return self.put(buf);
        }
        let mut joined = std::mem::take(&mut self.pending);
        joined.extend_from_slice(buf);
        self.put(&joined)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        if !self.pending.is_empty() {
            self.pending.clear();
            self.inner.write_all(b"?")?;
        }
        self.inner.flush()
    }
}

/// `e` with its column counted in bytes of the file: the text of a
/// Latin-1 file has two bytes for each character beyond ASCII, its file
/// one. Any other error, a UTF-8 text and a position at no particular
/// column are kept as they are.
pub fn file_columns(e: crate::error::Error, text: &str, charset: Charset) -> crate::error::Error {
    match e {
        crate::error::Error::Input(loc) if charset == Charset::Latin1 => {
            crate::error::Error::Input(file_column(loc, text))
        }
        other => other,
    }
}

/// [`file_columns`] of one located problem in a Latin-1 text.
fn file_column(mut loc: crate::error::Located, text: &str) -> crate::error::Located {
    if loc.line == 0 || loc.column == 0 {
        return loc;
    }
    let Some(line) = text.split('\n').nth(loc.line - 1) else {
        return loc;
    };
    let mut end = (loc.column - 1).min(line.len());
    while !line.is_char_boundary(end) {
        end -= 1;
    }
    let chars = line.get(..end).map_or(0, |t| t.chars().count());
    loc.column = chars + 1 + (loc.column - 1 - end);
    loc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every byte string decodes, and text decoded from Latin-1 encodes
    /// back to its bytes, through `encode` and through the writer cut
    /// anywhere.
    #[test]
    fn latin1_text_comes_back_byte_for_byte() {
        let bytes = b"MODULE M\r\n  ! Gr\xf6\xdfe \xb0C\r\n  TPWrite \"caf\xe9\";\r\nENDMODULE\r\n"
            .to_vec();
        let (text, cs) = decode(bytes.clone());
        assert_eq!(cs, Charset::Latin1);
        assert!(text.contains("! Größe °C"));
        assert!(text.contains("café"));
        assert_eq!(&*encode(&text, cs), &bytes[..]);
        for cut in 1..8 {
            let mut out = Vec::new();
            let mut w = Latin1Writer::new(&mut out);
            for chunk in text.as_bytes().chunks(cut) {
                w.write_all(chunk).unwrap();
            }
            w.flush().unwrap();
            assert_eq!(out, bytes, "chunks of {cut}");
        }
        let all: Vec<u8> = (0..=255).collect();
        let (text, cs) = decode(all.clone());
        assert_eq!(cs, Charset::Latin1);
        assert_eq!(&*encode(&text, cs), &all[..]);
    }

    #[test]
    fn utf8_stays_utf8_and_the_unwritable_is_a_question_mark() {
        let (text, cs) = decode("! Größe\n".as_bytes().to_vec());
        assert_eq!((text.as_str(), cs), ("! Größe\n", Charset::Utf8));
        assert_eq!(&*encode("a€b", Charset::Latin1), b"a?b");
        let mut out = Vec::new();
        let mut w = Latin1Writer::new(&mut out);
        w.write_all(b"a\xffb\xc3").unwrap();
        w.flush().unwrap();
        assert_eq!(out, b"a?b?");
    }

    /// A column after characters beyond ASCII counts bytes of the Latin-1
    /// file; in UTF-8 text, and for other errors, it is kept.
    #[test]
    fn columns_count_file_bytes() {
        use crate::error::{Error, Located};
        let text = "MODULE M\n  TPWrite \"caf\u{e9}\"; x\n";
        let at = |col| Error::Input(Located::new("t.mod", 2, col, "m"));
        let col = |e: Error| match e {
            Error::Input(l) => l.column,
            _ => 0,
        };
        // `x` is byte 20 of the decoded line, byte 19 of the file's.
        assert_eq!(&text[9..][19..20], "x");
        assert_eq!(col(file_columns(at(20), text, Charset::Latin1)), 19);
        assert_eq!(col(file_columns(at(20), text, Charset::Utf8)), 20);
        // Before the `é`, nothing moves.
        assert_eq!(col(file_columns(at(3), text, Charset::Latin1)), 3);
        let whole = Error::Input(Located::whole_file("t.mod", "m"));
        assert_eq!(col(file_columns(whole, text, Charset::Latin1)), 0);
    }
}
