//! `mesh::watertight::close_all` (session 32): closed shapes with holes and "kites" (a
//! quad over the diagonals of two neighbours, which leaves a triangle hole on each side)
//! come back closed, valid, with the input's vertices untouched, the topology of the
//! shape they came from (Euler characteristic), and only the split strips' faces gone.

use point2quad::mesh::halfedge::{corner_set, HalfedgeMesh};
use point2quad::mesh::handles::FaceId;
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::shapes::{cube_sphere, grid, torus};
use point2quad::mesh::validate::validate;
use point2quad::mesh::watertight::{close_all, WatertightConfig, WatertightReport};
use point2quad::rng::Rng;
use proptest::prelude::*;
use std::collections::HashSet;

/// The faces of `m` that share the edge of half-edge `h` (`h`'s face and its twin's):
/// `[u, v, p, q]` and `[v, u, r, s]`; replaced by the kite `[v, q, u, s]`, which leaves
/// the triangles `(v, p, q)` and `(u, r, s)` open. `None` where either face is gone.
fn kite(m: &HalfedgeMesh, h: point2quad::mesh::handles::HalfedgeId) -> Option<(FaceId, FaceId, [u32; 4])> {
    let f1 = m.face(h)?;
    let f2 = m.face(h.opposite())?;
    let rot = |f: FaceId, start: u32| {
        let c = m.face_vertices(f).map(|v| v.0);
        let k = c.iter().position(|&v| v == start).unwrap();
        [c[k], c[(k + 1) % 4], c[(k + 2) % 4], c[(k + 3) % 4]]
    };
    let u = m.from_vertex(h).0;
    let v = m.to_vertex(h).0;
    let [_, _, _, q] = rot(f1, u);
    let [_, _, _, s] = rot(f2, v);
    Some((f1, f2, [v, q, u, s]))
}

/// `shape` with up to `kites` kites put in at random edges and about `share` of the other
/// faces taken out (removals that would pinch a vertex are skipped). Returns the mesh and
/// the kites' corner sets.
fn damaged(shape: &QuadMesh, kites: usize, share: f64, seed: u64) -> (QuadMesh, Vec<[u32; 4]>) {
    let mut rng = Rng::new(seed);
    let mut m = HalfedgeMesh::from_quads(shape.vertices.len(), &shape.quads).unwrap();
    let mut touched: HashSet<u32> = HashSet::new();
    let mut kite_keys = Vec::new();
    for _ in 0..kites {
        let faces: Vec<FaceId> = m.faces().collect();
        let f = faces[rng.below(faces.len())];
        let h = m.face_halfedges(f)[rng.below(4)];
        let Some((f1, f2, q)) = kite(&m, h) else { continue };
        let corners: Vec<u32> = [f1, f2].iter().flat_map(|&f| m.face_vertices(f).map(|v| v.0)).collect();
        // Kites apart from each other: no shared vertex with an earlier one.
        if corners.iter().any(|v| touched.contains(v)) {
            continue;
        }
        let before = m.clone();
        if m.remove_faces(&[f1, f2]).len() != 2
            || m.add_face(q.map(point2quad::mesh::handles::VertexId)).is_err()
        {
            m = before;
            continue;
        }
        touched.extend(corners);
        kite_keys.push(corner_set(q));
    }
    let faces: Vec<FaceId> = m.faces().collect();
    for f in faces {
        let c = m.face_vertices(f).map(|v| v.0);
        if !kite_keys.contains(&corner_set(c)) && rng.uniform(0.0, 1.0) < share {
            let _ = m.remove_face(f);
        }
    }
    validate(&m).unwrap();
    (m.to_quad_mesh(&shape.vertices).unwrap(), kite_keys)
}

fn keys(m: &QuadMesh) -> HashSet<[u32; 4]> {
    m.quads.iter().map(|&q| corner_set(q)).collect()
}

