//! Property tests of the nn layers: gradient checks of Conv1d, the fused
//! conv+BN+activation block (train and eval statistics) against finite differences
//! and against batch norm composed from primitive ops, batch-norm statistics and the
//! momentum rule, residual block, losses against direct formulas, dropout, init.

#[path = "common/tensor.rs"]
mod tensor_common;

use point2quad::nn::batch_norm::{BatchNorm1d, BatchNormConfig};
use point2quad::nn::conv1d::{Conv1d, ConvBnAct};
use point2quad::nn::dropout::Dropout;
use point2quad::nn::loss::{face_loss, weighted_cross_entropy};
use point2quad::nn::module::{Module, ResidualBlock, Sequential};
use point2quad::rng::Rng;
use point2quad::tensor::{Act, Grads, Graph, ParamKind, ParamStore, Tensor, Var};
use proptest::prelude::*;
use tensor_common::{assert_grads, max_diff, store_of, uniform};

fn cfg() -> ProptestConfig {
    ProptestConfig { failure_persistence: None, ..ProptestConfig::with_cases(24) }
}

fn act_of(k: u8) -> Act {
    match k {
        0 => Act::Identity,
        1 => Act::Relu,
        _ => Act::LeakyRelu(0.1),
    }
}

/// Batch norm composed from primitive ops (the reference for the fused kernel).
fn bn_reference(g: &mut Graph, z: Var, gamma: Var, beta: Var, eps: f32) -> point2quad::Result<Var> {
    let mu = g.mean_axis(z, 0)?;
    let zc = g.sub(z, mu)?;
    let sq = g.mul(zc, zc)?;
    let var = g.mean_axis(sq, 0)?;
    let ve = g.add_scalar(var, eps)?;
    let lv = g.log(ve)?;
    let half = g.scale(lv, -0.5)?;
    let inv = g.exp(half)?;
    let zh = g.mul(zc, inv)?;
    let y = g.mul(zh, gamma)?;
    g.add(y, beta)
}

/// True when every pre-activation value of `blk` on `x` is ≥ 0.05 from the kink and,
/// in train mode, every channel's batch variance is ≥ 0.01 (so an ε-step of the input
/// cannot move a value across the kink).
fn off_kinks(s: &mut ParamStore, blk: &ConvBnAct, x: point2quad::tensor::ParamId, train: bool) -> bool {
    let xt = s.get(x).clone();
    off_kinks_at(s, blk, &xt, train)
}

/// [`off_kinks`] for an input given by value.
fn off_kinks_at(s: &mut ParamStore, blk: &ConvBnAct, xt: &Tensor, train: bool) -> bool {
    let wt = s.get(blk.weight).clone();
    let mut g = Graph::new(s, false, train);
    let (xv, w) = (g.input(xt.clone()), g.param(blk.weight));
    let (ga, be) = (g.param(blk.bn.weight), g.param(blk.bn.bias));
    let y = g.conv_bn_act(xv, Some(w), ga, be, blk.bn.refs(), Act::Identity).unwrap();
    let far = g.value(y).data().iter().all(|v| v.abs() > 0.05);
    let (m, cin, cout) = (xt.rows(), xt.cols(), wt.rows());
    let var_ok = (0..cout).all(|j| {
        let z: Vec<f64> = (0..m)
            .map(|i| (0..cin).map(|p| xt.data()[i * cin + p] as f64 * wt.data()[j * cin + p] as f64).sum())
            .collect();
        let mu = z.iter().sum::<f64>() / m as f64;
        z.iter().map(|v| (v - mu).powi(2)).sum::<f64>() / m as f64 >= 0.01
    });
    far && (!train || var_ok)
}

