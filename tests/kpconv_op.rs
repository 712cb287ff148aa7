//! Property tests of the raw rigid KPConv kernel: forward against the direct formula, both
//! hand-written gradients against central finite differences (computed in f64 on the same
//! formula), and determinism of the parallel backward.

#[path = "common/kpconv.rs"]
mod kpc;

use kpc::{problem, Problem};
use point2quad::nn::kpconv::{kpconv_backward, kpconv_forward};
use proptest::prelude::*;

/// The KPConv formula evaluated directly in f64: out[q][o] = Σ_j Σ_k h_kj Σ_c f[j][c] W[k][c][o].
fn reference(p: &Problem, f: &[f64], w: &[f64]) -> Vec<f64> {
    let (ci, co) = (p.c_in, p.c_out);
    let mut out = vec![0.0; p.queries.len() * co];
    for (q, qp) in p.queries.iter().enumerate() {
        for &j in &p.neighbors[q * p.cap..(q + 1) * p.cap] {
            let j = j as usize;
            if j == p.support.len() {
                continue;
            }
            for (k, kp) in p.kernel.iter().enumerate() {
                let d: f64 = (0..3)
                    .map(|a| (p.support[j][a] as f64 - qp[a] as f64 - kp[a] as f64).powi(2))
                    .sum::<f64>()
                    .sqrt();
                let h = (1.0 - d / p.sigma as f64).max(0.0);
                for c in 0..ci {
                    for o in 0..co {
                        out[q * co + o] += h * f[j * ci + c] * w[(k * ci + c) * co + o];
                    }
                }
            }
        }
    }
    out
}

fn loss(p: &Problem, f: &[f64], w: &[f64]) -> f64 {
    reference(p, f, w).iter().zip(&p.grad_out).map(|(o, g)| o * *g as f64).sum()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn forward_matches_formula(p in problem()) {
        let out = kpconv_forward(&p.geometry(), &p.features, p.c_in, &p.weights, p.c_out).unwrap();
        let f: Vec<f64> = p.features.iter().map(|&x| x as f64).collect();
        let w: Vec<f64> = p.weights.iter().map(|&x| x as f64).collect();
        let want = reference(&p, &f, &w);
        for (a, b) in out.iter().zip(&want) {
            prop_assert!((*a as f64 - b).abs() <= 1e-4 * (1.0 + b.abs()), "{} vs {}", a, b);
        }
    }

    /// The loss Σ out·g is linear in f and in W separately, so central differences are exact up to
    /// rounding: this checks the gradients tightly.
    #[test]
    fn gradients_match_finite_differences(p in problem()) {
        let (gf, gw) = kpconv_backward(&p.geometry(), &p.features, p.c_in, &p.weights, p.c_out, &p.grad_out).unwrap();
        let f: Vec<f64> = p.features.iter().map(|&x| x as f64).collect();
        let w: Vec<f64> = p.weights.iter().map(|&x| x as f64).collect();
        let eps = 1e-3;
        for i in 0..f.len() {
            let (mut fp, mut fm) = (f.clone(), f.clone());
            fp[i] += eps;
            fm[i] -= eps;
            let fd = (loss(&p, &fp, &w) - loss(&p, &fm, &w)) / (2.0 * eps);
            prop_assert!((gf[i] as f64 - fd).abs() <= 1e-3 * (1.0 + fd.abs()), "df[{}]: {} vs {}", i, gf[i], fd);
        }
        for i in 0..w.len() {
            let (mut wp, mut wm) = (w.clone(), w.clone());
            wp[i] += eps;
            wm[i] -= eps;
            let fd = (loss(&p, &f, &wp) - loss(&p, &f, &wm)) / (2.0 * eps);
            prop_assert!((gw[i] as f64 - fd).abs() <= 1e-3 * (1.0 + fd.abs()), "dW[{}]: {} vs {}", i, gw[i], fd);
        }
        // The same check through the fused f32 forward itself (linear, so eps can be large).
        let g = p.geometry();
        let l32 = |f: &[f32], w: &[f32]| -> f64 {
            let out = kpconv_forward(&g, f, p.c_in, w, p.c_out).unwrap();
            out.iter().zip(&p.grad_out).map(|(o, g)| *o as f64 * *g as f64).sum()
        };
        let e32 = 0.25f32;
        for i in 0..p.features.len() {
            let (mut fp, mut fm) = (p.features.clone(), p.features.clone());
            fp[i] += e32;
            fm[i] -= e32;
            let fd = (l32(&fp, &p.weights) - l32(&fm, &p.weights)) / (2.0 * e32 as f64);
            prop_assert!((gf[i] as f64 - fd).abs() <= 1e-2 * (1.0 + fd.abs()), "df32[{}]: {} vs {}", i, gf[i], fd);
        }
        for i in 0..p.weights.len() {
            let (mut wp, mut wm) = (p.weights.clone(), p.weights.clone());
            wp[i] += e32;
            wm[i] -= e32;
            let fd = (l32(&p.features, &wp) - l32(&p.features, &wm)) / (2.0 * e32 as f64);
            prop_assert!((gw[i] as f64 - fd).abs() <= 1e-2 * (1.0 + fd.abs()), "dW32[{}]: {} vs {}", i, gw[i], fd);
        }
    }
}

