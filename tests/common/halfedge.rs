//! Shared builders for the mesh tests: small quad meshes with known topology (open grid,
//! closed box, voxel torus, genus-2 plate), soups made from them, and face-set helpers.
#![allow(dead_code)]

use std::collections::HashMap;

use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes;
use point2quad::rng::Rng;

/// A test mesh: positions, quads, and what its topology must be.
pub struct TestMesh {
    pub name: &'static str,
    pub positions: Vec<[f64; 3]>,
    pub quads: Vec<[u32; 4]>,
    pub closed: bool,
    pub genus: usize,
}

/// An n×m grid of unit quads in the plane z = 0 (open, a disk); vertex (i, j) is
/// (n + 1) j + i.
pub fn grid(n: u32, m: u32) -> TestMesh {
    let g = shapes::grid(n as usize, m as usize, n as f64, m as f64);
    TestMesh { name: "grid", positions: g.vertices, quads: g.quads, closed: false, genus: 0 }
}

/// The outer surface of a set of unit voxels (face-connected, no checkerboard contacts),
/// each boundary face an outward-oriented quad on the integer lattice.
pub fn voxels(name: &'static str, cells: &[[i32; 3]], genus: usize) -> TestMesh {
    let filled: std::collections::HashSet<[i32; 3]> = cells.iter().copied().collect();
    let mut ids: HashMap<[i32; 3], u32> = HashMap::new();
    let mut positions = Vec::new();
    let mut quads = Vec::new();
    let mut vid = |p: [i32; 3], positions: &mut Vec<[f64; 3]>| {
        *ids.entry(p).or_insert_with(|| {
            positions.push([p[0] as f64, p[1] as f64, p[2] as f64]);
            positions.len() as u32 - 1
        })
    };
    for c in cells {
        for axis in 0..3 {
            for dir in [-1i32, 1] {
                let mut nb = *c;
                nb[axis] += dir;
                if filled.contains(&nb) {
                    continue;
                }
                // The face square at offset (dir + 1) / 2 along `axis`, spanned by the two
                // other axes u, v; counter-clockwise about the outward normal.
                let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
                let mut base = *c;
                base[axis] += (dir + 1) / 2;
                let corner = |du: i32, dv: i32| {
                    let mut p = base;
                    p[u] += du;
                    p[v] += dv;
                    p
                };
                let mut q = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
                if dir < 0 {
                    q.reverse();
                }
                quads.push(q.map(|p| vid(p, &mut positions)));
            }
        }
    }
    TestMesh { name, positions, quads, closed: true, genus }
}

/// A closed box of 2×2×2 voxels (genus 0, 24 quads).
pub fn box_mesh() -> TestMesh {
    let mut cells = Vec::new();
    for x in 0..2 {
        for y in 0..2 {
            for z in 0..2 {
                cells.push([x, y, z]);
            }
        }
    }
    voxels("box", &cells, 0)
}

/// A 3×3 ring of voxels, one thick (genus 1).
pub fn torus() -> TestMesh {
    let cells: Vec<[i32; 3]> =
        (0..3).flat_map(|x| (0..3).map(move |y| [x, y, 0])).filter(|c| *c != [1, 1, 0]).collect();
    voxels("torus", &cells, 1)
}

/// A 5×3 plate with two holes, one voxel thick (genus 2).
pub fn genus2() -> TestMesh {
    let cells: Vec<[i32; 3]> = (0..5)
        .flat_map(|x| (0..3).map(move |y| [x, y, 0]))
        .filter(|c| *c != [1, 1, 0] && *c != [3, 1, 0])
        .collect();
    voxels("genus2", &cells, 2)
}

