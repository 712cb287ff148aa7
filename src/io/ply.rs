//! Stanford PLY: ascii, binary_little_endian and binary_big_endian. Reads the
//! `vertex` element's x y z (any scalar type) and the `face` element's
//! `vertex_indices` / `vertex_index` list (any integer types); every other property
//! and element, list properties included, is skipped (in ASCII its values are still
//! checked against their declared types). Writes doubles, so coordinates round-trip
//! exactly.

use super::mesh_io::check_writable;
use super::text::{self, out_err, parse_f64, parse_i64, show, Lines, Tokens};
use crate::error::{Error, Result};
use crate::mesh::poly::PolyMesh;
use std::io::Write;

/// How a PLY file is encoded when written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PlyEncoding {
    /// Text; larger and slower, but readable.
    Ascii,
    /// Binary, little-endian (the default: what most tools write).
    #[default]
    BinaryLittleEndian,
    /// Binary, big-endian.
    BinaryBigEndian,
}

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn from_name(t: &[u8]) -> Option<Scalar> {
        Some(match t {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_int(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// The type's name in the PLY specification, for messages.
    fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "char",
            Scalar::U8 => "uchar",
            Scalar::I16 => "short",
            Scalar::U16 => "ushort",
            Scalar::I32 => "int",
            Scalar::U32 => "uint",
            Scalar::F32 => "float",
            Scalar::F64 => "double",
        }
    }

    /// The smallest and largest value of an integer type; `None` for `float` and `double`.
    fn int_bounds(self) -> Option<(i64, i64)> {
        Some(match self {
            Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
            Scalar::U8 => (0, u8::MAX.into()),
            Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
            Scalar::U16 => (0, u16::MAX.into()),
            Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
            Scalar::U32 => (0, u32::MAX.into()),
            Scalar::F32 | Scalar::F64 => return None,
        })
    }

    /// The values the type holds, as a message fragment: `0 to 255`, or for `float`
    /// and `double` the largest magnitude.
    fn range_text(self) -> String {
        match (self.int_bounds(), self) {
            (Some((lo, hi)), _) => format!("{lo} to {hi}"),
            (None, Scalar::F32) => format!("at most ±{:e}", f32::MAX),
            (None, _) => format!("at most ±{:e}", f64::MAX),
        }
    }

    /// Parses an ASCII value of this integer type: an integer within the type's range.
    fn text_int(self, tok: &[u8]) -> std::result::Result<i64, Misfit> {
        let (lo, hi) = self.int_bounds().unwrap_or((i64::MIN, i64::MAX));
        match parse_i64(tok) {
            Some(v) if (lo..=hi).contains(&v) => Ok(v),
            Some(_) => Err(Misfit::OutOfRange),
            None => {
                let digits = unsigned(tok);
                if !digits.is_empty() && digits.iter().all(u8::is_ascii_digit) {
                    Err(Misfit::OutOfRange) // beyond even i64
                } else if parse_f64(tok).is_some() {
                    Err(Misfit::NotAnInteger)
                } else {
                    Err(Misfit::NotANumber)
                }
            }
        }
    }

    /// Parses an ASCII value of this type: an integer type takes an integer within its
    /// range (see [`Scalar::text_int`]); `float` and `double` take a number that is
    /// finite in that type (`1e39` is not a `float`). The words `nan` and `inf` pass,
    /// as a binary file can hold them too: coordinates refuse them as non-finite.
    /// The value is returned as written (a `float` is not rounded to f32).
    fn text_real(self, tok: &[u8]) -> std::result::Result<f64, Misfit> {
        if self.is_int() {
            return self.text_int(tok).map(|v| v as f64);
        }
        let v = parse_f64(tok).ok_or(Misfit::NotANumber)?;
        let fits = if v.is_finite() {
            self == Scalar::F64 || (v as f32).is_finite()
        } else {
            // `inf`, `nan` (spelt out) rather than digits that overflowed (`1e400`).
            unsigned(tok).first().is_some_and(u8::is_ascii_alphabetic)
        };
        if fits {
            Ok(v)
        } else {
            Err(Misfit::OutOfRange)
        }
    }

    /// Decodes one value from the first `size()` bytes of `b`.
    #[inline]
    fn read_f64(self, b: &[u8], big: bool) -> f64 {
        macro_rules! get {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&b[..$n]);
                if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }
            }};
        }
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(get!(i16, 2)),
            Scalar::U16 => f64::from(get!(u16, 2)),
            Scalar::I32 => f64::from(get!(i32, 4)),
            Scalar::U32 => f64::from(get!(u32, 4)),
            Scalar::F32 => f64::from(get!(f32, 4)),
            Scalar::F64 => get!(f64, 8),
        }
    }

    /// Decodes one integer (only called for integer types, where it is exact).
    #[inline]
    fn read_i64(self, b: &[u8], big: bool) -> i64 {
        self.read_f64(b, big) as i64
    }
}

/// `tok` without a leading sign.
fn unsigned(tok: &[u8]) -> &[u8] {
    tok.strip_prefix(b"-").or_else(|| tok.strip_prefix(b"+")).unwrap_or(tok)
}

/// Why an ASCII value does not fit its property's declared type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Misfit {
    /// Not a number at all (`x`, `1.2.3`).
    NotANumber,
    /// A number, but the type is an integer type (`0.7` for an `int`).
    NotAnInteger,
    /// Beyond the type's range (`300` for a `uchar`, `1e39` for a `float`).
    OutOfRange,
}

