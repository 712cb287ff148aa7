//! Property tests: random meshes and point clouds survive a write → read round trip
//! in every format and encoding, bit-exactly (coordinates) and identically (faces).

#[path = "common/io.rs"]
mod io_common;

use io_common::{bits, encode, points, poly_mesh, ENCODINGS};
use point2quad::io::mesh_io::{parse_mesh, read_mesh, write_mesh_with, MeshFormat, WriteOptions};
use point2quad::io::points::{parse_points, read_points, write_points_xyz, write_xyz, PointFormat};
use point2quad::mesh::poly::PolyMesh;
use proptest::prelude::*;
use std::path::PathBuf;

fn scratch(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("p2q_io_props_{tag}_{}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn mesh_round_trips_in_memory(mesh in poly_mesh()) {
        for (format, enc, _) in ENCODINGS {
            let buf = encode(&mesh, format, enc);
            let back = parse_mesh(&buf, format, "mem").map_err(|e| TestCaseError::fail(format!("{format:?} {enc:?}: {e}")))?;
            prop_assert_eq!(bits(&back.vertices), bits(&mesh.vertices), "{:?} {:?}", format, enc);
            prop_assert_eq!(&back.faces, &mesh.faces, "{:?} {:?}", format, enc);
        }
    }

    #[test]
    fn mesh_vertices_read_as_points(mesh in poly_mesh()) {
        for (format, enc, _) in ENCODINGS {
            let buf = encode(&mesh, format, enc);
            let pf = match format {
                MeshFormat::Obj => PointFormat::Obj,
                MeshFormat::Off => PointFormat::Off,
                MeshFormat::Ply => PointFormat::Ply,
            };
            let pts = parse_points(&buf, pf, "mem").map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(bits(&pts), bits(&mesh.vertices));
        }
    }

    #[test]
    fn points_round_trip_in_memory(pts in points()) {
        let mut buf = Vec::new();
        write_xyz(&mut buf, &pts).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let back = parse_points(&buf, PointFormat::Xyz, "mem").map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bits(&back), bits(&pts));
    }
}

proptest! {
    // Through the file system (atomic writes); fewer cases, each touches the disk.
    #![proptest_config(ProptestConfig::with_cases(16))]

    #[test]
    fn mesh_and_points_round_trip_through_files(mesh in poly_mesh(), pts in points()) {
        let dir = scratch("files");
        for (i, (_, enc, ext)) in ENCODINGS.iter().enumerate() {
            let p = dir.join(format!("m{i}.{ext}"));
            write_mesh_with(&p, &mesh, &WriteOptions { ply_encoding: *enc }).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let back = read_mesh(&p).map_err(|e| TestCaseError::fail(e.to_string()))?;
            prop_assert_eq!(bits(&back.vertices), bits(&mesh.vertices));
            prop_assert_eq!(&back.faces, &mesh.faces);
        }
        let p = dir.join("p.xyz");
        write_points_xyz(&p, &pts).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let back = read_points(&p).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bits(&back), bits(&pts));
        // Only the written files remain: no temporary left behind.
        let n = std::fs::read_dir(&dir).map_err(|e| TestCaseError::fail(e.to_string()))?.count();
        prop_assert_eq!(n, ENCODINGS.len() + 1);
        std::fs::remove_dir_all(&dir).map_err(|e| TestCaseError::fail(e.to_string()))?;
    }
}

/// Renders `pts` as .xyz text with random separators, extra columns, comments and
/// blank lines; the parser must give exactly `pts` back.
fn messy_xyz(pts: &[[f64; 3]], style: &[(u8, u8, u8)]) -> String {
    let mut s = String::from("# generated\n");
    for (i, p) in pts.iter().enumerate() {
        let (sep, extra, junk) = style[i % style.len()];
        let sep = [" ", "\t", ",", " , ", "  "][sep as usize % 5];
        if junk % 3 == 0 {
            s.push_str("\n   \n# comment line\n");
        }
        s.push_str(&format!("{:e}{sep}{}{sep}{:?}", p[0], p[1], p[2]));
        for k in 0..extra % 4 {
            s.push_str(&format!("{sep}{}", f64::from(k) * 0.5));
        }
        if junk % 2 == 0 {
            s.push_str(" # trailing");
        }
        s.push_str(if junk % 5 == 0 { "\r\n" } else { "\n" });
    }
    s
}

