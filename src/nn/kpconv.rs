//! Rigid KPConv (Thomas et al. 2019) as a fused kernel on flat slices: forward and hand-written
//! backward to features and weights, parallel over output points, deterministic for any thread count.
//!
//! For an output point q with neighbours x_j (relative position y = x_j − q) and kernel points
//! k_k, the influence is h_kj = max(0, 1 − |y − k_k| / σ) and
//! `out[q] = Σ_k Σ_j h_kj · f_j · W_k` (sum aggregation, W: K × C_in × C_out). Per point the kernel
//! first gathers `A_q = Σ_j h_kj f_j` (K × C_in, only over the (k, j) with h > 0, listed once in a
//! [`KpConvGeometry`]), then a block of points is one GEMM `[B × K·C_in] · [K·C_in × C_out]`.
//! Backward: `dW = Aᵀ · dOut` and `dA = dOut · Wᵀ`, then `df_j = Σ h_kj dA_q[k]` gathered through
//! the transposed influence table (no scatter, so no races and a fixed summation order).

use std::sync::Arc;

use nalgebra::{DMatrixView, DMatrixViewMut};

use crate::tensor::{CustomOp, Tensor};
use crate::{par, Error, Result};

/// One non-zero influence: neighbour `support` of an output point contributes `h` to kernel point `kernel`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InfluenceEntry {
    /// Index of the support point (never the shadow).
    pub support: u32,
    /// Kernel point index.
    pub kernel: u32,
    /// Influence, in (0, 1].
    pub h: f32,
}

/// The non-zero kernel influences of one KPConv application (one layer on one cloud),
/// computed from geometry only: fixed across epochs since rigid kernel points do not move.
#[derive(Clone, Debug)]
pub struct KpConvGeometry {
    /// Number of output (query) points.
    pub n_queries: usize,
    /// Number of support points (input feature rows).
    pub n_support: usize,
    /// Number of kernel points K.
    pub n_kernel: usize,
    /// CSR offsets into `entries`, `n_queries + 1` long. Invariant: entries of query q are
    /// `entries[offsets[q]..offsets[q+1]]`, in neighbour-slot order then kernel order.
    pub offsets: Vec<usize>,
    /// Non-zero influences.
    pub entries: Vec<InfluenceEntry>,
}

/// Queries handled per parallel task when building geometry.
const GEOM_BLOCK: usize = 256;