impl Misfit {
    /// The message for `tok`, a value of type `t` (`subject` names it: "property 'x'");
    /// `bad` words a token that is no number at all (the callers' "bad number").
    fn describe(self, t: Scalar, tok: &[u8], subject: &dyn std::fmt::Display, bad: &str) -> String {
        match self {
            Misfit::NotANumber => format!("{bad} '{}'", show(tok)),
            Misfit::NotAnInteger => {
                format!("{subject} is {}: '{}' is not an integer", t.name(), show(tok))
            }
            Misfit::OutOfRange => {
                format!("{subject} is {}: '{}' is out of range ({})", t.name(), show(tok), t.range_text())
            }
        }
    }
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Prop {
    name: String,
    kind: Kind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Prop>,
    /// Header line that declared it (for errors about its properties).
    line: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Ascii,
    Binary { big: bool },
}

struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Byte offset where the body starts.
    data_start: usize,
    /// Number of header lines (the body's first line is this + 1).
    lines: usize,
}

fn parse_header(bytes: &[u8], name: &str) -> Result<Header> {
    // A UTF-8 byte-order mark before `ply` (some Windows editors write one).
    let mut pos = if bytes.starts_with(b"\xEF\xBB\xBF") { 3 } else { 0 };
    // The header's line ends are those of its first line: `\n`, `\r\n` or a lone `\r`
    // (old Mac files). Deciding once keeps a binary body that starts with a 0x0A byte
    // from being read as the end of a `\r\n`.
    let cr_only = bytes[pos..].starts_with(b"ply\r") && !bytes[pos..].starts_with(b"ply\r\n");
    let eol = if cr_only { b'\r' } else { b'\n' };
    let mut ln = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(nl) = bytes[pos..].iter().position(|&b| b == eol) else {
            return Err(Error::parse(name, ln + 1, "header not terminated by 'end_header'"));
        };
        let mut line = &bytes[pos..pos + nl];
        if let [head @ .., b'\r'] = line {
            line = head;
        }
        pos += nl + 1;
        ln += 1;
        let mut t = Tokens::new(line);
        let key = t.next().unwrap_or(b"");
        if ln == 1 {
            if key != b"ply" {
                return Err(Error::parse(name, 1, "not a PLY file (first line is not 'ply')"));
            }
            continue;
        }
        match key {
            b"format" => {
                if let Some((_, first)) = format {
                    return Err(Error::parse(
                        name,
                        ln,
                        format!("a second 'format' line (the first is on line {first})"),
                    ));
                }
                let f = match t.next().unwrap_or(b"") {
                    b"ascii" => Format::Ascii,
                    b"binary_little_endian" => Format::Binary { big: false },
                    b"binary_big_endian" => Format::Binary { big: true },
                    other => {
                        return Err(Error::parse(name, ln, format!("unknown PLY format '{}'", show(other))))
                    }
                };
                match t.next() {
                    // `1`, `1.0`, `1.00`: the one version there is, however it is written.
                    Some(v) if parse_f64(v) == Some(1.0) => {}
                    Some(v) => {
                        return Err(Error::parse(
                            name,
                            ln,
                            format!("unsupported PLY version '{}' (only 1.0 is defined)", show(v)),
                        ))
                    }
                    None => {
                        return Err(Error::parse(
                            name,
                            ln,
                            "format line without a version (expected e.g. 'format ascii 1.0')",
                        ))
                    }
                }
                if let Some(extra) = t.next() {
                    return Err(Error::parse(
                        name,
                        ln,
                        format!("unexpected '{}' after the format's version", show(extra)),
                    ));
                }
                format = Some((f, ln));
            }
            b"comment" | b"obj_info" | b"" => {}
            b"element" => {
                let en = t.next().ok_or_else(|| Error::parse(name, ln, "element without a name"))?;
                let ct = t.next().unwrap_or(b"");
                let count = match parse_i64(ct).and_then(|c| usize::try_from(c).ok()) {
                    Some(c) => c,
                    _ => return Err(Error::parse(name, ln, format!("bad element count '{}'", show(ct)))),
                };
                let en = String::from_utf8_lossy(en).into_owned();
                if elements.iter().any(|e| e.name == en) {
                    return Err(Error::parse(name, ln, format!("element '{en}' declared twice")));
                }
                elements.push(Element { name: en, count, props: Vec::new(), line: ln });
            }
            b"property" => {
                let el = elements
                    .last_mut()
                    .ok_or_else(|| Error::parse(name, ln, "property before any element"))?;
                let ty = t.next().unwrap_or(b"");
                let scalar = |tok: &[u8]| {
                    Scalar::from_name(tok).ok_or_else(|| {
                        Error::parse(name, ln, format!("unknown property type '{}'", show(tok)))
                    })
                };
                let kind = if ty == b"list" {
                    let count = scalar(t.next().unwrap_or(b""))?;
                    let item = scalar(t.next().unwrap_or(b""))?;
                    if !count.is_int() {
                        return Err(Error::parse(name, ln, "list count type must be an integer type"));
                    }
                    Kind::List { count, item }
                } else {
                    Kind::Scalar(scalar(ty)?)
                };
                let pn = t.next().ok_or_else(|| Error::parse(name, ln, "property without a name"))?;
                let pn = String::from_utf8_lossy(pn).into_owned();
                // Readers would silently take the first one (or the last).
                if el.props.iter().any(|p| p.name == pn) {
                    return Err(Error::parse(
                        name,
                        ln,
                        format!(
                            "property '{}' declared twice in element '{}'",
                            show(pn.as_bytes()),
                            show(el.name.as_bytes())
                        ),
                    ));
                }
                el.props.push(Prop { name: pn, kind });
            }
            b"end_header" => break,
            other => {
                // A line of numbers is the data: the header's `end_header` is missing.
                let data = other.first().is_some_and(|b| b.is_ascii_digit() || b"+-.".contains(b));
                let hint = if data {
                    " (data before 'end_header'? the header must end with an 'end_header' line)"
                } else {
                    ""
                };
                return Err(Error::parse(name, ln, format!("unknown header line '{}'{hint}", show(other))));
            }
        }
    }
    let (format, _) = format.ok_or_else(|| Error::parse(name, ln, "header has no 'format' line"))?;
    Ok(Header { format, elements, data_start: pos, lines: ln })
}

