//! Robustness: damaged files (random truncations and byte flips) never panic and,
//! when they still parse, give a sane mesh; a table of malformed inputs gives
//! errors naming the file and the right line or element.

#[path = "common/io.rs"]
mod io_common;

use io_common::{check_sane, encode, poly_mesh, ENCODINGS};
use point2quad::io::mesh_io::{parse_mesh, read_mesh, MeshFormat, PlyEncoding};
use point2quad::io::points::{parse_points, read_points, PointFormat};
use point2quad::mesh::poly::PolyMesh;
use proptest::prelude::*;

fn point_format(f: MeshFormat) -> PointFormat {
    match f {
        MeshFormat::Obj => PointFormat::Obj,
        MeshFormat::Off => PointFormat::Off,
        MeshFormat::Ply => PointFormat::Ply,
    }
}

/// Parses damaged bytes as a mesh and as points; any Ok must be sane.
fn parse_damaged(bytes: &[u8], format: MeshFormat) -> Result<(), TestCaseError> {
    if let Ok(m) = parse_mesh(bytes, format, "dmg") {
        check_sane(&m).map_err(TestCaseError::fail)?;
    }
    if let Ok(p) = parse_points(bytes, point_format(format), "dmg") {
        prop_assert!(!p.is_empty() && p.iter().flatten().all(|c| c.is_finite()));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn truncations_never_panic(mesh in poly_mesh(), cut in 0.0..1.0f64) {
        for (format, enc, _) in ENCODINGS {
            let buf = encode(&mesh, format, enc);
            let at = ((buf.len() as f64) * cut) as usize;
            parse_damaged(&buf[..at], format)?;
            // A binary body has an exact length: any cut into it must be an error.
            if enc != PlyEncoding::Ascii && format == MeshFormat::Ply {
                let hdr = buf.windows(11).position(|w| w == b"end_header\n").map_or(0, |i| i + 11);
                let body_len = buf.len() - hdr;
                if at < buf.len() && (at > hdr || body_len > 0) {
                    prop_assert!(parse_mesh(&buf[..at], format, "cut").is_err(), "cut at {} of {}", at, buf.len());
                }
            }
        }
    }

    #[test]
    fn byte_flips_never_panic(
        mesh in poly_mesh(),
        flips in prop::collection::vec((0.0..1.0f64, 1u8..=255), 1..6),
    ) {
        for (format, enc, _) in ENCODINGS {
            let mut buf = encode(&mesh, format, enc);
            for &(pos, x) in &flips {
                let i = ((buf.len() as f64) * pos) as usize;
                if let Some(b) = buf.get_mut(i) {
                    *b ^= x;
                }
            }
            parse_damaged(&buf, format)?;
            let xyz = &buf[..];
            if let Ok(p) = parse_points(xyz, PointFormat::Xyz, "dmg") {
                prop_assert!(p.iter().flatten().all(|c| c.is_finite()));
            }
        }
    }

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        for format in [MeshFormat::Obj, MeshFormat::Off, MeshFormat::Ply] {
            parse_damaged(&bytes, format)?;
        }
        let _ = parse_points(&bytes, PointFormat::Xyz, "rnd");
    }

    /// Headers with random (often huge) counts must fail fast, not allocate them.
    #[test]
    fn lying_counts_are_errors(nv in 0u64..u64::from(u32::MAX), nf in 0u64..u64::from(u32::MAX)) {
        let off = format!("OFF\n{nv} {nf} 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
        let ok = nv == 3 && nf == 1;
        prop_assert_eq!(parse_mesh(off.as_bytes(), MeshFormat::Off, "c.off").is_ok(), ok);
        let ply = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\n\
             property float z\nelement face {nf}\nproperty list uchar int vertex_indices\nend_header\n"
        );
        let mut b = ply.into_bytes();
        for c in [0f32, 0., 0., 1., 0., 0., 0., 1., 0.] {
            b.extend(c.to_le_bytes());
        }
        b.push(3);
        for i in [0i32, 1, 2] {
            b.extend(i.to_le_bytes());
        }
        prop_assert_eq!(parse_mesh(&b, MeshFormat::Ply, "c.ply").is_ok(), ok);
    }
}

