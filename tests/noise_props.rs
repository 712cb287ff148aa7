//! Property tests of `pipeline::noise`: point count, every point within the stated normal
//! distance of its face with its footprint on the face (checked against a brute-force
//! point–triangle distance), determinism for a seed, and equivariance under scaling.

use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes;
use point2quad::pipeline::noise::{face_unit_normal, noise_points, noise_samples, NoiseConfig};
use point2quad::rng::Rng;
use proptest::prelude::*;

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn len(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Distance from `p` to segment ab.
fn seg_dist(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let ab = sub(b, a);
    let t = (dot(sub(p, a), ab) / dot(ab, ab).max(f64::MIN_POSITIVE)).clamp(0.0, 1.0);
    len(sub(p, [a[0] + t * ab[0], a[1] + t * ab[1], a[2] + t * ab[2]]))
}

/// Brute-force distance from `p` to triangle abc.
fn tri_dist(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (u, v) = (sub(b, a), sub(c, a));
    let n = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    let edges = seg_dist(p, a, b).min(seg_dist(p, b, c)).min(seg_dist(p, c, a));
    let nn = dot(n, n);
    if nn == 0.0 {
        return edges;
    }
    // Barycentric coordinates of the projection.
    let w = sub(p, a);
    let (uu, uv, vv, wu, wv) = (dot(u, u), dot(u, v), dot(v, v), dot(w, u), dot(w, v));
    let den = uu * vv - uv * uv;
    let s = (vv * wu - uv * wv) / den;
    let t = (uu * wv - uv * wu) / den;
    if s >= 0.0 && t >= 0.0 && s + t <= 1.0 {
        (dot(w, n) / nn.sqrt()).abs()
    } else {
        edges
    }
}

fn mean_edge(m: &QuadMesh, f: usize) -> f64 {
    let q = m.quads[f].map(|v| m.vertices[v as usize]);
    (0..4).map(|k| len(sub(q[(k + 1) % 4], q[k]))).sum::<f64>() / 4.0
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(40))]

    #[test]
    fn points_lie_near_their_faces(seed in 0u64..1_000_000, fraction in 0.0f64..0.5, offset in 0.0f64..0.5) {
        let mut rng = Rng::new(seed);
        let mesh = shapes::random_shape(&mut rng);
        let cfg = NoiseConfig { fraction, offset };
        let samples = noise_samples(&mesh, &cfg, &mut rng.clone()).unwrap();
        prop_assert_eq!(samples.len(), (fraction * mesh.vertices.len() as f64).round() as usize);
        // Same draws as noise_points.
        let pts = noise_points(&mesh, &cfg, &mut rng.clone()).unwrap();
        prop_assert!(pts.iter().zip(&samples).all(|(a, b)| *a == b.position));
        for s in &samples {
            let f = s.face as usize;
            let e = mean_edge(&mesh, f);
            prop_assert!(s.normal_offset.abs() <= offset * e * (1.0 + 1e-12));
            // The footprint (point moved back along the normal) lies on the face.
            let n = face_unit_normal(&mesh, f).unwrap();
            let d = s.normal_offset;
            let foot = [s.position[0] - d * n[0], s.position[1] - d * n[1], s.position[2] - d * n[2]];
            let q = mesh.quads[f].map(|v| mesh.vertices[v as usize]);
            let dist = tri_dist(foot, q[0], q[1], q[2]).min(tri_dist(foot, q[0], q[2], q[3]));
            prop_assert!(dist <= 1e-9 * e, "footprint {} off face {} (edge {})", dist, f, e);
            // Distance to the face (its closer triangle) is at most the offset bound.
            let to_face = tri_dist(s.position, q[0], q[1], q[2]).min(tri_dist(s.position, q[0], q[2], q[3]));
            prop_assert!(to_face <= offset * e + 1e-9 * e);
        }
    }

    #[test]
    fn deterministic_and_scale_equivariant(seed in 0u64..1_000_000, k in -20i32..20, s in 0.001f64..1000.0) {
        let mut rng = Rng::new(seed);
        let mesh = shapes::random_shape(&mut rng);
        let cfg = NoiseConfig::default();
        let a = noise_points(&mesh, &cfg, &mut Rng::new(seed)).unwrap();
        let b = noise_points(&mesh, &cfg, &mut Rng::new(seed)).unwrap();
        prop_assert_eq!(&a, &b);
        // Power-of-two scaling is exact in floating point: identical up to the factor.
        let f = 2f64.powi(k);
        let scaled = QuadMesh { vertices: mesh.vertices.iter().map(|v| v.map(|c| c * f)).collect(), quads: mesh.quads.clone() };
        let c = noise_points(&scaled, &cfg, &mut Rng::new(seed)).unwrap();
        prop_assert!(a.iter().zip(&c).all(|(p, q)| (0..3).all(|i| p[i] * f == q[i])));
        // Any scale: the same points up to rounding (offset scales with the mesh).
        let scaled = QuadMesh { vertices: mesh.vertices.iter().map(|v| v.map(|c| c * s)).collect(), quads: mesh.quads.clone() };
        let c = noise_points(&scaled, &cfg, &mut Rng::new(seed)).unwrap();
        let diag = {
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for v in &mesh.vertices { for i in 0..3 { lo[i] = lo[i].min(v[i]); hi[i] = hi[i].max(v[i]); } }
            len(sub(hi, lo))
        };
        let far = a.iter().zip(&c).filter(|(p, q)| len(sub(p.map(|x| x * s), **q)) > 1e-9 * diag * s).count();
        // A draw landing exactly on a triangle boundary may switch triangles under
        // rounding; allow none in practice but tolerate one such coincidence.
        prop_assert!(far <= 1, "{} points moved", far);
    }
}

#[test]
fn flat_faces_keep_points_within_offset_of_the_plane() {
    let mesh = shapes::cube(3);
    let cfg = NoiseConfig { fraction: 5.0, offset: 0.1 };
    let samples = noise_samples(&mesh, &cfg, &mut Rng::new(2)).unwrap();
    let edge = 2.0 / 3.0;
    let mut max_off = 0.0f64;
    for s in &samples {
        // Cube faces lie in the planes |x_i| = 1: distance to the plane of its face.
        let q = mesh.quads[s.face as usize].map(|v| mesh.vertices[v as usize]);
        let axis = (0..3).find(|&a| q.iter().all(|p| p[a] == q[0][a])).unwrap();
        let off = (s.position[axis] - q[0][axis]).abs();
        assert!(off <= 0.1 * edge + 1e-12);
        max_off = max_off.max(off);
        // Footprint inside the face's square.
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let lo = |a: usize| q.iter().map(|p| p[a]).fold(f64::INFINITY, f64::min) - 1e-12;
        let hi = |a: usize| q.iter().map(|p| p[a]).fold(f64::NEG_INFINITY, f64::max) + 1e-12;
        assert!((lo(b)..=hi(b)).contains(&s.position[b]) && (lo(c)..=hi(c)).contains(&s.position[c]));
    }
    // The bound is reached in practice (uniform offsets), not just respected.
    assert!(max_off > 0.09 * edge, "{max_off}");
}
