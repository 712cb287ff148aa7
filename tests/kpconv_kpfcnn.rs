//! KPConv on the tape and the whole KPFCNN: gradient checks through the tape (the fused op and a
//! whole small network), permutation equivariance, translation invariance (pyramid held fixed,
//! and whole-cell translations on dyadic cells), and locality of the receptive field.

#[path = "common/kpconv.rs"]
mod kpc;

use std::sync::Arc;

use point2quad::nn::kpconv::KpConvOp;
use point2quad::nn::kpfcnn::{prepare, Kpfcnn, KpfcnnConfig, PointPyramid};
use point2quad::spatial::neighborhoods::NeighborCap;
use point2quad::tensor::{gradcheck, GradCheckConfig, Graph, ParamKind, ParamStore, Tensor};
use proptest::prelude::*;

fn run(cfg: &KpfcnnConfig, params: &mut ParamStore, net: &Kpfcnn, pyr: &PointPyramid, train: bool) -> Tensor {
    let mut g = Graph::new(params, train, train);
    let out = net.forward(&mut g, pyr).unwrap();
    let t = g.value(out).clone();
    assert_eq!(t.dims(), &[pyr.num_inputs(), cfg.out_dim]);
    assert!(t.all_finite());
    t
}

fn assert_close(a: &[f32], b: &[f32], tol: f32) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!((x - y).abs() <= tol * (1.0 + x.abs().max(y.abs())), "element {i}: {x} vs {y}");
    }
}

/// The eval-mode check of the piecewise-linear tests below (small step, few switches).
fn piecewise_linear() -> GradCheckConfig {
    GradCheckConfig { eps: 1e-4, max_per_param: 6, seed: 3, train: false, ..GradCheckConfig::default() }
}

/// Gradient check of a fresh network for `cfg` on `pyr`: passes, with more than
/// `min_checked` entries checked.
fn check_grads(cfg: &KpfcnnConfig, pyr: &PointPyramid, gc: &GradCheckConfig, min_checked: usize) {
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(cfg, &mut ps).unwrap();
    let rep = gradcheck(&mut ps, |g| net.forward(g, pyr), gc).unwrap();
    kpc::assert_report_passed(&rep, gc);
    assert!(rep.checked > min_checked, "{}", rep.checked);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The custom op's backward, called by the tape, against finite differences of the tape.
    #[test]
    fn kpconv_op_gradcheck_through_tape(p in kpc::problem()) {
        let geom = Arc::new(p.geometry());
        let mut ps = ParamStore::new();
        let f = ps.add("f", ParamKind::Trainable, Tensor::new(&[p.support.len(), p.c_in], p.features.clone()).unwrap()).unwrap();
        let k = p.kernel.len();
        let w = ps.add("w", ParamKind::Trainable, Tensor::new(&[k, p.c_in, p.c_out], p.weights.clone()).unwrap()).unwrap();
        let rep = gradcheck(
            &mut ps,
            |g| {
                let (fv, wv) = (g.param(f), g.param(w));
                g.custom(Box::new(KpConvOp::new(geom.clone())), &[fv, wv])
            },
            &GradCheckConfig::default(),
        )
        .unwrap();
        prop_assert!(rep.passed(&GradCheckConfig::default()), "{:?}", rep.failures);
        prop_assert!(rep.checked > 0);
    }
}

/// The whole network (every block kind: simple, ResNet bottleneck, strided with max-pool
/// shortcut, nearest upsampling + skip concatenation, head) through the tape against central
/// differences. Eval mode and LeakyReLU slope 1 make the output piecewise *linear* in every
/// parameter (batch norm is affine with running statistics; only max-pool switches remain), so
/// the differences are exact up to f32 rounding and a small step keeps switches rare. (With
/// slope 0.1 at this initialisation many pre-activations sit within 1e-3 of the kink, and with
/// batch statistics the f32 noise is amplified: both make finite differences unreliable, not the
/// gradients wrong; the activation and train-mode batch norm are checked below and by the tensor
/// engine's own tests.)
#[test]
fn whole_small_kpfcnn_gradcheck_piecewise_linear() {
    let cfg = KpfcnnConfig { first_features_dim: 8, out_dim: 3, leaky_slope: 1.0, ..kpc::tiny_config() };
    let pts = kpc::sphere_cloud(90, 0.5, [0.0; 3], 1);
    let pyr = prepare(&pts, &cfg).unwrap();
    assert_eq!(pyr.points.iter().map(|l| l.len()).collect::<Vec<_>>(), vec![90, 77, 32]);
    assert!(pyr.pool.iter().all(|nb| nb.cap > 1), "max-pool must see several neighbours");
    check_grads(&cfg, &pyr, &piecewise_linear(), 300);
}