/// A batch-norm block with random affine weights and running statistics, and a random
/// `[m × c]` input: (store, block, [gamma, beta, running mean, running var], input, rng).
fn random_bn(m: usize, c: usize, seed: u64) -> (ParamStore, BatchNorm1d, [Tensor; 4], Tensor, Rng) {
    let mut rng = Rng::new(seed);
    let mut s = ParamStore::new();
    let bn = BatchNorm1d::new(&mut s, "bn", c, BatchNormConfig::default()).unwrap();
    let (gm, bt) = (uniform(&[c], 0.5, 1.5, &mut rng), uniform(&[c], -1.0, 1.0, &mut rng));
    let (rmv, rvv) = (uniform(&[c], -1.0, 1.0, &mut rng), uniform(&[c], 0.2, 2.0, &mut rng));
    *s.get_mut(bn.weight) = gm.clone();
    *s.get_mut(bn.bias) = bt.clone();
    *s.get_mut(bn.running_mean) = rmv.clone();
    *s.get_mut(bn.running_var) = rvv.clone();
    let x = uniform(&[m, c], -2.0, 2.0, &mut rng);
    (s, bn, [gm, bt, rmv, rvv], x, rng)
}

proptest! {
    #![proptest_config(cfg())]

    #[test]
    fn conv1d_grads(m in 1usize..8, cin in 1usize..7, cout in 1usize..7, bias in any::<bool>(), seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let mut s = ParamStore::new();
        let conv = Conv1d::new(&mut s, "c", cin, cout, bias, &mut rng).unwrap();
        let x = s.add("x", ParamKind::Trainable, uniform(&[m, cin], -1.0, 1.0, &mut rng)).unwrap();
        assert_grads(&mut s, |g| { let xv = g.param(x); conv.forward(g, xv) }, true, seed);
    }

    #[test]
    fn fused_block_grads_train_and_eval_off_kinks(m in 2usize..9, cin in 1usize..6, cout in 1usize..6, act in 0u8..3, train in any::<bool>(), seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let mut s = ParamStore::new();
        let blk = ConvBnAct::new(&mut s, "b", cin, cout, act_of(act), BatchNormConfig::default(), &mut rng).unwrap();
        // Non-trivial affine and running statistics.
        *s.get_mut(blk.bn.weight) = uniform(&[cout], 0.5, 1.5, &mut rng);
        *s.get_mut(blk.bn.bias) = uniform(&[cout], -0.5, 0.5, &mut rng);
        *s.get_mut(blk.bn.running_mean) = uniform(&[cout], -0.3, 0.3, &mut rng);
        *s.get_mut(blk.bn.running_var) = uniform(&[cout], 0.5, 1.5, &mut rng);
        let x = s.add("x", ParamKind::Trainable, uniform(&[m, cin], -1.0, 1.0, &mut rng)).unwrap();
        // Off kinks, and (train mode) no near-constant channel, where batch norm is
        // so curved that an ε-step is not small.
        prop_assume!(off_kinks(&mut s, &blk, x, train));
        assert_grads(&mut s, |g| { let xv = g.param(x); blk.forward(g, xv) }, train, seed);
    }

    #[test]
    fn fused_block_matches_composed_reference(m in 2usize..12, cin in 1usize..6, cout in 1usize..6, act in 0u8..3, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let mut s = ParamStore::new();
        let blk = ConvBnAct::new(&mut s, "b", cin, cout, act_of(act), BatchNormConfig::default(), &mut rng).unwrap();
        *s.get_mut(blk.bn.weight) = uniform(&[cout], 0.5, 1.5, &mut rng);
        *s.get_mut(blk.bn.bias) = uniform(&[cout], -0.5, 0.5, &mut rng);
        let x = s.add("x", ParamKind::Trainable, uniform(&[m, cin], -1.0, 1.0, &mut rng)).unwrap();
        let seed_t = uniform(&[m, cout], -1.0, 1.0, &mut rng);
        let mut run = |fused: bool| {
            let mut grads = Grads::new();
            let mut g = Graph::train(&mut s);
            let xv = g.param(x);
            let y = if fused { blk.forward(&mut g, xv).unwrap() } else {
                let w = g.param(blk.weight);
                let z = g.matmul_t(xv, w).unwrap();
                let (ga, be) = (g.param(blk.bn.weight), g.param(blk.bn.bias));
                let y = bn_reference(&mut g, z, ga, be, 1e-5).unwrap();
                match act_of(act) { Act::Identity => y, Act::Relu => g.relu(y).unwrap(), Act::LeakyRelu(k) => g.leaky_relu(y, k).unwrap() }
            };
            let out = g.value(y).clone();
            g.backward_from(y, seed_t.clone(), &mut grads).unwrap();
            (out, grads)
        };
        let (a, ga) = run(true);
        let (b, gb) = run(false);
        prop_assert!(max_diff(a.data(), b.data()) < 1e-4);
        for id in [x, blk.weight, blk.bn.weight, blk.bn.bias] {
            let (p, q) = (ga.get(id).unwrap(), gb.get(id).unwrap());
            let scale = q.data().iter().fold(1.0f32, |m, v| m.max(v.abs()));
            prop_assert!(max_diff(p.data(), q.data()) < 1e-3 * scale, "{:?} vs {:?}", p.data(), q.data());
        }
    }

    #[test]
    fn batch_norm_train_normalises_and_tracks_running_stats(m in 2usize..40, c in 1usize..6, mom in 0.0f32..1.0, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let mut s = ParamStore::new();
        let bn = BatchNorm1d::new(&mut s, "bn", c, BatchNormConfig { eps: 1e-5, momentum: mom }).unwrap();
        let mut rm = vec![0.0f64; c];
        let mut rv = vec![1.0f64; c];
        for _step in 0..2 {
            let x = uniform(&[m, c], -2.0, 3.0, &mut rng);
            let mut g = Graph::train(&mut s);
            let xv = g.input(x.clone());
            let y = bn.forward(&mut g, xv).unwrap();
            let yv = g.value(y).clone();
            for j in 0..c {
                let col: Vec<f64> = (0..m).map(|i| x.data()[i * c + j] as f64).collect();
                let mean = col.iter().sum::<f64>() / m as f64;
                let var = col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / m as f64;
                let ycol: Vec<f64> = (0..m).map(|i| yv.data()[i * c + j] as f64).collect();
                let ym = ycol.iter().sum::<f64>() / m as f64;
                let yvar = ycol.iter().map(|v| (v - ym).powi(2)).sum::<f64>() / m as f64;
                prop_assert!(ym.abs() < 1e-4);
                // Unit variance up to eps's effect.
                let want = var / (var + 1e-5);
                prop_assert!((yvar - want).abs() < 1e-3, "var {} want {}", yvar, want);
                rm[j] = (1.0 - mom as f64) * rm[j] + mom as f64 * mean;
                rv[j] = (1.0 - mom as f64) * rv[j] + mom as f64 * var * m as f64 / (m as f64 - 1.0);
            }
        }
        for j in 0..c {
            prop_assert!((s.get(bn.running_mean).data()[j] as f64 - rm[j]).abs() < 1e-4 * (1.0 + rm[j].abs()));
            prop_assert!((s.get(bn.running_var).data()[j] as f64 - rv[j]).abs() < 1e-4 * (1.0 + rv[j].abs()));
        }
    }

    #[test]
    fn batch_norm_eval_uses_running_stats(m in 1usize..10, c in 1usize..6, seed in 0u64..1000) {
        let (mut s, bn, [gm, bt, rmv, rvv], x, _) = random_bn(m, c, seed);
        let mut g = Graph::eval(&mut s);
        let xv = g.input(x.clone());
        let y = bn.forward(&mut g, xv).unwrap();
        for i in 0..m { for j in 0..c {
            let want = (x.data()[i * c + j] - rmv.data()[j]) / (rvv.data()[j] + 1e-5).sqrt() * gm.data()[j] + bt.data()[j];
            prop_assert!((g.value(y).data()[i * c + j] - want).abs() < 1e-5);
        }}
        drop(g);
        // Eval mode leaves the running statistics alone.
        prop_assert_eq!(s.get(bn.running_mean), &rmv);
    }

    /// An inference graph asked for batch statistics (`with_batch_stats`, what a
    /// `cloud_batch_stats` model scores with) normalises with the rows' own mean and
    /// biased variance (brute force here) when there are ≥ 2 rows and with the running
    /// statistics for one row; it never moves the running statistics. Recorded, its
    /// outputs and gradients equal a train graph's (the same statistics, the same rule).
    #[test]
    fn batch_norm_eval_with_batch_stats(m in 1usize..10, c in 1usize..6, seed in 0u64..1000) {
        let (mut s, bn, [gm, bt, rmv, rvv], x, mut rng) = random_bn(m, c, seed);
        let xd = x.data();
        let got = {
            let mut g = Graph::eval(&mut s).with_batch_stats(true);
            let xv = g.input(x.clone());
            let y = bn.forward(&mut g, xv).unwrap();
            g.value(y).clone()
        };
        for j in 0..c {
            let (mean, var) = if m >= 2 {
                let mean = (0..m).map(|i| xd[i * c + j] as f64).sum::<f64>() / m as f64;
                (mean, (0..m).map(|i| (xd[i * c + j] as f64 - mean).powi(2)).sum::<f64>() / m as f64)
            } else {
                (rmv.data()[j] as f64, rvv.data()[j] as f64)
            };
            for i in 0..m {
                let want = (xd[i * c + j] as f64 - mean) / (var + 1e-5).sqrt() * gm.data()[j] as f64 + bt.data()[j] as f64;
                prop_assert!((got.data()[i * c + j] as f64 - want).abs() < 1e-4 * (1.0 + want.abs()), "row {} col {}", i, j);
            }
        }
        prop_assert_eq!(s.get(bn.running_mean), &rmv);
        prop_assert_eq!(s.get(bn.running_var), &rvv);
        // Without the switch the same graph reads the running statistics: the check
        // above can tell the two apart.
        if m >= 2 {
            let plain = {
                let mut g = Graph::eval(&mut s);
                let xv = g.input(x.clone());
                let y = bn.forward(&mut g, xv).unwrap();
                g.value(y).clone()
            };
            prop_assert!(max_diff(plain.data(), got.data()) > 1e-4);
        }
        // Recorded: outputs and gradients as a train graph's.
        prop_assume!(m >= 2);
        let xid = s.add("x", ParamKind::Trainable, x.clone()).unwrap();
        let w = uniform(&[m, c], -1.0, 1.0, &mut rng);
        let run = |s: &mut ParamStore, train: bool| {
            let mut grads = Grads::new();
            let mut g = Graph::new(s, true, train).with_batch_stats(true);
            let xv = g.param(xid);
            let y = bn.forward(&mut g, xv).unwrap();
            let wv = g.input(w.clone());
            let p = g.mul(y, wv).unwrap();
            let l = g.sum(p).unwrap();
            let out = g.value(y).clone();
            g.backward(l, &mut grads).unwrap();
            (out, [xid, bn.weight, bn.bias].map(|id| grads.get(id).unwrap().clone()))
        };
        let (ye, ge) = run(&mut s, false);
        prop_assert_eq!(s.get(bn.running_mean), &rmv);
        let (yt, gt) = run(&mut s, true);
        prop_assert!(max_diff(ye.data(), yt.data()) == 0.0);
        for (a, b) in ge.iter().zip(&gt) {
            prop_assert!(max_diff(a.data(), b.data()) == 0.0);
        }
    }

    #[test]
    fn residual_block_grads(m in 3usize..8, w in 1usize..5, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let mut s = ParamStore::new();
        let blk = ResidualBlock::new(&mut s, "r", w, Act::LeakyRelu(0.1), BatchNormConfig::default(), &mut rng).unwrap();
        let x = s.add("x", ParamKind::Trainable, uniform(&[m, w], -1.0, 1.0, &mut rng)).unwrap();
        prop_assume!(off_kinks(&mut s, &blk.a, x, true));
        let h = {
            let mut g = Graph::new(&mut s, false, true);
            let xv = g.param(x);
            let h = blk.a.forward(&mut g, xv).unwrap();
            g.value(h).clone()
        };
        prop_assume!(off_kinks_at(&mut s, &blk.b, &h, true));
        // The sum before the last activation must stay off 0 too.
        let sum_ok = {
            let mut g = Graph::new(&mut s, false, true);
            let xv = g.param(x);
            let h = blk.a.forward(&mut g, xv).unwrap();
            let h2 = blk.b.forward(&mut g, h).unwrap();
            let sm = g.add(xv, h2).unwrap();
            g.value(sm).data().iter().all(|v| v.abs() > 0.05)
        };
        prop_assume!(sum_ok);
        assert_grads(&mut s, |g| { let xv = g.param(x); blk.forward(g, xv) }, true, seed);
    }

    #[test]
    fn losses_match_formulas_and_grads(m in 1usize..12, w in 0.5f32..5.0, seed in 0u64..1000) {
        let mut rng = Rng::new(seed);
        let logits = uniform(&[m, 2], -3.0, 3.0, &mut rng);
        let labels: Vec<u8> = (0..m).map(|_| (rng.f32() < 0.4) as u8).collect();
        let (mut s, ids) = store_of(vec![logits.clone()]);
        let (mut ce_ref, mut wsum, mut fl_ref) = (0.0f64, 0.0f64, 0.0f64);
        for (i, &y) in labels.iter().enumerate() {
            let (a, b) = (logits.data()[2 * i] as f64, logits.data()[2 * i + 1] as f64);
            let lse = (a.exp() + b.exp()).ln();
            let (p0, p1) = ((a - lse).exp(), (b - lse).exp());
            let wi = if y == 1 { w as f64 } else { 1.0 };
            ce_ref -= wi * if y == 1 { b - lse } else { a - lse };
            wsum += wi;
            fl_ref += if y == 1 { p0 } else { p1 };
        }
        ce_ref /= wsum;
        fl_ref /= m as f64;
        {
            let mut g = Graph::eval(&mut s);
            let l = g.param(ids[0]);
            let ce = weighted_cross_entropy(&mut g, l, &labels, w).unwrap();
            let fl = face_loss(&mut g, l, &labels).unwrap();
            prop_assert!((g.value(ce).item().unwrap() as f64 - ce_ref).abs() < 1e-5 * (1.0 + ce_ref));
            prop_assert!((g.value(fl).item().unwrap() as f64 - fl_ref).abs() < 1e-5);
        }
        assert_grads(&mut s, |g| {
            let l = g.param(ids[0]);
            let a = weighted_cross_entropy(g, l, &labels, w)?;
            let b = face_loss(g, l, &labels)?;
            g.add(a, b)
        }, true, seed);
    }
}

