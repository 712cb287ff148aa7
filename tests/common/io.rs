//! Proptest strategies and helpers for the I/O tests: random polygon meshes and
//! point clouds with awkward coordinates (negative zero, subnormals, extremes),
//! and a validator for whatever a parser returns.

#![allow(dead_code)]

use point2quad::io::mesh_io::{MeshFormat, PlyEncoding};
use point2quad::io::{obj, off, ply};
use point2quad::mesh::poly::PolyMesh;
use proptest::prelude::*;

/// Every way a mesh can be written: (format, PLY encoding, file extension).
pub const ENCODINGS: [(MeshFormat, PlyEncoding, &str); 5] = [
    (MeshFormat::Obj, PlyEncoding::Ascii, "obj"),
    (MeshFormat::Off, PlyEncoding::Ascii, "off"),
    (MeshFormat::Ply, PlyEncoding::Ascii, "ply"),
    (MeshFormat::Ply, PlyEncoding::BinaryLittleEndian, "ply"),
    (MeshFormat::Ply, PlyEncoding::BinaryBigEndian, "ply"),
];

/// A finite f64 that is hard to print: special values, any finite bit pattern, or
/// an ordinary coordinate.
pub fn coord() -> impl Strategy<Value = f64> {
    use proptest::num::f64 as F;
    prop_oneof![
        2 => prop::sample::select(vec![
            0.0,
            -0.0,
            5e-324,
            -5e-324,
            f64::MIN_POSITIVE,
            -2.225073858507201e-308,
            1e300,
            -1e-300,
            f64::MAX,
            f64::MIN,
            0.1,
            1.0 / 3.0,
            9_999_999_999_999_998.0,
            1e16,
            1e-5,
            9.99999999999e-6,
        ]),
        3 => F::NORMAL | F::SUBNORMAL | F::ZERO | F::POSITIVE | F::NEGATIVE,
        3 => -1e3..1e3f64,
    ]
}

/// A random polygon mesh: 1–40 vertices, 0–30 faces of 3–8 vertices (repeats allowed).
pub fn poly_mesh() -> impl Strategy<Value = PolyMesh> {
    prop::collection::vec([coord(), coord(), coord()], 1..40).prop_flat_map(|vertices| {
        let n = vertices.len() as u32;
        let faces = prop::collection::vec(prop::collection::vec(0..n, 3..9), 0..30);
        (Just(vertices), faces).prop_map(|(vertices, faces)| PolyMesh { vertices, faces })
    })
}

/// A random point cloud of 1–60 points.
pub fn points() -> impl Strategy<Value = Vec<[f64; 3]>> {
    prop::collection::vec([coord(), coord(), coord()], 1..60)
}

/// Writes `mesh` in memory in the given format/encoding.
pub fn encode(mesh: &PolyMesh, format: MeshFormat, enc: PlyEncoding) -> Vec<u8> {
    let mut buf = Vec::new();
    match format {
        MeshFormat::Obj => obj::write_obj(&mut buf, mesh),
        MeshFormat::Off => off::write_off(&mut buf, mesh),
        MeshFormat::Ply => ply::write_ply(&mut buf, mesh, enc),
    }
    .expect("writing a valid mesh to memory");
    buf
}

/// Coordinates as bit patterns, so that -0.0 ≠ 0.0 in comparisons.
pub fn bits(v: &[[f64; 3]]) -> Vec<[u64; 3]> {
    v.iter().map(|p| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()]).collect()
}

/// What every successfully parsed mesh must satisfy, whatever the input.
pub fn check_sane(m: &PolyMesh) -> Result<(), String> {
    if m.vertices.is_empty() {
        return Err("Ok with no vertices".into());
    }
    if let Some(p) = m.vertices.iter().find(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(format!("non-finite vertex {p:?} accepted"));
    }
    for (i, f) in m.faces.iter().enumerate() {
        if f.len() < 3 {
            return Err(format!("face {i} with {} vertices accepted", f.len()));
        }
        if f.iter().any(|&v| v as usize >= m.vertices.len()) {
            return Err(format!("face {i} {f:?} out of range of {} vertices", m.vertices.len()));
        }
    }
    Ok(())
}
