//! Refinement rounds (`pipeline::refine`): the features equal a brute-force reference
//! (straight from their definitions, O(M²)) on random candidate sets, do not depend on
//! where a quad's cyclic order starts nor on the order of the candidate list; a model
//! with rounds keeps its classifier exactly, round-trips through its weights file and
//! config text; training the rounds separates real faces from rivals that the base
//! probabilities cannot (average precision on held-out shapes rises). The points inside
//! each candidate (session 23's inside columns) equal a test of every point in f64.

use point2quad::mesh::shapes;
use point2quad::nn::checkpoint::Checkpoint;
use point2quad::pipeline::candidates::CandidateConfig;
use point2quad::pipeline::dataset::build_sample;
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::refine::{
    inside_points, refine_features, refine_features_with, score_stats, train_refiner, RefineInput,
    RefineSample, RefineTrainConfig, SideRule, FLOW_DIM, INSIDE_DIM, INSIDE_MARGIN, INSIDE_PLANE_TOL,
    REFINE_DIM,
};
use point2quad::pipeline::train::sample_input;
use point2quad::rng::Rng;
use proptest::prelude::*;
use std::path::Path;

fn logit(p: f32) -> f32 {
    let p = p.clamp(1e-6, 1.0 - 1e-6);
    (p / (1.0 - p)).ln()
}

fn sorted(mut v: [f32; 4]) -> [f32; 4] {
    v.sort_by(f32::total_cmp);
    v
}

/// Unit-free normal of quad `q` (f64 diagonal cross product).
fn normal64(points: &[[f32; 3]], q: &[u32; 4]) -> [f64; 3] {
    let p = q.map(|i| points[i as usize].map(|x| x as f64));
    let d1 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
    let d2 = [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]];
    [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]]
}

/// Cosine of the angle between the normals of quads `a` and `b` (0 when one is degenerate).
fn normal_cos(points: &[[f32; 3]], a: &[u32; 4], b: &[u32; 4]) -> f64 {
    let (x, y) = (normal64(points, a), normal64(points, b));
    let l = (x.iter().map(|v| v * v).sum::<f64>() * y.iter().map(|v| v * v).sum::<f64>()).sqrt();
    if l > 0.0 {
        (x[0] * y[0] + x[1] * y[1] + x[2] * y[2]) / l
    } else {
        0.0
    }
}

fn sub64(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
    [a[0] as f64 - b[0] as f64, a[1] as f64 - b[1] as f64, a[2] as f64 - b[2] as f64]
}

