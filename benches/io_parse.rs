//! Mesh parsing and writing speed. Prints `bench <name> <value> ms` lines (median
//! of 9 runs after a warm-up): a synthetic 160×160 quad grid (25,600 vertices,
//! 25,281 quads, random full-precision coordinates) in every format, and the large
//! shared meshes when ../shared/data/quads/large exists. On Linux each parse
//! figure also gets a `_cpu` line: the median CPU time of the thread (from
//! /proc/thread-self/schedstat), which stays meaningful on a loaded machine where
//! wall-clock time does not.

use point2quad::io::mesh_io::{parse_mesh, MeshFormat, PlyEncoding};
use point2quad::io::{obj, off, ply};
use point2quad::mesh::poly::PolyMesh;
use point2quad::rng::Rng;
use std::hint::black_box;
use std::time::Instant;

/// Median wall-clock and (where available) thread CPU milliseconds of `f`.
fn median_ms(mut f: impl FnMut()) -> (f64, Option<f64>) {
    f();
    let mut wall = Vec::new();
    let mut cpu = Vec::new();
    for _ in 0..9 {
        let c0 = thread_cpu_ns();
        let s = Instant::now();
        f();
        wall.push(s.elapsed().as_secs_f64() * 1e3);
        if let (Some(a), Some(b)) = (c0, thread_cpu_ns()) {
            cpu.push((b - a) as f64 * 1e-6);
        }
    }
    let med = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let cpu = if cpu.len() == wall.len() { Some(med(cpu)) } else { None };
    (med(wall), cpu)
}

/// Nanoseconds this thread has run on a CPU (Linux schedstat), if available.
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn report(name: &str, (wall, cpu): (f64, Option<f64>)) {
    println!("bench {name} {wall:.2} ms");
    if let Some(c) = cpu {
        println!("bench {name}_cpu {c:.2} ms");
    }
}

fn grid(n: u32) -> PolyMesh {
    let mut rng = Rng::new(0);
    let vertices = (0..n * n)
        .map(|_| [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)])
        .collect();
    let mut faces = Vec::new();
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let v = i * n + j;
            faces.push(vec![v, v + 1, v + n + 1, v + n]);
        }
    }
    PolyMesh { vertices, faces }
}

fn main() {
    let m = grid(160);
    let cases: [(&str, MeshFormat, PlyEncoding); 4] = [
        ("obj", MeshFormat::Obj, PlyEncoding::Ascii),
        ("off", MeshFormat::Off, PlyEncoding::Ascii),
        ("ply_ascii", MeshFormat::Ply, PlyEncoding::Ascii),
        ("ply_binary", MeshFormat::Ply, PlyEncoding::BinaryLittleEndian),
    ];
    for (name, format, enc) in cases {
        let mut buf = Vec::new();
        let write = |buf: &mut Vec<u8>| {
            buf.clear();
            match format {
                MeshFormat::Obj => obj::write_obj(buf, &m),
                MeshFormat::Off => off::write_off(buf, &m),
                MeshFormat::Ply => ply::write_ply(buf, &m, enc),
            }
            .expect("write to memory");
        };
        let w = median_ms(|| write(&mut buf));
        let r = median_ms(|| {
            black_box(parse_mesh(black_box(&buf), format, "bench").expect("parse"));
        });
        report(&format!("io_write_grid160_{name}"), w);
        report(&format!("io_parse_grid160_{name}"), r);
    }
    let large = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/quads/large"));
    let Ok(dir) = std::fs::read_dir(large) else {
        eprintln!("skipping the shared meshes: {} not found", large.display());
        return;
    };
    let mut files: Vec<_> = dir.filter_map(|e| e.ok().map(|e| e.path())).collect();
    files.sort();
    for p in files {
        let Ok(format) = MeshFormat::from_path(&p) else { continue };
        let bytes = std::fs::read(&p).expect("read shared mesh");
        let stem = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let r = median_ms(|| {
            black_box(parse_mesh(black_box(&bytes), format, "bench").expect("parse"));
        });
        report(&format!("io_parse_{stem}"), r);
    }
}
