//! Shared helpers for the candidate tests: coverage of a ground-truth quad mesh by
//! the candidates of its vertex cloud, and small tie-free synthetic clouds.

#![allow(dead_code)]

use point2quad::pipeline::candidates::{generate, CandidateConfig, Candidates};
use point2quad::pipeline::frame::Frame;

/// Folder with the shared real meshes: `../shared/data/quads` next to the checkout
/// (or two levels up, where the checkout is a worktree under `wt/`); `None` when
/// absent, and the tests that need it skip.
pub fn quads_dir() -> Option<std::path::PathBuf> {
    [
        concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/quads"),
        concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/quads"),
    ]
    .iter()
    .map(std::path::PathBuf::from)
    .find(|p| p.join("train").is_dir())
}

/// Sorted vertex set of a quad.
pub fn key(q: &[u32; 4]) -> [u32; 4] {
    let mut k = *q;
    k.sort_unstable();
    k
}

/// Result of one coverage measurement.
#[derive(Clone, Copy, Debug, Default)]
pub struct Cov {
    pub faces: usize,
    pub covered: usize,
    pub candidates: usize,
    pub points: usize,
    pub secs: f64,
}

impl Cov {
    pub fn ratio(&self) -> f64 {
        self.covered as f64 / self.faces.max(1) as f64
    }
    pub fn per_point(&self) -> f64 {
        self.candidates as f64 / self.points.max(1) as f64
    }
    pub fn add(&mut self, o: &Cov) {
        self.faces += o.faces;
        self.covered += o.covered;
        self.candidates += o.candidates;
        self.points += o.points;
        self.secs += o.secs;
    }
}

/// Candidates of `points` (world coordinates, normalised by `Frame` first) and the
/// share of `faces` (indices into the first vertices of `points`) among them.
pub fn coverage(points: &[[f64; 3]], faces: &[[u32; 4]], cfg: &CandidateConfig) -> (Cov, Candidates) {
    let frame = Frame::fit(points).expect("test meshes are valid clouds");
    let local = frame.to_local_all(points);
    let t = std::time::Instant::now();
    let c = generate(&local, cfg).expect("valid cloud");
    let secs = t.elapsed().as_secs_f64();
    let mut keys: Vec<[u32; 4]> = c.quads.iter().map(key).collect();
    keys.sort_unstable();
    let covered = faces.iter().filter(|f| keys.binary_search(&key(f)).is_ok()).count();
    (Cov { faces: faces.len(), covered, candidates: c.quads.len(), points: points.len(), secs }, c)
}

/// A random, tie-free, gently curved height-field cloud: a jittered grid on
/// z = a·sin(x)·cos(y), shuffled. Good for properties (no distance ties).
pub fn wavy_cloud(nx: usize, ny: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = point2quad::rng::Rng::new(seed);
    let mut v = Vec::with_capacity(nx * ny);
    for y in 0..ny {
        for x in 0..nx {
            let px = x as f64 + 0.3 * (rng.f64() - 0.5);
            let py = y as f64 * 1.3 + 0.3 * (rng.f64() - 0.5);
            v.push([px, py, 1.5 * (0.4 * px).sin() * (0.3 * py).cos()]);
        }
    }
    rng.shuffle(&mut v);
    v
}

/// Proptest strategy: a tie-free wavy cloud (see [`wavy_cloud`]) of 6–14 × 6–14 points.
pub fn wavy_strategy() -> impl proptest::strategy::Strategy<Value = Vec<[f64; 3]>> {
    use proptest::prelude::*;
    (6usize..14, 6usize..14, any::<u64>()).prop_map(|(nx, ny, seed)| wavy_cloud(nx, ny, seed))
}

/// f32 copy of a cloud.
pub fn to_f32(points: &[[f64; 3]]) -> Vec<[f32; 3]> {
    points.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32]).collect()
}

/// Applies `x ↦ s·R·x + t`.
pub fn similarity(points: &[[f64; 3]], r: &[[f64; 3]; 3], s: f64, t: [f64; 3]) -> Vec<[f64; 3]> {
    points
        .iter()
        .map(|p| {
            let q = point2quad::math::mat_vec(r, *p);
            [s * q[0] + t[0], s * q[1] + t[1], s * q[2] + t[2]]
        })
        .collect()
}

/// Rᵀ·v for a row-major rotation.
pub fn rotate_back(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    let mut o = [0.0; 3];
    for (i, row) in r.iter().enumerate() {
        for a in 0..3 {
            o[a] += row[a] * v[i];
        }
    }
    o
}

/// A cyclic quad as a comparable value up to rotation (direction kept): rotated so
/// its smallest entry is first.
pub fn cyclic_canonical(q: [u32; 4]) -> [u32; 4] {
    let s = (0..4).min_by_key(|&i| q[i]).unwrap();
    [q[s], q[(s + 1) % 4], q[(s + 2) % 4], q[(s + 3) % 4]]
}

/// The quad meshes of `quads_dir()/sub` (sorted by name), or `None` when the data is absent.
pub fn mesh_files(sub: &str) -> Option<Vec<std::path::PathBuf>> {
    let dir = quads_dir()?.join(sub);
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("obj" | "off" | "ply")))
        .collect();
    v.sort();
    Some(v)
}

/// A shared mesh as a quad mesh.
pub fn load_quad_mesh(path: &std::path::Path) -> point2quad::mesh::poly::QuadMesh {
    let m = point2quad::io::mesh_io::read_mesh(path).expect("shared meshes load");
    m.to_quads().expect("shared meshes are pure quad")
}

/// The mesh's vertices followed by 10% noise points (`NoiseConfig::default()`, seeded).
pub fn noisy_cloud(mesh: &point2quad::mesh::poly::QuadMesh, seed: u64) -> Vec<[f64; 3]> {
    use point2quad::pipeline::noise::{noise_points, NoiseConfig};
    let mut rng = point2quad::rng::Rng::new(seed);
    let mut pts = mesh.vertices.clone();
    pts.extend(noise_points(mesh, &NoiseConfig::default(), &mut rng).expect("noise on a valid mesh"));
    pts
}

/// A jittered planar lattice of `nx` × `ny` points, 1 apart along x and `pitch` apart
/// along y, row by row (jitter up to ±0.02 in x and y and ±0.0005 in z, seed 5): cells
/// whose corners across the rows lie beyond a small k (the far completion's tests).
pub fn rows_lattice(nx: usize, ny: usize, pitch: f64) -> Vec<[f64; 3]> {
    let mut rng = point2quad::rng::Rng::new(5);
    (0..nx * ny)
        .map(|v| {
            let (x, y) = ((v % nx) as f64, (v / nx) as f64);
            [x + 0.04 * (rng.f64() - 0.5), pitch * y + 0.04 * (rng.f64() - 0.5), 0.001 * (rng.f64() - 0.5)]
        })
        .collect()
}
