//! The closing of loops the hole filling leaves (`mesh::close`) and the rescue of
//! candidates at holes (`mesh::rescue`): the quadrangulation's optimum against brute
//! force, and mesh invariants (validator, border never longer) on grids with holes.

use point2quad::mesh::close::{
    close_holes, quadrangulate, quadrangulate_with, seal, untangle, untangle_with_candidates, CloseConfig,
    CloseReport,
};
use point2quad::mesh::halfedge::{corner_set, HalfedgeMesh};
use point2quad::mesh::handles::FaceId;
use point2quad::mesh::rescue::{rescue_faces, RescueConfig};
use point2quad::mesh::shapes::grid;
use point2quad::mesh::validate::validate;
use proptest::prelude::*;

/// Scaled Jacobian of a planar quad in the xy plane with corners in order, by its own
/// formula (min over corners of the sine of the corner angle, signed).
fn sj(p: &[[f64; 3]; 4]) -> f64 {
    (0..4)
        .map(|i| {
            let a = p[(i + 3) % 4];
            let b = p[i];
            let c = p[(i + 1) % 4];
            let (e0, e1) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
            (e0[0] * e1[1] - e0[1] * e1[0]) / ((e0[0].hypot(e0[1])) * (e1[0].hypot(e1[1])))
        })
        .fold(f64::INFINITY, f64::min)
}

fn area(p: &[[f64; 3]]) -> f64 {
    let n = p.len();
    0.5 * (0..n).map(|i| p[i][0] * p[(i + 1) % n][1] - p[(i + 1) % n][0] * p[i][1]).sum::<f64>()
}

/// Least Σ(1 − SJ + extra) over every set of n/2 − 1 quads on the vertices of the convex
/// polygon `pts` whose interiors are disjoint and whose areas add up to the polygon's;
/// `extra` sees a quad's corner indices in increasing order.
fn brute_force(pts: &[[f64; 3]], extra: &dyn Fn([usize; 4]) -> f64) -> f64 {
    let n = pts.len();
    let mut quads: Vec<[usize; 4]> = Vec::new();
    for a in 0..n {
        for b in a + 1..n {
            for c in b + 1..n {
                for d in c + 1..n {
                    quads.push([a, b, c, d]);
                }
            }
        }
    }
    // Two quads of a convex polygon have disjoint interiors iff all of one's vertices lie
    // in one closed arc between consecutive vertices of the other.
    let disjoint = |x: &[usize; 4], y: &[usize; 4]| {
        (0..4).any(|k| {
            let (lo, hi) = (x[k], x[(k + 1) % 4]);
            y.iter().all(|&v| if lo < hi { v >= lo && v <= hi } else { v >= lo || v <= hi })
        })
    };
    let total = area(pts);
    let k = n / 2 - 1;
    let mut best = f64::INFINITY;
    let mut chosen: Vec<usize> = Vec::new();
    fn rec(
        start: usize,
        k: usize,
        quads: &[[usize; 4]],
        chosen: &mut Vec<usize>,
        f: &mut dyn FnMut(&[usize]),
        ok: &dyn Fn(&[usize; 4], &[usize; 4]) -> bool,
    ) {
        if chosen.len() == k {
            f(chosen);
            return;
        }
        for q in start..quads.len() {
            if chosen.iter().all(|&c| ok(&quads[c], &quads[q])) {
                chosen.push(q);
                rec(q + 1, k, quads, chosen, f, ok);
                chosen.pop();
            }
        }
    }
    let mut visit = |set: &[usize]| {
        let qp: Vec<[[f64; 3]; 4]> = set.iter().map(|&q| quads[q].map(|v| pts[v])).collect();
        let a: f64 = qp.iter().map(|p| area(p)).sum();
        if (a - total).abs() < 1e-9 * total.abs().max(1.0) {
            let extras: f64 = set.iter().map(|&q| extra(quads[q])).sum();
            best = best.min(qp.iter().map(|p| 1.0 - sj(p)).sum::<f64>() + extras);
        }
    };
    rec(0, k, &quads, &mut chosen, &mut visit, &disjoint);
    best
}

/// Points on the unit circle (a convex polygon), one per gap, spaced by the gaps' shares
/// of the full turn.
fn circle_polygon(gaps: &[f64]) -> Vec<[f64; 3]> {
    let sum: f64 = gaps.iter().sum();
    let mut t = 0.0;
    gaps.iter()
        .map(|g| {
            t += g / sum * std::f64::consts::TAU;
            [t.cos(), t.sin(), 0.0]
        })
        .collect()
}