fn eof(name: &str, what: &dyn std::fmt::Display) -> Error {
    Error::parse(name, 0, format!("truncated: file ends in {what}"))
}

/// Reads values from the body, whatever the encoding. Errors name the element
/// instance (`what`), plus the line for ASCII.
enum Cursor<'a> {
    /// `item_line`: the body line where the current element instance began (0 before
    /// its first value), so that [`Cursor::end_item`] can hold each instance to one line.
    Ascii {
        lines: Lines<'a>,
        toks: Tokens<'a>,
        line: usize,
        first_line: usize,
        item_line: usize,
    },
    Binary {
        data: &'a [u8],
        pos: usize,
        big: bool,
    },
}

impl<'a> Cursor<'a> {
    fn line(&self) -> usize {
        match self {
            Cursor::Ascii { line, first_line, .. } => line + first_line,
            Cursor::Binary { .. } => 0,
        }
    }

    fn next_token(&mut self) -> Option<&'a [u8]> {
        let Cursor::Ascii { lines, toks, line, item_line, .. } = self else { return None };
        loop {
            if let Some(t) = toks.next() {
                if *item_line == 0 {
                    *item_line = *line;
                }
                return Some(t);
            }
            let (l, text) = lines.next()?;
            *line = l;
            *toks = Tokens::new(text);
        }
    }

    /// Ends one element instance. In ASCII each instance is one line (PLY's layout):
    /// values left on its line, or an instance that ran over to the next line, mean the
    /// line does not match the header (read as one stream, a line of 4 values and one of
    /// 2 made two valid vertices).
    fn end_item(&mut self, name: &str, what: &dyn std::fmt::Display) -> Result<()> {
        let Cursor::Ascii { toks, line, first_line, item_line, .. } = self else { return Ok(()) };
        let start = std::mem::replace(item_line, 0);
        if start != 0 && start != *line {
            return Err(Error::parse(
                name,
                start + *first_line,
                format!("{what}: the line ends before the values the header declares"),
            ));
        }
        if toks.next().is_some() {
            return Err(Error::parse(
                name,
                *line + *first_line,
                format!("{what}: the line has more values than the header declares"),
            ));
        }
        Ok(())
    }

    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let Cursor::Binary { data, pos, .. } = self else { return None };
        let end = pos.checked_add(n)?;
        let s = data.get(*pos..end)?;
        *pos = end;
        Some(s)
    }

    fn big(&self) -> bool {
        matches!(self, Cursor::Binary { big: true, .. })
    }

    /// One scalar of property `prop` as f64 (integers convert exactly). In ASCII the
    /// value must fit the declared type (see [`Scalar::text_real`]).
    fn real(&mut self, t: Scalar, name: &str, what: &dyn std::fmt::Display, prop: &str) -> Result<f64> {
        if let Cursor::Binary { .. } = self {
            let big = self.big();
            let b = self.take(t.size()).ok_or_else(|| eof(name, what))?;
            return Ok(t.read_f64(b, big));
        }
        let tok = self.next_token().ok_or_else(|| eof(name, what))?;
        t.text_real(tok)
            .map_err(|m| self.misfit(m, t, tok, name, what, &format_args!("property '{prop}'"), "bad number"))
    }

    /// One integer of property `prop`; in ASCII within the declared type's range.
    fn int(&mut self, t: Scalar, name: &str, what: &dyn std::fmt::Display, prop: &str) -> Result<i64> {
        if let Cursor::Binary { .. } = self {
            let big = self.big();
            let b = self.take(t.size()).ok_or_else(|| eof(name, what))?;
            return Ok(t.read_i64(b, big));
        }
        let tok = self.next_token().ok_or_else(|| eof(name, what))?;
        t.text_int(tok).map_err(|m| {
            self.misfit(m, t, tok, name, what, &format_args!("property '{prop}'"), "bad integer")
        })
    }

    /// The error for an ASCII value `tok` of type `t` that does not fit it: on the
    /// current line, after `what`; `subject` names the value, `bad` words a token that
    /// is no number at all.
    #[allow(clippy::too_many_arguments)]
    fn misfit(
        &self,
        m: Misfit,
        t: Scalar,
        tok: &[u8],
        name: &str,
        what: &dyn std::fmt::Display,
        subject: &dyn std::fmt::Display,
        bad: &str,
    ) -> Error {
        Error::parse(name, self.line(), format!("{what}: {}", m.describe(t, tok, subject, bad)))
    }

    /// Skips `n` values of type `t` (of property `prop`). In ASCII each must still
    /// fit the type: a `uchar` colour of 300 is as wrong as a coordinate would be.
    fn skip(
        &mut self,
        t: Scalar,
        n: usize,
        name: &str,
        what: &dyn std::fmt::Display,
        prop: &str,
    ) -> Result<()> {
        if let Cursor::Binary { .. } = self {
            let bytes = n.checked_mul(t.size()).ok_or_else(|| eof(name, what))?;
            return self.take(bytes).map(|_| ()).ok_or_else(|| eof(name, what));
        }
        for _ in 0..n {
            let tok = self.next_token().ok_or_else(|| eof(name, what))?;
            t.text_real(tok).map_err(|m| {
                let bad = if t.is_int() { "bad integer" } else { "bad number" };
                let subject = format!("property '{prop}'");
                self.misfit(m, t, tok, name, what, &subject, &format!("{subject}: {bad}"))
            })?;
        }
        Ok(())
    }

    /// Skips one property value (a list's count and items).
    fn skip_prop(&mut self, p: &Prop, name: &str, what: &dyn std::fmt::Display) -> Result<()> {
        match p.kind {
            Kind::Scalar(s) => self.skip(s, 1, name, what, &p.name),
            Kind::List { count, item } => {
                let n = self.list_len(count, name, what, &p.name)?;
                self.skip(item, n, name, what, &p.name)
            }
        }
    }

    /// The length of a list property `prop`: not negative, and in ASCII within the
    /// count type's range (a `uchar` count of 300 is not a count).
    fn list_len(
        &mut self,
        count: Scalar,
        name: &str,
        what: &dyn std::fmt::Display,
        prop: &str,
    ) -> Result<usize> {
        let n = match self {
            Cursor::Binary { .. } => self.int(count, name, what, prop)?,
            Cursor::Ascii { .. } => {
                let tok = self.next_token().ok_or_else(|| eof(name, what))?;
                match parse_i64(tok) {
                    Some(n) if n < 0 => n,
                    _ => count.text_int(tok).map_err(|m| {
                        let subject = format_args!("the list count of property '{prop}'");
                        self.misfit(m, count, tok, name, what, &subject, "bad integer")
                    })?,
                }
            }
        };
        usize::try_from(n)
            .map_err(|_| Error::parse(name, self.line(), format!("{what}: negative list length {n}")))
    }
}