/// Train mode (batch statistics, a smooth function of the parameters here): one level, so no
/// max-pool, and slope 1 so no activation kink. (With slope 0.1 this check sees kinks within
/// the step: a scan of the loss along `enc0.bn.beta[1]` showed the analytic slope 3.129 exactly
/// on the smooth side and a kink 5e-4 to the right.)
#[test]
fn single_level_kpfcnn_gradcheck_train_mode() {
    use point2quad::nn::kpfcnn::BlockKind::*;
    let cfg = KpfcnnConfig {
        first_features_dim: 8,
        out_dim: 3,
        leaky_slope: 1.0,
        blocks: vec![Simple, Resnetb, Resnetb],
        ..kpc::tiny_config()
    };
    let pts = kpc::sphere_cloud(90, 0.5, [0.0; 3], 1);
    let pyr = prepare(&pts, &cfg).unwrap();
    let gc = GradCheckConfig { max_per_param: 8, seed: 5, train: true, ..GradCheckConfig::default() };
    check_grads(&cfg, &pyr, &gc, 100);
}

#[test]
fn permutation_equivariance() {
    let cfg = kpc::tiny_config();
    let pts = kpc::sphere_cloud(400, 0.6, [0.1, -0.2, 0.05], 2);
    let mut perm: Vec<usize> = (0..pts.len()).collect();
    point2quad::rng::Rng::new(9).shuffle(&mut perm);
    let shuffled: Vec<[f32; 3]> = perm.iter().map(|&i| pts[i]).collect();
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    for train in [false, true] {
        let a = run(&cfg, &mut ps, &net, &prepare(&pts, &cfg).unwrap(), train);
        let b = run(&cfg, &mut ps, &net, &prepare(&shuffled, &cfg).unwrap(), train);
        let a_perm: Vec<f32> = perm.iter().flat_map(|&i| a.row(i).to_vec()).collect();
        assert_close(&a_perm, b.data(), 1e-4);
    }
}

#[test]
fn translation_invariance_with_the_pyramid_held_fixed() {
    let cfg = kpc::tiny_config();
    let pts = kpc::sphere_cloud(300, 0.6, [0.0; 3], 4);
    let pyr = prepare(&pts, &cfg).unwrap();
    let t = [0.37f32, -1.25, 2.5];
    let mut moved = pyr.clone();
    for level in &mut moved.points {
        for p in level.iter_mut() {
            *p = [p[0] + t[0], p[1] + t[1], p[2] + t[2]];
        }
    }
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    let a = run(&cfg, &mut ps, &net, &pyr, true);
    let b = run(&cfg, &mut ps, &net, &moved, true);
    // Relative positions change by f32 rounding only (|t| ≈ 2.8 → ~3e-7).
    assert_close(a.data(), b.data(), 2e-4);
}

