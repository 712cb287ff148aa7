//! Training on a tiny in-memory dataset (3 small synthetic shapes through
//! `dataset::build_sample`): resuming from a checkpoint image is bit-identical to
//! training straight through, and the loss goes down on a fixed set.

use point2quad::nn::checkpoint::{Checkpoint, TrainState};
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::train::{train, TrainConfig};
use point2quad::tensor::Tensor;
use point2quad::Result;

#[path = "common/training.rs"]
mod training;
use std::path::Path;
use training::{bits, no_progress, samples, train_cfg as cfg};

#[test]
fn resume_from_checkpoint_bytes_is_bit_identical() {
    let data = samples();
    let (tr, va) = (&data[..2], &data[2..]);
    // Straight through: 2 epochs.
    let mut straight = Model::new(ModelConfig::default_preset(), 5).unwrap();
    let mut states: Vec<TrainState> = Vec::new();
    let reps = train(&mut straight, tr, va, &cfg(2), None, &mut no_progress, &mut |_, st| {
        states.push(st.clone());
        Ok(())
    })
    .unwrap();
    assert_eq!(reps.len(), 2);
    // 1 epoch, checkpoint through bytes, resume for 1 more.
    let mut first = Model::new(ModelConfig::default_preset(), 5).unwrap();
    let mut saved: Option<Vec<u8>> = None;
    train(&mut first, tr, va, &cfg(1), None, &mut no_progress, &mut |m, st| {
        saved = Some(m.to_checkpoint(Some(st.clone())).to_bytes());
        Ok(())
    })
    .unwrap();
    let bytes = saved.expect("checkpoint callback ran");
    let ck = Checkpoint::from_bytes(&bytes, Path::new("mem.ckpt")).unwrap();
    let state = ck.train.clone().expect("state saved");
    assert_eq!(state.epoch, 1);
    assert_eq!(&state, &states[0], "the 1-epoch run saved the same state as the 2-epoch run after epoch 1");
    let mut resumed = Model::from_checkpoint(&ck, Path::new("mem.ckpt")).unwrap();
    assert_eq!(bits(&resumed), bits(&first), "checkpoint round trip");
    let more =
        train(&mut resumed, tr, va, &cfg(2), Some(state), &mut no_progress, &mut |_, _| Ok(())).unwrap();
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
    // And the 1-epoch model really differs from the 2-epoch one (the check can fail).
    assert_ne!(bits(&first), a);
    // Resuming at the target epoch does nothing.
    let st2 = states[1].clone();
    let none = train(&mut resumed, tr, va, &cfg(2), Some(st2), &mut no_progress, &mut |_, _| Ok(())).unwrap();
    assert!(none.is_empty());
}

#[test]
fn loss_decreases_on_a_fixed_tiny_set() {
    let data = samples();
    let mut model = Model::new(ModelConfig::default_preset(), 1).unwrap();
    let c = TrainConfig { rotate: false, ..cfg(6) };
    let reps = train(&mut model, &data, &data[..1], &c, None, &mut no_progress, &mut |_, _| Ok(())).unwrap();
    let losses: Vec<f64> = reps.iter().map(|r| r.loss).collect();
    assert!(losses.iter().all(|l| l.is_finite()));
    assert!(losses[5] < 0.8 * losses[0], "loss did not go down: {losses:?}");
}

#[test]
fn bad_training_inputs_are_errors() {
    let data = samples();
    let mut model = Model::new(ModelConfig::default_preset(), 1).unwrap();
    let mut ok = |_: &Model, _: &TrainState| -> Result<()> { Ok(()) };
    // No samples, or samples without candidates.
    assert!(train(&mut model, &[], &[], &cfg(1), None, &mut no_progress, &mut ok).is_err());
    let mut empty = data[0].clone();
    empty.candidates.clear();
    empty.labels.clear();
    empty.features.clear();
    assert!(train(&mut model, &[empty], &[], &cfg(1), None, &mut no_progress, &mut ok).is_err());
    // Too few features per candidate for the model.
    let mut narrow = data[0].clone();
    narrow.feature_dim = 3;
    narrow.features = vec![0.0; 3 * narrow.labels.len()];
    assert!(train(&mut model, &[narrow], &[], &cfg(1), None, &mut no_progress, &mut ok).is_err());
    // A failing checkpoint callback stops training with its error.
    let e = train(&mut model, &data, &[], &cfg(3), None, &mut no_progress, &mut |_, _| {
        Err(point2quad::Error::invalid("disk full"))
    })
    .unwrap_err();
    assert!(e.to_string().contains("disk full"));
    // A momentum state that does not fit the model.
    let bad = TrainState {
        epoch: 0,
        step: 0,
        rng: [1, 2, 3, 4],
        momentum: vec![("nope".into(), Tensor::new(&[2], vec![0.0; 2]).unwrap())],
    };
    assert!(train(&mut model, &data, &[], &cfg(1), Some(bad), &mut no_progress, &mut ok).is_err());
}
