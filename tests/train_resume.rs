//! Training on a tiny in-memory dataset (3 small synthetic shapes through
//! `dataset::build_sample`): resuming from a checkpoint image is bit-identical to
//! training straight through, and the loss goes down on a fixed set.

use point2quad::nn::checkpoint::TrainState;
use point2quad::pipeline::model::{Model, ModelConfig};
use point2quad::pipeline::train::{train, TrainConfig};
use point2quad::tensor::Tensor;
use point2quad::Result;

#[path = "common/training.rs"]
mod training;
use training::{bits, check_resume, no_progress, samples, train_cfg as cfg, Resumed};

#[test]
fn resume_from_checkpoint_bytes_is_bit_identical() {
    let data = samples();
    let (tr, va) = (&data[..2], &data[2..]);
    let Resumed { straight, first, mut resumed, states, .. } =
        check_resume(ModelConfig::default_preset(), &data);
    let a = bits(&straight);
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
        run: Vec::new(),
    };
    assert!(train(&mut model, &data, &[], &cfg(1), Some(bad), &mut no_progress, &mut ok).is_err());
}

/// Session 20's audit: a one-candidate sample failed mid-epoch in batch norm (train mode
/// needs two rows); `max_candidates` 1 did the same. The sample is skipped (an error
/// when nothing else is left) and the setting refused.
#[test]
fn tiny_batches_are_refused_or_skipped() {
    let data = samples();
    let mut ok = |_: &Model, _: &TrainState| -> Result<()> { Ok(()) };
    let mut one = data[0].clone();
    let dim = one.feature_dim as usize;
    one.candidates.truncate(1);
    one.labels.truncate(1);
    one.features.truncate(dim);
    let mut model = Model::new(ModelConfig::default_preset(), 1).unwrap();
    let reps =
        train(&mut model, &[one.clone(), data[2].clone()], &[], &cfg(1), None, &mut no_progress, &mut ok)
            .expect("a one-candidate sample is skipped");
    assert_eq!(reps.len(), 1);
    let e = train(&mut model, &[one], &[], &cfg(1), None, &mut no_progress, &mut ok).unwrap_err().to_string();
    assert!(e.contains("two or more candidates"), "{e}");
    let tiny = TrainConfig { max_candidates: 1, ..cfg(1) };
    let e = train(&mut model, &data, &[], &tiny, None, &mut no_progress, &mut ok).unwrap_err().to_string();
    assert!(e.contains("at least 2"), "{e}");
}

/// Noise variants (`NAME~2`, … of `dataset --noise-variants`): an epoch trains on one
/// draw of each sample, in turn. Variants that are exact copies of their sample train
/// exactly as the plain set (same steps, same random draws; the positive weight fixed,
/// since by default it counts every draw's labels); a variant that differs is read in the
/// second epoch, and only there.
#[test]
fn noise_variants_are_one_sample_per_epoch_in_turn() {
    let data = samples();
    let (a, b) = (data[0].clone(), data[1].clone());
    let fixed = |epochs| TrainConfig { pos_weight: Some(3.0), ..cfg(epochs) };
    let mut ok = |_: &Model, _: &TrainState| -> Result<()> { Ok(()) };
    let named = |s: &point2quad::pipeline::dataset::Sample, n: &str| {
        let mut s = s.clone();
        s.name = n.to_string();
        s
    };
    let run = |set: &[point2quad::pipeline::dataset::Sample], epochs: usize| {
        let mut m = Model::new(ModelConfig::default_preset(), 1).unwrap();
        let mut ok = |_: &Model, _: &TrainState| -> Result<()> { Ok(()) };
        let reps = train(&mut m, set, &[], &fixed(epochs), None, &mut no_progress, &mut ok).unwrap();
        (bits(&m), reps)
    };
    let plain = run(&[a.clone(), b.clone()], 2);
    // Copies as variants, members in any order (the groups keep the order of their
    // first members): the plain run, bit for bit.
    let a2 = named(&a, &format!("{}~2", a.name));
    let b3 = named(&b, &format!("{}~3", b.name));
    let b2 = named(&b, &format!("{}~2", b.name));
    let copies = run(&[a.clone(), b3, a2, b.clone(), b2], 2);
    assert_eq!(copies.0, plain.0);
    assert_eq!(copies.1.len(), 2);
    // A variant of A that holds B's data: epoch 1 reads A, epoch 2 reads the variant.
    let other = named(&b, &format!("{}~2", a.name));
    let one_epoch = run(&[a.clone(), other.clone(), b.clone()], 1);
    assert_eq!(one_epoch.0, run(&[a.clone(), b.clone()], 1).0, "epoch 1 must read the first draw");
    let mut m = Model::new(ModelConfig::default_preset(), 1).unwrap();
    let mut states = Vec::new();
    train(&mut m, &[a.clone(), b.clone()], &[], &fixed(1), None, &mut no_progress, &mut |_, st| {
        states.push(st.clone());
        Ok(())
    })
    .unwrap();
    // Epoch 2 by hand: resume with the variant in A's place (named A, so the group is A's).
    let swapped = named(&b, &a.name);
    train(&mut m, &[swapped, b.clone()], &[], &fixed(2), states.pop(), &mut no_progress, &mut ok).unwrap();
    let two_epochs = run(&[a.clone(), other, b.clone()], 2);
    assert_eq!(two_epochs.0, bits(&m), "epoch 2 must read the second draw");
    assert_ne!(two_epochs.0, plain.0);
}