impl KpConvGeometry {
    /// Influences for `queries` over `support`, with `neighbors` a `queries.len() × cap` row-major
    /// table of support indices padded with the shadow index `support.len()`, `kernel` the kernel
    /// points already scaled to the layer's radius, and `sigma` the influence extent.
    ///
    /// # Errors
    /// `Shape` when the neighbour table length is not `queries.len() × cap`; `InvalidInput` when a
    /// neighbour index exceeds the shadow index, `sigma` is not finite and positive, or `kernel` is empty.
    pub fn new(
        queries: &[[f32; 3]],
        support: &[[f32; 3]],
        neighbors: &[u32],
        cap: usize,
        kernel: &[[f32; 3]],
        sigma: f32,
    ) -> Result<Self> {
        if neighbors.len() != queries.len() * cap {
            return Err(Error::Shape {
                op: "kpconv",
                msg: format!(
                    "neighbour table has {} entries, expected {} × {cap}",
                    neighbors.len(),
                    queries.len()
                ),
            });
        }
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(Error::invalid(format!("KPConv extent sigma must be finite and > 0, got {sigma}")));
        }
        if kernel.is_empty() {
            return Err(Error::invalid("KPConv needs at least one kernel point"));
        }
        let shadow = support.len();
        if let Some(pos) = neighbors.iter().position(|&j| j as usize > shadow) {
            return Err(Error::invalid(format!(
                "neighbour index {} of query {} exceeds the shadow index {shadow}",
                neighbors[pos],
                pos / cap.max(1)
            )));
        }
        let inv_sigma = 1.0 / sigma;
        let sigma_sq = sigma * sigma;
        let n_blocks = queries.len().div_ceil(GEOM_BLOCK);
        let blocks: Vec<(Vec<usize>, Vec<InfluenceEntry>)> = par::map(n_blocks, |b| {
            let q0 = b * GEOM_BLOCK;
            let q1 = (q0 + GEOM_BLOCK).min(queries.len());
            let mut counts = Vec::with_capacity(q1 - q0);
            let mut entries = Vec::new();
            for (q, qp) in queries.iter().enumerate().take(q1).skip(q0) {
                let before = entries.len();
                for &j in &neighbors[q * cap..(q + 1) * cap] {
                    if j as usize == shadow {
                        continue;
                    }
                    let x = support[j as usize];
                    let y = [x[0] - qp[0], x[1] - qp[1], x[2] - qp[2]];
                    for (k, kp) in kernel.iter().enumerate() {
                        let d = [y[0] - kp[0], y[1] - kp[1], y[2] - kp[2]];
                        let d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
                        // Most (point, kernel point) pairs are out of reach: test before the sqrt.
                        if d2 < sigma_sq {
                            let h = 1.0 - d2.sqrt() * inv_sigma;
                            if h > 0.0 {
                                entries.push(InfluenceEntry { support: j, kernel: k as u32, h });
                            }
                        }
                    }
                }
                counts.push(entries.len() - before);
            }
            (counts, entries)
        });
        let total: usize = blocks.iter().map(|b| b.1.len()).sum();
        let mut offsets = Vec::with_capacity(queries.len() + 1);
        let mut entries = Vec::with_capacity(total);
        offsets.push(0);
        for (counts, e) in blocks {
            for c in counts {
                offsets.push(offsets.last().expect("internal error: offsets start with 0") + c);
            }
            entries.extend(e);
        }
        Ok(KpConvGeometry {
            n_queries: queries.len(),
            n_support: support.len(),
            n_kernel: kernel.len(),
            offsets,
            entries,
        })
    }

    /// The transposed table: for each support point, the `(query, kernel, h)` entries that read it,
    /// ordered by query then kernel (stable counting sort, so the order is fixed).
    fn transpose(&self) -> (Vec<usize>, Vec<InfluenceEntry>) {
        let mut offsets = vec![0usize; self.n_support + 1];
        for e in &self.entries {
            offsets[e.support as usize + 1] += 1;
        }
        for i in 0..self.n_support {
            offsets[i + 1] += offsets[i];
        }
        let mut fill = offsets.clone();
        let mut out = vec![InfluenceEntry { support: 0, kernel: 0, h: 0.0 }; self.entries.len()];
        for q in 0..self.n_queries {
            for e in &self.entries[self.offsets[q]..self.offsets[q + 1]] {
                let s = e.support as usize;
                // `support` in the transposed table holds the query index.
                out[fill[s]] = InfluenceEntry { support: q as u32, kernel: e.kernel, h: e.h };
                fill[s] += 1;
            }
        }
        (offsets, out)
    }
}

/// `c (m×n, row-major) = alpha · a · b + beta · c` where `a` is m×k and `b` is k×n, each given as a
/// slice with (row stride, column stride). Goes through nalgebra's (matrixmultiply) GEMM.
#[allow(clippy::too_many_arguments)]
fn gemm(
    m: usize,
    k: usize,
    n: usize,
    alpha: f32,
    a: &[f32],
    a_strides: (usize, usize),
    b: &[f32],
    b_strides: (usize, usize),
    beta: f32,
    c: &mut [f32],
) {
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        c[..m * n].iter_mut().for_each(|x| *x *= beta);
        return;
    }
    // nalgebra hands only matrices with every dimension > 5 to matrixmultiply; its fallback for
    // smaller ones mishandles strided views, so those take this plain loop instead.
    if m <= 5 || n <= 5 || k <= 5 {
        for i in 0..m {
            for j in 0..n {
                let mut acc = 0.0f32;
                for l in 0..k {
                    acc += a[i * a_strides.0 + l * a_strides.1] * b[l * b_strides.0 + j * b_strides.1];
                }
                let cij = &mut c[i * n + j];
                *cij = alpha * acc + if beta == 0.0 { 0.0 } else { beta * *cij };
            }
        }
        return;
    }
    let av = DMatrixView::from_slice_with_strides(a, m, k, a_strides.0, a_strides.1);
    let bv = DMatrixView::from_slice_with_strides(b, k, n, b_strides.0, b_strides.1);
    let mut cv = DMatrixViewMut::from_slice_with_strides_mut(c, m, n, n, 1);
    cv.gemm(alpha, &av, &bv, beta);
}

