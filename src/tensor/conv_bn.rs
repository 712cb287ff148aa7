//! Kernels of the fused conv1d (kernel size 1) + batch norm + activation: the hot path
//! of the face network. Forward: per block of [`gemm::ROW_BLOCK`] rows, `z = x·Wᵀ` (one
//! GEMM) and, while the block is in cache, its per-channel f64 partial sums (train) or
//! directly `act(z·scale + shift)` (eval); partials are combined in block order. Train
//! mode then makes one pass `a = act(γ·(z − μ)·σ⁻¹ + β)`. Backward: one pass turns
//! `∂L/∂a` into `∂L/∂y` and collects `Σ∂L/∂y`, `Σ∂L/∂y·ẑ`; a second gives `∂L/∂z` in
//! place; two GEMMs give `∂L/∂x` and `∂L/∂W`. Each loop is specialised per activation
//! (no branch on the variant inside). Results do not depend on the thread count.

use super::gemm::{self, ROW_BLOCK};
use super::op::Act;
use crate::par;

/// Rows per chunk of the element-wise passes (fixed: determinism).
pub const STAT_BLOCK: usize = ROW_BLOCK;

/// Calls `$body` with `$f` bound to the activation as a closure (monomorphised).
macro_rules! with_act {
    ($act:expr, $f:ident, $body:expr) => {
        match $act {
            Act::Identity => {
                let $f = |y: f32| y;
                $body
            }
            Act::Relu => {
                let $f = |y: f32| y.max(0.0);
                $body
            }
            Act::LeakyRelu(s) => {
                let $f = move |y: f32| y.max(0.0) + s * y.min(0.0);
                $body
            }
        }
    };
}

/// Same, with `$f` the derivative read from the activation's output.
macro_rules! with_act_grad {
    ($act:expr, $f:ident, $body:expr) => {
        match $act {
            Act::Identity => {
                let $f = |_a: f32| 1.0f32;
                $body
            }
            Act::Relu => {
                let $f = |a: f32| if a > 0.0 { 1.0f32 } else { 0.0 };
                $body
            }
            Act::LeakyRelu(s) => {
                let $f = move |a: f32| if a > 0.0 { 1.0f32 } else { s };
                $body
            }
        }
    };
}

/// Computes one block's `z` rows (`x·Wᵀ`, or a copy of `x` without weight).
fn block_z(x: &[f32], m: usize, cin: usize, w: Option<&[f32]>, cout: usize, bi: usize, zb: &mut [f32]) {
    let r0 = bi * ROW_BLOCK;
    let rows = zb.len() / cout;
    match w {
        Some(w) => gemm::gemm_block(rows, cout, cin, x, false, m, r0, w, true, zb, 0.0),
        None => zb.copy_from_slice(&x[r0 * cin..(r0 + rows) * cin]),
    }
}

/// Train-mode forward part 1: `z = x·Wᵀ` (`w = None`: `z = x`, `cin = cout`) into a new
/// `[m × cout]` buffer, with the per-channel mean and biased variance (f64).
pub fn linear_stats(
    x: &[f32],
    m: usize,
    cin: usize,
    w: Option<&[f32]>,
    cout: usize,
) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
    let mut z = vec![0.0f32; m * cout];
    if cout == 0 || m == 0 {
        return (z, vec![0.0; cout], vec![0.0; cout]);
    }
    let partial = par::map_chunks_mut(&mut z, ROW_BLOCK * cout, |bi, zb| {
        block_z(x, m, cin, w, cout, bi, zb);
        let mut s = vec![0.0f64; 2 * cout];
        let (s1, s2) = s.split_at_mut(cout);
        for row in zb.chunks_exact(cout) {
            for ((a, b), &v) in s1.iter_mut().zip(s2.iter_mut()).zip(row) {
                let v = v as f64;
                *a += v;
                *b += v * v;
            }
        }
        s
    });
    let mut mean = vec![0.0f64; cout];
    let mut sq = vec![0.0f64; cout];
    for p in &partial {
        for j in 0..cout {
            mean[j] += p[j];
            sq[j] += p[cout + j];
        }
    }
    let inv = 1.0 / m as f64;
    let mut var = vec![0.0f64; cout];
    for j in 0..cout {
        mean[j] *= inv;
        var[j] = (sq[j] * inv - mean[j] * mean[j]).max(0.0);
    }
    (z, mean, var)
}

/// Eval-mode forward in one pass per block: `act((x·Wᵀ)·scale + shift)`.
#[allow(clippy::too_many_arguments)]
pub fn linear_affine_act(
    x: &[f32],
    m: usize,
    cin: usize,
    w: Option<&[f32]>,
    cout: usize,
    scale: &[f32],
    shift: &[f32],
    act: Act,
) -> Vec<f32> {
    let mut out = vec![0.0f32; m * cout];
    if cout == 0 || m == 0 {
        return out;
    }
    with_act!(act, f, {
        par::for_each_chunk_mut(&mut out, ROW_BLOCK * cout, |bi, ob| {
            block_z(x, m, cin, w, cout, bi, ob);
            for row in ob.chunks_exact_mut(cout) {
                for ((v, &k), &b) in row.iter_mut().zip(scale).zip(shift) {
                    *v = f(*v * k + b);
                }
            }
        })
    });
    out
}

