//! Property tests of the half-edge mesh and post-process: random insertion orders and
//! orientations, refusals that leave the mesh untouched, removals, random soups through the
//! post-process, single-face holes — each checked by `validate()` and against the ground truth.

#[path = "common/halfedge.rs"]
mod common;

use common::*;
use point2quad::mesh::halfedge::{HalfedgeMesh, RefusalKind};
use point2quad::mesh::handles::{FaceId, VertexId};
use point2quad::mesh::hole_fill::{fill_holes, HoleFillConfig};
use point2quad::mesh::postprocess::{postprocess, support_priority, PostprocessConfig};
use point2quad::mesh::validate::validate;
use point2quad::rng::Rng;
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

#[test]
fn suite_has_the_stated_topology() {
    let names: Vec<&str> = suite().iter().map(|m| m.name).collect();
    eprintln!("suite: {names:?}, genus {:?}", suite().iter().map(|m| m.genus).collect::<Vec<_>>());
    for m in suite() {
        let h = HalfedgeMesh::from_quads(m.positions.len(), &m.quads).unwrap();
        validate(&h).unwrap();
        assert_eq!(h.n_faces(), m.quads.len(), "{}", m.name);
        assert_eq!(h.is_closed(), m.closed, "{}", m.name);
        if m.closed {
            assert_eq!(h.genus().unwrap(), m.genus, "{}", m.name);
            assert_eq!(h.connected_components().len(), 1);
            assert!(h.boundary_loops().is_empty());
        } else {
            assert!(!h.boundary_loops().is_empty());
        }
    }
}

/// Inserts `m`'s faces, each reversed with probability 1/2, in a random order (both from
/// `rng`): every face must go in, the mesh validate, and each component end consistently
/// oriented (all faces agree with the ground truth, or all disagree), topology kept.
fn builds_whole_in_random_order(m: &TestMesh, rng: &mut Rng) -> Result<(), TestCaseError> {
    let faces: Vec<[u32; 4]> =
        m.quads.iter().map(|&f| if rng.below(2) == 0 { f } else { reversed(f) }).collect();
    let mut order: Vec<usize> = (0..faces.len()).collect();
    rng.shuffle(&mut order);
    let mut h = HalfedgeMesh::new(m.positions.len());
    let out = h.insert_faces(&faces, &order);
    prop_assert!(out.refused.is_empty(), "{}: {:?}", m.name, out.refused);
    validate(&h).unwrap();
    let mut agree = 0;
    for (i, f) in out.inserted.iter().enumerate() {
        let got = h.face_vertices(f.unwrap()).map(|v| v.0);
        if same_cycle(got, m.quads[i]) {
            agree += 1;
        } else {
            prop_assert!(same_cycle(got, reversed(m.quads[i])));
        }
    }
    prop_assert!(agree == 0 || agree == m.quads.len(), "{}: {agree} of {} agree", m.name, m.quads.len());
    prop_assert_eq!(h.is_closed(), m.closed);
    if m.closed {
        prop_assert_eq!(h.genus().unwrap(), m.genus);
    }
    Ok(())
}

