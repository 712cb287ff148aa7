//! The half-edge invariant checker: proves in tests (and on demand) that a mesh is a
//! consistently oriented, pure-quad 2-manifold. It names the first invariant broken.

use std::collections::HashSet;

use super::halfedge::HalfedgeMesh;
use super::handles::{FaceId, HalfedgeId, VertexId};
use crate::error::{Error, Result};

fn fail<T>(msg: String) -> Result<T> {
    Err(Error::Topology(format!("validate: {msg}")))
}

/// Checks every invariant of [`HalfedgeMesh`]: array sizes; twins (`h ^ 1`) run in
/// opposite directions; `next`/`prev` are inverse and stay on live edges; consecutive
/// half-edges meet at a vertex; every face is a 4-cycle of half-edges naming it, with four
/// distinct corners; boundary half-edges link to boundary half-edges and no edge is
/// faceless on both sides; every vertex's stored half-edge starts there, is a boundary one
/// when the vertex has one, and a rotation around it reaches all its outgoing half-edges
/// (one fan) with at most one boundary among them; no two edges join the same vertices and
/// no two faces share their vertex set; the live counts match. Consistent orientation
/// follows: two faces sharing an edge use its two opposite half-edges.
///
/// # Errors
/// `Topology` naming the first broken invariant and the element it concerns.
pub fn validate(m: &HalfedgeMesh) -> Result<()> {
    check(m, false)
}

/// [`validate`] for the state inside [`HalfedgeMesh::insert_faces`], where a vertex may
/// hold several open fans: every invariant but the single fan, which becomes "the rotation
/// around a vertex reaches all its outgoing half-edges" (its fans' boundary half-edges are
/// linked into one cycle). The unit tests of the insertion check each step with it.
///
/// # Errors
/// `Topology` naming the first broken invariant and the element it concerns.
#[cfg(test)]
pub(crate) fn validate_with_several_fans(m: &HalfedgeMesh) -> Result<()> {
    check(m, true)
}