/// Columns per parallel task when a GEMM has too few rows to split by rows.
const COL_BLOCK: usize = 128;

/// `c (m×n, row-major) = a · b` split over fixed blocks of [`COL_BLOCK`] columns, each computed
/// into its own buffer and copied into place. Every element is produced by one GEMM call with
/// the same reduction over k, so the result does not depend on the thread count.
#[allow(clippy::too_many_arguments)]
fn gemm_col_split(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    a_strides: (usize, usize),
    b: &[f32],
    b_strides: (usize, usize),
    c: &mut [f32],
) {
    let n_blocks = n.div_ceil(COL_BLOCK);
    let blocks: Vec<Vec<f32>> = par::map(n_blocks, |bi| {
        let c0 = bi * COL_BLOCK;
        let cb = COL_BLOCK.min(n - c0);
        let mut tmp = vec![0.0f32; m * cb];
        gemm(m, k, cb, 1.0, a, a_strides, &b[c0 * b_strides.1..], b_strides, 0.0, &mut tmp);
        tmp
    });
    for (bi, tmp) in blocks.iter().enumerate() {
        let c0 = bi * COL_BLOCK;
        let cb = COL_BLOCK.min(n - c0);
        for r in 0..m {
            c[r * n + c0..r * n + c0 + cb].copy_from_slice(&tmp[r * cb..(r + 1) * cb]);
        }
    }
}

/// Output rows per parallel task: a task's gathered block A (rows × K·C_in) stays near 4 MiB,
/// and at least 128 rows share one packing of the weights (GEMM packs W once per call, which
/// costs as much as the multiply itself for a few dozen rows). Independent of the thread count.
fn rows_per_task(kc: usize) -> usize {
    ((1usize << 20) / kc.max(1)).clamp(128, 2048)
}

/// Gathers `A_q = Σ h_kj f_j` for queries `q0..q0 + rows` into `a` (rows × K·C_in, zeroed here).
fn gather_block(geom: &KpConvGeometry, features: &[f32], c_in: usize, q0: usize, rows: usize, a: &mut [f32]) {
    let kc = geom.n_kernel * c_in;
    a[..rows * kc].iter_mut().for_each(|x| *x = 0.0);
    for r in 0..rows {
        let q = q0 + r;
        let row = &mut a[r * kc..(r + 1) * kc];
        for e in &geom.entries[geom.offsets[q]..geom.offsets[q + 1]] {
            let f = &features[e.support as usize * c_in..(e.support as usize + 1) * c_in];
            let dst = &mut row[e.kernel as usize * c_in..(e.kernel as usize + 1) * c_in];
            for (d, &v) in dst.iter_mut().zip(f) {
                *d += e.h * v;
            }
        }
    }
}

fn check_shapes(
    geom: &KpConvGeometry,
    features: &[f32],
    c_in: usize,
    weights: &[f32],
    c_out: usize,
) -> Result<()> {
    if features.len() != geom.n_support * c_in {
        return Err(Error::Shape {
            op: "kpconv",
            msg: format!("features have {} values, expected {} × {c_in}", features.len(), geom.n_support),
        });
    }
    if weights.len() != geom.n_kernel * c_in * c_out {
        return Err(Error::Shape {
            op: "kpconv",
            msg: format!(
                "weights have {} values, expected {} × {c_in} × {c_out}",
                weights.len(),
                geom.n_kernel
            ),
        });
    }
    Ok(())
}