#[test]
fn translation_by_whole_cells_gives_the_same_pyramid_and_features() {
    // Dyadic cells and coordinates on a 2^-12 grid: p + t is exact, so voxels are the same.
    let cfg = KpfcnnConfig { first_cell: 0.125, ..kpc::tiny_config() };
    let q = |x: f32| (x * 4096.0).round() / 4096.0;
    let pts: Vec<[f32; 3]> =
        kpc::sphere_cloud(300, 0.6, [0.0; 3], 5).iter().map(|p| [q(p[0]), q(p[1]), q(p[2])]).collect();
    let coarsest = cfg.cell(cfg.num_levels() - 1);
    let t = [2.0 * coarsest, -3.0 * coarsest, coarsest];
    let moved: Vec<[f32; 3]> = pts.iter().map(|p| [p[0] + t[0], p[1] + t[1], p[2] + t[2]]).collect();
    let (pa, pb) = (prepare(&pts, &cfg).unwrap(), prepare(&moved, &cfg).unwrap());
    // Same voxels, same neighbour sets; only the order of (near-)equidistant neighbours may
    // differ, since distances are computed from translated, rounded coordinates.
    let sorted_rows = |nb: &point2quad::spatial::neighborhoods::Neighborhoods| -> Vec<Vec<u32>> {
        (0..nb.n_queries)
            .map(|q| {
                let mut r = nb.row(q).to_vec();
                r.sort_unstable();
                r
            })
            .collect()
    };
    for l in 0..pa.num_levels() {
        assert_eq!(pa.points[l].len(), pb.points[l].len(), "level {l}");
        for (p, q) in pa.points[l].iter().zip(&pb.points[l]) {
            assert!((0..3).all(|d| (p[d] + t[d] - q[d]).abs() <= 1e-5), "level {l}: {p:?} + {t:?} vs {q:?}");
        }
        assert_eq!(sorted_rows(&pa.conv[l]), sorted_rows(&pb.conv[l]), "level {l}");
    }
    for l in 0..pa.pool.len() {
        assert_eq!(sorted_rows(&pa.pool[l]), sorted_rows(&pb.pool[l]), "pool {l}");
        assert_eq!(pa.upsample[l], pb.upsample[l], "upsample {l}");
    }
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    let a = run(&cfg, &mut ps, &net, &pa, true);
    let b = run(&cfg, &mut ps, &net, &pb, true);
    assert_close(a.data(), b.data(), 2e-4);
}

#[test]
fn locality_far_changes_leave_features_unchanged() {
    // Eval mode (running statistics): batch statistics would couple all points by design.
    // Fixed caps: a percentile cap is a global statistic of the cloud, also by design.
    let cfg = KpfcnnConfig { neighbor_cap: NeighborCap::Fixed(40), ..kpc::tiny_config() };
    let a = kpc::sphere_cloud(200, 0.5, [0.0; 3], 6);
    let b = kpc::sphere_cloud(200, 0.5, [8.0, 0.0, 0.0], 7);
    let cloud: Vec<[f32; 3]> = a.iter().chain(&b).copied().collect();
    let mut changed = cloud.clone();
    changed[300] = [8.2, 0.3, 0.1];
    changed[350][2] += 0.05;
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    let x = run(&cfg, &mut ps, &net, &prepare(&cloud, &cfg).unwrap(), false);
    let y = run(&cfg, &mut ps, &net, &prepare(&changed, &cfg).unwrap(), false);
    assert_close(&x.data()[..200 * cfg.out_dim], &y.data()[..200 * cfg.out_dim], 1e-6);
    let far_diff = x.data()[200 * cfg.out_dim..]
        .iter()
        .zip(&y.data()[200 * cfg.out_dim..])
        .any(|(p, q)| (p - q).abs() > 1e-4);
    assert!(far_diff, "the change must matter where it happens");
}

#[test]
fn paper_preset_runs_and_counts_parameters() {
    let cfg = KpfcnnConfig::paper();
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    assert_eq!(ps.num_trainable(), cfg.param_count());
    let pts = kpc::sphere_cloud(600, 0.9, [0.0; 3], 8);
    let pyr = prepare(&pts, &cfg).unwrap();
    assert_eq!(pyr.num_levels(), 5);
    let out = run(&cfg, &mut ps, &net, &pyr, false);
    assert_eq!(out.dims(), &[600, 64]);
}