/// A problem big enough to use several parallel tasks and GEMM's fast path: the backward must
/// be bit-identical between runs (fixed chunking, no scatter) and match the f64 reference.
#[test]
fn large_backward_is_deterministic_and_correct() {
    let mut rng = point2quad::rng::Rng::new(17);
    let ns = 3000;
    let support: Vec<[f32; 3]> = (0..ns).map(|_| [rng.f32(), rng.f32(), rng.f32()]).collect();
    let queries: Vec<[f32; 3]> = support.iter().step_by(2).copied().collect();
    let tree = point2quad::spatial::kdtree::KdTree::build(&support);
    let nb = point2quad::spatial::neighborhoods::radius_neighborhoods(
        &tree,
        &queries,
        0.1,
        point2quad::spatial::neighborhoods::NeighborCap::Percentile(0.9),
    )
    .unwrap();
    let kernel = point2quad::nn::kernel_points::scaled_kernel_points(15, 0, 0.1).unwrap();
    let (c_in, c_out) = (8, 16);
    let features: Vec<f32> = (0..ns * c_in).map(|_| rng.f32() - 0.5).collect();
    let weights: Vec<f32> = (0..15 * c_in * c_out).map(|_| rng.f32() - 0.5).collect();
    let grad_out: Vec<f32> = (0..queries.len() * c_out).map(|_| rng.f32() - 0.5).collect();
    let p = Problem {
        queries,
        support,
        neighbors: nb.indices.clone(),
        cap: nb.cap,
        kernel,
        sigma: 0.04,
        c_in,
        c_out,
        features,
        weights,
        grad_out,
    };
    let g = p.geometry();
    let a = kpconv_backward(&g, &p.features, c_in, &p.weights, c_out, &p.grad_out).unwrap();
    let b = kpconv_backward(&g, &p.features, c_in, &p.weights, c_out, &p.grad_out).unwrap();
    assert_eq!(a, b);
    // dW is the exact linear map: compare one random column against the reference via linearity.
    let f: Vec<f64> = p.features.iter().map(|&x| x as f64).collect();
    let w: Vec<f64> = p.weights.iter().map(|&x| x as f64).collect();
    let out = kpconv_forward(&g, &p.features, c_in, &p.weights, c_out).unwrap();
    let want = reference(&p, &f, &w);
    for (x, y) in out.iter().zip(&want) {
        assert!((*x as f64 - y).abs() <= 1e-4 * (1.0 + y.abs()));
    }
    // ⟨dOut, out⟩ = ⟨dW, W⟩ = ⟨df, f⟩ (out is bilinear in f and W).
    let l: f64 = out.iter().zip(&p.grad_out).map(|(o, g)| *o as f64 * *g as f64).sum();
    let lw: f64 = a.1.iter().zip(&p.weights).map(|(g, x)| *g as f64 * *x as f64).sum();
    let lf: f64 = a.0.iter().zip(&p.features).map(|(g, x)| *g as f64 * *x as f64).sum();
    assert!((l - lw).abs() <= 1e-3 * (1.0 + l.abs()), "{l} vs {lw}");
    assert!((l - lf).abs() <= 1e-3 * (1.0 + l.abs()), "{l} vs {lf}");
}
