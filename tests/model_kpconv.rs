//! The Point2Quad model with its KPConv point encoder (KPFCNN → gather ×4 corners → concat with
//! the face encoder → classifier): whole-model gradient checks through the tape, checkpoint
//! round trips (predictions bit-identical, kernel points read from the file), training and
//! resuming bit-exactly on a tiny dataset, `reconstruct` end to end, and the CLI
//! (`train --config default_kp`, `reconstruct --model`).

#[path = "common/kpconv.rs"]
mod kpc;
#[path = "common/training.rs"]
mod training;
use training::{bits, check_resume, samples, Resumed};

use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::{PolyMesh, QuadMesh};
use point2quad::mesh::shapes;
use point2quad::mesh::validate::validate;
use point2quad::nn::kpfcnn::{prepare, KpfcnnConfig};
use point2quad::pipeline::dataset::Sample;
use point2quad::pipeline::model::{corner_indices, Model, ModelConfig};
use point2quad::pipeline::noise::{noise_points, NoiseConfig};
use point2quad::pipeline::reconstruct::{reconstruct, ReconstructConfig};
use point2quad::pipeline::train::{evaluate, sample_input};
use point2quad::rng::Rng;
use point2quad::tensor::{gradcheck, GradCheckConfig, Tensor};
use std::path::Path;

/// A small model for tests: tiny face net and classifier, and a 3-level KPFCNN whose cells
/// (0.15 / 0.3 / 0.6) suit clouds of ~100–300 points in the unit ball.
fn small_kp_config() -> ModelConfig {
    let d_p = 4;
    ModelConfig {
        preset: "test_kp".into(),
        face_widths: [16, 16, 16, 16, 16],
        classifier_widths: vec![16, 8],
        point_dim: d_p,
        point_encoder: Some(KpfcnnConfig { first_cell: 0.15, out_dim: d_p, ..kpc::tiny_config() }),
        ..ModelConfig::default_kp()
    }
}

/// M random candidates over `n` points and their random face features.
fn random_candidates(m: usize, n: usize, fin: usize, seed: u64) -> (Vec<[u32; 4]>, Vec<f32>) {
    let mut rng = Rng::new(seed);
    let corners = (0..m).map(|_| std::array::from_fn(|_| rng.below(n) as u32)).collect();
    let feats = (0..m * fin).map(|_| rng.f32() * 2.0 - 1.0).collect();
    (corners, feats)
}

/// Runs the gradient check of the whole model (KPFCNN, gather, face encoder, classifier) with
/// `cfg` on a 90-point cloud and `m` random candidates; returns (checked, skipped).
fn whole_model_gradcheck(cfg: ModelConfig, m: usize, gc: &GradCheckConfig) -> (usize, usize) {
    let pts = kpc::sphere_cloud(90, 0.5, [0.0; 3], 1);
    let mut model = Model::new(cfg, 4).unwrap();
    let kp_cfg = model.net.point_encoder().unwrap().config().clone();
    let pyr = prepare(&pts, &kp_cfg).unwrap();
    let fin = model.config().face_in();
    let (corners, feats) = random_candidates(m, pts.len(), fin, 9);
    let idx = corner_indices(&corners);
    let Model { net, params } = &mut model;
    if !gc.train {
        // One train-mode pass with batch-norm momentum 1 sets every running statistic to the
        // batch's, so eval mode normalises as a training step does. (With the initial mean 0 /
        // variance 1 the deep KPFCNN layers' gradients were ~1e-4, below the check's absolute
        // tolerance: a wrong gradient there could have passed.)
        let mut g = point2quad::tensor::Graph::new(params, false, true);
        let kp = net.point_encoder().expect("point model");
        let pf = kp.forward(&mut g, &pyr).unwrap();
        let x = g.input(Tensor::new(&[corners.len(), fin], feats.clone()).unwrap());
        net.forward(&mut g, x, Some((pf, idx.clone()))).unwrap();
    }
    let rep = gradcheck(
        params,
        |g| {
            let kp = net.point_encoder().expect("point model");
            let pf = kp.forward(g, &pyr)?;
            let x = g.input(Tensor::new(&[corners.len(), fin], feats.clone())?);
            net.forward(g, x, Some((pf, idx.clone())))
        },
        gc,
    )
    .unwrap();
    kpc::assert_report_passed(&rep, gc);
    (rep.checked, rep.skipped)
}

