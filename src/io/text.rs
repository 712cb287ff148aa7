//! Byte-level helpers shared by the text formats (.xyz, .obj, .off, ASCII .ply):
//! line and token splitting without allocation, number parsing, and the
//! round-trip-exact way coordinates are written.

use crate::error::Error;
use std::io::Write;

/// Iterates over the lines of a buffer as `(1-based line number, bytes)`, without
/// the `\n` and without a trailing `\r` (so CRLF files read like LF files), and
/// without a leading UTF-8 byte-order mark (Windows editors write one).
pub(crate) struct Lines<'a> {
    rest: &'a [u8],
    line: usize,
    done: bool,
}

impl<'a> Lines<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
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
        let (mut line, rest) = match find_byte(self.rest, b'\n') {
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

/// The text with classic Mac line endings (a lone `\r`) turned into `\n`. Without this
/// a CR-only file reads as one long line, and the formats that ignore extra columns
/// (OBJ, .xyz) would silently keep its first vertex only; in a file that mixes line
/// ends (a line pasted from a Mac editor into an LF file) the two lines around a lone
/// `\r` were read as one, the second's values taken for extra columns of the first.
/// With no `\n` at all, every `\r` is a line end. Otherwise a `\r` is one unless a
/// `\n` follows it, directly or after one more `\r`: `\r\n` and the `\r\r\n` of a
/// doubled conversion stay as they are (the `\r`s before the `\n` are read as blanks),
/// so their line numbers do not move, and `\r\r` between lines is two line ends. The
/// text as is (borrowed) when nothing changes. Only for text formats: never for a file
/// that may hold binary data.
pub(crate) fn cr_lines(bytes: &[u8]) -> std::borrow::Cow<'_, [u8]> {
    if find_byte(bytes, b'\n').is_none() {
        if find_byte(bytes, b'\r').is_none() {
            return std::borrow::Cow::Borrowed(bytes);
        }
        return std::borrow::Cow::Owned(bytes.iter().map(|&b| if b == b'\r' { b'\n' } else { b }).collect());
    }
    let lone = |j: usize| match bytes.get(j + 1) {
        Some(b'\n') => false,
        Some(b'\r') => bytes.get(j + 2) != Some(&b'\n'),
        _ => true,
    };
    let mut from = 0;
    let first = loop {
        match find_byte(&bytes[from..], b'\r') {
            None => return std::borrow::Cow::Borrowed(bytes),
            Some(k) if lone(from + k) => break from + k,
            Some(k) => from += k + 1,
        }
    };
    let mut out = bytes.to_vec();
    for (j, b) in out.iter_mut().enumerate().skip(first) {
        if *b == b'\r' && lone(j) {
            *b = b'\n';
        }
    }
    std::borrow::Cow::Owned(out)
}

/// Position of the first `needle` in `hay`. Eight bytes at a time (the classic
/// "has zero byte" word trick): lines are short, but a 1 MB file has 25k of them,
/// and a byte-at-a-time loop was a fifth of the parse time.
#[inline]
pub(crate) fn find_byte(hay: &[u8], needle: u8) -> Option<usize> {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    let rep = LO * u64::from(needle);
    let mut chunks = hay.chunks_exact(8);
    let mut base = 0;
    for c in &mut chunks {
        let mut a = [0u8; 8];
        a.copy_from_slice(c);
        let w = u64::from_le_bytes(a) ^ rep;
        // The lowest flagged byte is always a true match (false positives can only
        // appear above a real zero byte), so trailing_zeros finds the first one.
        let t = w.wrapping_sub(LO) & !w & HI;
        if t != 0 {
            return Some(base + (t.trailing_zeros() / 8) as usize);
        }
        base += 8;
    }
    chunks.remainder().iter().position(|&b| b == needle).map(|p| base + p)
}

/// True for the bytes that separate tokens in the text formats.
#[inline]
pub(crate) fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | b'\x0b' | b'\x0c')
}

/// Whitespace-separated tokens of a line (optionally also comma-separated, and
/// optionally ending at a `#` comment, in the same single pass).
#[derive(Clone)]
pub(crate) struct Tokens<'a> {
    rest: &'a [u8],
    commas: bool,
    comments: bool,
}

