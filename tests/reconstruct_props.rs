//! Properties of `pipeline::reconstruct` through the library API (no file I/O), with a
//! randomly initialised default model (the invariants do not depend on trained
//! weights): a valid manifold pure-quad mesh for any threshold, the input points
//! bit-identical at the front of the output, invariance under similarity transforms,
//! the raw path without post-process, and bad inputs that must error, never panic.

use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes;
use point2quad::mesh::validate::validate;
use point2quad::pipeline::candidates::generate;
use point2quad::pipeline::features::face_input;
use point2quad::pipeline::frame::Frame;
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::noise::{noise_points, NoiseConfig};
use point2quad::pipeline::reconstruct::{reconstruct, reconstruct_with_report, ReconstructConfig};
use point2quad::rng::Rng;
use proptest::prelude::*;
use std::collections::HashSet;
use std::sync::OnceLock;
#[path = "common/shipped.rs"]
mod shipped;
use shipped::shipped;

fn model() -> &'static Model {
    static M: OnceLock<Model> = OnceLock::new();
    M.get_or_init(|| Model::new(ModelConfig::default_preset(), 7).expect("test: model"))
}

/// A small noisy cloud (a few hundred points) of shape `kind`. Every coordinate is
/// jittered by up to ±5e-4 (about 0.5% of an edge): the generators' regular grids have
/// exact ties (a vertex's two neighbours along a ring are equally far), which rounding
/// breaks one way or the other after a rotation; scans have no exact ties.
fn cloud(kind: u8, seed: u64) -> Vec<[f64; 3]> {
    let mesh = match kind % 4 {
        0 => shapes::cube_sphere(5),
        1 => shapes::torus(14, 8, 1.0, 0.35),
        2 => shapes::height_field(12, 12, |u, v| 0.2 * (3.0 * u).sin() * (2.0 * v).cos()),
        _ => shapes::cylinder(14, 6, 0.5, 1.0, true),
    };
    let mut rng = Rng::new(seed);
    let mesh = shapes::random_pose(&mesh, &mut rng);
    let mut pts = mesh.vertices.clone();
    pts.extend(noise_points(&mesh, &NoiseConfig::default(), &mut rng).expect("test: noise"));
    for c in pts.iter_mut().flatten() {
        *c += 1e-3 * (rng.f64() - 0.5);
    }
    pts
}

/// Every face index in range, and the faces form a valid manifold, oriented, pure-quad mesh.
fn assert_valid(m: &QuadMesh) {
    for q in &m.quads {
        assert!(q.iter().all(|&v| (v as usize) < m.vertices.len()), "face {q:?} out of range");
    }
    let he = HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).expect("output is not manifold");
    validate(&he).expect("output fails validate");
}

/// The first `pts.len()` output vertices are the input, bit for bit, in order.
fn assert_prefix(m: &QuadMesh, pts: &[[f64; 3]]) {
    assert!(m.vertices.len() >= pts.len());
    for (i, (a, b)) in pts.iter().zip(&m.vertices).enumerate() {
        assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()), "vertex {i}: {a:?} became {b:?}");
    }
}

fn sorted(mut q: [u32; 4]) -> [u32; 4] {
    q.sort_unstable();
    q
}

