//! Property tests of candidate generation and F_info against independent f64
//! recomputations and invariances: index validity, uniqueness, convex counter-
//! clockwise order, value ranges, rigid-motion / uniform-scale invariance, and
//! invariance under a permutation of the input. Clouds are jittered wavy grids,
//! which have no distance ties (ties would make the kNN order, and so the candidate
//! set, depend on indices — see `pipeline::candidates`).

#[path = "common/candidates.rs"]
mod cands_common;

use cands_common::*;
use point2quad::math::{cross, dot, norm, normalize, sub};
use point2quad::pipeline::candidates::{generate, CandidateConfig, Candidates};
use point2quad::pipeline::features::{context_features, f_info, CONTEXT_DIM, F_INFO_DIM};
use proptest::prelude::*;

fn f64p(p: [f32; 3]) -> [f64; 3] {
    [p[0] as f64, p[1] as f64, p[2] as f64]
}

/// F_info of one candidate recomputed in f64 from DESIGN §2's definitions.
fn reference_f_info(points: &[[f32; 3]], c: &Candidates, q: [u32; 4]) -> Vec<f64> {
    let p = q.map(|v| f64p(points[v as usize]));
    let s = q.iter().map(|&v| c.spacing[v as usize] as f64).sum::<f64>() / 4.0;
    let mut row = Vec::with_capacity(F_INFO_DIM);
    for pi in &p {
        for a in 0..3 {
            row.push((pi[a] - p[0][a]) / s);
        }
    }
    let e: Vec<[f64; 3]> = (0..4).map(|i| sub(p[(i + 1) % 4], p[i])).collect();
    let n = normalize(cross(sub(p[2], p[0]), sub(p[3], p[1]))).unwrap();
    let mut sj = f64::INFINITY;
    let mut sines = Vec::new();
    let mut normals = Vec::new();
    for i in 0..4 {
        let prev = e[(i + 3) % 4];
        let ci = cross(prev, e[i]);
        let ll = norm(prev) * norm(e[i]);
        sj = sj.min(dot(ci, n) / ll);
        sines.push(norm(ci) / ll);
        normals.extend_from_slice(&normalize(ci).unwrap());
    }
    row.push(sj);
    row.extend(sines);
    row.extend(normals);
    row
}

/// `c1` (a run with a step after the proposal) only adds to `c0` (the run without it):
/// every candidate of `c0` is in `c1` with the same rank, score, inside count and
/// proposers; no vertex set twice; each added quad has rank `per_point` and one
/// proposer, four distinct corners, is convex and counter-clockwise about one of its
/// corners' normals (the one that ranked it), and passes the sine and edge-ratio
/// filters. Returns the indices of the added quads in `c1`.
fn check_only_adds(
    pts: &[[f32; 3]],
    cfg: &CandidateConfig,
    c0: &Candidates,
    c1: &Candidates,
) -> Result<Vec<usize>, TestCaseError> {
    let at: std::collections::HashMap<[u32; 4], usize> =
        c1.quads.iter().enumerate().map(|(i, q)| (*q, i)).collect();
    for (i, q) in c0.quads.iter().enumerate() {
        let j = *at.get(q).ok_or_else(|| TestCaseError::fail(format!("{q:?} lost")))?;
        prop_assert_eq!(
            (c0.rank[i], c0.score[i].to_bits(), c0.inside[i], c0.proposers[i]),
            (c1.rank[j], c1.score[j].to_bits(), c1.inside[j], c1.proposers[j])
        );
    }
    let mut keys: Vec<[u32; 4]> = c1.quads.iter().map(key).collect();
    keys.sort_unstable();
    let n_keys = keys.len();
    keys.dedup();
    prop_assert_eq!(n_keys, keys.len(), "duplicate vertex sets");
    let c0_set: std::collections::HashSet<[u32; 4]> = c0.quads.iter().copied().collect();
    let added: Vec<usize> = (0..c1.len()).filter(|&j| !c0_set.contains(&c1.quads[j])).collect();
    for &j in &added {
        let q = c1.quads[j];
        prop_assert_eq!((c1.rank[j] as usize, c1.proposers[j]), (cfg.per_point, 1));
        prop_assert!(key(&q).windows(2).all(|w| w[0] != w[1]), "repeated index in {:?}", q);
        let p = q.map(|v| f64p(pts[v as usize]));
        let fn_ = normalize(cross(sub(p[2], p[0]), sub(p[3], p[1]))).unwrap();
        let lens: Vec<f64> = (0..4).map(|i| norm(sub(p[(i + 1) % 4], p[i]))).collect();
        let (lmin, lmax) = lens.iter().fold((f64::MAX, 0.0f64), |(a, b), &l| (a.min(l), b.max(l)));
        prop_assert!(lmin >= cfg.min_edge_ratio as f64 * lmax * (1.0 - 1e-5));
        for i in 0..4 {
            let ci = cross(sub(p[i], p[(i + 3) % 4]), sub(p[(i + 1) % 4], p[i]));
            prop_assert!(dot(ci, fn_) > 0.0, "corner {} of {:?} not convex", i, q);
            prop_assert!(norm(ci) / (lens[i] * lens[(i + 3) % 4]) >= cfg.min_sine as f64 - 1e-5);
        }
        prop_assert!(
            (0..4).any(|i| dot(f64p(c1.normals[q[i] as usize]), fn_) > 0.0),
            "{:?} is clockwise about every corner's normal",
            q
        );
    }
    Ok(added)
}

