//! Property tests of `spatial::kdtree` against brute force: every kNN, nearest and radius answer
//! (single and batch) must equal the brute-force sort by `(dist_sq, index)` exactly, on uniform,
//! clustered-with-duplicates, identical, collinear, coplanar and tiny clouds.

#[path = "common/kdtree.rs"]
mod kdtree_common;

use kdtree_common::*;
use point2quad::spatial::kdtree::{KdTree, Neighbor};
use proptest::prelude::*;

fn split(v: &[Neighbor]) -> (Vec<u32>, Vec<f32>) {
    (v.iter().map(|n| n.index).collect(), v.iter().map(|n| n.dist_sq).collect())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn knn_and_nearest_match_brute_force(
        kind in cloud_kind(), n in cloud_size(), seed in any::<u64>(), k in 0usize..40,
    ) {
        let pts = make_cloud(kind, n, seed);
        let tree = KdTree::build(&pts);
        prop_assert_eq!(tree.len(), n);
        let qs = make_queries(&pts, 24, seed);
        let mut out = Vec::new();
        for &q in &qs {
            let want = brute_knn(&pts, q, k);
            tree.knn(q, k, &mut out);
            prop_assert_eq!(&out, &want, "query {:?} k {}", q, k);
            prop_assert_eq!(tree.nearest(q), brute_knn(&pts, q, 1).first().copied());
        }
        let table = tree.knn_batch(&qs, k);
        prop_assert_eq!(table.k, k.min(n));
        prop_assert_eq!(table.len(), qs.len());
        for (i, &q) in qs.iter().enumerate() {
            let (ii, dd) = split(&brute_knn(&pts, q, k));
            prop_assert_eq!(table.row(i), (&ii[..], &dd[..]));
        }
    }

    #[test]
    fn radius_matches_brute_force(
        kind in cloud_kind(), n in cloud_size(), seed in any::<u64>(), r_frac in 0.0f32..1.0,
    ) {
        let pts = make_cloud(kind, n, seed);
        let tree = KdTree::build(&pts);
        let qs = make_queries(&pts, 16, seed);
        let mut out = Vec::new();
        for &q in &qs {
            // Radii taken from actual distances hit the `<=` boundary exactly.
            let sorted = brute_sorted(&pts, q);
            let radius_sq = if sorted.is_empty() {
                r_frac
            } else {
                sorted[((sorted.len() - 1) as f32 * r_frac * r_frac) as usize].dist_sq
            };
            let want = brute_radius(&pts, q, radius_sq);
            tree.within_radius(q, radius_sq, &mut out);
            prop_assert_eq!(&out, &want, "query {:?} radius_sq {}", q, radius_sq);
            let table = tree.within_radius_batch(&[q, q], radius_sq);
            let (ii, dd) = split(&want);
            prop_assert_eq!(table.len(), 2);
            prop_assert_eq!(table.row(0), (&ii[..], &dd[..]));
            prop_assert_eq!(table.row(1), (&ii[..], &dd[..]));
        }
        let radius_sq = 4.0 * r_frac;
        let table = tree.within_radius_batch(&qs, radius_sq);
        prop_assert_eq!(table.offsets.len(), qs.len() + 1);
        for (i, &q) in qs.iter().enumerate() {
            let (ii, dd) = split(&brute_radius(&pts, q, radius_sq));
            prop_assert_eq!(table.row(i), (&ii[..], &dd[..]));
        }
    }

}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn all_points_queried_find_themselves_first(
        kind in cloud_kind(), n in 1usize..1000, seed in any::<u64>(),
    ) {
        // The pipeline's main use: every point queried with k = 12, itself included.
        let pts = make_cloud(kind, n, seed);
        let tree = KdTree::build(&pts);
        let table = tree.knn_batch(&pts, 12);
        for (i, &p) in pts.iter().enumerate() {
            let (ii, dd) = split(&brute_knn(&pts, p, 12));
            prop_assert_eq!(table.row(i), (&ii[..], &dd[..]));
            prop_assert_eq!(dd[0], 0.0);
        }
    }
}
