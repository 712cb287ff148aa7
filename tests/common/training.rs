//! Shared helpers for the training tests: a tiny in-memory dataset, a training config
//! that exercises the RNG (subsampling, augmentation), and bit-level snapshots of a model.

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
    let cand = candidate_cfg();
    meshes
        .iter()
        .enumerate()
        .map(|(i, (name, m))| {
            let mut rng = Rng::new(100 + i as u64);
            build_sample(name, m, &NoiseConfig::default(), &cand, &mut rng).expect("test: sample")
        })
        .collect()
}

/// The candidate settings of [`samples`].
pub fn candidate_cfg() -> CandidateConfig {
    CandidateConfig { k: 12, per_point: 8, ..CandidateConfig::default() }
}

/// Subsampling (200 of ~300 candidates) and the default augmentation (rotation,
/// anisotropic scale, jitter) on: a resume test must see the RNG state restored, not
/// only the weights.
pub fn train_cfg(epochs: usize) -> TrainConfig {
    TrainConfig {
        epochs,
        seed: 11,
        max_candidates: 200,
        candidates: candidate_cfg(),
        ..TrainConfig::default()
    }
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

/// What [`check_resume`] trained.
pub struct Resumed {
    /// Two epochs straight through.
    pub straight: Model,
    /// One epoch.
    pub first: Model,
    /// `first` through checkpoint bytes, then one more epoch.
    pub resumed: Model,
    /// The straight run's reports.
    pub reps: Vec<point2quad::pipeline::train::EpochReport>,
    /// The straight run's state after each epoch.
    pub states: Vec<point2quad::nn::checkpoint::TrainState>,
}

/// Trains `config` (seed 5) two epochs straight, and one epoch + a resume from the
/// checkpoint's bytes + one more; asserts the saved state, the checkpoint round trip,
/// the resumed epoch's loss and validation figures and every tensor equal bit for bit.
pub fn check_resume(config: point2quad::pipeline::model::ModelConfig, data: &[Sample]) -> Resumed {
    use point2quad::nn::checkpoint::{Checkpoint, TrainState};
    use point2quad::pipeline::train::train;
    use std::path::Path;
    let (tr, va) = (&data[..2], &data[2..]);
    let mut straight = Model::new(config.clone(), 5).unwrap();
    let mut states: Vec<TrainState> = Vec::new();
    let reps = train(&mut straight, tr, va, &train_cfg(2), None, &mut no_progress, &mut |_, st| {
        states.push(st.clone());
        Ok(())
    })
    .unwrap();
    assert_eq!(reps.len(), 2);
    assert!(reps.iter().all(|r| r.loss.is_finite()));
    let mut first = Model::new(config, 5).unwrap();
    let mut saved: Option<Vec<u8>> = None;
    train(&mut first, tr, va, &train_cfg(1), None, &mut no_progress, &mut |m, st| {
        saved = Some(m.to_checkpoint(Some(st.clone())).to_bytes());
        Ok(())
    })
    .unwrap();
    let ck = Checkpoint::from_bytes(&saved.expect("checkpoint callback ran"), Path::new("mem.ckpt")).unwrap();
    let state = ck.train.clone().expect("state saved");
    assert_eq!(state.epoch, 1);
    assert_eq!(&state, &states[0], "the 1-epoch run saved the same state as the 2-epoch run after epoch 1");
    let mut resumed = Model::from_checkpoint(&ck, Path::new("mem.ckpt")).unwrap();
    assert_eq!(bits(&resumed), bits(&first), "checkpoint round trip");
    let more = train(&mut resumed, tr, va, &train_cfg(2), Some(state), &mut no_progress, &mut |_, _| Ok(()))
        .unwrap();
    assert_eq!(more.len(), 1);
    assert_eq!(more[0].epoch, 2);
    assert_eq!(more[0].loss.to_bits(), reps[1].loss.to_bits());
    assert_eq!(more[0].val, reps[1].val);
    let (a, b) = (bits(&straight), bits(&resumed));
    assert_eq!(a.len(), b.len());
    for ((na, ta), (nb, tb)) in a.iter().zip(&b) {
        assert_eq!(na, nb);
        assert!(ta == tb, "tensor {na} differs after resuming");
    }
    Resumed { straight, first, resumed, reps, states }
}