/// Parses a PLY mesh from memory; `name` stands for the file in error messages.
/// A face may repeat a vertex (it loads; later stages judge it). A file without a
/// `face` element gives a mesh without faces.
///
/// # Errors
/// `Parse` naming `name` and the header line or the element (`vertex 12`, with the
/// line for ASCII) for: a malformed header, an unknown format, a version other than
/// 1.0, a second `format` line, a property declared twice in one element, a vertex
/// element without scalar x, y and z, a face element without a `vertex_indices`
/// list, a bad or non-finite number, an ASCII value that does not fit its
/// property's declared type (naming the property: `uchar 300`, `int 0.7`, `float
/// 1e39`; list counts and indices included), a face with fewer than 3 vertices, an
/// index out of range, a body shorter or longer than the header declares.
pub fn parse_ply(bytes: &[u8], name: &str) -> Result<PolyMesh> {
    parse_ply_with(bytes, name, true)
}

/// As [`parse_ply`]; with `want_faces == false` the face element is skipped like
/// any other (so its contents are not checked beyond its length).
pub(crate) fn parse_ply_with(bytes: &[u8], name: &str, want_faces: bool) -> Result<PolyMesh> {
    let h = parse_header(bytes, name)?;
    let raw_body = &bytes[h.data_start..];
    // An ASCII body with lone-`\r` line ends (the header's were read the same way).
    let text_body = match h.format {
        Format::Ascii => super::text::cr_lines(raw_body),
        Format::Binary { .. } => std::borrow::Cow::Borrowed(raw_body),
    };
    let body: &[u8] = &text_body;
    let mut cur = match h.format {
        Format::Ascii => Cursor::Ascii {
            lines: Lines::new(body),
            toks: Tokens::new(b""),
            line: 0,
            first_line: h.lines,
            item_line: 0,
        },
        Format::Binary { big } => Cursor::Binary { data: body, pos: 0, big },
    };
    let mut mesh = PolyMesh::default();
    let mut have_vertices = false;
    // Faces read before the vertex element: their indices are range-checked at the end.
    let mut unchecked_faces = false;
    for el in &h.elements {
        match el.name.as_str() {
            "vertex" => {
                read_vertices(el, &mut cur, body.len(), name, &mut mesh.vertices)?;
                have_vertices = true;
            }
            "face" if want_faces => {
                let nv = if have_vertices { Some(mesh.vertices.len()) } else { None };
                unchecked_faces = nv.is_none();
                read_faces(el, &mut cur, body.len(), name, nv, &mut mesh.faces)?;
            }
            // An element without properties occupies no bytes, whatever its count
            // claims: looping over a lying count of 10^18 would never end.
            _ if el.props.is_empty() => {}
            _ => {
                for i in 0..el.count {
                    let what = format_args!("{} {i} of {} declared", el.name, el.count);
                    for p in &el.props {
                        cur.skip_prop(p, name, &what)?;
                    }
                    cur.end_item(name, &what)?;
                }
            }
        }
    }
    if !have_vertices {
        return Err(Error::parse(name, 0, "no 'vertex' element in the header"));
    }
    if unchecked_faces {
        let nv = mesh.vertices.len();
        for (i, f) in mesh.faces.iter().enumerate() {
            if let Some(&v) = f.iter().find(|&&v| v as usize >= nv) {
                return Err(Error::parse(
                    name,
                    0,
                    format!("face {i}: vertex index {v} out of range ({nv} vertices)"),
                ));
            }
        }
    }
    if let Cursor::Binary { data, pos, .. } = &cur {
        if *pos < data.len() {
            return Err(Error::parse(
                name,
                0,
                format!(
                    "{} bytes after the last element (the header declares fewer elements)",
                    data.len() - pos
                ),
            ));
        }
    } else if cur.next_token().is_some() {
        return Err(Error::parse(
            name,
            cur.line(),
            "data after the last element (the header declares fewer elements)",
        ));
    }
    Ok(mesh)
}

