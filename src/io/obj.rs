//! Wavefront OBJ: `v` lines (extra columns such as `w` or colours ignored) and `f`
//! faces in every index form (`i`, `i/t`, `i/t/n`, `i//n`, negative = relative).
//! Everything else (vn, vt, g, o, s, usemtl, mtllib, l, p, comments) is skipped.

use super::mesh_io::check_writable;
use super::text::{self, coord, out_err, parse_i64, show, Lines, Tokens};
use crate::error::{Error, Result};
use crate::mesh::poly::PolyMesh;
use std::io::Write;

/// Parses an OBJ mesh from memory; `name` stands for the file in error messages.
///
/// A face may repeat a vertex (it loads; the metrics and the half-edge builder
/// judge it). Positive indices may refer to vertices defined later in the file;
/// negative ones count back from the vertices defined so far.
///
/// # Errors
/// `Parse` naming `name` and the line for: a `v` line with fewer than 3 numbers, a
/// bad or non-finite number, a face with fewer than 3 vertices, index 0, an index
/// out of range or unparsable (the face is named too), a texture or normal index
/// that is not an integer (`2/x`), a corner with more than three parts.
pub fn parse_obj(bytes: &[u8], name: &str) -> Result<PolyMesh> {
    parse_obj_with(bytes, name, true)
}

/// As [`parse_obj`]; with `want_faces == false` the `f` lines are not read at all.
pub(crate) fn parse_obj_with(bytes: &[u8], name: &str, want_faces: bool) -> Result<PolyMesh> {
    let bytes = &*text::cr_lines(bytes);
    let mut mesh = PolyMesh::default();
    // The largest positive (forward-resolvable) index seen, its line and its face,
    // checked at the end.
    let mut max_index: (u64, usize, usize) = (0, 0, 0);
    for (ln, raw) in Lines::new(bytes) {
        let mut toks = Tokens::commented(raw);
        let Some(key) = toks.next() else { continue };
        match key {
            b"v" => {
                let i = mesh.vertices.len();
                let mut p = [0.0; 3];
                for (axis, c) in p.iter_mut().enumerate() {
                    let tok = toks.next().ok_or_else(|| {
                        Error::parse(name, ln, format!("vertex {i}: needs 3 coordinates, found {axis}"))
                    })?;
                    *c = coord(tok, name, ln, &format_args!("vertex {i}"))?;
                }
                mesh.vertices.push(p);
            }
            b"f" if want_faces => {
                let nv = mesh.vertices.len() as i64;
                let mut face = Vec::with_capacity(4);
                for tok in toks {
                    let head = tok.split(|&b| b == b'/').next().unwrap_or(tok);
                    let idx = parse_i64(head).ok_or_else(|| {
                        Error::parse(
                            name,
                            ln,
                            format!("face {}: bad vertex index '{}'", mesh.faces.len(), show(tok)),
                        )
                    })?;
                    check_corner_tail(tok)
                        .map_err(|msg| Error::parse(name, ln, format!("face {}: {msg}", mesh.faces.len())))?;
                    let zero_based = match idx {
                        0 => {
                            return Err(Error::parse(
                                name,
                                ln,
                                format!("face {}: vertex index 0 (OBJ indices start at 1)", mesh.faces.len()),
                            ))
                        }
                        i if i > 0 => {
                            if i as u64 > max_index.0 {
                                max_index = (i as u64, ln, mesh.faces.len());
                            }
                            i - 1
                        }
                        i => nv + i,
                    };
                    if zero_based < 0 || zero_based > i64::from(u32::MAX) {
                        return Err(Error::parse(
                            name,
                            ln,
                            format!(
                                "face {}: vertex index {idx} out of range ({nv} vertices so far)",
                                mesh.faces.len()
                            ),
                        ));
                    }
                    face.push(zero_based as u32);
                }
                if face.len() < 3 {
                    return Err(Error::parse(
                        name,
                        ln,
                        format!("face {}: has {} vertices, needs at least 3", mesh.faces.len(), face.len()),
                    ));
                }
                mesh.faces.push(face);
            }
            _ => {}
        }
    }
    let nv = mesh.vertices.len() as u64;
    if max_index.0 > nv {
        return Err(Error::parse(
            name,
            max_index.1,
            format!(
                "vertex index {} out of range in face {} (the file has {nv} vertices)",
                max_index.0, max_index.2
            ),
        ));
    }
    Ok(mesh)
}