#[test]
fn degenerate_clouds_give_results_or_clear_errors() {
    let cfg = kpc::tiny_config();
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    // One point: every level has one point; eval works, train-mode batch norm refuses clearly.
    let one = prepare(&[[0.1, 0.2, 0.3]], &cfg).unwrap();
    assert!(one.points.iter().all(|l| l.len() == 1));
    let out = run(&cfg, &mut ps, &net, &one, false);
    assert_eq!(out.dims(), &[1, cfg.out_dim]);
    let mut g = Graph::train(&mut ps);
    let err = net.forward(&mut g, &one).unwrap_err();
    assert!(matches!(err, point2quad::Error::Shape { .. }), "{err}");
    drop(g);
    // Duplicates and a collinear cloud.
    let line: Vec<[f32; 3]> = (0..60)
        .map(|i| [i as f32 * 0.02 - 0.6, 0.0, 0.0])
        .chain(std::iter::repeat([0.0; 3]).take(10))
        .collect();
    let pyr = prepare(&line, &cfg).unwrap();
    let out = run(&cfg, &mut ps, &net, &pyr, true);
    assert_eq!(out.dims(), &[70, cfg.out_dim]);
    // Rows of identical points get identical features.
    for r in 61..70 {
        assert_eq!(out.row(r), out.row(60));
    }
    // Bad input is an error, never a panic.
    assert!(prepare(&[], &cfg).is_err());
    assert!(prepare(&[[f32::NAN, 0.0, 0.0]], &cfg).is_err());
    assert!(prepare(&[[f32::INFINITY, 0.0, 0.0], [0.0; 3]], &cfg).is_err());
    assert!(prepare(&[[1e30, 0.0, 0.0]], &cfg).is_err());
    // A pyramid from another configuration is refused.
    let other = prepare(&line, &KpfcnnConfig::paper()).unwrap();
    let mut g = Graph::eval(&mut ps);
    assert!(net.forward(&mut g, &other).is_err());
}

#[test]
fn xyz_input_option_feeds_coordinates() {
    use point2quad::nn::kpfcnn::InputFeatures;
    let cfg = KpfcnnConfig { input: InputFeatures::OnesXyz, ..kpc::tiny_config() };
    let pts = kpc::sphere_cloud(120, 0.5, [0.0; 3], 11);
    let pyr = prepare(&pts, &cfg).unwrap();
    let x = pyr.input_features(InputFeatures::OnesXyz).unwrap();
    assert_eq!(x.dims(), &[120, 4]);
    for (i, p) in pts.iter().enumerate() {
        assert_eq!(x.row(i), &[1.0, p[0], p[1], p[2]]);
    }
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    assert_eq!(ps.num_trainable(), cfg.param_count());
    assert_eq!(cfg.param_count(), kpc::tiny_config().param_count() + 3 * 15 * 4);
    let out = run(&cfg, &mut ps, &net, &pyr, true);
    assert_eq!(out.dims(), &[120, cfg.out_dim]);
}

#[test]
fn precomputed_geometries_give_the_same_features() {
    let cfg = kpc::tiny_config();
    let pts = kpc::sphere_cloud(200, 0.6, [0.0; 3], 12);
    let pyr = prepare(&pts, &cfg).unwrap();
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    let geoms = net.geometries(&pyr).unwrap();
    assert_eq!(geoms.len(), cfg.kpconv_layers().len());
    let a = run(&cfg, &mut ps, &net, &pyr, true);
    let mut g = Graph::train(&mut ps);
    let out = net.forward_with(&mut g, &pyr, &geoms).unwrap();
    assert_eq!(g.value(out).data(), a.data());
    assert!(net.forward_with(&mut g, &pyr, &geoms[1..]).is_err());
    let other = prepare(&kpc::sphere_cloud(150, 0.6, [0.0; 3], 13), &cfg).unwrap();
    assert!(net.forward_with(&mut g, &other, &geoms).is_err());
}

