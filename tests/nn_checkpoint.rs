//! Checkpoints: exact save → load round trips (bytes and files), every single-byte
//! corruption and every truncation detected as `Error::Checkpoint`, wrong magic /
//! version / names / shapes rejected, and training that resumes bit-identically.

#[path = "common/tensor.rs"]
mod tensor_common;

use point2quad::nn::batch_norm::BatchNormConfig;
use point2quad::nn::checkpoint::{self, fnv1a64, Checkpoint, TrainState, MAGIC};
use point2quad::nn::conv1d::{Conv1d, ConvBnAct};
use point2quad::nn::dropout::Dropout;
use point2quad::nn::loss::{face_loss, weighted_cross_entropy};
use point2quad::nn::module::Module;
use point2quad::nn::optim::{Sgd, SgdConfig};
use point2quad::rng::Rng;
use point2quad::tensor::{Act, Grads, Graph, ParamKind, ParamStore, Tensor};
use point2quad::Error;
use proptest::prelude::*;
use std::path::Path;
use tensor_common::uniform;

fn sample(seed: u64) -> Checkpoint {
    let mut rng = Rng::new(seed);
    let mut s = ParamStore::new();
    s.add("a.weight", ParamKind::Trainable, uniform(&[3, 4], -1.0, 1.0, &mut rng)).unwrap();
    s.add("a.bias", ParamKind::Trainable, uniform(&[4], -1.0, 1.0, &mut rng)).unwrap();
    s.add("scalar", ParamKind::Buffer, Tensor::scalar(rng.f32())).unwrap();
    s.add("empty", ParamKind::Buffer, Tensor::zeros(&[0, 3]).unwrap()).unwrap();
    s.add("cube", ParamKind::Trainable, uniform(&[2, 1, 2, 2], -1.0, 1.0, &mut rng)).unwrap();
    let train = TrainState {
        epoch: 17,
        step: 12345,
        rng: rng.state(),
        momentum: vec![("a.weight".into(), uniform(&[3, 4], -1.0, 1.0, &mut rng))],
        // A run record (flag 2) on odd seeds, none (flag 1) on even ones; an empty value
        // and a non-ASCII one among them.
        run: if seed % 2 == 1 {
            vec![
                ("seed".into(), seed.to_string()),
                ("hold-out".into(), String::new()),
                ("é".into(), "x,y".into()),
            ]
        } else {
            Vec::new()
        },
    };
    Checkpoint::from_store(&s, b"preset=default;width=64", Some(train))
}

fn is_ckpt_err(r: point2quad::Result<Checkpoint>) -> bool {
    matches!(r, Err(Error::Checkpoint { .. }))
}

