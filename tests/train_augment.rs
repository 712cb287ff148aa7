//! Training augmentation (`pipeline::augment`, `train`'s per-step scale and jitter):
//! the identity reproduces the dataset's stored face input bit for bit; a uniform scale
//! leaves it unchanged (F_info and the context are scale-free) while an anisotropic one
//! changes it exactly as the definitions say (checked against DESIGN §2's formulas in
//! f64 on the mapped points); training with augmentation is deterministic, resumes
//! bit-exactly, and really differs from training without; and the `train` CLI options
//! parse and refuse bad values with usage errors.

use std::process::{Command, Output};
use std::sync::OnceLock;

use point2quad::pipeline::augment::{face_rows, Augmentation, SampleGeometry};
use point2quad::pipeline::candidates::CandidateConfig;
use point2quad::pipeline::dataset::{save_sample, Sample};
use point2quad::pipeline::features::{to_local_frame, CONTEXT_DIM, F_INFO_DIM};
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::train::{sample_input, train};
use point2quad::rng::Rng;
use proptest::prelude::*;

#[path = "common/augment.rs"]
mod reference;
#[path = "common/scratch.rs"]
mod scratch;
#[path = "common/training.rs"]
mod training;

const FIN: usize = F_INFO_DIM + CONTEXT_DIM;

/// The three training samples and their geometry (built once: proptest calls the body
/// many times).
fn data() -> &'static [(Sample, SampleGeometry)] {
    static D: OnceLock<Vec<(Sample, SampleGeometry)>> = OnceLock::new();
    D.get_or_init(|| {
        training::samples()
            .into_iter()
            .map(|s| {
                let g = SampleGeometry::new(&s.points, &s.candidates, &training::candidate_cfg()).unwrap();
                (s, g)
            })
            .collect()
    })
}

/// Every candidate's face input (`fin` columns) for `aug`, and the recomputed spacing.
fn augmented(s: &Sample, g: &SampleGeometry, aug: &Augmentation, fin: usize) -> (Vec<f32>, Vec<f32>) {
    let moved = aug.apply(&s.points);
    let (normals, spacing) = g.recompute(&moved, aug);
    let picks: Vec<usize> = (0..s.labels.len()).collect();
    (face_rows(s, &picks, fin, &moved, &normals, &spacing), spacing)
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-4 * (1.0 + b.abs())
}

/// Scale 1, no jitter, no rotation: the recomputed input is the stored one, bit for
/// bit, both with the dataset's candidate settings and with the training default (a
/// kNN row's prefix does not depend on k).
#[test]
fn identity_reproduces_the_stored_features_exactly() {
    for cfg in [training::candidate_cfg(), CandidateConfig::default()] {
        for s in training::samples() {
            let g = SampleGeometry::new(&s.points, &s.candidates, &cfg).unwrap();
            let aug =
                Augmentation::draw(&mut Rng::new(1), false, Some((1.0, 1.0)), 0.0, g.spacing()).unwrap();
            assert_eq!(aug.apply(&s.points), s.points, "{}: scale 1 moved points", s.name);
            for fin in [F_INFO_DIM, FIN] {
                let (got, _) = augmented(&s, &g, &aug, fin);
                let want = sample_input(&s, fin);
                assert_eq!(got.len(), want.len());
                for (i, (a, b)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        a.to_bits() == b.to_bits(),
                        "{}: candidate {} column {}: {a} vs stored {b}",
                        s.name,
                        i / fin,
                        i % fin
                    );
                }
            }
        }
    }
}

