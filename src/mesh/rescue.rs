//! Two repairs of the post-process (not in the paper; README "Deviations"), run after the
//! manifold insertion (floaters) and after the greedy hole filling (rescue):
//! - [`remove_small_open_components`]: floaters — a lone quad or a small open patch away
//!   from the surface — are almost always wrong faces (a quad over noise points, or a
//!   wrong quad that lost every neighbour to a likelier rival); they add four or more
//!   boundary edges each and are never holes' fillers.
//! - [`rescue_faces`]: a hole left by the classifier is usually tiled by candidates it
//!   scored under the threshold. Candidates that glue to the hole's border along at least
//!   `min_glued` edges (so they fill a corner of the hole instead of growing outward) are
//!   inserted, most-glued and most probable first, through [`HalfedgeMesh::add_face`], so
//!   the mesh stays manifold. Two of those edges must border different faces: a quad
//!   over two sides of one face would fold over it. Optionally (`lone_min_prob`, session
//!   23) a candidate glued on one edge also goes in when one of its corners has no face
//!   yet and the classifier believes it enough: an input point no face uses, next to a
//!   hole, is a vertex the hole's faces need. (`add_face` keeps every vertex manifold,
//!   so such a quad goes in only when both corners off the glued edge have no face.)

use std::collections::HashMap;

use super::close::walk_loop;
use super::halfedge::HalfedgeMesh;
use super::handles::{FaceId, VertexId};
use super::hole_fill::quad_normal;
use crate::math::dot;

/// Settings of the rescue of candidates at holes.
#[derive(Clone, Debug, PartialEq)]
pub struct RescueConfig {
    /// Whether the rescue runs.
    pub enabled: bool,
    /// Candidates with a lower probability are never rescued.
    pub min_prob: f32,
    /// A candidate is rescued only when at least this many of its edges are boundary
    /// edges of the mesh (2 or more: it fills a corner of a hole, never extends a border
    /// by a free-standing strip).
    pub min_glued: usize,
    /// Passes over the boundary; each inserts what fits, the next sees the new border.
    pub max_passes: usize,
    /// A candidate glued on a single edge is rescued too when a corner of it is a
    /// vertex without faces and its probability is at least this (`None`: never).
    pub lone_min_prob: Option<f32>,
    /// A candidate is refused when, oriented to agree with a face it glues to, its
    /// normal and that face's are further apart than this dot product allows (session
    /// 24: a quad glued on two border edges of a flat patch could lie folded back over
    /// the patch's own faces). −0.9: folded back to within ≈ 25° of the face. Not the
    /// hole filling's and the closing's −0.3 (a dihedral sharper than ≈ 73°): real
    /// surfaces have such creases (thin shells' rims, knife edges; 705 edges of the
    /// training set's organic and thin meshes), and that bound refused their true faces
    /// (session 25), while they almost never fold back so far (1 under −0.95).
    pub min_normal_dot: f64,
    /// A candidate is refused when inserting it leaves more odd boundary loops around
    /// its corners than there were (session 30: an odd loop cannot be closed by quads
    /// over its own vertices, so a rescue that splits an even hole into two odd ones
    /// leaves both open).
    pub keep_parity: bool,
}

impl Default for RescueConfig {
    fn default() -> Self {
        RescueConfig {
            enabled: true,
            min_prob: 0.1,
            min_glued: 2,
            max_passes: 16,
            lone_min_prob: None,
            min_normal_dot: -0.9,
            keep_parity: false,
        }
    }
}

