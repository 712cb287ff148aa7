//! The half-edge quad mesh: connectivity only (positions live with the caller), kept an
//! oriented 2-manifold between calls. `add_face` plans first and mutates only when the
//! result stays manifold; where a new quad joins two patches of opposite orientation the
//! smaller patch is flipped (DESIGN §8) instead of refusing the face. `insert_faces` may let
//! a vertex hold several fans for a while, as robust half-edge libraries do while a mesh is
//! built, so that faces given in any order assemble; it returns only a mesh whose every
//! vertex has one fan.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap, HashSet, VecDeque};

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
///   half-edge is a boundary one when it is on the boundary, `None` when it is isolated.
///   Only inside [`HalfedgeMesh::insert_faces`] may a vertex hold several open fans: their
///   boundary half-edges are then linked into one cycle around it (the incoming boundary
///   half-edge of each fan to the outgoing one of the next), so that the rotation still
///   reaches every outgoing half-edge;
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
    /// A corner vertex has a fan the quad touches only at that vertex, so the vertex would
    /// hold two fans (the quad may fit later, once the faces between arrive;
    /// `insert_faces` reports the faces still in that state at its end). Inside
    /// `insert_faces`, where a vertex may hold several fans for a while, also: the quad
    /// would close one of them into a disk beside another.
    SecondFan(VertexId),
    /// The quad would join one patch to itself with opposite orientations.
    Orientation,
}

/// Result of [`HalfedgeMesh::insert_faces`].
#[derive(Clone, Debug, Default)]
pub struct InsertOutcome {
    /// Per input face: its face handle if it was inserted.
    pub inserted: Vec<Option<FaceId>>,
    /// Refused input faces (index into the input, reason): first those refused outright,
    /// in refusal order, then, by rank in `order`, those still waiting at the end because
    /// they would give a corner a second fan ([`RefusalKind::SecondFan`]).
    pub refused: Vec<(usize, Refusal)>,
}

/// What `add_face` will do once all checks passed.
struct Plan {
    quad: [VertexId; 4],
    flip: Vec<FaceId>,
}

/// How many rounds of its second phase [`HalfedgeMesh::insert_faces`] runs, each after
/// taking back the faces that left a vertex with two fans in the one before, before it
/// gives up forcing. Each round takes back at least one face. Measured: a valid manifold
/// needs one round; the post-process benchmark's soup (`benches/mesh_insert.rs`) two; the
/// random soups of `tests/mesh_props.rs` (up to as many wrong quads as true ones) one to
/// three as a rule, and 8 in 1 of ~4,500 batches.
const FORCE_ROUNDS: usize = 8;

/// One open fan around a vertex, as `flip_patch` sees it: its incoming boundary
/// half-edge, its outgoing one, and whether it belongs to the patch being flipped.
type FanEnds = (HalfedgeId, HalfedgeId, bool);

/// Whether quad `f` has the edge {a, b} (either direction).
fn has_edge(f: [u32; 4], a: u32, b: u32) -> bool {
    (0..4).any(|k| {
        let (x, y) = (f[k], f[(k + 1) % 4]);
        (x == a && y == b) || (x == b && y == a)
    })
}

/// The state of one [`HalfedgeMesh::insert_faces`] call; cloned to restart its second phase.
#[derive(Clone)]
struct Batch {
    /// Ranks (positions in `order`) to try, smallest first; a rank may be pushed again
    /// after deferral.
    heap: BinaryHeap<Reverse<usize>>,
    /// Per vertex: ranks refused with `SecondFan` at it, retried once a face is added there.
    waiting: HashMap<u32, Vec<usize>>,
    /// Ranks waiting, with the refusal that made them wait.
    deferred: BTreeMap<usize, Refusal>,
    /// Per rank: inserted or refused for good.
    done: Vec<bool>,
    /// The faces inserted, as (rank, face), in insertion order.
    added: Vec<(usize, FaceId)>,
    out: InsertOutcome,
}