fn boundary_edges(m: &HalfedgeMesh) -> usize {
    m.boundary_loops().iter().map(Vec::len).sum()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// On points of a circle (always a convex polygon), the quadrangulation's cost is the
    /// brute-force optimum, and its quads partition the polygon.
    #[test]
    fn quadrangulation_is_optimal(half in 2usize..5, gaps in prop::collection::vec(0.2f64..1.0, 8)) {
        let n = 2 * half;
        let pts = circle_polygon(&gaps[..n]);
        let mesh = HalfedgeMesh::new(n);
        let vs: Vec<u32> = (0..n as u32).collect();
        let quads = quadrangulate(&mesh, &pts, &vs, &vec![None; n], &CloseConfig::default()).unwrap();
        prop_assert_eq!(quads.len(), n / 2 - 1);
        let qp: Vec<[[f64; 3]; 4]> = quads.iter().map(|q| q.map(|v| pts[v as usize])).collect();
        let a: f64 = qp.iter().map(|p| area(p)).sum();
        prop_assert!((a - area(&pts)).abs() < 1e-9, "quads do not tile the polygon");
        let cost: f64 = qp.iter().map(|p| 1.0 - sj(p)).sum();
        let best = brute_force(&pts, &|_| 0.0);
        prop_assert!((cost - best).abs() < 1e-9, "cost {} vs brute force {}", cost, best);
    }

    /// With an extra cost per quad (here a hash of its corners, as the seal's support
    /// term is per corner set), the quadrangulation is still the brute-force optimum.
    #[test]
    fn quadrangulation_with_extra_cost_is_optimal(
        half in 2usize..5,
        gaps in prop::collection::vec(0.2f64..1.0, 8),
        salt in any::<u64>(),
    ) {
        let n = 2 * half;
        let pts = circle_polygon(&gaps[..n]);
        let extra = |q: [usize; 4]| {
            let h = q.iter().fold(salt, |h, &v| (h ^ v as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
            (h >> 11) as f64 / (1u64 << 53) as f64 * 2.0
        };
        let mesh = HalfedgeMesh::new(n);
        let vs: Vec<u32> = (0..n as u32).collect();
        let by_ids = |q: [u32; 4]| extra(q.map(|v| v as usize));
        let quads = quadrangulate_with(&mesh, &pts, &vs, &vec![None; n], &CloseConfig::default(), &by_ids).unwrap();
        prop_assert_eq!(quads.len(), n / 2 - 1);
        let cost: f64 = quads.iter().map(|q| 1.0 - sj(&q.map(|v| pts[v as usize])) + by_ids(*q)).sum();
        let best = brute_force(&pts, &extra);
        prop_assert!((cost - best).abs() < 1e-9, "cost {} vs brute force {}", cost, best);
    }

    /// Grids with faces removed at random: closing keeps the mesh valid, never lengthens
    /// the border, adds no vertex, and closes every interior hole of one face pair or
    /// less exactly as it was.
    #[test]
    fn closing_keeps_the_mesh_valid(nu in 3usize..8, nv in 3usize..8, seed in any::<u64>(), share in 0.05f64..0.5) {
        let g = grid(nu, nv, nu as f64, nv as f64);
        let mut rng = point2quad::rng::Rng::new(seed);
        let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &g.quads).unwrap();
        for f in 0..g.quads.len() {
            if rng.uniform(0.0, 1.0) < share {
                let _ = mesh.remove_face(FaceId(f as u32));
            }
        }
        validate(&mesh).unwrap();
        let (faces0, border0) = (mesh.n_faces(), boundary_edges(&mesh));
        let r = close_holes(&mut mesh, &g.vertices, &CloseConfig::default());
        validate(&mesh).unwrap();
        prop_assert!(boundary_edges(&mesh) <= border0);
        prop_assert_eq!(mesh.n_faces(), faces0 - r.faces_removed + r.quads_added);
        prop_assert_eq!(mesh.n_vertices(), g.vertices.len());
        for f in mesh.faces() {
            let p = mesh.face_vertices(f).map(|v| g.vertices[v.idx()]);
            prop_assert!(sj(&p) > 0.0, "a reflex or flat corner {:?}", p);
        }
    }

    /// Sparse holes (no two removed faces share a vertex) are tiled back exactly by the
    /// rescue from a pool of the true faces and less probable wrong quads over the same
    /// corners; the border never gets longer and only pool faces above min_prob go in.
    #[test]
    fn rescue_restores_sparse_holes(n in 3usize..8, seed in any::<u64>()) {
        let g = grid(n, n, n as f64, n as f64);
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let mut rng = point2quad::rng::Rng::new(seed);
        let mut removed = vec![false; n * n];
        for f in 0..n * n {
            let (i, j) = (f % n, f / n);
            // No two removed faces share a vertex (that vertex would hold two fans).
            let nb_removed = (i > 0 && removed[f - 1])
                || (j > 0 && (removed[f - n] || (i > 0 && removed[f - n - 1]) || (i + 1 < n && removed[f - n + 1])));
            // The corner face always goes: there the true face and its rival glue on
            // the same number of edges and only the probability decides.
            if !nb_removed && (f == 0 || rng.uniform(0.0, 1.0) < 0.3) {
                removed[f] = true;
            }
        }
        let kept: Vec<[u32; 4]> = (0..n * n).filter(|&f| !removed[f]).map(|f| g.quads[f]).collect();
        prop_assume!(!kept.is_empty());
        // Two extra isolated vertices per face for the rivals to leave through.
        let nv = g.vertices.len();
        let mut mesh = HalfedgeMesh::from_quads(nv + 2 * n * n, &kept).unwrap();
        let mut pool_faces = Vec::new();
        let mut probs = Vec::new();
        let mut open = Vec::new();
        // The extra vertices sit on the corners they replace, so the wrong quads lie
        // flat over their holes, facing as the mesh does (not folded over it).
        let mut pos = g.vertices.clone();
        pos.resize(nv + 2 * n * n, [0.0; 3]);
        for f in (0..n * n).filter(|&f| removed[f]) {
            let (i, j) = (f % n, f / n);
            let (x, y) = ((nv + 2 * f) as u32, (nv + 2 * f + 1) as u32);
            pos[x as usize] = g.vertices[id(i, j) as usize];
            pos[y as usize] = g.vertices[id(i + 1, j + 1) as usize];
            pool_faces.push(g.quads[f]);
            if f != 0 && rng.uniform(0.0, 1.0) < 0.2 {
                // Offered only below min_prob: this hole stays open.
                probs.push(0.05);
                open.push(f);
                continue;
            }
            probs.push(0.3 + 0.6 * rng.uniform(0.0, 1.0) as f32);
            // A wrong kite on the face's corner (i + 1, j + 1), over its right and top
            // sides, less probable than the true face.
            pool_faces.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1), x]);
            probs.push(0.25);
            // A likelier one on the opposite corner, but below min_prob.
            pool_faces.push([id(i, j + 1), id(i, j), id(i + 1, j), y]);
            probs.push(0.05);
        }
        let border0 = boundary_edges(&mesh);
        let pool: Vec<usize> = (0..pool_faces.len()).collect();
        let cfg = RescueConfig::default();
        let got = rescue_faces(&mut mesh, &pos, &pool_faces, &probs, &pool, &cfg);
        validate(&mesh).unwrap();
        prop_assert!(boundary_edges(&mesh) <= border0);
        prop_assert!(got.iter().all(|&c| probs[c] >= cfg.min_prob));
        let mut want: Vec<[u32; 4]> = g.quads.iter().enumerate().filter(|(f, _)| !open.contains(f)).map(|(_, q)| q).map(|q| { let mut k = *q; k.sort_unstable(); k }).collect();
        want.sort_unstable();
        let mut have: Vec<[u32; 4]> = mesh.faces().map(|f| { let mut k = mesh.face_vertices(f).map(|v| v.0); k.sort_unstable(); k }).collect();
        have.sort_unstable();
        prop_assert_eq!(have, want);
    }
}

