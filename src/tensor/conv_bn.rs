//! Kernels of the fused conv1d (kernel size 1) + batch norm + activation: the hot path
//! of the face network. Forward: `z = x·Wᵀ` (parallel row-block GEMM), per-channel
//! statistics (fixed row chunks, f64 partial sums combined in chunk order), then one
//! pass `a = act(γ·(z − μ)·σ⁻¹ + β)`. Backward: one pass turns `∂L/∂a` into `∂L/∂y` and
//! collects `Σ∂L/∂y`, `Σ∂L/∂y·ẑ`; a second gives `∂L/∂z` in place; two GEMMs give
//! `∂L/∂x` and `∂L/∂W`. Results do not depend on the thread count.

use super::gemm;
use super::op::Act;
use crate::par;

/// Rows per chunk for statistics and element-wise passes (fixed: determinism).
pub const STAT_BLOCK: usize = 1024;

/// `z = x·Wᵀ` for `x: [m × cin]`, `w: [cout × cin]`, into a new `[m × cout]` buffer.
pub fn linear(x: &[f32], m: usize, cin: usize, w: &[f32], cout: usize) -> Vec<f32> {
    let mut z = vec![0.0f32; m * cout];
    gemm::gemm_rows(m, cout, cin, x, false, w, true, &mut z, 0.0);
    z
}

/// Per-channel mean and biased variance of `z: [m × c]` (f64 accumulation per chunk,
/// chunks summed in order). Returns `(mean, var)`.
pub fn batch_stats(z: &[f32], m: usize, c: usize) -> (Vec<f64>, Vec<f64>) {
    let chunks = m.div_ceil(STAT_BLOCK);
    let partial = par::map(chunks, |ci| {
        let r0 = ci * STAT_BLOCK;
        let r1 = (r0 + STAT_BLOCK).min(m);
        let mut s = vec![0.0f64; 2 * c];
        let (s1, s2) = s.split_at_mut(c);
        for row in z[r0 * c..r1 * c].chunks_exact(c) {
            for ((a, b), &v) in s1.iter_mut().zip(s2.iter_mut()).zip(row) {
                let v = v as f64;
                *a += v;
                *b += v * v;
            }
        }
        s
    });
    let mut mean = vec![0.0f64; c];
    let mut sq = vec![0.0f64; c];
    for p in &partial {
        for j in 0..c {
            mean[j] += p[j];
            sq[j] += p[c + j];
        }
    }
    let inv = 1.0 / m.max(1) as f64;
    let mut var = vec![0.0f64; c];
    for j in 0..c {
        mean[j] *= inv;
        var[j] = (sq[j] * inv - mean[j] * mean[j]).max(0.0);
    }
    (mean, var)
}

/// `out = act(z·scale + shift)` per channel, `z` and `out` `[m × c]`.
pub fn affine_act(z: &[f32], out: &mut [f32], c: usize, scale: &[f32], shift: &[f32], act: Act) {
    if c == 0 {
        return;
    }
    par::for_each_chunk_mut(out, STAT_BLOCK * c, |ci, oc| {
        let zc = &z[ci * STAT_BLOCK * c..ci * STAT_BLOCK * c + oc.len()];
        for (orow, zrow) in oc.chunks_exact_mut(c).zip(zc.chunks_exact(c)) {
            for j in 0..c {
                orow[j] = act.apply(zrow[j] * scale[j] + shift[j]);
            }
        }
    });
}

/// In place: `buf = act(buf·scale + shift)` per channel.
pub fn affine_act_inplace(buf: &mut [f32], c: usize, scale: &[f32], shift: &[f32], act: Act) {
    if c == 0 {
        return;
    }
    par::for_each_chunk_mut(buf, STAT_BLOCK * c, |_, bc| {
        for row in bc.chunks_exact_mut(c) {
            for j in 0..c {
                row[j] = act.apply(row[j] * scale[j] + shift[j]);
            }
        }
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
    let partial = par::map_chunks_mut(g, STAT_BLOCK * c, |ci, gc| {
        let off = ci * STAT_BLOCK * c;
        let oc = &out[off..off + gc.len()];
        let zc = &z[off..off + gc.len()];
        let mut s = vec![0.0f64; 2 * c];
        let (sb, sg) = s.split_at_mut(c);
        for ((grow, orow), zrow) in gc.chunks_exact_mut(c).zip(oc.chunks_exact(c)).zip(zc.chunks_exact(c)) {
            for j in 0..c {
                let gy = grow[j] * act.grad_from_output(orow[j]);
                grow[j] = gy;
                let zhat = (zrow[j] - mean[j]) * invstd[j];
                sb[j] += gy as f64;
                sg[j] += (gy * zhat) as f64;
            }
        }
        s
    });
    let mut dbeta = vec![0.0f64; c];
    let mut dgamma = vec![0.0f64; c];
    for p in &partial {
        for j in 0..c {
            dbeta[j] += p[j];
            dgamma[j] += p[c + j];
        }
    }
    let k1: Vec<f32> = (0..c).map(|j| gamma[j] * invstd[j]).collect();
    if batch_stats {
        let inv_m = 1.0 / m as f64;
        let mb: Vec<f32> = dbeta.iter().map(|&v| (v * inv_m) as f32).collect();
        let mg: Vec<f32> = dgamma.iter().map(|&v| (v * inv_m) as f32).collect();
        par::for_each_chunk_mut(g, STAT_BLOCK * c, |ci, gc| {
            let off = ci * STAT_BLOCK * c;
            let zc = &z[off..off + gc.len()];
            for (grow, zrow) in gc.chunks_exact_mut(c).zip(zc.chunks_exact(c)) {
                for j in 0..c {
                    let zhat = (zrow[j] - mean[j]) * invstd[j];
                    grow[j] = k1[j] * (grow[j] - mb[j] - zhat * mg[j]);
                }
            }
        });
    } else {
        par::for_each_chunk_mut(g, STAT_BLOCK * c, |_, gc| {
            for grow in gc.chunks_exact_mut(c) {
                for j in 0..c {
                    grow[j] *= k1[j];
                }
            }
        });
    }
    (dgamma.iter().map(|&v| v as f32).collect(), dbeta.iter().map(|&v| v as f32).collect())
}