/// Candidate vertex sets of a cloud, as the pipeline computes them.
fn candidate_sets(pts: &[[f64; 3]]) -> HashSet<[u32; 4]> {
    let f = Frame::fit(pts).expect("test: frame");
    let c =
        generate(&f.to_local_all(pts), &ReconstructConfig::default().candidates).expect("test: candidates");
    c.quads.iter().map(|&q| sorted(q)).collect()
}

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(10) })]

    #[test]
    fn output_is_valid_and_keeps_input_points(kind in 0u8..4, seed in 0u64..1000, threshold in 0.0f32..0.99) {
        let pts = cloud(kind, seed);
        let cfg = ReconstructConfig { threshold, ..Default::default() };
        let m = reconstruct(&pts, model(), &cfg).expect("reconstruct");
        assert_valid(&m);
        assert_prefix(&m, &pts);
        prop_assert!(m.vertices[pts.len()..].iter().all(|v| v.iter().all(|c| c.is_finite())));
        // Every added vertex is a corner of some face (session 41's audit: a filling's
        // vertex whose quads a later step took out stayed, isolated).
        let mut used = vec![false; m.vertices.len()];
        m.quads.iter().flatten().for_each(|&v| used[v as usize] = true);
        prop_assert!(used[pts.len()..].iter().all(|&u| u), "an added vertex no face uses");
    }

    /// With the far completion in the candidates (`--far`, session 29; off by default)
    /// the output is just as valid.
    #[test]
    fn output_with_far_completion_is_valid(kind in 0u8..4, seed in 0u64..1000, far in 1usize..9) {
        let pts = cloud(kind, seed);
        let mut cfg = ReconstructConfig::default();
        cfg.candidates.far_per_point = far;
        // No floor: some of these clouds are smaller than the default's 200 points.
        cfg.candidates.far_min_points = 0;
        let m = reconstruct(&pts, model(), &cfg).expect("reconstruct");
        assert_valid(&m);
        assert_prefix(&m, &pts);
    }

    /// The input's order does not matter (session 30): `reconstruct` takes the points
    /// in coordinate order, so a shuffled cloud gives the same faces on the same points
    /// (mapped through the shuffle), in the same order, and the same added vertices, bit
    /// for bit. Before, candidates started at their smallest input index and the
    /// network's scores followed it (47 of 1,850 faces differed on a shuffled cloud).
    #[test]
    fn any_order_gives_the_same_faces(kind in 0u8..4, seed in 0u64..1000) {
        let pts = cloud(kind, seed);
        let mut order: Vec<usize> = (0..pts.len()).collect();
        Rng::new(seed ^ 0x0dd).shuffle(&mut order);
        // shuffled[j] = pts[order[j]]
        let shuffled: Vec<[f64; 3]> = order.iter().map(|&i| pts[i]).collect();
        let cfg = ReconstructConfig::default();
        let a = reconstruct(&pts, shipped(), &cfg).expect("reconstruct");
        let b = reconstruct(&shuffled, shipped(), &cfg).expect("reconstruct shuffled");
        let n = pts.len();
        let back = |v: u32| if (v as usize) < n { order[v as usize] as u32 } else { v };
        let mapped: Vec<[u32; 4]> = b.quads.iter().map(|q| q.map(back)).collect();
        prop_assert!(a.quads.len() > 50, "{} faces", a.quads.len());
        prop_assert_eq!(&a.quads, &mapped);
        let bits = |m: &QuadMesh| m.vertices[n..].iter().map(|p| p.map(f64::to_bits)).collect::<Vec<_>>();
        prop_assert_eq!(bits(&a), bits(&b));
    }

    /// The same with near-duplicates (session 41's audit): a group of points closer
    /// than the merge share counts once, and the one its faces use was the first in
    /// input order, so a shuffled cloud used other coordinates and gave other faces
    /// (141 of 684 on one cloud). Now it is the first in coordinate order: the same
    /// faces on the same points, whatever the order.
    #[test]
    fn any_order_gives_the_same_faces_with_near_duplicates(kind in 0u8..4, seed in 0u64..1000, copies in 1usize..40) {
        let mut pts = cloud(kind, seed);
        let mut rng = Rng::new(seed ^ 0xd0b);
        let span = pts.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max) - pts.iter().map(|p| p[0]).fold(f64::INFINITY, f64::min);
        for _ in 0..copies {
            let q = pts[rng.below(pts.len())];
            // Far below the merge share (1e-3 of the spacing) and never an exact copy;
            // either side of the point, so the copy is first in coordinate order about
            // half the time.
            let sign = if rng.below(2) == 0 { 1.0 } else { -1.0 };
            let e = sign * span * 1e-9 * (1.0 + rng.f64());
            pts.push([q[0] + e, q[1] - e, q[2]]);
        }
        let mut order: Vec<usize> = (0..pts.len()).collect();
        rng.shuffle(&mut order);
        let shuffled: Vec<[f64; 3]> = order.iter().map(|&i| pts[i]).collect();
        let cfg = ReconstructConfig::default();
        let (a, ra) = reconstruct_with_report(&pts, shipped(), &cfg).expect("reconstruct");
        let b = reconstruct(&shuffled, shipped(), &cfg).expect("reconstruct shuffled");
        prop_assert!(ra.duplicates >= copies, "{} of {copies} copies merged", ra.duplicates);
        let n = pts.len();
        let back = |v: u32| if (v as usize) < n { order[v as usize] as u32 } else { v };
        let mapped: Vec<[u32; 4]> = b.quads.iter().map(|q| q.map(back)).collect();
        prop_assert!(a.quads.len() > 50, "{} faces", a.quads.len());
        prop_assert_eq!(&a.quads, &mapped);
    }

    /// A power-of-two scale is exact in floating point: the centroid, the radius and
    /// `(p − c) / s` all scale exactly, so the local frame, hence every later stage, is
    /// bit-identical and the faces must be equal (not just close).
    #[test]
    fn power_of_two_scale_gives_identical_faces(kind in 0u8..4, seed in 0u64..1000, e in -20i32..20) {
        let pts = cloud(kind, seed);
        let k = 2f64.powi(e);
        let scaled: Vec<[f64; 3]> = pts.iter().map(|p| [p[0] * k, p[1] * k, p[2] * k]).collect();
        let cfg = ReconstructConfig::default();
        let a = reconstruct(&pts, model(), &cfg).expect("reconstruct");
        let b = reconstruct(&scaled, model(), &cfg).expect("reconstruct scaled");
        prop_assert_eq!(&a.quads, &b.quads);
        prop_assert_eq!(a.vertices.len(), b.vertices.len());
    }

    /// A rigid motion plus a uniform scale changes the local coordinates only by a
    /// rotation and f64→f32 rounding. The candidates are built from rotation-invariant
    /// geometry (distances, PCA normals, angles), so their vertex sets must agree up to
    /// ties broken differently by rounding. The classifier's inputs hold vectors (it is
    /// not rotation invariant; training augments rotations), so the faces are not
    /// compared: the output must still be valid. Measured: without the jitter of
    /// [`cloud`] a torus keeps only 63–79% of its candidates under a rotation (exact
    /// kNN ties cut differently); with it, 100% on every shape tried.
    #[test]
    fn similarity_keeps_the_candidate_set(kind in 0u8..4, seed in 0u64..1000, s in 0.01f64..100.0, t in -1e3f64..1e3) {
        let pts = cloud(kind, seed);
        let r = Rng::new(seed ^ 0x5eed).rotation();
        let moved: Vec<[f64; 3]> = pts
            .iter()
            .map(|p| {
                let q = point2quad::math::mat_vec(&r, *p);
                [q[0] * s + t, q[1] * s - 0.5 * t, q[2] * s + 0.25 * t]
            })
            .collect();
        let (a, b) = (candidate_sets(&pts), candidate_sets(&moved));
        let common = a.intersection(&b).count();
        let union = a.len() + b.len() - common;
        prop_assert!(!a.is_empty());
        // f32 local coordinates still flip near-ties (kNN cut, per-point ranking):
        // Jaccard 0.986 was the worst seen (torus). A broken frame, an axis-dependent
        // filter or exact ties (0.63 on the raw torus) fall well below 0.97.
        prop_assert!(common as f64 >= 0.97 * union as f64, "{common} common of {union} ({} vs {})", a.len(), b.len());
        let m = reconstruct(&moved, model(), &ReconstructConfig::default()).expect("reconstruct moved");
        assert_valid(&m);
        assert_prefix(&m, &moved);
    }
}