/// Two triangle holes left by a wrong quad over the diagonal of two true ones: the
/// pairing removes it and the two true quads come back.
#[test]
fn a_diagonal_quad_between_two_triangles_is_replaced_by_the_true_pair() {
    let g = grid(4, 3, 4.0, 3.0);
    let id = |i: u32, j: u32| j * 5 + i;
    // True faces (1, 1) and (2, 1) make the hexagon a b c d e f.
    let (a, b, c, d, e, f) = (id(1, 1), id(2, 1), id(3, 1), id(3, 2), id(2, 2), id(1, 2));
    let key = |q: [u32; 4]| {
        let mut k = q;
        k.sort_unstable();
        k
    };
    let dropped = [key([a, b, e, f]), key([b, c, d, e])];
    let mut faces: Vec<[u32; 4]> = g.quads.iter().copied().filter(|q| !dropped.contains(&key(*q))).collect();
    assert_eq!(faces.len(), g.quads.len() - 2);
    faces.push([a, b, d, e]);
    let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
    let lens: Vec<usize> = mesh.boundary_loops().iter().map(Vec::len).filter(|&l| l == 3).collect();
    assert_eq!(lens.len(), 2, "two triangle holes");
    let r = close_holes(&mut mesh, &g.vertices, &CloseConfig::default());
    validate(&mesh).unwrap();
    assert_eq!((r.faces_removed, r.quads_added, r.loops_closed), (1, 2, 1), "{r:?}");
    let mut have: Vec<[u32; 4]> = mesh.faces().map(|f| key(mesh.face_vertices(f).map(|v| v.0))).collect();
    have.sort_unstable();
    let mut want: Vec<[u32; 4]> = g.quads.iter().map(|q| key(*q)).collect();
    want.sort_unstable();
    assert_eq!(have, want);
    // Without the pairing the triangles stay.
    let mut m2 = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
    let r2 = close_holes(&mut m2, &g.vertices, &CloseConfig { pair_odd_loops: false, ..Default::default() });
    assert_eq!(r2.quads_added, 0);
}