#[test]
fn round_trip_is_exact_in_memory_and_on_disk() {
    let c = sample(1);
    let bytes = c.to_bytes();
    assert_eq!(Checkpoint::from_bytes(&bytes, Path::new("mem")).unwrap(), c);
    let dir = std::env::temp_dir().join(format!("p2q_ckpt_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("model.p2q");
    checkpoint::save(&p, &c).unwrap();
    assert_eq!(checkpoint::load(&p).unwrap(), c);
    // Overwriting keeps exactly one file (the temporary one is renamed away).
    checkpoint::save(&p, &sample(2)).unwrap();
    assert_eq!(checkpoint::load(&p).unwrap(), sample(2));
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(matches!(checkpoint::load(&p), Err(Error::Io { .. })));
}

#[test]
fn every_flipped_byte_and_every_truncation_is_detected() {
    let bytes = sample(3).to_bytes();
    for i in 0..bytes.len() {
        for x in [0x01u8, 0x80, 0xff] {
            let mut b = bytes.clone();
            b[i] ^= x;
            assert!(is_ckpt_err(Checkpoint::from_bytes(&b, Path::new("f"))), "flip at {i} undetected");
        }
    }
    for len in 0..bytes.len() {
        assert!(is_ckpt_err(Checkpoint::from_bytes(&bytes[..len], Path::new("t"))), "truncation at {len}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(is_ckpt_err(Checkpoint::from_bytes(&longer, Path::new("t"))));
}

/// Re-seals a modified image with a valid checksum (to reach the later checks).
fn reseal(mut b: Vec<u8>) -> Vec<u8> {
    let n = b.len();
    let h = fnv1a64(&b[..n - 8]);
    b[n - 8..].copy_from_slice(&h.to_le_bytes());
    b
}

#[test]
fn wrong_magic_version_and_inner_lengths_give_clear_errors() {
    let bytes = sample(4).to_bytes();
    let mut b = bytes.clone();
    b[0] = b'X';
    let e = Checkpoint::from_bytes(&reseal(b), Path::new("m")).unwrap_err().to_string();
    assert!(e.contains("magic"), "{e}");
    let mut b = bytes.clone();
    b[8] = 9;
    let e = Checkpoint::from_bytes(&reseal(b), Path::new("v")).unwrap_err().to_string();
    assert!(e.contains("version 9"), "{e}");
    // An absurd tensor count with a valid checksum must not allocate or panic.
    let clen = u64::from_le_bytes(bytes[24..32].try_into().unwrap()) as usize;
    let mut b = bytes.clone();
    b[32 + clen..40 + clen].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(is_ckpt_err(Checkpoint::from_bytes(&reseal(b), Path::new("n"))));
    assert_eq!(&bytes[..8], &MAGIC);
}

/// The run record: a state without one is written with flag 1, in the layout from before
/// the record existed; with one, the same bytes with flag 2 and the record appended.
/// A flag beyond 2, an absurd record count and a key that is not UTF-8 are errors.
#[test]
fn run_record_is_appended_under_flag_two() {
    let mut without = sample(2);
    without.train.as_mut().unwrap().run.clear();
    let mut with = without.clone();
    with.train.as_mut().unwrap().run = vec![("k".into(), "vw".into())];
    let (a, b) = (without.to_bytes(), with.to_bytes());
    let n = a.len() - 8;
    let tail: Vec<u8> =
        [&1u64.to_le_bytes()[..], &1u32.to_le_bytes(), b"k", &2u32.to_le_bytes(), b"vw"].concat();
    assert_eq!(b.len(), a.len() + tail.len());
    let differ: Vec<usize> = (24..n).filter(|&i| a[i] != b[i]).collect();
    assert_eq!(differ.len(), 1, "one byte (the flag) differs, not {differ:?}");
    let flag = differ[0];
    assert_eq!((a[flag], b[flag]), (1, 2));
    assert_eq!(&b[n..n + tail.len()], &tail[..]);
    assert_eq!(Checkpoint::from_bytes(&b, Path::new("r")).unwrap(), with);
    let mut c = a.clone();
    c[flag] = 3;
    let e = Checkpoint::from_bytes(&reseal(c), Path::new("f3")).unwrap_err().to_string();
    assert!(e.contains("training-state flag 3") && e.contains("f3"), "{e}");
    let mut c = b.clone();
    c[n..n + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = Checkpoint::from_bytes(&reseal(c), Path::new("cnt")).unwrap_err().to_string();
    assert!(e.contains("run record count"), "{e}");
    let mut c = b.clone();
    c[n + 12] = 0xff;
    let e = Checkpoint::from_bytes(&reseal(c), Path::new("utf")).unwrap_err().to_string();
    assert!(e.contains("not UTF-8"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(64) })]

    #[test]
    fn random_corruption_with_resealed_checksum_never_panics(pos in 24usize..400, val in any::<u8>(), seed in 0u64..50) {
        // Even with a valid checksum, garbage inside must give an error or a valid parse.
        let bytes = sample(seed).to_bytes();
        let pos = pos % (bytes.len() - 8);
        let mut b = bytes.clone();
        b[pos] = val;
        let _ = Checkpoint::from_bytes(&reseal(b), Path::new("r"));
    }
}

#[test]
fn mismatched_models_are_rejected_and_left_unchanged() {
    let mut rng = Rng::new(5);
    let mut a = ParamStore::new();
    Conv1d::new(&mut a, "c", 4, 3, true, &mut rng).unwrap();
    let ck = Checkpoint::from_store(&a, b"", None);
    let mut b = ParamStore::new();
    Conv1d::new(&mut b, "c", 5, 3, true, &mut rng).unwrap(); // shape differs
    let before = b.clone();
    let e = ck.apply_to(&mut b, Path::new("x")).unwrap_err().to_string();
    assert!(e.contains("c.weight"), "{e}");
    assert_eq!(b.get(b.find("c.bias").unwrap()), before.get(before.find("c.bias").unwrap()));
    let mut c = ParamStore::new();
    Conv1d::new(&mut c, "d", 4, 3, true, &mut rng).unwrap(); // names differ
    assert!(ck.apply_to(&mut c, Path::new("x")).is_err());
    let mut d = ParamStore::new();
    Conv1d::new(&mut d, "c", 4, 3, false, &mut rng).unwrap(); // tensor missing from the model
    assert!(ck.apply_to(&mut d, Path::new("x")).is_err());
    let mut e2 = ParamStore::new();
    Conv1d::new(&mut e2, "c", 4, 3, true, &mut rng).unwrap();
    e2.add("extra", ParamKind::Buffer, Tensor::zeros(&[1]).unwrap()).unwrap(); // missing from the file
    assert!(ck.apply_to(&mut e2, Path::new("x")).is_err());
    let mut ok = ParamStore::new();
    Conv1d::new(&mut ok, "c", 4, 3, true, &mut rng).unwrap();
    ck.apply_to(&mut ok, Path::new("x")).unwrap();
    assert_eq!(ok.get(ok.find("c.weight").unwrap()), a.get(a.find("c.weight").unwrap()));
}

struct Model {
    params: ParamStore,
    l0: ConvBnAct,
    head: Conv1d,
}

fn model() -> Model {
    let mut rng = Rng::new(42);
    let mut params = ParamStore::new();
    let l0 = ConvBnAct::new(
        &mut params,
        "l0",
        6,
        16,
        Act::LeakyRelu(0.1),
        BatchNormConfig { eps: 1e-5, momentum: 0.02 },
        &mut rng,
    )
    .unwrap();
    let head = Conv1d::new(&mut params, "head", 16, 2, true, &mut rng).unwrap();
    Model { params, l0, head }
}

/// `n` training steps: random batch and dropout from `rng`, compound loss, SGD.
fn train(m: &mut Model, sgd: &mut Sgd, rng: &mut Rng, n: usize) {
    let dropout = Dropout::new(0.2).unwrap();
    for _ in 0..n {
        let x = uniform(&[32, 6], -1.0, 1.0, rng);
        let y: Vec<u8> = (0..32).map(|_| (rng.f32() < 0.3) as u8).collect();
        let mut grads = Grads::new();
        let mut g = Graph::train(&mut m.params);
        let xv = g.input(x);
        let h = m.l0.forward(&mut g, xv).unwrap();
        let h = dropout.forward(&mut g, h, rng).unwrap();
        let logits = m.head.forward(&mut g, h).unwrap();
        let a = weighted_cross_entropy(&mut g, logits, &y, 2.0).unwrap();
        let b = face_loss(&mut g, logits, &y).unwrap();
        let l = g.add(a, b).unwrap();
        g.backward(l, &mut grads).unwrap();
        drop(g);
        sgd.step(&mut m.params, &grads, 0.05).unwrap();
    }
}

#[test]
fn training_resumes_bit_identically() {
    let cfg = SgdConfig { lr: 0.05, momentum: 0.9, weight_decay: 1e-3, clip: Some(100.0), nesterov: false };
    let mut straight = model();
    let mut sgd = Sgd::new(cfg).unwrap();
    let mut rng = Rng::new(1);
    train(&mut straight, &mut sgd, &mut rng, 8);

    let mut first = model();
    let mut sgd1 = Sgd::new(cfg).unwrap();
    let mut rng1 = Rng::new(1);
    train(&mut first, &mut sgd1, &mut rng1, 4);
    let state = TrainState {
        epoch: 4,
        step: sgd1.steps(),
        rng: rng1.state(),
        momentum: sgd1.buffers(&first.params),
        run: Vec::new(),
    };
    let bytes = Checkpoint::from_store(&first.params, b"cfg", Some(state)).to_bytes();
    drop(first);

    let ck = Checkpoint::from_bytes(&bytes, Path::new("resume")).unwrap();
    let mut resumed = model();
    ck.apply_to(&mut resumed.params, Path::new("resume")).unwrap();
    let st = ck.train.unwrap();
    let mut sgd2 = Sgd::new(cfg).unwrap();
    sgd2.set_buffers(&resumed.params, &st.momentum, st.step).unwrap();
    let mut rng2 = Rng::from_state(st.rng);
    train(&mut resumed, &mut sgd2, &mut rng2, 4);

    for id in straight.params.ids() {
        assert_eq!(straight.params.get(id), resumed.params.get(id), "{}", straight.params.name(id));
    }
    assert_eq!(sgd.steps(), sgd2.steps());
}
