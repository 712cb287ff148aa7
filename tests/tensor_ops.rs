//! Property tests of every tape op: gradients against central finite differences on
//! random shapes and values (kept off activation kinks), forward values against
//! direct computations, and the custom-op escape hatch.

#[path = "common/tensor.rs"]
mod tensor_common;

use point2quad::rng::Rng;
use point2quad::tensor::{CustomOp, Grads, Graph, ParamStore, Tensor};
use proptest::prelude::*;
use std::sync::Arc;
use tensor_common::{assert_grads, max_diff, off_kink, store_of, uniform};

fn cfg() -> ProptestConfig {
    ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(24) }
}

/// Shape of `b` for a broadcast kind against `[r × c]`.
fn bshape(kind: u8, r: usize, c: usize) -> Vec<usize> {
    match kind {
        0 => vec![r, c],
        1 => vec![1, c],
        2 => vec![r, 1],
        3 => vec![c],
        _ => vec![1],
    }
}

proptest! {
    #![proptest_config(cfg())]

    #[test]
    fn matmul_grads(m in 1usize..10, k in 1usize..10, n in 1usize..10, tb in any::<bool>(), seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let a = uniform(&[m, k], -1.0, 1.0, &mut rng);
        let b = if tb { uniform(&[n, k], -1.0, 1.0, &mut rng) } else { uniform(&[k, n], -1.0, 1.0, &mut rng) };
        let (want_a, want_b) = (a.clone(), b.clone());
        let (mut s, ids) = store_of(vec![a, b]);
        // Forward against a naive product.
        {
            let mut g = Graph::eval(&mut s);
            let (x, y) = (g.param(ids[0]), g.param(ids[1]));
            let z = if tb { g.matmul_t(x, y).unwrap() } else { g.matmul(x, y).unwrap() };
            let out = g.value(z).data().to_vec();
            for i in 0..m { for j in 0..n {
                let mut acc = 0.0f64;
                for p in 0..k {
                    let bv = if tb { want_b.data()[j * k + p] } else { want_b.data()[p * n + j] };
                    acc += want_a.data()[i * k + p] as f64 * bv as f64;
                }
                prop_assert!((out[i * n + j] as f64 - acc).abs() < 1e-4);
            }}
        }
        assert_grads(&mut s, |g| {
            let (x, y) = (g.param(ids[0]), g.param(ids[1]));
            if tb { g.matmul_t(x, y) } else { g.matmul(x, y) }
        }, true, seed);
    }

    #[test]
    fn broadcast_binary_grads(r in 1usize..6, c in 1usize..6, kind in 0u8..5, swap in any::<bool>(), op in 0u8..4, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let a = uniform(&[r, c], -1.0, 1.0, &mut rng);
        // Divisors kept away from 0.
        let b = off_kink(&bshape(kind, r, c), 0.5, &mut rng);
        let (mut s, ids) = store_of(vec![a, b]);
        assert_grads(&mut s, |g| {
            let (x, y) = (g.param(ids[0]), g.param(ids[1]));
            let (p, q) = if swap && op != 3 { (y, x) } else { (x, y) };
            match op { 0 => g.add(p, q), 1 => g.sub(p, q), 2 => g.mul(p, q), _ => g.div(p, q) }
        }, true, seed);
    }

    #[test]
    fn unary_and_reduction_grads(r in 1usize..6, c in 1usize..6, which in 0u8..10, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let a = if which == 3 { uniform(&[r, c], 0.5, 2.0, &mut rng) } else { off_kink(&[r, c], 0.05, &mut rng) };
        let (mut s, ids) = store_of(vec![a]);
        assert_grads(&mut s, |g| {
            let x = g.param(ids[0]);
            match which {
                0 => g.scale(x, -1.7),
                1 => g.add_scalar(x, 0.3),
                2 => g.exp(x),
                3 => g.log(x),
                4 => g.sum(x),
                5 => g.mean(x),
                6 => g.sum_axis(x, (seed % 2) as usize),
                7 => g.mean_axis(x, (seed % 2) as usize),
                8 => g.relu(x),
                _ => g.leaky_relu(x, 0.1),
            }
        }, true, seed);
    }

    #[test]
    fn log_softmax_grads_and_rows_normalised(r in 1usize..6, c in 1usize..6, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let a = uniform(&[r, c], -3.0, 3.0, &mut rng);
        let (mut s, ids) = store_of(vec![a]);
        {
            let mut g = Graph::eval(&mut s);
            let x = g.param(ids[0]);
            let y = g.log_softmax(x).unwrap();
            for row in g.value(y).data().chunks(c) {
                let tot: f64 = row.iter().map(|&v| (v as f64).exp()).sum();
                prop_assert!((tot - 1.0).abs() < 1e-5);
            }
        }
        assert_grads(&mut s, |g| { let x = g.param(ids[0]); g.log_softmax(x) }, true, seed);
    }

    #[test]
    fn gather_concat_reshape_grads(n in 1usize..6, c in 1usize..5, m in 1usize..9, padded in any::<bool>(), seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let a = uniform(&[n, c], -1.0, 1.0, &mut rng);
        let b = uniform(&[m, 2], -1.0, 1.0, &mut rng);
        let lim = if padded { n + 1 } else { n };
        let idx: Arc<[u32]> = (0..m).map(|_| rng.below(lim) as u32).collect();
        let (mut s, ids) = store_of(vec![a.clone(), b]);
        {
            let mut g = Graph::eval(&mut s);
            let x = g.param(ids[0]);
            let y = g.gather_rows(x, idx.clone(), padded).unwrap();
            for (i, &j) in idx.iter().enumerate() {
                let want: Vec<f32> = if (j as usize) < n { a.row(j as usize).to_vec() } else { vec![0.0; c] };
                prop_assert_eq!(g.value(y).row(i), &want[..]);
            }
        }
        assert_grads(&mut s, |g| {
            let (x, y) = (g.param(ids[0]), g.param(ids[1]));
            let h = g.gather_rows(x, idx.clone(), padded)?;
            let cat = g.concat_cols(&[h, y, h])?;
            let r = g.reshape(cat, &[m * (2 * c + 2)])?;
            g.mul(r, r)
        }, true, seed);
    }

    #[test]
    fn max_neighbors_grads_with_shadow(n in 1usize..6, c in 1usize..4, nout in 1usize..5, k in 1usize..4, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        // Distinct values ≥ 0.05 apart (and from the shadow's 0) so no max switches within ε.
        let mut vals: Vec<f32> = (0..n * c).map(|i| (i as f32 + 1.0) * 0.1 * if i % 3 == 0 { -1.0 } else { 1.0 }).collect();
        rng.shuffle(&mut vals);
        let a = Tensor::new(&[n, c], vals).unwrap();
        let idx: Vec<u32> = (0..nout * k).map(|_| rng.below(n + 1) as u32).collect();
        let (mut s, ids) = store_of(vec![a.clone()]);
        {
            let mut g = Graph::eval(&mut s);
            let x = g.param(ids[0]);
            let y = g.max_neighbors(x, &idx, k).unwrap();
            for i in 0..nout { for j in 0..c {
                let want = idx[i * k..(i + 1) * k].iter()
                    .map(|&s| if (s as usize) < n { a.data()[s as usize * c + j] } else { 0.0 })
                    .fold(f32::NEG_INFINITY, f32::max);
                prop_assert_eq!(g.value(y).data()[i * c + j], want);
            }}
        }
        assert_grads(&mut s, |g| { let x = g.param(ids[0]); g.max_neighbors(x, &idx, k) }, true, seed);
    }
}

