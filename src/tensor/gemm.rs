//! Matrix products on row-major f32 buffers through nalgebra's GEMM (which calls the
//! packed, SIMD `matrixmultiply` kernel for dynamic sizes). Row-major buffers are
//! handed to nalgebra as strided views (row stride = row length, column stride 1), so
//! nothing is transposed or copied.
//!
//! Parallelism and determinism: [`gemm_rows`] splits the output into fixed blocks of
//! [`ROW_BLOCK`] rows, one GEMM each; [`gemm_tn`] (a reduction over the long axis, used
//! for weight gradients) sums fixed chunks of [`RED_BLOCK`] rows in a fixed order. The
//! blocks never depend on the thread count, so results are bit-identical for any
//! number of threads (given the same CPU features, which pick the SIMD kernel).

use crate::par;
use nalgebra::{Dyn, MatrixView, MatrixViewMut};

/// Rows of the output computed by one GEMM call in [`gemm_rows`].
pub const ROW_BLOCK: usize = 512;
/// Rows of the reduction axis summed by one GEMM call in [`gemm_tn`].
pub const RED_BLOCK: usize = 8192;

/// nalgebra hands a product to `matrixmultiply` only when all of `m`, `n`, `k` exceed
/// this; its own fallback loop mis-handles row-major strided views, so smaller
/// products take [`small_gemm`] instead.
const NALGEBRA_MIN_DIM: usize = 6;

type View<'a> = MatrixView<'a, f32, Dyn, Dyn, Dyn, Dyn>;
type ViewMut<'a> = MatrixViewMut<'a, f32, Dyn, Dyn, Dyn, Dyn>;

/// A strided view of `rows × cols` starting at `data[0]`.
fn view(data: &[f32], rows: usize, cols: usize, rs: usize, cs: usize) -> View<'_> {
    View::from_slice_with_strides(data, rows, cols, rs, cs)
}

/// Plain triple loop for products with a dimension below [`NALGEBRA_MIN_DIM`].
/// `a(i, p) = a[i·ars + p·acs]`, `b(p, j) = b[p·brs + j·bcs]`.
#[allow(clippy::too_many_arguments)]
fn small_gemm(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    (ars, acs): (usize, usize),
    b: &[f32],
    (brs, bcs): (usize, usize),
    c: &mut [f32],
    beta: f32,
) {
    for i in 0..m {
        for j in 0..n {
            let mut s = 0.0f32;
            for p in 0..k {
                s += a[i * ars + p * acs] * b[p * brs + j * bcs];
            }
            let o = &mut c[i * n + j];
            *o = if beta == 0.0 { s } else { beta * *o + s };
        }
    }
}

/// `C = beta·C + op(A)·op(B)` on one thread. `C` is `m × n` row-major; `op(A)` is
/// `m × k`: `A` stored `m × k` row-major, or `k × m` when `ta` (then `op(A) = Aᵀ`);
/// `op(B)` is `k × n`: `B` stored `k × n`, or `n × k` when `tb`. `beta = 0` ignores
/// the previous content of `C` (NaN included).
///
/// # Panics
/// When a buffer is shorter than its dimensions say (internal invariant of callers).
#[allow(clippy::too_many_arguments)]
pub fn gemm(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    ta: bool,
    b: &[f32],
    tb: bool,
    c: &mut [f32],
    beta: f32,
) {
    assert!(c.len() >= m * n, "internal error: gemm output buffer too small");
    assert!(a.len() >= m * k && b.len() >= k * n, "internal error: gemm input buffer too small");
    // The whole operand is one block; `gemm_block` handles the empty cases.
    gemm_block(m, n, k, a, ta, m, 0, b, tb, &mut c[..m * n], beta);
}

/// Like [`gemm`] but with `op(A)` given as a row block: rows `r0..r0+m` of an
/// `M × k` operand (stored `M × k`, or `k × M` when `ta`, with `lda_t = M`); `c` is
/// that block's `m × n` output.
#[allow(clippy::too_many_arguments)]
pub fn gemm_block(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    ta: bool,
    big_m: usize,
    r0: usize,
    b: &[f32],
    tb: bool,
    c: &mut [f32],
    beta: f32,
) {
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        for x in c.iter_mut() {
            *x = if beta == 0.0 { 0.0 } else { *x * beta };
        }
        return;
    }
    let (a, astr) = if ta { (&a[r0..], (1, big_m)) } else { (&a[r0 * k..], (k, 1)) };
    let bstr = if tb { (1, k) } else { (n, 1) };
    if m < NALGEBRA_MIN_DIM || n < NALGEBRA_MIN_DIM || k < NALGEBRA_MIN_DIM {
        return small_gemm(m, n, k, a, astr, b, bstr, c, beta);
    }
    let av = view(a, m, k, astr.0, astr.1);
    let bv = view(b, k, n, bstr.0, bstr.1);
    let mut cv = ViewMut::from_slice_with_strides_mut(c, m, n, n, 1);
    // nalgebra documents that C is not read when beta is zero.
    cv.gemm(1.0, &av, &bv, beta);
}

