//! Library-level fuzzing of what the CLI exposes: metrics and pictures of face soups
//! with NaN/inf/extreme coordinates never panic and never produce a NaN; shape and
//! accuracy measures are the same at any scale (down to 1e±300); the readers never
//! panic on token soups or on damaged samples whose checksum was recomputed to get
//! past it. References: brute-force edge counts, the unscaled measurement, and the
//! encoder (a sample that reads must encode back to the same bytes).

#[path = "common/io.rs"]
mod io_common;
#[path = "common/quality.rs"]
mod quality_common;
#[path = "common/robust.rs"]
mod robust_common;

use std::collections::HashMap;

use point2quad::io::mesh_io::{parse_mesh, MeshFormat};
use point2quad::io::points::{parse_points, PointFormat};
use point2quad::io::svg::{render_svg, RenderOptions};
use point2quad::mesh::poly::PolyMesh;
use point2quad::mesh::quality::{compare, mesh_metrics, quad_shape};
use point2quad::nn::checkpoint::{fnv1a64, Checkpoint, TrainState};
use point2quad::pipeline::dataset::{encode_sample, read_sample, Sample};
use point2quad::tensor::Tensor;
use proptest::prelude::*;
use quality_common::{check_xml, grid};
use robust_common::{token_file, wild_coord, wild_soup};