/// Checks the texture and normal parts of a face corner `v/vt/vn` (`1/2/3`, `1//3`,
/// `1/2`): each may be empty, a non-empty one must be an integer (negative counts
/// back, as for vertices), and there are at most three parts. They are not used,
/// but `2/x` is damage, not data. `Err` holds the reason.
fn check_corner_tail(tok: &[u8]) -> std::result::Result<(), String> {
    let mut parts = tok.split(|&b| b == b'/').skip(1);
    for kind in ["texture", "normal"] {
        match parts.next() {
            None => return Ok(()),
            Some(p) if p.is_empty() || parse_i64(p).is_some() => {}
            Some(p) => return Err(format!("bad {kind} index '{}' in '{}'", show(p), show(tok))),
        }
    }
    match parts.next() {
        None => Ok(()),
        Some(_) => Err(format!("'{}' has more than 3 parts (v/vt/vn)", show(tok))),
    }
}

/// Writes `mesh` as OBJ (`v x y z` lines with round-trip-exact coordinates, then
/// `f` lines with 1-based indices).
///
/// # Errors
/// `InvalidInput` for a mesh that could not be read back (non-finite coordinate,
/// face with fewer than 3 vertices or an index out of range); `Io` from the writer.
pub fn write_obj(w: &mut dyn Write, mesh: &PolyMesh) -> Result<()> {
    check_writable(mesh)?;
    write_obj_unchecked(w, mesh).map_err(out_err)
}

fn write_obj_unchecked(w: &mut dyn Write, mesh: &PolyMesh) -> std::io::Result<()> {
    for p in &mesh.vertices {
        w.write_all(b"v ")?;
        text::write_xyz_line(w, *p)?;
    }
    for f in &mesh.faces {
        w.write_all(b"f")?;
        for &i in f {
            write!(w, " {}", u64::from(i) + 1)?;
        }
        w.write_all(b"\n")?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_all_face_forms_and_ignores_the_rest() {
        let src = b"# comment\nmtllib a.mtl\no thing\nv 0 0 0 1 0.5 0.2\nv 1 0 0\r\nv 1 1 0\nv 0 1 0\n\
                    vt 0 0\nvn 0 0 1\ng grp\ns off\nusemtl m\nf 1 2 3 4\nf 1/1/1 2/2/1 3/3/1\n\
                    f 1//1 3//1 4//1\nf -4 -3 -2 -1 # trailing comment\nl 1 2\n";
        let m = parse_obj(src, "t.obj").unwrap();
        assert_eq!(m.vertices.len(), 4);
        assert_eq!(m.vertices[0], [0.0, 0.0, 0.0]);
        assert_eq!(m.faces, vec![vec![0, 1, 2, 3], vec![0, 1, 2], vec![0, 2, 3], vec![0, 1, 2, 3]]);
    }

    #[test]
    fn forward_references_and_repeated_vertices_load() {
        let m = parse_obj(b"f 1 2 3 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n", "t.obj").unwrap();
        assert_eq!(m.faces, vec![vec![0, 1, 2, 2]]);
    }

    #[test]
    fn errors_name_file_and_line() {
        let cases: &[(&[u8], &str)] = &[
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "t.obj:4: face 0: vertex index 0"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "t.obj:4: vertex index 4 out of range in face 0"),
            (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -4\n", "t.obj:4: face 0: vertex index -4 out of range"),
            (b"v 0 0 0\nv 1 0 0\nf 1 2\n", "t.obj:3: face 0: has 2 vertices"),
            (b"v 0 0\n", "t.obj:1: vertex 0: needs 3 coordinates, found 2"),
            (b"v 0 0 0\nv 0 x 0\n", "t.obj:2: vertex 1: bad number 'x'"),
            (b"v 0 0 0\nv 0 0 inf\n", "t.obj:2: vertex 1: non-finite"),
            (b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 a 3\n", "t.obj:4: face 0: bad vertex index 'a'"),
        ];
        for (src, want) in cases {
            let e = parse_obj(src, "t.obj").unwrap_err().to_string();
            assert!(e.contains(want), "got '{e}', want '{want}'");
        }
    }

    /// Regression: a file with classic Mac line endings (CR only) read as one line,
    /// so only its first vertex loaded and its faces were silently dropped.
    #[test]
    fn cr_only_line_endings_keep_every_line() {
        let m = parse_obj(b"v 0 0 0\rv 1 0 0\rv 1 1 0\rv 0 1 0\rf 1 2 3 4\r", "t.obj").unwrap();
        assert_eq!((m.vertices.len(), m.faces.clone()), (4, vec![vec![0, 1, 2, 3]]));
        let e = parse_obj(b"v 0 0 0\rv 1 x 0\r", "t.obj").unwrap_err().to_string();
        assert!(e.contains("t.obj:2: vertex 1: bad number 'x'"), "{e}");
    }
}
