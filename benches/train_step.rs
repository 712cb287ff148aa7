//! One training step of the Point2Quad model on a ~10,000-point sample, as `pipeline::train`
//! runs it (12,000 candidates drawn, the default augmentation — rotation, anisotropic scale,
//! jitter, face input recomputed from the moved points —, KPFCNN over every point in train
//! mode, loss, backward, SGD step), for the `default_kp` preset, with its KPFCNN part measured
//! on its own (pyramid, forward + backward) and the `default` preset (no point encoder) beside
//! it; plus inference (`predict_with_points`, what `reconstruct` runs) and the parameter counts.
//!
//! Each measured `train_step_*` call is a whole one-sample, one-epoch `train` run, so it also
//! builds the sample's augmentation geometry (kNN rows, normals, spacing), which a real run
//! does once per sample at its start: `augment_geometry_10k` is that part, and
//! `augment_step_10k` the per-step augmentation itself (draw, move the points, recompute
//! normals, spacing and the face input of 12,000 candidates). `train_step_rotate_only_*` is
//! the same step with rotation as the only augmentation (scale and jitter off).
//!
//! The sample: the `.p2qs` file named by `P2Q_BENCH_SAMPLE` if set (e.g. a dataset sample of a
//! train mesh), otherwise a synthetic torus (100 × 91 quads, 9,100 vertices + 10% noise points =
//! 10,010 points) built in memory. Lines: `bench <name> <value> <unit>`, medians after a
//! warm-up. Threads follow `RAYON_NUM_THREADS`.

use std::path::Path;

use point2quad::nn::kpfcnn::prepare;
use point2quad::pipeline::augment::{face_rows, Augmentation, SampleGeometry};
use point2quad::pipeline::candidates::CandidateConfig;
use point2quad::pipeline::dataset::{build_sample, load_sample, Sample};
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::noise::NoiseConfig;
use point2quad::pipeline::train::{sample_input, train, TrainConfig};
use point2quad::rng::Rng;
use point2quad::tensor::{Grads, Graph, Tensor};

#[path = "common/mod.rs"]
mod common;
use common::timed;

fn sample() -> Sample {
    if let Ok(p) = std::env::var("P2Q_BENCH_SAMPLE") {
        return load_sample(Path::new(&p)).expect("P2Q_BENCH_SAMPLE: a readable .p2qs sample");
    }
    let mesh = point2quad::mesh::shapes::torus(100, 91, 0.7, 0.3);
    build_sample("torus", &mesh, &NoiseConfig::default(), &CandidateConfig::default(), &mut Rng::new(1))
        .expect("synthetic sample")
}

/// One epoch over a one-sample training set (= one step), no validation, no checkpoint;
/// `full_augment` false: rotation only (what training did before scale and jitter).
fn step(model: &mut Model, s: &Sample, seed: u64, full_augment: bool) {
    let mut cfg = TrainConfig { epochs: 1, seed, ..TrainConfig::default() };
    if !full_augment {
        cfg.scale = None;
        cfg.jitter = 0.0;
    }
    train(model, std::slice::from_ref(s), &[], &cfg, None, &mut |_| {}, &mut |_, _| Ok(())).expect("step");
}