impl Batch {
    /// Inserts what the heap holds, highest priority first, deferring faces that would
    /// start a second fan at a corner, until the heap is empty.
    fn drain(&mut self, mesh: &mut HalfedgeMesh, faces: &[[u32; 4]], order: &[usize]) {
        while let Some(Reverse(r)) = self.heap.pop() {
            if self.done[r] {
                continue;
            }
            let i = order[r];
            match mesh.plan_face(faces[i].map(VertexId), false) {
                Ok(plan) => {
                    let f = mesh.apply_plan(plan);
                    self.accept(r, i, f, faces);
                }
                Err(refusal) => match refusal.kind {
                    RefusalKind::SecondFan(v) => {
                        self.waiting.entry(v.0).or_default().push(r);
                        self.deferred.insert(r, refusal);
                    }
                    _ => self.refuse(r, i, refusal),
                },
            }
        }
    }

    /// Records face `f` for rank `r` (input `i`) and queues the faces waiting at its corners.
    fn accept(&mut self, r: usize, i: usize, f: FaceId, faces: &[[u32; 4]]) {
        self.done[r] = true;
        self.deferred.remove(&r);
        self.out.inserted[i] = Some(f);
        self.added.push((r, f));
        for v in faces[i] {
            if let Some(list) = self.waiting.remove(&v) {
                let done = &self.done;
                self.heap.extend(list.into_iter().filter(|&q| !done[q]).map(Reverse));
            }
        }
    }

    /// Refuses rank `r` (input `i`) for good.
    fn refuse(&mut self, r: usize, i: usize, refusal: Refusal) {
        self.done[r] = true;
        self.deferred.remove(&r);
        self.out.refused.push((i, refusal));
    }
}

/// The corners of quad `q` sorted: the same for every cyclic start and orientation, so
/// it names the face's vertex set (how candidates, faces and ground truth are matched).
pub fn corner_set(q: [u32; 4]) -> [u32; 4] {
    let mut k = q;
    k.sort_unstable();
    k
}

