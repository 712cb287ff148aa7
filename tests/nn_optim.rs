//! SGD against closed forms: on a separable quadratic, momentum SGD (with weight
//! decay) is the linear recurrence `[θ, buf]_{t+1} = A·[θ, buf]_t`, so θ_t comes from
//! the matrix power `A^t` (computed by repeated squaring in f64); clipping and
//! Nesterov against their defining formulas; the exponential schedule.

use point2quad::nn::optim::{ExpDecay, Sgd, SgdConfig};
use point2quad::tensor::{Grads, ParamKind, ParamStore, Tensor};
use proptest::prelude::*;

type M2 = [[f64; 2]; 2];

fn mul(a: M2, b: M2) -> M2 {
    let mut c = [[0.0; 2]; 2];
    for i in 0..2 {
        for j in 0..2 {
            c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
        }
    }
    c
}

fn pow(mut a: M2, mut e: u32) -> M2 {
    let mut r = [[1.0, 0.0], [0.0, 1.0]];
    while e > 0 {
        if e & 1 == 1 {
            r = mul(r, a);
        }
        a = mul(a, a);
        e >>= 1;
    }
    r
}

proptest! {
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(48) })]

    #[test]
    fn momentum_sgd_matches_matrix_power_on_a_quadratic(
        curv in proptest::collection::vec(0.1f64..2.0, 1..5),
        theta0 in proptest::collection::vec(-2.0f64..2.0, 5),
        lr in 0.01f32..0.3, m in 0.0f32..0.95, wd in 0.0f32..0.1, steps in 1u32..40,
    ) {
        let n = curv.len();
        let mut params = ParamStore::new();
        let id = params.add("theta", ParamKind::Trainable,
            Tensor::new(&[n], theta0[..n].iter().map(|&v| v as f32).collect()).unwrap()).unwrap();
        let mut sgd = Sgd::new(SgdConfig { lr, momentum: m, weight_decay: wd, clip: None, nesterov: false }).unwrap();
        for _ in 0..steps {
            // ∇ ½·a·θ² = a·θ
            let g: Vec<f32> = params.get(id).data().iter().zip(&curv).map(|(&t, &a)| (a * t as f64) as f32).collect();
            let mut grads = Grads::new();
            grads.accumulate(id, Tensor::new(&[n], g).unwrap()).unwrap();
            sgd.step(&mut params, &grads, lr).unwrap();
        }
        for i in 0..n {
            let k = curv[i] + wd as f64;
            let (lr, m) = (lr as f64, m as f64);
            let a = pow([[1.0 - lr * k, -lr * m], [k, m]], steps);
            let want = a[0][0] * theta0[i];
            let got = params.get(id).data()[i] as f64;
            prop_assert!((got - want).abs() < 1e-4 * (1.0 + want.abs()), "coord {}: {} vs {}", i, got, want);
        }
        prop_assert_eq!(sgd.steps(), steps as u64);
    }

    #[test]
    fn clipping_and_nesterov_follow_their_formulas(g0 in -500.0f32..500.0, g1 in -500.0f32..500.0, clip in 1.0f32..200.0, m in 0.1f32..0.9) {
        let mut params = ParamStore::new();
        let id = params.add("p", ParamKind::Trainable, Tensor::new(&[1], vec![1.0]).unwrap()).unwrap();
        let (lr, wd) = (0.01f32, 0.01f32);
        let mut sgd = Sgd::new(SgdConfig { lr, momentum: m, weight_decay: wd, clip: Some(clip), nesterov: true }).unwrap();
        let (mut th, mut buf) = (1.0f64, 0.0f64);
        for (t, gv) in [g0, g1].into_iter().enumerate() {
            let mut grads = Grads::new();
            grads.accumulate(id, Tensor::new(&[1], vec![gv]).unwrap()).unwrap();
            sgd.step(&mut params, &grads, lr).unwrap();
            let d = (gv as f64).clamp(-clip as f64, clip as f64) + wd as f64 * th;
            buf = if t == 0 { d } else { m as f64 * buf + d };
            th -= lr as f64 * (d + m as f64 * buf);
        }
        let got = params.get(id).data()[0] as f64;
        prop_assert!((got - th).abs() < 1e-5 * (1.0 + th.abs()), "{} vs {}", got, th);
    }
}

#[test]
fn non_finite_gradients_and_bad_configs_are_rejected_without_update() {
    let mut params = ParamStore::new();
    let id = params.add("p", ParamKind::Trainable, Tensor::new(&[2], vec![1.0, 2.0]).unwrap()).unwrap();
    let mut sgd = Sgd::new(SgdConfig::default()).unwrap();
    let mut grads = Grads::new();
    grads.accumulate(id, Tensor::new(&[2], vec![0.5, f32::NAN]).unwrap()).unwrap();
    assert!(sgd.step(&mut params, &grads, 0.1).is_err());
    assert_eq!(params.get(id).data(), &[1.0, 2.0]);
    assert!(Sgd::new(SgdConfig { momentum: 1.0, ..SgdConfig::default() }).is_err());
    assert!(Sgd::new(SgdConfig { lr: -1.0, ..SgdConfig::default() }).is_err());
    assert!(Sgd::new(SgdConfig { clip: Some(0.0), ..SgdConfig::default() }).is_err());
}

#[test]
fn buffers_are_not_optimised() {
    let mut params = ParamStore::new();
    let b = params.add("running", ParamKind::Buffer, Tensor::new(&[1], vec![3.0]).unwrap()).unwrap();
    let mut grads = Grads::new();
    grads.accumulate(b, Tensor::new(&[1], vec![1.0]).unwrap()).unwrap();
    Sgd::new(SgdConfig::default()).unwrap().step(&mut params, &grads, 1.0).unwrap();
    assert_eq!(params.get(b).data(), &[3.0]);
}

#[test]
fn exp_decay_is_tenfold_every_150_epochs() {
    let s = ExpDecay::new(1e-3);
    assert!((s.lr(0.0) - 1e-3).abs() < 1e-9);
    assert!((s.lr(150.0) - 1e-4).abs() < 1e-9);
    assert!((s.lr(300.0) - 1e-5).abs() < 1e-10);
    assert!((s.lr(75.0) as f64 - 1e-3 * 0.1f64.sqrt()).abs() < 1e-9);
    assert!(s.lr(10.0) < s.lr(9.0));
}
