//! Noise points as in the paper: extra points near the surface of a quad mesh, each at an
//! area-uniform random position on the mesh, pushed along its face's normal by a random
//! amount proportional to that face's size. They make training clouds look like scans.
//!
//! Scale: the normal offset is uniform in [−`offset`, `offset`] × (the face's mean edge
//! length); the default `offset` is 0.1, i.e. at most a tenth of an edge off the surface.

use crate::error::{Error, Result};
use crate::math::{add, cross, norm, scale, sub};
use crate::mesh::poly::QuadMesh;
use crate::rng::Rng;

/// How many noise points and how far from the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseConfig {
    /// Noise points per mesh vertex (the count is `round(fraction × #vertices)`).
    /// Default 0.1 (the paper's 10%).
    pub fraction: f64,
    /// Largest distance along the face normal, as a fraction of the face's mean edge
    /// length. Default 0.1.
    pub offset: f64,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        NoiseConfig { fraction: 0.1, offset: 0.1 }
    }
}

/// Most noise points one call makes (10 million, 240 MB of positions): far beyond
/// any cloud this tool handles; without a bound a large `fraction` made the
/// allocation abort the process instead of returning an error.
pub const MAX_NOISE_POINTS: usize = 10_000_000;

/// One noise point with where it came from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoisePoint {
    /// Position.
    pub position: [f64; 3],
    /// The quad it was sampled on.
    pub face: u32,
    /// Signed distance moved along the face's unit normal from the sampled surface point
    /// (|value| ≤ `offset` × the face's mean edge length).
    pub normal_offset: f64,
}

/// `round(cfg.fraction × #vertices)` noise points on `mesh` (see the module header).
///
/// # Errors
/// `InvalidInput` when `fraction` or `offset` is negative or not finite, `fraction` asks
/// for more than [`MAX_NOISE_POINTS`] points, a face index is out of range, a vertex is not finite,
/// points are asked for on a mesh without area, or `offset` is so large that a point
/// would not be finite.
pub fn noise_points(mesh: &QuadMesh, cfg: &NoiseConfig, rng: &mut Rng) -> Result<Vec<[f64; 3]>> {
    Ok(noise_samples(mesh, cfg, rng)?.into_iter().map(|p| p.position).collect())
}

/// Like [`noise_points`], keeping each point's face and normal offset (for tests and
/// diagnostics). Draws the same random numbers, so the positions are identical.
///
/// # Errors
/// As [`noise_points`].
pub fn noise_samples(mesh: &QuadMesh, cfg: &NoiseConfig, rng: &mut Rng) -> Result<Vec<NoisePoint>> {
    if !(cfg.fraction.is_finite() && cfg.fraction >= 0.0) {
        return Err(Error::invalid(format!("noise fraction must be finite and >= 0, got {}", cfg.fraction)));
    }
    if !(cfg.offset.is_finite() && cfg.offset >= 0.0) {
        return Err(Error::invalid(format!("noise offset must be finite and >= 0, got {}", cfg.offset)));
    }
    check_mesh(mesh)?;
    let nv = mesh.vertices.len();
    let wanted = (cfg.fraction * nv as f64).round();
    if wanted > MAX_NOISE_POINTS as f64 {
        return Err(Error::invalid(format!(
            "noise fraction {} asks for {wanted} noise points on {nv} vertices; at most {MAX_NOISE_POINTS}",
            cfg.fraction
        )));
    }
    let count = wanted as usize;
    if count == 0 {
        return Ok(Vec::new());
    }
    // Two triangles per quad, (0,1,2) and (0,2,3); cumulative areas for the area-uniform pick.
    let p = |v: u32| mesh.vertices[v as usize];
    let mut cumulative = Vec::with_capacity(2 * mesh.quads.len());
    let mut total = 0.0;
    for q in &mesh.quads {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            total += 0.5 * norm(cross(sub(p(t[1]), p(t[0])), sub(p(t[2]), p(t[0]))));
            cumulative.push(total);
        }
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(Error::invalid(format!(
            "cannot place {count} noise points: the mesh's area is {total} ({} faces)",
            mesh.quads.len()
        )));
    }
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        // The first triangle whose cumulative area exceeds the draw; zero-area triangles
        // never qualify since they repeat their predecessor's sum.
        let x = rng.f64() * total;
        let ti = cumulative.partition_point(|&c| c <= x).min(cumulative.len() - 1);
        let fi = ti / 2;
        let q = mesh.quads[fi];
        let t = if ti % 2 == 0 { [q[0], q[1], q[2]] } else { [q[0], q[2], q[3]] };
        let (mut r1, mut r2) = (rng.f64(), rng.f64());
        if r1 + r2 > 1.0 {
            (r1, r2) = (1.0 - r1, 1.0 - r2);
        }
        let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
        let on_surface = add(a, add(scale(sub(b, a), r1), scale(sub(c, a), r2)));
        let mean_edge = (0..4).map(|k| norm(sub(p(q[(k + 1) % 4]), p(q[k])))).sum::<f64>() / 4.0;
        let d = rng.uniform(-1.0, 1.0) * cfg.offset * mean_edge;
        let n = face_unit_normal(mesh, fi).unwrap_or_else(|| {
            // A degenerate quad diagonal: fall back to the picked (non-degenerate) triangle.
            let n = cross(sub(b, a), sub(c, a));
            scale(n, 1.0 / norm(n))
        });
        let position = add(on_surface, scale(n, d));
        if !position.iter().all(|c| c.is_finite()) {
            return Err(Error::invalid(format!(
                "noise offset {} is too large for this mesh: noise point {} is not finite",
                cfg.offset,
                out.len()
            )));
        }
        out.push(NoisePoint { position, face: fi as u32, normal_offset: d });
    }
    Ok(out)
}

