//! Per-step geometric augmentation of a training sample (DESIGN §4: rotation,
//! anisotropic scale, jitter): the sample's points are jittered, then mapped by a random
//! linear map M = rotation · anisotropic scale, and the model's face input is recomputed
//! from the moved points for the sample's fixed candidates and labels.
//!
//! * Scale: S = Qᵀ·diag(s)·Q with Q a uniformly random rotation (a random orthonormal
//!   frame) and each s_a uniform in the configured range, so the stretch axes are not
//!   tied to the coordinate axes. M = R·S (R the step's rotation, or the identity).
//! * Jitter: p + δ with δ ~ N(0, (jitter · s_p)² I) per point, s_p the point's local
//!   spacing in the dataset, added before M.
//! * Recomputed from the moved points: all of F_info and the context columns that depend
//!   on positions (6–13: edge lengths over the local spacing, corner normals against the
//!   face normal; [`features::context_geometry_row`]). Local spacing and PCA normals are
//!   recomputed with the neighbours the dataset used (the same kNN rows, rebuilt once per
//!   sample and cached in [`SampleGeometry`]); each new normal takes the sign that agrees
//!   with the dataset's oriented normal carried by M's inverse transpose (how normals
//!   map under M), so no orientation propagation runs per step.
//! * Kept from the dataset: the context columns that describe candidate generation
//!   (edge sharing counts, rank, proposers, inside count, ranking score). The candidates
//!   themselves are not regenerated (about a second per 10k-point cloud), so neither are
//!   the noise points: fresh noise per epoch is not done here.
//!
//! With the identity map and no jitter the recomputed input equals the stored one bit
//! for bit (the same arithmetic as `point2quad dataset`; tested).

use crate::error::{Error, Result};
use crate::math::{mat_vec, to_f32};
use crate::pipeline::candidates::{
    fill_missing_spacing, knn_table, neighbours, normal_rows, CandidateConfig,
};
use crate::pipeline::dataset::Sample;
use crate::pipeline::features::{self, F_INFO_DIM};
use crate::pipeline::normals::{estimate_normals, orient_normals, pca_normal};
use crate::rng::Rng;

/// What augmenting a sample needs that never changes between steps: the kNN rows of
/// its normals and spacing, its oriented normals and spacing, and which points are
/// candidate corners. About 90 bytes per point.
#[derive(Clone, Debug)]
pub struct SampleGeometry {
    /// Row-major `n × normal_w` neighbour indices for the PCA normals (the point and
    /// its `normal_k` nearest, as candidate generation takes them).
    normal_rows: Vec<u32>,
    /// Width of a row of `normal_rows`.
    normal_w: usize,
    /// Point i's spacing neighbours are `spacing_idx[spacing_start[i]..spacing_start[i + 1]]`:
    /// its nearest *distinct* points (at most `spacing_k`), in kNN order.
    spacing_start: Vec<u32>,
    spacing_idx: Vec<u32>,
    /// Oriented unit normals of the dataset's points.
    normals: Vec<[f32; 3]>,
    /// Local spacing of the dataset's points.
    spacing: Vec<f32>,
    /// Distinct candidate corners, ascending: the only points whose normal is read.
    corners: Vec<u32>,
}

#[inline]
fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()
}

