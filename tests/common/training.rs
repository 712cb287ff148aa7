//! Shared helpers for the training tests: a tiny in-memory dataset, a training config
//! that exercises the RNG (subsampling, rotations), and bit-level snapshots of a model.

#![allow(dead_code)]

use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes;
use point2quad::pipeline::candidates::CandidateConfig;
use point2quad::pipeline::dataset::{build_sample, Sample};
use point2quad::pipeline::model::Model;
use point2quad::pipeline::noise::NoiseConfig;
use point2quad::pipeline::train::{Progress, TrainConfig};
use point2quad::rng::Rng;

/// Three small noisy shapes through `dataset::build_sample` (~100–200 points each).
pub fn samples() -> Vec<Sample> {
    let meshes: [(&str, QuadMesh); 3] = [
        ("sphere", shapes::cube_sphere(4)),
        ("torus", shapes::torus(12, 6, 1.0, 0.4)),
        ("hill", shapes::height_field(9, 9, |u, v| 0.3 * (2.0 * u).sin() * v)),
    ];
    let cand = CandidateConfig { k: 12, per_point: 8, ..CandidateConfig::default() };
    meshes
        .iter()
        .enumerate()
        .map(|(i, (name, m))| {
            let mut rng = Rng::new(100 + i as u64);
            build_sample(name, m, &NoiseConfig::default(), &cand, &mut rng).expect("test: sample")
        })
        .collect()
}

/// Subsampling (200 of ~300 candidates) and rotations on: a resume test must see the
/// RNG state restored, not only the weights.
pub fn train_cfg(epochs: usize) -> TrainConfig {
    TrainConfig { epochs, seed: 11, max_candidates: 200, ..TrainConfig::default() }
}

/// Every tensor of the store (parameters, batch-norm buffers, kernel points), by
/// name, as bits.
pub fn bits(m: &Model) -> Vec<(String, Vec<u32>)> {
    m.params
        .ids()
        .map(|id| {
            (m.params.name(id).to_string(), m.params.get(id).data().iter().map(|x| x.to_bits()).collect())
        })
        .collect()
}

/// A progress callback that ignores its argument.
pub fn no_progress(_: Progress) {}