/// Unit normal of quad `fi` from its diagonals, `(p2 − p0) × (p3 − p1)`; `None` if degenerate.
pub fn face_unit_normal(mesh: &QuadMesh, fi: usize) -> Option<[f64; 3]> {
    let q = mesh.quads[fi].map(|v| mesh.vertices[v as usize]);
    crate::math::normalize(cross(sub(q[2], q[0]), sub(q[3], q[1])))
}

/// `InvalidInput` naming the first non-finite vertex or out-of-range face index.
fn check_mesh(mesh: &QuadMesh) -> Result<()> {
    let nv = mesh.vertices.len();
    if let Some(i) = mesh.vertices.iter().position(|v| !v.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid(format!("vertex {i} has a non-finite coordinate")));
    }
    for (fi, q) in mesh.quads.iter().enumerate() {
        if let Some(&v) = q.iter().find(|&&v| v as usize >= nv) {
            return Err(Error::invalid(format!("face {fi} refers to vertex {v}, but the mesh has {nv}")));
        }
    }
    Ok(())
}

/// The mesh with every vertex moved by a Gaussian step of standard deviation `sigma`
/// × the mean length of the edges at that vertex in each coordinate (scanner-like
/// positional noise; `synth --jitter`, session 23). Faces are kept; a vertex no face
/// uses stays where it is. `sigma` = 0 returns the mesh unchanged and draws nothing
/// from `rng` (so what is drawn after it is as without jitter).
///
/// # Errors
/// `InvalidInput` when `sigma` is negative or not finite, a face index is out of range,
/// a vertex is not finite, or a moved vertex would not be finite.
pub fn jitter_vertices(mesh: &QuadMesh, sigma: f64, rng: &mut Rng) -> Result<QuadMesh> {
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(Error::invalid(format!("jitter must be finite and >= 0, got {sigma}")));
    }
    check_mesh(mesh)?;
    let nv = mesh.vertices.len();
    if sigma == 0.0 {
        return Ok(mesh.clone());
    }
    // Each face side once per face that has it: an edge of two faces counts twice at
    // both its ends, which leaves the mean unchanged on a manifold mesh.
    let (mut sum, mut count) = (vec![0.0f64; nv], vec![0u32; nv]);
    for q in &mesh.quads {
        for i in 0..4 {
            let (a, b) = (q[i] as usize, q[(i + 1) % 4] as usize);
            let l = norm(sub(mesh.vertices[a], mesh.vertices[b]));
            for v in [a, b] {
                sum[v] += l;
                count[v] += 1;
            }
        }
    }
    let mut vertices = mesh.vertices.clone();
    for (i, v) in vertices.iter_mut().enumerate() {
        if count[i] == 0 {
            continue;
        }
        let s = sigma * sum[i] / f64::from(count[i]);
        let step = [rng.normal(), rng.normal(), rng.normal()];
        *v = add(*v, scale(step, s));
        if !v.iter().all(|c| c.is_finite()) {
            return Err(Error::invalid(format!(
                "jitter {sigma} moves vertex {i} beyond the floating-point range"
            )));
        }
    }
    Ok(QuadMesh { vertices, quads: mesh.quads.clone() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::shapes;

    #[test]
    fn count_is_rounded_fraction_of_vertices() {
        let m = shapes::grid(4, 4, 1.0, 1.0); // 25 vertices
        let mut rng = Rng::new(1);
        for (f, n) in [(0.1, 3), (0.0, 0), (1.0, 25), (2.02, 51)] {
            let cfg = NoiseConfig { fraction: f, ..Default::default() };
            assert_eq!(noise_points(&m, &cfg, &mut rng).unwrap().len(), n);
        }
    }

    #[test]
    fn bad_config_and_meshes_are_errors() {
        let m = shapes::grid(2, 2, 1.0, 1.0);
        let mut rng = Rng::new(0);
        for cfg in [
            NoiseConfig { fraction: -0.1, offset: 0.1 },
            NoiseConfig { fraction: f64::NAN, offset: 0.1 },
            NoiseConfig { fraction: 0.1, offset: f64::INFINITY },
        ] {
            assert!(noise_points(&m, &cfg, &mut rng).is_err());
        }
        let cfg = NoiseConfig { fraction: 1.0, offset: 0.1 };
        let mut bad = m.clone();
        bad.quads[0][2] = 99;
        assert!(noise_points(&bad, &cfg, &mut rng).unwrap_err().to_string().contains("face 0"));
        let flat = QuadMesh { vertices: vec![[0.0; 3]; 4], quads: vec![[0, 1, 2, 3]] };
        assert!(noise_points(&flat, &cfg, &mut rng).is_err());
        let mut nan = m.clone();
        nan.vertices[3][1] = f64::NAN;
        assert!(noise_points(&nan, &cfg, &mut rng).is_err());
        assert!(noise_points(&QuadMesh::default(), &cfg, &mut rng).unwrap().is_empty());
    }

    /// Regression: `synth --noise 1e9` aborted the process on a 11.6 TB allocation, and
    /// a huge offset gave infinite noise points; both are now errors.
    #[test]
    fn huge_fraction_and_offset_are_errors_not_aborts() {
        let m = shapes::grid(4, 4, 1.0, 1.0);
        let mut rng = Rng::new(0);
        let e = noise_points(&m, &NoiseConfig { fraction: 1e9, offset: 0.1 }, &mut rng).unwrap_err();
        assert!(e.to_string().contains("noise fraction"), "{e}");
        let limit = MAX_NOISE_POINTS as f64 / 25.0;
        let over = NoiseConfig { fraction: limit * 1.001, offset: 0.1 };
        assert!(noise_points(&m, &over, &mut rng).is_err());
        // Mean edge 250: offset × edge overflows for all but the tiniest draws.
        let wide = shapes::grid(4, 4, 1000.0, 1000.0);
        let e = noise_points(&wide, &NoiseConfig { fraction: 1.0, offset: f64::MAX }, &mut rng).unwrap_err();
        assert!(e.to_string().contains("offset"), "{e}");
    }

    #[test]
    fn faces_are_picked_by_area() {
        // Two quads, the second 3 times larger: it should get ~75% of the points.
        let m = QuadMesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
                [4.0, 0.0, 0.0],
                [4.0, 1.0, 0.0],
            ],
            quads: vec![[0, 1, 2, 3], [1, 4, 5, 2]],
        };
        let cfg = NoiseConfig { fraction: 2000.0, offset: 0.0 };
        let s = noise_samples(&m, &cfg, &mut Rng::new(4)).unwrap();
        let big = s.iter().filter(|p| p.face == 1).count() as f64 / s.len() as f64;
        assert!((big - 0.75).abs() < 0.02, "{big}");
        // Within the big face, uniform in x: mean x ≈ 2.5.
        let xs: Vec<f64> = s.iter().filter(|p| p.face == 1).map(|p| p.position[0]).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((mean - 2.5).abs() < 0.05, "{mean}");
        assert!(s.iter().all(|p| p.position[2] == 0.0));
    }
}
