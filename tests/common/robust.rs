//! Strategies for the robustness tests: coordinates that break naive arithmetic
//! (NaN, ±inf, ±f64::MAX, subnormals, any bit pattern), face soups whose faces have
//! any length (0 included) and indices past the end, and token soups for the text
//! parsers. Include with `#[path = "common/robust.rs"] mod robust_common;`.
#![allow(dead_code)]

use point2quad::mesh::poly::PolyMesh;
use proptest::prelude::*;

/// Any f64 a file or a caller could hand over, with the dangerous ones over-weighted.
pub fn wild_coord() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -3.0f64..3.0,
        2 => prop::sample::select(vec![
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::MAX,
            f64::MIN,
            1e300,
            -1e300,
            1e-300,
            5e-324,
            -5e-324,
            0.0,
            -0.0,
        ]),
        1 => any::<u64>().prop_map(f64::from_bits),
    ]
}

/// A face soup: 1..12 vertices with wild coordinates, faces of 0..7 indices that may
/// repeat and may point up to 3 past the last vertex.
pub fn wild_soup() -> impl Strategy<Value = PolyMesh> {
    (1usize..12).prop_flat_map(|nv| {
        (
            prop::collection::vec(prop::array::uniform3(wild_coord()), nv),
            prop::collection::vec(prop::collection::vec(0u32..(nv as u32 + 3), 0..7), 0..10),
        )
            .prop_map(|(vertices, faces)| PolyMesh { vertices, faces })
    })
}

/// Tokens the OBJ, OFF and PLY readers give meaning to, plus numbers that are
/// out of range, negative, non-finite or malformed, and a non-UTF-8 one.
pub const TOKENS: &[&str] = &[
    "v",
    "f",
    "vn",
    "vt",
    "#",
    "OFF",
    "COFF",
    "nOFF",
    "ply",
    "format",
    "ascii",
    "binary_little_endian",
    "1.0",
    "element",
    "vertex",
    "face",
    "junk",
    "property",
    "float",
    "double",
    "uchar",
    "int",
    "list",
    "x",
    "y",
    "z",
    "vertex_indices",
    "end_header",
    "comment",
    "nan",
    "inf",
    "-inf",
    "1e999",
    "-1",
    "0",
    "1",
    "2",
    "3",
    "4",
    "4294967295",
    "4294967296",
    "99999999999999999999",
    "1e308",
    "-0",
    "0.5",
    "1/2/3",
    "2//1",
    "-2",
    "\u{ff}",
    "",
    "3 0 1 2",
];

/// A text file made of `TOKENS`, optionally after a plausible header so that the
/// parser gets past its first line.
pub fn token_file() -> impl Strategy<Value = Vec<u8>> {
    let line = prop::collection::vec(prop::sample::select(TOKENS.to_vec()), 0..7).prop_map(|t| t.join(" "));
    let header = prop::sample::select(vec![
        "",
        "OFF\n",
        "OFF\n3 1 0\n",
        "ply\nformat ascii 1.0\n",
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n",
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty uchar x\nproperty uchar y\nproperty uchar z\nend_header\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\n",
    ]);
    (header, prop::collection::vec(line, 0..24)).prop_map(|(h, lines)| {
        let mut s = h.to_string();
        for l in lines {
            s.push_str(&l);
            s.push('\n');
        }
        // The non-UTF-8 token stands for a raw 0xff byte.
        s.replace('\u{ff}', "\u{1}").into_bytes().into_iter().map(|b| if b == 1 { 0xff } else { b }).collect()
    })
}