#[test]
fn without_postprocess_returns_the_raw_predicted_faces() {
    let pts = cloud(0, 3);
    for threshold in [0.0f32, 0.3, 0.5, 0.7] {
        let cfg = ReconstructConfig { threshold, run_postprocess: false, ..Default::default() };
        let m = reconstruct(&pts, model(), &cfg).expect("reconstruct");
        // Reference: the same stages by hand, on the points in coordinate order.
        let mut order: Vec<usize> = (0..pts.len()).collect();
        order.sort_by(|&a, &b| {
            let (p, q) = (pts[a], pts[b]);
            p[0].total_cmp(&q[0]).then(p[1].total_cmp(&q[1])).then(p[2].total_cmp(&q[2]))
        });
        let sorted_pts: Vec<[f64; 3]> = order.iter().map(|&i| pts[i]).collect();
        let f = Frame::fit(&sorted_pts).unwrap();
        let local = f.to_local_all(&sorted_pts);
        let c = generate(&local, &cfg.candidates).unwrap();
        let p = model().predict(&face_input(&local, &c, model().config().use_context)).unwrap();
        let want: Vec<[u32; 4]> = c
            .quads
            .iter()
            .zip(&p)
            .filter(|(_, &p)| p > threshold)
            .map(|(q, _)| q.map(|v| order[v as usize] as u32))
            .collect();
        assert_eq!(m.quads, want, "threshold {threshold}");
        assert_eq!(m.vertices, pts);
        if threshold == 0.0 {
            assert_eq!(m.quads.len(), c.quads.len(), "threshold 0 keeps every candidate");
        }
    }
}

