//! Coarsening a quad mesh by chord collapse (session 10; training data, not the
//! reconstruction).
//!
//! A *chord* (poly-chord) is a strip of quads, each entered through one side and left
//! through the opposite one, running until it meets the border or closes on itself. Its
//! *rungs* are the edges it crosses. Collapsing it merges the two ends of every rung into
//! one vertex at the rung's midpoint: the strip's quads vanish and the two edges that ran
//! along each of them become one. The result is again a pure-quad mesh with the same
//! Euler characteristic (V falls by the rungs, E by rungs + strip faces, F by the strip
//! faces), the same border loops, and fewer, larger faces that bend more from one to the
//! next — what a coarse mesh of an organic shape looks like, made from a real mesh's own
//! structure instead of a synthetic bump.
//!
//! [`coarsen`] collapses random chords, never two neighbouring ones in one pass (so the
//! resolution halves evenly instead of one region shrinking to needles), refusing any
//! collapse that would break the manifold (checked by [`validate`]), leave an inner
//! vertex with fewer than three faces, or bend a face it changes out of shape.

use std::collections::{HashMap, HashSet};

use super::halfedge::HalfedgeMesh;
use super::hole_fill::quad_normal;
use super::poly::QuadMesh;
use super::quality::quad_shape;
use super::validate::validate;
use crate::math::{dot, norm, sub};
use crate::rng::Rng;

/// Settings of [`coarsen`].
#[derive(Clone, Debug, PartialEq)]
pub struct CoarsenConfig {
    /// Stop once at most this share of the input's faces is left.
    pub face_fraction: f64,
    /// A face a collapse changes must keep a scaled Jacobian of at least
    /// `min(this, its value before)`.
    pub min_scaled_jacobian: f64,
    /// ... and its unit normal must stay within this cosine of its normal before.
    pub min_normal_dot: f64,
    /// Only chords whose faces are at most this elongated across the strip are
    /// collapsed: mean over the strip of (sum of the two rungs) / (sum of the two sides).
    /// Collapsing a strip widens its neighbours across it by half a rung, so a bound near
    /// 1 takes the short way first and keeps the coarse faces near square, where random
    /// strips would stack up in one direction and leave needles.
    pub max_aspect: f64,
    /// A pass ends after this many chords in a row could not be collapsed.
    pub max_misses: usize,
    /// At most this many passes (each clears the "next to a collapsed chord" marks).
    pub max_passes: usize,
}

impl Default for CoarsenConfig {
    fn default() -> Self {
        CoarsenConfig {
            face_fraction: 0.25,
            min_scaled_jacobian: 0.2,
            min_normal_dot: 0.5,
            max_aspect: 1.1,
            max_misses: 256,
            max_passes: 8,
        }
    }
}

/// Undirected edge key.
fn key(a: u32, b: u32) -> (u32, u32) {
    if a < b {
        (a, b)
    } else {
        (b, a)
    }
}

/// Undirected edge → the (face, side) pairs holding it; side `i` is the edge from corner
/// `i` to corner `i + 1`.
pub type EdgeMap = HashMap<(u32, u32), Vec<(u32, u8)>>;

/// The [`EdgeMap`] of `quads`.
pub fn edge_map(quads: &[[u32; 4]]) -> EdgeMap {
    let mut m: EdgeMap = HashMap::with_capacity(quads.len() * 2);
    for (f, q) in quads.iter().enumerate() {
        for i in 0..4 {
            m.entry(key(q[i], q[(i + 1) % 4])).or_default().push((f as u32, i as u8));
        }
    }
    m
}

/// The chord through face `f` that crosses its sides `side` and `side + 2`, as (face,
/// side) pairs: the side is one of the two rungs of that face (the other is side + 2).
/// `None` when the chord crosses itself (visits a face twice other than by closing), or
/// meets a non-manifold edge.
///
/// # Panics
/// If `f` is not a face of `quads`, or `edges` is not `quads`' [`edge_map`].
pub fn chord(quads: &[[u32; 4]], edges: &EdgeMap, f: usize, side: usize) -> Option<Vec<(usize, usize)>> {
    let side = side % 4;
    let mut seen: HashSet<usize> = HashSet::new();
    seen.insert(f);
    let mut forward = vec![(f, side)];
    // Walks from (face, exit side) across the rungs; returns whether it came back to `f`
    // through `side` (a closed chord).
    let mut walk = |mut g: usize, mut exit: usize, out: &mut Vec<(usize, usize)>| -> Option<bool> {
        loop {
            let q = quads[g];
            let (a, b) = (q[exit], q[(exit + 1) % 4]);
            let holders = edges.get(&key(a, b))?;
            if holders.len() > 2 {
                return None;
            }
            let Some(&(h, t)) = holders.iter().find(|&&(h, _)| h as usize != g) else {
                return Some(false); // the border
            };
            let (h, t) = (h as usize, t as usize);
            if h == f {
                return if t == side || t == (side + 2) % 4 { Some(true) } else { None };
            }
            if !seen.insert(h) {
                return None;
            }
            out.push((h, t));
            g = h;
            exit = (t + 2) % 4;
        }
    };
    if walk(f, (side + 2) % 4, &mut forward)? {
        return Some(forward);
    }
    let mut backward = Vec::new();
    if walk(f, side, &mut backward)? {
        return None; // closed only one way round: cannot happen on a manifold
    }
    backward.reverse();
    backward.extend(forward);
    Some(backward)
}