/// Malformed inputs across formats, through the public entry points: each error
/// must name the file and the line (or element).
#[test]
fn malformed_inputs_name_file_and_location() {
    let ply_head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
                    property double z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n";
    let mesh_cases: Vec<(MeshFormat, &str, String, &str)> = vec![
        (
            MeshFormat::Obj,
            "a.obj",
            "v 0 0 0\nv 1 0 0\n\nv 0 1 0\nf 1 2 0\n".into(),
            "a.obj:5: face 0: vertex index 0",
        ),
        (
            MeshFormat::Obj,
            "a.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 3 2 1\nf 1 2 9\n".into(),
            "a.obj:5: vertex index 9 out of range",
        ),
        (
            MeshFormat::Obj,
            "a.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1 2/2\n".into(),
            "a.obj:4: face 0: has 2 vertices",
        ),
        (MeshFormat::Obj, "a.obj", "# c\nv 0 0 1e999\n".into(), "a.obj:2: vertex 0: non-finite"),
        (
            MeshFormat::Obj,
            "a.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3x\n".into(),
            "a.obj:4: face 0: bad vertex index '3x'",
        ),
        (MeshFormat::Obj, "a.obj", "vn 0 0 1\n".into(), "a.obj: contains no vertices"),
        (
            MeshFormat::Off,
            "b.off",
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n".into(),
            "b.off:6: face 0: vertex index 3 out of range",
        ),
        (
            MeshFormat::Off,
            "b.off",
            "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n".into(),
            "b.off: truncated: file ends at face 1 of 2",
        ),
        (
            MeshFormat::Off,
            "b.off",
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 2 1 0\n".into(),
            "b.off:7: data after the last face",
        ),
        (
            MeshFormat::Off,
            "b.off",
            "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 z\n3 0 1 2\n".into(),
            "b.off:5: vertex 2: bad number 'z'",
        ),
        (MeshFormat::Off, "b.off", "4OFF\n3 1 0\n".into(), "b.off:1: '4OFF' has 4-D vertices"),
        (
            MeshFormat::Ply,
            "c.ply",
            format!("{ply_head}0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"),
            "c.ply:13: face 0: vertex index 7 out of range",
        ),
        (
            MeshFormat::Ply,
            "c.ply",
            format!("{ply_head}0 0 0\n1 0 0\n0 1 0\n"),
            "c.ply: truncated: file ends in face 0 of 1 declared",
        ),
        (
            MeshFormat::Ply,
            "c.ply",
            format!("{ply_head}0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n1 1 1\n"),
            "c.ply:14: data after the last element",
        ),
        (
            MeshFormat::Ply,
            "c.ply",
            format!("{ply_head}0 0 0\n1 0 NaN\n0 1 0\n3 0 1 2\n"),
            "c.ply:11: vertex 1: non-finite",
        ),
        (
            MeshFormat::Ply,
            "c.ply",
            "ply\nformat binary_middle_endian 1.0\nend_header\n".into(),
            "c.ply:2: unknown PLY format",
        ),
        (
            MeshFormat::Ply,
            "c.ply",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float z\nend_header\n1 2\n"
                .into(),
            "c.ply:3: element vertex has no property 'y'",
        ),
    ];
    for (format, name, src, want) in &mesh_cases {
        let e = parse_mesh(src.as_bytes(), *format, name).expect_err(want).to_string();
        assert!(e.contains(want), "got '{e}', want '{want}'");
    }
    let point_cases: &[(&str, &str)] = &[
        ("1 2 3\n4 5 6\n7 8\n", "p.xyz:3: point 2: needs 3 coordinates, found 2"),
        ("1 2 3\n# c\n4 5 six\n", "p.xyz:3: point 1: bad number 'six'"),
        ("1 2 3\n4 5 inf\n", "p.xyz:2: point 1: non-finite"),
        ("# nothing\n", "p.xyz: contains no points"),
    ];
    for (src, want) in point_cases {
        let e = parse_points(src.as_bytes(), PointFormat::Xyz, "p.xyz").expect_err(want).to_string();
        assert!(e.contains(want), "got '{e}', want '{want}'");
    }
}

/// Binary PLY errors name the element.
#[test]
fn binary_ply_errors_name_the_element() {
    let m = PolyMesh {
        vertices: (0..20).map(|i| [f64::from(i), 0.5, -1.0]).collect(),
        faces: vec![vec![0, 1, 2, 3]; 5],
    };
    for (enc, nan) in [
        (PlyEncoding::BinaryLittleEndian, f64::NAN.to_le_bytes()),
        (PlyEncoding::BinaryBigEndian, f64::INFINITY.to_be_bytes()),
    ] {
        let mut buf = Vec::new();
        point2quad::io::ply::write_ply(&mut buf, &m, enc).unwrap();
        let hdr = buf.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let at = hdr + 12 * 24 + 16; // vertex 12, z
        buf[at..at + 8].copy_from_slice(&nan);
        let e = parse_mesh(&buf, MeshFormat::Ply, "bin.ply").unwrap_err().to_string();
        assert!(e.contains("bin.ply: vertex 12: non-finite"), "{enc:?}: {e}");
        let e = parse_points(&buf, PointFormat::Ply, "bin.ply").unwrap_err().to_string();
        assert!(e.contains("bin.ply: vertex 12: non-finite"), "{enc:?}: {e}");
    }
}

/// Errors from files name the path; a missing file is an I/O error naming it.
#[test]
fn file_errors_name_the_path() {
    let dir = std::env::temp_dir().join(format!("p2q_io_robust_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("broken.off");
    std::fs::write(&p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n").unwrap();
    let e = read_mesh(&p).unwrap_err().to_string();
    assert!(e.contains(&format!("{}:6:", p.display())), "{e}");
    let e = read_points(&dir.join("missing.xyz")).unwrap_err().to_string();
    assert!(e.contains("missing.xyz"), "{e}");
    let e = read_mesh(&dir.join("x.stl")).unwrap_err().to_string();
    assert!(e.contains("x.stl") && e.contains(".obj .off .ply"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A leading UTF-8 byte-order mark (Windows editors write one) is skipped by every text
/// format: the points and faces read are those of the same file without it.
#[test]
fn a_leading_byte_order_mark_is_ignored() {
    let bom = |b: &[u8]| [&b"\xEF\xBB\xBF"[..], b].concat();
    let xyz = b"# cloud\n0 0 0\n1 0 0.5\n0 1 2\n".to_vec();
    let want = parse_points(&xyz, PointFormat::Xyz, "a").unwrap();
    assert_eq!(parse_points(&bom(&xyz), PointFormat::Xyz, "a").unwrap(), want);
    let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n".to_vec();
    let off = b"OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n".to_vec();
    for (bytes, format) in [(obj, MeshFormat::Obj), (off, MeshFormat::Off)] {
        let want = parse_mesh(&bytes, format, "a").unwrap();
        let got = parse_mesh(&bom(&bytes), format, "a").unwrap();
        assert_eq!((got.vertices, got.faces), (want.vertices, want.faces), "{format:?}");
    }
}