/// Regression (issue 3's area): with these inputs of
/// `random_order_and_orientation_builds_the_whole_mesh`, face-by-face insertion left 10–11
/// faces of the voxel cage waiting on each other (each between two faces of another
/// around some vertex), so they were refused although the whole set is a manifold. They
/// were found by running that test's body on the seeds 0..3000 and the one reported.
#[test]
fn faces_waiting_on_each_other_in_the_suite_go_in() {
    for seed in [10_419_881_408_664_574_711, 113, 133, 489, 1002] {
        let mut rng = Rng::new(seed);
        for m in suite() {
            builds_whole_in_random_order(&m, &mut rng).unwrap_or_else(|e| panic!("seed {seed}: {e}"));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// `QuadMesh::without_unused` and `without_unused_from(start)` against their
    /// definition, brute force: the kept indices are exactly those below `start` and the
    /// used ones, ascending; each kept vertex is its original; each quad maps back to the
    /// original quad corner for corner.
    #[test]
    fn without_unused_matches_brute_force(
        n in 1usize..40,
        raw in prop::collection::vec(prop::array::uniform4(0usize..1000), 0..30),
        start in prop::option::of(0usize..45),
    ) {
        use point2quad::mesh::poly::QuadMesh;
        let vertices: Vec<[f64; 3]> = (0..n).map(|i| [i as f64, (i * i) as f64, -(i as f64)]).collect();
        let quads: Vec<[u32; 4]> = raw.iter().map(|q| q.map(|v| (v % n) as u32)).collect();
        let m = QuadMesh { vertices: vertices.clone(), quads: quads.clone() };
        let (c, kept) = match start {
            None => m.without_unused(),
            Some(s) => m.without_unused_from(s),
        };
        let s = start.unwrap_or(0);
        let used: Vec<u32> =
            (0..n as u32).filter(|v| (*v as usize) < s || quads.iter().any(|q| q.contains(v))).collect();
        prop_assert_eq!(&kept, &used);
        prop_assert_eq!(c.vertices.len(), kept.len());
        for (k, &orig) in kept.iter().enumerate() {
            prop_assert_eq!(c.vertices[k], vertices[orig as usize]);
        }
        prop_assert_eq!(c.quads.len(), quads.len());
        for (cq, q) in c.quads.iter().zip(&quads) {
            prop_assert_eq!(cq.map(|v| kept[v as usize]), *q);
        }
    }

    /// Any order, any orientation: every face goes in (see [`builds_whole_in_random_order`]).
    #[test]
    fn random_order_and_orientation_builds_the_whole_mesh(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            builds_whole_in_random_order(&m, &mut rng)?;
        }
    }

    /// The same on random voxel cages (tunnels, valence 3–6 corners), where faces waiting
    /// on each other are most common.
    #[test]
    fn random_voxel_cages_build_whole_in_any_order(seed in any::<u64>(), dims in prop::array::uniform3(2usize..7), fill in 0.2f64..0.8) {
        let mut rng = Rng::new(seed);
        let m = from_shape("random cage", point2quad::mesh::shapes::voxel_cage(&mut rng, dims, fill));
        for _ in 0..4 {
            builds_whole_in_random_order(&m, &mut rng)?;
        }
    }

    /// Soups in a random order: the result validates, and no refused face fits it
    /// (`add_face` refuses it and leaves the mesh unchanged); a face refused for a second
    /// fan names one of its corners.
    #[test]
    fn insertion_of_random_soups_is_valid_and_maximal(seed in any::<u64>(), drop in 0.0f64..0.3) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            let wrong = 1 + rng.below(m.quads.len());
            let (faces, _) = random_soup(&m, &mut rng, drop, wrong);
            let mut order: Vec<usize> = (0..faces.len()).collect();
            rng.shuffle(&mut order);
            let mut h = HalfedgeMesh::new(m.positions.len());
            let out = h.insert_faces(&faces, &order);
            validate(&h).unwrap();
            prop_assert_eq!(out.inserted.iter().filter(|f| f.is_some()).count(), h.n_faces());
            prop_assert_eq!(h.n_faces() + out.refused.len(), faces.len());
            let full = h.clone();
            for (i, r) in &out.refused {
                if let RefusalKind::SecondFan(v) = r.kind {
                    prop_assert!(faces[*i].contains(&v.0), "{}: {}", m.name, r.msg);
                }
                prop_assert!(h.add_face(faces[*i].map(VertexId)).is_err(), "{}: refused face {i} fits: {}", m.name, r.msg);
                prop_assert!(h == full);
            }
        }
    }

    /// add_face one by one in a random order: every refusal leaves the arrays identical,
    /// every success validates; refused faces touch existing fans only at a vertex.
    #[test]
    fn refusals_leave_the_mesh_bit_identical(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            let mut faces = m.quads.clone();
            rng.shuffle(&mut faces);
            let mut h = HalfedgeMesh::new(m.positions.len());
            for &f in &faces {
                let before = h.clone();
                match h.add_face(f.map(VertexId)) {
                    Ok(_) => validate(&h).unwrap(),
                    Err(e) => {
                        prop_assert!(h == before, "{}: refusal changed the mesh", m.name);
                        prop_assert!(e.to_string().contains("vertex"), "{e}");
                    }
                }
            }
            // Wrong faces over a complete mesh: all refused, nothing changes.
            let full = HalfedgeMesh::from_quads(m.positions.len(), &m.quads).unwrap();
            let mut h = full.clone();
            for _ in 0..20 {
                let g = m.quads[rng.below(m.quads.len())];
                let f = [g[0], g[1], rng.below(m.positions.len()) as u32, rng.below(m.positions.len()) as u32];
                if h.add_face(f.map(VertexId)).is_err() {
                    prop_assert!(h == full);
                } else {
                    validate(&h).unwrap();
                    h = full.clone();
                }
                prop_assert!(h.add_face(g.map(VertexId)).is_err(), "duplicate accepted");
                prop_assert!(h.add_face(reversed(g).map(VertexId)).is_err(), "reversed duplicate accepted");
                prop_assert!(h == full);
            }
        }
    }

    /// Removing random faces: each removal validates or is refused without change; the
    /// removed faces go back in.
    #[test]
    fn remove_face_keeps_the_mesh_valid(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            let full = HalfedgeMesh::from_quads(m.positions.len(), &m.quads).unwrap();
            let mut h = full.clone();
            let mut removed = Vec::new();
            for _ in 0..m.quads.len() / 2 {
                let f = FaceId(rng.below(m.quads.len()) as u32);
                if !h.is_face_alive(f) {
                    continue;
                }
                let verts = h.face_vertices(f).map(|v| v.0);
                let before = h.clone();
                match h.remove_face(f) {
                    Ok(()) => {
                        validate(&h).unwrap();
                        removed.push(verts);
                    }
                    Err(_) => prop_assert!(h == before),
                }
            }
            let order: Vec<usize> = (0..removed.len()).collect();
            let out = h.insert_faces(&removed, &order);
            prop_assert!(out.refused.is_empty(), "{}: {:?}", m.name, out.refused);
            validate(&h).unwrap();
            prop_assert_eq!(mesh_keys(&h), mesh_keys(&full));
        }
    }

    /// Random soups through the whole post-process: always a valid, pure-quad, oriented
    /// manifold whose first vertices are the input positions, bit for bit.
    #[test]
    fn postprocess_of_random_soups_is_a_valid_mesh(
        seed in any::<u64>(),
        drop in 0.0f64..0.3,
        limit in prop::sample::select(vec![2u32, 10]),
        support in prop::sample::select(vec![0.0f32, 2.0]),
    ) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            let wrong = 1 + rng.below(m.quads.len());
            let (faces, probs) = random_soup(&m, &mut rng, drop, wrong);
            let cfg = PostprocessConfig { score_limit: limit, support_weight: support, ..Default::default() };
            let (qm, rep) = postprocess(&m.positions, &faces, &probs, &cfg).unwrap();
            prop_assert_eq!(&qm.vertices[..m.positions.len()], &m.positions[..]);
            for (a, b) in qm.vertices.iter().zip(&m.positions) {
                prop_assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()));
            }
            let h = HalfedgeMesh::from_quads(qm.vertices.len(), &qm.quads).unwrap();
            validate(&h).unwrap();
            prop_assert_eq!(h.n_faces(), qm.quads.len());
            prop_assert_eq!(rep.faces_out, qm.quads.len());
            prop_assert_eq!(rep.faces_in, faces.len());
            prop_assert!(rep.inserted + rep.refused_on_insertion + rep.removed_by_score + rep.degenerate + rep.zero_area + rep.duplicates == faces.len());
        }
    }

    /// The insertion priority with edge support equals a brute-force reference: for
    /// each face, each of its sides (a, b), the best probability among the other kept
    /// faces across it, averaged over the four sides. Across = running b → a (direction
    /// rule, no positions); with positions, running a → b instead when the two face
    /// normals (f64 diagonal cross products) are more than 120° apart. Some true faces
    /// are given reversed (orientation seams).
    #[test]
    fn support_priority_matches_brute_force(seed in any::<u64>(), w in 0.0f32..4.0) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            let wrong = 1 + rng.below(m.quads.len());
            let (mut faces, probs) = random_soup(&m, &mut rng, 0.1, wrong);
            for f in &mut faces {
                if rng.f64() < 0.2 {
                    f.reverse();
                }
            }
            let keep: Vec<bool> = faces.iter().map(|_| rng.f64() < 0.9).collect();
            let normal = |q: &[u32; 4]| {
                let p = q.map(|i| m.positions[i as usize]);
                let d1 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
                let d2 = [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]];
                [d1[1] * d2[2] - d1[2] * d2[1], d1[2] * d2[0] - d1[0] * d2[2], d1[0] * d2[1] - d1[1] * d2[0]]
            };
            for with_positions in [false, true] {
                let at = with_positions.then_some(&m.positions[..]);
                let got = support_priority(at, &faces, &probs, &keep, w);
                'faces: for (f, q) in faces.iter().enumerate() {
                    // A face the order will not insert gets its probability alone.
                    if !keep[f] {
                        prop_assert_eq!(got[f], probs[f]);
                        continue;
                    }
                    let mut sum = 0.0f32;
                    for i in 0..4 {
                        let (a, b) = (q[i], q[(i + 1) % 4]);
                        let mut best = 0.0f32;
                        for (g, r) in faces.iter().enumerate() {
                            let runs_ba = (0..4).any(|j| r[j] == b && r[(j + 1) % 4] == a);
                            let runs_ab = (0..4).any(|j| r[j] == a && r[(j + 1) % 4] == b);
                            let across = if with_positions {
                                let (nf, ng) = (normal(q), normal(r));
                                let d = nf[0] * ng[0] + nf[1] * ng[1] + nf[2] * ng[2];
                                let l = (nf.iter().map(|x| x * x).sum::<f64>() * ng.iter().map(|x| x * x).sum::<f64>()).sqrt();
                                // Normals exactly 120° apart (a 6-sided torus section) are
                                // decided by rounding: not a case this reference can judge.
                                if (runs_ab || runs_ba) && l > 0.0 && (d / l + 0.5).abs() < 1e-4 {
                                    continue 'faces;
                                }
                                if l > 0.0 && d <= -0.5 * l {
                                    runs_ab
                                } else {
                                    runs_ba
                                }
                            } else {
                                runs_ba
                            };
                            if g != f && keep[g] && across && a != b {
                                best = best.max(probs[g]);
                            }
                        }
                        sum += best;
                    }
                    let want = probs[f] + w * sum / 4.0;
                    prop_assert!(
                        (got[f] - want).abs() <= 1e-5 * (1.0 + want.abs()),
                        "{} face {} {:?} (positions {}): {} vs {}", m.name, f, q, with_positions, got[f], want
                    );
                }
            }
        }
    }

    /// A single-face hole always closes, with exactly the removed face.
    #[test]
    fn single_face_holes_close_exactly(seed in any::<u64>()) {
        let mut rng = Rng::new(seed);
        for m in suite() {
            let full = HalfedgeMesh::from_quads(m.positions.len(), &m.quads).unwrap();
            let mut h = full.clone();
            let f = FaceId(rng.below(m.quads.len()) as u32);
            let interior = full.face_halfedges(f).iter().all(|x| !full.is_boundary(x.opposite()));
            h.remove_face(f).unwrap();
            let mut pos = m.positions.clone();
            let r = fill_holes(&mut h, &mut pos, &HoleFillConfig::default()).unwrap();
            validate(&h).unwrap();
            if interior {
                prop_assert_eq!(r.quads_by_pattern, [1, 0, 0]);
                prop_assert_eq!(mesh_keys(&h), mesh_keys(&full));
            }
            prop_assert_eq!(pos.len(), m.positions.len());
        }
    }
}

