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