fn run(points: &[[f32; 3]]) -> Candidates {
    generate(points, &CandidateConfig::default()).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn candidates_are_valid_convex_ccw_and_match_reference_features(cloud in wavy_strategy()) {
        let pts = to_f32(&cloud);
        let cfg = CandidateConfig::default();
        let c = run(&pts);
        prop_assert!(!c.is_empty());
        let n = pts.len() as u32;
        let mut keys: Vec<[u32; 4]> = c.quads.iter().map(key).collect();
        keys.sort_unstable();
        let before = keys.len();
        keys.dedup();
        prop_assert_eq!(before, keys.len(), "duplicate vertex sets");
        for nrm in &c.normals {
            prop_assert!((norm(f64p(*nrm)) - 1.0).abs() < 1e-5);
        }
        let f = f_info(&pts, &c);
        let ctx = context_features(&pts, &c);
        prop_assert_eq!(f.len(), c.len() * F_INFO_DIM);
        prop_assert_eq!(ctx.len(), c.len() * CONTEXT_DIM);
        for (ci, q) in c.quads.iter().enumerate() {
            prop_assert!(q.iter().all(|&v| v < n));
            prop_assert!(key(q).windows(2).all(|w| w[0] != w[1]), "repeated index in {:?}", q);
            let row = &f[ci * F_INFO_DIM..(ci + 1) * F_INFO_DIM];
            let reference = reference_f_info(&pts, &c, *q);
            for (a, (&got, &want)) in row.iter().zip(&reference).enumerate() {
                prop_assert!((got as f64 - want).abs() < 1e-4 * (1.0 + want.abs()),
                    "F_info column {} of {:?}: {} vs reference {}", a, q, got, want);
            }
            // Convex: every corner turns the same way as the face normal; CCW about
            // the local normals.
            let p = q.map(|v| f64p(pts[v as usize]));
            let fn_ = normalize(cross(sub(p[2], p[0]), sub(p[3], p[1]))).unwrap();
            for i in 0..4 {
                let cn = [row[17 + 3 * i] as f64, row[18 + 3 * i] as f64, row[19 + 3 * i] as f64];
                prop_assert!(dot(cn, fn_) > 0.0, "corner {} of {:?} not convex", i, q);
                prop_assert!((norm(cn) - 1.0).abs() < 1e-5);
            }
            let local: [f64; 3] = (0..4).fold([0.0; 3], |acc, i| {
                let m = f64p(c.normals[q[i] as usize]);
                [acc[0] + m[0], acc[1] + m[1], acc[2] + m[2]]
            });
            prop_assert!(dot(local, fn_) > 0.0, "{:?} is clockwise about the local normal", q);
            // Ranges and the configured filters.
            prop_assert!(row[12] <= 1.0 && row[12] >= -1.0);
            prop_assert!(row[13..17].iter().all(|&s| (0.0..=1.0).contains(&s) && s >= cfg.min_sine - 1e-5));
            let lens: Vec<f64> = (0..4).map(|i| norm(sub(p[(i + 1) % 4], p[i]))).collect();
            let (lmin, lmax) = lens.iter().fold((f64::MAX, 0.0f64), |(a, b), &l| (a.min(l), b.max(l)));
            prop_assert!(lmin >= cfg.min_edge_ratio as f64 * lmax * (1.0 - 1e-5));
            let crow = &ctx[ci * CONTEXT_DIM..(ci + 1) * CONTEXT_DIM];
            prop_assert!(crow[5] >= 1.0 && crow[5] <= 4.0);
            // Rank `per_point` only for the lattice continuation's quads (one proposer).
            prop_assert!((crow[4] as usize) < cfg.per_point || (crow[4] as usize == cfg.per_point && crow[5] == 1.0));
            for i in 0..4 {
                let s = 0.5 * (c.spacing[q[i] as usize] + c.spacing[q[(i + 1) % 4] as usize]) as f64;
                prop_assert!((crow[6 + i] as f64 - lens[i] / s).abs() < 1e-4 * (1.0 + lens[i] / s));
            }
        }
    }

    #[test]
    fn candidates_and_f_info_invariant_under_similarity(
        cloud in wavy_strategy(),
        seed in any::<u64>(),
        s in 0.01f64..100.0,
        t in prop::array::uniform3(-50.0f64..50.0),
    ) {
        let r = point2quad::rng::Rng::new(seed).rotation();
        let moved = similarity(&cloud, &r, s, t);
        // Through the normalising frame, as the pipeline does.
        let to_local = |c: &[[f64; 3]]| {
            point2quad::pipeline::frame::Frame::fit(c).unwrap().to_local_all(c)
        };
        let (pa, pb) = (to_local(&cloud), to_local(&moved));
        let (ca, cb) = (run(&pa), run(&pb));
        prop_assert_eq!(&ca.quads, &cb.quads);
        let (fa, fb) = (f_info(&pa, &ca), f_info(&pb, &cb));
        for (ra, rb) in fa.chunks(F_INFO_DIM).zip(fb.chunks(F_INFO_DIM)) {
            // Positions and normals rotate: rotate b's back.
            for v in 0..8 {
                let off = if v < 4 { 3 * v } else { 17 + 3 * (v - 4) };
                let back = rotate_back(&r, [rb[off] as f64, rb[off + 1] as f64, rb[off + 2] as f64]);
                for a in 0..3 {
                    prop_assert!((ra[off + a] as f64 - back[a]).abs() < 2e-3, "{:?} vs {:?}", ra, rb);
                }
            }
            for a in 12..17 {
                prop_assert!((ra[a] - rb[a]).abs() < 1e-3);
            }
        }
    }

    #[test]
    fn candidates_invariant_under_permutation(cloud in wavy_strategy(), seed in any::<u64>()) {
        let pts = to_f32(&cloud);
        let mut perm: Vec<usize> = (0..pts.len()).collect();
        point2quad::rng::Rng::new(seed).shuffle(&mut perm);
        // shuffled[j] = pts[perm[j]]
        let shuffled: Vec<[f32; 3]> = perm.iter().map(|&i| pts[i]).collect();
        let ca = run(&pts);
        let cb = run(&shuffled);
        let mut a: Vec<[u32; 4]> = ca.quads.clone();
        let mut b: Vec<[u32; 4]> = cb.quads.iter().map(|q| cyclic_canonical(q.map(|j| perm[j as usize] as u32))).collect();
        a.sort_unstable();
        b.sort_unstable();
        prop_assert_eq!(a, b);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Lattice continuation only adds: every candidate of the run without it is there
    /// with the same rank, score, inside count and proposers; each added one has rank
    /// `per_point` and one proposer, a new vertex set of distinct points, is convex and
    /// counter-clockwise about its corners' normals, passes the sine and edge-ratio
    /// filters, and runs a side of another candidate the other way (the seed it
    /// continues). A small budget (4 per point) leaves it something to add.
    #[test]
    fn continuation_only_adds_valid_quads_next_to_other_candidates(cloud in wavy_strategy(), rank in 1u16..4) {
        let pts = to_f32(&cloud);
        let base = CandidateConfig { per_point: 4, continue_rank: 0, ..CandidateConfig::default() };
        let cfg = CandidateConfig { continue_rank: rank, ..base.clone() };
        let (c0, c1) = (generate(&pts, &base).unwrap(), generate(&pts, &cfg).unwrap());
        let added = check_only_adds(&pts, &cfg, &c0, &c1)?;
        let directed: std::collections::HashSet<(u32, u32)> =
            c1.quads.iter().flat_map(|q| (0..4).map(move |e| (q[e], q[(e + 1) % 4]))).collect();
        for &j in &added {
            let q = c1.quads[j];
            prop_assert!((0..4).any(|e| directed.contains(&(q[(e + 1) % 4], q[e]))),
                "{:?} continues no candidate", q);
        }
    }
}

#[test]
fn coplanar_cloud_is_an_open_surface_with_candidates() {
    let mut cloud = wavy_cloud(10, 10, 3);
    for p in &mut cloud {
        p[2] = 0.0;
    }
    let pts = to_f32(&cloud);
    let c = run(&pts);
    assert!(c.len() >= 81, "only {} candidates on a 10 x 10 plane", c.len());
    for n in &c.normals {
        assert!((n[2].abs() - 1.0).abs() < 1e-5, "plane normal {n:?}");
    }
}

#[test]
fn bad_clouds_are_errors_not_panics() {
    let cfg = CandidateConfig::default();
    assert!(generate(&[], &cfg).is_err());
    assert!(generate(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], &cfg).is_err());
    let mut pts = to_f32(&wavy_cloud(6, 6, 1));
    pts[17][0] = f32::INFINITY;
    let e = generate(&pts, &cfg).unwrap_err().to_string();
    assert!(e.contains("point 17"), "{e}");
    // Exactly four points (a square) and k larger than the cloud.
    let sq = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.1, 0.0]];
    let c = generate(&sq, &cfg).unwrap();
    assert_eq!(c.quads.len(), 1);
    assert_eq!(key(&c.quads[0]), [0, 1, 2, 3]);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Far completion (session 29) only adds: every candidate of the run without it is
    /// there with the same rank, score, inside count and proposers; each added one has
    /// rank `per_point` and one proposer, a new vertex set of distinct points, is convex
    /// and counter-clockwise about a corner's normal, and passes the sine and edge-ratio
    /// filters; at most `far_per_point` are added per point; and the candidate set does
    /// not depend on the order of the input points. The proposal's reach is cut to k = 8
    /// and the sheets are stretched up to 8:1 across their rows; from 4:1 on, cells reach
    /// beyond the 8 nearest and something must be added.
    #[test]
    fn far_completion_only_adds_valid_quads_in_any_input_order(
        cloud in wavy_strategy(),
        stretch in 1.0f64..8.0,
        far in 1usize..6,
        seed in any::<u64>(),
    ) {
        let cloud: Vec<[f64; 3]> = cloud.iter().map(|p| [p[0], p[1] * stretch, p[2]]).collect();
        let pts = to_f32(&cloud);
        // No floor: these sheets are smaller than the default's 200 points.
        let base = CandidateConfig { k: 8, far_min_points: 0, ..CandidateConfig::default() };
        let cfg = CandidateConfig { far_per_point: far, ..base.clone() };
        let (c0, c1) = (generate(&pts, &base).unwrap(), generate(&pts, &cfg).unwrap());
        let added = check_only_adds(&pts, &cfg, &c0, &c1)?;
        prop_assert!(added.len() <= far * pts.len());
        // Cells 4:1 and longer reach past the 8 nearest: something must be added there.
        prop_assert!(stretch < 4.0 || !added.is_empty(), "nothing added at stretch {}", stretch);
        let mut perm: Vec<usize> = (0..pts.len()).collect();
        point2quad::rng::Rng::new(seed).shuffle(&mut perm);
        let shuffled: Vec<[f32; 3]> = perm.iter().map(|&i| pts[i]).collect();
        let cs = generate(&shuffled, &cfg).unwrap();
        // Vertex sets: on sheets stretched this far the normals' global sign (hence every
        // quad's turn) can follow the input order; that is the orientation, not the far
        // completion, and the seams are the post-process's business.
        let mut a: Vec<[u32; 4]> = c1.quads.iter().map(key).collect();
        let mut b: Vec<[u32; 4]> = cs.quads.iter().map(|q| key(&q.map(|j| perm[j as usize] as u32))).collect();
        a.sort_unstable();
        b.sort_unstable();
        prop_assert_eq!(a, b);
    }
}