/// The whole model in eval mode (the inference path) with every LeakyReLU slope 1: batch norm
/// is affine (running statistics), so the logits are piecewise *linear* in every parameter —
/// only the classifier's ReLUs and the KPFCNN's max-pools switch — and central differences are
/// exact up to f32 rounding (see `kpconv_kpfcnn.rs` for why slope 0.1 makes finite differences
/// unreliable, not the gradients wrong). Covers every KPFCNN layer (through the gather and the
/// classifier), the face encoder and the classifier. Few candidates and a step of 3e-4 keep
/// switches inside the step rare: with 24 candidates, a few early-KPFCNN elements (upstream of
/// every max-pool and ReLU) differed by 2–7% from the analytic value, the signature of a switch
/// the double-step test missed; eps 1e-4 is at the f32 noise floor; here the worst ratio over
/// seeds 3–11 was 0.25–0.55 of the tolerance with at most 2 skipped.
#[test]
fn whole_model_gradcheck_eval_piecewise_linear() {
    let mut cfg = small_kp_config();
    cfg.leaky_slope = 1.0;
    cfg.bn_momentum = 1.0;
    if let Some(k) = &mut cfg.point_encoder {
        k.leaky_slope = 1.0;
        k.bn_momentum = 1.0;
    }
    let gc =
        GradCheckConfig { eps: 3e-4, max_per_param: 4, seed: 3, train: false, ..GradCheckConfig::default() };
    let (checked, _) = whole_model_gradcheck(cfg, 8, &gc);
    assert!(checked > 250, "{checked}");
}

/// Train mode (batch statistics everywhere, as in a training step), one KPFCNN level (no
/// max-pool) and slope 1: the function is smooth except at the classifier's ReLU kinks, which
/// the check detects and skips.
#[test]
fn whole_model_gradcheck_train_mode() {
    use point2quad::nn::kpfcnn::BlockKind::*;
    let mut cfg = small_kp_config();
    cfg.leaky_slope = 1.0;
    if let Some(k) = &mut cfg.point_encoder {
        k.leaky_slope = 1.0;
        k.blocks = vec![Simple, Resnetb, Resnetb];
    }
    let gc = GradCheckConfig { max_per_param: 4, seed: 5, train: true, ..GradCheckConfig::default() };
    let (checked, _) = whole_model_gradcheck(cfg, 24, &gc);
    assert!(checked > 150, "{checked}");
}

/// Predictions of `m` on every sample, as bits.
fn prediction_bits(m: &Model, data: &[Sample]) -> Vec<u32> {
    data.iter()
        .flat_map(|s| {
            let x = sample_input(s, m.config().face_in());
            m.predict_with_points(&s.points, &s.candidates, &x).unwrap()
        })
        .map(f32::to_bits)
        .collect()
}