/// Forward: `features` is `n_support × c_in`, `weights` is `K × c_in × c_out` (row-major); returns
/// `n_queries × c_out`.
///
/// # Errors
/// `Shape` when a buffer length does not match the geometry and channel counts.
pub fn kpconv_forward(
    geom: &KpConvGeometry,
    features: &[f32],
    c_in: usize,
    weights: &[f32],
    c_out: usize,
) -> Result<Vec<f32>> {
    check_shapes(geom, features, c_in, weights, c_out)?;
    let kc = geom.n_kernel * c_in;
    let rows = rows_per_task(kc);
    let mut out = vec![0.0f32; geom.n_queries * c_out];
    if c_out == 0 {
        return Ok(out);
    }
    if geom.n_queries >= 2 * rows || c_out < 2 * COL_BLOCK {
        par::for_each_chunk_mut(&mut out, rows * c_out, |ci, chunk| {
            let q0 = ci * rows;
            let n = chunk.len() / c_out;
            // One buffer per task, reused for all of the task's rows.
            let mut a = vec![0.0f32; n * kc];
            gather_block(geom, features, c_in, q0, n, &mut a);
            gemm(n, kc, c_out, 1.0, &a, (kc, 1), weights, (c_out, 1), 0.0, chunk);
        });
    } else {
        // Few points, wide layers (the coarse levels): one gather, the GEMM split by columns.
        let mut a = vec![0.0f32; geom.n_queries * kc];
        gather_block(geom, features, c_in, 0, geom.n_queries, &mut a);
        gemm_col_split(geom.n_queries, kc, c_out, &a, (kc, 1), weights, (c_out, 1), &mut out);
    }
    Ok(out)
}

/// Backward of [`kpconv_forward`]: given `grad_out` (`n_queries × c_out`), returns
/// `(grad_features (n_support × c_in), grad_weights (K × c_in × c_out))`.
///
/// # Errors
/// `Shape` when a buffer length does not match the geometry and channel counts.
pub fn kpconv_backward(
    geom: &KpConvGeometry,
    features: &[f32],
    c_in: usize,
    weights: &[f32],
    c_out: usize,
    grad_out: &[f32],
) -> Result<(Vec<f32>, Vec<f32>)> {
    let (gf, gw) = kpconv_backward_select(geom, features, c_in, weights, c_out, grad_out, true, true)?;
    Ok((gf.expect("internal error: requested"), gw.expect("internal error: requested")))
}

/// `(grad_features, grad_weights)`, each present when requested.
pub type GradPair = (Option<Vec<f32>>, Option<Vec<f32>>);

/// [`kpconv_backward`] computing only the requested gradients (`None` for the others): the
/// first layer's input features need none, and skipping them saves the transposed gather.
///
/// # Errors
/// `Shape` when a buffer length does not match the geometry and channel counts.
#[allow(clippy::too_many_arguments)]
pub fn kpconv_backward_select(
    geom: &KpConvGeometry,
    features: &[f32],
    c_in: usize,
    weights: &[f32],
    c_out: usize,
    grad_out: &[f32],
    need_features: bool,
    need_weights: bool,
) -> Result<GradPair> {
    check_shapes(geom, features, c_in, weights, c_out)?;
    if grad_out.len() != geom.n_queries * c_out {
        return Err(Error::Shape {
            op: "kpconv backward",
            msg: format!("grad_out has {} values, expected {} × {c_out}", grad_out.len(), geom.n_queries),
        });
    }
    let kc = geom.n_kernel * c_in;
    let nq = geom.n_queries;
    let rows = rows_per_task(kc);
    let mut grad_w = None;
    if need_weights {
        grad_w = Some(weight_grad(geom, features, c_in, c_out, grad_out));
    }
    if !need_features {
        return Ok((None, grad_w));
    }
    // dA = dOut · Wᵀ (nq × kc).
    let mut grad_a = vec![0.0f32; nq * kc];
    if nq >= 2 * rows || kc < 2 * COL_BLOCK {
        par::for_each_chunk_mut(&mut grad_a, rows * kc, |ci, chunk| {
            let q0 = ci * rows;
            let n = chunk.len() / kc.max(1);
            gemm(n, c_out, kc, 1.0, &grad_out[q0 * c_out..], (c_out, 1), weights, (1, c_out), 0.0, chunk);
        });
    } else {
        gemm_col_split(nq, c_out, kc, grad_out, (c_out, 1), weights, (1, c_out), &mut grad_a);
    }
    // df_j = Σ_{(q,k) reading j} h · dA_q[k], gathered per support point.
    let (t_off, t_entries) = geom.transpose();
    let mut grad_f = vec![0.0f32; geom.n_support * c_in];
    if c_in > 0 {
        let frows = 256usize;
        par::for_each_chunk_mut(&mut grad_f, frows * c_in, |ci, chunk| {
            let j0 = ci * frows;
            for (r, dst) in chunk.chunks_mut(c_in).enumerate() {
                let j = j0 + r;
                for e in &t_entries[t_off[j]..t_off[j + 1]] {
                    let q = e.support as usize;
                    let src =
                        &grad_a[q * kc + e.kernel as usize * c_in..q * kc + (e.kernel as usize + 1) * c_in];
                    for (d, &g) in dst.iter_mut().zip(src) {
                        *d += e.h * g;
                    }
                }
            }
        });
    }
    Ok((Some(grad_f), grad_w))
}