#[test]
fn loss_inputs_are_validated() {
    let mut s = ParamStore::new();
    let mut g = Graph::eval(&mut s);
    let l = g.input(Tensor::zeros(&[3, 2]).unwrap());
    assert!(weighted_cross_entropy(&mut g, l, &[0, 1], 1.0).is_err());
    assert!(weighted_cross_entropy(&mut g, l, &[0, 1, 2], 1.0).is_err());
    assert!(weighted_cross_entropy(&mut g, l, &[0, 1, 1], -1.0).is_err());
    assert!(weighted_cross_entropy(&mut g, l, &[0, 1, 1], f32::NAN).is_err());
    let e = g.input(Tensor::zeros(&[0, 2]).unwrap());
    assert!(face_loss(&mut g, e, &[]).is_err());
    let l3 = g.input(Tensor::zeros(&[3, 3]).unwrap());
    assert!(face_loss(&mut g, l3, &[0, 1, 1]).is_err());
}

#[test]
fn train_mode_batch_norm_needs_two_rows() {
    let mut s = ParamStore::new();
    let bn = BatchNorm1d::new(&mut s, "bn", 3, BatchNormConfig::default()).unwrap();
    let mut g = Graph::train(&mut s);
    let x = g.input(Tensor::zeros(&[1, 3]).unwrap());
    assert!(bn.forward(&mut g, x).is_err());
}

