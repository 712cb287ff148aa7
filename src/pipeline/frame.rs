//! The normalising frame: every stage after reading works on the cloud translated to
//! its centroid and scaled so that the farthest point lies at distance 1. The frame
//! keeps the transform so results can be mapped back to the input coordinates.

use crate::error::{Error, Result};

/// The smallest radius [`Frame::fit`] accepts, in f64 steps (`f64::EPSILON` times the
/// largest coordinate magnitude): below it the points' positions are mostly rounding.
pub const MIN_EXTENT_STEPS: f64 = 64.0;

/// A similarity transform `local = (world − center) / scale`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Centroid of the fitted cloud (world coordinates).
    pub center: [f64; 3],
    /// Largest distance from `center` to a point of the fitted cloud (> 0).
    pub scale: f64,
}

impl Frame {
    /// Fits the frame to a cloud: centroid, and the largest distance from it mapped to 1.
    ///
    /// # Errors
    /// `InvalidInput` when the cloud is empty, has fewer than 4 points, has a NaN or
    /// infinite coordinate (the error names the point index), has no extent (all
    /// points identical, up to f64 rounding relative to the coordinates' magnitude), or
    /// is so large (coordinates near ±1.8e308) that its radius overflows f64. Clouds at
    /// any other scale, subnormal up to about 1e307, are fitted.
    pub fn fit(points: &[[f64; 3]]) -> Result<Frame> {
        if points.is_empty() {
            return Err(Error::invalid("empty point cloud"));
        }
        if points.len() < 4 {
            return Err(Error::invalid(format!(
                "point cloud has {} point(s); at least 4 are needed for a quad",
                points.len()
            )));
        }
        if let Some((i, p)) = points.iter().enumerate().find(|(_, p)| p.iter().any(|c| !c.is_finite())) {
            return Err(Error::invalid(format!("point {i} has a non-finite coordinate {p:?}")));
        }
        // Checked exactly: the rounding of the centroid below leaves identical points a
        // tiny radius, which would be reported as an extent lost in rounding.
        if points.iter().all(|p| p == &points[0]) {
            return Err(Error::invalid("degenerate point cloud: all points are identical"));
        }
        // Work on the points divided by their largest coordinate magnitude: sums and
        // squared distances of raw coordinates overflow (1e200) or underflow (1e-200,
        // subnormals) long before the coordinates themselves do, and a cloud at 1e200
        // was refused as "all points identical".
        let mag = points.iter().flatten().fold(0.0f64, |m, c| m.max(c.abs()));
        let unit = |p: &[f64; 3]| [p[0] / mag, p[1] / mag, p[2] / mag];
        let n = points.len() as f64;
        let mut centroid = [0.0f64; 3];
        for p in points {
            let q = unit(p);
            for a in 0..3 {
                centroid[a] += q[a];
            }
        }
        for c in &mut centroid {
            *c /= n;
        }
        let radius =
            points.iter().map(|p| crate::math::dist_sq(unit(p), centroid)).fold(0.0f64, f64::max).sqrt();
        // An extent of a few f64 steps of the coordinates is no extent: the local
        // coordinates would be rounding noise. The bound is [`MIN_EXTENT_STEPS`] steps
        // (a step is `f64::EPSILON · mag` here, within 2× of the true spacing of the
        // largest coordinate); it used to be 1e-12 · mag, which refused a unit grid
        // offset by 1e13 although its points sit 500 steps apart.
        if radius <= MIN_EXTENT_STEPS * f64::EPSILON {
            return Err(Error::invalid(format!(
                "degenerate point cloud: its extent ({:.3e}) is below the f64 resolution of its \
                 coordinates (up to {mag:.3e}, in steps of about {:.1e}; at least {MIN_EXTENT_STEPS} \
                 steps are needed); subtract the common offset first",
                radius * mag,
                f64::EPSILON * mag
            )));
        }
        let center = centroid.map(|c| c * mag);
        let scale = radius * mag;
        if !scale.is_finite() {
            return Err(Error::invalid(format!(
                "point cloud too large: its radius overflows f64 (coordinates up to {mag:.3e})"
            )));
        }
        Ok(Frame { center, scale })
    }

    /// World → local (f32, the precision every later stage works in).
    #[inline]
    pub fn to_local(&self, p: [f64; 3]) -> [f32; 3] {
        self.to_local_f64(p).map(|c| c as f32)
    }