/// `dW = Aᵀ · dOut` with A re-gathered (K·C_in × C_out).
fn weight_grad(
    geom: &KpConvGeometry,
    features: &[f32],
    c_in: usize,
    c_out: usize,
    grad_out: &[f32],
) -> Vec<f32> {
    let kc = geom.n_kernel * c_in;
    let nq = geom.n_queries;
    let rows = rows_per_task(kc);
    // A (nq × kc), recomputed rather than kept from the forward pass: the gather costs ~1/C_out of the GEMM.
    let mut a = vec![0.0f32; nq * kc];
    par::for_each_chunk_mut(&mut a, rows * kc, |ci, chunk| {
        gather_block(geom, features, c_in, ci * rows, chunk.len() / kc.max(1), chunk);
    });
    // dW = Aᵀ · dOut, split over fixed row ranges of dW (kc rows): each element is computed
    // by exactly one task with the same reduction, whatever the thread count.
    let mut grad_w = vec![0.0f32; kc * c_out];
    let wrows = 64usize;
    if c_out > 0 {
        par::for_each_chunk_mut(&mut grad_w, wrows * c_out, |ci, chunk| {
            let r0 = ci * wrows;
            let len = chunk.len() / c_out;
            gemm(len, nq, c_out, 1.0, &a[r0..], (1, kc), grad_out, (c_out, 1), 0.0, chunk);
        });
    }
    grad_w
}

/// Rigid KPConv as a [`CustomOp`] on the tape. Inputs: features `[n_support × C_in]` and
/// weights `[K × C_in × C_out]`; output `[n_queries × C_out]`. The geometry (influences) is
/// shared, so many layers and epochs can reuse one table.
pub struct KpConvOp {
    geom: Arc<KpConvGeometry>,
}

impl KpConvOp {
    /// The op over a precomputed geometry.
    pub fn new(geom: Arc<KpConvGeometry>) -> Self {
        KpConvOp { geom }
    }

    fn dims(&self, inputs: &[&Tensor]) -> Result<(usize, usize)> {
        let [f, w] = inputs else {
            return Err(Error::Shape {
                op: "kpconv",
                msg: format!("expected 2 inputs, got {}", inputs.len()),
            });
        };
        let wd = w.dims();
        if wd.len() != 3 || wd[0] != self.geom.n_kernel {
            return Err(Error::Shape {
                op: "kpconv",
                msg: format!("weights must be [{} × C_in × C_out], got {}", self.geom.n_kernel, w.shape()),
            });
        }
        if f.rows() != self.geom.n_support || f.cols() != wd[1] {
            return Err(Error::Shape {
                op: "kpconv",
                msg: format!(
                    "features {} for {} support points and weights {}",
                    f.shape(),
                    self.geom.n_support,
                    w.shape()
                ),
            });
        }
        Ok((wd[1], wd[2]))
    }
}

