//! Invariant checks for quad meshes used by the shape and dataset tests: pure quads,
//! valid indices, edge- and vertex-manifold, consistent orientation, no unreferenced or
//! coincident vertices; plus Euler characteristic, components and signed volume.
//! (A stand-in until the half-edge validator lands; it panics with a message naming
//! the offending element.)

#![allow(dead_code)]

use std::collections::HashMap;

use point2quad::mesh::poly::QuadMesh;

/// Counts of a checked mesh.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MeshStats {
    pub vertices: usize,
    pub edges: usize,
    pub faces: usize,
    pub boundary_edges: usize,
    pub components: usize,
}

impl MeshStats {
    /// V − E + F.
    pub fn euler(&self) -> i64 {
        self.vertices as i64 - self.edges as i64 + self.faces as i64
    }
}

fn find(p: &mut [usize], mut x: usize) -> usize {
    while p[x] != x {
        p[x] = p[p[x]];
        x = p[x];
    }
    x
}

/// Checks every invariant of a generated quad mesh; panics naming the first violation.
pub fn check_quad_mesh(m: &QuadMesh) -> MeshStats {
    let nv = m.vertices.len();
    assert!(!m.quads.is_empty(), "mesh has no faces");
    for (i, v) in m.vertices.iter().enumerate() {
        assert!(v.iter().all(|c| c.is_finite()), "vertex {i} not finite: {v:?}");
    }
    let mut used = vec![false; nv];
    // Directed edge → face; undirected edge → count.
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    let mut undirected: HashMap<(u32, u32), usize> = HashMap::new();
    for (fi, q) in m.quads.iter().enumerate() {
        for k in 0..4 {
            assert!((q[k] as usize) < nv, "face {fi} index {} out of range ({nv} vertices)", q[k]);
            for l in 0..k {
                assert_ne!(q[k], q[l], "face {fi} repeats vertex {}", q[k]);
            }
            used[q[k] as usize] = true;
        }
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            if let Some(other) = directed.insert((a, b), fi) {
                panic!("directed edge {a}->{b} used by faces {other} and {fi} (inconsistent orientation or non-manifold)");
            }
            *undirected.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    if let Some(v) = used.iter().position(|&u| !u) {
        panic!("vertex {v} is unreferenced");
    }
    let mut boundary = 0;
    for (&(a, b), &c) in &undirected {
        assert!(c == 1 || c == 2, "edge {a}-{b} has {c} faces");
        if c == 1 {
            boundary += 1;
        }
    }
    // Vertex manifold: the corners (wedges) at each vertex, joined across shared edges,
    // form a single fan.
    let mut wedges: Vec<Vec<(u32, u32)>> = vec![Vec::new(); nv];
    for q in &m.quads {
        for k in 0..4 {
            wedges[q[k] as usize].push((q[(k + 3) % 4], q[(k + 1) % 4]));
        }
    }
    for (v, w) in wedges.iter().enumerate() {
        let mut parent: Vec<usize> = (0..w.len()).collect();
        let mut by_nb: HashMap<u32, usize> = HashMap::new();
        for (i, &(p, n)) in w.iter().enumerate() {
            for x in [p, n] {
                if let Some(&j) = by_nb.get(&x) {
                    let (ri, rj) = (find(&mut parent, i), find(&mut parent, j));
                    parent[ri] = rj;
                } else {
                    by_nb.insert(x, i);
                }
            }
        }
        let roots = (0..w.len()).filter(|&i| find(&mut parent, i) == i).count();
        assert_eq!(roots, 1, "vertex {v} is non-manifold: its {} faces form {roots} fans", w.len());
    }
    // Coincident vertices: sweep along x with a tolerance relative to the bounding box.
    let tol = 1e-9 * bbox_diag(m);
    let mut order: Vec<usize> = (0..nv).collect();
    order.sort_by(|&a, &b| m.vertices[a][0].total_cmp(&m.vertices[b][0]));
    for i in 0..nv {
        for j in i + 1..nv {
            let (a, b) = (m.vertices[order[i]], m.vertices[order[j]]);
            if b[0] - a[0] > tol {
                break;
            }
            let d = ((0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>()).sqrt();
            assert!(d > tol, "vertices {} and {} coincide at {a:?}", order[i], order[j]);
        }
    }
    // Components over face adjacency.
    let mut parent: Vec<usize> = (0..nv).collect();
    for q in &m.quads {
        for k in 1..4 {
            let (a, b) = (find(&mut parent, q[0] as usize), find(&mut parent, q[k] as usize));
            parent[a] = b;
        }
    }
    let components = (0..nv).filter(|&i| find(&mut parent, i) == i).count();
    MeshStats {
        vertices: nv,
        edges: undirected.len(),
        faces: m.quads.len(),
        boundary_edges: boundary,
        components,
    }
}

/// Signed volume enclosed by a closed mesh (each quad split into two triangles);
/// positive for outward orientation.
pub fn signed_volume(m: &QuadMesh) -> f64 {
    let p = |i: u32| m.vertices[i as usize];
    let tri = |a: [f64; 3], b: [f64; 3], c: [f64; 3]| {
        (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))
            / 6.0
    };
    m.quads.iter().map(|q| tri(p(q[0]), p(q[1]), p(q[2])) + tri(p(q[0]), p(q[2]), p(q[3]))).sum()
}

/// Bounding-box diagonal.
pub fn bbox_diag(m: &QuadMesh) -> f64 {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for v in &m.vertices {
        for a in 0..3 {
            lo[a] = lo[a].min(v[a]);
            hi[a] = hi[a].max(v[a]);
        }
    }
    ((0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>()).sqrt()
}