/// Undirected edge valences by brute force (sides whose ends coincide are not edges).
fn brute_edges(m: &PolyMesh) -> HashMap<(u32, u32), usize> {
    let mut e = HashMap::new();
    for f in &m.faces {
        for i in 0..f.len() {
            let (a, b) = (f[i], f[(i + 1) % f.len()]);
            if a != b {
                *e.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
    }
    e
}

/// Faces the renderer can draw: at least 3 indices, all in range and finite.
fn drawable(m: &PolyMesh) -> usize {
    m.faces
        .iter()
        .filter(|f| {
            f.len() >= 3
                && f.iter()
                    .all(|&v| m.vertices.get(v as usize).is_some_and(|p| p.iter().all(|c| c.is_finite())))
        })
        .count()
}

/// FNV-1a 64, the `.p2qs` checksum (written here from the published constants).
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn reseal(bytes: &mut [u8]) {
    let end = bytes.len() - 8;
    let h = fnv1a(&bytes[..end]);
    bytes[end..].copy_from_slice(&h.to_le_bytes());
}

fn small_sample() -> impl Strategy<Value = Sample> {
    (1usize..8, 0usize..5, 0u32..4, "[a-z]{0,6}").prop_flat_map(|(n, m, d, name)| {
        (
            prop::collection::vec(prop::array::uniform3(-2.0f32..2.0), n),
            0..=n as u32,
            prop::collection::vec(prop::array::uniform4(0..n as u32), m),
            prop::collection::vec(-1.0f32..1.0, m * d as usize),
            prop::collection::vec(0u8..2, m),
        )
            .prop_map(move |(points, nmv, candidates, features, labels)| {
                let gt_faces = if nmv > 0 { vec![[0, nmv - 1, 0, nmv - 1]] } else { vec![] };
                Sample {
                    name: name.clone(),
                    points,
                    n_mesh_vertices: nmv,
                    gt_faces,
                    candidates,
                    features,
                    feature_dim: d,
                    labels,
                }
            })
    })
}

/// A quad far from degenerate (so that rounding cannot move its measures much).
fn sturdy_quad() -> impl Strategy<Value = [[f64; 3]; 4]> {
    prop::array::uniform4(prop::array::uniform3(-3.0f64..3.0)).prop_filter("well shaped", |p| {
        let s = quad_shape(p);
        s.scaled_jacobian.abs() > 0.1 && s.edge_ratio.is_some_and(|r| r < 20.0)
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Metrics of any soup: finite, in range, and edge counts equal to brute force.
    #[test]
    fn metrics_of_wild_soups_are_finite_and_count_edges_exactly(m in wild_soup()) {
        let mm = mesh_metrics(&m);
        let reals = [
            mm.watertightness, mm.manifoldness, mm.scaled_jacobian, mm.scaled_jacobian_min,
            mm.edge_ratio, mm.angle_dev_deg, mm.angle_rms_deg,
        ];
        prop_assert!(reals.iter().all(|x| x.is_finite()), "{:?}", mm);
        let e = brute_edges(&m);
        prop_assert_eq!(mm.edges, e.len());
        prop_assert_eq!(mm.boundary_edges, e.values().filter(|&&c| c == 1).count());
        prop_assert_eq!(mm.nonmanifold_edges, e.values().filter(|&&c| c > 2).count());
        prop_assert!((0.0..=1.0).contains(&mm.watertightness) && (0.0..=1.0).contains(&mm.manifoldness));
        prop_assert!((-1.0..=1.0).contains(&mm.scaled_jacobian) && mm.scaled_jacobian_min <= mm.scaled_jacobian);
        prop_assert!(mm.edge_ratio == 0.0 || mm.edge_ratio >= 1.0);
        // RMS ≥ mean of absolute values (Cauchy–Schwarz), up to rounding.
        prop_assert!(mm.angle_rms_deg >= mm.angle_dev_deg * (1.0 - 1e-12));
        prop_assert_eq!(mm.quads, m.faces.iter().filter(|f| f.len() == 4).count());
    }

    /// Pictures of any soup: well-formed, no NaN or inf, one polygon per drawable face.
    #[test]
    fn svg_of_wild_soups_has_no_nan(m in wild_soup(), az in wild_coord(), el in wild_coord(), z_up in any::<bool>()) {
        let opts = RenderOptions { azimuth_deg: az, elevation_deg: el, z_up, ..Default::default() };
        let svg = render_svg(&m, &opts);
        prop_assert!(check_xml(&svg).is_ok(), "{:?}", check_xml(&svg));
        prop_assert!(!svg.contains("NaN") && !svg.contains("inf"), "{}", svg);
        prop_assert_eq!(svg.matches("<polygon").count(), drawable(&m));
    }

    /// Regression: a mesh at 1e300 overflowed in the projection and the normals
    /// (`height="NaN"`, wrong shading). The picture is fitted to the mesh and scaling
    /// by a power of two is exact, so it must be the very same picture.
    #[test]
    fn svg_is_the_same_picture_at_any_scale(
        pts in prop::collection::vec(prop::array::uniform3(-3.0f64..3.0), 3..10),
        raw in prop::collection::vec(prop::collection::vec(0u32..10, 3..6), 1..8),
        k in prop::sample::select(vec![-900i32, -500, 500, 900, 1020]),
    ) {
        let n = pts.len() as u32;
        let m = PolyMesh { vertices: pts, faces: raw.iter().map(|f| f.iter().map(|v| v % n).collect()).collect() };
        let s = 2f64.powi(k);
        let scaled = PolyMesh { vertices: m.vertices.iter().map(|p| p.map(|c| c * s)).collect(), faces: m.faces.clone() };
        let opts = RenderOptions::default();
        prop_assert_eq!(render_svg(&scaled, &opts), render_svg(&m, &opts));
    }

    /// Regression: squared lengths overflowed (1e300) or underflowed (1e-300), and a
    /// perfectly good quad was called degenerate. Scaling by a power of two is exact,
    /// so the measures must agree with the unscaled ones.
    #[test]
    fn quad_measures_do_not_depend_on_scale(p in sturdy_quad(), k in prop::sample::select(vec![-1000i32, -700, -300, 300, 700, 1000])) {
        let s = 2f64.powi(k);
        let q = p.map(|v| v.map(|c| c * s));
        let (a, b) = (quad_shape(&p), quad_shape(&q));
        prop_assert!((a.scaled_jacobian - b.scaled_jacobian).abs() < 1e-9, "{:?} vs {:?}", a, b);
        let (ra, rb) = (a.edge_ratio.unwrap_or(0.0), b.edge_ratio.unwrap_or(-1.0));
        prop_assert!((ra - rb).abs() < 1e-9 * ra, "{:?} vs {:?}", a, b);
        let (aa, ab) = (a.angles_deg.unwrap_or([0.0; 4]), b.angles_deg.unwrap_or([-1.0; 4]));
        for i in 0..4 {
            prop_assert!((aa[i] - ab[i]).abs() < 1e-7, "{:?} vs {:?}", aa, ab);
        }
    }

    /// Readers on token soups: never a panic; whatever parses is a sane mesh.
    #[test]
    fn parsers_survive_token_soups(bytes in token_file()) {
        for f in [MeshFormat::Obj, MeshFormat::Off, MeshFormat::Ply] {
            if let Ok(m) = parse_mesh(&bytes, f, "soup") {
                prop_assert!(io_common::check_sane(&m).is_ok(), "{:?}", io_common::check_sane(&m));
            }
        }
        for f in [PointFormat::Xyz, PointFormat::Obj, PointFormat::Off, PointFormat::Ply] {
            if let Ok(p) = parse_points(&bytes, f, "soup") {
                prop_assert!(!p.is_empty() && p.iter().flatten().all(|c| c.is_finite()));
            } else if let Err(e) = parse_points(&bytes, f, "soup") {
                prop_assert!(e.to_string().contains("soup"), "{}", e);
            }
        }
    }

    /// Samples damaged anywhere, checksum recomputed: never a panic; an error names
    /// the source; a sample that reads encodes back to exactly the same bytes.
    #[test]
    fn read_sample_survives_resealed_damage(
        s in small_sample(),
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        let mut bytes = encode_sample(&s).expect("test: valid sample encodes");
        prop_assert_eq!(&read_sample(&bytes, "orig").expect("test: reads back"), &s);
        let body = bytes.len() - 8;
        for (at, x) in &flips {
            bytes[at.index(body)] ^= x | 1;
        }
        reseal(&mut bytes);
        match read_sample(&bytes, "dmg.p2qs") {
            Ok(back) => prop_assert_eq!(encode_sample(&back).expect("test: re-encode"), bytes),
            Err(e) => prop_assert!(e.to_string().contains("dmg.p2qs"), "{}", e),
        }
    }

    /// Random bytes behind a valid magic and version: never a panic.
    #[test]
    fn read_sample_survives_random_bytes(tail in prop::collection::vec(any::<u8>(), 0..200), seal in any::<bool>()) {
        let mut bytes = b"P2QS".to_vec();
        bytes.extend_from_slice(&1u32.to_le_bytes());
        bytes.extend_from_slice(&tail);
        if seal && bytes.len() >= 16 {
            reseal(&mut bytes);
        }
        if let Err(e) = read_sample(&bytes, "rnd") {
            prop_assert!(e.to_string().contains("rnd"), "{}", e);
        }
    }
}

fn small_checkpoint(seed: u64) -> Checkpoint {
    let mut rng = point2quad::rng::Rng::new(seed);
    let t = |dims: &[usize], rng: &mut point2quad::rng::Rng| {
        let n = dims.iter().product();
        Tensor::new(dims, (0..n).map(|_| rng.f32()).collect()).expect("test: tensor")
    };
    let tensors = vec![("a.w".to_string(), t(&[2, 3], &mut rng)), ("b".to_string(), t(&[4], &mut rng))];
    let train = (seed % 2 == 0).then(|| TrainState {
        epoch: 3,
        step: 17,
        rng: [1, 2, 3, 4],
        momentum: vec![("a.w".to_string(), t(&[2, 3], &mut rng))],
        // Seed 2 also stores a run record (flag 2).
        run: if seed == 2 { vec![("lr".to_string(), "0.01".to_string())] } else { Vec::new() },
    });
    Checkpoint { config: b"cfg".to_vec(), tensors, train }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Weights damaged anywhere, with the length and checksum made right again so the
    /// parser itself is reached: never a panic, and an error names the file. (A flip
    /// in the reserved header word still loads, so no byte-exact round trip here.)
    #[test]
    fn checkpoint_survives_resealed_damage(
        seed in 0u64..4,
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
        cut in any::<prop::sample::Index>(),
        truncate in any::<bool>(),
    ) {
        let path = std::path::Path::new("dmg.ckpt");
        let mut bytes = small_checkpoint(seed).to_bytes();
        prop_assert_eq!(&Checkpoint::from_bytes(&bytes, path).expect("test: reads back"), &small_checkpoint(seed));
        let body = bytes.len() - 8;
        for (at, x) in &flips {
            let i = 24 + at.index(body - 24);
            bytes[i] ^= x | 1;
        }
        if truncate {
            bytes.truncate(24 + 8 + cut.index(bytes.len() - 32));
        }
        let n = bytes.len();
        bytes[16..24].copy_from_slice(&(n as u64).to_le_bytes());
        let h = fnv1a64(&bytes[..n - 8]);
        bytes[n - 8..].copy_from_slice(&h.to_le_bytes());
        if let Err(e) = Checkpoint::from_bytes(&bytes, path) {
            prop_assert!(e.to_string().contains("dmg.ckpt"), "{}", e);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// Regression: a ground truth at 1e±270 had an overflowing (or vanishing)
    /// bounding-box diagonal, so `compare` refused it. Power-of-two scaling is exact,
    /// and everything works in the ground truth's normalised frame, so precision and
    /// recall must be equal and the Chamfer distance equal to rounding.
    #[test]
    fn compare_does_not_depend_on_scale(
        keep in prop::collection::vec(any::<bool>(), 12),
        k in prop::sample::select(vec![-900i32, -300, 300, 900]),
        seed in 0u64..100,
    ) {
        let gt = grid(4, 3);
        let mut pred = gt.clone();
        pred.faces = gt.faces.iter().zip(&keep).filter(|(_, k)| **k).map(|(f, _)| f.clone()).collect();
        prop_assume!(!pred.faces.is_empty());
        let s = 2f64.powi(k);
        let scale = |m: &PolyMesh| PolyMesh { vertices: m.vertices.iter().map(|p| p.map(|c| c * s)).collect(), faces: m.faces.clone() };
        let a = compare(&pred, &gt, seed).expect("test: unscaled compare");
        let b = compare(&scale(&pred), &scale(&gt), seed).expect("scaled compare must work");
        prop_assert_eq!((a.precision, a.recall, a.matched_vertices), (b.precision, b.recall, b.matched_vertices));
        let (ca, cb) = (a.chamfer.expect("test: chamfer defined"), b.chamfer.expect("test: chamfer defined"));
        prop_assert!((ca - cb).abs() <= 1e-12 * ca.max(1e-12), "{} vs {}", ca, cb);
    }
}

/// Session 37's audit: a ground truth spanning ±1.7e308 was refused by `compare` (its
/// bounding-box diagonal overflows, though every coordinate and half the diagonal are
/// finite). A centred grid scaled by 2^1021 and 2^1022 (exact) scores as the unit grid:
/// the same precision, recall and matches, the Chamfer distance equal to rounding.
#[test]
fn compare_takes_a_ground_truth_as_wide_as_f64_allows() {
    let mut gt = grid(4, 3);
    let n = gt.vertices.len() as f64;
    let c: [f64; 3] = std::array::from_fn(|k| gt.vertices.iter().map(|p| p[k]).sum::<f64>() / n);
    for p in &mut gt.vertices {
        *p = std::array::from_fn(|k| p[k] - c[k]);
    }
    let mut pred = gt.clone();
    pred.faces.truncate(gt.faces.len() - 2);
    let a = compare(&pred, &gt, 3).expect("test: unit compare");
    for k in [1021, 1022] {
        let s = 2f64.powi(k);
        let scale = |m: &PolyMesh| PolyMesh {
            vertices: m.vertices.iter().map(|p| p.map(|c| c * s)).collect(),
            faces: m.faces.clone(),
        };
        let wide = scale(&gt);
        assert!(wide.vertices.iter().flatten().all(|c| c.is_finite()), "2^{k}: the test's grid overflows");
        let b = compare(&scale(&pred), &wide, 3).unwrap_or_else(|e| panic!("2^{k}: {e}"));
        assert_eq!(
            (a.precision, a.recall, a.matched_vertices),
            (b.precision, b.recall, b.matched_vertices),
            "2^{k}"
        );
        let (ca, cb) = (a.chamfer.expect("test: chamfer"), b.chamfer.expect("test: chamfer"));
        assert!((ca - cb).abs() <= 1e-12 * ca.max(1e-12), "2^{k}: {ca} vs {cb}");
    }
}
