//! The half-edge quad mesh: connectivity only (positions live with the caller), kept an
//! oriented 2-manifold at every step. `add_face` plans first and mutates only when the
//! result stays manifold; where a new quad joins two patches of opposite orientation the
//! smaller patch is flipped (DESIGN §8) instead of refusing the face.

use std::collections::{BinaryHeap, HashMap, HashSet, VecDeque};

use super::handles::{FaceId, HalfedgeId, VertexId};
use super::poly::QuadMesh;
use crate::error::{Error, Result};

/// Connectivity of a pure-quad, oriented, manifold surface mesh (with boundary).
///
/// Invariants (checked by [`crate::mesh::validate::validate`]):
/// - half-edges come in twin pairs `(2e, 2e + 1)`; an edge is alive in both or neither;
/// - `next`/`prev` are inverse permutations on live half-edges; a face's cycle has length 4,
///   a boundary half-edge (no face) links to the next boundary half-edge of its loop;
/// - every vertex has at most one fan of faces (a disk or a half-disk); its outgoing
///   half-edge is a boundary one when it is on the boundary, `None` when it is isolated;
/// - no two edges join the same two vertices, no face repeats a vertex.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HalfedgeMesh {
    /// Per half-edge: the vertex it points to.
    pub(crate) he_to: Vec<VertexId>,
    /// Per half-edge: the next half-edge of its face or boundary loop.
    pub(crate) he_next: Vec<HalfedgeId>,
    /// Per half-edge: the inverse of `he_next`.
    pub(crate) he_prev: Vec<HalfedgeId>,
    /// Per half-edge: its face, `None` on the boundary.
    pub(crate) he_face: Vec<Option<FaceId>>,
    /// Per edge (`h >> 1`): whether it is in use; dead edges are recycled through `free_edges`.
    pub(crate) edge_alive: Vec<bool>,
    pub(crate) free_edges: Vec<u32>,
    /// Per vertex: one outgoing half-edge (a boundary one where there is one).
    pub(crate) v_out: Vec<Option<HalfedgeId>>,
    /// Per face: one of its half-edges, `None` once the face has been removed.
    pub(crate) f_he: Vec<Option<HalfedgeId>>,
    pub(crate) n_live_faces: usize,
    pub(crate) n_live_edges: usize,
}

/// Why a face could not be added; `kind` lets callers (the deferred insertion) decide
/// whether a later retry can succeed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Refusal {
    /// The class of the problem.
    pub kind: RefusalKind,
    /// What was wrong, naming the vertex or edge.
    pub msg: String,
}

/// Classes of [`Refusal`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RefusalKind {
    /// A vertex index is not in the mesh.
    OutOfRange,
    /// The quad repeats a vertex.
    Degenerate,
    /// An edge of the quad already has two faces.
    EdgeFull,
    /// The same four vertices already form a face.
    Duplicate,
    /// A corner vertex is already interior (its faces form a closed disk).
    ClosedVertex,
    /// A corner vertex already has a fan the quad does not attach to (it would get two
    /// fans). The only kind that can succeed later, once neighbouring faces arrive.
    SecondFan(VertexId),
    /// The quad would join one patch to itself with opposite orientations.
    Orientation,
}

/// Result of [`HalfedgeMesh::insert_faces`].
#[derive(Clone, Debug, Default)]
pub struct InsertOutcome {
    /// Per input face: its face handle if it was inserted.
    pub inserted: Vec<Option<FaceId>>,
    /// Refused input faces (index into the input, reason), in refusal order.
    pub refused: Vec<(usize, Refusal)>,
}

/// What `add_face` will do once all checks passed.
struct Plan {
    quad: [VertexId; 4],
    flip: Vec<FaceId>,
}

impl HalfedgeMesh {
    /// A mesh with `n_vertices` isolated vertices and no faces.
    pub fn new(n_vertices: usize) -> Self {
        HalfedgeMesh {
            he_to: Vec::new(),
            he_next: Vec::new(),
            he_prev: Vec::new(),
            he_face: Vec::new(),
            edge_alive: Vec::new(),
            free_edges: Vec::new(),
            v_out: vec![None; n_vertices],
            f_he: Vec::new(),
            n_live_faces: 0,
            n_live_edges: 0,
        }
    }

    /// Builds a mesh from quads (indices into `0..n_vertices`). The faces may come in any
    /// order: a face that touches an existing fan only at a vertex is retried once its
    /// neighbours are in (see [`HalfedgeMesh::insert_faces`]).
    ///
    /// # Errors
    /// `Topology` naming the first face that cannot be inserted (non-manifold input,
    /// degenerate quad, index out of range).
    pub fn from_quads(n_vertices: usize, quads: &[[u32; 4]]) -> Result<HalfedgeMesh> {
        let mut m = HalfedgeMesh::new(n_vertices);
        let order: Vec<usize> = (0..quads.len()).collect();
        let out = m.insert_faces(quads, &order);
        if let Some((i, r)) = out.refused.iter().min_by_key(|(i, _)| *i) {
            return Err(Error::Topology(format!("face {i} {:?}: {}", quads[*i], r.msg)));
        }
        Ok(m)
    }

