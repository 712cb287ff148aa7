//! Property tests of KPConv's geometric preprocessing against brute-force references: grid
//! subsampling (barycentres per voxel, input-order independence), capped radius neighbourhoods
//! with shadow padding, nearest upsampling, and kernel point placement.

// Axis loops (`for d in 0..3`) index several arrays at once; iterators would obscure that.
#![allow(clippy::needless_range_loop)]

#[path = "common/kpconv.rs"]
mod kpc;

use std::collections::BTreeMap;

use point2quad::nn::kernel_points::{kernel_points, MEAN_RADIUS_RATIO};
use point2quad::spatial::kdtree::{dist_sq, KdTree};
use point2quad::spatial::neighborhoods::{
    nearest_upsampling, percentile_cap, radius_neighborhoods, NeighborCap,
};
use point2quad::spatial::subsample::{grid_subsample, subsample_pyramid, voxel_key};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn subsample_matches_brute_force_voxels(pts in kpc::cloud(200), cell in 0.05f32..1.5, seed in any::<u64>()) {
        let feats: Vec<f32> = pts.iter().flat_map(|p| [p[0] * 2.0, 1.0]).collect();
        let s = grid_subsample(&pts, Some((&feats, 2)), cell).unwrap();
        // Reference: group by key in a BTreeMap (sorted keys = the promised output order).
        let mut groups: BTreeMap<[i64; 3], Vec<usize>> = BTreeMap::new();
        for (i, p) in pts.iter().enumerate() {
            groups.entry(voxel_key(*p, cell)).or_default().push(i);
        }
        prop_assert_eq!(s.points.len(), groups.len());
        for (v, (key, members)) in groups.iter().enumerate() {
            let n = members.len() as f64;
            for d in 0..3 {
                let want = members.iter().map(|&i| pts[i][d] as f64).sum::<f64>() / n;
                prop_assert!((s.points[v][d] as f64 - want).abs() <= 1e-6 * (1.0 + want.abs()));
            }
            // The barycentre of a voxel lies in that voxel (closed box, up to rounding).
            for d in 0..3 {
                let lo = key[d] as f64 * cell as f64;
                prop_assert!(s.points[v][d] as f64 >= lo - 1e-5 && (s.points[v][d] as f64) <= lo + cell as f64 + 1e-5);
            }
            let fwant = members.iter().map(|&i| feats[2 * i] as f64).sum::<f64>() / n;
            prop_assert!((s.features[2 * v] as f64 - fwant).abs() <= 1e-5 * (1.0 + fwant.abs()));
            prop_assert_eq!(s.features[2 * v + 1], 1.0);
            for &i in members {
                prop_assert_eq!(s.cluster[i] as usize, v);
            }
        }
        // Shuffled input: bit-identical output, clusters permuted along.
        let mut perm: Vec<usize> = (0..pts.len()).collect();
        point2quad::rng::Rng::new(seed).shuffle(&mut perm);
        let p2: Vec<[f32; 3]> = perm.iter().map(|&i| pts[i]).collect();
        let f2: Vec<f32> = perm.iter().flat_map(|&i| [feats[2 * i], feats[2 * i + 1]]).collect();
        let s2 = grid_subsample(&p2, Some((&f2, 2)), cell).unwrap();
        prop_assert_eq!(&s.points, &s2.points);
        prop_assert_eq!(&s.features, &s2.features);
        for (new_i, &old_i) in perm.iter().enumerate() {
            prop_assert_eq!(s2.cluster[new_i], s.cluster[old_i]);
        }
    }

    #[test]
    fn pyramid_levels_are_chained_subsamplings(pts in kpc::cloud(150), cell in 0.05f32..0.5) {
        let p = subsample_pyramid(&pts, cell, 4).unwrap();
        prop_assert_eq!(&p.levels[0], &pts);
        for l in 1..4 {
            prop_assert!((p.cells[l] - cell * (1u32 << l) as f32).abs() <= 1e-6 * p.cells[l]);
            let want = grid_subsample(&p.levels[l - 1], None, p.cells[l]).unwrap().points;
            prop_assert_eq!(&p.levels[l], &want);
            prop_assert!(p.levels[l].len() <= p.levels[l - 1].len() && !p.levels[l].is_empty());
        }
    }

    #[test]
    fn capped_neighbourhoods_match_brute_force(
        support in kpc::cloud(120),
        queries in kpc::cloud(30),
        radius in 0.1f32..1.5,
        pct in 0.5f64..1.0,
    ) {
        let tree = KdTree::build(&support);
        let nb = radius_neighborhoods(&tree, &queries, radius, NeighborCap::Percentile(pct)).unwrap();
        let full: Vec<Vec<u32>> = queries.iter().map(|q| kpc::brute_radius(&support, *q, radius * radius)).collect();
        let counts: Vec<usize> = full.iter().map(|v| v.len()).collect();
        let cap = percentile_cap(&counts, pct).unwrap();
        prop_assert_eq!(nb.cap, cap);
        // At least a fraction pct of the queries keep every neighbour.
        let untouched = counts.iter().filter(|&&c| c <= cap).count();
        prop_assert!(untouched as f64 >= pct * queries.len() as f64 - 1e-9);
        prop_assert_eq!(nb.n_truncated, queries.len() - untouched);
        for (q, want) in full.iter().enumerate() {
            let row = nb.row(q);
            let n = want.len().min(cap);
            prop_assert_eq!(&row[..n], &want[..n]);
            prop_assert!(row[n..].iter().all(|&j| j == support.len() as u32));
        }
        let fixed = radius_neighborhoods(&tree, &queries, radius, NeighborCap::Fixed(3)).unwrap();
        prop_assert_eq!(fixed.cap, 3);
        prop_assert_eq!(fixed.indices.len(), queries.len() * 3);
    }

    #[test]
    fn upsampling_picks_the_nearest_coarse_point(coarse in kpc::cloud(40), fine in kpc::cloud(80)) {
        let up = nearest_upsampling(&KdTree::build(&coarse), &fine).unwrap();
        prop_assert_eq!(up.len(), fine.len());
        for (f, &c) in fine.iter().zip(&up) {
            let best = coarse.iter().map(|p| dist_sq(*p, *f)).fold(f32::INFINITY, f32::min);
            let first = coarse.iter().position(|p| dist_sq(*p, *f) == best).unwrap();
            prop_assert_eq!(c as usize, first);
        }
    }

    #[test]
    fn kernel_points_in_ball_distinct_centred(k in 1usize..25, seed in 0u64..1000) {
        let kp = kernel_points(k, seed).unwrap();
        prop_assert_eq!(kp.len(), k);
        prop_assert_eq!(kp[0], [0.0f32; 3]);
        let norm = |p: [f32; 3]| (p.iter().map(|c| (*c as f64).powi(2)).sum::<f64>()).sqrt();
        for (i, a) in kp.iter().enumerate() {
            prop_assert!(norm(*a) <= 1.0);
            for b in &kp[i + 1..] {
                prop_assert!(dist_sq(*a, *b) > 1e-4, "coincident kernel points");
            }
        }
        if k > 1 {
            let mean = kp[1..].iter().map(|p| norm(*p)).sum::<f64>() / (k - 1) as f64;
            prop_assert!((mean - MEAN_RADIUS_RATIO).abs() < 1e-5, "mean radius {}", mean);
        }
        prop_assert_eq!(&kp[..], &kernel_points(k, seed).unwrap()[..]);
    }
}

#[test]
fn one_point_and_duplicate_clouds() {
    let one = [[0.3f32, -0.2, 0.1]];
    let tree = KdTree::build(&one);
    let nb = radius_neighborhoods(&tree, &one, 0.1, NeighborCap::Percentile(0.9)).unwrap();
    assert_eq!((nb.cap, nb.indices.clone()), (1, vec![0]));
    let dup = vec![[1.0f32, 1.0, 1.0]; 50];
    let s = grid_subsample(&dup, None, 0.1).unwrap();
    assert_eq!(s.points, vec![[1.0, 1.0, 1.0]]);
    let nb =
        radius_neighborhoods(&KdTree::build(&dup), &s.points, 0.1, NeighborCap::Percentile(0.9)).unwrap();
    assert_eq!(nb.cap, 50);
    assert_eq!(nb.indices, (0..50).collect::<Vec<u32>>());
}
