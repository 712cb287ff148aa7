//! Object File Format (OFF): headers `OFF`, `COFF`, `NOFF`, `CNOFF`, `STOFF`, …
//! (any of the `[ST][C][N]` prefixes; `4OFF` and `nOFF` with a dimension other
//! than 3 are refused), the non-standard `N OFF` first line found in the shared
//! data (read as `NOFF`), counts on the header line or the next, `#` comments
//! anywhere, extra columns (normals, colours, texture coordinates) ignored.
//! One vertex or face per line, as every writer we know does.

use super::mesh_io::check_writable;
use super::text::{self, coord, out_err, parse_i64, show, Lines, Tokens};
use crate::error::{Error, Result};
use crate::mesh::poly::PolyMesh;
use std::io::Write;

/// Parses an OFF mesh from memory; `name` stands for the file in error messages.
/// A face may repeat a vertex (it loads; later stages judge it).
///
/// # Errors
/// `Parse` naming `name` and the line for: a missing or unsupported header, bad
/// counts, a vertex line with fewer than 3 numbers, a bad or non-finite number, a
/// face with fewer than 3 vertices or fewer indices than its count, an index out of
/// range, a file that ends before the declared vertices and faces (naming which one
/// is missing), and data after them (the header declared fewer).
pub fn parse_off(bytes: &[u8], name: &str) -> Result<PolyMesh> {
    parse_off_with(bytes, name, true)
}

/// As [`parse_off`]; with `want_faces == false` reading stops after the vertices.
pub(crate) fn parse_off_with(bytes: &[u8], name: &str, want_faces: bool) -> Result<PolyMesh> {
    let bytes = &*text::cr_lines(bytes);
    // Lines holding data (not blank, not only a comment).
    let mut lines = Lines::new(bytes).filter(|(_, l)| Tokens::commented(l).next().is_some());
    let (hl, header) = lines.next().ok_or_else(|| Error::parse(name, 0, "empty file (no OFF header)"))?;
    let mut toks = Tokens::commented(header);
    let mut key = toks.next().unwrap_or(b"");
    if key == b"N" {
        // `N OFF`: seen in the wild for NOFF.
        key = b"NOFF";
        if toks.next() != Some(&b"OFF"[..]) {
            return Err(Error::parse(name, hl, format!("not an OFF header: '{}'", show(header))));
        }
    }
    let prefix = match key.strip_suffix(b"OFF") {
        Some(p) => p,
        None => return Err(Error::parse(name, hl, format!("not an OFF header: '{}'", show(header)))),
    };
    if !prefix.iter().all(|b| b"STCN4n".contains(b)) {
        return Err(Error::parse(name, hl, format!("unknown OFF header '{}'", show(key))));
    }
    if prefix.contains(&b'4') {
        return Err(Error::parse(
            name,
            hl,
            format!("'{}' has 4-D vertices; only 3-D is supported", show(key)),
        ));
    }
    // The rest of the header line, then the following lines, hold the numbers.
    let mut cl = hl;
    if prefix.contains(&b'n') {
        let (dl, dtok) = next_token(&mut toks, hl, &mut lines)
            .ok_or_else(|| Error::parse(name, hl, "nOFF header without a dimension"))?;
        if parse_i64(dtok) != Some(3) {
            return Err(Error::parse(name, dl, format!("dimension '{}' not supported (only 3)", show(dtok))));
        }
        cl = dl;
    }
    match toks.clone().next() {
        Some(b"BINARY") => return Err(Error::parse(name, cl, "binary OFF is not supported")),
        Some(_) => {}
        None => {
            let (l, t) = lines
                .next()
                .ok_or_else(|| Error::parse(name, cl, "file ends before the vertex/face counts"))?;
            toks = Tokens::commented(t);
            cl = l;
        }
    }
    let counts: Vec<&[u8]> = toks.collect();
    if counts.len() < 2 {
        return Err(Error::parse(name, cl, "expected the counts 'vertices faces [edges]'"));
    }
    // More than three numbers: the vertices were run on after the counts (a whole file
    // on one line); reported as such, not as a file truncated at vertex 0.
    if counts.len() > 3 {
        return Err(Error::parse(
            name,
            cl,
            format!(
                "the counts line holds {} value(s) after 'vertices faces edges'; \
                 each vertex and each face must be on its own line",
                counts.len() - 3
            ),
        ));
    }
    let count = |t: &[u8], what: &str| -> Result<usize> {
        match parse_i64(t).and_then(|v| usize::try_from(v).ok()) {
            Some(v) => Ok(v),
            _ => Err(Error::parse(name, cl, format!("bad {what} count '{}'", show(t)))),
        }
    };
    let nv = count(counts[0], "vertex")?;
    let nf = count(counts[1], "face")?;
    if nv > u32::MAX as usize {
        return Err(Error::parse(name, cl, format!("{nv} vertices is more than this reader supports")));
    }
    // Capacity from the data actually present, not from a count that may lie.
    let mut mesh = PolyMesh { vertices: Vec::with_capacity(nv.min(bytes.len() / 6)), faces: Vec::new() };
    for i in 0..nv {
        let (ln, line) = lines.next().ok_or_else(|| {
            Error::parse(name, 0, format!("truncated: file ends at vertex {i} of {nv} declared"))
        })?;
        let mut t = Tokens::commented(line);
        let mut p = [0.0; 3];
        for (axis, c) in p.iter_mut().enumerate() {
            let tok = t.next().ok_or_else(|| {
                Error::parse(name, ln, format!("vertex {i}: needs 3 coordinates, found {axis}"))
            })?;
            *c = coord(tok, name, ln, &format_args!("vertex {i}"))?;
        }
        mesh.vertices.push(p);
    }
    // The faces are read (and checked) even for a point cloud: a header whose vertex
    // count is wrong shows only there, as a face line read as a vertex or a vertex
    // line read as a face. Every error from here on also names the header.
    let hint = |e: Error| match e {
        Error::Parse { path, line, msg } => Error::Parse {
            path,
            line,
            msg: format!(
                "{msg} (the header on line {cl} declares {nv} vertices and {nf} faces; is a count wrong?)"
            ),
        },
        other => other,
    };
    let faces = parse_faces(&mut lines, name, nv, nf, want_faces, bytes.len()).map_err(hint)?;
    mesh.faces = faces;
    Ok(mesh)
}