/// With `spacing_cells` the pyramid does not depend on the cloud's scale: a cloud scaled
/// by a power of two (exact in floating point) gives the bit-identical pyramid and
/// features. Without it the same scaling changes the pyramid (so this test can fail).
#[test]
fn spacing_cells_make_the_pyramid_independent_of_the_cloud_scale() {
    let pts = kpc::sphere_cloud(400, 0.6, [0.1, -0.2, 0.05], 7);
    let scaled = |c: f32| pts.iter().map(|p| [p[0] * c, p[1] * c, p[2] * c]).collect::<Vec<_>>();
    let spaced = KpfcnnConfig { spacing_cells: 1.5, ..kpc::tiny_config() };
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&spaced, &mut ps).unwrap();
    let base = prepare(&pts, &spaced).unwrap();
    let want = run(&spaced, &mut ps, &net, &base, false);
    for c in [0.25f32, 8.0, 1024.0] {
        let pyr = prepare(&scaled(c), &spaced).unwrap();
        assert_eq!(pyr.points, base.points, "scale {c}: points");
        assert_eq!(pyr.cells, base.cells, "scale {c}: cells");
        for l in 0..base.num_levels() {
            let rows = |p: &PointPyramid| {
                (0..p.conv[l].n_queries).map(|q| p.conv[l].row(q).to_vec()).collect::<Vec<_>>()
            };
            assert_eq!(rows(&pyr), rows(&base), "scale {c}: level {l} neighbourhoods");
        }
        assert_eq!(pyr.upsample, base.upsample, "scale {c}: upsampling");
        let got = run(&spaced, &mut ps, &net, &pyr, false);
        assert_eq!(got.data(), want.data(), "scale {c}: features");
    }
    // Level 0's median spacing is spacing_cells × first_cell after the scaling.
    let d = point2quad::nn::kpfcnn::median_spacing(&base.points[0]).unwrap();
    assert!((d / (1.5 * spaced.first_cell) - 1.0).abs() < 1e-5, "median spacing {d}");
    // The plain config sees a different pyramid at another scale.
    let plain = kpc::tiny_config();
    let (a, b) = (prepare(&pts, &plain).unwrap(), prepare(&scaled(8.0), &plain).unwrap());
    assert_ne!(a.points[1].len(), b.points[1].len(), "the plain pyramid should depend on scale");
}

/// With `input_cell`, level 0 is the cloud grid-subsampled: one barycentre per voxel of
/// `input_cell × first_cell` (brute force here), and each input point reads its voxel's
/// row. A cloud with every point twice gives each copy the row the cloud alone gives
/// that point, bit for bit (the same voxels and barycentres), in eval and train mode;
/// the features differ from those with the raw cloud as level 0 (the check can fail).
#[test]
fn input_cell_reads_each_points_voxel() {
    use point2quad::spatial::subsample::voxel_key;
    let cfg = KpfcnnConfig { input_cell: 0.5, ..kpc::tiny_config() };
    let cell = 0.5 * cfg.first_cell;
    // Points close enough together that voxels hold several.
    let pts = kpc::sphere_cloud(1500, 0.6, [0.1, -0.2, 0.05], 4);
    let pyr = prepare(&pts, &cfg).unwrap();
    let voxel = pyr.input_voxel.clone().expect("input_cell sets the voxel table");
    assert_eq!((voxel.len(), pyr.num_inputs()), (pts.len(), pts.len()));
    let mut groups: std::collections::HashMap<[i64; 3], Vec<usize>> = Default::default();
    for (i, &p) in pts.iter().enumerate() {
        groups.entry(voxel_key(p, cell)).or_default().push(i);
    }
    assert_eq!(pyr.points[0].len(), groups.len());
    assert!(groups.len() < pts.len() * 9 / 10, "too few shared voxels to test: {}", groups.len());
    for members in groups.values() {
        let mut c = [0.0f64; 3];
        for &i in members {
            (0..3).for_each(|d| c[d] += pts[i][d] as f64);
        }
        let want = c.map(|x| (x / members.len() as f64) as f32);
        for &i in members {
            assert_eq!(pyr.points[0][voxel[i] as usize], want, "point {i}");
        }
    }
    // Levels above 0 are the plain pyramid of level 0.
    let plain = prepare(&pyr.points[0], &kpc::tiny_config()).unwrap();
    assert_eq!(plain.points, pyr.points);
    let twice: Vec<[f32; 3]> = pts.iter().chain(&pts).copied().collect();
    let mut ps = ParamStore::new();
    let net = Kpfcnn::new(&cfg, &mut ps).unwrap();
    for train in [false, true] {
        let once = run(&cfg, &mut ps, &net, &pyr, train);
        let both = run(&cfg, &mut ps, &net, &prepare(&twice, &cfg).unwrap(), train);
        for i in 0..pts.len() {
            assert_eq!(both.row(i), once.row(i), "train {train}, point {i}");
            assert_eq!(both.row(i + pts.len()), once.row(i), "train {train}, copy of point {i}");
        }
        let raw =
            run(&kpc::tiny_config(), &mut ps, &net, &prepare(&pts, &kpc::tiny_config()).unwrap(), train);
        assert!(raw.data().iter().zip(once.data()).any(|(a, b)| (a - b).abs() > 1e-3));
    }
}