/// The invariants of a closing of a mesh cut from a closed shape of Euler characteristic
/// `chi`: valid, closed, pure quads over distinct corners, the input's vertices first
/// and bit for bit, the input's faces all there but the split ones, and the shape's
/// Euler characteristic.
fn check_closed(
    input: &QuadMesh,
    out: &QuadMesh,
    r: &WatertightReport,
    chi: i64,
) -> Result<(), TestCaseError> {
    let hm = HalfedgeMesh::from_quads(out.vertices.len(), &out.quads).unwrap();
    validate(&hm).unwrap();
    prop_assert!(hm.boundary_loops().is_empty(), "{} loops left open; {:?}", hm.boundary_loops().len(), r);
    prop_assert_eq!(r.loops_left, 0);
    for q in &out.quads {
        prop_assert_eq!(q.iter().collect::<HashSet<_>>().len(), 4, "{:?}", q);
    }
    prop_assert!(out.vertices.len() >= input.vertices.len());
    for (a, b) in input.vertices.iter().zip(&out.vertices) {
        prop_assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
    }
    prop_assert_eq!(out.vertices.len() - input.vertices.len(), r.vertices_added);
    let gone = keys(input).difference(&keys(out)).count();
    prop_assert_eq!(gone, r.faces_split, "{:?}", r);
    // Euler characteristic over the vertices the faces use.
    let used: HashSet<u32> = out.quads.iter().flatten().copied().collect();
    let chi_out = used.len() as i64 - hm.n_edges() as i64 + hm.n_faces() as i64;
    prop_assert_eq!(chi_out, chi);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    /// Tori and spheres with kites (pairs of triangle holes) and holes: closed again.
    #[test]
    fn close_all_closes_damaged_closed_shapes(
        sphere: bool,
        n in 3usize..7,
        kites in 0usize..5,
        share in prop::sample::select(vec![0.0, 0.03, 0.1, 0.25]),
        seed in any::<u64>(),
        weighted: bool,
        split_long_loops: bool,
    ) {
        let (shape, chi) = if sphere { (cube_sphere(n), 2) } else { (torus(2 * n, n + 1, 3.0, 1.0), 0) };
        let (input, kite_keys) = damaged(&shape, kites, share, seed);
        let loops = HalfedgeMesh::from_quads(input.vertices.len(), &input.quads).unwrap().boundary_loops();
        let odd = loops.iter().filter(|l| l.len() % 2 == 1).count();
        prop_assert!(odd % 2 == 0);
        let (cands, probs): (Vec<[u32; 4]>, Vec<f32>) =
            if weighted { (kite_keys.clone(), vec![0.9; kite_keys.len()]) } else { (vec![], vec![]) };
        let cfg = WatertightConfig { split_long_loops, ..WatertightConfig::default() };
        let (out, r) = close_all(&input, &cfg, &cands, &probs).unwrap();
        check_closed(&input, &out, &r, chi)?;
        prop_assert!(r.odd_pairs >= odd / 2, "{} odd loops, {:?}", odd, r);
        if loops.is_empty() {
            prop_assert_eq!(&out, &input);
        }
    }
}

/// A grid sheet with one kite: the two triangles are paired through the kite (one face,
/// split in two), each becomes a 4-edge loop closed by one quad; the sheet's border,
/// longer than the bound, stays as it was.
#[test]
fn a_kite_between_two_triangles_is_split_and_both_closed() {
    let g = grid(6, 6, 6.0, 6.0);
    let m = HalfedgeMesh::from_quads(g.vertices.len(), &g.quads).unwrap();
    // An interior edge: the one between faces 14 and 15 (row 2, columns 2 and 3).
    let id = |i: u32, j: u32| j * 7 + i;
    let h = m
        .find_halfedge(
            point2quad::mesh::handles::VertexId(id(3, 2)),
            point2quad::mesh::handles::VertexId(id(3, 3)),
        )
        .unwrap();
    let h = if m.face(h).is_some() && m.face(h.opposite()).is_some() { h } else { panic!("interior edge") };
    let (f1, f2, q) = kite(&m, h).unwrap();
    let mut m2 = m.clone();
    assert_eq!(m2.remove_faces(&[f1, f2]).len(), 2);
    m2.add_face(q.map(point2quad::mesh::handles::VertexId)).unwrap();
    let input = m2.to_quad_mesh(&g.vertices).unwrap();
    let border = |m: &QuadMesh| {
        let hm = HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).unwrap();
        let mut l: Vec<usize> = hm.boundary_loops().iter().map(Vec::len).collect();
        l.sort_unstable();
        l
    };
    assert_eq!(border(&input), vec![3, 3, 24]);
    let cfg = WatertightConfig { max_loop_edges: 23, ..Default::default() };
    let (out, r) = close_all(&input, &cfg, &[], &[]).unwrap();
    validate(&HalfedgeMesh::from_quads(out.vertices.len(), &out.quads).unwrap()).unwrap();
    assert_eq!(border(&out), vec![24]);
    assert_eq!(
        (r.odd_pairs, r.faces_split, r.loops_filled, r.quads_added, r.vertices_added, r.loops_left),
        (1, 1, 2, 2, 2, 1),
        "{r:?}"
    );
    assert_eq!(r.longest_loop, 4, "the border is beyond the bound: {r:?}");
    assert!(!keys(&out).contains(&corner_set(q)), "the kite is split");
    assert_eq!(out.quads.len(), input.quads.len() - 1 + 2 + 2);
    // Without a bound the border is closed too (the user asked for a closed mesh).
    let (all, r) = close_all(&input, &WatertightConfig::default(), &[], &[]).unwrap();
    assert!(border(&all).is_empty(), "{r:?}");
    assert_eq!(r.longest_loop, 24, "{r:?}");
}