/// Renders `mesh` as OBJ whose face indices use random forms (`i`, `i/t`,
/// `i/t/n`, `i//n`, negative relative indices) and vt/vn/s/o lines around; the
/// last two vertices come after the faces, so negative indices are resolved
/// against the count at the face's line. Faces using those two are left out.
fn messy_obj(mesh: &PolyMesh, forms: &[u8]) -> String {
    let mut s = String::from("mtllib x.mtl\no obj\n");
    let split = mesh.vertices.len().saturating_sub(2);
    let emit_v = |s: &mut String, p: &[f64; 3]| {
        s.push_str(&format!("v {:?} {:?} {:?} 1 0.5 0.25\nvt 0 0\nvn 0 0 1\n", p[0], p[1], p[2]))
    };
    for p in &mesh.vertices[..split] {
        emit_v(&mut s, p);
    }
    let mut k = 0;
    // Faces using the last vertices are left out (the caller expects that).
    for f in mesh.faces.iter().filter(|f| f.iter().all(|&i| (i as usize) < split)) {
        s.push('f');
        for &i in f {
            let form = forms[k % forms.len()] % 5;
            k += 1;
            let one = i + 1;
            let neg = i64::from(i) - split as i64;
            match form {
                0 => s.push_str(&format!(" {one}")),
                1 => s.push_str(&format!(" {one}/1")),
                2 => s.push_str(&format!(" {one}/1/1")),
                3 => s.push_str(&format!(" {one}//1")),
                _ => s.push_str(&format!(" {neg}")),
            }
        }
        s.push_str("\ns off\n");
    }
    for p in &mesh.vertices[split..] {
        emit_v(&mut s, p);
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn messy_xyz_parses_to_the_points(pts in points(), style in prop::collection::vec((0u8..5, 0u8..4, 0u8..30), 1..8)) {
        let text = messy_xyz(&pts, &style);
        let back = parse_points(text.as_bytes(), PointFormat::Xyz, "m.xyz").map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bits(&back), bits(&pts));
    }

    #[test]
    fn obj_index_forms_parse_to_the_mesh(mesh in poly_mesh(), forms in prop::collection::vec(0u8..5, 1..16)) {
        // Only faces that use the early vertices are emitted (see messy_obj).
        let split = mesh.vertices.len().saturating_sub(2);
        let expect_faces: Vec<Vec<u32>> = mesh.faces.iter().filter(|f| f.iter().all(|&i| (i as usize) < split)).cloned().collect();
        let text = messy_obj(&mesh, &forms);
        let back = parse_mesh(text.as_bytes(), MeshFormat::Obj, "m.obj").map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bits(&back.vertices), bits(&mesh.vertices));
        prop_assert_eq!(back.faces, expect_faces);
    }
}

/// Re-joins `text`'s lines with line ends drawn from `ends` in turn: `\n`, `\r\n`, a
/// lone `\r`, or `\r\r\n` (a doubled conversion).
fn mixed_line_ends(text: &str, ends: &[u8]) -> String {
    let mut out = String::new();
    for (i, line) in text.lines().enumerate() {
        out.push_str(line);
        out.push_str(["\n", "\r\n", "\r", "\r\r\n"][ends[i % ends.len()] as usize % 4]);
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Session 41's audit: a lone `\r` in a file with `\n` line ends joined two lines
    /// (the second point's values were read as extra columns of the first and dropped).
    /// Any mix of line ends now reads every point, in every text format.
    #[test]
    fn any_mix_of_line_ends_reads_every_point(pts in points(), ends in prop::collection::vec(0u8..4, 1..6)) {
        let mut xyz = Vec::new();
        write_xyz(&mut xyz, &pts).expect("in memory");
        let text = mixed_line_ends(&String::from_utf8(xyz).expect("utf-8"), &ends);
        let back = parse_points(text.as_bytes(), PointFormat::Xyz, "m.xyz").map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(bits(&back), bits(&pts));
        let mesh = PolyMesh { vertices: pts.clone(), faces: vec![] };
        for format in [MeshFormat::Obj, MeshFormat::Off] {
            let buf = encode(&mesh, format, point2quad::io::mesh_io::PlyEncoding::Ascii);
            let text = mixed_line_ends(&String::from_utf8(buf).expect("utf-8"), &ends);
            let back = parse_mesh(text.as_bytes(), format, "m").map_err(|e| TestCaseError::fail(format!("{format:?}: {e}")))?;
            prop_assert_eq!(bits(&back.vertices), bits(&pts), "{:?}", format);
        }
    }
}
