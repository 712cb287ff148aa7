//! Shared proptest strategies and references for the KPConv tests: small random clouds (with
//! duplicates and negative coordinates), random KPConv problems, and brute-force references.
#![allow(dead_code)]

use point2quad::nn::kpconv::KpConvGeometry;
use proptest::prelude::*;

/// A cloud of 1..max_n points in [-2, 2]³; some points are exact duplicates of earlier ones.
pub fn cloud(max_n: usize) -> impl Strategy<Value = Vec<[f32; 3]>> {
    prop::collection::vec(
        (prop::array::uniform3(-2.0f32..2.0), any::<bool>(), any::<prop::sample::Index>()),
        1..max_n,
    )
    .prop_map(|v| {
        let mut out: Vec<[f32; 3]> = Vec::with_capacity(v.len());
        for (p, dup, idx) in v {
            if dup && !out.is_empty() {
                out.push(out[idx.index(out.len())]);
            } else {
                out.push(p);
            }
        }
        out
    })
}

/// A small random KPConv problem: geometry plus feature, weight and upstream-gradient buffers.
#[derive(Clone, Debug)]
pub struct Problem {
    pub queries: Vec<[f32; 3]>,
    pub support: Vec<[f32; 3]>,
    pub neighbors: Vec<u32>,
    pub cap: usize,
    pub kernel: Vec<[f32; 3]>,
    pub sigma: f32,
    pub c_in: usize,
    pub c_out: usize,
    pub features: Vec<f32>,
    pub weights: Vec<f32>,
    pub grad_out: Vec<f32>,
}

impl Problem {
    pub fn geometry(&self) -> KpConvGeometry {
        KpConvGeometry::new(&self.queries, &self.support, &self.neighbors, self.cap, &self.kernel, self.sigma)
            .expect("strategy builds valid problems")
    }
}

/// Random problems: up to 12 support points, up to 6 queries, random (possibly repeated or
/// shadow) neighbour slots, K in 1..=6 kernel points in a ball of radius 0.6, σ in [0.3, 0.8].
pub fn problem() -> impl Strategy<Value = Problem> {
    (1usize..12, 1usize..6, 1usize..5, 1usize..=6, 1usize..4, 1usize..4, 0.3f32..0.8, any::<u64>()).prop_map(
        |(ns, nq, cap, k, c_in, c_out, sigma, seed)| {
            let mut rng = point2quad::rng::Rng::new(seed);
            let mut u = |s: f32| (rng.f32() * 2.0 - 1.0) * s;
            let support: Vec<[f32; 3]> = (0..ns).map(|_| [u(0.5), u(0.5), u(0.5)]).collect();
            let queries: Vec<[f32; 3]> = (0..nq).map(|_| [u(0.3), u(0.3), u(0.3)]).collect();
            let kernel: Vec<[f32; 3]> = (0..k).map(|_| [u(0.35), u(0.35), u(0.35)]).collect();
            let features: Vec<f32> = (0..ns * c_in).map(|_| u(1.0)).collect();
            let weights: Vec<f32> = (0..k * c_in * c_out).map(|_| u(1.0)).collect();
            let grad_out: Vec<f32> = (0..nq * c_out).map(|_| u(1.0)).collect();
            let mut r2 = point2quad::rng::Rng::new(seed ^ 1);
            let neighbors: Vec<u32> = (0..nq * cap).map(|_| r2.below(ns + 1) as u32).collect();
            Problem {
                queries,
                support,
                neighbors,
                cap,
                kernel,
                sigma,
                c_in,
                c_out,
                features,
                weights,
                grad_out,
            }
        },
    )
}

/// Brute-force radius neighbours sorted by (dist², index), with the kd-tree's distance expression.
pub fn brute_radius(support: &[[f32; 3]], q: [f32; 3], radius_sq: f32) -> Vec<u32> {
    let mut v: Vec<(f32, u32)> = support
        .iter()
        .enumerate()
        .map(|(i, p)| (point2quad::spatial::kdtree::dist_sq(*p, q), i as u32))
        .filter(|(d, _)| *d <= radius_sq)
        .collect();
    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    v.into_iter().map(|(_, i)| i).collect()
}

/// `n` points on a sphere of radius `r` centred at `c` (Fibonacci lattice, jittered by `seed`).
pub fn sphere_cloud(n: usize, r: f32, c: [f32; 3], seed: u64) -> Vec<[f32; 3]> {
    let mut rng = point2quad::rng::Rng::new(seed);
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - z * z).sqrt();
            let t = golden * i as f64 + 0.3 * rng.f64();
            let p = [rho * t.cos(), rho * t.sin(), z];
            [c[0] + r * p[0] as f32, c[1] + r * p[1] as f32, c[2] + r * p[2] as f32]
        })
        .collect()
}

/// A tiny KPFCNN for tests: 3 levels, widths 8/16/32, cells 0.1/0.2/0.4, d_P = 6.
pub fn tiny_config() -> point2quad::nn::kpfcnn::KpfcnnConfig {
    use point2quad::nn::kpfcnn::BlockKind::*;
    point2quad::nn::kpfcnn::KpfcnnConfig {
        blocks: vec![Simple, Resnetb, ResnetbStrided, Resnetb, ResnetbStrided, Resnetb],
        first_features_dim: 8,
        first_cell: 0.1,
        out_dim: 6,
        ..point2quad::nn::kpfcnn::KpfcnnConfig::default_preset()
    }
}

/// Asserts that a gradient check of a KPFCNN or whole model passed under `gc`, naming
/// the worst ratio, the skipped and checked counts and the failures when it did not.
pub fn assert_report_passed(
    rep: &point2quad::tensor::GradCheckReport,
    gc: &point2quad::tensor::GradCheckConfig,
) {
    assert!(
        rep.passed(gc),
        "worst {} skipped {} of {}: {:?}",
        rep.worst_ratio,
        rep.skipped,
        rep.checked,
        rep.failures
    );
}