#[test]
fn kaiming_uniform_bounds_and_spread() {
    let mut rng = Rng::new(3);
    let mut s = ParamStore::new();
    let conv = Conv1d::new(&mut s, "c", 64, 256, true, &mut rng).unwrap();
    let bound = 1.0 / 8.0;
    let w = s.get(conv.weight).data();
    assert!(w.iter().all(|v| v.abs() <= bound));
    let var = w.iter().map(|&v| (v as f64).powi(2)).sum::<f64>() / w.len() as f64;
    // U(−b, b) has variance b²/3.
    assert!((var / (bound as f64 * bound as f64 / 3.0) - 1.0).abs() < 0.05, "{var}");
    assert!(s.get(conv.bias.unwrap()).data().iter().all(|v| v.abs() <= bound));
    let bn = BatchNorm1d::new(&mut s, "bn", 4, BatchNormConfig::default()).unwrap();
    assert_eq!(s.get(bn.weight).data(), &[1.0; 4]);
    assert_eq!(s.get(bn.bias).data(), &[0.0; 4]);
}

#[test]
fn dropout_is_seeded_scaled_and_off_in_eval() {
    let d = Dropout::new(0.3).unwrap();
    assert!(Dropout::new(1.0).is_err());
    let mut s = ParamStore::new();
    let x = Tensor::full(&[100, 50], 1.0).unwrap();
    let run = |s: &mut ParamStore, train: bool, seed: u64| {
        let mut g = Graph::new(s, false, train);
        let xv = g.input(x.clone());
        let y = d.forward(&mut g, xv, &mut Rng::new(seed)).unwrap();
        g.value(y).clone()
    };
    let a = run(&mut s, true, 1);
    assert_eq!(a, run(&mut s, true, 1));
    assert_ne!(a, run(&mut s, true, 2));
    let zeros = a.data().iter().filter(|&&v| v == 0.0).count() as f64 / a.len() as f64;
    assert!((zeros - 0.3).abs() < 0.03, "{zeros}");
    assert!(a.data().iter().all(|&v| v == 0.0 || (v - 1.0 / 0.7).abs() < 1e-6));
    assert_eq!(run(&mut s, false, 1), x);
}