    /// World → local in f64 (the post-process's precision). Divides rather than
    /// multiplying by `1 / scale`, which is infinite for a subnormal scale.
    #[inline]
    pub fn to_local_f64(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| (p[a] - self.center[a]) / self.scale)
    }

    /// Local → world.
    #[inline]
    pub fn to_world(&self, p: [f32; 3]) -> [f64; 3] {
        [
            p[0] as f64 * self.scale + self.center[0],
            p[1] as f64 * self.scale + self.center[1],
            p[2] as f64 * self.scale + self.center[2],
        ]
    }

    /// Local → world, from f64 local coordinates.
    #[inline]
    pub fn to_world_f64(&self, p: [f64; 3]) -> [f64; 3] {
        std::array::from_fn(|a| p[a] * self.scale + self.center[a])
    }

    /// [`Frame::to_local`] on every point.
    pub fn to_local_all(&self, points: &[[f64; 3]]) -> Vec<[f32; 3]> {
        points.iter().map(|&p| self.to_local(p)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_maps_into_unit_ball_and_round_trips() {
        let pts =
            vec![[10.0, 0.0, 0.0], [12.0, 0.0, 0.0], [10.0, 3.0, 0.0], [10.0, 0.0, -5.0], [11.0, 1.0, 1.0]];
        let f = Frame::fit(&pts).unwrap();
        let local = f.to_local_all(&pts);
        let rmax =
            local.iter().map(|p| (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()).fold(0.0f32, f32::max);
        assert!((rmax - 1.0).abs() < 1e-6);
        let mut c = [0.0f32; 3];
        for p in &local {
            for a in 0..3 {
                c[a] += p[a] / local.len() as f32;
            }
        }
        assert!(c.iter().all(|x| x.abs() < 1e-6));
        for (p, l) in pts.iter().zip(&local) {
            let w = f.to_world(*l);
            assert!(crate::math::dist_sq(w, *p).sqrt() < 1e-5 * f.scale);
        }
    }

    #[test]
    fn fit_rejects_bad_clouds() {
        assert!(Frame::fit(&[]).is_err());
        assert!(Frame::fit(&[[0.0; 3]; 3]).is_err());
        assert!(Frame::fit(&[[1.0, 2.0, 3.0]; 7]).is_err());
        let mut p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        p[2][1] = f64::NAN;
        let e = Frame::fit(&p).unwrap_err().to_string();
        assert!(e.contains("point 2"), "{e}");
        p[2][1] = f64::INFINITY;
        assert!(Frame::fit(&p).is_err());
        // Collinear is a legitimate (if useless) frame.
        assert!(Frame::fit(&[[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]).is_ok());
    }
    fn lattice() -> Vec<[f64; 3]> {
        (0..27).map(|i| [(i % 3) as f64 - 0.5, ((i / 3) % 3) as f64 + 0.25, (i / 9) as f64 * 0.75]).collect()
    }

    /// Regression: squared distances overflowed at 1e200 (and vanished at 1e-200), so
    /// such clouds were refused as "all points identical". Power-of-two scaling is
    /// exact, so the local coordinates must be bit-identical at any such scale.
    #[test]
    fn extreme_scales_fit_to_the_same_local_frame() {
        let pts = lattice();
        let local = Frame::fit(&pts).unwrap().to_local_all(&pts);
        for e in [-1020, -700, -300, 300, 700, 1000] {
            let k = 2f64.powi(e);
            let scaled: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|c| c * k)).collect();
            let f = Frame::fit(&scaled).unwrap_or_else(|err| panic!("2^{e}: {err}"));
            assert_eq!(f.to_local_all(&scaled), local, "2^{e}");
            for (p, l) in scaled.iter().zip(&local) {
                let w = f.to_world(*l);
                assert!(crate::math::dist_sq(w.map(|c| c / k), p.map(|c| c / k)).sqrt() < 1e-6, "2^{e}");
            }
        }
        // Subnormal coordinates (1e-310): fewer bits, but a frame, and finite local
        // coordinates in the unit ball (1 / scale is infinite there; no division by it).
        let sub: Vec<[f64; 3]> = pts.iter().map(|p| p.map(|c| c * 1e-310)).collect();
        let f = Frame::fit(&sub).unwrap();
        for (a, b) in f.to_local_all(&sub).iter().zip(&local) {
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-3), "{a:?} vs {b:?}");
        }
    }

    /// The refusals say what is wrong: identical points, an extent lost in the rounding
    /// of a large offset (naming both), a radius that overflows f64.
    #[test]
    fn degenerate_frames_say_why() {
        let err = |p: &[[f64; 3]]| Frame::fit(p).unwrap_err().to_string();
        assert!(err(&[[0.0; 3]; 5]).contains("identical"));
        // The centroid of 100 copies of 3.5 is not exactly 3.5: still "identical".
        assert!(err(&[[1.5, 2.5, 3.5]; 100]).contains("all points are identical"));
        let offset: Vec<[f64; 3]> = lattice().iter().map(|p| [p[0] + 1e15, p[1], p[2]]).collect();
        let e = err(&offset);
        assert!(e.contains("f64 resolution") && e.contains("1.000e15"), "{e}");
        // 1e12 is fine (DESIGN: any scale, pose or offset that f64 resolves), and so are
        // 1e13 and 1e14 (refused before session 20): the lattice's coordinates are
        // multiples of 1/4, exact at those offsets, so the local frame is the one without
        // the offset up to a similarity (the centroid and radius are rounded at the
        // offset's magnitude): the same differences between points, relative to the
        // largest of them.
        let shape = |l: &[[f32; 3]]| -> Vec<[f32; 3]> {
            let d: Vec<[f32; 3]> = l.iter().map(|p| std::array::from_fn(|a| p[a] - l[0][a])).collect();
            let big = d.iter().map(|v| v.iter().map(|c| c * c).sum::<f32>().sqrt()).fold(0.0, f32::max);
            d.iter().map(|v| v.map(|c| c / big)).collect()
        };
        let local = shape(&Frame::fit(&lattice()).unwrap().to_local_all(&lattice()));
        for off in [1e12, 1e13, 1e14] {
            let ok: Vec<[f64; 3]> = lattice().iter().map(|p| [p[0] + off, p[1] - off, p[2]]).collect();
            let f = Frame::fit(&ok).unwrap_or_else(|e| panic!("offset {off:e}: {e}"));
            for (a, b) in shape(&f.to_local_all(&ok)).iter().zip(&local) {
                assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-5), "offset {off:e}: {a:?} vs {b:?}");
            }
        }
        let far = [[f64::MAX, 0.0, 0.0], [-f64::MAX, 0.0, 0.0], [0.0, f64::MAX, 0.0], [0.0, 0.0, -f64::MAX]];
        assert!(err(&far).contains("overflows"), "{}", err(&far));
    }
}