#[test]
fn thresholds_outside_0_1_are_errors() {
    let pts = cloud(1, 1);
    for t in [-0.1f32, 1.0, 1.5, f32::NAN] {
        let cfg = ReconstructConfig { threshold: t, ..Default::default() };
        assert!(reconstruct(&pts, model(), &cfg).is_err(), "threshold {t}");
    }
}

/// Runs `reconstruct` on a degenerate input: `Ok` must be a valid mesh keeping the
/// input; `Err` is accepted (a clean error); a panic fails the test.
fn ok_or_clean_error(pts: &[[f64; 3]], what: &str) -> Option<String> {
    match reconstruct(pts, model(), &ReconstructConfig::default()) {
        Ok(m) => {
            assert_valid(&m);
            assert_prefix(&m, pts);
            None
        }
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.is_empty(), "{what}: empty error message");
            Some(msg)
        }
    }
}

#[test]
fn too_few_points_and_non_finite_are_errors() {
    let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    for n in 0..=3 {
        assert!(reconstruct(&p[..n], model(), &ReconstructConfig::default()).is_err(), "{n} points");
    }
    let base = cloud(0, 5);
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        for (i, axis) in [(0usize, 0usize), (17, 1), (base.len() - 1, 2)] {
            let mut pts = base.clone();
            pts[i][axis] = bad;
            let e =
                reconstruct(&pts, model(), &ReconstructConfig::default()).expect_err("non-finite accepted");
            assert!(e.to_string().contains(&format!("point {i} ")), "{e}");
        }
    }
}

#[test]
fn degenerate_clouds_never_panic() {
    // All identical: no extent, an error.
    assert!(ok_or_clean_error(&[[1.5, -2.0, 3.0]; 50], "identical").is_some());
    // Collinear.
    let line: Vec<[f64; 3]> = (0..60).map(|i| [i as f64 * 0.1, 2.0 * i as f64 * 0.1, 1.0]).collect();
    ok_or_clean_error(&line, "collinear");
    // Four points only (the minimum), a square.
    ok_or_clean_error(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]], "square");
    // Coplanar regular grid (many exact ties in the kNN distances).
    let grid: Vec<[f64; 3]> = shapes::grid(12, 12, 1.0, 1.0).vertices;
    ok_or_clean_error(&grid, "grid");
    // A grid with every point present 3 times (exact duplicates).
    let dup: Vec<[f64; 3]> = grid.iter().flat_map(|&p| [p, p, p]).collect();
    ok_or_clean_error(&dup, "duplicated grid");
    // A closed shape with every point twice, and a cloud that is mostly one point.
    let c = cloud(0, 9);
    let dup2: Vec<[f64; 3]> = c.iter().flat_map(|&p| [p, p]).collect();
    ok_or_clean_error(&dup2, "duplicated sphere");
    let mut lump = vec![[0.25, 0.5, 0.75]; 200];
    lump.extend_from_slice(&c[..20]);
    ok_or_clean_error(&lump, "lump");
    // Extent at the rounding level of huge coordinates.
    let far: Vec<[f64; 3]> = (0..10).map(|i| [1e300, 1e300 + i as f64, 0.0]).collect();
    ok_or_clean_error(&far, "far");
    // Huge and tiny magnitudes (overflow of squared distances, subnormals).
    let big: Vec<[f64; 3]> = c.iter().map(|p| [p[0] * 1e200, p[1] * 1e200, p[2] * 1e200]).collect();
    ok_or_clean_error(&big, "1e200");
    let tiny: Vec<[f64; 3]> = c.iter().map(|p| [p[0] * 1e-300, p[1] * 1e-300, p[2] * 1e-300]).collect();
    ok_or_clean_error(&tiny, "1e-300");
}