/// What collapsing a chord gives: the remaining faces (indices into the same vertex
/// array), the merges (removed vertex → kept vertex) and the kept vertices' new positions.
#[derive(Clone, Debug, PartialEq)]
pub struct Collapse {
    /// The faces left, with merged vertices renamed.
    pub quads: Vec<[u32; 4]>,
    /// (removed, kept) per rung.
    pub merged: Vec<(u32, u32)>,
    /// (kept vertex, its new position: the rung's midpoint).
    pub moved: Vec<(u32, [f64; 3])>,
}

/// Collapses the chord `ch` (from [`chord`]) of the mesh (`positions`, `quads`), or
/// `None` when the result would not be a valid manifold pure-quad mesh, would leave an
/// inner vertex with fewer than three faces, or would bend a changed face below the
/// bounds of `cfg` (see [`CoarsenConfig`]).
pub fn collapse(
    positions: &[[f64; 3]],
    quads: &[[u32; 4]],
    ch: &[(usize, usize)],
    cfg: &CoarsenConfig,
) -> Option<Collapse> {
    let mut partner: HashMap<u32, u32> = HashMap::new();
    let mut in_chord = vec![false; quads.len()];
    for &(f, s) in ch {
        in_chord[f] = true;
        let q = quads[f];
        for r in [s, (s + 2) % 4] {
            let (a, b) = (q[r], q[(r + 1) % 4]);
            for (x, y) in [(a, b), (b, a)] {
                match partner.get(&x) {
                    Some(&p) if p != y => return None, // a vertex on two rungs
                    _ => {
                        partner.insert(x, y);
                    }
                }
            }
        }
    }
    // Each rung {a, b}: the smaller index stays and moves to the midpoint.
    let mut rename: HashMap<u32, u32> = HashMap::new();
    let mut merged = Vec::new();
    let mut moved = Vec::new();
    for (&a, &b) in &partner {
        if a < b {
            rename.insert(b, a);
            merged.push((b, a));
            let (pa, pb) = (positions[a as usize], positions[b as usize]);
            moved.push((a, std::array::from_fn(|k| 0.5 * (pa[k] + pb[k]))));
        }
    }
    merged.sort_unstable();
    moved.sort_unstable_by_key(|m| m.0);
    let new_pos: HashMap<u32, [f64; 3]> = moved.iter().copied().collect();
    let pos = |v: u32| new_pos.get(&v).copied().unwrap_or(positions[v as usize]);
    let mut out = Vec::with_capacity(quads.len() - ch.len());
    for (f, q) in quads.iter().enumerate() {
        if in_chord[f] {
            continue;
        }
        let nq = q.map(|v| rename.get(&v).copied().unwrap_or(v));
        if q.iter().any(|v| partner.contains_key(v)) {
            // A changed face (renamed or moved corners): distinct corners, shape and
            // normal within the bounds.
            for i in 0..4 {
                if nq[(i + 1)..].contains(&nq[i]) {
                    return None;
                }
            }
            let before = q.map(|v| positions[v as usize]);
            let after = nq.map(pos);
            let (sb, sa) = (quad_shape(&before).scaled_jacobian, quad_shape(&after).scaled_jacobian);
            if sa < cfg.min_scaled_jacobian.min(sb) {
                return None;
            }
            match (quad_normal(&before), quad_normal(&after)) {
                (Some(nb), Some(na)) if dot(nb, na) >= cfg.min_normal_dot => {}
                _ => return None,
            }
        }
        out.push(nq);
    }
    if out.is_empty() {
        return None;
    }
    let mesh = HalfedgeMesh::from_quads(positions.len(), &out).ok()?;
    validate(&mesh).ok()?;
    // Inner vertices need three faces (two would make a doublet: two faces sharing two
    // edges, a crease with no area between them).
    for &(_, kept) in &merged {
        let v = super::handles::VertexId(kept);
        if !mesh.is_boundary_vertex(v) && mesh.vertex_faces(v).count() < 3 {
            return None;
        }
    }
    Some(Collapse { quads: out, merged, moved })
}