/// Regression: the paper's limit (2) also deletes faces with two boundary edges, so
/// scattered holes grow and merge until nothing is left; the default (10) must keep a
/// mesh with a few percent of its faces missing, and the hole filling must restore them.
#[test]
fn default_filter_does_not_erode_a_mesh_with_scattered_holes() {
    let m = from_shape("cube_sphere", point2quad::mesh::shapes::cube_sphere(12));
    let mut rng = Rng::new(5);
    let faces: Vec<[u32; 4]> = m.quads.iter().filter(|_| rng.f64() >= 0.05).copied().collect();
    let probs = vec![0.9f32; faces.len()];
    let (qm, rep) = postprocess(&m.positions, &faces, &probs, &PostprocessConfig::default()).unwrap();
    assert_eq!(rep.removed_by_score, 0);
    let gt: std::collections::HashSet<[u32; 4]> = m.quads.iter().map(|&f| key(f)).collect();
    let got = qm.quads.iter().filter(|&&f| gt.contains(&key(f))).count();
    assert!(got as f64 >= 0.99 * m.quads.len() as f64, "{got} of {} restored: {rep:?}", m.quads.len());
    let paper = PostprocessConfig { score_limit: 2, ..Default::default() };
    let (_, rep2) = postprocess(&m.positions, &faces, &probs, &paper).unwrap();
    assert!(rep2.removed_by_score > 0);
}

