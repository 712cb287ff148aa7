//! Property tests of the synthetic shape generators (`mesh::shapes`): every family over
//! many seeds and sizes passes the invariant checker of `tests/common/shapes.rs`, with the
//! expected Euler characteristic and outward orientation; Catmull–Clark keeps χ and quads.

#[path = "common/shapes.rs"]
mod common_shapes;

use common_shapes::{bbox_diag, check_quad_mesh, signed_volume};
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes::{self, Family, VoxelSet};
use point2quad::rng::Rng;
use proptest::prelude::*;

fn closed_outward(m: &QuadMesh, chi: i64) {
    let s = check_quad_mesh(m);
    assert_eq!(s.boundary_edges, 0, "closed mesh has boundary");
    assert_eq!(s.components, 1);
    assert_eq!(s.euler(), chi, "{s:?}");
    assert!(signed_volume(m) > 0.0, "volume {}", signed_volume(m));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn grids_and_height_fields_are_open_disks(nu in 1usize..20, nv in 1usize..20, su in 0.01f64..100.0, sv in 0.01f64..100.0, a in -2.0f64..2.0) {
        for m in [shapes::grid(nu, nv, su, sv), shapes::height_field(nu, nv, |x, y| a * (x * 3.0).sin() * y)] {
            let s = check_quad_mesh(&m);
            prop_assert_eq!(s.euler(), 1);
            prop_assert_eq!((s.vertices, s.faces), ((nu + 1) * (nv + 1), nu * nv));
            prop_assert_eq!(s.boundary_edges, 2 * (nu + nv));
            prop_assert_eq!(s.components, 1);
            // Normals towards +z: the projected signed area of each quad is positive.
            for q in &m.quads {
                let p = q.map(|v| m.vertices[v as usize]);
                let area2: f64 = (0..4).map(|k| p[k][0] * p[(k + 1) % 4][1] - p[(k + 1) % 4][0] * p[k][1]).sum();
                prop_assert!(area2 > 0.0);
            }
        }
    }

    #[test]
    fn cubes_and_cube_spheres_are_spheres(n in 1usize..14) {
        let c = shapes::cube(n);
        closed_outward(&c, 2);
        prop_assert_eq!(c.vertices.len(), 6 * n * n + 2);
        let s = shapes::cube_sphere(n);
        closed_outward(&s, 2);
        for v in &s.vertices {
            prop_assert!(((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn tori_have_euler_zero(nu in 3usize..40, nv in 3usize..30, minor in 0.05f64..0.95) {
        let t = shapes::torus(nu, nv, 1.0, minor);
        closed_outward(&t, 0);
        prop_assert_eq!(t.vertices.len(), nu * nv);
    }

    #[test]
    fn cylinders_open_and_capped(nu in 3usize..40, nv in 1usize..20, r in 0.1f64..10.0, h in 0.1f64..10.0) {
        let tube = shapes::cylinder(nu, nv, r, h, false);
        let s = check_quad_mesh(&tube);
        prop_assert_eq!(s.euler(), 0);
        prop_assert_eq!(s.boundary_edges, 2 * nu);
        let capped = shapes::cylinder(nu, nv, r, h, true);
        closed_outward(&capped, 2);
        // The caps are flat disks at z = 0 and z = h.
        prop_assert!(capped.vertices.iter().all(|v| v[2] >= -1e-12 && v[2] <= h + 1e-12));
        // Flat caps on the inscribed polygon (nu rounded up to a multiple of 4): a prism.
        let n4 = nu.div_ceil(4) * 4;
        let vol = 0.5 * n4 as f64 * r * r * (std::f64::consts::TAU / n4 as f64).sin() * h;
        prop_assert!((signed_volume(&capped) - vol).abs() < 1e-9 * vol, "{} vs {}", signed_volume(&capped), vol);
    }

    #[test]
    fn voxel_cages_are_closed_manifolds(seed in 0u64..1_000_000, dx in 1usize..7, dy in 1usize..7, dz in 1usize..5, fill in 0.05f64..1.0) {
        let mut rng = Rng::new(seed);
        let cage = shapes::voxel_cage(&mut rng, [dx, dy, dz], fill);
        let s = check_quad_mesh(&cage);
        prop_assert_eq!(s.boundary_edges, 0);
        prop_assert_eq!(s.components, 1);
        // One closed orientable surface: χ = 2 − 2g with g ≥ 0.
        let chi = s.euler();
        prop_assert!(chi <= 2 && chi % 2 == 0, "chi {}", chi);
        // Outward: the enclosed volume is the (positive, integer) number of voxels.
        let vol = signed_volume(&cage);
        prop_assert!(vol >= 1.0 - 1e-9 && (vol - vol.round()).abs() < 1e-9);
        for sharp in [false, true] {
            let cc = shapes::catmull_clark(&cage, 2, sharp);
            let t = check_quad_mesh(&cc);
            prop_assert_eq!(t.euler(), chi);
            prop_assert_eq!((t.faces, t.boundary_edges, t.components), (16 * s.faces, 0, 1));
            prop_assert!(signed_volume(&cc) > 0.0);
        }
    }

    #[test]
    fn catmull_clark_on_open_meshes(nu in 1usize..8, nv in 1usize..8, levels in 0usize..3) {
        for m in [shapes::grid(nu, nv, 1.0, 2.0), shapes::cylinder(nu + 3, nv, 1.0, 1.0, false)] {
            let s = check_quad_mesh(&m);
            let cc = shapes::catmull_clark(&m, levels, false);
            let t = check_quad_mesh(&cc);
            prop_assert_eq!(t.euler(), s.euler());
            prop_assert_eq!(t.faces, s.faces * 4usize.pow(levels as u32));
            prop_assert_eq!(t.boundary_edges, s.boundary_edges * 2usize.pow(levels as u32));
        }
    }

    #[test]
    fn random_shapes_are_valid(seed in 0u64..1_000_000) {
        let mut rng = Rng::new(seed);
        for family in Family::ALL {
            let m = shapes::random_shape_of(family, &mut rng);
            let s = check_quad_mesh(&m);
            prop_assert!((200..=5200).contains(&s.vertices), "{:?}: {} vertices", family, s.vertices);
            prop_assert_eq!(s.components, 1);
            if family.is_closed() {
                prop_assert_eq!(s.boundary_edges, 0, "{:?}", family);
                prop_assert!(signed_volume(&m) > 0.0, "{:?} inward", family);
            } else {
                prop_assert!(s.boundary_edges > 0);
            }
            let expected = match family {
                Family::Grid | Family::HeightField => Some(1),
                Family::Tube | Family::Torus => Some(0),
                Family::Cube | Family::CubeSphere | Family::Cylinder => Some(2),
                Family::CageSmooth | Family::CageSharp => None,
            };
            if let Some(chi) = expected {
                prop_assert_eq!(s.euler(), chi, "{:?}", family);
            }
        }
    }
}

#[test]
fn voxel_frame_with_two_holes_has_genus_two() {
    let mut set = VoxelSet::new([5, 3, 1]);
    for x in 0..5 {
        for y in 0..3 {
            if !(y == 1 && (x == 1 || x == 3)) {
                set.set([x, y, 0]);
            }
        }
    }
    assert_eq!(shapes::repair_voxels(&mut set), 0);
    let m = shapes::voxel_boundary(&set);
    closed_outward(&m, -2);
    assert!((signed_volume(&m) - 13.0).abs() < 1e-9);
}

#[test]
fn touching_voxels_are_repaired_to_a_manifold() {
    // Two voxels sharing an edge, two sharing a corner: both must be repaired.
    for pair in [[[0, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 1]]] {
        let mut set = VoxelSet::new([2, 2, 2]);
        set.set(pair[0]);
        set.set(pair[1]);
        assert!(shapes::repair_voxels(&mut set) > 0);
        closed_outward(&shapes::voxel_boundary(&set), 2);
    }
}

#[test]
fn random_cages_reach_higher_genus() {
    // Across seeds the generator must produce tunnels, not only spheres.
    let mut rng = Rng::new(5);
    let mut genera = std::collections::BTreeSet::new();
    for _ in 0..60 {
        let m = shapes::voxel_cage(&mut rng, [6, 6, 3], 0.5);
        genera.insert((2 - check_quad_mesh(&m).euler()) / 2);
    }
    assert!(genera.len() >= 3 && genera.iter().any(|&g| g >= 2), "genera seen: {genera:?}");
}

#[test]
fn sharp_subdivision_keeps_cube_edges_straight() {
    // Creased CC of a cube: points on the crease lines stay on the cube's edges; smooth
    // CC pulls the corners inwards.
    let c = shapes::cube(1);
    let sharp = shapes::catmull_clark(&c, 3, true);
    check_quad_mesh(&sharp);
    assert!(sharp.vertices.iter().any(|v| v.iter().all(|x| (x.abs() - 1.0).abs() < 1e-12)));
    let smooth = shapes::catmull_clark(&c, 3, false);
    assert!(smooth.vertices.iter().all(|v| v.iter().filter(|x| (x.abs() - 1.0).abs() < 1e-12).count() < 3));
}

#[test]
fn random_pose_is_a_similarity() {
    let mut rng = Rng::new(9);
    let m = shapes::torus(12, 6, 2.0, 0.7);
    for _ in 0..20 {
        let p = shapes::random_pose(&m, &mut rng);
        let ratio = bbox_diag(&p) / bbox_diag(&m);
        // Distances scale by one factor; orientation (volume sign) preserved.
        let d0 = |mm: &QuadMesh, a: usize, b: usize| {
            let (x, y) = (mm.vertices[a], mm.vertices[b]);
            ((0..3).map(|k| (x[k] - y[k]).powi(2)).sum::<f64>()).sqrt()
        };
        let s = d0(&p, 0, 1) / d0(&m, 0, 1);
        assert!((d0(&p, 3, 40) / d0(&m, 3, 40) - s).abs() < 1e-9 * s);
        assert!(ratio > 0.0 && signed_volume(&p) > 0.0);
        check_quad_mesh(&p);
    }
}

#[test]
fn random_shape_is_deterministic_and_covers_elongated_quads() {
    let a = shapes::random_shape(&mut Rng::new(3));
    let b = shapes::random_shape(&mut Rng::new(3));
    assert_eq!(a, b);
    let mut rng = Rng::new(1);
    let mut min_ratio = 1.0f64;
    for _ in 0..30 {
        let m = shapes::random_shape(&mut rng);
        for q in &m.quads {
            let p = q.map(|v| m.vertices[v as usize]);
            let l: Vec<f64> = (0..4)
                .map(|k| ((0..3).map(|c| (p[k][c] - p[(k + 1) % 4][c]).powi(2)).sum::<f64>()).sqrt())
                .collect();
            let r = l.iter().cloned().fold(f64::INFINITY, f64::min) / l.iter().cloned().fold(0.0, f64::max);
            min_ratio = min_ratio.min(r);
        }
    }
    assert!(min_ratio < 0.4, "no elongated quads: min edge ratio {min_ratio}");
}

/// Brute-force reference for the shape modifiers: per vertex, the sum of its quads'
/// diagonal cross products (p2 − p0) × (p3 − p1) and its shortest incident edge; and the
/// mean edge length over all quad sides.
fn reference_vertex_frames(m: &QuadMesh) -> (Vec<[f64; 3]>, Vec<f64>, f64) {
    let n = m.vertices.len();
    let mut shortest = vec![f64::INFINITY; n];
    let mut normal = vec![[0.0f64; 3]; n];
    let (mut total, mut count) = (0.0, 0.0);
    for q in &m.quads {
        let p = q.map(|i| m.vertices[i as usize]);
        let d1 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
        let d2 = [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]];
        let c = [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]];
        for k in 0..4 {
            let (a, b) = (p[k], p[(k + 1) % 4]);
            let l = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            let (v, w) = (q[k] as usize, q[(k + 1) % 4] as usize);
            shortest[v] = shortest[v].min(l);
            shortest[w] = shortest[w].min(l);
            for a in 0..3 {
                normal[v][a] += c[a];
            }
            total += l;
            count += 1.0;
        }
    }
    (normal, shortest, total / count)
}

/// Scaled Jacobian of face `f` of `m` (the metric code's definition).
fn face_sj(m: &QuadMesh, f: usize) -> f64 {
    let q = m.quads[f];
    point2quad::mesh::quality::quad_shape(&q.map(|i| m.vertices[i as usize])).scaled_jacobian
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// `irregularize` against its contract, checked independently: connectivity kept,
    /// every move tangential and within amount × the vertex's shortest original edge,
    /// no face below min(min_sj, its original scaled Jacobian), and still a valid mesh.
    #[test]
    fn irregularize_keeps_connectivity_and_shape_bounds(seed in 0u64..1_000_000, amount in 0.0f64..0.5, min_sj in 0.2f64..0.8) {
        let mut rng = Rng::new(seed);
        let m = shapes::random_shape(&mut rng);
        let before = check_quad_mesh(&m);
        let j = shapes::irregularize(&m, amount, min_sj, &mut rng);
        prop_assert_eq!(&j.quads, &m.quads);
        prop_assert_eq!(j.vertices.len(), m.vertices.len());
        let after = check_quad_mesh(&j);
        prop_assert_eq!((after.euler(), after.boundary_edges, after.components), (before.euler(), before.boundary_edges, before.components));
        let (normal, shortest, _) = reference_vertex_frames(&m);
        let n = m.vertices.len();
        for v in 0..n {
            let d: Vec<f64> = (0..3).map(|a| j.vertices[v][a] - m.vertices[v][a]).collect();
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            prop_assert!(len <= amount * shortest[v] * (1.0 + 1e-9) + 1e-12, "vertex {v} moved {len}, bound {}", amount * shortest[v]);
            let nl = (normal[v][0].powi(2) + normal[v][1].powi(2) + normal[v][2].powi(2)).sqrt();
            if nl > 0.0 && len > 0.0 {
                let along = (d[0] * normal[v][0] + d[1] * normal[v][1] + d[2] * normal[v][2]) / nl;
                prop_assert!(along.abs() <= 1e-9 * len.max(shortest[v]), "vertex {v}: {along} along the normal");
            }
        }
        for f in 0..m.quads.len() {
            let (s0, s1) = (face_sj(&m, f), face_sj(&j, f));
            prop_assert!(s1 >= min_sj.min(s0) - 1e-12, "face {f}: scaled Jacobian {s0} -> {s1} (bound {min_sj})");
        }
    }
}

#[test]
fn irregularize_makes_faces_irregular_and_zero_amount_is_identity() {
    let g = shapes::grid(20, 20, 1.0, 1.0);
    let mut rng = Rng::new(5);
    assert_eq!(shapes::irregularize(&g, 0.0, 0.5, &mut rng).vertices, g.vertices);
    let j = shapes::irregularize(&g, 0.3, 0.5, &mut rng);
    let mean = |m: &QuadMesh| (0..m.quads.len()).map(|f| face_sj(m, f)).sum::<f64>() / m.quads.len() as f64;
    // A square grid has SJ 1 everywhere; moves of up to 30% of an edge must show.
    assert!((mean(&g) - 1.0).abs() < 1e-12);
    let (mj, lo) = (mean(&j), (0..j.quads.len()).map(|f| face_sj(&j, f)).fold(1.0, f64::min));
    assert!(mj < 0.97 && lo >= 0.5, "mean SJ {mj}, min {lo}");
    // Deterministic for a seed.
    assert_eq!(
        shapes::irregularize(&g, 0.3, 0.5, &mut Rng::new(9)).vertices,
        shapes::irregularize(&g, 0.3, 0.5, &mut Rng::new(9)).vertices
    );
}

/// Largest angle (degrees) between the diagonal normals of two faces sharing an edge,
/// and the mean over shared edges (brute force over face pairs).
fn dihedral_stats(m: &QuadMesh) -> f64 {
    let normal = |q: &[u32; 4]| {
        let p = q.map(|i| m.vertices[i as usize]);
        let d1 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
        let d2 = [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]];
        let c = [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]];
        let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        [c[0] / l, c[1] / l, c[2] / l]
    };
    let mut edges: std::collections::HashMap<(u32, u32), Vec<usize>> = Default::default();
    for (f, q) in m.quads.iter().enumerate() {
        for k in 0..4 {
            let (a, b) = (q[k], q[(k + 1) % 4]);
            edges.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let (mut sum, mut n) = (0.0, 0usize);
    for fs in edges.values().filter(|fs| fs.len() == 2) {
        let (a, b) = (normal(&m.quads[fs[0]]), normal(&m.quads[fs[1]]));
        sum += (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0).acos().to_degrees();
        n += 1;
    }
    sum / n.max(1) as f64
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// `add_bumps` against its contract: connectivity kept, every vertex moved along its
    /// own normal (brute-force reference) by at most √waves × amplitude mean edges, and
    /// no face below min(min_sj, its scaled Jacobian before).
    #[test]
    fn add_bumps_moves_along_normals_within_bounds(seed in 0u64..1_000_000, waves in 1usize..5, amplitude in 0.0f64..1.5, min_sj in 0.1f64..0.6) {
        let mut rng = Rng::new(seed);
        let m = shapes::random_shape(&mut rng);
        let b = shapes::add_bumps(&m, waves, (3.0, 8.0), amplitude, min_sj, &mut rng);
        prop_assert_eq!(&b.quads, &m.quads);
        let (normal, _, mean_edge) = reference_vertex_frames(&m);
        let bound = (waves as f64).sqrt() * amplitude * mean_edge;
        for (v, nv) in normal.iter().enumerate() {
            let d: Vec<f64> = (0..3).map(|a| b.vertices[v][a] - m.vertices[v][a]).collect();
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            prop_assert!(len <= bound * (1.0 + 1e-9) + 1e-12, "vertex {v} moved {len} > {bound}");
            let nl = (nv[0].powi(2) + nv[1].powi(2) + nv[2].powi(2)).sqrt();
            // Parallel to the normal: the cross product vanishes.
            let cr = [d[1] * nv[2] - d[2] * nv[1], d[2] * nv[0] - d[0] * nv[2], d[0] * nv[1] - d[1] * nv[0]];
            let off = (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt() / nl.max(1e-300);
            prop_assert!(off <= 1e-9 * bound.max(1e-300) + 1e-12, "vertex {v}: {off} off its normal");
        }
        for f in 0..m.quads.len() {
            let (s0, s1) = (face_sj(&m, f), face_sj(&b, f));
            prop_assert!(s1 >= min_sj.min(s0) - 1e-12, "face {f}: {s0} -> {s1}");
        }
    }
}

#[test]
fn add_bumps_bends_a_sphere_between_neighbouring_faces() {
    let s = shapes::cube_sphere(12);
    let before = dihedral_stats(&s);
    // 12 × 12 per side: neighbouring faces ~7° apart; waves a few edges long, up to an
    // edge high, must bend every draw further (a do-nothing or a halved-to-nothing
    // displacement fails).
    assert!(before < 9.0, "{before}");
    for seed in 0..8 {
        let b = shapes::add_bumps(&s, 3, (3.0, 6.0), 1.0, 0.2, &mut Rng::new(seed));
        let after = dihedral_stats(&b);
        assert!(after > before + 0.5, "seed {seed}: mean dihedral {before:.1}° -> {after:.1}°");
    }
    assert_eq!(shapes::add_bumps(&s, 2, (3.0, 6.0), 0.0, 0.2, &mut Rng::new(4)).vertices, s.vertices);
}

/// `dataset --bumpy`: the same shapes (names, connectivity) bent more between
/// neighbouring faces for most samples; without it, exactly the unbumped recipe
/// (family then shape from the sample's stream), so the shipped weights' data is unchanged.
#[test]
fn bumpy_synthetic_samples_bend_more_and_plain_ones_are_unchanged() {
    use point2quad::pipeline::dataset::{sample_rng, synthetic_mesh};
    let mut bent = 0;
    for i in 0..12 {
        let (name, plain, _) = synthetic_mesh(7, i, false);
        let mut rng = sample_rng(7, i);
        let family = Family::ALL[rng.below(Family::ALL.len())];
        let reference = shapes::random_shape_of(family, &mut rng);
        assert_eq!(
            (plain.vertices.clone(), plain.quads.clone()),
            (reference.vertices, reference.quads),
            "{name}"
        );
        let (bname, bumpy, _) = synthetic_mesh(7, i, true);
        assert_eq!((&bname, &bumpy.quads), (&name, &plain.quads));
        if bumpy.vertices != plain.vertices {
            let (d0, d1) = (dihedral_stats(&plain), dihedral_stats(&bumpy));
            assert!(d1 > d0, "{name}: mean dihedral {d0:.1}° -> {d1:.1}°");
            bent += 1;
        }
    }
    // Three in four on average: at least half of 12.
    assert!(bent >= 6, "only {bent} of 12 bumpy");
}

/// `dataset --min-aspect` (session 20's experiment): at the default 0.25 the shapes are
/// exactly `random_shape_of`'s; at 0.1 the same stream gives the same families (a grid
/// keeps its faces, only stretched further), and some grid then has quads more
/// elongated than 4:1, which the default never makes.
#[test]
fn a_smaller_min_aspect_stretches_only_the_elongated_shapes() {
    use point2quad::pipeline::dataset::{synthetic_mesh, synthetic_mesh_with_aspect};
    let ratio = |m: &QuadMesh| {
        m.quads
            .iter()
            .map(|q| {
                let e: Vec<f64> = (0..4)
                    .map(|i| {
                        let (a, b) = (m.vertices[q[i] as usize], m.vertices[q[(i + 1) % 4] as usize]);
                        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
                    })
                    .collect();
                e.iter().cloned().fold(f64::MAX, f64::min) / e.iter().cloned().fold(0.0, f64::max)
            })
            .fold(f64::MAX, f64::min)
    };
    for i in 0..30 {
        let (name, plain, _) = synthetic_mesh(3, i, false);
        let (n25, m25, _) = synthetic_mesh_with_aspect(3, i, false, shapes::DEFAULT_MIN_ASPECT);
        assert!(n25 == name && m25.vertices == plain.vertices && m25.quads == plain.quads, "{name}");
        // The same family from the same stream (a torus or tube may get other rings).
        let (n10, _, _) = synthetic_mesh_with_aspect(3, i, false, 0.1);
        assert_eq!(n10, name);
    }
    let (mut default_min, mut narrow_min) = (f64::MAX, f64::MAX);
    for seed in 0..30 {
        let plain = shapes::random_shape_of(Family::Grid, &mut Rng::new(seed));
        let narrow = shapes::random_shape_with_aspect(Family::Grid, &mut Rng::new(seed), 0.1);
        assert!(plain.quads == narrow.quads, "seed {seed}: a grid keeps its faces");
        default_min = default_min.min(ratio(&plain));
        narrow_min = narrow_min.min(ratio(&narrow));
    }
    assert!(default_min > 0.2, "default grids reach an edge ratio of {default_min}");
    assert!(narrow_min < 0.2, "min aspect 0.1: grids only reach {narrow_min}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The triangle mesh's conversion to quads (`shapes::triangle_split`) against its
    /// definition, on every family: a valid, consistently oriented quad mesh with the same
    /// Euler characteristic, boundary (each border edge split in two) and signed volume;
    /// the input's vertices first, bit for bit; every other vertex the midpoint of an
    /// edge of the input's triangles or the centroid of a triangle; 6 quads per quad,
    /// each a corner, two midpoints and a centroid, planar (all four in one triangle).
    #[test]
    fn triangle_split_is_the_triangle_meshs_conversion(seed in 0u64..1_000_000, fam in 0usize..Family::ALL.len()) {
        let mut rng = Rng::new(seed);
        let m = shapes::random_shape_of(Family::ALL[fam], &mut rng);
        let t = shapes::triangle_split(&m, &mut rng);
        let (s, st) = (check_quad_mesh(&m), check_quad_mesh(&t));
        prop_assert_eq!(st.euler(), s.euler());
        prop_assert_eq!(st.boundary_edges, 2 * s.boundary_edges);
        prop_assert_eq!(st.components, s.components);
        prop_assert_eq!(t.quads.len(), 6 * m.quads.len());
        // V' = V + (edges of the triangle mesh) + (its 2F triangles).
        prop_assert_eq!(t.vertices.len(), s.vertices + (s.edges + m.quads.len()) + 2 * m.quads.len());
        prop_assert!(t.vertices[..m.vertices.len()] == m.vertices[..]);
        // Orientation kept: a closed mesh keeps the sign of its volume.
        if s.boundary_edges == 0 {
            prop_assert!(signed_volume(&m) * signed_volume(&t) > 0.0);
        }
        let mut tri_volume = 0.0;
        let n0 = m.vertices.len() as u32;
        let d = bbox_diag(&m);
        let close = |a: [f64; 3], b: [f64; 3]| (0..3).all(|k| (a[k] - b[k]).abs() <= 1e-12 * d);
        for q in &t.quads {
            // Corner first, then a midpoint, the centroid, a midpoint.
            prop_assert!(q[0] < n0 && q[1..].iter().all(|&v| v >= n0), "{:?}", q);
            let [a, m1, g, m2] = q.map(|v| t.vertices[v as usize]);
            // m1 = (a + b) / 2, m2 = (a + c) / 2 for the triangle's other corners b, c,
            // whose centroid is g = (a + b + c) / 3.
            let b: [f64; 3] = std::array::from_fn(|k| 2.0 * m1[k] - a[k]);
            let c: [f64; 3] = std::array::from_fn(|k| 2.0 * m2[k] - a[k]);
            prop_assert!(close(g, std::array::from_fn(|k| (a[k] + b[k] + c[k]) / 3.0)), "{:?}", q);
            // b and c are vertices of the input mesh.
            for p in [b, c] {
                prop_assert!(m.vertices.iter().any(|&v| close(v, p)), "{:?}", q);
            }
            // Each triangle is met once from each of its 3 corners.
            let cr = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
            tri_volume += (cr[0] * c[0] + cr[1] * c[1] + cr[2] * c[2]) / 18.0;
        }
        // The quads are flat (each lies in its triangle): the volume is the triangles'.
        if s.boundary_edges == 0 {
            let v = signed_volume(&t);
            prop_assert!((v - tri_volume).abs() <= 1e-9 * v.abs(), "{} vs {}", v, tri_volume);
        }
    }
}