impl SampleGeometry {
    /// Rebuilds, from the dataset's points, the kNN rows, oriented normals and local
    /// spacing that candidate generation computed with `cfg` (only `k`, `normal_k` and
    /// `spacing_k` are read; `point2quad dataset` uses [`CandidateConfig::default`]).
    ///
    /// # Errors
    /// `InvalidInput` when a point is not finite or a candidate refers to a point that
    /// does not exist.
    pub fn new(
        points: &[[f32; 3]],
        candidates: &[[u32; 4]],
        cfg: &CandidateConfig,
    ) -> Result<SampleGeometry> {
        let n = points.len();
        if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(Error::invalid(format!("point {i} is not finite")));
        }
        if let Some((c, q)) = candidates.iter().enumerate().find(|(_, q)| q.iter().any(|&v| v as usize >= n))
        {
            return Err(Error::invalid(format!(
                "candidate {c} {q:?} refers to a point beyond the {n} given"
            )));
        }
        // The table `candidates::generate` searches (a kNN row's prefix does not depend
        // on k: rows are ordered by (distance, index)), then its normal table.
        let k = cfg.k.max(cfg.normal_k).max(cfg.spacing_k).max(3);
        let knn = knn_table(points, k);
        let table = normal_rows(points, &knn, n, cfg.normal_k);
        let normal_w = table.k;
        let mut normals = estimate_normals(points, &table);
        orient_normals(points, &table, &mut normals);
        // Spacing neighbours: the first `spacing_k` distinct points of each row.
        let mut spacing_start = Vec::with_capacity(n + 1);
        let mut spacing_idx = Vec::with_capacity(n * cfg.spacing_k.max(1));
        spacing_start.push(0u32);
        for i in 0..n {
            let mut c = 0;
            for j in neighbours(&knn, n, i, usize::MAX) {
                if dist(points[j as usize], points[i]) > 0.0 {
                    spacing_idx.push(j);
                    c += 1;
                    if c == cfg.spacing_k.max(1) {
                        break;
                    }
                }
            }
            spacing_start.push(spacing_idx.len() as u32);
        }
        let mut corners: Vec<u32> = candidates.iter().flatten().copied().collect();
        corners.sort_unstable();
        corners.dedup();
        let mut g = SampleGeometry {
            normal_rows: table.indices,
            normal_w,
            spacing_start,
            spacing_idx,
            normals,
            spacing: Vec::new(),
            corners,
        };
        g.spacing = g.spacing_of(points);
        Ok(g)
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.normals.len()
    }

    /// True for an empty cloud.
    pub fn is_empty(&self) -> bool {
        self.normals.is_empty()
    }

    /// The dataset's oriented unit normal per point.
    pub fn normals(&self) -> &[[f32; 3]] {
        &self.normals
    }

    /// The dataset's local spacing per point.
    pub fn spacing(&self) -> &[f32] {
        &self.spacing
    }

    /// Mean distance of each point to its cached spacing neighbours in `points` (pairs
    /// that became identical are skipped); points with none get the median of the others.
    fn spacing_of(&self, points: &[[f32; 3]]) -> Vec<f32> {
        let mut s: Vec<f32> = crate::par::map(points.len(), |i| {
            let row = &self.spacing_idx[self.spacing_start[i] as usize..self.spacing_start[i + 1] as usize];
            let mut sum = 0.0f32;
            let mut c = 0usize;
            for &j in row {
                let d = dist(points[j as usize], points[i]);
                if d > 0.0 {
                    sum += d;
                    c += 1;
                }
            }
            if c == 0 {
                f32::NAN
            } else {
                sum / c as f32
            }
        });
        fill_missing_spacing(&mut s);
        s
    }

    /// Normals and local spacing of the moved points `moved` (the dataset's points
    /// under `aug`): PCA over the cached rows with the sign of the mapped dataset
    /// normal, and spacing over the cached neighbours. Normals are computed for
    /// candidate corners only; other entries are zero (nothing reads them).
    ///
    /// # Panics
    /// If `moved` does not have one point per point of the geometry (internal error).
    pub fn recompute(&self, moved: &[[f32; 3]], aug: &Augmentation) -> (Vec<[f32; 3]>, Vec<f32>) {
        assert_eq!(moved.len(), self.len(), "internal error: one moved point per point");
        let w = self.normal_w;
        let it = &aug.inverse_transpose;
        let computed = crate::par::map(self.corners.len(), |k| {
            let i = self.corners[k] as usize;
            let nv = pca_normal(moved, moved[i], &self.normal_rows[i * w..(i + 1) * w], w >= moved.len());
            let reference = mat_vec(it, crate::math::to_f64(self.normals[i]));
            let agree =
                nv[0] as f64 * reference[0] + nv[1] as f64 * reference[1] + nv[2] as f64 * reference[2];
            if agree < 0.0 {
                [-nv[0], -nv[1], -nv[2]]
            } else {
                nv
            }
        });
        let mut normals = vec![[0.0f32; 3]; self.len()];
        for (&i, nv) in self.corners.iter().zip(computed) {
            normals[i as usize] = nv;
        }
        (normals, self.spacing_of(moved))
    }
}

/// One step's random transform of a sample: `moved_p = linear · (p + offsets[p])`.
#[derive(Clone, Debug, PartialEq)]
pub struct Augmentation {
    /// The linear map M = rotation · anisotropic scale (row-major).
    pub linear: [[f64; 3]; 3],
    /// M⁻ᵀ, which maps surface normals (up to length) the way M maps points.
    pub inverse_transpose: [[f64; 3]; 3],
    /// Jitter per point, added before `linear`; empty for none.
    pub offsets: Vec<[f64; 3]>,
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut c = [[0.0; 3]; 3];
    for (i, row) in c.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    c
}

fn transpose(a: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    [[a[0][0], a[1][0], a[2][0]], [a[0][1], a[1][1], a[2][1]], [a[0][2], a[1][2], a[2][2]]]
}