/// `out = act(z·scale + shift)` per channel, `z` and `out` `[m × c]`.
pub fn affine_act(z: &[f32], out: &mut [f32], c: usize, scale: &[f32], shift: &[f32], act: Act) {
    if c == 0 {
        return;
    }
    with_act!(act, f, {
        par::for_each_chunk_mut(out, STAT_BLOCK * c, |ci, oc| {
            let zc = &z[ci * STAT_BLOCK * c..ci * STAT_BLOCK * c + oc.len()];
            for (orow, zrow) in oc.chunks_exact_mut(c).zip(zc.chunks_exact(c)) {
                for (((o, &zv), &k), &b) in orow.iter_mut().zip(zrow).zip(scale).zip(shift) {
                    *o = f(zv * k + b);
                }
            }
        })
    });
}

/// In place: `buf = act(buf·scale + shift)` per channel.
pub fn affine_act_inplace(buf: &mut [f32], c: usize, scale: &[f32], shift: &[f32], act: Act) {
    if c == 0 {
        return;
    }
    with_act!(act, f, {
        par::for_each_chunk_mut(buf, STAT_BLOCK * c, |_, bc| {
            for row in bc.chunks_exact_mut(c) {
                for ((v, &k), &b) in row.iter_mut().zip(scale).zip(shift) {
                    *v = f(*v * k + b);
                }
            }
        })
    });
}

/// Backward of `a = act(γ·ẑ + β)`, `ẑ = (z − μ)·invstd`, in place on `g` (`∂L/∂a` in,
/// `∂L/∂z` out). With `batch_stats` the statistics depend on `z` (train mode) and
/// their gradient is included. Returns `(∂L/∂γ, ∂L/∂β)`.
#[allow(clippy::too_many_arguments)]
pub fn bn_act_backward(
    g: &mut [f32],
    out: &[f32],
    z: &[f32],
    m: usize,
    c: usize,
    mean: &[f32],
    invstd: &[f32],
    gamma: &[f32],
    act: Act,
    batch_stats: bool,
) -> (Vec<f32>, Vec<f32>) {
    if c == 0 || m == 0 {
        return (vec![0.0; c], vec![0.0; c]);
    }
    // Per-block partial sums in f32 over ≤ STAT_BLOCK rows (combined in f64 below).
    let partial = with_act_grad!(act, df, {
        par::map_chunks_mut(g, STAT_BLOCK * c, |ci, gc| {
            let off = ci * STAT_BLOCK * c;
            let oc = &out[off..off + gc.len()];
            let zc = &z[off..off + gc.len()];
            let mut s = vec![0.0f32; 2 * c];
            let (sb, sg) = s.split_at_mut(c);
            for ((grow, orow), zrow) in gc.chunks_exact_mut(c).zip(oc.chunks_exact(c)).zip(zc.chunks_exact(c))
            {
                for j in 0..c {
                    let gy = grow[j] * df(orow[j]);
                    grow[j] = gy;
                    let zhat = (zrow[j] - mean[j]) * invstd[j];
                    sb[j] += gy;
                    sg[j] += gy * zhat;
                }
            }
            s
        })
    });
    let mut dbeta = vec![0.0f64; c];
    let mut dgamma = vec![0.0f64; c];
    for p in &partial {
        for j in 0..c {
            dbeta[j] += p[j] as f64;
            dgamma[j] += p[c + j] as f64;
        }
    }
    let k1: Vec<f32> = (0..c).map(|j| gamma[j] * invstd[j]).collect();
    if batch_stats {
        let inv_m = 1.0 / m as f64;
        // ∂z = k1·(gy − mb − ẑ·mg) = k1·gy − k1·mb − k1·mg·invstd·(z − μ): an affine
        // map of (gy, z) per channel.
        let mb: Vec<f32> = dbeta.iter().map(|&v| (v * inv_m) as f32).collect();
        let mg: Vec<f32> = dgamma.iter().map(|&v| (v * inv_m) as f32).collect();
        let kz: Vec<f32> = (0..c).map(|j| k1[j] * mg[j] * invstd[j]).collect();
        let k0: Vec<f32> = (0..c).map(|j| -k1[j] * mb[j] + kz[j] * mean[j]).collect();
        par::for_each_chunk_mut(g, STAT_BLOCK * c, |ci, gc| {
            let off = ci * STAT_BLOCK * c;
            let zc = &z[off..off + gc.len()];
            for (grow, zrow) in gc.chunks_exact_mut(c).zip(zc.chunks_exact(c)) {
                for j in 0..c {
                    grow[j] = k1[j] * grow[j] - kz[j] * zrow[j] + k0[j];
                }
            }
        });
    } else {
        par::for_each_chunk_mut(g, STAT_BLOCK * c, |_, gc| {
            for grow in gc.chunks_exact_mut(c) {
                for (v, &k) in grow.iter_mut().zip(&k1) {
                    *v *= k;
                }
            }
        });
    }
    (dgamma.iter().map(|&v| v as f32).collect(), dbeta.iter().map(|&v| v as f32).collect())
}