fn read_vertices(
    el: &Element,
    cur: &mut Cursor,
    body_len: usize,
    name: &str,
    out: &mut Vec<[f64; 3]>,
) -> Result<()> {
    let mut axis_prop = [usize::MAX; 3];
    for (a, an) in ["x", "y", "z"].iter().enumerate() {
        // The exact name first, then any case (session 37's audit: `property double X`
        // was refused, while the text readers take any case in a header).
        let i = el
            .props
            .iter()
            .position(|p| p.name == *an)
            .or_else(|| el.props.iter().position(|p| p.name.eq_ignore_ascii_case(an)))
            .ok_or_else(|| Error::parse(name, el.line, format!("element vertex has no property '{an}'")))?;
        if let Kind::List { .. } = el.props[i].kind {
            return Err(Error::parse(name, el.line, format!("vertex property '{an}' is a list")));
        }
        axis_prop[a] = i;
    }
    // Never trust the declared count for the allocation: a lying header must not
    // make us reserve gigabytes.
    out.reserve(el.count.min(body_len / 3 + 1));
    let finite = |p: [f64; 3], i: usize, line: usize| -> Result<[f64; 3]> {
        if p.iter().all(|c| c.is_finite()) {
            Ok(p)
        } else {
            Err(Error::parse(name, line, format!("vertex {i}: non-finite coordinate {p:?}")))
        }
    };
    // Fast path: binary with only scalar properties has a fixed stride.
    let all_scalar = el.props.iter().all(|p| matches!(p.kind, Kind::Scalar(_)));
    if let (true, Cursor::Binary { data, pos, big }) = (all_scalar, &mut *cur) {
        let mut offsets = Vec::with_capacity(el.props.len());
        let mut stride = 0;
        for p in &el.props {
            offsets.push(stride);
            if let Kind::Scalar(s) = p.kind {
                stride += s.size();
            }
        }
        let rest = &data[*pos..];
        let avail = rest.len().checked_div(stride).unwrap_or(el.count);
        let ty = |a: usize| match el.props[axis_prop[a]].kind {
            Kind::Scalar(s) => s,
            Kind::List { .. } => unreachable!("internal error: lists were rejected above"),
        };
        let (tx, ty_, tz) = (ty(0), ty(1), ty(2));
        let (ox, oy, oz) = (offsets[axis_prop[0]], offsets[axis_prop[1]], offsets[axis_prop[2]]);
        for i in 0..el.count.min(avail) {
            let r = &rest[i * stride..(i + 1) * stride];
            let p = [tx.read_f64(&r[ox..], *big), ty_.read_f64(&r[oy..], *big), tz.read_f64(&r[oz..], *big)];
            out.push(finite(p, i, 0)?);
        }
        if avail < el.count {
            return Err(Error::parse(
                name,
                0,
                format!("truncated: file ends in vertex {avail} of {} declared", el.count),
            ));
        }
        *pos += el.count * stride;
        return Ok(());
    }
    for i in 0..el.count {
        let what = format_args!("vertex {i} of {} declared", el.count);
        let mut p = [0.0; 3];
        let mut line = 0;
        for (k, prop) in el.props.iter().enumerate() {
            match prop.kind {
                Kind::Scalar(s) if axis_prop.contains(&k) => {
                    let v = cur.real(s, name, &what, &prop.name)?;
                    line = cur.line();
                    for a in 0..3 {
                        if axis_prop[a] == k {
                            p[a] = v;
                        }
                    }
                }
                _ => cur.skip_prop(prop, name, &what)?,
            }
        }
        cur.end_item(name, &what)?;
        out.push(finite(p, i, line)?);
    }
    Ok(())
}

fn read_faces(
    el: &Element,
    cur: &mut Cursor,
    body_len: usize,
    name: &str,
    nv: Option<usize>,
    out: &mut Vec<Vec<u32>>,
) -> Result<()> {
    let idx_prop = el
        .props
        .iter()
        .position(|p| p.name == "vertex_indices" || p.name == "vertex_index")
        .ok_or_else(|| Error::parse(name, el.line, "element face has no 'vertex_indices' list"))?;
    let Kind::List { count: ct, item: it } = el.props[idx_prop].kind else {
        return Err(Error::parse(name, el.line, "face property 'vertex_indices' is not a list"));
    };
    if !it.is_int() {
        return Err(Error::parse(name, el.line, "face vertex indices must have an integer type"));
    }
    out.reserve(el.count.min(body_len / 4 + 1));
    for i in 0..el.count {
        let what = format_args!("face {i} of {} declared", el.count);
        for (k, prop) in el.props.iter().enumerate() {
            if k != idx_prop {
                cur.skip_prop(prop, name, &what)?;
                continue;
            }
            let n = cur.list_len(ct, name, &what, &prop.name)?;
            let line = cur.line();
            if n < 3 {
                return Err(Error::parse(
                    name,
                    line,
                    format!("face {i}: has {n} vertices, needs at least 3"),
                ));
            }
            let mut face = Vec::with_capacity(n.min(64));
            for _ in 0..n {
                let v = cur.int(it, name, &what, &prop.name)?;
                let ok = v >= 0 && v <= i64::from(u32::MAX) && nv.map_or(true, |nv| (v as u64) < nv as u64);
                if !ok {
                    let line = cur.line();
                    let total = nv.map_or(String::new(), |nv| format!(" ({nv} vertices)"));
                    return Err(Error::parse(
                        name,
                        line,
                        format!("face {i}: vertex index {v} out of range{total}"),
                    ));
                }
                face.push(v as u32);
            }
            out.push(face);
        }
        cur.end_item(name, &what)?;
    }
    Ok(())
}