const IDENTITY: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Checks augmentation settings: a scale range needs finite 0 < min ≤ max, jitter must
/// be finite and non-negative.
///
/// # Errors
/// `InvalidInput` naming the bad setting and its value.
pub fn check_settings(scale: Option<(f32, f32)>, jitter: f32) -> Result<()> {
    if let Some((lo, hi)) = scale {
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
            return Err(Error::invalid(format!(
                "augmentation scale range ({lo}, {hi}): needs finite 0 < min <= max"
            )));
        }
    }
    if !(jitter.is_finite() && jitter >= 0.0) {
        return Err(Error::invalid(format!("augmentation jitter {jitter}: needs a finite value >= 0")));
    }
    Ok(())
}

impl Augmentation {
    /// The identity (no rotation, scale or jitter).
    pub fn identity() -> Augmentation {
        Augmentation { linear: IDENTITY, inverse_transpose: IDENTITY, offsets: Vec::new() }
    }

    /// A pure linear map `linear` (no jitter); `None` when it is not invertible or
    /// not finite.
    pub fn linear(linear: [[f64; 3]; 3]) -> Option<Augmentation> {
        let m = nalgebra::Matrix3::from_fn(|i, j| linear[i][j]);
        let inv = m.try_inverse()?;
        let inverse_transpose = [0, 1, 2].map(|i| [0, 1, 2].map(|j| inv[(j, i)]));
        let finite = inverse_transpose.iter().chain(linear.iter()).flatten().all(|x| x.is_finite());
        finite.then_some(Augmentation { linear, inverse_transpose, offsets: Vec::new() })
    }

    /// Draws a step's transform from `rng`, in this order: a uniformly random rotation
    /// (when `rotate`), a scale frame and three factors uniform in `scale` (when
    /// given), then 3 normal deviates per point scaled by `jitter · spacing[p]` (when
    /// `jitter > 0`; `spacing` is the dataset's local spacing per point). With
    /// `rotate` alone it draws exactly what `rng.rotation()` draws.
    ///
    /// # Errors
    /// `InvalidInput` for settings [`check_settings`] refuses.
    pub fn draw(
        rng: &mut Rng,
        rotate: bool,
        scale: Option<(f32, f32)>,
        jitter: f32,
        spacing: &[f32],
    ) -> Result<Augmentation> {
        check_settings(scale, jitter)?;
        let r = if rotate { rng.rotation() } else { IDENTITY };
        let (linear, inverse_transpose) = match scale {
            None => (r, r),
            Some((lo, hi)) => {
                let q = rng.rotation();
                let s = [0; 3].map(|_| rng.uniform(lo as f64, hi as f64));
                let diag =
                    |f: &dyn Fn(f64) -> f64| [[f(s[0]), 0.0, 0.0], [0.0, f(s[1]), 0.0], [0.0, 0.0, f(s[2])]];
                let qt = transpose(&q);
                let scale_m = mat_mul(&qt, &mat_mul(&diag(&|x| x), &q));
                let inv_scale = mat_mul(&qt, &mat_mul(&diag(&|x| 1.0 / x), &q));
                // M = R·S; M⁻ᵀ = R⁻ᵀ·S⁻ᵀ = R·S⁻¹ (R orthogonal, S symmetric).
                (mat_mul(&r, &scale_m), mat_mul(&r, &inv_scale))
            }
        };
        let offsets = if jitter > 0.0 {
            spacing
                .iter()
                .map(|&s| {
                    let sigma = jitter as f64 * s as f64;
                    [0; 3].map(|_| rng.normal() * sigma)
                })
                .collect()
        } else {
            Vec::new()
        };
        Ok(Augmentation { linear, inverse_transpose, offsets })
    }

    /// `points` moved by this transform (in f64, rounded to f32).
    ///
    /// # Panics
    /// If there are offsets but not one per point (internal error).
    pub fn apply(&self, points: &[[f32; 3]]) -> Vec<[f32; 3]> {
        assert!(
            self.offsets.is_empty() || self.offsets.len() == points.len(),
            "internal error: one jitter offset per point"
        );
        points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mut v = crate::math::to_f64(*p);
                if let Some(o) = self.offsets.get(i) {
                    v = crate::math::add(v, *o);
                }
                to_f32(mat_vec(&self.linear, v))
            })
            .collect()
    }
}

