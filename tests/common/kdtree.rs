//! Shared fixtures for kd-tree tests: point clouds of several shapes (uniform, clustered with
//! exact duplicates, identical, collinear, coplanar, tiny), queries that hit points and tie
//! exactly, and the brute-force reference that every tree answer must equal.

#![allow(dead_code)]

use point2quad::rng::Rng;
use point2quad::spatial::kdtree::{dist_sq, Neighbor};
use proptest::prelude::*;

/// Which kind of cloud [`make_cloud`] draws.
#[derive(Clone, Copy, Debug)]
pub enum CloudKind {
    /// Uniform in a box.
    Uniform,
    /// A few clusters on a coarse integer grid: many exact duplicates and exactly equal distances.
    ClusteredDuplicates,
    /// One point repeated.
    Identical,
    /// On a line, parameters on a coarse grid (duplicates and ties again).
    Collinear,
    /// On an axis-aligned plane with a coarse grid in it.
    Coplanar,
}

/// A cloud of `n` points of the given kind, fully determined by `seed`.
pub fn make_cloud(kind: CloudKind, n: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut r = Rng::new(seed);
    match kind {
        CloudKind::Uniform => {
            let s = [1.0f32, 10.0, 1e-3][r.below(3)];
            (0..n).map(|_| [s * r.f32(), s * r.f32(), s * r.f32()]).collect()
        }
        CloudKind::ClusteredDuplicates => {
            let centers: Vec<[f32; 3]> = (0..1 + r.below(4))
                .map(|_| [r.below(40) as f32, r.below(40) as f32, r.below(40) as f32])
                .collect();
            (0..n)
                .map(|_| {
                    let c = centers[r.below(centers.len())];
                    let h = 0.25 * r.below(5) as f32;
                    [c[0] + h, c[1] + 0.25 * r.below(3) as f32, c[2] - 0.5 * r.below(2) as f32]
                })
                .collect()
        }
        CloudKind::Identical => {
            let p = [r.f32() - 0.5, 3.0 * r.f32(), -r.f32()];
            vec![p; n]
        }
        CloudKind::Collinear => {
            let a = [r.f32(), r.f32(), r.f32()];
            let d = [r.f32() - 0.5, r.f32() - 0.5, r.f32() - 0.5];
            (0..n)
                .map(|_| {
                    let t = r.below(64) as f32 * 0.125;
                    [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]]
                })
                .collect()
        }
        CloudKind::Coplanar => {
            let axis = r.below(3);
            let level = r.f32();
            (0..n)
                .map(|_| {
                    let mut p = [r.below(30) as f32 * 0.5, r.f32() * 10.0, r.below(30) as f32 * 0.5];
                    p[axis] = level;
                    p
                })
                .collect()
        }
    }
}

/// Any [`CloudKind`].
pub fn cloud_kind() -> impl Strategy<Value = CloudKind> {
    prop_oneof![
        Just(CloudKind::Uniform),
        Just(CloudKind::ClusteredDuplicates),
        Just(CloudKind::Identical),
        Just(CloudKind::Collinear),
        Just(CloudKind::Coplanar),
    ]
}

/// Cloud sizes: tiny (0..5) a third of the time, otherwise up to a few thousand.
pub fn cloud_size() -> impl Strategy<Value = usize> {
    prop_oneof![0usize..5, 5usize..200, 200usize..3000]
}

/// `m` queries for `points`: the points themselves, jittered points, grid points (exact ties on
/// the clustered kinds), uniform ones in the bounding region and far away ones.
pub fn make_queries(points: &[[f32; 3]], m: usize, seed: u64) -> Vec<[f32; 3]> {
    let mut r = Rng::new(seed ^ 0x5151);
    (0..m)
        .map(|_| match r.below(5) {
            0 if !points.is_empty() => points[r.below(points.len())],
            1 if !points.is_empty() => {
                let p = points[r.below(points.len())];
                [p[0] + 0.01 * (r.f32() - 0.5), p[1], p[2] + 0.01 * r.f32()]
            }
            2 => [r.below(40) as f32, r.below(40) as f32 + 0.125, r.below(40) as f32],
            3 => [1e4 * (r.f32() - 0.5), -2e4 * r.f32(), 3e3],
            _ => [40.0 * r.f32() - 1.0, 40.0 * r.f32(), 40.0 * r.f32() - 5.0],
        })
        .collect()
}

/// All points sorted by `(dist_sq, index)` from `q`.
pub fn brute_sorted(points: &[[f32; 3]], q: [f32; 3]) -> Vec<Neighbor> {
    let mut all: Vec<Neighbor> = points
        .iter()
        .enumerate()
        .map(|(i, &p)| Neighbor { index: i as u32, dist_sq: dist_sq(q, p) })
        .collect();
    all.sort_by(|a, b| a.dist_sq.total_cmp(&b.dist_sq).then(a.index.cmp(&b.index)));
    all
}

/// The brute-force k nearest neighbours.
pub fn brute_knn(points: &[[f32; 3]], q: [f32; 3], k: usize) -> Vec<Neighbor> {
    let mut all = brute_sorted(points, q);
    all.truncate(k);
    all
}

/// The brute-force radius search.
pub fn brute_radius(points: &[[f32; 3]], q: [f32; 3], radius_sq: f32) -> Vec<Neighbor> {
    brute_sorted(points, q).into_iter().filter(|n| n.dist_sq <= radius_sq).collect()
}