/// [`gemm`] split over fixed blocks of [`ROW_BLOCK`] output rows, in parallel.
///
/// # Panics
/// When a buffer is shorter than its dimensions say.
#[allow(clippy::too_many_arguments)]
pub fn gemm_rows(
    m: usize,
    n: usize,
    k: usize,
    a: &[f32],
    ta: bool,
    b: &[f32],
    tb: bool,
    c: &mut [f32],
    beta: f32,
) {
    assert!(
        c.len() >= m * n && a.len() >= m * k && b.len() >= k * n,
        "internal error: gemm_rows buffer too small"
    );
    if m == 0 || n == 0 {
        return;
    }
    if m <= ROW_BLOCK {
        return gemm(m, n, k, a, ta, b, tb, c, beta);
    }
    par::for_each_chunk_mut(&mut c[..m * n], ROW_BLOCK * n, |bi, cb| {
        let r0 = bi * ROW_BLOCK;
        let rows = cb.len() / n;
        gemm_block(rows, n, k, a, ta, m, r0, b, tb, cb, beta);
    });
}

/// `C = beta·C + Aᵀ·B` with `A` stored `kk × m`, `B` stored `kk × n` (both row-major),
/// `C` `m × n`: a reduction over the long axis `kk` (rows of activations), summed in
/// fixed chunks of [`RED_BLOCK`] in chunk order (parallel across chunks).
///
/// # Panics
/// When a buffer is shorter than its dimensions say.
pub fn gemm_tn(m: usize, n: usize, kk: usize, a: &[f32], b: &[f32], c: &mut [f32], beta: f32) {
    assert!(
        c.len() >= m * n && a.len() >= kk * m && b.len() >= kk * n,
        "internal error: gemm_tn buffer too small"
    );
    if kk <= RED_BLOCK {
        return gemm(m, n, kk, a, true, b, false, c, beta);
    }
    let chunks = kk.div_ceil(RED_BLOCK);
    let partials = par::map(chunks, |ci| {
        let r0 = ci * RED_BLOCK;
        let r1 = (r0 + RED_BLOCK).min(kk);
        let mut p = vec![0.0f32; m * n];
        gemm(m, n, r1 - r0, &a[r0 * m..r1 * m], true, &b[r0 * n..r1 * n], false, &mut p, 0.0);
        p
    });
    let c = &mut c[..m * n];
    if beta == 0.0 {
        c.fill(0.0);
    } else if beta != 1.0 {
        c.iter_mut().for_each(|x| *x *= beta);
    }
    for p in &partials {
        for (x, y) in c.iter_mut().zip(p) {
            *x += y;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn naive(m: usize, n: usize, k: usize, a: &[f32], ta: bool, b: &[f32], tb: bool) -> Vec<f64> {
        let mut c = vec![0.0f64; m * n];
        for i in 0..m {
            for j in 0..n {
                let mut s = 0.0f64;
                for p in 0..k {
                    let x = if ta { a[p * m + i] } else { a[i * k + p] };
                    let y = if tb { b[j * k + p] } else { b[p * n + j] };
                    s += x as f64 * y as f64;
                }
                c[i * n + j] = s;
            }
        }
        c
    }

    #[test]
    fn all_transpose_variants_match_naive() {
        let mut r = Rng::new(1);
        for &(m, n, k) in &[(1, 1, 1), (3, 7, 2), (300, 9, 17), (600, 13, 6), (6, 6, 0)] {
            let a: Vec<f32> = (0..m * k).map(|_| r.f32() - 0.5).collect();
            let b: Vec<f32> = (0..k * n).map(|_| r.f32() - 0.5).collect();
            for &(ta, tb) in &[(false, false), (true, false), (false, true), (true, true)] {
                let want = naive(m, n, k, &a, ta, &b, tb);
                let mut c = vec![1.0f32; m * n];
                gemm_rows(m, n, k, &a, ta, &b, tb, &mut c, 1.0);
                for (x, y) in c.iter().zip(&want) {
                    assert!((*x as f64 - (y + 1.0)).abs() < 1e-4, "{m} {n} {k} {ta} {tb}");
                }
            }
        }
    }

    #[test]
    fn reduction_matches_naive() {
        let mut r = Rng::new(2);
        let (m, n, kk) = (5, 7, RED_BLOCK * 2 + 3);
        let a: Vec<f32> = (0..kk * m).map(|_| r.f32() - 0.5).collect();
        let b: Vec<f32> = (0..kk * n).map(|_| r.f32() - 0.5).collect();
        let want = naive(m, n, kk, &a, true, &b, false);
        let mut c = vec![0.0f32; m * n];
        gemm_tn(m, n, kk, &a, &b, &mut c, 0.0);
        for (x, y) in c.iter().zip(&want) {
            assert!((*x as f64 - y).abs() < 1e-2 * (1.0 + y.abs()));
        }
    }
}