/// The face-input rows (`picks.len() × fin`) of `sample`'s candidates `picks` for the
/// moved points `moved` with their recomputed `normals` and `spacing`
/// ([`SampleGeometry::recompute`]): the stored row with F_info (when `fin ≥ 29`) and the
/// position-dependent context columns (when `fin ≥ 29 + 14`) replaced.
///
/// # Panics
/// If a pick is out of range, `fin` exceeds the sample's feature dimension, or
/// `moved`/`normals`/`spacing` do not cover the candidates' corners (internal errors:
/// the trainer checks samples against the model first).
pub fn face_rows(
    sample: &Sample,
    picks: &[usize],
    fin: usize,
    moved: &[[f32; 3]],
    normals: &[[f32; 3]],
    spacing: &[f32],
) -> Vec<f32> {
    let fd = sample.feature_dim as usize;
    assert!(fin <= fd, "internal error: the model reads more features than the sample has");
    let mut x = vec![0.0f32; picks.len() * fin];
    crate::par::for_each_chunk_mut(&mut x, fin.max(1) * 256, |ci, chunk| {
        for (r, row) in chunk.chunks_mut(fin.max(1)).enumerate() {
            let c = picks[ci * 256 + r];
            row.copy_from_slice(&sample.features[c * fd..c * fd + fin]);
            let q = sample.candidates[c];
            if fin >= F_INFO_DIM {
                features::f_info_row(moved, spacing, q, &mut row[..F_INFO_DIM]);
            }
            if fin >= F_INFO_DIM + 14 {
                features::context_geometry_row(moved, spacing, normals, q, &mut row[F_INFO_DIM..]);
            }
        }
    });
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draw_order_and_settings() {
        // Rotation alone draws what `rng.rotation()` draws, and nothing else.
        let (mut a, mut b) = (Rng::new(4), Rng::new(4));
        let aug = Augmentation::draw(&mut a, true, None, 0.0, &[1.0; 5]).unwrap();
        assert_eq!(aug.linear, b.rotation());
        assert_eq!(a.state(), b.state());
        assert!(aug.offsets.is_empty());
        // Nothing on: the identity, no draw.
        let mut c = Rng::new(4);
        assert_eq!(Augmentation::draw(&mut c, false, None, 0.0, &[]).unwrap(), Augmentation::identity());
        assert_eq!(c.state(), Rng::new(4).state());
        // Bad settings.
        for (s, j) in [
            (Some((0.0, 1.0)), 0.0),
            (Some((1.2, 1.1)), 0.0),
            (Some((-1.0, 1.0)), 0.0),
            (Some((1.0, f32::INFINITY)), 0.0),
            (Some((f32::NAN, 1.0)), 0.0),
            (None, -0.1),
            (None, f32::NAN),
        ] {
            assert!(Augmentation::draw(&mut Rng::new(1), true, s, j, &[1.0]).is_err(), "{s:?} {j}");
        }
    }

    /// M·M⁻ᵀᵀ = I, the stretch factors lie in the range (singular values of S), and
    /// the rotation is folded in as M = R·S.
    #[test]
    fn linear_map_is_rotation_times_symmetric_scale() {
        for seed in 0..20 {
            let mut rng = Rng::new(seed);
            let aug = Augmentation::draw(&mut rng, true, Some((0.9, 1.1)), 0.0, &[]).unwrap();
            let check = mat_mul(&aug.linear, &transpose(&aug.inverse_transpose));
            for i in 0..3 {
                for j in 0..3 {
                    assert!((check[i][j] - IDENTITY[i][j]).abs() < 1e-12);
                }
            }
            let mut r2 = Rng::new(seed);
            let r = r2.rotation();
            // S = Rᵀ·M must be symmetric with eigenvalues in [0.9, 1.1].
            let s = mat_mul(&transpose(&r), &aug.linear);
            let m = nalgebra::Matrix3::from_fn(|i, j| s[i][j]);
            assert!((m - m.transpose()).abs().max() < 1e-12);
            let ev = nalgebra::SymmetricEigen::new(m).eigenvalues;
            assert!(ev.iter().all(|&e| (0.9 - 1e-12..1.1 + 1e-12).contains(&e)), "{ev:?}");
            assert!(ev.max() - ev.min() > 1e-3, "anisotropic");
        }
    }

    #[test]
    fn jitter_scales_with_spacing_and_apply_moves_points() {
        let n = 4000;
        let spacing: Vec<f32> = (0..n).map(|i| if i % 2 == 0 { 1.0 } else { 4.0 }).collect();
        let pts = vec![[0.25f32, -0.5, 2.0]; n];
        let mut rng = Rng::new(9);
        let aug = Augmentation::draw(&mut rng, false, None, 0.02, &spacing).unwrap();
        let moved = aug.apply(&pts);
        // RMS displacement per coordinate / (jitter · spacing) ≈ 1 (Gaussian, σ = 0.02 s).
        for parity in 0..2 {
            let (mut sum, mut c) = (0.0f64, 0);
            for i in (parity..n).step_by(2) {
                for a in 0..3 {
                    let d = (moved[i][a] - pts[i][a]) as f64 / (0.02 * spacing[i] as f64);
                    sum += d * d;
                    c += 1;
                }
            }
            let rms = (sum / c as f64).sqrt();
            assert!((rms - 1.0).abs() < 0.05, "parity {parity}: rms {rms}");
        }
        assert_eq!(Augmentation::identity().apply(&pts), pts);
    }
}