/// The face section of an OFF file after its `nv` vertices: `nf` faces, then nothing.
/// Faces are kept only with `keep`.
fn parse_faces<'a>(
    lines: &mut impl Iterator<Item = (usize, &'a [u8])>,
    name: &str,
    nv: usize,
    nf: usize,
    keep: bool,
    n_bytes: usize,
) -> Result<Vec<Vec<u32>>> {
    let mut faces: Vec<Vec<u32>> = Vec::with_capacity(if keep { nf.min(n_bytes / 8) } else { 0 });
    for i in 0..nf {
        let (ln, line) = lines.next().ok_or_else(|| {
            Error::parse(name, 0, format!("truncated: file ends at face {i} of {nf} declared"))
        })?;
        let mut t = Tokens::commented(line);
        let ntok = t.next().unwrap_or(b"");
        let n = match parse_i64(ntok) {
            Some(n) if n >= 3 => usize::try_from(n)
                .map_err(|_| Error::parse(name, ln, format!("face {i}: vertex count {n} too large")))?,
            Some(n) => {
                return Err(Error::parse(name, ln, format!("face {i}: has {n} vertices, needs at least 3")))
            }
            None => {
                return Err(Error::parse(name, ln, format!("face {i}: bad vertex count '{}'", show(ntok))))
            }
        };
        let mut face = Vec::with_capacity(n.min(64));
        for k in 0..n {
            let tok = t.next().ok_or_else(|| {
                Error::parse(name, ln, format!("face {i}: declares {n} vertices but lists {k}"))
            })?;
            match parse_i64(tok) {
                Some(v) if v >= 0 && (v as u64) < nv as u64 => face.push(v as u32),
                Some(v) => {
                    return Err(Error::parse(
                        name,
                        ln,
                        format!("face {i}: vertex index {v} out of range ({nv} vertices)"),
                    ))
                }
                None => {
                    return Err(Error::parse(name, ln, format!("face {i}: bad vertex index '{}'", show(tok))))
                }
            }
        }
        // Anything after the indices is a colour; ignored.
        if keep {
            faces.push(face);
        }
    }
    if let Some((ln, _)) = lines.next() {
        return Err(Error::parse(name, ln, "data after the last face"));
    }
    Ok(faces)
}

/// The next token on the current line, else the first of the next data line.
fn next_token<'a>(
    toks: &mut Tokens<'a>,
    line: usize,
    lines: &mut impl Iterator<Item = (usize, &'a [u8])>,
) -> Option<(usize, &'a [u8])> {
    if let Some(t) = toks.next() {
        return Some((line, t));
    }
    let (l, text) = lines.next()?;
    *toks = Tokens::commented(text);
    toks.next().map(|t| (l, t))
}