/// A two-face hole is closed over its own vertices with the true chord.
#[test]
fn a_hexagon_hole_is_quadrangulated_back() {
    let g = grid(4, 4, 4.0, 4.0);
    let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &g.quads).unwrap();
    mesh.remove_face(FaceId(5)).unwrap();
    mesh.remove_face(FaceId(6)).unwrap();
    let r = close_holes(&mut mesh, &g.vertices, &CloseConfig::default());
    validate(&mesh).unwrap();
    assert_eq!((r.quads_added, r.loops_closed, r.faces_removed), (2, 1, 0));
    assert_eq!(mesh.n_faces(), 16);
    assert_eq!(boundary_edges(&mesh), 16, "only the outer border");
    let off = close_holes(&mut mesh, &g.vertices, &CloseConfig { enabled: false, ..Default::default() });
    assert_eq!(off.quads_added, 0);
}

/// Borders are not holes: the open ends of tubes (normals all round) and the outer border
/// of a sheet (it turns the other way) stay open, and an already closed mesh is unchanged.
#[test]
fn borders_of_open_surfaces_stay_open() {
    use point2quad::mesh::shapes;
    let mut cases = vec![("sheet", grid(5, 3, 5.0, 3.0))];
    for n in [4, 6, 8, 12, 16] {
        cases.push(("tube", shapes::cylinder(n, 3, 1.0, 1.5, false)));
    }
    cases.push(("closed", shapes::cube_sphere(4)));
    for (name, q) in cases {
        let mut mesh = HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).unwrap();
        let before = mesh.clone();
        let r = close_holes(&mut mesh, &q.vertices, &CloseConfig::default());
        assert_eq!(r.quads_added, 0, "{name}: {r:?}");
        assert_eq!(mesh, before, "{name}");
    }
    // The same tube end, seen as a hole by a configuration without the border tests, is
    // closed: the tests are what keeps it open.
    let q = shapes::cylinder(8, 3, 1.0, 1.5, false);
    let mut mesh = HalfedgeMesh::from_quads(q.vertices.len(), &q.quads).unwrap();
    let lax = CloseConfig { min_loop_coherence: 0.0, min_loop_alignment: -1.0, ..Default::default() };
    assert!(close_holes(&mut mesh, &q.vertices, &lax).quads_added > 0);
}

/// Sorted corner sets of a mesh's faces, and its boundary half-edges as (from, to).
fn face_keys(m: &HalfedgeMesh) -> Vec<[u32; 4]> {
    m.corner_sets()
}

fn border_set(m: &HalfedgeMesh) -> Vec<(u32, u32)> {
    let mut v: Vec<(u32, u32)> =
        m.boundary_loops().iter().flatten().map(|&h| (m.from_vertex(h).0, m.to_vertex(h).0)).collect();
    v.sort_unstable();
    v
}

/// Scaled Jacobian of a face by the metric's formula (diagonal normal), in 3-D.
fn sj3(p: &[[f64; 3]; 4]) -> f64 {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let n = cross(sub(p[2], p[0]), sub(p[3], p[1]));
    let ln = dot(n, n).sqrt();
    (0..4)
        .map(|i| {
            let (e0, e1) = (sub(p[i], p[(i + 3) % 4]), sub(p[(i + 1) % 4], p[i]));
            dot(cross(e0, e1), n) / (ln * dot(e0, e0).sqrt() * dot(e1, e1).sqrt())
        })
        .fold(f64::INFINITY, f64::min)
}