/// Geometry rebuilt from inconsistent samples is an error, not a panic.
#[test]
fn geometry_of_bad_samples_is_an_error() {
    let s = &training::samples()[0];
    let mut bad = s.candidates.clone();
    bad[3][1] = s.points.len() as u32;
    assert!(SampleGeometry::new(&s.points, &bad, &CandidateConfig::default())
        .unwrap_err()
        .to_string()
        .contains("candidate 3"));
    let mut pts = s.points.clone();
    pts[7][2] = f32::NAN;
    assert!(SampleGeometry::new(&pts, &s.candidates, &CandidateConfig::default())
        .unwrap_err()
        .to_string()
        .contains("point 7"));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// F_info in the candidate's own frame (what `local_frame` models read) does not
    /// change under a rotation of the cloud, while the cloud-frame rows do; and the
    /// local row is a rotation of the cloud-frame one (the Gram matrix of its 4 offsets
    /// and 4 corner normals is kept) that puts the first edge on +x in the xz-plane and
    /// the diagonal normal on +z.
    #[test]
    fn local_frame_f_info_is_rotation_invariant(which in 0usize..3, seed in any::<u64>()) {
        let (s, g) = &data()[which];
        let aug = Augmentation::draw(&mut Rng::new(seed), true, None, 0.0, g.spacing()).unwrap();
        let (mut got, _) = augmented(s, g, &aug, F_INFO_DIM);
        let mut want = sample_input(s, F_INFO_DIM);
        let moved_cols = got.iter().zip(&want).filter(|(a, b)| !close(**a, **b)).count();
        prop_assert!(moved_cols > 0, "a random rotation left every cloud-frame value in place");
        let vecs = |r: &[f32]| -> Vec<[f64; 3]> {
            [0, 3, 6, 9, 17, 20, 23, 26].iter().map(|&c| [r[c] as f64, r[c + 1] as f64, r[c + 2] as f64]).collect()
        };
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        for (gr, wr) in got.chunks_mut(F_INFO_DIM).zip(want.chunks_mut(F_INFO_DIM)) {
            let before = vecs(wr);
            let shape: Vec<f32> = wr[12..17].to_vec();
            to_local_frame(gr);
            to_local_frame(wr);
            for (c, (a, b)) in gr.iter().zip(wr.iter()).enumerate() {
                prop_assert!(close(*a, *b), "column {}: {} vs {}", c, a, b);
            }
            prop_assert_eq!(&wr[12..17], &shape[..]);
            let after = vecs(wr);
            let scale = before.iter().map(|v| dot(*v, *v)).fold(1.0f64, f64::max);
            for i in 0..8 {
                for j in 0..8 {
                    let (x, y) = (dot(before[i], before[j]), dot(after[i], after[j]));
                    prop_assert!((x - y).abs() <= 1e-4 * scale, "Gram ({}, {}): {} vs {}", i, j, x, y);
                }
            }
            let p = &after[..4];
            prop_assert!(p[1][1].abs() <= 1e-4 * scale.sqrt() && p[1][0] > 0.0, "first edge {:?}", p[1]);
            let d1 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
            let d2 = [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]];
            let n = [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]];
            let l = dot(n, n).sqrt();
            prop_assert!((n[0].abs() + n[1].abs()) <= 1e-4 * l && n[2] > 0.0, "diagonal normal {:?}", n);
        }
    }

    /// A uniform scale (through the random-frame path) leaves every column unchanged
    /// (up to f32 rounding) and scales every point's spacing by exactly that factor.
    #[test]
    fn uniform_scale_leaves_the_face_input_unchanged(which in 0usize..3, c in 0.5f32..2.0, seed in any::<u64>()) {
        let (s, g) = &data()[which];
        let aug = Augmentation::draw(&mut Rng::new(seed), false, Some((c, c)), 0.0, g.spacing()).unwrap();
        let (got, spacing) = augmented(s, g, &aug, FIN);
        let want = sample_input(s, FIN);
        for (i, (a, b)) in got.iter().zip(&want).enumerate() {
            prop_assert!(close(*a, *b), "candidate {} column {}: {} vs {}", i / FIN, i % FIN, a, b);
        }
        for (a, b) in spacing.iter().zip(g.spacing()) {
            prop_assert!((a / b - c).abs() <= 1e-5 * c, "spacing {} vs {} × {}", a, b, c);
        }
    }

    /// An anisotropic scale (with a rotation) changes the input, and as the
    /// definitions say: the shape columns equal DESIGN §2's formulas on the mapped
    /// points (f64 reference), the relative positions are M times the stored ones
    /// times one factor per candidate (the spacing ratio, within [1/1.1, 1/0.9]), the
    /// spacing ratio of every point lies in [0.9, 1.1], and the normals agree in sign
    /// with the mapped dataset normals.
    #[test]
    fn anisotropic_scale_changes_the_input_as_defined(which in 0usize..3, seed in any::<u64>()) {
        let (s, g) = &data()[which];
        let aug = Augmentation::draw(&mut Rng::new(seed), true, Some((0.9, 1.1)), 0.0, g.spacing()).unwrap();
        let moved = aug.apply(&s.points);
        let (normals, spacing) = g.recompute(&moved, &aug);
        let picks: Vec<usize> = (0..s.labels.len()).collect();
        let got = face_rows(s, &picks, FIN, &moved, &normals, &spacing);
        let want = sample_input(s, FIN);
        let m = &aug.linear;
        let mut changed = 0.0f32;
        for (c, (row, old)) in got.chunks_exact(FIN).zip(want.chunks_exact(FIN)).enumerate() {
            let q = s.candidates[c];
            let p = q.map(|v| reference::apply(m, s.points[v as usize]));
            let shape = reference::shape_columns(p);
            for (j, r) in shape.iter().enumerate() {
                prop_assert!(close(row[12 + j], *r as f32), "candidate {} column {}: {} vs {}", c, 12 + j, row[12 + j], r);
            }
            // Relative positions: row = k · M · old for one k per candidate.
            let mv = |i: usize| {
                let v = [old[3 * i], old[3 * i + 1], old[3 * i + 2]];
                reference::apply(m, v)
            };
            let len = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let k = len([row[3] as f64, row[4] as f64, row[5] as f64]) / len(mv(1));
            prop_assert!((1.0 / 1.1 - 1e-4..=1.0 / 0.9 + 1e-4).contains(&k), "candidate {}: factor {}", c, k);
            for i in 1..4 {
                let r = mv(i);
                for a in 0..3 {
                    prop_assert!(close(row[3 * i + a], (k * r[a]) as f32), "candidate {} column {}", c, 3 * i + a);
                }
            }
            // Context: edge lengths over the recomputed spacing; other columns kept.
            for i in 0..4 {
                let (a, b) = (q[i] as usize, q[(i + 1) % 4] as usize);
                let e = len([p[(i + 1) % 4][0] - p[i][0], p[(i + 1) % 4][1] - p[i][1], p[(i + 1) % 4][2] - p[i][2]]);
                let want_len = e / (0.5 * (spacing[a] as f64 + spacing[b] as f64));
                prop_assert!(close(row[F_INFO_DIM + 6 + i], want_len as f32));
            }
            for j in [0, 1, 2, 3, 4, 5, 14, 15] {
                prop_assert_eq!(row[F_INFO_DIM + j].to_bits(), old[F_INFO_DIM + j].to_bits());
            }
            for j in 3..F_INFO_DIM {
                changed = changed.max((row[j] - old[j]).abs());
            }
        }
        prop_assert!(changed > 1e-3, "an anisotropic scale changed nothing (max {})", changed);
        for (i, (a, b)) in spacing.iter().zip(g.spacing()).enumerate() {
            prop_assert!((0.9 - 1e-5..=1.1 + 1e-5).contains(&(a / b)), "point {}: spacing ratio {}", i, a / b);
        }
        for q in &s.candidates {
            for &v in q {
                let (n, n0) = (normals[v as usize], g.normals()[v as usize]);
                let r = reference::apply(&aug.inverse_transpose, n0);
                let dot = n[0] as f64 * r[0] + n[1] as f64 * r[1] + n[2] as f64 * r[2];
                let unit = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                prop_assert!(dot >= 0.0 && (unit - 1.0).abs() < 1e-5, "point {}: {:?} vs {:?}", v, n, r);
            }
        }
    }
}