/// Writes `mesh` as PLY with double coordinates (exact round trip) and a
/// `vertex_indices` list per face (`uchar` counts, or `uint` when a face has more
/// than 255 vertices; `int` indices).
///
/// # Errors
/// `InvalidInput` for a mesh that could not be read back (non-finite coordinate,
/// face with fewer than 3 vertices or an index out of range); `Io` from the writer.
pub fn write_ply(w: &mut dyn Write, mesh: &PolyMesh, encoding: PlyEncoding) -> Result<()> {
    check_writable(mesh)?;
    write_ply_unchecked(w, mesh, encoding).map_err(out_err)
}

fn write_ply_unchecked(w: &mut dyn Write, mesh: &PolyMesh, encoding: PlyEncoding) -> std::io::Result<()> {
    let fmt = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
        PlyEncoding::BinaryBigEndian => "binary_big_endian",
    };
    let wide_count = mesh.faces.iter().any(|f| f.len() > 255);
    let wide_index = mesh.vertices.len() > i32::MAX as usize;
    write!(
        w,
        "ply\nformat {fmt} 1.0\ncomment written by point2quad\nelement vertex {}\n\
         property double x\nproperty double y\nproperty double z\nelement face {}\n\
         property list {} {} vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.faces.len(),
        if wide_count { "uint" } else { "uchar" },
        if wide_index { "uint" } else { "int" },
    )?;
    let big = match encoding {
        PlyEncoding::Ascii => {
            for p in &mesh.vertices {
                text::write_xyz_line(w, *p)?;
            }
            for f in &mesh.faces {
                text::write_counted_face(w, f)?;
            }
            return Ok(());
        }
        PlyEncoding::BinaryLittleEndian => false,
        PlyEncoding::BinaryBigEndian => true,
    };
    let u32b = |v: u32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
    let mut rec = [0u8; 24];
    for p in &mesh.vertices {
        for (k, c) in p.iter().enumerate() {
            let b = if big { c.to_be_bytes() } else { c.to_le_bytes() };
            rec[k * 8..k * 8 + 8].copy_from_slice(&b);
        }
        w.write_all(&rec)?;
    }
    // Both `int` and `uint` indices are written as the u32 bit pattern: `int` is
    // only chosen when every index fits in i32.
    let mut buf = Vec::new();
    for f in &mesh.faces {
        buf.clear();
        if wide_count {
            buf.extend_from_slice(&u32b(f.len() as u32));
        } else {
            buf.push(f.len() as u8);
        }
        for &i in f {
            buf.extend_from_slice(&u32b(i));
        }
        w.write_all(&buf)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube_like() -> PolyMesh {
        PolyMesh {
            vertices: vec![[-0.0, 1e300, 5e-324], [0.1, -2.5, 3.0], [1.0, 1.0, 1.0], [7.0, -8.0, 1e-310]],
            faces: vec![vec![0, 1, 2, 3], vec![2, 1, 0], vec![3, 3, 1]],
        }
    }

    #[test]
    fn faces_with_more_than_255_vertices_round_trip() {
        let n = 300u32;
        let m = PolyMesh { vertices: vec![[1.0, 2.0, 3.0]; n as usize], faces: vec![(0..n).collect()] };
        for enc in [PlyEncoding::Ascii, PlyEncoding::BinaryLittleEndian, PlyEncoding::BinaryBigEndian] {
            let mut buf = Vec::new();
            write_ply(&mut buf, &m, enc).unwrap();
            assert_eq!(parse_ply(&buf, "mem").unwrap(), m);
        }
    }

    /// Builds a binary file by hand with odd types, extra properties and elements.
    #[test]
    fn skips_other_properties_and_elements_in_binary() {
        for big in [false, true] {
            let fmt = if big { "binary_big_endian" } else { "binary_little_endian" };
            let mut b = format!(
                "ply\r\nformat {fmt} 1.0\r\ncomment x\r\nobj_info y\r\nelement material 1\r\n\
                 property list uint8 float32 stuff\r\nelement vertex 3\r\nproperty uchar red\r\n\
                 property float32 x\r\nproperty int16 y\r\nproperty list ushort char tags\r\nproperty double z\r\n\
                 element face 1\r\nproperty float q\r\nproperty list uchar uint vertex_index\r\n\
                 element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\nend_header\r\n"
            )
            .into_bytes();
            let e16 = |v: i16| if big { v.to_be_bytes() } else { v.to_le_bytes() };
            let eu16 = |v: u16| if big { v.to_be_bytes() } else { v.to_le_bytes() };
            let e32 = |v: f32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
            let eu32 = |v: u32| if big { v.to_be_bytes() } else { v.to_le_bytes() };
            let e64 = |v: f64| if big { v.to_be_bytes() } else { v.to_le_bytes() };
            // material: list of 2 floats
            b.push(2);
            b.extend(e32(1.0));
            b.extend(e32(2.0));
            for i in 0..3i16 {
                b.push(200);
                b.extend(e32(0.5 + f32::from(i)));
                b.extend(e16(-i));
                b.extend(eu16(i as u16));
                b.extend(std::iter::repeat(7u8).take(i as usize));
                b.extend(e64(f64::from(i) * 0.25));
            }
            b.extend(e32(9.0));
            b.push(3);
            for i in [2u32, 0, 1] {
                b.extend(eu32(i));
            }
            b.extend(eu32(0));
            b.extend(eu32(1));
            let m = parse_ply(&b, "t.ply").unwrap_or_else(|e| panic!("{fmt}: {e}"));
            assert_eq!(m.vertices, vec![[0.5, 0.0, 0.0], [1.5, -1.0, 0.25], [2.5, -2.0, 0.5]], "{fmt}");
            assert_eq!(m.faces, vec![vec![2, 0, 1]]);
            // One byte more or less: the header lies.
            let e = parse_ply(&b[..b.len() - 1], "t.ply").unwrap_err().to_string();
            assert!(e.contains("t.ply: truncated: file ends in edge 0"), "{e}");
            b.push(0);
            let e = parse_ply(&b, "t.ply").unwrap_err().to_string();
            assert!(e.contains("1 bytes after the last element"), "{e}");
        }
    }

    #[test]
    fn ascii_with_extra_properties() {
        let src = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float nx\nproperty float x\n\
                    property float y\nproperty float z\nproperty list uchar int junk\nelement face 1\n\
                    property list uchar int vertex_indices\nproperty uchar red\nend_header\n\
                    9 0 0 0 2 5 6\n9 1 0 0 0\n9 0 1 0 1 4\n3 0 1 2 255\n";
        let m = parse_ply(src, "t.ply").unwrap();
        assert_eq!(m.vertices, vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        assert_eq!(m.faces, vec![vec![0, 1, 2]]);
    }

    /// A UTF-8 byte-order mark before `ply`, and lone-`\r` line ends (header and ASCII
    /// body), read like the plain file; a binary body after a `\r` header is untouched.
    #[test]
    fn bom_and_cr_only_line_ends_read_like_the_plain_file() {
        let src = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                   property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
                   0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let want = parse_ply(src.as_bytes(), "t.ply").unwrap();
        let bom = [b"\xEF\xBB\xBF".as_slice(), src.as_bytes()].concat();
        assert_eq!(parse_ply(&bom, "t.ply").unwrap(), want);
        let cr = src.replace('\n', "\r");
        assert_eq!(parse_ply(cr.as_bytes(), "t.ply").unwrap(), want);
        // Binary little-endian with a `\r` header: a body starting with 0x0A stays data.
        let mut b = b"ply\rformat binary_little_endian 1.0\relement vertex 1\rproperty float x\r\
                      property float y\rproperty float z\rend_header\r"
            .to_vec();
        for v in [f32::from_le_bytes([0x0A, 0, 0x80, 0x3F]), 2.0, 3.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let m = parse_ply(&b, "t.ply").unwrap();
        assert_eq!(m.vertices, vec![[f32::from_le_bytes([0x0A, 0, 0x80, 0x3F]) as f64, 2.0, 3.0]]);
    }

    #[test]
    fn errors_name_file_and_line_or_element() {
        let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                    property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let cases: Vec<(String, &str)> = vec![
            ("ply\nformat binary_middle_endian 1.0\nend_header\n".into(), "t.ply:2: unknown PLY format"),
            ("plx\n".into(), "t.ply:1: not a PLY file"),
            ("ply\nformat ascii 1.0 junk\nend_header\n".into(), "t.ply:2: unexpected 'junk' after the format's version"),
            ("ply\nformat ascii 1.0\n".into(), "t.ply:3: header not terminated"),
            // `end_header` left out: the first data line is named as such (session 41).
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n0 0 0\n".into(), "t.ply:7: unknown header line '0' (data before 'end_header'?"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n".into(), "t.ply:3: element vertex has no property 'z'"),
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty blob x\nend_header\n".into(), "t.ply:4: unknown property type 'blob'"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"), "t.ply:13: face 0: vertex index 3 out of range"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n2 0 1\n"), "t.ply:13: face 0: has 2 vertices"),
            (format!("{head}0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n"), "t.ply:11: vertex 1 of 3 declared: bad number 'x'"),
            (format!("{head}0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n"), "t.ply:11: vertex 1: non-finite"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n"), "t.ply: truncated: file ends in face 0 of 1 declared"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n"), "t.ply:14: data after the last element"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n"), "t.ply:13: face 0 of 1 declared: negative list length"),
            // One element instance per line: a line of 4 values and one of 2 are not
            // two vertices.
            (format!("{head}0 0 0 7\n1 0\n0 1 0\n3 0 1 2\n"), "t.ply:10: vertex 0 of 3 declared: the line has more values"),
            (format!("{head}0 0\n0 1 0 0\n0 1 0\n3 0 1 2\n"), "t.ply:10: vertex 0 of 3 declared: the line ends before"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1\n2\n"), "t.ply:13: face 0 of 1 declared: the line ends before"),
            // Values that do not fit the declared type.
            (format!("{head}0 0 0\n1 0 0\n0 1 1e39\n3 0 1 2\n"), "t.ply:12: vertex 2 of 3 declared: property 'z' is float: '1e39' is out of range"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n256 0 1 2\n"), "t.ply:13: face 0 of 1 declared: the list count of property 'vertex_indices' is uchar: '256' is out of range (0 to 255)"),
            (format!("{head}0 0 0\n1 0 0\n0 1 0\n3 0 1 2.0\n"), "t.ply:13: face 0 of 1 declared: property 'vertex_indices' is int: '2.0' is not an integer"),
            // The header: a property twice, the format line twice, another version.
            ("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nend_header\n".into(), "t.ply:5: property 'x' declared twice in element 'vertex'"),
            ("ply\nformat ascii 1.0\nformat ascii 1.0\nend_header\n".into(), "t.ply:3: a second 'format' line (the first is on line 2)"),
            ("ply\nformat ascii 2.0\nend_header\n".into(), "t.ply:2: unsupported PLY version '2.0'"),
        ];
        for (src, want) in &cases {
            let e = parse_ply(src.as_bytes(), "t.ply").unwrap_err().to_string();
            assert!(e.contains(want), "got '{e}', want '{want}'");
        }
    }

    /// ASCII values against their declared type: the limits pass, one beyond fails,
    /// and the words nan/inf pass the type check (coordinates refuse them later).
    #[test]
    fn ascii_values_are_checked_against_their_type() {
        use Misfit::*;
        let cases: &[(Scalar, &str, Result<f64, Misfit>)] = &[
            (Scalar::U8, "255", Ok(255.0)),
            (Scalar::U8, "256", Err(OutOfRange)),
            (Scalar::U8, "-1", Err(OutOfRange)),
            (Scalar::I8, "-128", Ok(-128.0)),
            (Scalar::I8, "128", Err(OutOfRange)),
            (Scalar::U16, "65535", Ok(65535.0)),
            (Scalar::I16, "-32769", Err(OutOfRange)),
            (Scalar::I32, "2147483647", Ok(2147483647.0)),
            (Scalar::I32, "-2147483649", Err(OutOfRange)),
            (Scalar::U32, "4294967295", Ok(4294967295.0)),
            (Scalar::U32, "-99999999999999999999", Err(OutOfRange)),
            (Scalar::I32, "0.7", Err(NotAnInteger)),
            (Scalar::I32, "nan", Err(NotAnInteger)),
            (Scalar::I32, "x", Err(NotANumber)),
            (Scalar::I32, "-", Err(NotANumber)),
            (Scalar::F32, "3.4028235e38", Ok(3.4028235e38)),
            (Scalar::F32, "3.5e38", Err(OutOfRange)),
            (Scalar::F32, "0.1", Ok(0.1)),
            (Scalar::F64, "3.5e38", Ok(3.5e38)),
            (Scalar::F64, "-1e309", Err(OutOfRange)),
            (Scalar::F32, "1e400", Err(OutOfRange)),
            (Scalar::F32, "x", Err(NotANumber)),
        ];
        for &(t, tok, want) in cases {
            let got = t.text_real(tok.as_bytes());
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "{t:?} {tok}");
        }
        for (t, tok) in [(Scalar::F32, "inf"), (Scalar::F64, "-Infinity"), (Scalar::F32, "nan")] {
            assert!(t.text_real(tok.as_bytes()).is_ok_and(|v| !v.is_finite()), "{t:?} {tok}");
        }
        assert_eq!(Scalar::U8.text_int(b"7"), Ok(7));
        assert_eq!(Scalar::U8.range_text(), "0 to 255");
        assert_eq!(Scalar::F32.range_text(), "at most ±3.4028235e38");
    }

    /// Regression: an element with no properties and a count of 10^18 made the
    /// reader loop 10^18 times over nothing (a hang on a 200-byte file).
    #[test]
    fn propertyless_element_with_huge_count_does_not_hang() {
        for fmt in ["ascii", "binary_little_endian"] {
            let mut b = format!(
                "ply\nformat {fmt} 1.0\nelement junk 1000000000000000000\nelement vertex 1\n\
                 property float x\nproperty float y\nproperty float z\nend_header\n"
            )
            .into_bytes();
            if fmt == "ascii" {
                b.extend_from_slice(b"1 2 3\n");
            } else {
                for c in [1.0f32, 2.0, 3.0] {
                    b.extend_from_slice(&c.to_le_bytes());
                }
            }
            let m = parse_ply(&b, "t.ply").unwrap_or_else(|e| panic!("{fmt}: {e}"));
            assert_eq!(m.vertices, vec![[1.0, 2.0, 3.0]], "{fmt}");
        }
    }

    #[test]
    fn binary_errors_name_the_element() {
        let m = cube_like();
        let mut buf = Vec::new();
        write_ply(&mut buf, &m, PlyEncoding::BinaryLittleEndian).unwrap();
        let hdr = buf.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let mut bad = buf.clone();
        bad[hdr + 24 + 8..hdr + 24 + 16].copy_from_slice(&f64::NAN.to_le_bytes());
        let e = parse_ply(&bad, "b.ply").unwrap_err().to_string();
        assert!(e.contains("b.ply: vertex 1: non-finite"), "{e}");
        let e = parse_ply(&buf[..hdr + 24 * 2 + 3], "b.ply").unwrap_err().to_string();
        assert!(e.contains("b.ply: truncated: file ends in vertex 2 of 4"), "{e}");
        let mut bad = buf.clone();
        let f0 = hdr + 24 * 4;
        bad[f0 + 1..f0 + 5].copy_from_slice(&9u32.to_le_bytes());
        let e = parse_ply(&bad, "b.ply").unwrap_err().to_string();
        assert!(e.contains("b.ply: face 0: vertex index 9 out of range (4 vertices)"), "{e}");
    }
}