/// A test custom op: `y = x ⊙ s` for a fixed (non-differentiable) row scale `s`, plus
/// `w` broadcast per column — exercises the `CustomOp` route end to end.
struct RowScale {
    s: Vec<f32>,
}

impl CustomOp for RowScale {
    fn name(&self) -> &'static str {
        "row_scale"
    }
    fn forward(&mut self, inputs: &[&Tensor]) -> point2quad::Result<Tensor> {
        let (x, w) = (inputs[0], inputs[1]);
        let c = x.cols();
        let d = x.data().iter().enumerate().map(|(i, &v)| v * self.s[i / c] * w.data()[i % c]).collect();
        Tensor::from_shape(x.shape(), d)
    }
    fn backward(
        &self,
        inputs: &[&Tensor],
        _o: &Tensor,
        go: &Tensor,
        needs: &[bool],
    ) -> point2quad::Result<Vec<Option<Tensor>>> {
        let (x, w) = (inputs[0], inputs[1]);
        let c = x.cols();
        let gx = needs[0].then(|| {
            let d = go.data().iter().enumerate().map(|(i, &g)| g * self.s[i / c] * w.data()[i % c]).collect();
            Tensor::from_shape(x.shape(), d).unwrap()
        });
        let gw = needs[1].then(|| {
            let mut d = vec![0.0; c];
            for (i, &g) in go.data().iter().enumerate() {
                d[i % c] += g * self.s[i / c] * x.data()[i];
            }
            Tensor::from_shape(w.shape(), d).unwrap()
        });
        Ok(vec![gx, gw])
    }
}