/// True faces with higher probabilities than the wrong ones come back almost all, and
/// almost nothing else does.
#[test]
fn postprocess_recovers_the_ground_truth_from_a_noisy_soup() {
    let m = from_shape("cube_sphere", point2quad::mesh::shapes::cube_sphere(10));
    let mut rng = Rng::new(11);
    let (faces, probs) = random_soup(&m, &mut rng, 0.03, m.quads.len() / 5);
    let (qm, rep) = postprocess(&m.positions, &faces, &probs, &PostprocessConfig::default()).unwrap();
    let gt: std::collections::HashSet<[u32; 4]> = m.quads.iter().map(|&f| key(f)).collect();
    let good = qm.quads.iter().filter(|&&f| gt.contains(&key(f))).count();
    let recall = good as f64 / m.quads.len() as f64;
    let precision = good as f64 / qm.quads.len() as f64;
    assert!(recall >= 0.97 && precision >= 0.97, "recall {recall} precision {precision}: {rep:?}");
}

/// The borders of open surfaces (grids, height fields, tube ends of any resolution) are not
/// holes: filling a complete open mesh adds nothing.
#[test]
fn open_borders_are_not_filled() {
    use point2quad::mesh::shapes::{self, Family};
    let mut rng = Rng::new(21);
    let mut meshes = Vec::new();
    for n in [4, 6, 8, 12, 16] {
        meshes.push(("tube", shapes::cylinder(n, 3, 1.0, 1.5, false)));
    }
    for family in [Family::Grid, Family::HeightField, Family::Tube] {
        for _ in 0..3 {
            meshes.push((family.name(), shapes::random_shape_of(family, &mut rng)));
        }
    }
    for (name, q) in meshes {
        let mut h = HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).unwrap();
        let mut pos = q.vertices.clone();
        let r = fill_holes(&mut h, &mut pos, &HoleFillConfig::default()).unwrap();
        // A square tube's end is a 4-edge loop, which pattern 1 always closes.
        let expected = if name == "tube" && h.boundary_loops().iter().all(|l| l.len() == 4) { 2 } else { 0 };
        assert_eq!(r.quads_added(), expected, "{name}: {r:?}");
    }
}

/// Closed outputs face outward whatever the input orientation; open ones keep the
/// orientation most of their input faces had.
#[test]
fn output_orientation_is_outward_or_as_given() {
    let mut rng = Rng::new(8);
    for m in suite() {
        for flip_share in [0.0, 0.3, 0.7, 1.0] {
            let faces: Vec<[u32; 4]> =
                m.quads.iter().map(|&f| if rng.f64() < flip_share { reversed(f) } else { f }).collect();
            let probs: Vec<f32> = (0..faces.len()).map(|_| rng.f32()).collect();
            let (qm, _) = postprocess(&m.positions, &faces, &probs, &PostprocessConfig::default()).unwrap();
            assert_eq!(qm.quads.len(), m.quads.len(), "{}", m.name);
            // The generators give closed shapes outward and open ones a fixed orientation.
            let want_as_gt = m.closed || flip_share < 0.5;
            for f in &qm.quads {
                let gt = m.quads.iter().find(|g| key(**g) == key(*f)).unwrap();
                let as_gt = same_cycle(*f, *gt);
                assert_eq!(as_gt, want_as_gt, "{} flip share {flip_share}", m.name);
            }
        }
    }
}