impl CustomOp for KpConvOp {
    fn name(&self) -> &'static str {
        "kpconv"
    }

    fn forward(&mut self, inputs: &[&Tensor]) -> Result<Tensor> {
        let (c_in, c_out) = self.dims(inputs)?;
        let out = kpconv_forward(&self.geom, inputs[0].data(), c_in, inputs[1].data(), c_out)?;
        Tensor::new(&[self.geom.n_queries, c_out], out)
    }

    fn backward(
        &self,
        inputs: &[&Tensor],
        _output: &Tensor,
        grad_output: &Tensor,
        needs_grad: &[bool],
    ) -> Result<Vec<Option<Tensor>>> {
        let (c_in, c_out) = self.dims(inputs)?;
        let need = |i: usize| needs_grad.get(i).copied().unwrap_or(false);
        let (gf, gw) = kpconv_backward_select(
            &self.geom,
            inputs[0].data(),
            c_in,
            inputs[1].data(),
            c_out,
            grad_output.data(),
            need(0),
            need(1),
        )?;
        let gf = gf.map(|g| Tensor::from_shape(inputs[0].shape(), g)).transpose()?;
        let gw = gw.map(|g| Tensor::from_shape(inputs[1].shape(), g)).transpose()?;
        Ok(vec![gf, gw])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct evaluation of the KPConv formula, no tables, no GEMM.
    #[allow(clippy::too_many_arguments)]
    fn naive(
        q: &[[f32; 3]],
        s: &[[f32; 3]],
        nb: &[u32],
        cap: usize,
        kp: &[[f32; 3]],
        sigma: f32,
        f: &[f32],
        ci: usize,
        w: &[f32],
        co: usize,
    ) -> Vec<f32> {
        let mut out = vec![0.0; q.len() * co];
        for (qi, qp) in q.iter().enumerate() {
            for &j in &nb[qi * cap..(qi + 1) * cap] {
                if j as usize == s.len() {
                    continue;
                }
                for (k, kpk) in kp.iter().enumerate() {
                    let d: f32 =
                        (0..3).map(|a| (s[j as usize][a] - qp[a] - kpk[a]).powi(2)).sum::<f32>().sqrt();
                    let h = (1.0 - d / sigma).max(0.0);
                    for c in 0..ci {
                        for o in 0..co {
                            out[qi * co + o] += h * f[j as usize * ci + c] * w[(k * ci + c) * co + o];
                        }
                    }
                }
            }
        }
        out
    }

    #[test]
    fn matches_naive_formula_with_shadow_padding() {
        let mut rng = crate::rng::Rng::new(5);
        let s: Vec<[f32; 3]> = (0..40).map(|_| [rng.f32(), rng.f32(), rng.f32()]).collect();
        let q: Vec<[f32; 3]> = s.iter().step_by(3).copied().collect();
        let cap = 7;
        let nb: Vec<u32> =
            (0..q.len() * cap).map(|i| if i % 5 == 4 { 40 } else { rng.below(40) as u32 }).collect();
        let kp = crate::nn::kernel_points::scaled_kernel_points(15, 1, 0.5).unwrap();
        let (ci, co) = (3, 9);
        let f: Vec<f32> = (0..40 * ci).map(|_| rng.f32() - 0.5).collect();
        let w: Vec<f32> = (0..15 * ci * co).map(|_| rng.f32() - 0.5).collect();
        let g = KpConvGeometry::new(&q, &s, &nb, cap, &kp, 0.3).unwrap();
        let out = kpconv_forward(&g, &f, ci, &w, co).unwrap();
        let want = naive(&q, &s, &nb, cap, &kp, 0.3, &f, ci, &w, co);
        for (a, b) in out.iter().zip(&want) {
            assert!((a - b).abs() < 1e-4, "{a} vs {b}");
        }
    }

    /// Few points and wide layers take the column-split GEMM path (forward and dA): compare
    /// forward with the formula and both gradients with direct loops over the influences.
    #[test]
    fn column_split_path_matches_direct_loops() {
        let mut rng = crate::rng::Rng::new(8);
        let s: Vec<[f32; 3]> = (0..30).map(|_| [rng.f32(), rng.f32(), rng.f32()]).collect();
        let q: Vec<[f32; 3]> = s.iter().step_by(3).copied().collect();
        let cap = 12;
        let nb: Vec<u32> = (0..q.len() * cap).map(|_| rng.below(31) as u32).collect();
        let kp = crate::nn::kernel_points::scaled_kernel_points(15, 2, 0.6).unwrap();
        let (ci, co) = (20, 300);
        assert!(q.len() < 2 * rows_per_task(15 * ci) && co >= 2 * COL_BLOCK && 15 * ci >= 2 * COL_BLOCK);
        let f: Vec<f32> = (0..30 * ci).map(|_| rng.f32() - 0.5).collect();
        let w: Vec<f32> = (0..15 * ci * co).map(|_| rng.f32() - 0.5).collect();
        let go: Vec<f32> = (0..q.len() * co).map(|_| rng.f32() - 0.5).collect();
        let g = KpConvGeometry::new(&q, &s, &nb, cap, &kp, 0.4).unwrap();
        let out = kpconv_forward(&g, &f, ci, &w, co).unwrap();
        let want = naive(&q, &s, &nb, cap, &kp, 0.4, &f, ci, &w, co);
        for (a, b) in out.iter().zip(&want) {
            assert!((a - b).abs() < 1e-3 * (1.0 + b.abs()), "{a} vs {b}");
        }
        let (gf, gw) = kpconv_backward(&g, &f, ci, &w, co, &go).unwrap();
        let (mut rf, mut rw) = (vec![0.0f64; gf.len()], vec![0.0f64; gw.len()]);
        for qi in 0..q.len() {
            for e in &g.entries[g.offsets[qi]..g.offsets[qi + 1]] {
                let (j, k) = (e.support as usize, e.kernel as usize);
                for c in 0..ci {
                    for o in 0..co {
                        let wi = (k * ci + c) * co + o;
                        rw[wi] += e.h as f64 * f[j * ci + c] as f64 * go[qi * co + o] as f64;
                        rf[j * ci + c] += e.h as f64 * w[wi] as f64 * go[qi * co + o] as f64;
                    }
                }
            }
        }
        for (a, b) in gf.iter().zip(&rf).chain(gw.iter().zip(&rw)) {
            assert!((*a as f64 - b).abs() < 1e-3 * (1.0 + b.abs()), "{a} vs {b}");
        }
    }

    #[test]
    fn bad_shapes_and_indices_are_errors() {
        let s = [[0.0f32; 3]; 3];
        let kp = [[0.0f32; 3]];
        assert!(KpConvGeometry::new(&s, &s, &[0, 1], 1, &kp, 1.0).is_err());
        assert!(KpConvGeometry::new(&s, &s, &[0, 1, 4], 1, &kp, 1.0).is_err());
        assert!(KpConvGeometry::new(&s, &s, &[0, 1, 3], 1, &kp, 0.0).is_err());
        let g = KpConvGeometry::new(&s, &s, &[0, 1, 3], 1, &kp, 1.0).unwrap();
        assert!(kpconv_forward(&g, &[1.0; 4], 1, &[1.0], 1).is_err());
        assert!(kpconv_forward(&g, &[1.0; 3], 1, &[1.0; 2], 1).is_err());
        assert!(kpconv_backward(&g, &[1.0; 3], 1, &[1.0], 1, &[1.0; 2]).is_err());
        // The shadow row contributes nothing.
        assert_eq!(kpconv_forward(&g, &[1.0, 2.0, 3.0], 1, &[2.0], 1).unwrap(), vec![2.0, 4.0, 0.0]);
    }
}