/// Training with augmentation on is deterministic and resumes bit-exactly (the
/// draws come from the checkpointed RNG), and it really trains on other inputs than
/// training without it.
#[test]
fn augmented_training_resumes_exactly_and_differs_from_plain() {
    let data = training::samples();
    let cfg = training::train_cfg(2);
    assert!(cfg.scale.is_some() && cfg.jitter > 0.0 && cfg.rotate, "the shared config augments");
    let training::Resumed { straight, .. } = training::check_resume(ModelConfig::default_preset(), &data);
    let mut plain = Model::new(ModelConfig::default_preset(), 5).unwrap();
    let c = point2quad::pipeline::train::TrainConfig { scale: None, jitter: 0.0, ..cfg.clone() };
    train(&mut plain, &data[..2], &data[2..], &c, None, &mut training::no_progress, &mut |_, _| Ok(()))
        .unwrap();
    assert_ne!(training::bits(&plain), training::bits(&straight), "scale and jitter changed nothing");
    // Bad settings are refused before anything trains.
    let mut m = Model::new(ModelConfig::default_preset(), 5).unwrap();
    for c in [
        point2quad::pipeline::train::TrainConfig { scale: Some((1.1, 0.9)), ..cfg.clone() },
        point2quad::pipeline::train::TrainConfig { scale: Some((0.0, 1.0)), ..cfg.clone() },
        point2quad::pipeline::train::TrainConfig { jitter: -1.0, ..cfg.clone() },
    ] {
        let e = train(&mut m, &data[..2], &[], &c, None, &mut training::no_progress, &mut |_, _| Ok(()));
        assert!(e.unwrap_err().to_string().contains("augmentation"));
    }
}