/// Removes every connected component that has a boundary and at most `max_faces`
/// faces, unless it is a largest component (a small open surface on its own is the
/// result, not a floater). Returns how many faces it removed. Closed components stay
/// whatever their size (a small closed part is a real part).
pub fn remove_small_open_components(mesh: &mut HalfedgeMesh, max_faces: usize) -> usize {
    if max_faces == 0 {
        return 0;
    }
    let comps = mesh.connected_components();
    let largest = comps.iter().map(Vec::len).max().unwrap_or(0);
    let mut removed = 0;
    for comp in comps {
        if comp.len() > max_faces || comp.len() == largest {
            continue;
        }
        let open =
            comp.iter().any(|&f| mesh.face_halfedges(f).iter().any(|h| mesh.is_boundary(h.opposite())));
        if !open {
            continue;
        }
        removed += mesh.remove_faces(&comp).len();
    }
    removed
}

/// Inserts candidates from `pool` (indices into `faces`/`probs`) at the mesh's holes, as
/// the module documentation says. Candidates below `cfg.min_prob`, or already in the mesh,
/// are ignored, and so is one that would fold over a face it glues to (`pos`: the
/// vertices' positions; `cfg.min_normal_dot`). Returns the indices inserted, in
/// insertion order.
///
/// # Panics
/// If an index of `pool` is out of range of `faces` or `probs`, or a face's vertex is not
/// a vertex of `mesh` or has no position in `pos`.
pub fn rescue_faces(
    mesh: &mut HalfedgeMesh,
    pos: &[[f64; 3]],
    faces: &[[u32; 4]],
    probs: &[f32],
    pool: &[usize],
    cfg: &RescueConfig,
) -> Vec<usize> {
    let mut inserted = Vec::new();
    if !cfg.enabled {
        return inserted;
    }
    // Undirected edge → pool candidates on it.
    let key = |a: u32, b: u32| if a < b { (a, b) } else { (b, a) };
    let mut by_edge: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for &c in pool {
        if probs[c] < cfg.min_prob || !probs[c].is_finite() {
            continue;
        }
        let f = faces[c];
        for i in 0..4 {
            by_edge.entry(key(f[i], f[(i + 1) % 4])).or_default().push(c as u32);
        }
    }
    if by_edge.is_empty() {
        return inserted;
    }
    let mut used = vec![false; faces.len()];
    let mut stamp = vec![0u32; faces.len()];
    let normal_of = |q: [VertexId; 4]| quad_normal(&q.map(|v| pos[v.idx()]));
    // Boundary edges of the quad: how many of its edges exist with one face; `None` when
    // an edge already has two faces (it cannot go in), when two of those edges belong
    // to one face (the quad would share three corners with it and fold over it, at a
    // convex corner of a border), or when the quad, turned to agree with a face across
    // one of them, faces away from it by more than `min_normal_dot` allows (folded back
    // over it) or either has no normal (no fold can be ruled out: unlike the closing,
    // which skips the test there, the rescue only adds faces and leaves such an edge to
    // the hole filling).
    let glued = |mesh: &HalfedgeMesh, f: &[u32; 4]| -> Option<usize> {
        let mut across: [Option<FaceId>; 4] = [None; 4];
        let mut g = 0;
        let n = normal_of(f.map(VertexId));
        for i in 0..4 {
            let (a, b) = (VertexId(f[i]), VertexId(f[(i + 1) % 4]));
            if let Some(h) = mesh.find_halfedge(a, b) {
                if !mesh.is_boundary(h) && !mesh.is_boundary(h.opposite()) {
                    return None;
                }
                let nb = mesh.face(h).or(mesh.face(h.opposite()));
                if across[..g].contains(&nb) {
                    return None;
                }
                if let Some(face) = nb {
                    // The face runs a → b when it owns h: then the quad goes in reversed.
                    let sign = if mesh.face(h).is_some() { -1.0 } else { 1.0 };
                    let m = normal_of(mesh.face_vertices(face))?;
                    if sign * dot(n?, m) < cfg.min_normal_dot {
                        return None;
                    }
                }
                across[g] = nb;
                g += 1;
            }
        }
        Some(g)
    };
    // Whether candidate c may go in with `g` glued edges: `min_glued` of them, or one
    // and a faceless corner (`lone_min_prob`).
    let enough = |mesh: &HalfedgeMesh, c: usize, g: usize| {
        g >= cfg.min_glued
            || (g >= 1
                && cfg.lone_min_prob.is_some_and(|t| probs[c] >= t)
                && faces[c].iter().any(|&v| mesh.is_isolated(VertexId(v))))
    };
    for pass in 1..=cfg.max_passes as u32 {
        let mut cands: Vec<(usize, f32, u32)> = Vec::new();
        for lp in mesh.boundary_loops() {
            for h in lp {
                let (a, b) = (mesh.from_vertex(h).0, mesh.to_vertex(h).0);
                let Some(list) = by_edge.get(&key(a, b)) else { continue };
                for &c in list {
                    let c = c as usize;
                    if used[c] || stamp[c] == pass {
                        continue;
                    }
                    stamp[c] = pass;
                    if let Some(g) = glued(mesh, &faces[c]) {
                        if enough(mesh, c, g) {
                            cands.push((g, probs[c], c as u32));
                        }
                    }
                }
            }
        }
        // Most glued first, then most probable, then lowest index.
        cands.sort_by(|x, y| y.0.cmp(&x.0).then(y.1.total_cmp(&x.1)).then(x.2.cmp(&y.2)));
        let mut added = 0;
        for &(_, _, c) in &cands {
            let c = c as usize;
            // Earlier insertions of this pass changed the border: check again.
            match glued(mesh, &faces[c]) {
                Some(g) if enough(mesh, c, g) => {}
                _ => continue,
            }
            let odd_before = if cfg.keep_parity { odd_loops_at(mesh, &faces[c]) } else { 0 };
            if let Ok(f) = mesh.add_face(faces[c].map(VertexId)) {
                // Taking a face just added out again restores the border it met.
                if cfg.keep_parity
                    && odd_loops_at(mesh, &faces[c]) > odd_before
                    && mesh.remove_face(f).is_ok()
                {
                    continue;
                }
                used[c] = true;
                inserted.push(c);
                added += 1;
            }
        }
        if added == 0 {
            break;
        }
    }
    inserted
}

