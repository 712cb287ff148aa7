//! Property tests: random meshes and point clouds survive a write → read round trip
//! in every format and encoding, bit-exactly (coordinates) and identically (faces).

#[path = "common/io.rs"]
mod io_common;

use io_common::{bits, encode, points, poly_mesh, ENCODINGS};
use point2quad::io::mesh_io::{parse_mesh, read_mesh, write_mesh_with, MeshFormat, WriteOptions};
use point2quad::io::points::{parse_points, read_points, write_points_xyz, write_xyz, PointFormat};
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