/// `mesh` with random chords collapsed until at most `cfg.face_fraction` of its faces
/// are left, or no chord can be collapsed (see the module documentation); the unused
/// vertices are dropped (their order otherwise kept). Deterministic for a given `rng`
/// state. A mesh whose faces do not form a valid manifold is returned unchanged.
pub fn coarsen(mesh: &QuadMesh, cfg: &CoarsenConfig, rng: &mut Rng) -> QuadMesh {
    let target = (mesh.quads.len() as f64 * cfg.face_fraction).ceil() as usize;
    let mut pos = mesh.vertices.clone();
    let mut quads = mesh.quads.clone();
    let valid = HalfedgeMesh::from_quads(pos.len(), &quads).and_then(|m| validate(&m)).is_ok();
    if !valid {
        return mesh.clone();
    }
    for _ in 0..cfg.max_passes {
        if quads.len() <= target {
            break;
        }
        // Vertices of collapsed chords' faces (after the merge): a chord through a face
        // holding one runs next to a chord collapsed in this pass.
        let mut locked = vec![false; pos.len()];
        let mut edges = edge_map(&quads);
        let mut misses = 0;
        let mut collapsed_any = false;
        while misses < cfg.max_misses && quads.len() > target {
            let f = rng.below(quads.len());
            let s = rng.below(2);
            let Some(ch) = chord(&quads, &edges, f, s) else {
                misses += 1;
                continue;
            };
            if ch.iter().any(|&(g, _)| quads[g].iter().any(|&v| locked[v as usize]))
                || aspect(&pos, &quads, &ch) > cfg.max_aspect
            {
                misses += 1;
                continue;
            }
            let Some(c) = collapse(&pos, &quads, &ch, cfg) else {
                misses += 1;
                continue;
            };
            for &(g, _) in &ch {
                for v in quads[g] {
                    locked[v as usize] = true;
                }
            }
            for &(removed, kept) in &c.merged {
                locked[removed as usize] = true;
                locked[kept as usize] = true;
            }
            for &(v, p) in &c.moved {
                pos[v as usize] = p;
            }
            quads = c.quads;
            edges = edge_map(&quads);
            misses = 0;
            collapsed_any = true;
        }
        if !collapsed_any {
            break;
        }
    }
    QuadMesh { vertices: pos, quads }.without_unused().0
}

/// Mean over the chord's faces of (rung + rung) / (side + side): above 1 the strip's
/// faces are longer across it than along it.
pub fn aspect(pos: &[[f64; 3]], quads: &[[u32; 4]], ch: &[(usize, usize)]) -> f64 {
    let len = |a: u32, b: u32| norm(sub(pos[a as usize], pos[b as usize]));
    let mut sum = 0.0;
    for &(f, s) in ch {
        let q = quads[f];
        let e = |i: usize| len(q[(s + i) % 4], q[(s + i + 1) % 4]);
        let side = e(1) + e(3);
        sum += if side > 0.0 { (e(0) + e(2)) / side } else { f64::INFINITY };
    }
    sum / ch.len().max(1) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An open m × n grid of unit squares in the plane z = 0.
    fn grid(m: usize, n: usize) -> QuadMesh {
        let mut vertices = Vec::new();
        for j in 0..=n {
            for i in 0..=m {
                vertices.push([i as f64, j as f64, 0.0]);
            }
        }
        let id = |i: usize, j: usize| (j * (m + 1) + i) as u32;
        let mut quads = Vec::new();
        for j in 0..n {
            for i in 0..m {
                quads.push([id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        QuadMesh { vertices, quads }
    }

    #[test]
    fn a_grid_chord_is_a_row_or_a_column() {
        let g = grid(5, 3);
        let e = edge_map(&g.quads);
        // Face 7 = (2, 1). Side 0 is its bottom edge: the chord runs up the column.
        let col = chord(&g.quads, &e, 7, 0).unwrap();
        let mut faces: Vec<usize> = col.iter().map(|c| c.0).collect();
        faces.sort_unstable();
        assert_eq!(faces, vec![2, 7, 12]);
        // Side 1 is its right edge: the chord runs along the row.
        let row = chord(&g.quads, &e, 7, 1).unwrap();
        let mut faces: Vec<usize> = row.iter().map(|c| c.0).collect();
        faces.sort_unstable();
        assert_eq!(faces, vec![5, 6, 7, 8, 9]);
    }

    #[test]
    fn collapsing_a_grid_column_leaves_a_narrower_grid() {
        let g = grid(5, 3);
        let e = edge_map(&g.quads);
        let col = chord(&g.quads, &e, 7, 0).unwrap();
        let c = collapse(
            &g.vertices,
            &g.quads,
            &col,
            &CoarsenConfig { min_scaled_jacobian: 0.0, ..Default::default() },
        )
        .unwrap();
        assert_eq!(c.quads.len(), 12);
        assert_eq!(c.merged.len(), 4); // the column's 4 rungs
                                       // Every kept vertex of a rung sits at x = 2.5.
        for &(_, p) in &c.moved {
            assert_eq!(p[0], 2.5);
        }
    }
}