fn main() {
    let smoke = !std::env::args().any(|a| a == "--bench");
    let s = sample();
    let runs = if smoke { 1 } else { 7 };
    println!("bench train_step_threads {} threads", point2quad::par::num_threads());
    println!("bench train_step_sample_points {} points", s.points.len());
    println!("bench train_step_sample_candidates {} candidates", s.candidates.len());
    let cand_cfg = CandidateConfig::default();
    let (t, cpu) = timed(runs, || {
        std::hint::black_box(SampleGeometry::new(&s.points, &s.candidates, &cand_cfg).expect("geometry"));
    });
    println!("bench augment_geometry_10k {t:.1} ms");
    println!("bench augment_geometry_cpu_10k {cpu:.0} ms");
    let geo = SampleGeometry::new(&s.points, &s.candidates, &cand_cfg).expect("geometry");
    let tc = TrainConfig::default();
    let picks: Vec<usize> = (0..s.candidates.len()).step_by(8).take(tc.max_candidates).collect();
    let mut rng = Rng::new(4);
    let (t, cpu) = timed(runs, || {
        let aug = Augmentation::draw(&mut rng, tc.rotate, tc.scale, tc.jitter, geo.spacing()).expect("draw");
        let moved = aug.apply(&s.points);
        let (normals, spacing) = geo.recompute(&moved, &aug);
        std::hint::black_box(face_rows(&s, &picks, s.feature_dim as usize, &moved, &normals, &spacing));
    });
    println!("bench augment_step_10k {t:.1} ms");
    println!("bench augment_step_cpu_10k {cpu:.0} ms");
    for preset in ["default_kp", "default"] {
        let mut model = Model::new(ModelConfig::preset(preset).expect("preset"), 0).expect("model");
        println!("bench params_{preset} {} params", model.param_count());
        let mut seed = 0;
        let (t, cpu) = timed(runs, || {
            seed += 1;
            step(&mut model, &s, seed, true);
        });
        println!("bench train_step_10k_{preset} {t:.1} ms");
        println!("bench train_step_cpu_10k_{preset} {cpu:.0} ms");
        let (t, cpu) = timed(runs, || {
            seed += 1;
            step(&mut model, &s, seed, false);
        });
        println!("bench train_step_rotate_only_10k_{preset} {t:.1} ms");
        println!("bench train_step_rotate_only_cpu_10k_{preset} {cpu:.0} ms");
        let x = sample_input(&s, model.config().face_in());
        let (t, cpu) = timed(runs, || {
            std::hint::black_box(model.predict_with_points(&s.points, &s.candidates, &x).expect("predict"));
        });
        println!("bench predict_10k_all_candidates_{preset} {t:.1} ms");
        println!("bench predict_cpu_10k_all_candidates_{preset} {cpu:.0} ms");
        let Some(kp) = model.net.point_encoder().cloned() else { continue };
        let kcfg = kp.config().clone();
        println!("bench params_{preset}_kpfcnn {} params", kcfg.param_count());
        let rot = Rng::new(3).rotation();
        let rotated: Vec<[f32; 3]> = s
            .points
            .iter()
            .map(|p| {
                point2quad::math::to_f32(point2quad::math::mat_vec(
                    &rot,
                    [p[0] as f64, p[1] as f64, p[2] as f64],
                ))
            })
            .collect();
        let (t_prep, cpu) = timed(runs, || {
            std::hint::black_box(prepare(&rotated, &kcfg).expect("pyramid"));
        });
        println!("bench train_step_10k_{preset}_kpfcnn_prepare {t_prep:.1} ms");
        println!("bench train_step_cpu_10k_{preset}_kpfcnn_prepare {cpu:.0} ms");
        let pyr = prepare(&rotated, &kcfg).expect("pyramid");
        let upstream: Vec<f32> = {
            let mut r = Rng::new(2);
            (0..s.points.len() * kcfg.out_dim).map(|_| r.f32() - 0.5).collect()
        };
        let (t_fb, cpu) = timed(runs, || {
            let mut grads = Grads::new();
            let mut g = Graph::train(&mut model.params);
            let out = kp.forward(&mut g, &pyr).expect("forward");
            let u = Tensor::new(&[s.points.len(), kcfg.out_dim], upstream.clone()).expect("shape");
            g.backward_from(out, u, &mut grads).expect("backward");
            std::hint::black_box(grads.norm_sq());
        });
        println!("bench train_step_10k_{preset}_kpfcnn_fwdbwd {t_fb:.1} ms");
        println!("bench train_step_cpu_10k_{preset}_kpfcnn_fwdbwd {cpu:.0} ms");
        let levels: Vec<String> = pyr.points.iter().map(|l| l.len().to_string()).collect();
        let caps: Vec<String> = pyr.conv.iter().map(|n| n.cap.to_string()).collect();
        println!(
            "bench train_step_10k_{preset}_levels {} points ({} neighbour caps)",
            levels.join("/"),
            caps.join("/")
        );
    }
}