/// On a jittered lattice of 1 × 5 cells with the proposal's reach cut to k = 8, a point
/// 5 or more columns from its row's ends has its own row as its 8 nearest, so no corner
/// of a cell there has the other three among them and the point straight across lies
/// beyond them: the proposal (without the lattice continuation, which would find the
/// cells from those near the rows' ends) finds under a tenth of those cells, and the far
/// completion (session 29, whose far corners are the direction-diverse neighbours
/// beyond the k nearest) every one.
#[test]
fn far_completion_reaches_cells_beyond_the_k_nearest() {
    let (nx, ny) = (60usize, 12usize);
    let pts = to_f32(&rows_lattice(nx, ny, 5.0));
    // The cells whose corners are 5 or more columns from the rows' ends.
    let cells: Vec<[u32; 4]> = (0..ny - 1)
        .flat_map(|y| (5..nx - 6).map(move |x| (y * nx + x) as u32))
        .map(|v| key(&[v, v + 1, v + nx as u32 + 1, v + nx as u32]))
        .collect();
    let share = |cfg: &CandidateConfig| {
        let have: std::collections::HashSet<[u32; 4]> =
            generate(&pts, cfg).unwrap().quads.iter().map(key).collect();
        cells.iter().filter(|c| have.contains(*c)).count() as f64 / cells.len() as f64
    };
    let base = CandidateConfig { k: 8, continue_rank: 0, ..CandidateConfig::default() };
    let off = share(&base);
    let on = share(&CandidateConfig { far_per_point: 4, ..base.clone() });
    assert!(
        off < 0.1 && on == 1.0,
        "cells among the candidates: {off:.3} without, {on:.3} with far completion"
    );
}