/// How many of the boundary loops through the vertices `vs` have an odd number of edges
/// (each loop counted once).
fn odd_loops_at(mesh: &HalfedgeMesh, vs: &[u32; 4]) -> usize {
    let mut seen = Vec::new();
    let mut odd = 0;
    for &v in vs {
        for h in mesh.vertex_outgoing(VertexId(v)).filter(|&h| mesh.is_boundary(h)) {
            if !seen.contains(&h) {
                let lp = walk_loop(mesh, h, usize::MAX).expect("internal error: an unbounded walk");
                odd += lp.len() % 2;
                seen.extend(lp);
            }
        }
    }
    odd
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::validate::validate;

    fn grid(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        let m = crate::mesh::shapes::grid(n, n, n as f64, n as f64);
        (m.vertices, m.quads)
    }

    /// Odd boundary loops of a mesh, counted from `boundary_loops` (not the rescue's walk).
    fn odd_loops(mesh: &HalfedgeMesh) -> usize {
        mesh.boundary_loops().iter().filter(|l| l.len() % 2 == 1).count()
    }

    /// `keep_parity` (session 30): a quad glued on two opposite sides of an even hole that
    /// splits it into a triangle and a pentagon is refused; a true cell glued on three
    /// sides of the same hole, which leaves it even, still goes in.
    #[test]
    fn keep_parity_refuses_a_quad_that_splits_an_even_hole_into_odd_ones() {
        let (p, q) = grid(5);
        // Hole: the cells (1..=3, 2) in row 2, a 1 × 3 strip with an 8-edge border.
        // Vertex (i, j) is 6j + i: the strip's bottom row is 13..=16, its top 19..=22.
        let strip = |i: usize| matches!(i % 5, 1..=3) && i / 5 == 2;
        let keep: Vec<[u32; 4]> = q.iter().enumerate().filter(|(i, _)| !strip(*i)).map(|(_, f)| *f).collect();
        let fresh = || HalfedgeMesh::from_quads(p.len(), &keep).unwrap();
        let before = fresh();
        assert_eq!(odd_loops(&before), 0);
        // The wrong quad: the bottom edge 13 → 14 and the top edge 21 → 20, two border
        // edges apart; it leaves a triangle (13, 20, 19) and a pentagon (14, 15, 16, 22, 21).
        let wrong = [13u32, 14, 21, 20];
        let cell = [13u32, 14, 20, 19];
        let on = RescueConfig { keep_parity: true, ..RescueConfig::default() };
        for (cfg, want_in, want_odd) in [(RescueConfig::default(), true, 2), (on.clone(), false, 0)] {
            let mut mesh = fresh();
            let got = rescue_faces(&mut mesh, &p, &[wrong], &[0.4], &[0], &cfg);
            validate(&mesh).unwrap();
            assert_eq!(!got.is_empty(), want_in, "keep_parity {}", cfg.keep_parity);
            assert_eq!(odd_loops(&mesh), want_odd, "keep_parity {}", cfg.keep_parity);
            if !want_in {
                assert_eq!(mesh.corner_sets(), before.corner_sets(), "refused: the mesh is as it was");
            }
        }
        let mut mesh = fresh();
        let got = rescue_faces(&mut mesh, &p, &[cell], &[0.4], &[0], &on);
        validate(&mesh).unwrap();
        assert_eq!(got, vec![0]);
        assert_eq!(odd_loops(&mesh), 0);
    }

    /// With `keep_parity`, however many quads the rescue inserts, the mesh never has more
    /// odd loops than before it (each insertion keeps the count around its corners, and
    /// the other loops do not change), on random holes and random pools: the dropped
    /// cells, their sheared rivals and random quads over their vertices; the mesh stays
    /// valid. Without `keep_parity` the same pools add odd loops (checked, so the
    /// property is not vacuous: 8 of the 200 trials).
    #[test]
    fn keep_parity_never_adds_an_odd_loop() {
        let (p, q) = grid(6);
        let on = RescueConfig { keep_parity: true, ..RescueConfig::default() };
        let mut rng = crate::rng::Rng::new(3);
        let (mut inserted_total, mut worse_without) = (0, 0);
        for trial in 0..200 {
            let drop: Vec<bool> = (0..q.len()).map(|_| rng.below(3) == 0).collect();
            let keep: Vec<[u32; 4]> = q.iter().zip(&drop).filter(|(_, d)| !**d).map(|(f, _)| *f).collect();
            let Ok(mut mesh) = HalfedgeMesh::from_quads(p.len(), &keep) else { continue };
            let odd_before = odd_loops(&mesh);
            // Pool: the dropped cells and random quads of vertices of dropped cells.
            let verts: Vec<u32> =
                q.iter().zip(&drop).filter(|(_, d)| **d).flat_map(|(f, _)| f.iter().copied()).collect();
            if verts.is_empty() {
                continue;
            }
            let mut pool: Vec<[u32; 4]> = q.iter().zip(&drop).filter(|(_, d)| **d).map(|(f, _)| *f).collect();
            // Wrong rivals of each dropped cell: the cell sheared by one column either way
            // (top edge moved right or left), which glue to a hole on two opposite sides.
            for (c, _) in q.iter().enumerate().filter(|(c, _)| drop[*c]) {
                let (i, j) = ((c % 6) as u32, (c / 6) as u32);
                let v = |x: u32, y: u32| 7 * y + x;
                if i + 2 <= 6 {
                    pool.push([v(i, j), v(i + 1, j), v(i + 2, j + 1), v(i + 1, j + 1)]);
                }
                if i >= 1 {
                    pool.push([v(i, j), v(i + 1, j), v(i, j + 1), v(i - 1, j + 1)]);
                }
            }
            for _ in 0..40 {
                let mut f = [0u32; 4].map(|_| verts[rng.below(verts.len())]);
                f.sort_unstable();
                if f.windows(2).any(|w| w[0] == w[1]) {
                    continue;
                }
                // A random cyclic order of the four.
                rng.shuffle(&mut f);
                pool.push(f);
            }
            let probs: Vec<f32> = pool.iter().map(|_| 0.1 + 0.4 * rng.f32()).collect();
            let idx: Vec<usize> = (0..pool.len()).collect();
            let mut plain = mesh.clone();
            let got = rescue_faces(&mut mesh, &p, &pool, &probs, &idx, &on);
            validate(&mesh).unwrap();
            assert!(odd_loops(&mesh) <= odd_before, "trial {trial}: {} > {odd_before}", odd_loops(&mesh));
            inserted_total += got.len();
            rescue_faces(&mut plain, &p, &pool, &probs, &idx, &RescueConfig::default());
            worse_without += usize::from(odd_loops(&plain) > odd_before);
        }
        assert!(inserted_total > 100, "the rescue inserted {inserted_total} quads in all");
        assert!(worse_without >= 4, "without keep_parity {worse_without} trials added odd loops");
    }

    #[test]
    fn a_hole_is_tiled_by_its_low_probability_candidates() {
        let (p, q) = grid(5);
        // Drop the 3 × 3 block in the middle; offer its faces and wrong rivals (each
        // overlapping a true face, more probable) as the pool.
        let keep: Vec<[u32; 4]> = q
            .iter()
            .enumerate()
            .filter(|(i, _)| !matches!(i % 5, 1..=3) || !matches!(i / 5, 1..=3))
            .map(|(_, f)| *f)
            .collect();
        let mut mesh = HalfedgeMesh::from_quads(p.len(), &keep).unwrap();
        let hole: Vec<[u32; 4]> = q
            .iter()
            .enumerate()
            .filter(|(i, _)| matches!(i % 5, 1..=3) && matches!(i / 5, 1..=3))
            .map(|(_, f)| *f)
            .collect();
        let mut pool_faces = hole.clone();
        // A wrong kite on the same corner as the true face (1, 1): it takes the hole's
        // border edges 7 → 8 and 13 → 7 (vertex (i, j) is 6j + i) and leaves through
        // (3, 3) = 21. Less probable than the true face, so it loses that corner.
        pool_faces.push([7, 8, 21, 13]);
        let mut probs = vec![0.3; hole.len()];
        probs.push(0.2);
        let pool: Vec<usize> = (0..pool_faces.len()).collect();
        let got = rescue_faces(&mut mesh, &p, &pool_faces, &probs, &pool, &RescueConfig::default());
        validate(&mesh).unwrap();
        assert!(mesh.is_closed() || mesh.boundary_loops().len() == 1, "only the outer border is left");
        assert_eq!(mesh.n_faces(), 25);
        assert_eq!(got.len(), 9);
        assert!(!got.contains(&(pool_faces.len() - 1)), "the overlapping quad cannot go in");
    }

    #[test]
    fn nothing_grows_outward_and_low_probabilities_are_ignored() {
        let (p, q) = grid(3);
        let mut mesh = HalfedgeMesh::from_quads(p.len() + 20, &q).unwrap();
        // The 20 extra vertices lie beyond the grid's x = 0 side, out of its plane.
        let p: Vec<[f64; 3]> =
            p.iter().copied().chain((0..20).map(|i| [-1.0 - i as f64, 0.5 * i as f64, 1.0])).collect();
        let before = mesh.clone();
        // A quad glued to the outer border along one edge only (it would extend the border)
        // and an inner face below min_prob.
        let faces = vec![[1, 0, 16, 17], [0, 1, 5, 4]];
        let got = rescue_faces(&mut mesh, &p, &faces, &[0.9, 0.9], &[0], &RescueConfig::default());
        assert!(got.is_empty());
        assert_eq!(mesh, before);
        let (p, q) = grid(3);
        let mut mesh = HalfedgeMesh::from_quads(p.len(), &q[1..]).unwrap();
        let cfg = RescueConfig::default();
        assert!(rescue_faces(&mut mesh, &p, &q, &[0.01; 9], &[0], &cfg).is_empty());
        assert_eq!(rescue_faces(&mut mesh, &p, &q, &[0.5; 9], &[0], &cfg), vec![0]);
        let off = RescueConfig { enabled: false, ..cfg };
        let mut m2 = HalfedgeMesh::from_quads(p.len(), &q[1..]).unwrap();
        assert!(rescue_faces(&mut m2, &p, &q, &[0.5; 9], &[0], &off).is_empty());
    }

    /// Session 24 (an audit's find): a flat 2 × 2 patch of a 3 × 3 point grid, and the
    /// two 1 × 2 rectangles over it, each glued to the patch's border on two edges of
    /// different faces (bottom and top). Turned to agree with those faces they face
    /// the other way: folded back over the patch, so neither goes in, in any pose; with
    /// the normal bound off (−∞) one does, as before the guard (the audit's cloud got
    /// both, through the border the first left).
    #[test]
    fn quads_folded_back_over_the_faces_they_glue_to_stay_out() {
        let (p, q) = grid(2);
        let folds = vec![[0, 6, 7, 1], [1, 7, 8, 2]];
        let mut rng = crate::rng::Rng::new(24);
        for pose in 0..8 {
            let r = rng.rotation();
            let s = 10f64.powi(pose - 4);
            let pp: Vec<[f64; 3]> = p
                .iter()
                .map(|v| {
                    let w = crate::math::mat_vec(&r, *v);
                    [s * w[0] + 3.0, s * w[1] - 7.0, s * w[2]]
                })
                .collect();
            let mut mesh = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
            let before = mesh.clone();
            let got = rescue_faces(&mut mesh, &pp, &folds, &[0.9, 0.9], &[0, 1], &RescueConfig::default());
            assert!(got.is_empty(), "pose {pose}: {got:?} folded back in");
            assert_eq!(mesh, before);
            let off = RescueConfig { min_normal_dot: f64::NEG_INFINITY, ..RescueConfig::default() };
            let got = rescue_faces(&mut mesh, &pp, &folds, &[0.9, 0.9], &[0, 1], &off);
            assert!(!got.is_empty(), "pose {pose}: without the bound a fold glues on");
            validate(&mesh).unwrap();
        }
        // A true face of a hole in the same patch still goes in, in that pose too.
        let mut mesh = HalfedgeMesh::from_quads(p.len(), &q[1..]).unwrap();
        assert_eq!(rescue_faces(&mut mesh, &p, &q, &[0.5; 4], &[0], &RescueConfig::default()), vec![0]);
    }

    /// Session 25: the bound tells a crease from a fold. A quad hinged on one edge of
    /// a unit square (glued on that edge alone, `min_glued` 1) at angle θ from the
    /// square's plane continued (θ = 0: flat; 180°: lying back over the square) has the
    /// normal dot cos θ with it. Sharp true creases (θ = 120°, 150°: dot −0.5, −0.87)
    /// go in; folds back within 18° (dot under −0.95) stay out; whatever the pose.
    #[test]
    fn creases_go_in_and_folds_stay_out() {
        let mut rng = crate::rng::Rng::new(25);
        for deg in [0.0f64, 60.0, 120.0, 150.0, 162.0, 170.0, 180.0] {
            let t = deg.to_radians();
            let d = [t.cos(), 0.0, t.sin()];
            let p = [
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0 + d[0], 0.0, d[2]],
                [1.0 + d[0], 1.0, d[2]],
            ];
            let r = rng.rotation();
            let p: Vec<[f64; 3]> = p.iter().map(|v| crate::math::mat_vec(&r, *v)).collect();
            let cfg = RescueConfig { min_glued: 1, ..RescueConfig::default() };
            let mut mesh = HalfedgeMesh::from_quads(6, &[[0, 1, 2, 3]]).unwrap();
            let got = rescue_faces(&mut mesh, &p, &[[2, 1, 4, 5]], &[0.9], &[0], &cfg);
            let dot = t.cos();
            assert_eq!(got.is_empty(), dot < cfg.min_normal_dot, "θ = {deg}°: dot {dot:.3}, got {got:?}");
            assert_eq!(got.is_empty(), deg > 155.0, "θ = {deg}°");
            validate(&mesh).unwrap();
        }
    }

    /// Session 23's `lone_min_prob`: a 3 × 3 hole whose pool holds only the middle face of
    /// each side (glued on one edge, two corners without faces). The default rescue takes
    /// none; with the bound at or under their probability the first goes in, and so does
    /// every other that does not meet a rescued one at a corner alone (that would make a
    /// non-manifold vertex): faces 7 and 17 (face (i, j) is 5j + i), opposite each other.
    #[test]
    fn lone_corners_let_one_glued_edge_in() {
        let (p, q) = grid(5);
        let hole = |i: usize| matches!(i % 5, 1..=3) && matches!(i / 5, 1..=3);
        let keep: Vec<[u32; 4]> = q.iter().enumerate().filter(|(i, _)| !hole(*i)).map(|(_, f)| *f).collect();
        let sides = [q[7], q[11], q[13], q[17]];
        let pool = [0, 1, 2, 3];
        let fresh = || HalfedgeMesh::from_quads(p.len(), &keep).unwrap();
        let probs = [0.35f32; 4];
        let mut mesh = fresh();
        assert!(rescue_faces(&mut mesh, &p, &sides, &probs, &pool, &RescueConfig::default()).is_empty());
        let above = RescueConfig { lone_min_prob: Some(0.4), ..RescueConfig::default() };
        assert!(rescue_faces(&mut mesh, &p, &sides, &probs, &pool, &above).is_empty());
        assert_eq!(mesh, fresh());
        let lone = RescueConfig { lone_min_prob: Some(0.3), ..RescueConfig::default() };
        let got = rescue_faces(&mut mesh, &p, &sides, &probs, &pool, &lone);
        validate(&mesh).unwrap();
        assert_eq!(got, vec![0, 3]);
        assert_eq!(mesh.n_faces(), keep.len() + 2);
    }

    #[test]
    fn small_open_components_go_and_closed_ones_stay() {
        let (_, q) = grid(4);
        let mut faces = q.clone();
        // A lone quad and a 2-face strip far away, and a closed cube.
        faces.push([100, 101, 102, 103]);
        faces.push([110, 111, 114, 113]);
        faces.push([111, 112, 115, 114]);
        let cube = crate::mesh::shapes::cube_sphere(1);
        let off = 120u32;
        faces.extend(cube.quads.iter().map(|f| f.map(|v| v + off)));
        let n = off as usize + cube.vertices.len();
        let mut mesh = HalfedgeMesh::from_quads(n, &faces).unwrap();
        assert_eq!(remove_small_open_components(&mut mesh, 0), 0);
        let removed = remove_small_open_components(&mut mesh, 6);
        validate(&mesh).unwrap();
        assert_eq!(removed, 3);
        assert_eq!(mesh.n_faces(), 16 + 6);
        assert_eq!(mesh.connected_components().len(), 2);
        // A lone quad, or two, on their own are the result: they stay.
        let mut lone = HalfedgeMesh::from_quads(8, &[[0, 1, 2, 3], [4, 5, 6, 7]]).unwrap();
        assert_eq!(remove_small_open_components(&mut lone, 6), 0);
        assert_eq!(lone.n_faces(), 2);
    }
}
