//! Shared helpers for the tensor / nn property tests: random tensors from a seed,
//! a parameter store of named inputs, and a gradient-check assertion.
#![allow(dead_code)]

use point2quad::rng::Rng;
use point2quad::tensor::{gradcheck, GradCheckConfig, Graph, ParamId, ParamKind, ParamStore, Tensor, Var};

/// Uniform values in `[lo, hi)`.
pub fn uniform(dims: &[usize], lo: f32, hi: f32, rng: &mut Rng) -> Tensor {
    let n: usize = dims.iter().product();
    Tensor::new(dims, (0..n).map(|_| lo + (hi - lo) * rng.f32()).collect()).unwrap()
}

/// Values with `|v| ∈ [gap, 1]` and random sign: kept off the kink at 0.
pub fn off_kink(dims: &[usize], gap: f32, rng: &mut Rng) -> Tensor {
    let n: usize = dims.iter().product();
    Tensor::new(
        dims,
        (0..n)
            .map(|_| {
                let m = gap + (1.0 - gap) * rng.f32();
                if rng.f32() < 0.5 {
                    -m
                } else {
                    m
                }
            })
            .collect(),
    )
    .unwrap()
}

/// A store holding each tensor as a trainable parameter named by its position.
pub fn store_of(ts: Vec<Tensor>) -> (ParamStore, Vec<ParamId>) {
    let mut s = ParamStore::new();
    let ids = ts
        .into_iter()
        .enumerate()
        .map(|(i, t)| s.add(&format!("in{i}"), ParamKind::Trainable, t).unwrap())
        .collect();
    (s, ids)
}

/// Runs a gradient check of `f` over every trainable tensor of `store` and panics
/// with the failing elements when it does not pass.
pub fn assert_grads<F>(store: &mut ParamStore, f: F, train: bool, seed: u64)
where
    F: FnMut(&mut Graph) -> point2quad::Result<Var>,
{
    let cfg = GradCheckConfig { train, seed, ..GradCheckConfig::default() };
    let rep = gradcheck(store, f, &cfg).expect("gradcheck ran");
    assert!(rep.checked > 0, "nothing checked");
    assert!(
        rep.passed(&cfg),
        "gradient check failed: {} checked, {} skipped, {:?}",
        rep.checked,
        rep.skipped,
        rep.failures
    );
}

/// Max absolute difference between two equal-length slices.
pub fn max_diff(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}
