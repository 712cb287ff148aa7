//! Coarsens quad meshes by chord collapse (`mesh::coarsen`) and prints what changed:
//! faces, vertices, Euler characteristic, and the mean angle between the normals of
//! faces sharing an edge (how much the mesh bends from one face to the next).
//! A measurement and inspection tool; asserts nothing.
//!
//! ```text
//! cargo run --release --example coarsen_mesh -- [--fraction F] [--seed S] [--out DIR] MESH...
//! ```

use point2quad::io::mesh_io::{read_mesh, write_mesh};
use point2quad::mesh::coarsen::{coarsen, CoarsenConfig};
use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::{PolyMesh, QuadMesh};
use point2quad::rng::Rng;
use std::collections::HashMap;
use std::path::PathBuf;

fn bend_deg(m: &QuadMesh) -> f64 {
    let n: Vec<Option<[f64; 3]>> = m
        .quads
        .iter()
        .map(|q| {
            let p = q.map(|v| m.vertices[v as usize]);
            let a = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
            let b = [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]];
            let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
            let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
            (l > 0.0).then(|| [c[0] / l, c[1] / l, c[2] / l])
        })
        .collect();
    let mut by_edge: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (f, q) in m.quads.iter().enumerate() {
        for i in 0..4 {
            let (a, b) = (q[i], q[(i + 1) % 4]);
            by_edge.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let (mut s, mut k) = (0.0, 0usize);
    for fs in by_edge.values() {
        if let [f, g] = fs[..] {
            if let (Some(a), Some(b)) = (n[f], n[g]) {
                let d = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0);
                s += d.acos().to_degrees();
                k += 1;
            }
        }
    }
    s / k.max(1) as f64
}

fn euler(m: &QuadMesh) -> i64 {
    HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).map(|h| h.euler_characteristic()).unwrap_or(i64::MIN)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let mut cfg = CoarsenConfig::default();
    let mut seed = 0u64;
    let mut out: Option<PathBuf> = None;
    let mut files = Vec::new();
    while let Some(a) = args.next() {
        match a.as_str() {
            "--fraction" => cfg.face_fraction = args.next().unwrap().parse().unwrap(),
            "--seed" => seed = args.next().unwrap().parse().unwrap(),
            "--out" => out = Some(PathBuf::from(args.next().unwrap())),
            _ => files.push(PathBuf::from(a)),
        }
    }
    for path in files {
        let m = read_mesh(&path).unwrap().to_quads().unwrap();
        let t = std::time::Instant::now();
        let c = coarsen(&m, &cfg, &mut Rng::new(seed));
        let ms = t.elapsed().as_secs_f64() * 1e3;
        println!(
            "{}\tfaces {} -> {} ({:.2})\tverts {} -> {}\teuler {} -> {}\tbend {:.1} -> {:.1} deg\t{:.0} ms",
            path.file_stem().unwrap().to_string_lossy(),
            m.quads.len(),
            c.quads.len(),
            c.quads.len() as f64 / m.quads.len() as f64,
            m.vertices.len(),
            c.vertices.len(),
            euler(&m),
            euler(&c),
            bend_deg(&m),
            bend_deg(&c),
            ms
        );
        if let Some(dir) = &out {
            let poly = PolyMesh {
                vertices: c.vertices.clone(),
                faces: c.quads.iter().map(|q| q.to_vec()).collect(),
            };
            let name = path.file_stem().unwrap().to_string_lossy().to_string();
            write_mesh(&dir.join(format!("{name}.obj")), &poly).unwrap();
        }
    }
}