/// Grid faces (i, j) and (i + 1, j) (or (i, j + 1) when `vertical`) as their hexagon's
/// other split by the chord from corner `which` (0 or 1): two quads over the same six
/// vertices, one of them with a straight corner on a regular grid.
fn resplit(n: usize, i: usize, j: usize, vertical: bool, which: usize) -> ([usize; 2], [[u32; 4]; 2]) {
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    // The hexagon in the grid's orientation, starting at the pair's first corner.
    let (hex, faces) = if vertical {
        (
            [id(i + 1, j), id(i + 1, j + 1), id(i + 1, j + 2), id(i, j + 2), id(i, j + 1), id(i, j)],
            [j * n + i, (j + 1) * n + i],
        )
    } else {
        (
            [id(i, j), id(i + 1, j), id(i + 2, j), id(i + 2, j + 1), id(i + 1, j + 1), id(i, j + 1)],
            [j * n + i, j * n + i + 1],
        )
    };
    // The true chord joins hexagon corners 1 and 4; the others are 0–3 and 2–5.
    let a = if which == 0 { 0 } else { 2 };
    let q1 = [hex[a], hex[a + 1], hex[a + 2], hex[(a + 3) % 6]];
    let q2 = [hex[(a + 3) % 6], hex[(a + 4) % 6], hex[(a + 5) % 6], hex[a]];
    (faces, [q1, q2])
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// One face pair of a regular grid re-split the wrong way (each new quad has a straight
    /// corner) is put back exactly: the brute-force reference is the grid itself.
    #[test]
    fn untangle_restores_a_wrongly_split_pair(n in 3usize..7, i in 0usize..5, j in 0usize..5, vertical: bool, which in 0usize..2) {
        let (i, j) = (i % (n - 1), j % (n - 1));
        let g = grid(n, n, n as f64, n as f64);
        let (drop, add) = resplit(n, i, j, vertical, which);
        let mut faces: Vec<[u32; 4]> = g.quads.iter().enumerate().filter(|(k, _)| !drop.contains(k)).map(|(_, q)| *q).collect();
        faces.extend(add);
        let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
        let border0 = border_set(&mesh);
        let replaced = untangle(&mut mesh, &g.vertices, &CloseConfig::default(), &|_| 0.0);
        validate(&mesh).unwrap();
        prop_assert_eq!(replaced, 2);
        prop_assert_eq!(face_keys(&mesh), face_keys(&HalfedgeMesh::from_quads(g.vertices.len(), &g.quads).unwrap()));
        prop_assert_eq!(border_set(&mesh), border0);
    }

    /// Jittered grids with several pairs re-split the wrong way: untangling keeps the mesh
    /// valid, the border, the vertices in use and the face count unchanged, never lowers
    /// the worst scaled Jacobian nor raises Σ(1 − SJ), and leaves no face under the bound
    /// that a one-neighbour re-split over the jittered grid's own pair would have fixed
    /// when every pair is far from the others.
    #[test]
    fn untangle_keeps_border_and_vertices_and_improves_shape(
        n in 4usize..9, seed in any::<u64>(), jitter in 0.0f64..0.3, pairs in 1usize..6,
    ) {
        let g = grid(n, n, n as f64, n as f64);
        let mut rng = point2quad::rng::Rng::new(seed);
        let mut pos = g.vertices.clone();
        for p in pos.iter_mut() {
            p[0] += rng.uniform(-jitter, jitter);
            p[1] += rng.uniform(-jitter, jitter);
            p[2] += rng.uniform(-jitter, jitter);
        }
        let mut used = vec![false; g.quads.len()];
        let mut faces: Vec<[u32; 4]> = Vec::new();
        for _ in 0..pairs {
            let (i, j) = ((rng.uniform(0.0, 1.0) * (n - 1) as f64) as usize, (rng.uniform(0.0, 1.0) * (n - 1) as f64) as usize);
            let (drop, add) = resplit(n, i.min(n - 2), j.min(n - 2), rng.uniform(0.0, 1.0) < 0.5, (rng.uniform(0.0, 1.0) * 2.0) as usize % 2);
            if drop.iter().any(|&k| used[k]) {
                continue;
            }
            for k in drop {
                used[k] = true;
            }
            faces.extend(add);
        }
        faces.extend(g.quads.iter().enumerate().filter(|(k, _)| !used[*k]).map(|(_, q)| *q));
        let mut mesh = HalfedgeMesh::from_quads(pos.len(), &faces).unwrap();
        let shape = |m: &HalfedgeMesh| {
            let s: Vec<f64> = m.faces().map(|f| sj3(&m.face_vertices(f).map(|v| pos[v.idx()]))).collect();
            (s.iter().cloned().fold(f64::INFINITY, f64::min), s.iter().map(|x| 1.0 - x).sum::<f64>())
        };
        let in_use = |m: &HalfedgeMesh| {
            let mut v: Vec<u32> = m.faces().flat_map(|f| m.face_vertices(f)).map(|v| v.0).collect();
            v.sort_unstable();
            v.dedup();
            v
        };
        let (border0, used0, n0, (min0, cost0)) = (border_set(&mesh), in_use(&mesh), mesh.n_faces(), shape(&mesh));
        let replaced = untangle(&mut mesh, &pos, &CloseConfig::default(), &|_| 0.0);
        validate(&mesh).unwrap();
        prop_assert_eq!(border_set(&mesh), border0);
        prop_assert_eq!(in_use(&mesh), used0);
        prop_assert_eq!(mesh.n_faces(), n0);
        let (min1, cost1) = shape(&mesh);
        prop_assert!(min1 >= min0 - 1e-12, "worst SJ {} -> {}", min0, min1);
        prop_assert!(cost1 <= cost0 + 1e-9, "cost {} -> {}", cost0, cost1);
        if replaced == 0 {
            // (A re-split that `add_face` refused is undone: same faces, other order.)
            prop_assert!((cost1 - cost0).abs() < 1e-9, "cost {} -> {}", cost0, cost1);
        } else {
            prop_assert!(cost1 < cost0);
        }
    }
}