/// The strips run through the least believed faces: with the kite believed and the rest
/// not, the triangles are paired around it and the kite stays; with the kite not
/// believed it is the strip.
#[test]
fn strips_avoid_believed_faces() {
    let g = torus(12, 8, 3.0, 1.0);
    let (input, kite_keys) = damaged(&g, 1, 0.0, 3);
    assert_eq!(kite_keys.len(), 1);
    let k = kite_keys[0];
    let (out, r) = close_all(&input, &WatertightConfig::default(), &[k], &[0.99]).unwrap();
    assert!(keys(&out).contains(&k), "{r:?}");
    assert!(r.faces_split >= 2, "{r:?}");
    let others: Vec<[u32; 4]> = input.quads.iter().copied().filter(|&q| corner_set(q) != k).collect();
    let (out, r) =
        close_all(&input, &WatertightConfig::default(), &others, &vec![0.99; others.len()]).unwrap();
    assert!(!keys(&out).contains(&k), "{r:?}");
    assert_eq!(r.faces_split, 1, "{r:?}");
}

/// A mesh with nothing open comes back as it was; a non-finite coordinate is an error
/// naming the vertex.
#[test]
fn closed_meshes_pass_through_and_bad_coordinates_are_refused() {
    let s = cube_sphere(3);
    let (out, r) = close_all(&s, &WatertightConfig::default(), &[], &[]).unwrap();
    assert_eq!(out, s);
    assert_eq!(r, WatertightReport::default());
    let mut bad = s.clone();
    bad.vertices[5][1] = f64::NAN;
    let e = close_all(&bad, &WatertightConfig::default(), &[], &[]).unwrap_err().to_string();
    assert!(e.contains("vertex 5"), "{e}");
    let c = [[0, 1, 2, 3]];
    for (cands, probs, what) in [
        (&c[..], &[][..], "1 candidates but 0 probabilities"),
        (&[[0, 1, 2, 100_000]][..], &[0.5][..], "candidate 0 has a corner beyond"),
        (&c[..], &[f32::NAN][..], "candidate 0 has a non-finite probability"),
    ] {
        let e = close_all(&s, &WatertightConfig::default(), cands, probs).unwrap_err().to_string();
        assert!(e.contains(what), "{e}");
    }
}

/// The rescue (when asked for): a hole left where the four faces around a vertex were
/// taken out is closed by those faces when they are candidates (the vertex in the middle
/// is used again, nothing is invented), and over the hole's own border without them.
#[test]
fn candidates_fill_a_hole_before_anything_is_invented() {
    let s = cube_sphere(4);
    let mut m = HalfedgeMesh::from_quads(s.vertices.len(), &s.quads).unwrap();
    let centre = (0..s.vertices.len() as u32)
        .map(point2quad::mesh::handles::VertexId)
        .find(|&v| m.vertex_faces(v).count() == 4)
        .unwrap();
    let around: Vec<FaceId> = m.vertex_faces(centre).collect();
    let taken: Vec<[u32; 4]> = around.iter().map(|&f| m.face_vertices(f).map(|v| v.0)).collect();
    assert_eq!(m.remove_faces(&around).len(), 4);
    let input = m.to_quad_mesh(&s.vertices).unwrap();
    let rescue = WatertightConfig { rescue_min_prob: Some(0.0), ..Default::default() };
    let (out, r) = close_all(&input, &rescue, &taken, &[0.3; 4]).unwrap();
    assert_eq!(keys(&out), keys(&s), "{r:?}");
    assert_eq!((r.rescued, r.vertices_added, r.loops_left), (4, 0, 0), "{r:?}");
    let (out, r) = close_all(&input, &rescue, &[], &[]).unwrap();
    assert_eq!((r.rescued, r.quads_added, r.vertices_added, r.loops_left), (0, 3, 0, 0), "{r:?}");
    // Off by default: the same without candidates.
    let (out2, r) = close_all(&input, &WatertightConfig::default(), &taken, &[0.3; 4]).unwrap();
    assert_eq!((r.rescued, r.quads_added), (0, 3), "{r:?}");
    assert_eq!(out2, out);
    assert!(out.quads.iter().all(|q| !q.contains(&centre.0)));
    // Not rescued below the bound.
    let cfg = WatertightConfig { rescue_min_prob: Some(0.5), ..rescue };
    let (_, r) = close_all(&input, &cfg, &taken, &[0.3; 4]).unwrap();
    assert_eq!(r.rescued, 0, "{r:?}");
}

