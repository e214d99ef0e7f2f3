//! Line and token helpers shared by the text readers (OBJ, ASCII PLY, ASCII STL, OFF).
//!
//! Lines are read into one reused buffer (no allocation per line); tokens are
//! whitespace-separated byte slices of it.

use std::io::{BufRead, Read};

/// Longest data line accepted by the text readers (a polygon of millions of
/// vertices still fits).
pub(crate) const MAX_LINE: u64 = 64 << 20;

/// The UTF-8 byte order mark, skipped at the start of text files.
pub(crate) const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// A line reader over a buffered source that counts lines (1-based) and bytes.
pub(crate) struct Lines<R> {
    inner: R,
    buf: Vec<u8>,
    line: usize,
    consumed: u64,
}

/// What [`Lines::next_line`] found.
pub(crate) enum Next<'a> {
    /// A line (without its `\n` / `\r\n`) and its 1-based number.
    Line(usize, &'a [u8]),
    /// The end of the file.
    Eof,
    /// A line that cannot be text of a mesh file (its number and why): longer than
    /// the allowed maximum, or holding a carriage return that does not end it.
    Bad(usize, &'static str),
}

impl<R: BufRead> Lines<R> {
    pub(crate) fn new(inner: R) -> Self {
        Self::starting_at(inner, 0)
    }

    /// A line reader whose first line is numbered `line + 1` (a reader that takes
    /// over after `line` lines were read by other means; the byte order mark is
    /// skipped only at line 1).
    pub(crate) fn starting_at(inner: R, line: usize) -> Self {
        Lines {
            inner,
            buf: Vec::with_capacity(256),
            line,
            consumed: 0,
        }
    }

    /// The number of the last line returned (0 before the first).
    pub(crate) fn line(&self) -> usize {
        self.line
    }

    /// Bytes consumed so far (including line terminators).
    pub(crate) fn consumed(&self) -> u64 {
        self.consumed
    }

    /// The underlying reader, positioned just after the last line returned.
    pub(crate) fn into_inner(self) -> R {
        self.inner
    }

    /// The last line read (without its terminator) and its number.
    pub(crate) fn current(&self) -> Option<(usize, &[u8])> {
        if self.line == 0 {
            return None;
        }
        let mut s: &[u8] = &self.buf;
        if let Some(t) = s.strip_suffix(b"\n") {
            s = t;
        }
        if let Some(t) = s.strip_suffix(b"\r") {
            s = t;
        }
        Some((self.line, s))
    }

    /// The next line, reading at most `max` bytes for it (so that junk without
    /// newlines cannot make the reader buffer a whole file).
    pub(crate) fn next_line(&mut self, max: u64) -> std::io::Result<Next<'_>> {
        self.buf.clear();
        let n = (&mut self.inner)
            .take(max.saturating_add(1))
            .read_until(b'\n', &mut self.buf)?;
        if n == 0 {
            return Ok(Next::Eof);
        }
        self.consumed += n as u64;
        self.line += 1;
        if self.line == 1 && self.buf.starts_with(UTF8_BOM) {
            // A UTF-8 byte order mark before the first line is not content.
            self.buf.drain(..UTF8_BOM.len());
        }
        if n as u64 > max && self.buf.last() != Some(&b'\n') {
            return Ok(Next::Bad(self.line, "line too long"));
        }
        let mut s: &[u8] = &self.buf;
        if let Some(t) = s.strip_suffix(b"\n") {
            s = t;
        }
        if let Some(t) = s.strip_suffix(b"\r") {
            s = t;
        }
        // (Binary data, with NUL bytes, is left to the readers to report as such.)
        if s.contains(&b'\r') && !has_nul(s) {
            return Ok(Next::Bad(
                self.line,
                "carriage return inside a line (CR-only line endings are not supported; use LF or CRLF)",
            ));
        }
        Ok(Next::Line(self.line, s))
    }
}

/// The line up to (not including) the first `#`.
pub(crate) fn strip_comment(line: &[u8]) -> &[u8] {
    match line.iter().position(|&b| b == b'#') {
        Some(i) => line.get(..i).unwrap_or(line),
        None => line,
    }
}

/// Whitespace-separated tokens of a line.
pub(crate) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// True when the line holds a NUL byte (binary data in a text file).
pub(crate) fn has_nul(line: &[u8]) -> bool {
    line.contains(&0)
}

/// A token as text for error messages (lossy, shortened).
pub(crate) fn show(tok: &[u8]) -> String {
    let s = String::from_utf8_lossy(tok);
    if s.chars().count() > 40 {
        let mut t: String = s.chars().take(40).collect();
        t.push('…');
        t
    } else {
        s.into_owned()
    }
}

/// Parses a decimal real number (any value, including non-finite ones).
pub(crate) fn parse_f64(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse::<f64>().ok()
}

/// Parses a decimal integer (optional sign, then digits; `None` on overflow), as
/// `str::parse::<i64>` does, without the UTF-8 check (a hot path: OBJ indices).
pub(crate) fn parse_i64(tok: &[u8]) -> Option<i64> {
    let (neg, digits) = match tok.split_first()? {
        (b'-', rest) => (true, rest),
        (b'+', rest) => (false, rest),
        _ => (false, tok),
    };
    if digits.is_empty() {
        return None;
    }
    let mut v: i64 = 0;
    for &d in digits {
        if !d.is_ascii_digit() {
            return None;
        }
        let d = i64::from(d - b'0');
        // Accumulate negatively so that i64::MIN parses.
        v = v.checked_mul(10)?.checked_sub(d)?;
    }
    if neg {
        Some(v)
    } else {
        v.checked_neg()
    }
}

/// Parses a finite coordinate, or says what is wrong with the token.
pub(crate) fn parse_coord(tok: &[u8]) -> Result<f64, String> {
    check_coord(tok, parse_f64(tok))
}

/// Parses a finite coordinate declared as a 32-bit float (rounded once, from the
/// decimal text to `f32`, then widened exactly).
pub(crate) fn parse_coord_f32(tok: &[u8]) -> Result<f64, String> {
    let v = std::str::from_utf8(tok)
        .ok()
        .and_then(|s| s.parse::<f32>().ok());
    check_coord(tok, v.map(f64::from))
}

fn check_coord(tok: &[u8], v: Option<f64>) -> Result<f64, String> {
    match v {
        Some(v) if v.is_finite() => Ok(v),
        Some(_) => Err(format!(
            "non-finite coordinate '{}' (NaN and infinity are not allowed)",
            show(tok)
        )),
        None => Err(format!("'{}' is not a number", show(tok))),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn parse_i64_matches_std() {
        for t in [
            "0",
            "-0",
            "+7",
            "42",
            "-42",
            "9223372036854775807",
            "-9223372036854775808",
            "9223372036854775808",
            "-9223372036854775809",
            "",
            "-",
            "+",
            "1a",
            "--1",
            "+-1",
            " 1",
            "\u{661}",
            "00012",
        ] {
            assert_eq!(
                super::parse_i64(t.as_bytes()),
                t.parse::<i64>().ok(),
                "{t:?}"
            );
        }
    }
}
