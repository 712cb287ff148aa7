//! Property tests of the chord-collapse coarsening (`mesh::coarsen`), against brute-force
//! references and the independent invariant checker of `tests/common/shapes.rs`:
//! - on a grid, the chord through a face is exactly its row or its column, and collapsing
//!   it leaves the grid with that row or column gone (faces, boundary, positions);
//! - on every synthetic family, coarsening keeps a valid, consistently oriented,
//!   manifold pure-quad mesh with the same Euler characteristic, border loops and
//!   components, never more faces, no face below the shape bound, and is deterministic.

#[path = "common/shapes.rs"]
mod common_shapes;

use common_shapes::check_quad_mesh;
use point2quad::mesh::coarsen::{chord, coarsen, collapse, edge_map, CoarsenConfig};
use point2quad::mesh::halfedge::HalfedgeMesh;
use point2quad::mesh::poly::QuadMesh;
use point2quad::mesh::quality::quad_shape;
use point2quad::mesh::shapes::{self, Family};
use point2quad::rng::Rng;
use proptest::prelude::*;

fn min_sj(m: &QuadMesh) -> f64 {
    m.quads
        .iter()
        .map(|q| quad_shape(&q.map(|v| m.vertices[v as usize])).scaled_jacobian)
        .fold(f64::INFINITY, f64::min)
}

fn boundary_loops(m: &QuadMesh) -> usize {
    HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).unwrap().boundary_loops().len()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn a_grid_chord_is_its_row_or_column_and_collapses_to_a_smaller_grid(
        nu in 2usize..10, nv in 2usize..10, pick in 0usize..1000, side in 0usize..4,
    ) {
        let g = shapes::grid(nu, nv, nu as f64, nv as f64);
        // Brute force: face f = (i, j) at index j * nu + i; sides 0 and 2 are the edges
        // along u (the chord runs along v: the column i), 1 and 3 along v (the row j).
        let f = pick % g.quads.len();
        let (i, j) = (f % nu, f / nu);
        let e = edge_map(&g.quads);
        let ch = chord(&g.quads, &e, f, side).expect("a grid chord never crosses itself");
        let mut got: Vec<usize> = ch.iter().map(|c| c.0).collect();
        got.sort_unstable();
        let corner0 = g.quads[f][0];
        let v_side = g.vertices[g.quads[f][1] as usize][0] != g.vertices[corner0 as usize][0];
        // Whether side 0 of this face runs along u (x) in the generator's corner order.
        let along_u = if side % 2 == 0 { v_side } else { !v_side };
        let want: Vec<usize> = if along_u {
            (0..nv).map(|jj| jj * nu + i).collect()
        } else {
            (0..nu).map(|ii| j * nu + ii).collect()
        };
        prop_assert_eq!(&got, &want);
        let cfg = CoarsenConfig { min_scaled_jacobian: 0.0, ..Default::default() };
        let c = collapse(&g.vertices, &g.quads, &ch, &cfg).expect("a grid row or column collapses");
        prop_assert_eq!(c.quads.len(), nu * nv - want.len());
        prop_assert_eq!(c.merged.len(), want.len() + 1);
        let mut pos = g.vertices.clone();
        for &(v, p) in &c.moved {
            pos[v as usize] = p;
        }
        let mut used = vec![false; pos.len()];
        for q in &c.quads {
            for &v in q {
                used[v as usize] = true;
            }
        }
        for &(removed, _) in &c.merged {
            prop_assert!(!used[removed as usize]);
        }
        // The result is an (nu − 1) × nv or nu × (nv − 1) grid: compact and check.
        let mut idx = vec![u32::MAX; pos.len()];
        let mut vertices = Vec::new();
        for (k, &u) in used.iter().enumerate() {
            if u {
                idx[k] = vertices.len() as u32;
                vertices.push(pos[k]);
            }
        }
        let m = QuadMesh { vertices, quads: c.quads.iter().map(|q| q.map(|v| idx[v as usize])).collect() };
        let s = check_quad_mesh(&m);
        let (a, b) = if along_u { (nu - 1, nv) } else { (nu, nv - 1) };
        prop_assert_eq!(s.euler(), 1);
        prop_assert_eq!((s.vertices, s.faces, s.boundary_edges), ((a + 1) * (b + 1), a * b, 2 * (a + b)));
        // Every vertex stays on the grid's lines x = integer or a rung midpoint.
        for p in &m.vertices {
            prop_assert!((p[0] * 2.0).fract() == 0.0 && (p[1] * 2.0).fract() == 0.0);
        }
    }

    #[test]
    fn coarsening_keeps_a_valid_mesh_of_the_same_topology(
        seed in 0u64..10_000, family in 0usize..9, fraction in 0.1f64..0.9, bound in 0.2f64..0.9,
    ) {
        let fam = Family::ALL[family];
        let m = shapes::random_shape_of(fam, &mut Rng::new(seed));
        let before = check_quad_mesh(&m);
        let cfg = CoarsenConfig { face_fraction: fraction, min_scaled_jacobian: bound, ..Default::default() };
        let c = coarsen(&m, &cfg, &mut Rng::new(seed ^ 0x5eed));
        let after = check_quad_mesh(&c);
        prop_assert_eq!(after.euler(), before.euler(), "{:?}: {:?} -> {:?}", fam, before, after);
        prop_assert_eq!(after.components, before.components);
        prop_assert_eq!(boundary_loops(&c), boundary_loops(&m));
        prop_assert!(after.faces <= before.faces);
        prop_assert!(min_sj(&c) >= cfg.min_scaled_jacobian.min(min_sj(&m)) - 1e-12);
        // Deterministic for the random stream.
        let again = coarsen(&m, &cfg, &mut Rng::new(seed ^ 0x5eed));
        prop_assert_eq!(&again, &c);
    }
}

