//! Proptest strategies for `pipeline::dataset` samples: small random, internally
//! consistent samples (indices in range, labels 0/1, finite values, any UTF-8 name).

#![allow(dead_code)]

use point2quad::pipeline::dataset::Sample;
use proptest::prelude::*;

/// A random consistent sample with up to `max_points` points and `max_cands` candidates.
pub fn sample(max_points: usize, max_cands: usize) -> impl Strategy<Value = Sample> {
    (1..=max_points, 0..=max_cands, 0u32..8, ".{0,12}").prop_flat_map(|(n, m, d, name)| {
        let v = 0..=n as u32;
        (Just((n, m, d, name)), v).prop_flat_map(|((n, m, d, name), v)| {
            let finite = -1e6f32..1e6f32;
            let points = prop::collection::vec([finite.clone(), finite.clone(), finite.clone()], n);
            let gt = if v == 0 {
                prop::collection::vec([0u32..1, 0..1, 0..1, 0..1], 0).boxed()
            } else {
                prop::collection::vec([0..v, 0..v, 0..v, 0..v], 0..6).boxed()
            };
            let nn = n as u32;
            let cands = prop::collection::vec([0..nn, 0..nn, 0..nn, 0..nn], m);
            let feats = prop::collection::vec(finite, m * d as usize);
            let labels = prop::collection::vec(0u8..2, m);
            (Just(name), points, Just(v), gt, cands, feats, Just(d), labels).prop_map(
                |(name, points, v, gt_faces, candidates, features, feature_dim, labels)| Sample {
                    name,
                    points,
                    n_mesh_vertices: v,
                    gt_faces,
                    candidates,
                    features,
                    feature_dim,
                    labels,
                },
            )
        })
    })
}
