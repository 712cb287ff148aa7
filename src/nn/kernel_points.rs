//! KPConv kernel point placement (Thomas et al. 2019): K points in the unit ball, the first
//! fixed at the centre, the others spread by gradient descent on a repulsion + centre-attraction
//! potential, best of several random starts, rescaled, randomly rotated, cached per (K, seed).
//!
//! Conventions (the KPConv authors' "fixed centre" variant):
//! - The ball has radius 1 = the kernel's spatial extent, i.e. the convolution radius; a layer
//!   multiplies the points by its radius. (σ, the influence extent of each point, is separate.)
//! - "Mean radius" is the mean distance to the centre over the K − 1 *non-centre* points
//!   (the centre, at radius 0, is excluded); it is rescaled to [`MEAN_RADIUS_RATIO`] = 0.66.
//! - The potential is E = Σ_{i<j} 1/|x_i − x_j| + 5 Σ_i |x_i|² (the centre repels too but never moves).
//!   Of the starts, the one with the lowest final E wins.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use crate::rng::Rng;
use crate::{Error, Result};

/// Mean distance of the non-centre kernel points to the centre, as a fraction of the ball radius.
pub const MEAN_RADIUS_RATIO: f64 = 0.66;

/// Number of random starts optimised; the lowest-energy one is kept.
pub const NUM_STARTS: usize = 16;

/// Gradient-descent iterations per start (stops earlier once the moves become negligible).
const MAX_ITERS: usize = 4000;

/// Largest K accepted (the optimisation is O(K²) per iteration; KPConv uses 15, at most ~45).
pub const MAX_KERNEL_POINTS: usize = 64;

type Cache = Mutex<HashMap<(usize, u64), Arc<[[f32; 3]]>>>;

fn cache() -> &'static Cache {
    static CACHE: OnceLock<Cache> = OnceLock::new();
    CACHE.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The `k` kernel points for `seed`, in the unit ball (radius 1 = convolution radius).
/// Point 0 is the centre `[0, 0, 0]`; the other `k − 1` have mean norm 0.66.
/// Deterministic for `(k, seed)` and computed once per process for each pair.
///
/// # Errors
/// `InvalidInput` when `k` is 0 or larger than [`MAX_KERNEL_POINTS`].
pub fn kernel_points(k: usize, seed: u64) -> Result<Arc<[[f32; 3]]>> {
    if k == 0 || k > MAX_KERNEL_POINTS {
        return Err(Error::invalid(format!(
            "kernel point count must be in 1..={MAX_KERNEL_POINTS}, got {k}"
        )));
    }
    // A poisoned lock only means another thread panicked mid-insert; the map is still valid.
    if let Some(p) = cache().lock().unwrap_or_else(|e| e.into_inner()).get(&(k, seed)) {
        return Ok(p.clone());
    }
    let pts: Arc<[[f32; 3]]> = compute(k, seed).into();
    cache().lock().unwrap_or_else(|e| e.into_inner()).entry((k, seed)).or_insert(pts.clone());
    Ok(pts)
}

/// [`kernel_points`] multiplied by `radius` (the layer's convolution radius).
///
/// # Errors
/// As [`kernel_points`]; also `InvalidInput` when `radius` is not finite and positive.
pub fn scaled_kernel_points(k: usize, seed: u64, radius: f32) -> Result<Vec<[f32; 3]>> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(Error::invalid(format!("kernel radius must be finite and > 0, got {radius}")));
    }
    Ok(kernel_points(k, seed)?.iter().map(|p| [p[0] * radius, p[1] * radius, p[2] * radius]).collect())
}

/// The potential E of a configuration (see the module docs).
pub fn energy(points: &[[f64; 3]]) -> f64 {
    let mut e = 0.0;
    for (i, a) in points.iter().enumerate() {
        e += 5.0 * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        for b in &points[i + 1..] {
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            e += 1.0 / d.max(1e-9);
        }
    }
    e
}

fn compute(k: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(seed ^ 0x4B50_436F_6E76_0000);
    let mut best: Option<(f64, Vec<[f64; 3]>)> = None;
    for start in 0..NUM_STARTS {
        let mut srng = rng.fork(start as u64);
        let pts = optimise(k, &mut srng);
        let e = energy(&pts);
        if best.as_ref().map_or(true, |(be, _)| e < *be) {
            best = Some((e, pts));
        }
    }
    let (_, mut pts) = best.expect("internal error: NUM_STARTS > 0");
    // Rescale: mean norm of the non-centre points becomes MEAN_RADIUS_RATIO.
    if k > 1 {
        let mean = pts[1..].iter().map(|p| crate::math::norm(*p)).sum::<f64>() / (k - 1) as f64;
        let s = MEAN_RADIUS_RATIO / mean.max(1e-12);
        for p in &mut pts {
            *p = crate::math::scale(*p, s);
        }
    }
    let rot = rng.rotation();
    pts.iter().map(|p| crate::math::to_f32(crate::math::mat_vec(&rot, *p))).collect()
}