#[test]
fn kp_model_trains_and_resumes_bit_identically() {
    let data = samples();
    let va = &data[2..];
    let fresh = Model::new(small_kp_config(), 5).unwrap();
    let Resumed { straight, reps, .. } = check_resume(small_kp_config(), &data);
    let a = bits(&straight);
    // Training really reached the point encoder: its weights and batch-norm statistics moved,
    // its kernel points (fixed geometry) did not.
    let before = bits(&fresh);
    for ((name, t0), (_, t1)) in before.iter().zip(&a) {
        if name.ends_with(".kernel_points") {
            assert_eq!(t0, t1, "{name} changed");
        } else if name == "kpfcnn.enc0.kpconv.weight" || name == "kpfcnn.head.bn.running_mean" {
            assert_ne!(t0, t1, "{name} did not change");
        }
    }
    assert!(before.iter().any(|(n, _)| n == "kpfcnn.head.bn.running_mean"), "BN buffer names changed");
    // The trained model's predictions survive a weights-only round trip bit for bit.
    let back = Model::from_bytes(&straight.to_checkpoint(None).to_bytes(), Path::new("w")).unwrap();
    assert_eq!(prediction_bits(&back, &data), prediction_bits(&straight, &data));
    assert_eq!(evaluate(&back, va, 0.5).unwrap(), reps[1].val);
}

/// The loaded model uses the kernel points stored in the file: moving one in the file changes
/// the predictions (so a change of the placement code cannot silently alter trained models).
#[test]
fn kernel_points_come_from_the_checkpoint() {
    let data = samples();
    let m = Model::new(small_kp_config(), 2).unwrap();
    let mut ck = m.to_checkpoint(None);
    let back = Model::from_checkpoint(&ck, Path::new("a")).unwrap();
    assert_eq!(prediction_bits(&back, &data), prediction_bits(&m, &data));
    let (_, kp) = ck.tensors.iter_mut().find(|(n, _)| n == "kpfcnn.enc0.kpconv.kernel_points").unwrap();
    for x in kp.data_mut().iter_mut().skip(3) {
        *x *= 0.5;
    }
    let moved = Model::from_checkpoint(&ck, Path::new("b")).unwrap();
    assert_ne!(prediction_bits(&moved, &data), prediction_bits(&m, &data));
    // A non-finite kernel point is a checkpoint error, not a panic.
    let (_, kp) = ck.tensors.iter_mut().find(|(n, _)| n == "kpfcnn.enc1.kpconv.kernel_points").unwrap();
    kp.data_mut()[4] = f32::NAN;
    let e = Model::from_checkpoint(&ck, Path::new("c.p2qm")).err().expect("NaN kernel point accepted");
    assert!(e.to_string().contains("c.p2qm") && e.to_string().contains("kernel"), "{e}");
}

/// A noisy cloud of a few hundred points.
fn cloud(seed: u64) -> Vec<[f64; 3]> {
    let mut rng = Rng::new(seed);
    let mesh = shapes::random_pose(&shapes::cube_sphere(6), &mut rng);
    let mut pts = mesh.vertices.clone();
    pts.extend(noise_points(&mesh, &NoiseConfig::default(), &mut rng).unwrap());
    pts
}

fn assert_valid(m: &QuadMesh, input: &[[f64; 3]]) {
    assert_eq!(&m.vertices[..input.len()], input, "input points not at the front, bit for bit");
    let he = HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).expect("output is not manifold");
    validate(&he).expect("output fails validate");
}

#[test]
fn reconstruct_with_a_point_encoder_gives_a_valid_mesh() {
    let pts = cloud(3);
    for model in
        [Model::new(small_kp_config(), 1).unwrap(), Model::new(ModelConfig::default_kp(), 1).unwrap()]
    {
        // Threshold 0 hands every candidate to the post-process; 0.5 whatever the
        // untrained network says.
        for threshold in [0.0, 0.5] {
            let cfg = ReconstructConfig { threshold, ..ReconstructConfig::default() };
            let mesh = reconstruct(&pts, &model, &cfg).unwrap();
            assert_valid(&mesh, &pts);
            if threshold == 0.0 {
                assert!(!mesh.quads.is_empty());
            }
        }
    }
}

