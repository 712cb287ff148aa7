//! Byte-level helpers shared by the text formats (.xyz, .obj, .off, ASCII .ply):
//! line and token splitting without allocation, number parsing, and the
//! round-trip-exact way coordinates are written.

use crate::error::Error;
use std::io::Write;

/// Iterates over the lines of a buffer as `(1-based line number, bytes)`, without
/// the `\n` and without a trailing `\r` (so CRLF files read like LF files).
pub(crate) struct Lines<'a> {
    rest: &'a [u8],
    line: usize,
    done: bool,
}

impl<'a> Lines<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Lines { rest: bytes, line: 0, done: bytes.is_empty() }
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);
    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        self.line += 1;
        let (mut line, rest) = match self.rest.iter().position(|&b| b == b'\n') {
            Some(i) => (&self.rest[..i], &self.rest[i + 1..]),
            None => {
                self.done = true;
                (self.rest, &self.rest[self.rest.len()..])
            }
        };
        if rest.is_empty() {
            self.done = true;
        }
        self.rest = rest;
        if let [head @ .., b'\r'] = line {
            line = head;
        }
        Some((self.line, line))
    }
}

/// The part of a line before a `#` comment.
pub(crate) fn strip_comment(line: &[u8]) -> &[u8] {
    match line.iter().position(|&b| b == b'#') {
        Some(i) => &line[..i],
        None => line,
    }
}

/// True for the bytes that separate tokens in the text formats.
#[inline]
pub(crate) fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\x0b' | b'\x0c')
}

/// Whitespace-separated tokens of a line (optionally also comma-separated).
#[derive(Clone)]
pub(crate) struct Tokens<'a> {
    rest: &'a [u8],
    commas: bool,
}

impl<'a> Tokens<'a> {
    /// Tokens separated by whitespace.
    pub(crate) fn new(line: &'a [u8]) -> Self {
        Tokens { rest: line, commas: false }
    }
    /// Tokens separated by whitespace and/or commas.
    pub(crate) fn with_commas(line: &'a [u8]) -> Self {
        Tokens { rest: line, commas: true }
    }
    #[inline]
    fn sep(&self, b: u8) -> bool {
        is_space(b) || (self.commas && b == b',')
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = &'a [u8];
    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let start = self.rest.iter().position(|&b| !self.sep(b))?;
        let rest = &self.rest[start..];
        let end = rest.iter().position(|&b| self.sep(b)).unwrap_or(rest.len());
        self.rest = &rest[end..];
        Some(&rest[..end])
    }
}

/// Parses a decimal floating-point number (any form Rust's `f64::from_str` takes,
/// including `inf`/`nan`, which callers reject with a better message).
#[inline]
pub(crate) fn parse_f64(tok: &[u8]) -> Option<f64> {
    std::str::from_utf8(tok).ok()?.parse::<f64>().ok()
}

/// Parses a decimal integer with an optional sign; `None` on anything else or overflow.
#[inline]
pub(crate) fn parse_i64(tok: &[u8]) -> Option<i64> {
    let (neg, digits) = match tok.first()? {
        b'-' => (true, &tok[1..]),
        b'+' => (false, &tok[1..]),
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
        v = v.checked_mul(10)?.checked_add(i64::from(d - b'0'))?;
    }
    Some(if neg { -v } else { v })
}

/// A token for an error message: lossy UTF-8, cut to a readable length.
pub(crate) fn show(tok: &[u8]) -> String {
    const MAX: usize = 40;
    let s = String::from_utf8_lossy(&tok[..tok.len().min(MAX)]).into_owned();
    if tok.len() > MAX {
        format!("{s}…")
    } else {
        s
    }
}

/// Parses a coordinate token: a bad number or a non-finite value is a parse error
/// at `line` of `name`; `what` says which value it was (e.g. "vertex 3 y").
pub(crate) fn coord(tok: &[u8], name: &str, line: usize, what: &dyn std::fmt::Display) -> Result<f64, Error> {
    match parse_f64(tok) {
        Some(v) if v.is_finite() => Ok(v),
        Some(_) => Err(Error::parse(name, line, format!("{what}: non-finite coordinate '{}'", show(tok)))),
        None => Err(Error::parse(name, line, format!("{what}: bad number '{}'", show(tok)))),
    }
}

/// Writes `x` so that `f64::from_str` gives back exactly the same bits (sign of
/// zero included). Rust's `{}` and `{:e}` both print the shortest round-trip
/// digits; plain notation is used for ordinary magnitudes and exponent notation
/// for very large or small ones (plain `{}` would print 1e300 as 301 digits).
pub(crate) fn write_f64(w: &mut dyn Write, x: f64) -> std::io::Result<()> {
    let a = x.abs();
    if a == 0.0 || (1e-5..1e16).contains(&a) {
        write!(w, "{x}")
    } else {
        write!(w, "{x:e}")
    }
}

/// Maps an I/O error from an in-memory writer (no path known here; `write_atomic`
/// replaces it with one naming the file).
pub(crate) fn out_err(e: std::io::Error) -> Error {
    Error::io("<output>", e)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_strip_cr_and_count_from_one() {
        let v: Vec<_> = Lines::new(b"a\r\nb\n\nc").collect();
        assert_eq!(v, vec![(1, &b"a"[..]), (2, &b"b"[..]), (3, &b""[..]), (4, &b"c"[..])]);
        assert_eq!(Lines::new(b"a\n").count(), 1);
        assert_eq!(Lines::new(b"").count(), 0);
    }

    #[test]
    fn tokens_split_on_space_and_optionally_commas() {
        let t: Vec<_> = Tokens::new(b"  1\t2,3  ").collect();
        assert_eq!(t, vec![&b"1"[..], &b"2,3"[..]]);
        let t: Vec<_> = Tokens::with_commas(b"1, 2 ,3").collect();
        assert_eq!(t, vec![&b"1"[..], &b"2"[..], &b"3"[..]]);
    }

    #[test]
    fn integers_parse_strictly() {
        assert_eq!(parse_i64(b"-12"), Some(-12));
        assert_eq!(parse_i64(b"+7"), Some(7));
        assert_eq!(parse_i64(b"1.0"), None);
        assert_eq!(parse_i64(b"-"), None);
        assert_eq!(parse_i64(b"99999999999999999999"), None);
    }

    #[test]
    fn floats_round_trip_bit_exactly() {
        let xs = [
            -0.0,
            0.0,
            5e-324,
            -2.2250738585072014e-308,
            1e300,
            -1.7976931348623157e308,
            0.1,
            1.0 / 3.0,
            123456789.123,
            1e-5,
            9_999_999_999_999_998.0,
            1e16,
        ];
        for x in xs {
            let mut buf = Vec::new();
            write_f64(&mut buf, x).unwrap();
            let back = parse_f64(&buf).unwrap();
            assert_eq!(back.to_bits(), x.to_bits(), "{x} -> {}", String::from_utf8_lossy(&buf));
            assert!(buf.len() < 26, "{}", String::from_utf8_lossy(&buf));
        }
    }

    #[test]
    fn coord_rejects_non_finite_and_garbage() {
        let e = coord(b"nan", "f.xyz", 3, &"point 2 x").unwrap_err().to_string();
        assert!(e.contains("f.xyz:3") && e.contains("non-finite"), "{e}");
        let e = coord(b"1.2.3", "f.xyz", 4, &"point 3 x").unwrap_err().to_string();
        assert!(e.contains("f.xyz:4") && e.contains("bad number"), "{e}");
    }
}
