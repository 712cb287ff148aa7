//! The normalising frame: every stage after reading works on the cloud translated to
//! its centroid and scaled so that the farthest point lies at distance 1. The frame
//! keeps the transform so results can be mapped back to the input coordinates.

use crate::error::{Error, Result};

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
    /// infinite coordinate (the error names the point index), or has no extent (all
    /// points identical, up to f64 rounding relative to the coordinates' magnitude).
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
        let n = points.len() as f64;
        let mut center = [0.0f64; 3];
        for p in points {
            for a in 0..3 {
                center[a] += p[a];
            }
        }
        for c in &mut center {
            *c /= n;
        }
        let mut r2 = 0.0f64;
        let mut mag = 0.0f64;
        for p in points {
            r2 = r2.max(crate::math::dist_sq(*p, center));
            mag = mag.max(p.iter().fold(0.0f64, |m, c| m.max(c.abs())));
        }
        let scale = r2.sqrt();
        // An extent at the level of f64 rounding of the coordinates is no extent: the
        // local coordinates would be pure rounding noise.
        if !scale.is_finite() || scale <= mag * 1e-12 || scale == 0.0 {
            return Err(Error::invalid("degenerate point cloud: all points are identical"));
        }
        Ok(Frame { center, scale })
    }

    /// World → local (f32, the precision every later stage works in).
    #[inline]
    pub fn to_local(&self, p: [f64; 3]) -> [f32; 3] {
        let s = 1.0 / self.scale;
        [
            ((p[0] - self.center[0]) * s) as f32,
            ((p[1] - self.center[1]) * s) as f32,
            ((p[2] - self.center[2]) * s) as f32,
        ]
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
}