/// Panics when a vertex of `m` from `first` on lies within `tol` of another vertex.
fn assert_apart(m: &QuadMesh, first: usize, tol: f64, what: &str) {
    for (i, a) in m.vertices.iter().enumerate().skip(first) {
        for (j, b) in m.vertices.iter().enumerate().take(i) {
            let d = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
            assert!(d > tol, "{what}: added vertex {i} lies on vertex {j} at {a:?}");
        }
    }
}

/// Session 37's audit: a flat 40 × 40 grid closed with `--watertight` got 4 quads with
/// four collinear corners (pieces of its straight border cut off by chords) and an
/// added vertex on an input point. Flat and stretched sheets of many sizes: no closing
/// quad is degenerate (`is_degenerate_quad`), and no added vertex lands on another
/// vertex; a loop that cannot be closed without either stays open and is counted.
#[test]
fn flat_sheets_close_without_degenerate_quads() {
    use point2quad::mesh::quality::is_degenerate_quad;
    for (nu, nv, stretch) in
        [(40, 40, 1.0), (30, 30, 1.0), (12, 7, 1.0), (39, 39, 10.0), (20, 5, 0.1), (6, 6, 1.0)]
    {
        let g = grid(nu, nv, nu as f64 * stretch, nv as f64);
        let (out, r) = close_all(&g, &WatertightConfig::default(), &[], &[]).unwrap();
        let hm = HalfedgeMesh::from_quads(out.vertices.len(), &out.quads).unwrap();
        validate(&hm).unwrap();
        assert_eq!(hm.boundary_loops().len(), r.loops_left, "{nu}x{nv}");
        for q in &out.quads {
            let p = q.map(|v| out.vertices[v as usize]);
            assert!(!is_degenerate_quad(&p), "{nu}x{nv} ×{stretch}: degenerate quad {q:?} at {p:?}");
        }
        assert_apart(&out, g.vertices.len(), 1e-6 * stretch.min(1.0), &format!("{nu}x{nv} ×{stretch}"));
    }
}

/// The audit's case end to end: `reconstruct` with the watertight closing on a flat
/// 40 × 40 grid cloud (spacing 0.1) and on the same grid stretched 10 : 1. The output
/// has no degenerate quad, and no added vertex within 10⁻⁶ of a spacing of another
/// vertex, after the closing's vertices are mapped back from the normalised frame (the
/// mapping's rounding had put one exactly on an input point).
#[test]
fn reconstruct_watertight_on_a_flat_grid_adds_no_degenerate_quad() {
    use point2quad::mesh::quality::is_degenerate_quad;
    use point2quad::pipeline::reconstruct::{reconstruct, ReconstructConfig};
    #[path = "common/shipped.rs"]
    mod shipped;
    for stretch in [1.0, 10.0] {
        let pts: Vec<[f64; 3]> =
            (0..1600).map(|i| [0.1 * stretch * (i % 40) as f64, 0.1 * (i / 40) as f64, 0.0]).collect();
        let cfg = ReconstructConfig { watertight: Some(WatertightConfig::default()), ..Default::default() };
        let m = reconstruct(&pts, shipped::shipped(), &cfg).expect("reconstruct");
        assert!(m.quads.len() > 1000, "×{stretch}: {} faces", m.quads.len());
        for q in &m.quads {
            let p = q.map(|v| m.vertices[v as usize]);
            assert!(!is_degenerate_quad(&p), "×{stretch}: degenerate quad {q:?} at {p:?}");
        }
        assert_apart(&m, pts.len(), 1e-7, &format!("×{stretch}"));
    }
}