/// Regression: the frame's squared distances overflowed at 1e200 (vanished at
/// 1e-200), so such clouds were refused as "all points are identical", and the
/// post-process ran in input coordinates, where areas overflow. Power-of-two scaling
/// is exact, so the faces must be the unit cloud's and the vertices hole filling adds
/// must be the unit cloud's, scaled.
#[test]
fn extreme_power_of_two_scales_give_identical_faces() {
    let cfg = ReconstructConfig { threshold: 0.3, ..Default::default() };
    // The first of these clouds for which the (untrained) model makes the hole filling
    // add vertices, so that their mapping back to the input's frame is checked below
    // (cloud(0, 3) did until session 25's unfold changed the holes).
    let (pts, a) = (0..4u8)
        .flat_map(|kind| (0..8u64).map(move |seed| cloud(kind, seed)))
        .map(|pts| {
            let a = reconstruct(&pts, model(), &cfg).expect("reconstruct");
            (pts, a)
        })
        .find(|(pts, a)| a.vertices.len() > pts.len())
        .expect("no cloud where the hole filling adds a vertex: the check below would be vacuous");
    assert!(!a.quads.is_empty());
    for e in [-1000, -700, 700, 1000] {
        let k = 2f64.powi(e);
        let scaled: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|c| c * k)).collect();
        let b = reconstruct(&scaled, model(), &cfg).unwrap_or_else(|err| panic!("2^{e}: {err}"));
        assert_eq!(a.quads, b.quads, "2^{e}");
        assert_valid(&b);
        assert_prefix(&b, &scaled);
        assert_eq!(a.vertices.len(), b.vertices.len(), "2^{e}");
        for (u, v) in a.vertices[pts.len()..].iter().zip(&b.vertices[pts.len()..]) {
            let back = v.map(|c| c / k);
            assert!(point2quad::math::dist_sq(*u, back).sqrt() < 1e-9, "2^{e}: {u:?} vs {back:?}");
        }
    }
}

/// `max_rounds` and the small-cloud limit run the model's first rounds: the raw faces
/// equal those of the same stages by hand with the rounds cut short (the shipped
/// weights, five rounds); a cloud of exactly `small_cloud_points` points is not small;
/// and the rounds change the faces, so the check can fail.
#[test]
fn fewer_rounds_score_as_the_rounds_cut_short() {
    let model = shipped();
    let all = model.refiner().expect("test: the shipped weights have rounds").rounds.len();
    let mut changed = 0;
    for (kind, seed) in [(0u8, 3u64), (1, 4), (2, 5), (3, 6)] {
        let pts = cloud(kind, seed);
        // No small-cloud limit unless a case sets one.
        let raw = ReconstructConfig {
            run_postprocess: false,
            second_pass: None,
            small_cloud_points: 0,
            ..Default::default()
        };
        // The same stages by hand, on the points in coordinate order, with `n` rounds.
        let mut order: Vec<usize> = (0..pts.len()).collect();
        order.sort_by(|&a, &b| {
            let (p, q) = (pts[a], pts[b]);
            p[0].total_cmp(&q[0]).then(p[1].total_cmp(&q[1])).then(p[2].total_cmp(&q[2]))
        });
        let sorted_pts: Vec<[f64; 3]> = order.iter().map(|&i| pts[i]).collect();
        let local = Frame::fit(&sorted_pts).unwrap().to_local_all(&sorted_pts);
        let c = generate(&local, &raw.candidates).unwrap();
        let base = model
            .predict_base(&local, &c.quads, &face_input(&local, &c, model.config().use_context))
            .unwrap();
        let by_hand = |n: usize| -> Vec<[u32; 4]> {
            let mut cut = model.refiner().unwrap().clone();
            cut.rounds.truncate(n);
            let p = cut.apply(&model.params, &local, &c.quads, &base).unwrap();
            c.quads
                .iter()
                .zip(&p)
                .filter(|(_, &p)| p > raw.threshold)
                .map(|(q, _)| q.map(|v| order[v as usize] as u32))
                .collect()
        };
        let run = |cfg: &ReconstructConfig| reconstruct(&pts, model, cfg).expect("reconstruct").quads;
        let full = run(&raw);
        assert_eq!(full, by_hand(all), "kind {kind}: every round");
        for n in [0, 2, all - 1] {
            let want = by_hand(n);
            assert_eq!(
                run(&ReconstructConfig { max_rounds: Some(n), ..raw.clone() }),
                want,
                "kind {kind}: --rounds {n}"
            );
            let small =
                ReconstructConfig { small_cloud_points: pts.len() + 1, small_cloud_rounds: n, ..raw.clone() };
            assert_eq!(run(&small), want, "kind {kind}: a small cloud, {n} rounds");
            let not_small = ReconstructConfig { small_cloud_points: pts.len(), ..small.clone() };
            assert_eq!(run(&not_small), full, "kind {kind}: {} points is not fewer", pts.len());
            // Both limits: the lower one holds.
            let both = ReconstructConfig { max_rounds: Some(all), ..small };
            assert_eq!(run(&both), want, "kind {kind}: both limits");
            changed += usize::from(want != full);
        }
    }
    assert!(
        changed >= 4,
        "the rounds changed the faces in only {changed} of 12 cases: the check could not fail"
    );
}