impl<'a> Tokens<'a> {
    /// Tokens separated by whitespace; `#` is an ordinary byte.
    pub(crate) fn new(line: &'a [u8]) -> Self {
        Tokens { rest: line, commas: false, comments: false }
    }
    /// Tokens separated by whitespace; a `#` ends the line (comment).
    pub(crate) fn commented(line: &'a [u8]) -> Self {
        Tokens { rest: line, commas: false, comments: true }
    }
    /// Tokens separated by whitespace and/or commas; a `#` ends the line.
    pub(crate) fn with_commas(line: &'a [u8]) -> Self {
        Tokens { rest: line, commas: true, comments: true }
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
        if self.comments && rest[0] == b'#' {
            self.rest = &[];
            return None;
        }
        let end =
            rest.iter().position(|&b| self.sep(b) || (self.comments && b == b'#')).unwrap_or(rest.len());
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
    if digits.len() <= 18 {
        // 18 digits cannot overflow i64: skip the checked arithmetic.
        for &d in digits {
            if !d.is_ascii_digit() {
                return None;
            }
            v = v * 10 + i64::from(d - b'0');
        }
    } else {
        for &d in digits {
            if !d.is_ascii_digit() {
                return None;
            }
            v = v.checked_mul(10)?.checked_add(i64::from(d - b'0'))?;
        }
    }
    Some(if neg { -v } else { v })
}

/// A token for an error message: lossy UTF-8, control characters escaped (a binary
/// file must not send terminal escape sequences to the user's stderr), cut to a
/// readable length.
pub(crate) fn show(tok: &[u8]) -> String {
    const MAX: usize = 40;
    let mut s = String::new();
    for c in String::from_utf8_lossy(&tok[..tok.len().min(MAX)]).chars() {
        // Non-ASCII spaces (a no-break space from a spreadsheet) are shown escaped: they
        // look like separators but are none.
        if c.is_control() || (c.is_whitespace() && !c.is_ascii()) {
            s.extend(c.escape_default());
        } else {
            s.push(c);
        }
    }
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

/// Writes one `x y z` line (round-trip exact, see [`write_f64`]): the vertex line of
/// .xyz, OFF and ASCII PLY, and of OBJ after its `v `.
pub(crate) fn write_xyz_line(w: &mut dyn Write, p: [f64; 3]) -> std::io::Result<()> {
    write_f64(w, p[0])?;
    w.write_all(b" ")?;
    write_f64(w, p[1])?;
    w.write_all(b" ")?;
    write_f64(w, p[2])?;
    w.write_all(b"\n")
}

/// Writes one `n i0 … i(n-1)` face line with 0-based indices (OFF, ASCII PLY).
pub(crate) fn write_counted_face(w: &mut dyn Write, face: &[u32]) -> std::io::Result<()> {
    write!(w, "{}", face.len())?;
    for &i in face {
        write!(w, " {i}")?;
    }
    w.write_all(b"\n")
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
    fn a_leading_byte_order_mark_is_skipped() {
        let v: Vec<_> = Lines::new(b"\xEF\xBB\xBF1 2 3\n4 5 6").collect();
        assert_eq!(v, vec![(1, &b"1 2 3"[..]), (2, &b"4 5 6"[..])]);
        // Only at the start, and only the whole mark.
        let v: Vec<_> = Lines::new(b"1\n\xEF\xBB\xBF2").collect();
        assert_eq!(v[1].1, b"\xEF\xBB\xBF2");
        assert_eq!(Lines::new(b"\xEF\xBB\xBF").count(), 0);
        assert_eq!(Lines::new(b"\xEF\xBB1").next().unwrap().1, b"\xEF\xBB1");
    }

    #[test]
    fn cr_only_text_becomes_lines() {
        assert_eq!(&*cr_lines(b"a\rb\r"), b"a\nb\n");
        // Mixed line ends: a lone `\r` between `\n` lines ends its line (it joined two
        // lines before); `\r\n` and `\r\r\n` stay as they are.
        assert_eq!(&*cr_lines(b"a\r\nb\r"), b"a\r\nb\n");
        assert_eq!(&*cr_lines(b"a\nb\rc\nd\r\ne\r\r\nf"), b"a\nb\nc\nd\r\ne\r\r\nf");
        assert!(matches!(cr_lines(b"a\r\nb\r\r\nc\n"), std::borrow::Cow::Borrowed(_)));
        assert_eq!(&*cr_lines(b"a\r\rb\nc"), b"a\n\nb\nc");
        let text = cr_lines(b"1 2 3\n4 5 6\r7 8 9\r\n");
        let lines: Vec<(usize, &[u8])> = Lines::new(&text).collect();
        assert_eq!(lines, vec![(1, &b"1 2 3"[..]), (2, b"4 5 6"), (3, b"7 8 9")]);
        assert!(matches!(cr_lines(b"a b"), std::borrow::Cow::Borrowed(_)));
    }

    #[test]
    fn tokens_split_on_space_and_optionally_commas() {
        let t: Vec<_> = Tokens::new(b"  1\t2,3  ").collect();
        assert_eq!(t, vec![&b"1"[..], &b"2,3"[..]]);
        let t: Vec<_> = Tokens::with_commas(b"1, 2 ,3").collect();
        assert_eq!(t, vec![&b"1"[..], &b"2"[..], &b"3"[..]]);
        let t: Vec<_> = Tokens::commented(b" a b#c d").collect();
        assert_eq!(t, vec![&b"a"[..], &b"b"[..]]);
        assert_eq!(Tokens::commented(b"  # x").next(), None);
        assert_eq!(Tokens::new(b"a#b").collect::<Vec<_>>(), vec![&b"a#b"[..]]);
    }

    #[test]
    fn find_byte_matches_a_plain_search() {
        let hay: Vec<u8> = (0..200u32).map(|i| (i * 37 % 251) as u8).collect();
        for start in 0..40 {
            for needle in [0u8, 1, 10, 35, 128, 255, 250] {
                let h = &hay[start..];
                assert_eq!(find_byte(h, needle), h.iter().position(|&b| b == needle), "{start} {needle}");
            }
        }
        assert_eq!(find_byte(b"\x01\x00\n", b'\n'), Some(2));
    }

    #[test]
    fn integers_parse_strictly() {
        assert_eq!(parse_i64(b"-12"), Some(-12));
        assert_eq!(parse_i64(b"+7"), Some(7));
        assert_eq!(parse_i64(b"1.0"), None);
        assert_eq!(parse_i64(b"-"), None);
        assert_eq!(parse_i64(b"99999999999999999999"), None);
        assert_eq!(parse_i64(b"999999999999999999"), Some(999_999_999_999_999_999));
        assert_eq!(parse_i64(b"-9223372036854775807"), Some(-i64::MAX));
        assert_eq!(parse_i64(b"9223372036854775808"), None);
        assert_eq!(parse_i64(b"12a"), None);
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

    /// Regression: garbage bytes were echoed raw into error messages, so a binary
    /// file could send terminal escape sequences (ESC, BEL, CR) to stderr.
    #[test]
    fn show_escapes_control_bytes_from_garbage() {
        let s = show(b"a\x1b[2Jb\x07\r\x00\xff");
        assert!(!s.chars().any(char::is_control), "{s:?}");
        assert!(s.starts_with("a\\u{1b}[2Jb"), "{s:?}");
        assert_eq!(show(b"plain"), "plain");
        // A no-break space looks like a separator: shown escaped (session 24's audit).
        assert_eq!(show("1\u{a0}2\u{2007}3 4".as_bytes()), "1\\u{a0}2\\u{2007}3 4");
    }

    #[test]
    fn coord_rejects_non_finite_and_garbage() {
        let e = coord(b"nan", "f.xyz", 3, &"point 2 x").unwrap_err().to_string();
        assert!(e.contains("f.xyz:3") && e.contains("non-finite"), "{e}");
        let e = coord(b"1.2.3", "f.xyz", 4, &"point 3 x").unwrap_err().to_string();
        assert!(e.contains("f.xyz:4") && e.contains("bad number"), "{e}");
    }
}