/// Whether quads `a` and `b` list the same corners in the same cyclic order (any start).
pub fn same_cycle(a: [u32; 4], b: [u32; 4]) -> bool {
    (0..4).any(|k| (0..4).all(|i| a[(i + k) % 4] == b[i]))
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
    /// order and orientation (see [`HalfedgeMesh::insert_faces`]).
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

    /// Every live face's corner set (sorted corners), the list sorted: two meshes with
    /// the same faces, whatever their order, cyclic starts or ids, give the same list.
    pub fn corner_sets(&self) -> Vec<[u32; 4]> {
        let mut v: Vec<[u32; 4]> =
            self.faces().map(|f| corner_set(self.face_vertices(f).map(|v| v.0))).collect();
        v.sort_unstable();
        v
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
        let plan = self.plan_face(vs, false)?;
        Ok(self.apply_plan(plan))
    }

    /// Inserts `faces[order[0]]`, `faces[order[1]]`, … (earlier = higher priority) and
    /// returns a mesh whose every vertex has one fan. Indices in `order` that are out of
    /// range are ignored.
    ///
    /// Any face set that forms an oriented 2-manifold goes in whole, in any order and
    /// orientation. Faces that do not fit are refused; among faces that conflict, the
    /// earlier wins, except that a face that would start a second fan at a corner waits.
    /// Two phases:
    /// 1. Faces in priority order, each as [`HalfedgeMesh::add_face`] would take it; a face
    ///    refused only because a corner has a fan it does not touch by an edge waits, and
    ///    is retried (still in priority order) each time a face is added at that corner.
    /// 2. Waiting faces can block each other for good: B waits at vertex v until D gives
    ///    it an edge there, while D waits at w for B (the smallest case is in the tests).
    ///    Then the first waiting face that some other waiting face could join is forced
    ///    in, starting a second fan at its corner, and phase 1 resumes; a face may now
    ///    also join two fans of a vertex. When nothing can be forced any more, every vertex
    ///    must have one fan again. Where one has more, the fan holding its oldest face
    ///    stays and the faces of its other fans (all from phase 2) are taken back; phase 2
    ///    restarts from the end of phase 1 without them. After `FORCE_ROUNDS` rounds it
    ///    forces nothing, which leaves phase 1's mesh.
    /// 3. The faces taken back are offered again as in phase 1 (what they conflicted with
    ///    may have gone too).
    ///
    /// So phase 2 only adds faces to what phase 1 inserted, phase 1 inserts what
    /// face-by-face insertion with waiting does, and no refused face fits the final mesh
    /// (`add_face` refuses it). Faces still waiting at the end are refused with
    /// [`RefusalKind::SecondFan`].
    pub fn insert_faces(&mut self, faces: &[[u32; 4]], order: &[usize]) -> InsertOutcome {
        let mut run = Batch {
            heap: (0..order.len()).filter(|&r| order[r] < faces.len()).map(Reverse).collect(),
            waiting: HashMap::new(),
            deferred: BTreeMap::new(),
            done: vec![false; order.len()],
            added: Vec::new(),
            out: InsertOutcome { inserted: vec![None; faces.len()], refused: Vec::new() },
        };
        run.drain(self, faces, order);
        let mut taken_back: BTreeSet<usize> = BTreeSet::new();
        if !run.deferred.is_empty() {
            let start = (self.clone(), run.clone());
            let phase2 = run.added.len();
            for round in 0..=FORCE_ROUNDS {
                if round > 0 {
                    (*self, run) = start.clone();
                }
                for &r in &taken_back {
                    run.done[r] = true;
                    run.deferred.remove(&r);
                }
                if round == FORCE_ROUNDS {
                    break;
                }
                let forced = self.force_waiting(&mut run, faces, order);
                let culprits = self.second_fans(&forced, &run.added[phase2..], faces, order);
                if culprits.is_empty() {
                    break;
                }
                taken_back.extend(culprits);
            }
        }
        // Step 3: the faces taken back get a last pass as in phase 1.
        for &r in &taken_back {
            run.done[r] = false;
            run.heap.push(Reverse(r));
        }
        run.drain(self, faces, order);
        let Batch { deferred, mut out, .. } = run;
        let mut rest: Vec<(usize, Refusal)> = deferred.into_iter().collect();
        rest.sort_by_key(|(r, _)| *r);
        out.refused.extend(rest.into_iter().map(|(r, e)| (order[r], e)));
        out
    }

    /// Phase 2 of [`HalfedgeMesh::insert_faces`]: while faces wait, forces the first in,
    /// allowing it to start second fans, then resumes phase 1. Returns the forced ranks
    /// with their faces.
    ///
    /// Only a face that could be joined is forced: at each corner where it would start a
    /// fan, another waiting face must share one of its edges there (in a manifold, the
    /// face across such an edge is waiting). Others stay waiting, to be refused at the
    /// end: no face starts waiting in this phase, so a face without a partner never gets
    /// one, and a wrong quad touching the surface at one vertex is not forced at all.
    fn force_waiting(
        &mut self,
        run: &mut Batch,
        faces: &[[u32; 4]],
        order: &[usize],
    ) -> Vec<(usize, FaceId)> {
        let mut forced = Vec::new();
        let mut by_corner: HashMap<u32, Vec<usize>> = HashMap::new();
        for &r in run.deferred.keys() {
            for v in faces[order[r]] {
                by_corner.entry(v).or_default().push(r);
            }
        }
        let mut next = 0;
        while let Some((&r, _)) = run.deferred.range(next..).next() {
            next = r + 1;
            let i = order[r];
            let vs = faces[i];
            let joinable = (0..4).all(|k| {
                let (u, v, w) = (vs[(k + 3) % 4], vs[k], vs[(k + 1) % 4]);
                let starts_fan = self.v_out[v as usize].is_some()
                    && self.find_halfedge(VertexId(u), VertexId(v)).is_none()
                    && self.find_halfedge(VertexId(v), VertexId(w)).is_none();
                !starts_fan
                    || by_corner.get(&v).is_some_and(|list| {
                        list.iter().any(|&g| {
                            let fg = faces[order[g]];
                            g != r
                                && run.deferred.contains_key(&g)
                                && (has_edge(fg, u, v) || has_edge(fg, v, w))
                        })
                    })
            });
            if !joinable {
                continue;
            }
            match self.plan_face(vs.map(VertexId), true) {
                Ok(plan) => {
                    let f = self.apply_plan(plan);
                    run.accept(r, i, f, faces);
                    forced.push((r, f));
                }
                Err(refusal) => run.refuse(r, i, refusal),
            }
            run.drain(self, faces, order);
        }
        forced
    }

    /// After phase 2 (`forced` its forced faces, `added` all it inserted): the ranks of the
    /// faces to take back. Fans multiply only at corners of forced faces. At such a corner
    /// that holds several fans, the fan holding the vertex's oldest face stays: it holds
    /// any face phase 1 put there. The faces of its other fans go, all of them at once (a
    /// chain of wrong faces around the vertex would otherwise lose one face per round).
    fn second_fans(
        &self,
        forced: &[(usize, FaceId)],
        added: &[(usize, FaceId)],
        faces: &[[u32; 4]],
        order: &[usize],
    ) -> BTreeSet<usize> {
        let mut later_fans: HashSet<FaceId> = HashSet::new();
        let mut seen: HashSet<u32> = HashSet::new();
        for &(r, _) in forced {
            for v in faces[order[r]] {
                if !seen.insert(v) {
                    continue;
                }
                let v = VertexId(v);
                let starts: Vec<HalfedgeId> =
                    self.vertex_outgoing(v).filter(|&h| self.is_boundary(h)).collect();
                if starts.len() < 2 {
                    continue;
                }
                // Face ids grow with insertion time.
                let fans: Vec<Vec<FaceId>> = starts.iter().map(|&h| self.fan_faces(h)).collect();
                let oldest = (0..fans.len())
                    .min_by_key(|&k| fans[k].iter().min().copied())
                    .expect("internal error: a vertex with two fans has a fan");
                for (_, fan) in fans.into_iter().enumerate().filter(|&(k, _)| k != oldest) {
                    later_fans.extend(fan);
                }
            }
        }
        added.iter().filter(|(_, f)| later_fans.contains(f)).map(|&(r, _)| r).collect()
    }

    fn refuse(kind: RefusalKind, msg: String) -> std::result::Result<Plan, Refusal> {
        Err(Refusal { kind, msg })
    }

    /// Every check of `add_face`, without mutating. With `new_fan` (phase 2 of
    /// `insert_faces`), a corner may start a second fan.
    fn plan_face(&self, vs: [VertexId; 4], new_fan: bool) -> std::result::Result<Plan, Refusal> {
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
        let mut exists = [None; 4];
        let mut forward: Vec<FaceId> = Vec::new();
        let mut reverse: Vec<FaceId> = Vec::new();
        for i in 0..4 {
            let (a, b) = (vs[i], vs[(i + 1) % 4]);
            let Some(h) = self.find_halfedge(a, b) else { continue };
            exists[i] = Some(h);
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
        // Vertices: the quad must attach to the fan of each corner, or the corner is isolated.
        for i in 0..4 {
            let v = vs[i];
            let Some(h) = self.v_out[v.idx()] else { continue };
            if !self.is_boundary(h) {
                return Self::refuse(
                    RefusalKind::ClosedVertex,
                    format!("{v} is interior (its faces already form a closed disk)"),
                );
            }
            match (exists[(i + 3) % 4], exists[i]) {
                (None, None) if !new_fan => {
                    return Self::refuse(
                        RefusalKind::SecondFan(v),
                        format!(
                            "{v} already has a fan of faces the quad does not attach to (non-manifold vertex)"
                        ),
                    );
                }
                (Some(a), Some(b)) if self.closes_one_of_several_fans(v, a, b) => {
                    return Self::refuse(
                        RefusalKind::SecondFan(v),
                        format!(
                            "the quad would close a fan of {v} into a disk while {v} has another fan (non-manifold vertex)"
                        ),
                    );
                }
                _ => {}
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

    /// Whether a quad whose edges at corner `v` are the existing edges of `a` and `b` (one
    /// half-edge of each, either direction) would close one fan of `v` into a disk while
    /// `v` holds another. Each edge has one face, so one boundary half-edge; where `v` has a
    /// single fan those are its ends, the incoming one linked to the outgoing one. That
    /// link also holds when the edges end two different fans that follow each other around
    /// `v`, which the quad merely joins; only otherwise is the fan walked.
    fn closes_one_of_several_fans(&self, v: VertexId, a: HalfedgeId, b: HalfedgeId) -> bool {
        let free = |h: HalfedgeId| if self.is_boundary(h) { h } else { h.opposite() };
        let (x, y) = (free(a), free(b));
        let (b_in, b_out) = match (self.to_vertex(x) == v, self.to_vertex(y) == v) {
            (true, false) => (x, y),
            (false, true) => (y, x),
            // Both enter (or both leave) v: two fans of opposite orientation, never one.
            _ => return false,
        };
        self.next(b_in) != b_out && self.fan_end(b_out) == b_in
    }

    /// The boundary half-edge entering the vertex at the other end of the open fan that
    /// starts with boundary half-edge `b_out` (leaving the vertex): walks the fan's faces.
    fn fan_end(&self, b_out: HalfedgeId) -> HalfedgeId {
        let mut t = b_out.opposite();
        for _ in 0..self.he_to.len() {
            let i = self.next(t).opposite();
            if self.is_boundary(i) {
                return i;
            }
            t = i;
        }
        panic!("internal error: the fan of {b_out} does not end (corrupt mesh)")
    }

    /// The faces of the open fan that starts with boundary half-edge `b_out`, in order.
    fn fan_faces(&self, b_out: HalfedgeId) -> Vec<FaceId> {
        let mut fan = Vec::new();
        let mut t = b_out.opposite();
        while let Some(f) = self.face(t) {
            fan.push(f);
            if fan.len() > self.f_he.len() {
                panic!("internal error: the fan of {b_out} does not end (corrupt mesh)");
            }
            t = self.next(t).opposite();
        }
        fan
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
    /// x moves to opp x; boundary loops of the patch reverse with it. They link only
    /// half-edges of the patch, except (inside `insert_faces`) around a vertex whose fans
    /// belong to the patch and to other components: there the fans are relinked afterwards.
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
        // Vertices where a boundary half-edge of the patch links to one of another
        // component: their fans, each as (incoming end, outgoing start, in the patch).
        let mut mixed: Vec<(VertexId, Vec<FanEnds>)> = Vec::new();
        for &e in &edges {
            for x in [HalfedgeId(2 * e as u32), HalfedgeId(2 * e as u32 + 1)] {
                if !self.is_boundary(x) || seen.contains(&self.next(x).edge()) {
                    continue;
                }
                let v = self.to_vertex(x);
                if mixed.iter().any(|(w, _)| *w == v) {
                    continue;
                }
                let fans = self
                    .vertex_outgoing(v)
                    .filter(|&h| self.is_boundary(h))
                    .map(|h| (self.fan_end(h), h, seen.contains(&h.edge())))
                    .collect();
                mixed.push((v, fans));
            }
        }
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
        // A flipped fan's ends swap: its new outgoing start is the twin of its old incoming
        // end, and the other way round. Link each fan's end to the next fan's start.
        for (v, fans) in mixed {
            let swap = |(b_in, b_out, flipped): FanEnds| {
                if flipped {
                    (b_out.opposite(), b_in.opposite())
                } else {
                    (b_in, b_out)
                }
            };
            let ends: Vec<(HalfedgeId, HalfedgeId)> = fans.into_iter().map(swap).collect();
            for k in 0..ends.len() {
                self.link(ends[k].0, ends[(k + 1) % ends.len()].1);
            }
            self.v_out[v.idx()] = Some(ends[0].1);
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
        // reading the old links before writing any. Every link made at corner v is a link
        // at v (the next of a half-edge entering v, the prev of one leaving it), so corners
        // do not disturb each other.
        let mut links: Vec<(HalfedgeId, HalfedgeId)> = Vec::with_capacity(12);
        let mut outs: Vec<(VertexId, HalfedgeId)> = Vec::with_capacity(4);
        for i in 0..4 {
            let j = (i + 1) % 4;
            let (hin, hout, v) = (hs[i], hs[j], q[j]);
            match (is_new[i], is_new[j]) {
                // Closing a fan, or joining two fans that follow each other around v:
                // next(in) is already out.
                (false, false) if self.next(hin) == hout => {}
                // Joining fan A (ending with `hin`) to fan B (starting with `hout`) where
                // other fans lie between them around v: those fans move after B.
                (false, false) => {
                    let (first, last) = (self.next(hin), self.prev(hout));
                    let b_end = self.fan_end(hout);
                    debug_assert!(b_end != hin, "internal error: closing one of several fans");
                    links.push((b_end, first));
                    links.push((last, self.next(b_end)));
                }
                (false, true) => links.push((hout.opposite(), self.next(hin))),
                (true, false) => {
                    links.push((self.prev(hout), hin.opposite()));
                    outs.push((v, hin.opposite()));
                }
                // A new fan at v: alone, or (phase 2 of insert_faces) put into the cycle of
                // v's fans before the fan that starts with v's stored half-edge.
                (true, true) => {
                    match self.v_out[v.idx()] {
                        None => links.push((hout.opposite(), hin.opposite())),
                        Some(b_out) => {
                            links.push((self.prev(b_out), hin.opposite()));
                            links.push((hout.opposite(), b_out));
                        }
                    }
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

    /// Removes the live faces `fs`, each as soon as it can go: one in the middle of a
    /// corner's open fan ([`HalfedgeMesh::remove_face`] refuses it) waits for the faces
    /// around it. Returns the corners of the faces removed, in removal order; faces that
    /// never could go stay (fewer corners than `fs` then).
    pub fn remove_faces(&mut self, fs: &[FaceId]) -> Vec<[VertexId; 4]> {
        let mut left: Vec<FaceId> = fs.to_vec();
        let mut out: Vec<[VertexId; 4]> = Vec::with_capacity(fs.len());
        while !left.is_empty() {
            let before = left.len();
            left.retain(|&f| {
                let c = self.face_vertices(f);
                let gone = self.remove_face(f).is_ok();
                if gone {
                    out.push(c);
                }
                !gone
            });
            if left.len() == before {
                break;
            }
        }
        out
    }

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
        super::same_cycle(a.map(|v| v.0), b)
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

    /// The smallest case of faces waiting on each other (found by shrinking the voxel cage
    /// of issue 3's failing property case): an L of four quads given in the order A, B,
    /// C, D. B touches A only at vertex 0 until D is in; D touches C only at vertex 6
    /// until B is in. Face by face, both wait for ever.
    fn waiting_pair() -> Vec<[u32; 4]> {
        vec![[0, 1, 2, 3], [4, 5, 6, 0], [7, 8, 6, 5], [0, 6, 9, 1]]
    }

    #[test]
    fn faces_waiting_on_each_other_go_in() {
        let quads = waiting_pair();
        let mut m = HalfedgeMesh::new(10);
        m.add_face(q(0, 1, 2, 3)).unwrap();
        m.add_face(q(7, 8, 6, 5)).unwrap();
        for (f, v) in [(quads[1], 0), (quads[3], 6)] {
            let r = m.try_add_face(f.map(VertexId)).unwrap_err();
            assert_eq!(r.kind, RefusalKind::SecondFan(VertexId(v)), "{}", r.msg);
        }
        for order in [[0, 1, 2, 3], [0, 2, 1, 3], [0, 2, 3, 1], [2, 0, 3, 1]] {
            let mut m = HalfedgeMesh::new(10);
            let out = m.insert_faces(&quads, &order);
            assert!(out.refused.is_empty(), "{order:?}: {:?}", out.refused);
            assert!(out.inserted.iter().all(|f| f.is_some()));
            validate(&m).unwrap();
            assert_eq!(m.boundary_loops().len(), 1);
        }
    }

    #[test]
    fn a_face_that_leaves_a_second_fan_is_refused_and_the_rest_kept() {
        // A bowtie: the second quad only touches the first at vertex 0.
        let mut m = HalfedgeMesh::new(7);
        let out = m.insert_faces(&[[0, 1, 2, 3], [0, 4, 5, 6]], &[0, 1]);
        assert_eq!(out.refused.len(), 1);
        assert_eq!((out.refused[0].0, out.refused[0].1.kind), (1, RefusalKind::SecondFan(VertexId(0))));
        assert!(out.refused[0].1.msg.contains("vertex 0"), "{}", out.refused[0].1.msg);
        validate(&m).unwrap();
        assert_eq!(m.n_faces(), 1);
        // The waiting pair with two wrong quads W1, W2 at vertex 0 (sharing an edge, so
        // each could join the other), ahead of B and D: W1 is forced first, W2 joins it,
        // and their fan at 0 stays apart from the true one, so both are taken back; the
        // four true faces stay. Alone, W1 would not even be forced (nothing could join it).
        for with_w2 in [true, false] {
            let mut quads = waiting_pair();
            quads.push([0, 10, 11, 12]);
            quads.push([0, 12, 13, 14]);
            let order: &[usize] = if with_w2 { &[0, 4, 5, 1, 2, 3] } else { &[0, 4, 1, 2, 3] };
            let mut m = HalfedgeMesh::new(15);
            let out = m.insert_faces(&quads, order);
            let n_wrong = if with_w2 { 2 } else { 1 };
            assert_eq!(out.refused.len(), n_wrong, "{:?}", out.refused);
            for (k, (i, r)) in out.refused.iter().enumerate() {
                assert_eq!((*i, r.kind), (4 + k, RefusalKind::SecondFan(VertexId(0))), "{}", r.msg);
            }
            validate(&m).unwrap();
            assert!(out.inserted[..4].iter().all(|f| f.is_some()));
            // Nothing refused fits the result.
            let before = m.clone();
            for (i, _) in &out.refused {
                assert!(m.add_face(quads[*i].map(VertexId)).is_err());
            }
            assert_eq!(m, before);
        }
    }

    /// Forces `vs` in as phase 2 does (a corner may start a second fan).
    fn force(m: &mut HalfedgeMesh, vs: [VertexId; 4]) -> std::result::Result<FaceId, Refusal> {
        let plan = m.plan_face(vs, true)?;
        let f = m.apply_plan(plan);
        crate::mesh::validate::validate_with_several_fans(m).unwrap();
        Ok(f)
    }

    #[test]
    fn fans_are_joined_around_other_fans_and_never_closed_beside_one() {
        // The 2×2 grid around vertex 4, and a quad W = (4, 9, 10, 11) touching it at 4.
        let mut m = HalfedgeMesh::new(12);
        m.add_face(q(0, 1, 4, 3)).unwrap();
        force(&mut m, q(4, 9, 10, 11)).unwrap();
        // (4, 5, 8, 7) opposite, reversed: a third fan at 4, of the other orientation.
        force(&mut m, q(4, 7, 8, 5)).unwrap();
        assert_eq!(m.vertex_outgoing(VertexId(4)).filter(|&h| m.is_boundary(h)).count(), 3);
        // (1, 2, 5, 4) joins the first and third fans, which W separates in the cycle
        // around 4, and one of them is flipped to agree with the other.
        m.add_face(q(1, 2, 5, 4)).unwrap();
        crate::mesh::validate::validate_with_several_fans(&m).unwrap();
        assert_eq!(m.vertex_outgoing(VertexId(4)).filter(|&h| m.is_boundary(h)).count(), 2);
        // (3, 4, 7, 6) would close that fan into a disk while W's fan remains.
        let after = m.clone();
        for new_fan in [false, true] {
            let r = m.plan_face(q(3, 4, 7, 6), new_fan).map(|_| ()).unwrap_err();
            assert_eq!(r.kind, RefusalKind::SecondFan(VertexId(4)), "{}", r.msg);
            assert!(r.msg.contains("close"), "{}", r.msg);
        }
        assert_eq!(m, after);
        // Without W the same faces build the grid.
        let mut m = HalfedgeMesh::new(12);
        m.add_face(q(0, 1, 4, 3)).unwrap();
        force(&mut m, q(4, 7, 8, 5)).unwrap();
        m.add_face(q(1, 2, 5, 4)).unwrap();
        m.add_face(q(3, 4, 7, 6)).unwrap();
        validate(&m).unwrap();
    }

    #[test]
    fn forcing_every_face_keeps_the_fan_cycles_consistent() {
        // Every face of closed and open shapes in random order and orientation, each one
        // forced (so vertices collect several fans, of both orientations, that later faces
        // join and patches that get flipped): every step keeps the links consistent, no
        // face is refused, and the end is the valid, consistently oriented mesh.
        use crate::mesh::shapes;
        use crate::rng::Rng;
        let mut rng = Rng::new(4);
        let mut meshes: Vec<(usize, Vec<[u32; 4]>)> = Vec::new();
        for qm in [
            shapes::grid(4, 3, 1.0, 1.0),
            shapes::cube_sphere(3),
            shapes::torus(6, 5, 2.0, 0.7),
            shapes::cylinder(6, 3, 1.0, 1.0, false),
            shapes::voxel_cage(&mut rng, [4, 4, 2], 0.5),
            shapes::voxel_cage(&mut rng, [5, 5, 3], 0.5),
            shapes::voxel_cage(&mut rng, [6, 4, 3], 0.5),
        ] {
            meshes.push((qm.vertices.len(), qm.quads));
        }
        // A sphere of 2k quads with two valence-k poles (0 and 1) around a ring r_i = 2 + i
        // with middles m_i = 2 + k + i: many fans at once around a pole, so that joining
        // two of them often has to move others.
        for k in [6u32, 9, 12, 16] {
            let (r, mid) = (|i: u32| 2 + i % k, |i: u32| 2 + k + i);
            let top = (0..k).map(|i| [0, r(i), mid(i), r(i + 1)]);
            let bottom = (0..k).map(|i| [1, r(i + 1), mid(i), r(i)]);
            meshes.push((2 + 2 * k as usize, top.chain(bottom).collect()));
        }
        for (nv, quads) in &meshes {
            for _ in 0..12 {
                let mut m = HalfedgeMesh::new(*nv);
                let mut order: Vec<usize> = (0..quads.len()).collect();
                rng.shuffle(&mut order);
                let mut made = vec![None; quads.len()];
                for &i in &order {
                    let f = quads[i];
                    let f = if rng.below(2) == 0 { f } else { [f[0], f[3], f[2], f[1]] };
                    made[i] = Some(force(&mut m, f.map(VertexId)).unwrap());
                }
                validate(&m).unwrap();
                let agree = (0..quads.len())
                    .filter(|&i| same_cycle(m.face_vertices(made[i].unwrap()), quads[i]))
                    .count();
                assert!(agree == 0 || agree == quads.len(), "{agree} of {}", quads.len());
            }
        }
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