/// The far completion's floor (session 36): on the 720-point lattice above it adds
/// quads when the floor is the cloud's size and nothing at all (the candidates equal
/// those without it, rank and score included) when the floor is one point more.
#[test]
fn far_completion_stays_off_clouds_under_its_floor() {
    let pts = to_f32(&rows_lattice(60, 12, 5.0));
    let base = CandidateConfig { k: 8, continue_rank: 0, ..CandidateConfig::default() };
    let off = generate(&pts, &base).unwrap();
    let with = |floor: usize| {
        generate(&pts, &CandidateConfig { far_per_point: 4, far_min_points: floor, ..base.clone() }).unwrap()
    };
    let (at, above) = (with(pts.len()), with(pts.len() + 1));
    assert!(at.quads.len() > off.quads.len(), "nothing added at the floor");
    assert_eq!(above.quads, off.quads);
    assert_eq!(above.rank, off.rank);
    assert_eq!(
        above.score.iter().map(|s| s.to_bits()).collect::<Vec<_>>(),
        off.score.iter().map(|s| s.to_bits()).collect::<Vec<_>>()
    );
}

/// The far completion on degenerate clouds an embedder may pass straight to the
/// library (no input hygiene): every point the same, every point twice, a line, a
/// plane grid with a far outlier, two distant clusters. No panic; what it returns
/// has four distinct corners and no repeated vertex set.
#[test]
fn far_completion_on_degenerate_clouds() {
    let grid: Vec<[f32; 3]> = (0..64).map(|v| [(v % 8) as f32, (v / 8) as f32 * 3.0, 0.0]).collect();
    let twice: Vec<[f32; 3]> = grid.iter().flat_map(|&p| [p, p]).collect();
    let mut outlier = grid.clone();
    outlier.push([1e4, -3e4, 2e4]);
    let clusters: Vec<[f32; 3]> = (0..40)
        .map(|v| [(v % 5) as f32 * 0.01 + if v < 20 { 0.0 } else { 100.0 }, (v / 5 % 4) as f32 * 0.01, 0.0])
        .collect();
    let clouds: Vec<(&str, Vec<[f32; 3]>)> = vec![
        ("identical", vec![[0.5, 0.5, 0.5]; 12]),
        ("twice", twice),
        ("line", (0..30).map(|v| [v as f32, 2.0 * v as f32, 0.0]).collect()),
        ("outlier", outlier),
        ("clusters", clusters),
    ];
    for (name, pts) in clouds {
        // No floor: these clouds are smaller than the default's 200 points.
        let cfg = CandidateConfig { far_per_point: 8, far_min_points: 0, ..CandidateConfig::default() };
        let c = generate(&pts, &cfg).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut keys: Vec<[u32; 4]> = c.quads.iter().map(key).collect();
        assert!(keys.iter().all(|k| k.windows(2).all(|w| w[0] != w[1])), "{name}: a repeated corner");
        keys.sort_unstable();
        let n = keys.len();
        keys.dedup();
        assert_eq!(n, keys.len(), "{name}: a repeated vertex set");
    }
}