/// The classifier's word wins over shape: a wrongly split pair is not re-split when the
/// classifier believes its two faces more than the true pair, and is when it believes
/// the true pair (or neither).
#[test]
fn untangle_never_trades_believed_faces_for_less_believed_ones() {
    let n = 4;
    let g = grid(n, n, n as f64, n as f64);
    let (drop, add) = resplit(n, 1, 1, false, 0);
    let mut faces: Vec<[u32; 4]> =
        g.quads.iter().enumerate().filter(|(k, _)| !drop.contains(k)).map(|(_, q)| *q).collect();
    faces.extend(add);
    let wrong: Vec<[u32; 4]> = add.iter().map(|&q| corner_set(q)).collect();
    let right: Vec<[u32; 4]> = drop.iter().map(|&f| corner_set(g.quads[f])).collect();
    let truth = face_keys(&HalfedgeMesh::from_quads(g.vertices.len(), &g.quads).unwrap());
    for (p_wrong, p_right, fixed) in
        [(0.9f32, 0.0f32, false), (0.9, 0.4, false), (0.2, 0.3, true), (0.0, 0.0, true)]
    {
        let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
        let support = |k: [u32; 4]| {
            if wrong.contains(&k) {
                p_wrong
            } else if right.contains(&k) {
                p_right
            } else {
                0.0
            }
        };
        let replaced = untangle(&mut mesh, &g.vertices, &CloseConfig::default(), &support);
        validate(&mesh).unwrap();
        assert_eq!(replaced == 2, fixed, "p {p_wrong} / {p_right}: replaced {replaced}");
        assert_eq!(face_keys(&mesh) == truth, fixed);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Reading the support from candidate lists, restricted to the candidates near bad
    /// faces, gives the same mesh as a table of every candidate (the reference): wrong
    /// pairs on a jittered grid, each face of the grid and of the wrong splits a candidate
    /// with a random probability, some listed twice.
    #[test]
    fn untangle_with_candidates_equals_the_full_table(n in 4usize..8, seed in any::<u64>(), pairs in 1usize..5) {
        let g = grid(n, n, n as f64, n as f64);
        let mut rng = point2quad::rng::Rng::new(seed);
        let mut pos = g.vertices.clone();
        for p in pos.iter_mut() {
            p[0] += rng.uniform(-0.1, 0.1);
            p[1] += rng.uniform(-0.1, 0.1);
        }
        let mut used = vec![false; g.quads.len()];
        let mut faces: Vec<[u32; 4]> = Vec::new();
        let mut cands: Vec<[u32; 4]> = g.quads.clone();
        for _ in 0..pairs {
            let (i, j) = (rng.below(n - 1), rng.below(n - 1));
            let (drop, add) = resplit(n, i, j, rng.below(2) == 1, rng.below(2));
            if drop.iter().any(|&k| used[k]) {
                continue;
            }
            for k in drop {
                used[k] = true;
            }
            faces.extend(add);
            cands.extend(add.map(|q| [q[1], q[2], q[3], q[0]]));
        }
        faces.extend(g.quads.iter().enumerate().filter(|(k, _)| !used[*k]).map(|(_, q)| *q));
        let probs: Vec<f32> = cands.iter().map(|_| rng.uniform(0.0, 1.0) as f32).collect();
        let (extra, extra_p): (Vec<[u32; 4]>, Vec<f32>) =
            cands.iter().step_by(3).map(|&q| (q, rng.uniform(0.0, 1.0) as f32)).unzip();
        let mut full: std::collections::HashMap<[u32; 4], f32> = std::collections::HashMap::new();
        for (q, &p) in cands.iter().zip(&probs).chain(extra.iter().zip(&extra_p)) {
            let e = full.entry(corner_set(*q)).or_insert(p);
            *e = e.max(p);
        }
        let cfg = CloseConfig::default();
        let mut a = HalfedgeMesh::from_quads(pos.len(), &faces).unwrap();
        let mut b = HalfedgeMesh::from_quads(pos.len(), &faces).unwrap();
        let ra = untangle(&mut a, &pos, &cfg, &|k| full.get(&k).copied().unwrap_or(0.0));
        let rb = untangle_with_candidates(&mut b, &pos, &cfg, &[(&cands, &probs), (&extra, &extra_p)]);
        prop_assert_eq!(ra, rb);
        prop_assert_eq!(a.corner_sets(), b.corner_sets());
    }
}

/// Corner lists or sorted corner sets of quads.
type Quads = Vec<[u32; 4]>;

/// A grid whose row-1 faces 1..=k+1 are replaced by k sheared quads, which leaves a
/// triangle hole at each end of the strip, k faces apart (further than `close_holes`
/// pairs). Returns the grid, the faces, and the sheared quads' and strip's corner sets.
fn sheared_strip(k: u32) -> (point2quad::mesh::poly::QuadMesh, Quads, Quads, Quads) {
    let nu = k + 4;
    let g = grid(nu as usize, 4, nu as f64, 4.0);
    let id = |i: u32, j: u32| j * (nu + 1) + i;
    let strip: Vec<[u32; 4]> =
        (1..=k + 1).map(|i| corner_set([id(i, 1), id(i + 1, 1), id(i + 1, 2), id(i, 2)])).collect();
    let sheared: Vec<[u32; 4]> =
        (1..=k).map(|i| [id(i, 1), id(i + 1, 1), id(i + 2, 2), id(i + 1, 2)]).collect();
    let mut faces: Vec<[u32; 4]> =
        g.quads.iter().copied().filter(|q| !strip.contains(&corner_set(*q))).collect();
    faces.extend(&sheared);
    let sheared_keys = sheared.iter().map(|&q| corner_set(q)).collect();
    (g, faces, sheared_keys, strip)
}

/// Two triangle holes joined by a strip of four sheared quads: `close_holes` cannot pair
/// them (its paths are at most two faces), the seal takes the strip out and splits it
/// back into the true quads, which the classifier supports more.
#[test]
fn the_seal_replaces_a_sheared_strip_between_two_triangles() {
    let (g, faces, sheared, strip) = sheared_strip(4);
    let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
    let triangles = mesh.boundary_loops().iter().filter(|l| l.len() == 3).count();
    assert_eq!(triangles, 2);
    let before = mesh.clone();
    assert_eq!(close_holes(&mut mesh, &g.vertices, &CloseConfig::default()).quads_added, 0);
    assert_eq!(mesh, before, "close_holes reaches two faces only");
    let support = |k: [u32; 4]| if sheared.contains(&k) { 0.6 } else { 0.9 };
    let mut r = CloseReport::default();
    seal(&mut mesh, &g.vertices, &CloseConfig::default(), &support, &mut r);
    validate(&mesh).unwrap();
    assert_eq!((r.sealed, r.seal_removed, r.seal_added), (1, 4, 5), "{r:?}");
    let mut want: Vec<[u32; 4]> = g.quads.iter().map(|&q| corner_set(q)).collect();
    want.sort_unstable();
    assert_eq!(face_keys(&mesh), want);
    assert!(strip.iter().all(|k| face_keys(&mesh).contains(k)));
    // Switched off, nothing happens.
    let mut m2 = before.clone();
    seal(
        &mut m2,
        &g.vertices,
        &CloseConfig { seal: false, ..Default::default() },
        &support,
        &mut CloseReport::default(),
    );
    assert_eq!(m2, before);
}

/// The seal never trades faces the classifier believes for ones it believes less: with
/// the true strip unsupported and the sheared quads believed, the mesh stays as it is
/// (the faces around it are believed too, so no path through them is cheap).
#[test]
fn the_seal_keeps_believed_faces() {
    let (g, faces, sheared, strip) = sheared_strip(4);
    let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
    let before = face_keys(&mesh);
    let support = |k: [u32; 4]| {
        if sheared.contains(&k) {
            0.9
        } else if strip.contains(&k) {
            0.0
        } else {
            1.0
        }
    };
    let mut r = CloseReport::default();
    seal(&mut mesh, &g.vertices, &CloseConfig::default(), &support, &mut r);
    assert_eq!(r.sealed, 0, "{r:?}");
    validate(&mesh).unwrap();
    assert_eq!(face_keys(&mesh), before, "attempts put their faces back");
    // Without the guard (keep 0) the strip goes, and the split it gets back is the
    // best-shaped one: the true quads.
    let lax = CloseConfig { seal_keep_support: 0.0, ..Default::default() };
    seal(&mut mesh, &g.vertices, &lax, &support, &mut r);
    assert_eq!(r.sealed, 1, "{r:?}");
    assert!(strip.iter().all(|k| face_keys(&mesh).contains(k)));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Grids with faces removed and sheared strips put in at random: the seal keeps the
    /// mesh valid, never lengthens the border, adds no vertex, puts in only quads that
    /// meet the closing's shape bound, and closes a lone sheared strip exactly.
    #[test]
    fn the_seal_keeps_the_mesh_valid(k in 3u32..7, seed in any::<u64>(), share in prop::sample::select(vec![0.0, 0.05, 0.1, 0.2])) {
        let (g, faces, sheared, _) = sheared_strip(k);
        let mut rng = point2quad::rng::Rng::new(seed);
        let mut mesh = HalfedgeMesh::from_quads(g.vertices.len(), &faces).unwrap();
        for (f, q) in faces.iter().enumerate() {
            // Removals that would leave a corner with two fans are refused; skip those.
            if !sheared.contains(&corner_set(*q)) && rng.uniform(0.0, 1.0) < share {
                let _ = mesh.remove_face(FaceId(f as u32));
            }
        }
        let border0: usize = mesh.boundary_loops().iter().map(Vec::len).sum();
        let old = face_keys(&mesh);
        let support = |q: [u32; 4]| if sheared.contains(&q) { 0.5 } else { 0.9 };
        let mut r = CloseReport::default();
        seal(&mut mesh, &g.vertices, &CloseConfig::default(), &support, &mut r);
        validate(&mesh).unwrap();
        let border: usize = mesh.boundary_loops().iter().map(Vec::len).sum();
        prop_assert!(border <= border0, "border {} > {}", border, border0);
        prop_assert_eq!(mesh.n_vertices(), g.vertices.len());
        prop_assert_eq!(mesh.n_faces() + r.seal_removed, old.len() + r.seal_added);
        for f in mesh.faces() {
            let c = mesh.face_vertices(f).map(|v| v.0);
            if !old.contains(&corner_set(c)) {
                prop_assert!(sj3(&c.map(|v| g.vertices[v as usize])) >= 0.02, "new quad {:?}", c);
            }
        }
        if share == 0.0 {
            prop_assert_eq!(r.sealed, 1);
        }
    }
}

/// Folded edges of `mesh`: interior edges whose two quads' normals (cross product of the
/// diagonals, normalised) have a dot under `bound`, as (less probable face, other face).
fn folded_edges(mesh: &HalfedgeMesh, pos: &[[f64; 3]], probs: &[f32], bound: f64) -> Vec<(FaceId, FaceId)> {
    let normal = |f: FaceId| {
        let p = mesh.face_vertices(f).map(|v| pos[v.idx()]);
        let (a, b) = (
            [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]],
            [p[3][0] - p[1][0], p[3][1] - p[1][1], p[3][2] - p[1][2]],
        );
        let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
        let n = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        c.map(|x| x / n)
    };
    let mut out = Vec::new();
    for f in mesh.faces() {
        for h in mesh.face_halfedges(f) {
            if let Some(g) = mesh.face(h.opposite()) {
                let (nf, ng) = (normal(f), normal(g));
                if f.idx() < g.idx() && nf[0] * ng[0] + nf[1] * ng[1] + nf[2] * ng[2] < bound {
                    let f_loses = (probs[f.idx()], g.idx()) < (probs[g.idx()], f.idx());
                    out.push(if f_loses { (f, g) } else { (g, f) });
                }
            }
        }
    }
    out
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Session 25's unfold on a flat grid with flaps hinged on its bottom and top border
    /// edges at random angles (some folded back over the grid, some creases) and random
    /// probabilities: the mesh stays valid, only faces on a folded edge of the input go,
    /// and every folded edge left is one where neither face can go (each removal would
    /// split a vertex's fan), checked by trying both on a copy. (With the unfold off the
    /// last check fails: the flaps fold.)
    #[test]
    fn unfold_leaves_only_folds_it_cannot_take_out(
        nx in 2usize..6,
        ny in 1usize..4,
        flaps in proptest::collection::vec((any::<bool>(), 0usize..6, 0usize..7), 1..8),
        seed in any::<u64>(),
    ) {
        let g = grid(nx, ny, nx as f64, ny as f64);
        let id = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
        let mut pos = g.vertices.clone();
        let mut quads = g.quads.clone();
        let base = HalfedgeMesh::from_quads(pos.len(), &quads).unwrap();
        let mut used = std::collections::HashSet::new();
        for (top, i, angle) in flaps {
            let i = i % nx;
            if !used.insert((top, i)) {
                continue;
            }
            let j = if top { ny } else { 0 };
            let (a, b) = (id(i, j), id(i + 1, j));
            let deg = [0.0f64, 60.0, 120.0, 150.0, 165.0, 172.0, 180.0][angle];
            let t = deg.to_radians();
            let out = if top { 1.0 } else { -1.0 };
            let d = [0.0, out * t.cos(), t.sin()];
            let (pa, pb) = (pos[a as usize], pos[b as usize]);
            let (xa, xb) = (pos.len() as u32, pos.len() as u32 + 1);
            pos.push([pa[0] + d[0], pa[1] + d[1], pa[2] + d[2]]);
            pos.push([pb[0] + d[0], pb[1] + d[1], pb[2] + d[2]]);
            let h = base.find_halfedge(point2quad::mesh::handles::VertexId(a), point2quad::mesh::handles::VertexId(b));
            let grid_runs_ab = h.is_some_and(|h| base.face(h).is_some());
            quads.push(if grid_runs_ab { [b, a, xa, xb] } else { [a, b, xb, xa] });
        }
        let mut mesh = HalfedgeMesh::from_quads(pos.len(), &quads).unwrap();
        let mut rng = point2quad::rng::Rng::new(seed);
        let probs: Vec<f32> = (0..quads.len()).map(|_| rng.uniform(0.05, 0.95) as f32).collect();
        let before = folded_edges(&mesh, &pos, &probs, -0.95);
        let on_fold: std::collections::HashSet<usize> =
            before.iter().flat_map(|&(l, o)| [l.idx(), o.idx()]).collect();
        let alive0: Vec<usize> = mesh.faces().map(|f| f.idx()).collect();
        let n = point2quad::mesh::postprocess::unfold(&mut mesh, &pos, &probs, -0.95);
        validate(&mesh).unwrap();
        let alive1: std::collections::HashSet<usize> = mesh.faces().map(|f| f.idx()).collect();
        let gone: Vec<usize> = alive0.iter().copied().filter(|f| !alive1.contains(f)).collect();
        prop_assert_eq!(gone.len(), n);
        prop_assert!(n <= before.len(), "{} removed for {} folded edges", n, before.len());
        for f in &gone {
            prop_assert!(on_fold.contains(f), "face {} was on no folded edge", f);
        }
        for (loser, other) in folded_edges(&mesh, &pos, &probs, -0.95) {
            for f in [loser, other] {
                let mut copy = mesh.clone();
                prop_assert!(copy.remove_face(f).is_err(), "a fold left whose face {} could go", f.idx());
            }
        }
    }
}