fn p2q(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_point2quad")).args(args).output().expect("test: run the binary")
}

#[test]
fn cli_augmentation_options_parse_and_refuse_bad_values() {
    let dir = scratch::Scratch::new("train_augment");
    let (data, out) = (dir.p("data"), dir.p("m.p2qm"));
    std::fs::create_dir_all(&data).unwrap();
    for s in training::samples() {
        save_sample(&dir.path("data").join(format!("{}.p2qs", s.name)), &s).unwrap();
    }
    let base = ["train", "--data", &data, "--out", &out, "--epochs", "1", "--val-fraction", "0"];
    let refused: [(&[&str], &str); 11] = [
        (&["--scale", "0,1.1"], "MIN must be positive"),
        (&["--scale", "-0.5,1.1"], "MIN must be positive"),
        (&["--scale", "1.2,1.1"], "MIN must not exceed MAX"),
        (&["--scale", "inf,2"], "finite"),
        (&["--scale", "0.9"], "expected MIN,MAX"),
        (&["--scale", "a,1"], "cannot parse \"a\""),
        (&["--jitter", "-0.1"], "--jitter must be between 0 and 1, got -0.1"),
        (&["--jitter", "2"], "--jitter must be between 0 and 1, got 2"),
        (&["--jitter", "NaN"], "--jitter must be between 0 and 1, got NaN"),
        (&["--no-augment", "--scale", "0.9,1.1"], "--no-augment cannot be combined"),
        (&["--no-augment", "--no-rotate"], "--no-augment cannot be combined"),
    ];
    for (extra, msg) in refused {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        let o = p2q(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(msg), "{extra:?}: {err}");
        assert!(!dir.path("m.p2qm").exists(), "{extra:?}: trained anyway");
    }
    // Accepted values train; `--scale 1,1 --jitter 0 --no-rotate` is `--no-augment`
    // (same weights), and the defaults differ from both.
    let run = |extra: &[&str]| -> Vec<u8> {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        let o = p2q(&args);
        assert!(o.status.success(), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(&out).unwrap()
    };
    let off = run(&["--no-augment"]);
    assert_eq!(run(&["--scale", "1,1", "--jitter", "0", "--no-rotate"]), off);
    assert_ne!(run(&[]), off);
    assert_ne!(run(&["--scale", "0.8,1.25", "--jitter", "0.02", "--no-rotate"]), off);
}