proptest! {
    #![proptest_config(cfg())]

    #[test]
    fn custom_op_grads(r in 1usize..6, c in 1usize..5, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let x = uniform(&[r, c], -1.0, 1.0, &mut rng);
        let w = uniform(&[c], -1.0, 1.0, &mut rng);
        let s: Vec<f32> = (0..r).map(|_| rng.f32() + 0.5).collect();
        let (mut st, ids) = store_of(vec![x, w]);
        assert_grads(&mut st, |g| {
            let (x, w) = (g.param(ids[0]), g.param(ids[1]));
            let y = g.custom(Box::new(RowScale { s: s.clone() }), &[x, w])?;
            g.mul(y, y)
        }, true, seed);
    }
}

#[test]
fn gradcheck_catches_a_wrong_gradient() {
    // A custom op with a deliberately wrong backward must fail the check.
    struct Wrong;
    impl CustomOp for Wrong {
        fn name(&self) -> &'static str {
            "wrong"
        }
        fn forward(&mut self, i: &[&Tensor]) -> point2quad::Result<Tensor> {
            Tensor::from_shape(i[0].shape(), i[0].data().iter().map(|v| v * v).collect())
        }
        fn backward(
            &self,
            i: &[&Tensor],
            _o: &Tensor,
            g: &Tensor,
            _n: &[bool],
        ) -> point2quad::Result<Vec<Option<Tensor>>> {
            // d(x²)/dx is 2x; return x instead.
            Ok(vec![Some(Tensor::from_shape(
                i[0].shape(),
                i[0].data().iter().zip(g.data()).map(|(x, g)| x * g).collect(),
            )?)])
        }
    }
    let mut rng = Rng::new(5);
    let (mut s, ids) = store_of(vec![uniform(&[3, 3], 0.5, 1.0, &mut rng)]);
    let cfg = point2quad::tensor::GradCheckConfig::default();
    let rep = point2quad::tensor::gradcheck(
        &mut s,
        |g| {
            let x = g.param(ids[0]);
            g.custom(Box::new(Wrong), &[x])
        },
        &cfg,
    )
    .unwrap();
    assert!(!rep.passed(&cfg));
}

#[test]
fn shape_errors_and_misuse_are_errors_not_panics() {
    let mut s = ParamStore::new();
    let mut g = Graph::train(&mut s);
    let a = g.input(Tensor::zeros(&[2, 3]).unwrap());
    let b = g.input(Tensor::zeros(&[4, 2]).unwrap());
    assert!(g.matmul(a, b).is_err());
    assert!(g.add(a, b).is_err());
    assert!(g.concat_cols(&[a, b]).is_err());
    assert!(g.gather_rows(a, Arc::from(vec![2u32]), false).is_err());
    assert!(g.gather_rows(a, Arc::from(vec![3u32]), true).is_err());
    assert!(g.max_neighbors(a, &[0, 1, 3], 3).is_err());
    assert!(g.max_neighbors(a, &[0, 1, 1], 2).is_err());
    assert!(g.reshape(a, &[5]).is_err());
    let mut grads = Grads::new();
    assert!(g.backward(a, &mut grads).is_err()); // not a scalar
    let l = g.sum(a).unwrap();
    g.backward(l, &mut grads).unwrap();
    assert!(g.backward(l, &mut grads).is_err()); // spent
    let mut s2 = ParamStore::new();
    let mut e = Graph::eval(&mut s2);
    let x = e.input(Tensor::zeros(&[2]).unwrap());
    let l = e.sum(x).unwrap();
    assert!(e.backward(l, &mut Grads::new()).is_err()); // no_grad graph
    e.free(x);
    assert!(e.sum(x).is_err()); // freed value
}

#[test]
fn eval_graph_records_nothing_and_matches_recorded_values() {
    let mut rng = Rng::new(9);
    let (mut s, ids) =
        store_of(vec![uniform(&[7, 4], -1.0, 1.0, &mut rng), uniform(&[3, 4], -1.0, 1.0, &mut rng)]);
    let run = |s: &mut ParamStore, record: bool| {
        let mut g = Graph::new(s, record, false);
        let (x, w) = (g.param(ids[0]), g.param(ids[1]));
        let y = g.matmul_t(x, w).unwrap();
        let y = g.leaky_relu(y, 0.1).unwrap();
        let y = g.log_softmax(y).unwrap();
        g.value(y).clone()
    };
    let a = run(&mut s, false);
    let b = run(&mut s, true);
    assert_eq!(max_diff(a.data(), b.data()), 0.0);
}