#[test]
fn no_grad_matches_recording_eval_graph_for_a_network() {
    let mut rng = Rng::new(4);
    let mut s = ParamStore::new();
    let bn = BatchNormConfig::default();
    let net = Sequential::new(vec![
        Box::new(ConvBnAct::new(&mut s, "a", 5, 16, Act::LeakyRelu(0.1), bn, &mut rng).unwrap()),
        Box::new(ResidualBlock::new(&mut s, "r", 16, Act::LeakyRelu(0.1), bn, &mut rng).unwrap()),
        Box::new(ConvBnAct::new(&mut s, "b", 16, 8, Act::Relu, bn, &mut rng).unwrap()),
        Box::new(Conv1d::new(&mut s, "c", 8, 2, true, &mut rng).unwrap()),
    ]);
    // Train a few batches so the running statistics are not the initial ones.
    for _ in 0..3 {
        let mut g = Graph::train(&mut s);
        let x = g.input(uniform(&[40, 5], -1.0, 2.0, &mut rng));
        net.forward(&mut g, x).unwrap();
    }
    let x = uniform(&[33, 5], -1.0, 2.0, &mut rng);
    let out = |s: &mut ParamStore, record: bool| {
        let mut g = Graph::new(s, record, false);
        let xv = g.input(x.clone());
        let y = net.forward(&mut g, xv).unwrap();
        g.value(y).clone()
    };
    let a = out(&mut s, false);
    let b = out(&mut s, true);
    assert_eq!(a, b);
}
