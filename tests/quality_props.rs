//! Property tests of the quality metrics (DESIGN §7) against references: brute-force
//! edge valences and fans, brute-force vertex matching for precision/recall,
//! invariance under rigid motion and uniform scale, and exact bounds on the Chamfer
//! distance of a shifted plane.

#[path = "common/quality.rs"]
mod quality_common;

use std::collections::{BTreeMap, BTreeSet};

use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::quality::{compare, is_degenerate_quad, mesh_metrics, quad_shape, MATCH_TOLERANCE};
use point2quad::rng::Rng;
use proptest::prelude::*;
use quality_common::{cube, grid, torus, transform};

/// A perturbed grid or torus (perturbation keeps quads non-degenerate).
fn shape(kind: u8, nu: u32, nv: u32, jitter: f64, seed: u64) -> PolyMesh {
    let mut m = if kind == 0 { grid(nu, nv) } else { torus(nu.max(3), nv.max(3), 0.4) };
    let mut rng = Rng::new(seed);
    let h = if kind == 0 { jitter } else { jitter * 0.1 };
    for p in &mut m.vertices {
        for c in p.iter_mut() {
            *c += h * (rng.f64() - 0.5);
        }
    }
    m
}

/// Reference edge valences: every face side, counted in a map.
fn ref_valences(m: &PolyMesh) -> BTreeMap<(u32, u32), usize> {
    let mut map = BTreeMap::new();
    for f in &m.faces {
        for i in 0..f.len() {
            let (a, b) = (f[i], f[(i + 1) % f.len()]);
            if a != b {
                *map.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
    }
    map
}

/// Reference non-manifold vertex count: per vertex, flood-fill its incident corners
/// through shared edges at the vertex; more than one component means non-manifold.
fn ref_nonmanifold_vertices(m: &PolyMesh) -> usize {
    let nv = m.vertices.len();
    let mut count = 0;
    for v in 0..nv as u32 {
        // Corners at v: (face, position), with the two neighbours along the face.
        let mut corners: Vec<(u32, u32)> = Vec::new();
        for f in &m.faces {
            let n = f.len();
            for k in 0..n {
                if f[k] == v {
                    corners.push((f[(k + n - 1) % n], f[(k + 1) % n]));
                }
            }
        }
        if corners.is_empty() {
            continue;
        }
        let mut seen = vec![false; corners.len()];
        let mut comps = 0;
        for s in 0..corners.len() {
            if seen[s] {
                continue;
            }
            comps += 1;
            let mut stack = vec![s];
            seen[s] = true;
            while let Some(c) = stack.pop() {
                for d in 0..corners.len() {
                    let shares = |x: u32| x != v && (corners[d].0 == x || corners[d].1 == x);
                    if !seen[d] && (shares(corners[c].0) || shares(corners[c].1)) {
                        seen[d] = true;
                        stack.push(d);
                    }
                }
            }
        }
        if comps > 1 {
            count += 1;
        }
    }
    count
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Diagonal of the axis-aligned bounding box of the vertices.
/// Reference boundary loops: a flood fill over the valence-1 edges through shared
/// vertices; (pieces, pieces with an odd number of edges).
fn ref_boundary_loops(val: &BTreeMap<(u32, u32), usize>) -> (usize, usize) {
    let border: Vec<(u32, u32)> = val.iter().filter(|(_, &c)| c == 1).map(|(&e, _)| e).collect();
    let mut seen = vec![false; border.len()];
    let (mut loops, mut odd) = (0, 0);
    for start in 0..border.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let (mut stack, mut size) = (vec![start], 0usize);
        while let Some(e) = stack.pop() {
            size += 1;
            let (a, b) = border[e];
            for (j, &(c, d)) in border.iter().enumerate() {
                if !seen[j] && (c == a || c == b || d == a || d == b) {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        loops += 1;
        odd += size % 2;
    }
    (loops, odd)
}

fn bbox_diag(m: &PolyMesh) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &m.vertices {
        for c in 0..3 {
            lo[c] = lo[c].min(p[c]);
            hi[c] = hi[c].max(p[c]);
        }
    }
    ((0..3).map(|c| (hi[c] - lo[c]).powi(2)).sum::<f64>()).sqrt()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * (1.0 + a.abs().max(b.abs()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// `is_degenerate_quad` against exact integer arithmetic: corners on a small lattice
    /// (so coincident corners and collinear or flat-folded quads are common) are
    /// degenerate iff two corners are equal or the diagonals' cross product is zero; the
    /// verdict survives any uniform scale and translation; and whatever `quad_shape`
    /// calls degenerate is degenerate.
    #[test]
    fn degenerate_quads_match_exact_arithmetic(
        corners in prop::array::uniform4(prop::array::uniform3(-2i64..3)),
        flat in any::<bool>(),
        scale_exp in -300i32..300, mantissa in 1.0f64..2.0, shift in prop::array::uniform3(-1e2f64..1e2),
    ) {
        let mut c = corners;
        if flat {
            // Half the cases in the z = 0 plane, where folds and lines are likelier.
            for p in &mut c { p[2] = 0; }
        }
        let sub = |a: [i64; 3], b: [i64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let (d1, d2) = (sub(c[2], c[0]), sub(c[3], c[1]));
        let cross = [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]];
        let repeated = (0..4).any(|i| (i + 1..4).any(|j| c[i] == c[j]));
        let expect = repeated || cross == [0, 0, 0];
        let k = mantissa * 2f64.powi(scale_exp);
        let p: [[f64; 3]; 4] = c.map(|q| std::array::from_fn(|a| (q[a] as f64 + shift[a]) * k));
        let exact: [[f64; 3]; 4] = c.map(|q| q.map(|x| x as f64));
        prop_assert_eq!(is_degenerate_quad(&exact), expect, "{:?}", c);
        // Shift then scale rounds the corners a little; the verdict must not move.
        prop_assert_eq!(is_degenerate_quad(&p), expect, "{:?} shifted by {:?}, scaled by {}", c, shift, k);
        if quad_shape(&exact).edge_ratio.is_none() {
            prop_assert!(is_degenerate_quad(&exact));
        }
    }

    /// Edge counts and non-manifold vertices of random quad soups over few vertices
    /// (so edges get 1, 2, 3+ faces and fans touch) against the references.
    #[test]
    fn topology_matches_brute_force(
        nverts in 4u32..12,
        raw in prop::collection::vec(prop::array::uniform4(0u32..12), 0..14),
    ) {
        let faces: Vec<Vec<u32>> = raw.iter().map(|f| f.iter().map(|&v| v % nverts).collect()).collect();
        let m = PolyMesh { vertices: (0..nverts).map(|i| [i as f64, (i * i) as f64, 0.5]).collect(), faces };
        let mm = mesh_metrics(&m);
        let val = ref_valences(&m);
        prop_assert_eq!(mm.edges, val.len());
        prop_assert_eq!(mm.boundary_edges, val.values().filter(|&&c| c == 1).count());
        prop_assert_eq!(mm.nonmanifold_edges, val.values().filter(|&&c| c > 2).count());
        let two = val.values().filter(|&&c| c == 2).count();
        let expect_w = if val.is_empty() { 0.0 } else { two as f64 / val.len() as f64 };
        prop_assert!(close(mm.watertightness, expect_w, 1e-12));
        prop_assert_eq!(mm.nonmanifold_vertices, ref_nonmanifold_vertices(&m));
        prop_assert_eq!((mm.boundary_loops, mm.odd_boundary_loops), ref_boundary_loops(&val));
        let used: BTreeSet<u32> = m.faces.iter().flatten().copied().collect();
        prop_assert_eq!(mm.unreferenced_vertices, nverts as usize - used.len());
        for x in [mm.scaled_jacobian, mm.edge_ratio, mm.angle_dev_deg, mm.angle_rms_deg, mm.manifoldness] {
            prop_assert!(x.is_finite());
        }
    }

    /// Holes punched in a quad grid or torus: the boundary loops match the flood fill,
    /// and, the mesh being all quads, the odd ones come in pairs (4F = 2·interior +
    /// border edges, so the border is even). A torus with nothing removed has none, a
    /// grid one even loop; a lone triangle adds an odd one.
    #[test]
    fn boundary_loops_of_punched_quad_meshes(
        kind in 0u8..2, nu in 3u32..9, nv in 3u32..9, drop in prop::collection::vec(any::<prop::sample::Index>(), 0..12),
    ) {
        let mut m = shape(kind, nu, nv, 0.0, 1);
        let whole = mesh_metrics(&m);
        prop_assert_eq!((whole.boundary_loops, whole.odd_boundary_loops), if kind == 0 { (1, 0) } else { (0, 0) });
        for d in &drop {
            if !m.faces.is_empty() {
                let i = d.index(m.faces.len());
                m.faces.swap_remove(i);
            }
        }
        let mm = mesh_metrics(&m);
        prop_assert_eq!((mm.boundary_loops, mm.odd_boundary_loops), ref_boundary_loops(&ref_valences(&m)));
        prop_assert_eq!(mm.odd_boundary_loops % 2, 0);
        // A lone triangle beside it is one more loop, an odd one.
        let n = m.vertices.len() as u32;
        m.vertices.extend([[9.0, 9.0, 9.0], [10.0, 9.0, 9.0], [9.0, 10.0, 9.0]]);
        m.faces.push(vec![n, n + 1, n + 2]);
        let with_tri = mesh_metrics(&m);
        prop_assert_eq!(
            (with_tri.boundary_loops, with_tri.odd_boundary_loops),
            (mm.boundary_loops + 1, mm.odd_boundary_loops + 1)
        );
    }

    /// Every metric is unchanged by a rigid motion with uniform scale.
    #[test]
    fn metrics_invariant_under_similarity(
        kind in 0u8..2, nu in 2u32..7, nv in 2u32..7, jitter in 0.0f64..0.4,
        seed in any::<u64>(), s in 0.01f64..100.0, t in prop::array::uniform3(-50.0f64..50.0),
    ) {
        let m = shape(kind, nu, nv, jitter, seed);
        let r = Rng::new(seed ^ 0x5eed).rotation();
        let mt = transform(&m, &r, s, t);
        let (a, b) = (mesh_metrics(&m), mesh_metrics(&mt));
        prop_assert_eq!(
            (a.faces, a.edges, a.boundary_edges, a.nonmanifold_edges, a.nonmanifold_vertices, a.degenerate_quads),
            (b.faces, b.edges, b.boundary_edges, b.nonmanifold_edges, b.nonmanifold_vertices, b.degenerate_quads)
        );
        prop_assert_eq!((a.watertightness, a.manifoldness), (b.watertightness, b.manifoldness));
        for (x, y) in [
            (a.scaled_jacobian, b.scaled_jacobian),
            (a.scaled_jacobian_min, b.scaled_jacobian_min),
            (a.edge_ratio, b.edge_ratio),
            (a.angle_dev_deg, b.angle_dev_deg),
            (a.angle_rms_deg, b.angle_rms_deg),
        ] {
            prop_assert!(close(x, y, 1e-9), "{} vs {}", x, y);
        }
        // The accuracy metrics too: transform prediction and ground truth together.
        let mut pred = m.clone();
        pred.faces.truncate(pred.faces.len() - 1);
        let (g1, g2) = (compare(&pred, &m, seed).unwrap(), compare(&transform(&pred, &r, s, t), &mt, seed).unwrap());
        prop_assert_eq!((g1.precision, g1.recall), (g2.precision, g2.recall));
        // Chamfer is in units of the GT's axis-aligned bbox diagonal (DESIGN §7), which a
        // rotation changes; in absolute units it is invariant (and scales with s).
        let (d1, d2) = (bbox_diag(&m), bbox_diag(&mt));
        let (c1, c2) = (g1.chamfer.unwrap(), g2.chamfer.unwrap());
        prop_assert!(close(c1 * d1 * s, c2 * d2, 1e-5), "{} vs {}", c1 * d1 * s, c2 * d2);
        // Translation and uniform scale alone keep even the normalised value.
        let g3 = compare(&transform(&pred, &IDENTITY, s, t), &transform(&m, &IDENTITY, s, t), seed).unwrap();
        let c3 = g3.chamfer.unwrap();
        prop_assert!(close(c1, c3, 1e-5), "{} vs {}", c1, c3);
    }

    /// Precision and recall against a brute-force reference: remove k faces, add wrong
    /// ones, renumber and move vertices (some within the tolerance, some beyond).
    #[test]
    fn precision_recall_match_brute_force(
        nu in 2u32..6, nv in 2u32..6, seed in any::<u64>(), k in 0usize..6, wrong in 0usize..5,
        far in 0usize..4,
    ) {
        let gt = shape(0, nu, nv, 0.3, seed);
        let mut rng = Rng::new(seed);
        let mut pred = gt.clone();
        for _ in 0..k.min(pred.faces.len() - 1) {
            let i = rng.below(pred.faces.len());
            pred.faces.remove(i);
        }
        for _ in 0..wrong {
            let f: Vec<u32> = (0..4).map(|_| rng.below(gt.vertices.len()) as u32).collect();
            pred.faces.push(f);
        }
        // Renumber the prediction's vertices.
        let mut perm: Vec<u32> = (0..gt.vertices.len() as u32).collect();
        rng.shuffle(&mut perm);
        let mut verts = vec![[0.0; 3]; perm.len()];
        for (old, &new) in perm.iter().enumerate() {
            verts[new as usize] = gt.vertices[old];
        }
        for f in &mut pred.faces {
            for v in f.iter_mut() {
                *v = perm[*v as usize];
            }
        }
        // Nudge every vertex well within the tolerance, and `far` of them beyond it.
        let diag = ((nu * nu + nv * nv) as f64).sqrt(); // ≥ the jittered grid's diagonal minus 0.3·√3
        for p in verts.iter_mut() {
            p[2] += 0.01 * MATCH_TOLERANCE * diag * rng.f64();
        }
        for _ in 0..far {
            let i = rng.below(verts.len());
            verts[i][0] += 100.0 * MATCH_TOLERANCE * diag;
        }
        pred.vertices = verts;

        // Reference: O(V²) matching in the GT's bbox-diagonal units.
        let gdiag = bbox_diag(&gt);
        let matched: Vec<Option<u32>> = pred.vertices.iter().map(|p| {
            (0..gt.vertices.len() as u32).find(|&g| {
                let q = gt.vertices[g as usize];
                ((0..3).map(|c| (p[c] - q[c]).powi(2)).sum::<f64>()).sqrt() <= MATCH_TOLERANCE * gdiag
            })
        }).collect();
        let gt_sets: Vec<BTreeSet<u32>> = gt.faces.iter().map(|f| f.iter().copied().collect()).collect();
        let mut recalled = BTreeSet::new();
        let mut hits = 0;
        for f in &pred.faces {
            let ids: Option<Vec<u32>> = f.iter().map(|&v| matched[v as usize]).collect();
            let Some(ids) = ids else { continue };
            let set: BTreeSet<u32> = ids.iter().copied().collect();
            if set.len() != ids.len() {
                continue;
            }
            let mut hit = false;
            for (g, s) in gt_sets.iter().enumerate() {
                if *s == set {
                    hit = true;
                    recalled.insert(g);
                }
            }
            hits += hit as usize;
        }
        let r = compare(&pred, &gt, 1).unwrap();
        prop_assert_eq!(r.matched_vertices, matched.iter().filter(|m| m.is_some()).count());
        prop_assert!(close(r.precision, hits as f64 / pred.faces.len() as f64, 1e-12));
        prop_assert!(close(r.recall, recalled.len() as f64 / gt.faces.len() as f64, 1e-12));
        if far == 0 && wrong == 0 {
            prop_assert!(close(r.precision, 1.0, 1e-12));
            prop_assert!(close(r.recall, pred.faces.len() as f64 / gt.faces.len() as f64, 1e-12));
        }
    }
}

/// A plane shifted by d along its normal: every sample's nearest neighbour is at least
/// d away, and at most sqrt(d² + r²) where r is its in-plane distance in the unshifted
/// case (same seeded samples), so 2d ≤ CD(d) ≤ 2d + CD(0).
#[test]
fn chamfer_of_shifted_plane_is_bounded_by_the_shift_and_the_floor() {
    let gt = grid(8, 6);
    let diag = 10.0; // bbox 8 × 6 × 0
    let floor = compare(&gt, &gt, 7).unwrap().chamfer.unwrap();
    assert!(floor > 0.0 && floor < 0.01, "sampling floor {floor}");
    let mut last = floor;
    for d in [0.001, 0.01, 0.05, 0.2] {
        let shifted = transform(&gt, &IDENTITY, 1.0, [0.0, 0.0, d * diag]);
        let cd = compare(&shifted, &gt, 7).unwrap();
        let (c, p2g, g2p) =
            (cd.chamfer.unwrap(), cd.chamfer_pred_to_gt.unwrap(), cd.chamfer_gt_to_pred.unwrap());
        assert!(c >= 2.0 * d - 1e-12 && c <= 2.0 * d + floor + 1e-9, "d {d}: {cd:?}");
        assert!(c > last);
        assert!((c - p2g - g2p).abs() < 1e-15);
        assert_eq!((cd.precision, cd.recall), (0.0, 0.0));
        last = c;
    }
}

#[test]
fn chamfer_is_deterministic_per_seed_and_a_closed_mesh_matches_itself() {
    let t = torus(24, 12, 0.35);
    let a = compare(&t, &t, 5).unwrap();
    assert_eq!(a, compare(&t, &t, 5).unwrap());
    assert_ne!(a.chamfer, compare(&t, &t, 6).unwrap().chamfer);
    assert_eq!((a.precision, a.recall), (1.0, 1.0));
    assert!(a.chamfer.unwrap() < 0.02, "{a:?}");
    let c = mesh_metrics(&cube([0.0; 3]));
    assert_eq!((c.watertightness, c.boundary_edges), (1.0, 0));
}