/// A test mesh from a generated [`QuadMesh`]; closedness and genus by brute force over a
/// map of undirected edges (independent of the half-edge code).
pub fn from_shape(name: &'static str, q: QuadMesh) -> TestMesh {
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for f in &q.quads {
        for i in 0..4 {
            let (a, b) = (f[i], f[(i + 1) % 4]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let closed = edges.values().all(|&c| c == 2);
    let used: std::collections::HashSet<u32> = q.quads.iter().flatten().copied().collect();
    let chi = used.len() as i64 - edges.len() as i64 + q.quads.len() as i64;
    // Generated closed shapes are one connected surface: genus = (2 − χ)/2.
    let genus = if closed { ((2 - chi) / 2) as usize } else { 0 };
    TestMesh { name, positions: q.vertices, quads: q.quads, closed, genus }
}

/// The suite: open grid and tube, closed cube-sphere (valence-3 corners), torus, a random
/// voxel cage (genus 3 with this seed), the genus-2 plate.
pub fn suite() -> Vec<TestMesh> {
    let mut rng = Rng::new(21);
    vec![
        from_shape("grid", shapes::grid(5, 4, 1.0, 0.8)),
        from_shape("tube", shapes::cylinder(8, 3, 1.0, 1.0, false)),
        from_shape("cube_sphere", shapes::cube_sphere(3)),
        from_shape("torus", shapes::torus(8, 6, 2.0, 0.7)),
        from_shape("voxel_cage", shapes::voxel_cage(&mut rng, [5, 5, 3], 0.5)),
        genus2(),
    ]
}

/// A face's vertex set, sorted (orientation- and rotation-free identity).
pub fn key(f: [u32; 4]) -> [u32; 4] {
    let mut k = f;
    k.sort_unstable();
    k
}

/// The sorted keys of a mesh's live faces.
pub fn mesh_keys(m: &HalfedgeMesh) -> Vec<[u32; 4]> {
    let mut v: Vec<[u32; 4]> = m.faces().map(|f| key(m.face_vertices(f).map(|v| v.0))).collect();
    v.sort_unstable();
    v
}

/// Whether `a` is `b` up to rotation (same orientation).
pub fn same_cycle(a: [u32; 4], b: [u32; 4]) -> bool {
    (0..4).any(|k| (0..4).all(|i| a[(i + k) % 4] == b[i]))
}

/// Reverses a quad's orientation.
pub fn reversed(f: [u32; 4]) -> [u32; 4] {
    [f[0], f[3], f[2], f[1]]
}

/// A soup from a ground-truth mesh: drops a share of its faces, adds wrong quads over its
/// vertices (random, overlapping, duplicated, reversed, fins), shuffles; returns faces and
/// probabilities (true faces tend to score higher, with overlap).
pub fn random_soup(m: &TestMesh, rng: &mut Rng, drop: f64, wrong: usize) -> (Vec<[u32; 4]>, Vec<f32>) {
    let nv = m.positions.len();
    let mut faces: Vec<([u32; 4], f32)> = Vec::new();
    for &f in &m.quads {
        if rng.f64() >= drop {
            faces.push((f, 0.5 + 0.5 * rng.f32()));
        }
    }
    for _ in 0..wrong {
        let g = m.quads[rng.below(m.quads.len())];
        let f = match rng.below(5) {
            // Four random vertices (crossing, possibly degenerate).
            0 => [0; 4].map(|_| rng.below(nv) as u32),
            // Overlapping: one corner moved to a random vertex.
            1 => {
                let mut f = g;
                f[rng.below(4)] = rng.below(nv) as u32;
                f
            }
            2 => g,
            3 => reversed(g),
            // A fin on one of g's edges.
            _ => {
                let i = rng.below(4);
                [g[i], g[(i + 1) % 4], rng.below(nv) as u32, rng.below(nv) as u32]
            }
        };
        faces.push((f, 0.7 * rng.f32()));
    }
    rng.shuffle(&mut faces);
    (faces.iter().map(|x| x.0).collect(), faces.iter().map(|x| x.1).collect())
}

/// The shared mesh folder (`../shared/data/quads/<sub>`), or `None` (with a message) when
/// it is absent so that the caller can skip.
pub fn shared_meshes(sub: &str) -> Option<Vec<std::path::PathBuf>> {
    // From the main checkout the data is at ../shared; from a worktree under wt/, ../../shared.
    let main = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/quads"));
    let wt = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/quads"));
    let dir = if main.is_dir() { main } else { wt }.join(sub);
    let Ok(rd) = std::fs::read_dir(&dir) else {
        eprintln!("skipping: {} not found", dir.display());
        return None;
    };
    let mut v: Vec<_> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("obj" | "off" | "ply")))
        .collect();
    v.sort();
    Some(v)
}