#[test]
fn a_torus_grid_reaches_the_target_share_of_faces() {
    // 24 × 16 faces, every chord closed and every collapse well shaped: a quarter is
    // reachable by collapsing every other chord in both directions.
    let m = shapes::torus(24, 16, 3.0, 1.0);
    let c = coarsen(&m, &CoarsenConfig::default(), &mut Rng::new(1));
    let s = check_quad_mesh(&c);
    assert_eq!(s.euler(), 0);
    assert!(c.quads.len() * 4 <= m.quads.len() + 40, "{} of {} faces left", c.quads.len(), m.quads.len());
    assert!(c.quads.len() < m.quads.len());
}

#[test]
fn a_non_manifold_input_comes_back_unchanged() {
    // Three flaps hinged on the edge 0–1 (x axis), at 0°, 120° and 240° around it. A
    // strip across one flap alone would collapse (and leave a valid two-flap mesh), so
    // only the validity check of the input keeps it unchanged.
    let mut vertices = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
    let mut quads = Vec::new();
    for k in 0..3u32 {
        let a = f64::from(k) * 2.0 * std::f64::consts::PI / 3.0;
        let (y, z) = (a.cos(), a.sin());
        vertices.push([1.0, y, z]);
        vertices.push([0.0, y, z]);
        quads.push([0, 1, 2 + 2 * k, 3 + 2 * k]);
    }
    let m = QuadMesh { vertices, quads };
    assert!(HalfedgeMesh::from_quads(m.vertices.len(), &m.quads).is_err());
    assert_eq!(coarsen(&m, &CoarsenConfig::default(), &mut Rng::new(0)), m);
}

#[test]
fn a_collapse_that_would_fold_a_face_is_refused() {
    // A 3 × 3 grid with the vertex line x = 2 lifted high: collapsing the column
    // x ∈ [1, 2] moves that line's vertices to x = 1.5, turning the faces beside it
    // from steep to flat; a strict normal bound refuses it, a loose one accepts it.
    let g = shapes::grid(3, 3, 3.0, 3.0);
    let mut bent = g.clone();
    // Lift the middle row of vertices far up: faces beside the collapsed column turn.
    for p in bent.vertices.iter_mut() {
        if p[0] == 2.0 {
            p[2] = 10.0;
        }
    }
    let e = edge_map(&bent.quads);
    // The column through face 0's neighbour at x ∈ [1, 2].
    let f = 1;
    let side = (0..4)
        .find(|&s| {
            let q = bent.quads[f];
            bent.vertices[q[s] as usize][1] == bent.vertices[q[(s + 1) % 4] as usize][1]
        })
        .unwrap();
    let ch = chord(&bent.quads, &e, f, side).unwrap();
    let strict = CoarsenConfig { min_normal_dot: 0.99, ..Default::default() };
    assert!(collapse(&bent.vertices, &bent.quads, &ch, &strict).is_none());
    let loose = CoarsenConfig { min_normal_dot: -1.0, min_scaled_jacobian: -1.0, ..Default::default() };
    assert!(collapse(&bent.vertices, &bent.quads, &ch, &loose).is_some());
}