    // ---- sizes and raw access -------------------------------------------------------

    /// Number of vertices (isolated ones included).
    pub fn n_vertices(&self) -> usize {
        self.v_out.len()
    }
    /// Number of live faces.
    pub fn n_faces(&self) -> usize {
        self.n_live_faces
    }
    /// Number of live edges.
    pub fn n_edges(&self) -> usize {
        self.n_live_edges
    }
    /// Length of the half-edge arrays (live and dead slots).
    pub fn halfedge_capacity(&self) -> usize {
        self.he_to.len()
    }
    /// Length of the face array (live and removed slots).
    pub fn face_capacity(&self) -> usize {
        self.f_he.len()
    }
    /// Whether edge slot `e` is in use.
    pub fn is_edge_alive(&self, e: usize) -> bool {
        self.edge_alive.get(e).copied().unwrap_or(false)
    }
    /// Whether `f` is a live face.
    pub fn is_face_alive(&self, f: FaceId) -> bool {
        self.f_he.get(f.idx()).is_some_and(|h| h.is_some())
    }
    /// Appends an isolated vertex.
    pub fn add_vertex(&mut self) -> VertexId {
        self.v_out.push(None);
        VertexId(self.v_out.len() as u32 - 1)
    }

    // ---- navigation -----------------------------------------------------------------

    /// The vertex `h` points to.
    #[inline]
    pub fn to_vertex(&self, h: HalfedgeId) -> VertexId {
        self.he_to[h.idx()]
    }
    /// The vertex `h` starts from.
    #[inline]
    pub fn from_vertex(&self, h: HalfedgeId) -> VertexId {
        self.he_to[h.opposite().idx()]
    }
    /// The next half-edge around `h`'s face (or boundary loop).
    #[inline]
    pub fn next(&self, h: HalfedgeId) -> HalfedgeId {
        self.he_next[h.idx()]
    }
    /// The previous half-edge around `h`'s face (or boundary loop).
    #[inline]
    pub fn prev(&self, h: HalfedgeId) -> HalfedgeId {
        self.he_prev[h.idx()]
    }
    /// The face of `h`; `None` for a boundary half-edge.
    #[inline]
    pub fn face(&self, h: HalfedgeId) -> Option<FaceId> {
        self.he_face[h.idx()]
    }
    /// Whether `h` is a boundary half-edge (has no face).
    #[inline]
    pub fn is_boundary(&self, h: HalfedgeId) -> bool {
        self.he_face[h.idx()].is_none()
    }
    /// One outgoing half-edge of `v` (a boundary one if `v` is on the boundary); `None`
    /// for an isolated vertex.
    #[inline]
    pub fn vertex_halfedge(&self, v: VertexId) -> Option<HalfedgeId> {
        self.v_out[v.idx()]
    }
    /// Whether `v` has no face.
    pub fn is_isolated(&self, v: VertexId) -> bool {
        self.v_out[v.idx()].is_none()
    }
    /// Whether `v` lies on the boundary (has faces and an outgoing boundary half-edge).
    pub fn is_boundary_vertex(&self, v: VertexId) -> bool {
        self.v_out[v.idx()].is_some_and(|h| self.is_boundary(h))
    }
    /// One half-edge of a live face.
    pub fn face_halfedge(&self, f: FaceId) -> Option<HalfedgeId> {
        self.f_he.get(f.idx()).copied().flatten()
    }