fn check(m: &HalfedgeMesh, several_fans: bool) -> Result<()> {
    let nh = m.he_to.len();
    let nv = m.v_out.len();
    if nh % 2 != 0
        || m.he_next.len() != nh
        || m.he_prev.len() != nh
        || m.he_face.len() != nh
        || m.edge_alive.len() != nh / 2
    {
        return fail("half-edge arrays have inconsistent lengths".into());
    }
    let alive = |h: HalfedgeId| h.idx() < nh && m.edge_alive[h.edge()];
    let mut n_edges = 0;
    let mut out_count = vec![0usize; nv];
    let mut out_boundary = vec![0usize; nv];
    let mut edge_keys: HashSet<(u32, u32)> = HashSet::new();
    for e in 0..nh / 2 {
        if !m.edge_alive[e] {
            continue;
        }
        n_edges += 1;
        let h = HalfedgeId(2 * e as u32);
        let (a, b) = (m.he_to[h.opposite().idx()], m.he_to[h.idx()]);
        if a.idx() >= nv || b.idx() >= nv {
            return fail(format!("edge {e} points to a vertex out of range"));
        }
        if a == b {
            return fail(format!("edge {e} is a loop at {a}"));
        }
        if !edge_keys.insert((a.0.min(b.0), a.0.max(b.0))) {
            return fail(format!("duplicate edge ({}, {})", a.0, b.0));
        }
        if m.he_face[h.idx()].is_none() && m.he_face[h.opposite().idx()].is_none() {
            return fail(format!("edge {e} ({}, {}) has no face on either side", a.0, b.0));
        }
        for x in [h, h.opposite()] {
            let (nx, pv) = (m.he_next[x.idx()], m.he_prev[x.idx()]);
            if !alive(nx) || !alive(pv) {
                return fail(format!("{x} links to a dead or out-of-range half-edge"));
            }
            if m.he_prev[nx.idx()] != x || m.he_next[pv.idx()] != x {
                return fail(format!("{x}: next and prev are not inverse"));
            }
            if m.he_to[nx.opposite().idx()] != m.he_to[x.idx()] {
                return fail(format!("{x}: next does not start where it ends"));
            }
            match m.he_face[x.idx()] {
                None => {
                    if m.he_face[nx.idx()].is_some() {
                        return fail(format!("boundary {x} links to a half-edge with a face"));
                    }
                }
                Some(f) => {
                    if f.idx() >= m.f_he.len() || m.f_he[f.idx()].is_none() {
                        return fail(format!("{x} names {f}, which is not a live face"));
                    }
                }
            }
            let from = m.he_to[x.opposite().idx()];
            out_count[from.idx()] += 1;
            if m.he_face[x.idx()].is_none() {
                out_boundary[from.idx()] += 1;
            }
        }
    }
    if n_edges != m.n_live_edges {
        return fail(format!("live edge count {} but {} edges alive", m.n_live_edges, n_edges));
    }
    let mut n_faces = 0;
    let mut face_keys: HashSet<[u32; 4]> = HashSet::new();
    for (i, h0) in m.f_he.iter().enumerate() {
        let f = FaceId(i as u32);
        let Some(h0) = *h0 else { continue };
        n_faces += 1;
        if !alive(h0) {
            return fail(format!("{f} stores a dead half-edge"));
        }
        let mut h = h0;
        let mut corners = [VertexId(0); 4];
        for (k, c) in corners.iter_mut().enumerate() {
            if m.he_face[h.idx()] != Some(f) {
                return fail(format!("{f}: {h} (position {k} of its cycle) does not name it"));
            }
            *c = m.he_to[h.opposite().idx()];
            h = m.he_next[h.idx()];
        }
        if h != h0 {
            return fail(format!("{f}: its half-edge cycle does not have length 4"));
        }
        let mut key = corners.map(|v| v.0);
        key.sort_unstable();
        if key.windows(2).any(|w| w[0] == w[1]) {
            return fail(format!("{f} is degenerate (repeats a vertex)"));
        }
        if !face_keys.insert(key) {
            return fail(format!("{f} duplicates another face's vertices {key:?}"));
        }
    }
    if n_faces != m.n_live_faces {
        return fail(format!("live face count {} but {} faces alive", m.n_live_faces, n_faces));
    }
    let with_face = m.he_face.iter().enumerate().filter(|(i, f)| m.edge_alive[i >> 1] && f.is_some()).count();
    if with_face != 4 * n_faces {
        return fail(format!("{with_face} half-edges name a face, expected {}", 4 * n_faces));
    }
    for (i, h) in m.v_out.iter().enumerate() {
        let v = VertexId(i as u32);
        let Some(h) = *h else {
            if out_count[i] != 0 {
                return fail(format!("{v} is marked isolated but has {} outgoing half-edges", out_count[i]));
            }
            continue;
        };
        if !alive(h) || m.he_to[h.opposite().idx()] != v {
            return fail(format!("{v}: its stored half-edge does not start there"));
        }
        if out_boundary[i] > 1 && !several_fans {
            return fail(format!("{v} is non-manifold: {} boundary fans meet there", out_boundary[i]));
        }
        if out_boundary[i] >= 1 && m.he_face[h.idx()].is_some() {
            return fail(format!("{v} is on the boundary but its stored half-edge is not a boundary one"));
        }
        let reached = m.vertex_outgoing(v).count();
        if reached != out_count[i] {
            return fail(format!(
                "{v} is non-manifold: rotation reaches {reached} of its {} outgoing half-edges",
                out_count[i]
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 3×3 vertex grid (2×2 quads), vertex (i, j) = 3j + i.
    fn grid() -> HalfedgeMesh {
        HalfedgeMesh::from_quads(9, &[[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]).unwrap()
    }

    fn expect_err(m: &HalfedgeMesh, needle: &str) {
        let err = validate(m).expect_err("corruption not detected").to_string();
        assert!(err.contains(needle), "expected {needle:?} in {err:?}");
    }

    #[test]
    fn valid_grid_passes() {
        validate(&grid()).unwrap();
    }

    #[test]
    fn broken_next_prev_is_named() {
        let mut m = grid();
        m.he_prev[3] = HalfedgeId(5);
        expect_err(&m, "next and prev are not inverse");
    }

    #[test]
    fn wrong_to_vertex_is_named() {
        let mut m = grid();
        let h = m.face_halfedges(FaceId(0))[0];
        m.he_to[h.idx()] = VertexId(8);
        assert!(validate(&m).is_err());
        let mut m = grid();
        let h = m.face_halfedges(FaceId(0))[0];
        // Swap the to-vertex of both twins: direction reversed on one edge only.
        let (a, b) = (m.he_to[h.idx()], m.he_to[h.opposite().idx()]);
        m.he_to[h.idx()] = b;
        m.he_to[h.opposite().idx()] = a;
        expect_err(&m, "next does not start where it ends");
    }

    #[test]
    fn face_cycle_and_face_names_are_checked() {
        let mut m = grid();
        let hs = m.face_halfedges(FaceId(1));
        m.he_face[hs[2].idx()] = Some(FaceId(0));
        expect_err(&m, "does not name it");
        let mut m = grid();
        m.f_he[0] = None;
        expect_err(&m, "not a live face");
    }

    #[test]
    fn vertex_halfedge_must_start_there_and_prefer_boundary() {
        let mut m = grid();
        let h = m.v_out[0].unwrap();
        m.v_out[0] = Some(h.opposite());
        expect_err(&m, "does not start there");
        let mut m = grid();
        let inner = m.vertex_outgoing(VertexId(1)).find(|&h| !m.is_boundary(h)).unwrap();
        m.v_out[1] = Some(inner);
        expect_err(&m, "not a boundary one");
        let mut m = grid();
        m.v_out[4] = None;
        expect_err(&m, "marked isolated");
    }

    #[test]
    fn counts_and_faceless_edges_are_checked() {
        let mut m = grid();
        m.n_live_faces += 1;
        expect_err(&m, "live face count");
        let mut m = grid();
        m.n_live_edges -= 1;
        expect_err(&m, "live edge count");
        let mut m = grid();
        // Remove the face label from the one face of a boundary edge.
        let h = m.face_halfedges(FaceId(0)).into_iter().find(|h| m.is_boundary(h.opposite())).unwrap();
        m.he_face[h.idx()] = None;
        expect_err(&m, "no face on either side");
    }

    #[test]
    fn degenerate_and_duplicate_are_checked() {
        let mut m = grid();
        let hs = m.face_halfedges(FaceId(0));
        let v = m.he_to[hs[0].idx()];
        // Make two corners equal by renaming one to-vertex (breaks several invariants;
        // the degenerate face or an edge loop must be among what is reported).
        m.he_to[hs[2].idx()] = v;
        assert!(validate(&m).is_err());
        let mut m = grid();
        m.edge_alive[0] = false;
        expect_err(&m, "dead or out-of-range");
    }

    #[test]
    fn duplicate_face_pillow_is_named() {
        // One quad whose boundary loop is turned into a second face on the same vertices:
        // a closed two-face "pillow", consistent in every other respect.
        let mut m = HalfedgeMesh::from_quads(4, &[[0, 1, 2, 3]]).unwrap();
        let loops = m.boundary_loops();
        for &h in &loops[0] {
            m.he_face[h.idx()] = Some(FaceId(1));
        }
        m.f_he.push(Some(loops[0][0]));
        m.n_live_faces += 1;
        expect_err(&m, "duplicates another face");
    }

    #[test]
    fn two_fans_at_a_vertex_are_named() {
        // Two quads sharing only vertex 0, linked by hand (add_face refuses to build it).
        let mut m = HalfedgeMesh::new(7);
        m.add_face([0, 1, 2, 3].map(VertexId)).unwrap();
        let mut other = HalfedgeMesh::new(7);
        other.add_face([0, 4, 5, 6].map(VertexId)).unwrap();
        // Splice the second mesh's arrays into the first, shifting indices.
        let off = m.he_to.len() as u32;
        m.he_to.extend(other.he_to.iter().copied());
        m.he_next.extend(other.he_next.iter().map(|h| HalfedgeId(h.0 + off)));
        m.he_prev.extend(other.he_prev.iter().map(|h| HalfedgeId(h.0 + off)));
        m.he_face.extend(other.he_face.iter().map(|f| f.map(|_| FaceId(1))));
        m.edge_alive.extend(other.edge_alive.iter().copied());
        m.f_he.push(other.f_he[0].map(|h| HalfedgeId(h.0 + off)));
        for v in 4..7 {
            m.v_out[v] = other.v_out[v].map(|h| HalfedgeId(h.0 + off));
        }
        m.n_live_faces += 1;
        m.n_live_edges += 4;
        expect_err(&m, "vertex 0 is non-manifold");
    }
}