/// Writes `mesh` as OFF (`OFF`, counts, `x y z` lines with round-trip-exact
/// coordinates, `n i0 … i(n-1)` face lines with 0-based indices).
///
/// # Errors
/// `InvalidInput` for a mesh that could not be read back (non-finite coordinate,
/// face with fewer than 3 vertices or an index out of range); `Io` from the writer.
pub fn write_off(w: &mut dyn Write, mesh: &PolyMesh) -> Result<()> {
    check_writable(mesh)?;
    write_off_unchecked(w, mesh).map_err(out_err)
}

fn write_off_unchecked(w: &mut dyn Write, mesh: &PolyMesh) -> std::io::Result<()> {
    writeln!(w, "OFF\n{} {} 0", mesh.vertices.len(), mesh.faces.len())?;
    for p in &mesh.vertices {
        text::write_xyz_line(w, *p)?;
    }
    for f in &mesh.faces {
        text::write_counted_face(w, f)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const QUAD: &str = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

    #[test]
    fn header_variants() {
        for head in [
            "OFF\n4 1 0\n",
            "OFF 4 1 0\n",
            "NOFF\n4 1\n",
            "N OFF\n4 1 4\n",
            "COFF\n# c\n\n4 1 0\n",
            "nOFF 3\n4 1 0\n",
            "nOFF\n3 4 1 0\n",
        ] {
            let src = format!("{head}{QUAD}");
            let m = parse_off(src.as_bytes(), "t.off").unwrap_or_else(|e| panic!("{head:?}: {e}"));
            assert_eq!(m.vertices.len(), 4, "{head:?}");
            assert_eq!(m.faces, vec![vec![0, 1, 2, 3]], "{head:?}");
        }
    }

    #[test]
    fn extra_columns_and_comments() {
        let src = b"# lead\nCNOFF\n3 1 0 # counts\n0 0 0 0 0 1 255 0 0 255\n1 0 0  0 0 1 1 1 1 1\n# mid\n0 1 0 0 0 1 0 0 0 0\n3 0 1 2 255 0 0\n\n# end\n";
        let m = parse_off(src, "t.off").unwrap();
        assert_eq!(m.vertices[1], [1.0, 0.0, 0.0]);
        assert_eq!(m.faces, vec![vec![0, 1, 2]]);
    }

    #[test]
    fn errors_name_file_and_line() {
        let cases: &[(&str, &str)] = &[
            ("4OFF\n1 0 0\n0 0 0 0\n", "t.off:1: '4OFF' has 4-D"),
            ("PLY\n", "t.off:1: not an OFF header"),
            ("XOFF\n", "t.off:1: unknown OFF header"),
            ("OFF\n4 x 0\n", "t.off:2: bad face count 'x'"),
            ("OFF\n4\n", "t.off:2: expected the counts"),
            (
                "OFF 3 0 0 0 0 0 1 0 0 0 1 0\n",
                "t.off:1: the counts line holds 9 value(s) after 'vertices faces edges'; each vertex",
            ),
            ("OFF\n5 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n", "t.off: truncated: file ends at vertex 4 of 5"),
            (
                "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n",
                "t.off: truncated: file ends at face 1 of 2",
            ),
            (
                "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n3 0 1 2\n",
                "t.off:8: data after the last face",
            ),
            (
                "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 4\n",
                "t.off:7: face 0: vertex index 4 out of range",
            ),
            (
                "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2\n",
                "t.off:7: face 0: declares 4 vertices but lists 3",
            ),
            ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 1\n", "t.off:7: face 0: has 2 vertices"),
            ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 nan 0\n0 1 0\n4 0 1 2 3\n", "t.off:5: vertex 2: non-finite"),
            ("OFF\n4 1 0\n0 0 0\n1 0 0\n1 1\n0 1 0\n4 0 1 2 3\n", "t.off:5: vertex 2: needs 3 coordinates"),
            ("OFF BINARY\n", "binary OFF is not supported"),
        ];
        for (src, want) in cases {
            let e = parse_off(src.as_bytes(), "t.off").unwrap_err().to_string();
            assert!(e.contains(want), "got '{e}', want '{want}'");
        }
    }

    /// Regression: a CR-only file was one line and failed as "truncated" although
    /// every vertex and face was there.
    #[test]
    fn cr_only_line_endings_read() {
        let m = parse_off(b"OFF\r3 1 0\r0 0 0\r1 0 0\r0 1 0\r3 0 1 2\r", "t.off").unwrap();
        assert_eq!((m.vertices.len(), m.faces.clone()), (3, vec![vec![0, 1, 2]]));
    }
}