    /// The live faces in index order.
    pub fn faces(&self) -> impl Iterator<Item = FaceId> + '_ {
        self.f_he.iter().enumerate().filter(|(_, h)| h.is_some()).map(|(i, _)| FaceId(i as u32))
    }

    /// The four half-edges of face `f`, starting at its stored half-edge.
    ///
    /// # Panics
    /// If `f` is not a live face.
    pub fn face_halfedges(&self, f: FaceId) -> [HalfedgeId; 4] {
        let h0 = self.face_halfedge(f).expect("face_halfedges: not a live face");
        let h1 = self.next(h0);
        let h2 = self.next(h1);
        [h0, h1, h2, self.next(h2)]
    }

    /// The four corners of face `f` in cyclic order (the from-vertex of each half-edge).
    ///
    /// # Panics
    /// If `f` is not a live face.
    pub fn face_vertices(&self, f: FaceId) -> [VertexId; 4] {
        self.face_halfedges(f).map(|h| self.from_vertex(h))
    }

    /// The outgoing half-edges of `v`, starting at its stored one (so the boundary one
    /// first), rotating through its single fan.
    pub fn vertex_outgoing(&self, v: VertexId) -> VertexOutgoing<'_> {
        let start = self.v_out[v.idx()];
        VertexOutgoing { mesh: self, start, cur: start, guard: self.he_to.len() + 1 }
    }

    /// The faces around `v`.
    pub fn vertex_faces(&self, v: VertexId) -> impl Iterator<Item = FaceId> + '_ {
        self.vertex_outgoing(v).filter_map(|h| self.face(h))
    }

    /// The half-edge from `a` to `b`, if that edge exists.
    pub fn find_halfedge(&self, a: VertexId, b: VertexId) -> Option<HalfedgeId> {
        self.vertex_outgoing(a).find(|&h| self.to_vertex(h) == b)
    }

    // ---- global queries -------------------------------------------------------------

    /// Every boundary loop, as the cycle of its boundary half-edges (following `next`),
    /// each loop starting at its lowest half-edge index.
    pub fn boundary_loops(&self) -> Vec<Vec<HalfedgeId>> {
        let mut seen = vec![false; self.he_to.len()];
        let mut loops = Vec::new();
        for i in 0..self.he_to.len() {
            let h = HalfedgeId(i as u32);
            if seen[i] || !self.edge_alive[h.edge()] || !self.is_boundary(h) {
                continue;
            }
            let mut lp = Vec::new();
            let mut c = h;
            while !seen[c.idx()] {
                seen[c.idx()] = true;
                lp.push(c);
                c = self.next(c);
            }
            loops.push(lp);
        }
        loops
    }

    /// The edge-connected components of the faces, each a sorted list of faces.
    pub fn connected_components(&self) -> Vec<Vec<FaceId>> {
        let mut seen = vec![false; self.f_he.len()];
        let mut comps = Vec::new();
        for f in self.faces() {
            if seen[f.idx()] {
                continue;
            }
            seen[f.idx()] = true;
            let mut comp = self.flood(f, |n| !std::mem::replace(&mut seen[n.idx()], true));
            comp.sort_unstable();
            comps.push(comp);
        }
        comps
    }

    /// The live faces across the four edges of face `f` (none across a boundary edge).
    fn face_neighbours(&self, f: FaceId) -> impl Iterator<Item = FaceId> + '_ {
        self.face_halfedges(f).into_iter().filter_map(move |h| self.face(h.opposite()))
    }

    /// The edge-connected component of `seed`, breadth first from it. `first_visit(g)`
    /// marks face `g` and says whether it was unmarked; `seed` must be marked already.
    /// The caller picks the marker: a dense flag per face when sweeping every component,
    /// a hash set for one component of a possibly much larger mesh (a dense array would
    /// cost O(#faces) per call, and insertion flips small patches often).
    fn flood(&self, seed: FaceId, mut first_visit: impl FnMut(FaceId) -> bool) -> Vec<FaceId> {
        let mut comp = vec![seed];
        let mut k = 0;
        while k < comp.len() {
            let g = comp[k];
            k += 1;
            for n in self.face_neighbours(g) {
                if first_visit(n) {
                    comp.push(n);
                }
            }
        }
        comp
    }

    /// V − E + F over the vertices that have faces (isolated vertices are not counted,
    /// so that input points no face uses do not change the topology).
    pub fn euler_characteristic(&self) -> i64 {
        let v = self.v_out.iter().filter(|h| h.is_some()).count() as i64;
        v - self.n_live_edges as i64 + self.n_live_faces as i64
    }

    /// Whether the mesh has no boundary half-edge.
    pub fn is_closed(&self) -> bool {
        (0..self.he_to.len()).all(|i| !self.edge_alive[i >> 1] || self.he_face[i].is_some())
    }

    /// Total genus of a closed mesh: Σ over components of (2 − χ_c)/2 = (2C − χ)/2.
    ///
    /// # Errors
    /// `Topology` when the mesh has a boundary (genus is defined here for closed meshes).
    pub fn genus(&self) -> Result<usize> {
        if !self.is_closed() {
            return Err(Error::Topology("genus: the mesh has boundary loops".into()));
        }
        let c = self.connected_components().len() as i64;
        Ok(((2 * c - self.euler_characteristic()) / 2).max(0) as usize)
    }

    /// The live faces as a [`QuadMesh`] over `positions` (copied in order, bit for bit).
    ///
    /// # Errors
    /// `InvalidInput` when `positions` does not have one entry per vertex.
    pub fn to_quad_mesh(&self, positions: &[[f64; 3]]) -> Result<QuadMesh> {
        if positions.len() != self.n_vertices() {
            return Err(Error::invalid(format!(
                "to_quad_mesh: {} positions for {} vertices",
                positions.len(),
                self.n_vertices()
            )));
        }
        let quads = self.faces().map(|f| self.face_vertices(f).map(|v| v.0)).collect();
        Ok(QuadMesh { vertices: positions.to_vec(), quads })
    }

    // ---- adding faces ---------------------------------------------------------------

    /// Adds the quad `vs` (cyclic order), possibly reversed to agree with its neighbours;
    /// where it joins patches of opposite orientation, the smaller patch is flipped.
    /// Checks everything first: on error the mesh is unchanged.
    ///
    /// # Errors
    /// `Topology` naming the vertex or edge when the quad is degenerate, out of range,
    /// a duplicate, or would create an edge with three faces, a vertex with two fans or
    /// a non-orientable patch.
    pub fn add_face(&mut self, vs: [VertexId; 4]) -> Result<FaceId> {
        self.try_add_face(vs).map_err(|r| Error::Topology(r.msg))
    }

    /// [`HalfedgeMesh::add_face`] with the refusal's class.
    ///
    /// # Errors
    /// The [`Refusal`] saying why; the mesh is then unchanged.
    pub fn try_add_face(&mut self, vs: [VertexId; 4]) -> std::result::Result<FaceId, Refusal> {
        let plan = self.plan_face(vs)?;
        Ok(self.apply_plan(plan))
    }

    /// Inserts `faces[order[0]]`, `faces[order[1]]`, … (earlier = higher priority). A face
    /// refused only because a corner already has a fan it does not touch is retried each
    /// time a face is added at that corner, still in priority order, so the result does
    /// not depend on the accidents of the order in which neighbours arrive. Indices in
    /// `order` that are out of range are ignored.
    pub fn insert_faces(&mut self, faces: &[[u32; 4]], order: &[usize]) -> InsertOutcome {
        let mut out = InsertOutcome { inserted: vec![None; faces.len()], refused: Vec::new() };
        // Heap of ranks (smallest rank first); a rank may be pushed again after deferral.
        let mut heap: BinaryHeap<std::cmp::Reverse<usize>> =
            (0..order.len()).filter(|&r| order[r] < faces.len()).map(std::cmp::Reverse).collect();
        let mut waiting: HashMap<u32, Vec<usize>> = HashMap::new();
        let mut deferred: HashMap<usize, Refusal> = HashMap::new();
        let mut done = vec![false; order.len()];
        while let Some(std::cmp::Reverse(r)) = heap.pop() {
            if done[r] {
                continue;
            }
            let i = order[r];
            let vs = faces[i].map(VertexId);
            match self.try_add_face(vs) {
                Ok(f) => {
                    done[r] = true;
                    deferred.remove(&r);
                    out.inserted[i] = Some(f);
                    for v in faces[i] {
                        if let Some(list) = waiting.remove(&v) {
                            heap.extend(list.into_iter().filter(|&q| !done[q]).map(std::cmp::Reverse));
                        }
                    }
                }
                Err(refusal) => match refusal.kind {
                    RefusalKind::SecondFan(v) => {
                        waiting.entry(v.0).or_default().push(r);
                        deferred.insert(r, refusal);
                    }
                    _ => {
                        done[r] = true;
                        deferred.remove(&r);
                        out.refused.push((i, refusal));
                    }
                },
            }
        }
        let mut rest: Vec<(usize, Refusal)> = deferred.into_iter().collect();
        rest.sort_by_key(|(r, _)| *r);
        out.refused.extend(rest.into_iter().map(|(r, e)| (order[r], e)));
        out
    }

    fn refuse(kind: RefusalKind, msg: String) -> std::result::Result<Plan, Refusal> {
        Err(Refusal { kind, msg })
    }

    /// Every check of `add_face`, without mutating.
    fn plan_face(&self, vs: [VertexId; 4]) -> std::result::Result<Plan, Refusal> {
        let n = self.n_vertices();
        for v in vs {
            if v.idx() >= n {
                return Self::refuse(
                    RefusalKind::OutOfRange,
                    format!("quad {:?}: {v} is out of range (mesh has {n} vertices)", vs.map(|v| v.0)),
                );
            }
        }
        for i in 0..4 {
            for j in i + 1..4 {
                if vs[i] == vs[j] {
                    return Self::refuse(
                        RefusalKind::Degenerate,
                        format!("quad {:?} repeats {}", vs.map(|v| v.0), vs[i]),
                    );
                }
            }
        }
        // Edges: existing ones must have exactly one face; record the orientation each asks for.
        let mut exists = [false; 4];
        let mut forward: Vec<FaceId> = Vec::new();
        let mut reverse: Vec<FaceId> = Vec::new();
        for i in 0..4 {
            let (a, b) = (vs[i], vs[(i + 1) % 4]);
            let Some(h) = self.find_halfedge(a, b) else { continue };
            exists[i] = true;
            match (self.face(h), self.face(h.opposite())) {
                (Some(_), Some(_)) => {
                    return Self::refuse(
                        RefusalKind::EdgeFull,
                        format!("edge ({}, {}) already has two faces", a.0, b.0),
                    );
                }
                (None, Some(g)) => forward.push(g),
                (Some(g), None) => reverse.push(g),
                (None, None) => {
                    return Self::refuse(
                        RefusalKind::EdgeFull,
                        format!("edge ({}, {}) has no face (corrupt mesh)", a.0, b.0),
                    );
                }
            }
        }
        let mut key = vs.map(|v| v.0);
        key.sort_unstable();
        for &g in forward.iter().chain(&reverse) {
            let mut k = self.face_vertices(g).map(|v| v.0);
            k.sort_unstable();
            if k == key {
                return Self::refuse(
                    RefusalKind::Duplicate,
                    format!("quad {:?} duplicates {g}", vs.map(|v| v.0)),
                );
            }
        }
        // Vertices: the quad must attach to the single fan of each corner, or the corner is isolated.
        for i in 0..4 {
            let v = vs[i];
            let Some(h) = self.v_out[v.idx()] else { continue };
            if !self.is_boundary(h) {
                return Self::refuse(
                    RefusalKind::ClosedVertex,
                    format!("{v} is interior (its faces already form a closed disk)"),
                );
            }
            let (e_in, e_out) = (exists[(i + 3) % 4], exists[i]);
            if !e_in && !e_out {
                return Self::refuse(
                    RefusalKind::SecondFan(v),
                    format!(
                        "{v} already has a fan of faces the quad does not attach to (non-manifold vertex)"
                    ),
                );
            }
        }
        // Orientation: flip the smaller side when the neighbours disagree.
        let (reversed, flip) = if reverse.is_empty() {
            (false, Vec::new())
        } else if forward.is_empty() {
            (true, Vec::new())
        } else {
            match self.smaller_side(&forward, &reverse) {
                None => {
                    return Self::refuse(
                        RefusalKind::Orientation,
                        format!(
                            "quad {:?} joins one patch to itself with opposite orientations (non-orientable)",
                            vs.map(|v| v.0)
                        ),
                    );
                }
                // Flipping the forward side's patches means the quad takes the reverse order.
                Some((flip_forward, faces)) => (flip_forward, faces),
            }
        };
        let quad = if reversed { [vs[0], vs[3], vs[2], vs[1]] } else { vs };
        Ok(Plan { quad, flip })
    }

    /// Floods the components of `a` and of `b` one face at a time each; returns which side
    /// was exhausted first (true = `a`) with all its faces, or `None` when the floods meet
    /// (one component contains faces of both sides). Costs O(size of the smaller side).
    fn smaller_side(&self, a: &[FaceId], b: &[FaceId]) -> Option<(bool, Vec<FaceId>)> {
        let mut owner: HashMap<u32, u8> = HashMap::new();
        let mut lists: [Vec<FaceId>; 2] = [Vec::new(), Vec::new()];
        let mut queues: [VecDeque<FaceId>; 2] = [VecDeque::new(), VecDeque::new()];
        /// Gives face `g` to side `s` (queued for its flood) unless it has it already;
        /// `false` when the other side has it: the floods met.
        fn claim(
            owner: &mut HashMap<u32, u8>,
            list: &mut Vec<FaceId>,
            queue: &mut VecDeque<FaceId>,
            s: usize,
            g: FaceId,
        ) -> bool {
            match owner.get(&g.0) {
                Some(&o) => o as usize == s,
                None => {
                    owner.insert(g.0, s as u8);
                    list.push(g);
                    queue.push_back(g);
                    true
                }
            }
        }
        for (s, seeds) in [a, b].into_iter().enumerate() {
            for &f in seeds {
                if !claim(&mut owner, &mut lists[s], &mut queues[s], s, f) {
                    return None;
                }
            }
        }
        loop {
            for s in 0..2 {
                let Some(f) = queues[s].pop_front() else {
                    return Some((s == 0, std::mem::take(&mut lists[s])));
                };
                for g in self.face_neighbours(f) {
                    if !claim(&mut owner, &mut lists[s], &mut queues[s], s, g) {
                        return None;
                    }
                }
            }
        }
    }

    fn new_edge(&mut self, a: VertexId, b: VertexId) -> HalfedgeId {
        let h = if let Some(e) = self.free_edges.pop() {
            let h = HalfedgeId(2 * e);
            self.edge_alive[e as usize] = true;
            self.he_to[h.idx()] = b;
            self.he_to[h.opposite().idx()] = a;
            for x in [h, h.opposite()] {
                self.he_next[x.idx()] = x;
                self.he_prev[x.idx()] = x;
                self.he_face[x.idx()] = None;
            }
            h
        } else {
            let h = HalfedgeId(self.he_to.len() as u32);
            self.he_to.extend([b, a]);
            self.he_next.extend([h, h.opposite()]);
            self.he_prev.extend([h, h.opposite()]);
            self.he_face.extend([None, None]);
            self.edge_alive.push(true);
            h
        };
        self.n_live_edges += 1;
        h
    }

    #[inline]
    fn link(&mut self, a: HalfedgeId, b: HalfedgeId) {
        self.he_next[a.idx()] = b;
        self.he_prev[b.idx()] = a;
    }

    /// Reverses the orientation of the whole connected component containing face `f`
    /// (a manifold stays manifold; only a whole component can be flipped consistently).
    ///
    /// # Errors
    /// `Topology` when `f` is not a live face.
    pub fn flip_component(&mut self, f: FaceId) -> Result<()> {
        if !self.is_face_alive(f) {
            return Err(Error::Topology(format!("flip_component: {f} is not a live face")));
        }
        let mut seen: HashSet<u32> = HashSet::from([f.0]);
        let comp = self.flood(f, |n| seen.insert(n.0));
        self.flip_patch(&comp);
        Ok(())
    }

    /// Reverses the orientation of the edge-connected patch `faces` (a whole component).
    /// Each edge's two half-edges swap roles: new next(opp x) = opp(prev x) and the face of
    /// x moves to opp x; boundary loops of the patch reverse with it (they only link
    /// half-edges of the patch, since every vertex has a single fan).
    fn flip_patch(&mut self, faces: &[FaceId]) {
        let mut edges: Vec<usize> = Vec::new();
        let mut seen: HashSet<usize> = HashSet::new();
        let mut verts: Vec<VertexId> = Vec::new();
        for &f in faces {
            for h in self.face_halfedges(f) {
                if seen.insert(h.edge()) {
                    edges.push(h.edge());
                }
                verts.push(self.to_vertex(h));
            }
        }
        verts.sort_unstable();
        verts.dedup();
        // New vertex half-edges must be computed from the old links.
        let new_out: Vec<(VertexId, HalfedgeId)> = verts
            .iter()
            .filter_map(|&v| {
                let h = self.v_out[v.idx()]?;
                self.is_boundary(h).then(|| (v, self.prev(h).opposite()))
            })
            .collect();
        let mut upd: Vec<(HalfedgeId, HalfedgeId, HalfedgeId, Option<FaceId>)> =
            Vec::with_capacity(edges.len() * 2);
        for &e in &edges {
            for x in [HalfedgeId(2 * e as u32), HalfedgeId(2 * e as u32 + 1)] {
                upd.push((x.opposite(), self.prev(x).opposite(), self.next(x).opposite(), self.face(x)));
            }
        }
        for (y, nx, pv, fc) in upd {
            self.he_next[y.idx()] = nx;
            self.he_prev[y.idx()] = pv;
            self.he_face[y.idx()] = fc;
        }
        for (v, h) in new_out {
            self.v_out[v.idx()] = Some(h);
        }
        for &f in faces {
            let h = self.f_he[f.idx()].expect("internal error: flipping a removed face");
            self.f_he[f.idx()] = Some(h.opposite());
        }
    }

    fn apply_plan(&mut self, plan: Plan) -> FaceId {
        if !plan.flip.is_empty() {
            self.flip_patch(&plan.flip);
        }
        let q = plan.quad;
        let mut hs = [HalfedgeId(0); 4];
        let mut is_new = [false; 4];
        for i in 0..4 {
            match self.find_halfedge(q[i], q[(i + 1) % 4]) {
                Some(h) => {
                    debug_assert!(self.is_boundary(h), "internal error: planned edge is not boundary");
                    hs[i] = h;
                }
                None => {
                    hs[i] = self.new_edge(q[i], q[(i + 1) % 4]);
                    is_new[i] = true;
                }
            }
        }
        // Boundary relinking at each corner v = q[i+1] between hs[i] (in) and hs[i+1] (out),
        // reading the old links before writing any.
        let mut links: Vec<(HalfedgeId, HalfedgeId)> = Vec::with_capacity(8);
        let mut outs: Vec<(VertexId, HalfedgeId)> = Vec::with_capacity(4);
        for i in 0..4 {
            let j = (i + 1) % 4;
            let (hin, hout, v) = (hs[i], hs[j], q[j]);
            match (is_new[i], is_new[j]) {
                // Closing the fan: next(in) is already out.
                (false, false) => {}
                (false, true) => links.push((hout.opposite(), self.next(hin))),
                (true, false) => {
                    links.push((self.prev(hout), hin.opposite()));
                    outs.push((v, hin.opposite()));
                }
                (true, true) => {
                    links.push((hout.opposite(), hin.opposite()));
                    outs.push((v, hin.opposite()));
                }
            }
        }
        for (a, b) in links {
            self.link(a, b);
        }
        let f = FaceId(self.f_he.len() as u32);
        self.f_he.push(Some(hs[0]));
        for i in 0..4 {
            self.link(hs[i], hs[(i + 1) % 4]);
            self.he_face[hs[i].idx()] = Some(f);
        }
        for (v, h) in outs {
            self.v_out[v.idx()] = Some(h);
        }
        // A corner whose fan was closed keeps a non-boundary outgoing half-edge; one whose
        // stored half-edge just became interior needs any outgoing half-edge still boundary.
        for v in q {
            if let Some(h) = self.v_out[v.idx()] {
                if !self.is_boundary(h) {
                    if let Some(b) = self.vertex_outgoing(v).find(|&x| self.is_boundary(x)) {
                        self.v_out[v.idx()] = Some(b);
                    }
                }
            }
        }
        self.n_live_faces += 1;
        f
    }

    // ---- removing faces ---------------------------------------------------------------

    /// Removes face `f`; edges left without faces are deleted and corners left without
    /// faces become isolated.
    ///
    /// # Errors
    /// `Topology` when `f` is not a live face, or when it sits in the middle of a corner's
    /// open fan (removing it would split that vertex into two fans); the mesh is then
    /// unchanged.
    pub fn remove_face(&mut self, f: FaceId) -> Result<()> {
        if !self.is_face_alive(f) {
            return Err(Error::Topology(format!("remove_face: {f} is not a live face")));
        }
        let hs = self.face_halfedges(f);
        let dead: [bool; 4] = hs.map(|h| self.is_boundary(h.opposite()));
        for i in 0..4 {
            let j = (i + 1) % 4;
            let v = self.to_vertex(hs[i]);
            if self.is_boundary_vertex(v) && !dead[i] && !dead[j] {
                return Err(Error::Topology(format!(
                    "remove_face: removing {f} would split the fan of {v} in two (non-manifold vertex)"
                )));
            }
        }
        let mut links: Vec<(HalfedgeId, HalfedgeId)> = Vec::with_capacity(4);
        let mut outs: Vec<(VertexId, Option<HalfedgeId>)> = Vec::with_capacity(4);
        for i in 0..4 {
            let j = (i + 1) % 4;
            let (hin, hout) = (hs[i], hs[j]);
            let v = self.to_vertex(hin);
            match (dead[i], dead[j]) {
                // Both kept: next(in) = out stays; out becomes boundary.
                (false, false) => outs.push((v, Some(hout))),
                (false, true) => {
                    let x = self.next(hout.opposite());
                    links.push((hin, x));
                    outs.push((v, Some(x)));
                }
                (true, false) => {
                    let y = self.prev(hin.opposite());
                    links.push((y, hout));
                    outs.push((v, Some(hout)));
                }
                (true, true) => outs.push((v, None)),
            }
        }
        for h in hs {
            self.he_face[h.idx()] = None;
        }
        for (a, b) in links {
            self.link(a, b);
        }
        for (v, h) in outs {
            self.v_out[v.idx()] = h;
        }
        for i in 0..4 {
            if dead[i] {
                let e = hs[i].edge();
                self.edge_alive[e] = false;
                self.free_edges.push(e as u32);
                self.n_live_edges -= 1;
                for x in [hs[i], hs[i].opposite()] {
                    self.he_next[x.idx()] = x;
                    self.he_prev[x.idx()] = x;
                    self.he_face[x.idx()] = None;
                }
            }
        }
        self.f_he[f.idx()] = None;
        self.n_live_faces -= 1;
        Ok(())
    }
}