/// One start: random initial points in a shell of the unit ball, centre fixed, then descent.
fn optimise(k: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    let mut pts = initial_points(k, rng);
    descend(&mut pts);
    pts
}

fn initial_points(k: usize, rng: &mut Rng) -> Vec<[f64; 3]> {
    let mut pts = vec![[0.0f64; 3]; k];
    for p in pts.iter_mut().skip(1) {
        // Rejection sampling in the shell 0.5 < |x|² < 0.81 (KPConv starts there too).
        loop {
            let c = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
            let r2 = crate::math::dot(c, c);
            if r2 > 0.5 * 0.5 && r2 < 0.9 * 0.9 {
                *p = c;
                break;
            }
        }
    }
    pts
}

/// Normalised gradient steps of decaying length (as in KPConv), each move clipped to 0.05;
/// point 0 (the centre) never moves.
fn descend(pts: &mut [[f64; 3]]) {
    let k = pts.len();
    let mut grads = vec![[0.0f64; 3]; k];
    let mut step = 1e-2;
    let mut old_norms = vec![0.0f64; k];
    for _ in 0..MAX_ITERS {
        for (i, g) in grads.iter_mut().enumerate() {
            let xi = pts[i];
            // ∂E/∂x_i = 10 x_i − Σ_j (x_i − x_j)/|x_i − x_j|³
            let mut acc = crate::math::scale(xi, 10.0);
            for (j, xj) in pts.iter().enumerate() {
                if j != i {
                    let d = crate::math::sub(xi, *xj);
                    let r2 = crate::math::dot(d, d);
                    let inv = 1.0 / (r2 * r2.sqrt() + 1e-6);
                    acc = crate::math::sub(acc, crate::math::scale(d, inv));
                }
            }
            *g = acc;
        }
        let mut max_change = 0.0f64;
        for i in 1..k {
            let gn = crate::math::norm(grads[i]);
            max_change = max_change.max((gn - old_norms[i]).abs());
            old_norms[i] = gn;
            let mv = (step * gn).min(0.05);
            if gn > 0.0 {
                pts[i] = crate::math::sub(pts[i], crate::math::scale(grads[i], mv / gn));
            }
        }
        if max_change < 1e-5 {
            break;
        }
        step *= 0.9995;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_fixed_mean_radius_and_distinct() {
        let p = kernel_points(15, 0).unwrap();
        assert_eq!(p.len(), 15);
        assert_eq!(p[0], [0.0, 0.0, 0.0]);
        let mean = p[1..].iter().map(|q| crate::math::norm(crate::math::to_f64(*q))).sum::<f64>() / 14.0;
        assert!((mean - MEAN_RADIUS_RATIO).abs() < 1e-5, "{mean}");
        for (i, a) in p.iter().enumerate() {
            assert!(crate::math::norm(crate::math::to_f64(*a)) <= 1.0);
            for b in &p[i + 1..] {
                assert!(crate::math::dist_sq(crate::math::to_f64(*a), crate::math::to_f64(*b)) > 0.01);
            }
        }
    }

    #[test]
    fn deterministic_and_seed_dependent_rotation() {
        let a = compute(15, 3);
        assert_eq!(a, compute(15, 3));
        assert_eq!(&a[..], &kernel_points(15, 3).unwrap()[..]);
        assert_ne!(a, compute(15, 4));
    }

    #[test]
    fn optimisation_lowers_energy_below_random_start() {
        let init = initial_points(15, &mut Rng::new(9));
        let mut opt = init.clone();
        descend(&mut opt);
        assert_eq!(opt[0], [0.0; 3]);
        assert!(energy(&opt) < 0.95 * energy(&init), "{} vs {}", energy(&opt), energy(&init));
    }

    #[test]
    fn bad_counts_are_errors_and_small_counts_work() {
        assert!(kernel_points(0, 0).is_err());
        assert!(kernel_points(MAX_KERNEL_POINTS + 1, 0).is_err());
        assert_eq!(&kernel_points(1, 0).unwrap()[..], &[[0.0f32; 3]]);
        let two = kernel_points(2, 0).unwrap();
        assert!((crate::math::norm(crate::math::to_f64(two[1])) - 0.66).abs() < 1e-6);
        assert!(scaled_kernel_points(15, 0, f32::NAN).is_err());
    }
}