/// What `input_cell` is for: on a dense patch, level 0's neighbourhoods hold at most the
/// voxels within the convolution radius ((2 · 2.5 / 0.5 + 1)² = 121 for a flat patch),
/// where the raw cloud's grow with the density.
#[test]
fn input_cell_bounds_level_zero_neighbourhoods() {
    let n = 60;
    let pts: Vec<[f32; 3]> =
        (0..n * n).map(|i| [(i % n) as f32 / n as f32, (i / n) as f32 / n as f32, 0.0]).collect();
    let raw = prepare(&pts, &kpc::tiny_config()).unwrap();
    let voxels = prepare(&pts, &KpfcnnConfig { input_cell: 0.5, ..kpc::tiny_config() }).unwrap();
    assert!(raw.conv[0].cap > 400, "raw level-0 cap {}", raw.conv[0].cap);
    assert!(voxels.conv[0].cap <= 121, "level-0 cap with input_cell {}", voxels.conv[0].cap);
    assert!(voxels.pool[0].cap <= 121, "pooling cap with input_cell {}", voxels.pool[0].cap);
}

/// Gradients through the voxel read (a gather whose backward adds the rows of points
/// sharing a voxel): the piecewise-linear check above on a cloud with every point twice.
#[test]
fn input_cell_kpfcnn_gradcheck_piecewise_linear() {
    let cfg = KpfcnnConfig {
        first_features_dim: 8,
        out_dim: 3,
        leaky_slope: 1.0,
        input_cell: 0.5,
        ..kpc::tiny_config()
    };
    let pts = kpc::sphere_cloud(90, 0.5, [0.0; 3], 1);
    let twice: Vec<[f32; 3]> = pts.iter().chain(&pts).copied().collect();
    let pyr = prepare(&twice, &cfg).unwrap();
    assert_eq!((pyr.points[0].len(), pyr.num_inputs()), (90, 180));
    check_grads(&cfg, &pyr, &piecewise_linear(), 300);
}

/// `median_spacing` equals a brute-force median of each point's nearest distinct
/// neighbour, on clouds with duplicated points (up to 3 copies) and a lone all-identical cloud.
#[test]
fn median_spacing_equals_brute_force() {
    use point2quad::nn::kpfcnn::median_spacing;
    for seed in 0..20u64 {
        let mut rng = point2quad::rng::Rng::new(seed);
        let n = 2 + (rng.next_u64() % 200) as usize;
        let mut pts: Vec<[f32; 3]> = (0..n)
            .map(|_| {
                [rng.uniform(-1.0, 1.0) as f32, rng.uniform(-1.0, 1.0) as f32, rng.uniform(-0.1, 0.1) as f32]
            })
            .collect();
        for i in 0..n / 4 {
            let copies = 1 + (rng.next_u64() % 2) as usize;
            for _ in 0..copies {
                pts.push(pts[i]);
            }
        }
        let mut nearest: Vec<f32> = pts
            .iter()
            .map(|p| {
                pts.iter()
                    .map(|q| (0..3).map(|d| (p[d] - q[d]) * (p[d] - q[d])).sum::<f32>())
                    .filter(|&d2| d2 > 0.0)
                    .fold(f32::INFINITY, f32::min)
            })
            .filter(|d2| d2.is_finite())
            .collect();
        nearest.sort_by(f32::total_cmp);
        let want = nearest[nearest.len() / 2].sqrt();
        let got = median_spacing(&pts).expect("distinct points");
        assert!((got - want).abs() <= 1e-6 * want, "seed {seed}: {got} vs brute force {want}");
    }
    assert_eq!(median_spacing(&[[1.0, 2.0, 3.0]; 5]), None);
    assert_eq!(median_spacing(&[[0.0; 3], [f32::NAN, 0.0, 0.0]]), None);
}