/// Iterator over the outgoing half-edges of one vertex (see
/// [`HalfedgeMesh::vertex_outgoing`]); rotation is `h → opposite(prev(h))`.
pub struct VertexOutgoing<'a> {
    mesh: &'a HalfedgeMesh,
    start: Option<HalfedgeId>,
    cur: Option<HalfedgeId>,
    /// Bounds the walk on a corrupted mesh (validate uses this iterator too).
    guard: usize,
}

impl Iterator for VertexOutgoing<'_> {
    type Item = HalfedgeId;
    fn next(&mut self) -> Option<HalfedgeId> {
        let h = self.cur?;
        if self.guard == 0 {
            self.cur = None;
            return None;
        }
        self.guard -= 1;
        let n = self.mesh.prev(h).opposite();
        self.cur = if Some(n) == self.start { None } else { Some(n) };
        Some(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::validate::validate;

    fn q(a: u32, b: u32, c: u32, d: u32) -> [VertexId; 4] {
        [VertexId(a), VertexId(b), VertexId(c), VertexId(d)]
    }

    /// 3×3 vertex grid (2×2 quads), vertex (i, j) = 3j + i.
    fn grid_quads() -> Vec<[u32; 4]> {
        vec![[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]
    }

    #[test]
    fn grid_builds_and_validates() {
        let m = HalfedgeMesh::from_quads(9, &grid_quads()).unwrap();
        validate(&m).unwrap();
        assert_eq!((m.n_faces(), m.n_edges()), (4, 12));
        assert_eq!(m.euler_characteristic(), 1);
        assert_eq!(m.boundary_loops().len(), 1);
        assert_eq!(m.boundary_loops()[0].len(), 8);
        assert!(m.genus().is_err());
        assert!(!m.is_boundary_vertex(VertexId(4)));
    }

    #[test]
    fn vertex_touching_fan_is_deferred_then_accepted() {
        // Faces 0 and 3 of the grid share only vertex 4.
        let mut m = HalfedgeMesh::new(9);
        m.add_face(q(0, 1, 4, 3)).unwrap();
        let before = m.clone();
        let err = m.add_face(q(4, 5, 8, 7)).unwrap_err().to_string();
        assert!(err.contains("vertex 4"), "{err}");
        assert_eq!(m, before);
        let quads = grid_quads();
        let out = m.insert_faces(&quads, &[3, 1, 2]);
        assert!(out.refused.is_empty(), "{:?}", out.refused);
        validate(&m).unwrap();
        assert_eq!(m.n_faces(), 4);
    }

    fn same_cycle(a: [VertexId; 4], b: [u32; 4]) -> bool {
        let a = a.map(|v| v.0);
        (0..4).any(|k| (0..4).all(|i| a[(i + k) % 4] == b[i]))
    }

    #[test]
    fn reversed_face_is_reoriented_and_smaller_patch_flips() {
        let mut m = HalfedgeMesh::new(9);
        m.add_face(q(0, 1, 4, 3)).unwrap();
        let f = m.add_face(q(1, 4, 5, 2)).unwrap();
        assert!(same_cycle(m.face_vertices(f), [1, 2, 5, 4]));
        validate(&m).unwrap();

        // Strip 0..4 bottom, 5..9 top: {F0} forward, {F3, F2} reversed, then F1 joins them.
        let mut m = HalfedgeMesh::new(10);
        let f0 = m.add_face(q(0, 1, 6, 5)).unwrap();
        let f3 = m.add_face(q(3, 8, 9, 4)).unwrap();
        let f2 = m.add_face(q(2, 3, 8, 7)).unwrap();
        assert!(same_cycle(m.face_vertices(f2), [2, 7, 8, 3]));
        let f1 = m.add_face(q(1, 2, 7, 6)).unwrap();
        validate(&m).unwrap();
        assert!(same_cycle(m.face_vertices(f0), [0, 5, 6, 1]), "the one-face patch flipped");
        assert!(same_cycle(m.face_vertices(f1), [1, 6, 7, 2]));
        assert!(same_cycle(m.face_vertices(f3), [3, 8, 9, 4]), "the larger patch kept");
        // A twisted join of one patch to itself is refused and leaves the mesh unchanged.
        let before = m.clone();
        let err = m.add_face(q(0, 5, 4, 9)).unwrap_err().to_string();
        assert!(err.contains("non-orientable"), "{err}");
        assert_eq!(m, before);
    }

    #[test]
    fn remove_face_refuses_fan_split_and_keeps_valid() {
        let mut m = HalfedgeMesh::from_quads(9, &grid_quads()).unwrap();
        // A 2x2 grid: every face is at the end of every corner fan, removal is fine.
        m.remove_face(FaceId(0)).unwrap();
        validate(&m).unwrap();
        assert!(m.is_isolated(VertexId(0)));
        // Now face 3 (4,5,8,7): vertex 4 has fan [1, 3, 2]; removing 3 splits it.
        let before = m.clone();
        let err = m.remove_face(FaceId(3)).unwrap_err().to_string();
        assert!(err.contains("vertex 4"), "{err}");
        assert_eq!(m, before);
        m.remove_face(FaceId(1)).unwrap();
        validate(&m).unwrap();
        let f = m.add_face(q(0, 1, 4, 3)).unwrap();
        validate(&m).unwrap();
        assert!(m.is_face_alive(f));
    }
}