fn len64(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// `refine_features_with`'s flow of neighbour `d` across edge i of `q` (f64): the
/// smaller cosine of the two lattice lines continued at the edge's ends, and
/// ln(mean edge of d / mean edge of q).
fn flow64(pts: &[[f32; 3]], q: &[u32; 4], i: usize, d: &[u32; 4]) -> (f64, f64) {
    let (a, b) = (q[i], q[(i + 1) % 4]);
    // d's corner next to v other than w.
    let other = |v: u32, w: u32| {
        let j = d.iter().position(|&x| x == v).unwrap();
        if d[(j + 1) % 4] == w {
            d[(j + 3) % 4]
        } else {
            d[(j + 1) % 4]
        }
    };
    let p = |v: u32| pts[v as usize];
    let cos = |u: [f64; 3], v: [f64; 3]| (u[0] * v[0] + u[1] * v[1] + u[2] * v[2]) / (len64(u) * len64(v));
    let sa = cos(sub64(p(a), p(q[(i + 3) % 4])), sub64(p(other(a, b)), p(a)));
    let sb = cos(sub64(p(b), p(q[(i + 2) % 4])), sub64(p(other(b, a)), p(b)));
    let mean = |r: &[u32; 4]| (0..4).map(|k| len64(sub64(p(r[(k + 1) % 4]), p(r[k])))).sum::<f64>() / 4.0;
    (sa.min(sb), (mean(d) / mean(q)).ln())
}

/// The features of candidate `c`, from the definitions in `refine_features`' doc
/// (and, with `flow`, the flow columns of `refine_features_with`'s doc).
/// Sides: `None` = by direction; `Some(points)` = a candidate running the edge the same
/// way is a rival and one running it the other way a neighbour, swapped when the two
/// normals are more than 120° apart (`None` is returned when a normal pair sits within
/// 1e-4 of 120°, which rounding decides).
fn reference_row(
    quads: &[[u32; 4]],
    sides: Option<&[[f32; 3]]>,
    p: &[f32],
    base: &[f32],
    c: usize,
    flow: bool,
) -> Option<Vec<f32>> {
    let q = quads[c];
    let mut flow_s = [0.0f32; 4];
    let mut flow_r = [0.0f32; 4];
    let has_directed = |d: &[u32; 4], a: u32, b: u32| (0..4).any(|i| d[i] == a && d[(i + 1) % 4] == b);
    let has_both = |d: &[u32; 4], a: u32, b: u32| d.contains(&a) && d.contains(&b);
    let best = |f: &dyn Fn(&[u32; 4]) -> bool, skip_self: bool| -> f32 {
        let mut m = 0.0f32;
        for (d, qd) in quads.iter().enumerate() {
            if (skip_self && d == c) || !f(qd) {
                continue;
            }
            m = m.max(p[d]);
        }
        m
    };
    let mut rival = [0.0; 4];
    let mut across = [0.0; 4];
    let mut shared = [0.0; 4];
    let mut at = [0.0; 4];
    let mut hi = [0.0; 4];
    for i in 0..4 {
        let (a, b) = (q[i], q[(i + 1) % 4]);
        match sides {
            None => {
                rival[i] = best(&|d| has_directed(d, a, b), true);
                across[i] = best(&|d| has_directed(d, b, a), true);
            }
            Some(pts) => {
                for (d, qd) in quads.iter().enumerate() {
                    let (fw, bw) = (has_directed(qd, a, b), has_directed(qd, b, a));
                    if d == c || !(fw || bw) {
                        continue;
                    }
                    let cos = normal_cos(pts, &q, qd);
                    if (cos + 0.5).abs() < 1e-4 {
                        return None;
                    }
                    let opp = cos <= -0.5;
                    if (fw && !opp) || (bw && opp) {
                        rival[i] = rival[i].max(p[d]);
                    }
                    if (bw && !opp) || (fw && opp) {
                        across[i] = across[i].max(p[d]);
                    }
                }
                if flow {
                    // Among the equally best neighbours across edge i, the one whose
                    // cyclic order started at its smallest corner is smallest.
                    let start_min = |r: &[u32; 4]| {
                        let s = (0..4).min_by_key(|&k| r[k]).unwrap();
                        [r[s], r[(s + 1) % 4], r[(s + 2) % 4], r[(s + 3) % 4]]
                    };
                    let mut chosen: Option<[u32; 4]> = None;
                    for (d, qd) in quads.iter().enumerate() {
                        let (fw, bw) = (has_directed(qd, a, b), has_directed(qd, b, a));
                        if d == c || !(fw || bw) {
                            continue;
                        }
                        let opp = normal_cos(pts, &q, qd) <= -0.5;
                        if ((bw && !opp) || (fw && opp)) && p[d] == across[i] {
                            let k = start_min(qd);
                            if chosen.map_or(true, |o| k < o) {
                                chosen = Some(k);
                            }
                        }
                    }
                    if let Some(k) = chosen {
                        let (s, r) = flow64(pts, &q, i, &k);
                        flow_s[i] = across[i] * s as f32;
                        flow_r[i] = across[i] * r.abs() as f32;
                    }
                }
            }
        }
        shared[i] = best(&|d| has_both(d, a, b), true);
        let mut s = 0.0f64;
        let mut n = 0;
        for (d, qd) in quads.iter().enumerate() {
            if d != c && qd.contains(&a) {
                s += p[d] as f64;
                n += (p[d] > 0.5) as u32;
            }
        }
        at[i] = s as f32;
        hi[i] = n as f32 / 4.0;
    }
    let diag = best(&|d| has_both(d, q[0], q[2]), true).max(best(&|d| has_both(d, q[1], q[3]), true));
    let diff = [0, 1, 2, 3].map(|i| across[i] - rival[i]);
    let mut row = vec![logit(p[c])];
    row.extend(sorted(rival));
    row.extend(sorted(across));
    row.extend(sorted(diff));
    row.push(diag);
    row.extend(sorted(at));
    row.extend(sorted(hi));
    row.extend(sorted(shared));
    row.push(logit(base[c]));
    if flow {
        row.extend(sorted(flow_s));
        row.extend(sorted(flow_r));
    }
    Some(row)
}

/// The points inside candidate `q` by the definition of `inside_points`, in f64, over
/// every point; `None` when a point lies within 1e-4 · L̄ of a bound (f32 and f64 may
/// then disagree) or the quad is degenerate.
fn reference_inside(pts: &[[f32; 3]], q: [u32; 4]) -> Option<Vec<u32>> {
    let p = q.map(|v| pts[v as usize].map(f64::from));
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let n = cross(sub(p[2], p[0]), sub(p[3], p[1]));
    let nl = dot(n, n).sqrt();
    let len = [0, 1, 2, 3].map(|e| len64(sub(p[(e + 1) % 4], p[e])));
    if nl < 1e-6 || len.iter().any(|&l| l < 1e-6) {
        return None;
    }
    let n = n.map(|x| x / nl);
    let lbar = len.iter().sum::<f64>() / 4.0;
    let centre = [0, 1, 2].map(|k| p.iter().map(|c| c[k]).sum::<f64>() / 4.0);
    let (tol, m) = (f64::from(INSIDE_PLANE_TOL) * lbar, f64::from(INSIDE_MARGIN) * lbar);
    let mut out = Vec::new();
    for (v, r) in pts.iter().enumerate() {
        if q.contains(&(v as u32)) {
            continue;
        }
        let r = r.map(f64::from);
        let off = dot(sub(r, centre), n).abs() - tol;
        let edges: Vec<f64> =
            (0..4).map(|e| dot(cross(n, sub(p[(e + 1) % 4], p[e])), sub(r, p[e])) / len[e] + m).collect();
        let slack = edges.iter().fold(off.abs(), |a, &x| a.min(x.abs()));
        if slack < 1e-4 * lbar {
            return None;
        }
        if off <= 0.0 && edges.iter().all(|&x| x >= 0.0) {
            out.push(v as u32);
        }
    }
    Some(out)
}

/// Random candidate sets over few points (so that edges, diagonals and corners are
/// shared a lot; the points at random positions, so candidates face every way), with
/// probabilities that include exact ties and 0.5.
/// Points, candidates, probabilities and base probabilities.
type CandidateSet = (Vec<[f32; 3]>, Vec<[u32; 4]>, Vec<f32>, Vec<f32>);

fn candidate_sets() -> impl Strategy<Value = CandidateSet> {
    (4usize..12, 0usize..50).prop_flat_map(|(n, m)| {
        let quad = proptest::sample::subsequence((0..n as u32).collect::<Vec<_>>(), 4)
            .prop_shuffle()
            .prop_map(|v| [v[0], v[1], v[2], v[3]]);
        let prob = prop_oneof![Just(0.5f32), Just(0.0f32), Just(1.0f32), 0.0f32..1.0, Just(0.25f32)];
        (
            proptest::collection::vec([-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0], n),
            proptest::collection::vec(quad, m),
            proptest::collection::vec(prob.clone(), m),
            proptest::collection::vec(prob, m),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn features_equal_the_brute_force_reference((pts, quads, p, base) in candidate_sets()) {
        for rule in [SideRule::Direction, SideRule::Normals] {
            let f = refine_features(&quads, &pts, rule, &p, &base).unwrap();
            prop_assert_eq!(f.len(), quads.len() * REFINE_DIM);
            let sides = (rule == SideRule::Normals).then_some(&pts[..]);
            for c in 0..quads.len() {
                let Some(want) = reference_row(&quads, sides, &p, &base, c, false) else { continue };
                let got = &f[c * REFINE_DIM..(c + 1) * REFINE_DIM];
                for (j, (g, w)) in got.iter().zip(&want).enumerate() {
                    // Columns 14–17 are sums (another order of additions); the rest are exact.
                    let tol = if (14..18).contains(&j) { 1e-5 } else { 0.0 };
                    prop_assert!((g - w).abs() <= tol, "{:?} candidate {} column {}: {} vs {}", rule, c, j, g, w);
                }
            }
        }
    }

    /// The flow columns (and the 27 before them) equal the reference on the same sets.
    #[test]
    fn flow_features_equal_the_brute_force_reference((pts, quads, p, base) in candidate_sets()) {
        let f = refine_features_with(&quads, &pts, SideRule::Normals, RefineInput::Flow, &p, &base).unwrap();
        prop_assert_eq!(f.len(), quads.len() * FLOW_DIM);
        let plain = refine_features(&quads, &pts, SideRule::Normals, &p, &base).unwrap();
        for c in 0..quads.len() {
            // The first 27 columns are exactly those of the base input.
            prop_assert_eq!(&f[c * FLOW_DIM..c * FLOW_DIM + REFINE_DIM], &plain[c * REFINE_DIM..(c + 1) * REFINE_DIM]);
            let Some(want) = reference_row(&quads, Some(&pts[..]), &p, &base, c, true) else { continue };
            prop_assert_eq!(want.len(), FLOW_DIM);
            let got = &f[c * FLOW_DIM..(c + 1) * FLOW_DIM];
            for j in REFINE_DIM..FLOW_DIM {
                // f32 against f64 arithmetic.
                let tol = 1e-4 * (1.0 + want[j].abs());
                prop_assert!((got[j] - want[j]).abs() <= tol, "candidate {} column {}: {} vs {}", c, j, got[j], want[j]);
            }
        }
    }

    /// The points inside each candidate equal the f64 test of every point, on the random
    /// sets and on the same sets flattened (so that points lie in many quads).
    #[test]
    fn inside_points_equal_the_brute_force_reference((pts, quads, _p, _b) in candidate_sets()) {
        let flat: Vec<[f32; 3]> = pts.iter().map(|v| [v[0], v[1], 0.05 * v[2]]).collect();
        for pts in [pts, flat] {
            let (start, members) = inside_points(&pts, &quads, INSIDE_PLANE_TOL, INSIDE_MARGIN);
            prop_assert_eq!(start.len(), quads.len() + 1);
            prop_assert_eq!(start[quads.len()] as usize, members.len());
            for (c, &q) in quads.iter().enumerate() {
                let got = &members[start[c] as usize..start[c + 1] as usize];
                if let Some(want) = reference_inside(&pts, q) {
                    prop_assert_eq!(got, &want[..], "candidate {} {:?}", c, q);
                }
            }
        }
    }

    /// The inside columns: the first 35 are the flow input's; 35 is the largest
    /// probability mass at a point inside the candidate, 36 the most candidates above
    /// 0.5 at one, / 4 (both 0 with no point inside).
    #[test]
    fn inside_features_equal_the_brute_force_reference((pts, quads, p, base) in candidate_sets()) {
        let pts: Vec<[f32; 3]> = pts.iter().map(|v| [v[0], v[1], 0.05 * v[2]]).collect();
        let f = refine_features_with(&quads, &pts, SideRule::Normals, RefineInput::Inside, &p, &base).unwrap();
        prop_assert_eq!(f.len(), quads.len() * INSIDE_DIM);
        let flow = refine_features_with(&quads, &pts, SideRule::Normals, RefineInput::Flow, &p, &base).unwrap();
        for c in 0..quads.len() {
            prop_assert_eq!(&f[c * INSIDE_DIM..c * INSIDE_DIM + FLOW_DIM], &flow[c * FLOW_DIM..(c + 1) * FLOW_DIM]);
            let Some(inside) = reference_inside(&pts, quads[c]) else { continue };
            let (mut mass, mut high) = (0.0f64, 0u32);
            for &v in &inside {
                let at = quads.iter().zip(&p).filter(|(q, _)| q.contains(&v));
                mass = mass.max(at.clone().map(|(_, &x)| f64::from(x)).sum::<f64>());
                high = high.max(at.filter(|(_, &x)| x > 0.5).count() as u32);
            }
            let got = &f[c * INSIDE_DIM + FLOW_DIM..(c + 1) * INSIDE_DIM];
            prop_assert!((f64::from(got[0]) - mass).abs() <= 1e-5, "candidate {}: mass {} vs {}", c, got[0], mass);
            prop_assert_eq!(got[1], high as f32 / 4.0, "candidate {}", c);
        }
    }

    /// Under the normals rule, reversing any candidates' cyclic orders (what an
    /// orientation seam does) changes no feature where the normals are clearly aligned
    /// or opposite: a reversed candidate runs every edge the other way and its normal
    /// flips, so both readings flip together. (Between the two, |cos| < 0.5, the
    /// direction decides, so there it does change.) The points are nearly coplanar, so
    /// almost every pair is judged.
    #[test]
    fn normal_sides_ignore_reversed_candidates((pts, quads, p, base) in candidate_sets(), seed in any::<u64>()) {
        let pts: Vec<[f32; 3]> = pts.iter().map(|v| [v[0], v[1], 0.05 * v[2]]).collect();
        let mut rng = Rng::new(seed);
        let f = refine_features(&quads, &pts, SideRule::Normals, &p, &base).unwrap();
        let flipped: Vec<[u32; 4]> =
            quads.iter().map(|&q| if rng.below(2) == 0 { [q[3], q[2], q[1], q[0]] } else { q }).collect();
        let f2 = refine_features(&flipped, &pts, SideRule::Normals, &p, &base).unwrap();
        let share_edge = |a: &[u32; 4], b: &[u32; 4]| {
            (0..4).any(|i| (0..4).any(|j| {
                let (x, y) = (a[i], a[(i + 1) % 4]);
                (b[j] == x && b[(j + 1) % 4] == y) || (b[j] == y && b[(j + 1) % 4] == x)
            }))
        };
        for c in 0..quads.len() {
            // Only where every candidate sharing an edge is clearly aligned or opposite.
            if quads.iter().any(|d| share_edge(&quads[c], d) && normal_cos(&pts, &quads[c], d).abs() < 0.5 + 1e-4) {
                continue;
            }
            for j in 0..REFINE_DIM {
                let (x, y) = (f[c * REFINE_DIM + j], f2[c * REFINE_DIM + j]);
                let tol = if (14..18).contains(&j) { 1e-5 } else { 0.0 };
                prop_assert!((x - y).abs() <= tol, "candidate {} column {}: {} vs {}", c, j, x, y);
            }
        }
    }

    #[test]
    fn features_ignore_list_order_and_cyclic_start(
        (pts, quads, p, base) in candidate_sets(), seed in any::<u64>()
    ) {
        for (rule, input) in [
            (SideRule::Direction, RefineInput::Base),
            (SideRule::Normals, RefineInput::Base),
            (SideRule::Normals, RefineInput::Flow),
            (SideRule::Normals, RefineInput::Inside),
        ] {
            let dim = input.dim();
            let f = refine_features_with(&quads, &pts, rule, input, &p, &base).unwrap();
            let mut rng = Rng::new(seed);
            let mut perm: Vec<usize> = (0..quads.len()).collect();
            rng.shuffle(&mut perm);
            // Candidate perm[i] goes to slot i, its cyclic order started at another corner.
            let q2: Vec<[u32; 4]> = perm.iter().map(|&c| {
                let s = rng.below(4);
                let q = quads[c];
                [q[s], q[(s + 1) % 4], q[(s + 2) % 4], q[(s + 3) % 4]]
            }).collect();
            let p2: Vec<f32> = perm.iter().map(|&c| p[c]).collect();
            let b2: Vec<f32> = perm.iter().map(|&c| base[c]).collect();
            let f2 = refine_features_with(&q2, &pts, rule, input, &p2, &b2).unwrap();
            for (i, &c) in perm.iter().enumerate() {
                let (a, b) = (&f[c * dim..(c + 1) * dim], &f2[i * dim..(i + 1) * dim]);
                for (j, (x, y)) in a.iter().zip(b).enumerate() {
                    // Sums in another order: the corner masses and the mean edge lengths.
                    let tol = if (14..18).contains(&j) || j >= REFINE_DIM { 1e-5 } else { 0.0 };
                    prop_assert!((x - y).abs() <= tol, "{:?} {:?} candidate {} column {}: {} vs {}", rule, input, c, j, x, y);
                }
            }
        }
    }

    /// The flow columns do not change when the points are rotated, moved and scaled
    /// (cosines and length ratios), where no pair of normals sits near the 120° at
    /// which the normals rule turns a neighbour into a rival.
    #[test]
    fn flow_features_are_similarity_invariant(
        (pts, quads, p, base) in candidate_sets(),
        angles in [0.0f64..6.3, 0.0f64..6.3, 0.0f64..6.3],
        scale in 0.01f64..100.0,
        shift in [-50.0f64..50.0, -50.0f64..50.0, -50.0f64..50.0],
    ) {
        let (ca, sa, cb, sb, cc, sc) =
            (angles[0].cos(), angles[0].sin(), angles[1].cos(), angles[1].sin(), angles[2].cos(), angles[2].sin());
        let moved: Vec<[f32; 3]> = pts.iter().map(|v| {
            let v = v.map(|x| x as f64);
            let v = [ca * v[0] - sa * v[1], sa * v[0] + ca * v[1], v[2]];
            let v = [cb * v[0] + sb * v[2], v[1], -sb * v[0] + cb * v[2]];
            let v = [v[0], cc * v[1] - sc * v[2], sc * v[1] + cc * v[2]];
            [0, 1, 2].map(|k| (scale * v[k] + shift[k]) as f32)
        }).collect();
        let f = refine_features_with(&quads, &pts, SideRule::Normals, RefineInput::Flow, &p, &base).unwrap();
        let g = refine_features_with(&quads, &moved, SideRule::Normals, RefineInput::Flow, &p, &base).unwrap();
        for c in 0..quads.len() {
            if reference_row(&quads, Some(&pts[..]), &p, &base, c, true).is_none()
                || quads.iter().any(|d| (normal_cos(&pts, &quads[c], d) + 0.5).abs() < 1e-3)
            {
                continue;
            }
            for j in REFINE_DIM..FLOW_DIM {
                let (x, y) = (f[c * FLOW_DIM + j], g[c * FLOW_DIM + j]);
                prop_assert!((x - y).abs() <= 1e-3 * (1.0 + x.abs()), "candidate {} column {}: {} vs {}", c, j, x, y);
            }
        }
    }
}

/// Session 23's review: a sharp kite (a 4° tip) keeps a point inside near its tip, past
/// the 8 × margin a fixed search radius reached; the search widens with the corner.
#[test]
fn inside_points_reach_sharp_corners() {
    let t = 4f32.to_radians() / 2.0;
    // Tip at the origin, pointing to −x; the kite runs counter-clockwise about +z.
    let (l, w) = (10.0f32, 10.0 * t.tan());
    let mut pts = vec![[0.0, 0.0, 0.0], [l, -w, 0.0], [l + 1.0, 0.0, 0.0], [l, w, 0.0]];
    // Just outside the tip, within the margin of both edge lines.
    let lbar = (2.0 * (l * l + w * w).sqrt() + 2.0 * (1.0 + w * w).sqrt()) / 4.0;
    pts.push([-0.8 * INSIDE_MARGIN * lbar / t.sin(), 0.0, 0.0]);
    pts.push([-3.0 * INSIDE_MARGIN * lbar / t.sin(), 0.0, 0.0]);
    let quads = [[0u32, 1, 2, 3]];
    let (start, members) = inside_points(&pts, &quads, INSIDE_PLANE_TOL, INSIDE_MARGIN);
    assert_eq!(&members[start[0] as usize..start[1] as usize], &[4]);
    assert_eq!(reference_inside(&pts, quads[0]), Some(vec![4]));
}

#[test]
fn features_refuse_bad_inputs() {
    let q = vec![[0u32, 1, 2, 3]];
    let pts = |n: usize| (0..n).map(|i| [i as f32, (i * i) as f32, 0.0]).collect::<Vec<_>>();
    for rule in [SideRule::Direction, SideRule::Normals] {
        assert!(refine_features(&q, &pts(3), rule, &[0.5], &[0.5])
            .unwrap_err()
            .to_string()
            .contains("candidate 0"));
        assert!(refine_features(&q, &pts(4), rule, &[0.5, 0.1], &[0.5]).is_err());
        assert!(refine_features(&[], &[], rule, &[], &[]).unwrap().is_empty());
        let err = refine_features(&[[0, 1, 2, 3], [4, 5, 4, 6]], &pts(7), rule, &[0.5, 0.5], &[0.5, 0.5])
            .unwrap_err();
        assert!(err.to_string().contains("candidate 1") && err.to_string().contains("repeats"), "{err}");
        for bad in [f32::NAN, -0.1, 1.5, f32::INFINITY] {
            let err = refine_features(&q, &pts(4), rule, &[bad], &[0.5]).unwrap_err();
            assert!(err.to_string().contains("candidate 0"), "{bad}: {err}");
            assert!(refine_features(&q, &pts(4), rule, &[0.5], &[bad]).is_err());
        }
    }
    // The flow columns need the normals rule.
    let err = refine_features_with(&q, &pts(4), SideRule::Direction, RefineInput::Flow, &[0.5], &[0.5])
        .unwrap_err();
    assert!(err.to_string().contains("normals"), "{err}");
}

/// A model with rounds keeps the classifier bit for bit, and its weights file and
/// config text carry the rounds.
#[test]
fn refined_model_keeps_the_classifier_and_round_trips() {
    let base = Model::new(ModelConfig::default_preset(), 3).unwrap();
    let mesh = shapes::torus(12, 6, 1.0, 0.4);
    let cfg = CandidateConfig { k: 12, per_point: 6, ..CandidateConfig::default() };
    let s = build_sample("torus", &mesh, &Default::default(), &cfg, &mut Rng::new(1)).unwrap();
    let x = sample_input(&s, base.config().face_in());
    let want = base.predict_with_points(&s.points, &s.candidates, &x).unwrap();
    let refined = base.with_refinement(2, &[8, 8], SideRule::Normals, 5).unwrap();
    assert_eq!(refined.config().refine_rounds, 2);
    assert_eq!(refined.refiner().unwrap().sides, SideRule::Normals);
    assert_eq!(refined.predict_base(&s.points, &s.candidates, &x).unwrap(), want);
    let got = refined.predict_with_points(&s.points, &s.candidates, &x).unwrap();
    assert_eq!(got.len(), want.len());
    assert_ne!(got, want, "the rounds changed nothing");
    assert!(refined.predict(&x).is_err(), "predict without candidates must refuse a refined model");
    let bytes = refined.to_checkpoint(None).to_bytes();
    let back = Model::from_bytes(&bytes, Path::new("mem")).unwrap();
    assert_eq!(back.config(), refined.config());
    assert_eq!(back.predict_with_points(&s.points, &s.candidates, &x).unwrap(), got);
    assert_eq!(Checkpoint::from_bytes(&bytes, Path::new("mem")).unwrap().to_bytes(), bytes);
    let text = refined.config().to_text();
    assert!(text.contains("refine_rounds = 2") && text.contains("refine_widths = 8,8"), "{text}");
    assert!(text.contains("refine_sides = normals"), "{text}");
    assert_eq!(&ModelConfig::from_text(&text, Path::new("cfg")).unwrap(), refined.config());
    // Files from before the rule existed have no `refine_sides` line: direction.
    let old = text.replace("refine_sides = normals\n", "");
    assert_eq!(ModelConfig::from_text(&old, Path::new("cfg")).unwrap().refine_sides, SideRule::Direction);
    let direction = base.with_refinement(2, &[8, 8], SideRule::Direction, 5).unwrap();
    assert!(!direction.config().to_text().contains("refine_sides"));
    assert_eq!(
        Model::from_bytes(&direction.to_checkpoint(None).to_bytes(), Path::new("mem")).unwrap().config(),
        direction.config()
    );
    // Without rounds nothing is written, so older files read unchanged.
    assert!(!base.config().to_text().contains("refine"));
    // Replacing the rounds of a refined model starts from its classifier again.
    let again = refined.with_refinement(1, &[4], SideRule::Normals, 0).unwrap();
    assert_eq!(again.predict_base(&s.points, &s.candidates, &x).unwrap(), want);
    // Config text with bad refinement keys: errors naming the line or the problem.
    let plain = base.config().to_text();
    for (extra, why) in [
        ("refine_rounds = 9\nrefine_widths = 8\n", "rounds"),
        ("refine_rounds = 2\nrefine_widths = 0\n", "zero width"),
        ("refine_rounds = 2\nrefine_widths = a\n", "width list"),
        ("refine_rounds = two\n", "number"),
        ("refine_rounds = 1\nrefine_rounds = 1\n", "repeated"),
        ("refine_rounds = 1\nrefine_widths = 8\nrefine_sides = left\n", "direction or normals"),
        (
            "refine_rounds = 1\nrefine_widths = 8\nrefine_sides = normals\nrefine_input = lattice\n",
            "base, flow or inside",
        ),
        ("refine_rounds = 1\nrefine_widths = 8\nrefine_input = flow\n", "needs refine_sides = normals"),
        ("refine_rounds = 1\nrefine_widths = 8\nrefine_input = inside\n", "needs refine_sides = normals"),
    ] {
        let err = ModelConfig::from_text(&format!("{plain}{extra}"), Path::new("cfg")).unwrap_err();
        assert!(err.to_string().contains(why), "{extra:?}: {err}");
    }
    // Rounds that read the flow columns: their own config line, a round trip, other
    // probabilities than the base input's rounds from the same seed; not with the
    // direction rule.
    let flow = base.with_refinement_reading(2, &[8, 8], SideRule::Normals, RefineInput::Flow, 5).unwrap();
    assert_eq!(flow.refiner().unwrap().input, RefineInput::Flow);
    let ftext = flow.config().to_text();
    assert!(ftext.contains("refine_input = flow"), "{ftext}");
    assert!(!text.contains("refine_input"), "{text}");
    assert_eq!(&ModelConfig::from_text(&ftext, Path::new("cfg")).unwrap(), flow.config());
    // The refinement keys are optional: they do not stand in for missing required ones.
    let short: String = ftext
        .lines()
        .filter(|l| !["preset", "use_context", "leaky_slope"].iter().any(|k| l.starts_with(k)))
        .map(|l| format!("{l}\n"))
        .collect();
    let err = ModelConfig::from_text(&short, Path::new("cfg")).unwrap_err();
    assert!(err.to_string().contains("missing keys"), "{err}");
    assert_eq!(flow.predict_base(&s.points, &s.candidates, &x).unwrap(), want);
    let fgot = flow.predict_with_points(&s.points, &s.candidates, &x).unwrap();
    assert_ne!(fgot, got, "the flow columns changed nothing");
    let fback = Model::from_bytes(&flow.to_checkpoint(None).to_bytes(), Path::new("mem")).unwrap();
    assert_eq!(fback.predict_with_points(&s.points, &s.candidates, &x).unwrap(), fgot);
    assert!(base.with_refinement_reading(1, &[8], SideRule::Direction, RefineInput::Flow, 0).is_err());
    // The same for rounds that read the inside columns (session 23).
    let inside = base.with_refinement_reading(2, &[8, 8], SideRule::Normals, RefineInput::Inside, 5).unwrap();
    let itext = inside.config().to_text();
    assert!(itext.contains("refine_input = inside"), "{itext}");
    assert_eq!(&ModelConfig::from_text(&itext, Path::new("cfg")).unwrap(), inside.config());
    let igot = inside.predict_with_points(&s.points, &s.candidates, &x).unwrap();
    let iback = Model::from_bytes(&inside.to_checkpoint(None).to_bytes(), Path::new("mem")).unwrap();
    assert_eq!(iback.predict_with_points(&s.points, &s.candidates, &x).unwrap(), igot);
    assert!(base.with_refinement_reading(1, &[8], SideRule::Direction, RefineInput::Inside, 0).is_err());
    // Bad settings.
    assert!(base.with_refinement(9, &[8], SideRule::Normals, 0).is_err());
    assert!(base.with_refinement(1, &[0], SideRule::Normals, 0).is_err());
}

/// Base probabilities that barely tell faces from non-faces (overlapping bands), on
/// shapes where real faces are surrounded by real faces: the trained rounds must use
/// the neighbourhood and raise the held-out average precision well above the base's.
#[test]
fn training_separates_faces_the_base_cannot() {
    let cfg = CandidateConfig { k: 12, per_point: 8, ..CandidateConfig::default() };
    let make = |name: &str, mesh: &point2quad::mesh::poly::QuadMesh, seed: u64| {
        let s = build_sample(name, mesh, &Default::default(), &cfg, &mut Rng::new(seed)).unwrap();
        let mut rng = Rng::new(seed ^ 99);
        let base: Vec<f32> = s
            .labels
            .iter()
            .map(|&y| if y == 1 { rng.uniform(0.35, 0.85) as f32 } else { rng.uniform(0.15, 0.65) as f32 })
            .collect();
        RefineSample { name: name.into(), points: s.points, quads: s.candidates, labels: s.labels, base }
    };
    let train =
        vec![make("torus", &shapes::torus(16, 8, 1.0, 0.4), 1), make("sphere", &shapes::cube_sphere(6), 2)];
    let val = vec![make("tube", &shapes::cylinder(14, 6, 0.5, 1.0, false), 3)];
    let base = Model::new(ModelConfig::default_preset(), 0).unwrap();
    let mut model = base.with_refinement(1, &[16], SideRule::Normals, 0).unwrap();
    let tc = RefineTrainConfig { epochs: 6, batch: 256, ..RefineTrainConfig::default() };
    let (refiner, params) = model.refiner_and_params_mut().unwrap();
    let reports = train_refiner(refiner, params, &train, &val, &tc, &mut |_| {}).unwrap();
    let r = &reports[0];
    let before = score_stats(&val[0].base, &val[0].labels);
    assert_eq!(r.val_before, before);
    assert!(
        r.val_after.average_precision > before.average_precision + 0.05,
        "AP {} -> {}",
        before.average_precision,
        r.val_after.average_precision
    );
    // The reported figures are those of the trained model applied afresh.
    let (refiner, params) = model.refiner_and_params_mut().unwrap();
    let p = refiner.apply(params, &val[0].points, &val[0].quads, &val[0].base).unwrap();
    assert_eq!(score_stats(&p, &val[0].labels), r.val_after);
    // Deterministic for a seed.
    let mut again = base.with_refinement(1, &[16], SideRule::Normals, 0).unwrap();
    let (refiner2, params2) = again.refiner_and_params_mut().unwrap();
    let reports2 = train_refiner(refiner2, params2, &train, &val, &tc, &mut |_| {}).unwrap();
    assert_eq!(reports2[0].val_after, r.val_after);
    assert_eq!(reports2[0].loss, r.loss);
}

#[test]
fn score_stats_match_hand_counts() {
    // Ranked: 0.9 (1), 0.8 (0), 0.6 (1), 0.2 (1): AP = (1/1 + 2/3 + 3/4) / 3.
    let s = score_stats(&[0.2, 0.9, 0.6, 0.8], &[1, 1, 1, 0]);
    assert!((s.average_precision - (1.0 + 2.0 / 3.0 + 0.75) / 3.0).abs() < 1e-12);
    assert!((s.precision - 2.0 / 3.0).abs() < 1e-12);
    assert!((s.recall - 2.0 / 3.0).abs() < 1e-12);
}