/// Tiny and degenerate clouds through a point-encoder model: a valid mesh or a clean error,
/// never a panic (the KPFCNN sees pyramids of a few points, duplicates, a flat or collinear
/// cloud). With threshold 0 the square, its duplicate and the flat grid give faces.
#[test]
fn tiny_and_degenerate_clouds_do_not_panic() {
    let model = Model::new(ModelConfig::default_kp(), 1).unwrap();
    let square = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let mut dup = square.clone();
    dup.extend(square.iter().copied());
    let line: Vec<[f64; 3]> = (0..6).map(|i| [i as f64, 0.0, 0.0]).collect();
    let flat: Vec<[f64; 3]> = (0..25).map(|i| [(i % 5) as f64, (i / 5) as f64, 0.0]).collect();
    let mut faces = 0;
    for (name, pts) in [("square", square), ("duplicates", dup), ("line", line), ("flat", flat)] {
        let cfg = ReconstructConfig { threshold: 0.0, ..ReconstructConfig::default() };
        match reconstruct(&pts, &model, &cfg) {
            Ok(mesh) => {
                assert_valid(&mesh, &pts);
                faces += mesh.quads.len();
            }
            Err(e) => assert!(!e.to_string().is_empty(), "{name}"),
        }
    }
    assert!(faces > 0, "no cloud reached the point encoder");
}

// ---- The CLI ----

struct Scratch(std::path::PathBuf);

impl Scratch {
    fn new(tag: &str) -> Scratch {
        let d = std::env::temp_dir().join(format!("p2q_model_kpconv_{tag}_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("test: scratch dir");
        Scratch(d)
    }
    fn p(&self, name: &str) -> String {
        self.0.join(name).display().to_string()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn ok(args: &[&str]) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_point2quad"))
        .args(args)
        .env("RAYON_NUM_THREADS", "1")
        .output()
        .expect("test: run the binary");
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success() && !err.contains("panicked"), "{args:?} failed: {err}");
    err
}

#[test]
fn cli_trains_resumes_and_reconstructs_with_default_kp() {
    let s = Scratch::new("cli");
    let meshes = s.p("meshes");
    std::fs::create_dir_all(&meshes).unwrap();
    for (name, m) in [("a_sphere", shapes::cube_sphere(4)), ("b_torus", shapes::torus(12, 6, 1.0, 0.4))] {
        let path = Path::new(&meshes).join(format!("{name}.obj"));
        point2quad::io::mesh_io::write_mesh(&path, &PolyMesh::from(&m)).unwrap();
    }
    let data = s.p("data");
    ok(&["dataset", "--meshes", &meshes, "--out", &data, "--seed", "3"]);
    let model = s.p("m.p2qm");
    let train_args = |epochs: &'static str| {
        vec![
            "train",
            "--data",
            &data,
            "--out",
            &model,
            "--config",
            "default_kp",
            "--epochs",
            epochs,
            "--val-fraction",
            "0",
            "--max-candidates",
            "300",
        ]
    };
    let err = ok(&train_args("1"));
    assert!(err.contains("default_kp") && err.contains("epoch 1/1"), "{err}");
    let loaded = Model::load(Path::new(&model)).unwrap();
    assert_eq!(loaded.config(), &ModelConfig::default_kp());
    let ckpt = format!("{model}.ckpt");
    let mut resume = train_args("2");
    resume.extend(["--resume", &ckpt]);
    let err = ok(&resume);
    assert!(err.contains("epoch 2/2"), "{err}");
    let cloud_path = s.p("cloud.xyz");
    let pts = cloud(4);
    let text: String = pts.iter().map(|p| format!("{:?} {:?} {:?}\n", p[0], p[1], p[2])).collect();
    std::fs::write(&cloud_path, text).unwrap();
    let out = s.p("out.obj");
    ok(&["reconstruct", &cloud_path, "-o", &out, "--model", &model, "--threshold", "0"]);
    let pm = point2quad::io::mesh_io::read_mesh(Path::new(&out)).unwrap();
    let q = pm.to_quads().expect("pure quad");
    assert!(!q.quads.is_empty());
    assert_valid(&q, &pts);
}
