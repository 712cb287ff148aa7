//! Refinement rounds (`pipeline::refine`): the features equal a brute-force reference
//! (straight from their definitions, O(M²)) on random candidate sets, do not depend on
//! where a quad's cyclic order starts nor on the order of the candidate list; a model
//! with rounds keeps its classifier exactly, round-trips through its weights file and
//! config text; training the rounds separates real faces from rivals that the base
//! probabilities cannot (average precision on held-out shapes rises).

use point2quad::mesh::shapes;
use point2quad::nn::checkpoint::Checkpoint;
use point2quad::pipeline::candidates::CandidateConfig;
use point2quad::pipeline::dataset::build_sample;
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::refine::{
    refine_features, score_stats, train_refiner, RefineSample, RefineTrainConfig, SideRule, REFINE_DIM,
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

/// The features of candidate `c`, from the definitions in `refine_features`' doc.
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
) -> Option<Vec<f32>> {
    let q = quads[c];
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
    Some(row)
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
                let Some(want) = reference_row(&quads, sides, &p, &base, c) else { continue };
                let got = &f[c * REFINE_DIM..(c + 1) * REFINE_DIM];
                for (j, (g, w)) in got.iter().zip(&want).enumerate() {
                    // Columns 14–17 are sums (another order of additions); the rest are exact.
                    let tol = if (14..18).contains(&j) { 1e-5 } else { 0.0 };
                    prop_assert!((g - w).abs() <= tol, "{:?} candidate {} column {}: {} vs {}", rule, c, j, g, w);
                }
            }
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
        for rule in [SideRule::Direction, SideRule::Normals] {
        let f = refine_features(&quads, &pts, rule, &p, &base).unwrap();
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
        let f2 = refine_features(&q2, &pts, rule, &p2, &b2).unwrap();
        for (i, &c) in perm.iter().enumerate() {
            let (a, b) = (&f[c * REFINE_DIM..(c + 1) * REFINE_DIM], &f2[i * REFINE_DIM..(i + 1) * REFINE_DIM]);
            for (j, (x, y)) in a.iter().zip(b).enumerate() {
                let tol = if (14..18).contains(&j) { 1e-5 } else { 0.0 };
                prop_assert!((x - y).abs() <= tol, "{:?} candidate {} column {}: {} vs {}", rule, c, j, x, y);
            }
        }
        }
    }
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
    ] {
        let err = ModelConfig::from_text(&format!("{plain}{extra}"), Path::new("cfg")).unwrap_err();
        assert!(err.to_string().contains(why), "{extra:?}: {err}");
    }
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
