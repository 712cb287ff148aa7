//! Every real quad mesh in ../shared/data/quads loads, with the vertex and face
//! counts SOURCES.csv lists, pure quads, indices in range. Skipped (with a
//! message) where the shared folder is absent.

use point2quad::io::mesh_io::read_mesh;
use point2quad::io::points::read_points;
use std::collections::HashMap;
use std::path::Path;

#[test]
fn all_shared_meshes_load_with_listed_counts() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/quads"));
    if !root.is_dir() {
        eprintln!("skipping: {} not found", root.display());
        return;
    }
    // SOURCES.csv lists the Thingi10K meshes twice: as `p2q/N.obj` with the counts
    // and as `thingi_N.obj` (the file name here) without; rows without counts are
    // provenance only.
    let csv = std::fs::read_to_string(root.join("SOURCES.csv")).expect("SOURCES.csv readable");
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("SOURCES.csv header").split(',').collect();
    assert_eq!(&header[..3], &["file", "V", "F"], "SOURCES.csv columns changed");
    let mut counts = HashMap::new();
    for line in lines {
        let cols: Vec<&str> = line.splitn(4, ',').collect();
        if cols.len() < 4 || cols[1].is_empty() {
            continue;
        }
        let name = match cols[0].strip_prefix("p2q/") {
            Some(n) => format!("thingi_{n}"),
            None => cols[0].to_string(),
        };
        let v: usize = cols[1].parse().expect("V column");
        let f: usize = cols[2].parse().expect("F column");
        counts.insert(name, (v, f));
    }
    let mut checked = 0;
    for dir in ["train", "eval", "large"] {
        let mut files: Vec<_> = std::fs::read_dir(root.join(dir))
            .expect("shared folder")
            .map(|e| e.expect("entry").path())
            .collect();
        files.sort();
        for path in files {
            let file = path.file_name().expect("file name").to_string_lossy().into_owned();
            let &(v, f) = counts.get(&file).unwrap_or_else(|| panic!("{file} has no counts in SOURCES.csv"));
            let m = read_mesh(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!((m.vertices.len(), m.faces.len()), (v, f), "{}", path.display());
            assert!(m.is_quad_only(), "{} is not pure quads", path.display());
            assert!(m.faces.iter().flatten().all(|&i| (i as usize) < v));
            let pts = read_points(&path).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(pts, m.vertices, "{}", path.display());
            checked += 1;
        }
    }
    assert_eq!(checked, 79, "SOURCES.csv the shared folders should hold 79 meshes");
}
