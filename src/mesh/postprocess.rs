//! The post-process (DESIGN §4): (a) the paper's score filter on the soup of predicted
//! faces, (b) insertion into the half-edge mesh by probability, refusing whatever would
//! break manifoldness, (c) greedy hole filling, then (not in the paper) the rescue of
//! candidates at holes and the closing of loops left open. The output is a pure-quad, consistently
//! oriented manifold mesh by construction; its first vertices are the input positions.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::close::{
    close_holes, seal, support_near_loops, untangle_with_candidates, CloseConfig, CloseReport,
};
use super::halfedge::{corner_set, same_cycle, HalfedgeMesh, InsertOutcome};
use super::handles::FaceId;
use super::hole_fill::{fill_holes, quad_normal, HoleFillConfig, HoleFillReport};
use super::poly::QuadMesh;
use super::quality::is_degenerate_quad;
use super::rescue::{remove_small_open_components, rescue_faces, RescueConfig};
use super::soup::FaceSoup;
use crate::error::{Error, Result};
use crate::math::{cross, dot};

/// Settings of the post-process.
#[derive(Clone, Debug, PartialEq)]
pub struct PostprocessConfig {
    /// Faces scoring above this are deleted by step (a). The paper uses 2: it deletes faces
    /// with a non-manifold edge and also faces with two or more boundary edges, so every
    /// hole grows to its bounding "rectangle" and nearby holes merge; measured on a
    /// cube-sphere of 21,600 quads with 5% of the faces missing, limit 2 deleted every face.
    /// The default, 10, deletes only faces with a non-manifold edge (same scores and order
    /// otherwise); holes are left to step (c).
    pub score_limit: u32,
    /// Whether step (a) runs at all.
    pub score_filter: bool,
    /// Step (b) inserts by `p + support_weight · support` instead of `p` alone, where
    /// `support` is the mean over the face's four sides of the highest probability of
    /// another kept face across that side ([`support_priority`]). 0 = the paper's order
    /// (probability alone). Default 2, chosen on the validation meshes of `train/` (10%
    /// noise, shipped weights, `examples/recall_breakdown.rs`): face-weighted P / R
    /// 0.9602 / 0.9627 at 0, 0.9625 / 0.9650 at 1, 0.9629 / 0.9650 at 2, 0.9630 / 0.9651
    /// at 8.
    pub support_weight: f32,
    /// Whether that support reads sides like [`crate::pipeline::refine::SideRule::Normals`]:
    /// a face running the side the same way still counts as the neighbour across it
    /// when the two faces' normals point opposite ways ([`opposite_normals`]: one of
    /// them was ordered against the other's orientation). Default true (session 8; false is
    /// the session-4 rule, direction alone).
    pub support_normal_sides: bool,
    /// After step (b), open components of at most this many faces are removed (floaters;
    /// [`remove_small_open_components`]). 0 keeps them.
    pub max_floater_faces: usize,
    /// After that, candidates at holes are rescued from the refused faces and the reserve
    /// ([`rescue_faces`]).
    pub rescue: RescueConfig,
    /// Whether step (c) runs.
    pub fill_holes: bool,
    /// Odd-loop pairing and quadrangulation of the loops left open ([`close_holes`]).
    pub close: CloseConfig,
    /// Hole-filling thresholds.
    pub hole_fill: HoleFillConfig,
    /// After step (b) and the floater removal, faces folded back over a neighbour are
    /// taken out ([`unfold`]): of each edge whose two quads' normals have a dot under
    /// this, the less probable face (or the other, where that one cannot go). −0.95:
    /// folded back within ≈ 18°, which real surfaces almost never are (1 of the 705 edges
    /// under −0.3 of the training set's organic and thin meshes; session 25).
    /// `f64::NEG_INFINITY` turns it off.
    pub unfold_min_dot: f64,
}

impl Default for PostprocessConfig {
    fn default() -> Self {
        PostprocessConfig {
            score_limit: 10,
            score_filter: true,
            support_weight: 2.0,
            support_normal_sides: true,
            max_floater_faces: 4,
            rescue: RescueConfig::default(),
            fill_holes: true,
            close: CloseConfig::default(),
            hole_fill: HoleFillConfig::default(),
            unfold_min_dot: -0.95,
        }
    }
}

/// What the post-process did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PostprocessReport {
    /// Faces given.
    pub faces_in: usize,
    /// Faces dropped before anything else because they repeat a vertex.
    pub degenerate: usize,
    /// Faces dropped before anything else because their corners, though distinct
    /// vertices, have no area: two at one position (all four included) or all on one
    /// line ([`is_degenerate_quad`]). Kept, they would pass every topological check and
    /// leave a zero-area quad in the output.
    pub zero_area: usize,
    /// Faces dropped before anything else because another face has the same four
    /// corners (repeated, or reversed); the likeliest of them stays (ties: the first).
    pub duplicates: usize,
    /// Faces deleted by the score filter (a).
    pub removed_by_score: usize,
    /// Faces inserted into the half-edge mesh (b).
    pub inserted: usize,
    /// Faces refused on insertion because they would break manifoldness (b).
    pub refused_on_insertion: usize,
    /// Faces of small open components removed after insertion.
    pub floater_faces_removed: usize,
    /// Faces taken out after insertion because they were folded back over a neighbour
    /// ([`unfold`]).
    pub unfolded: usize,
    /// Candidates rescued at holes (from refused faces or the reserve).
    pub rescued: usize,
    /// The hole filling's account (c); zero when it did not run.
    pub hole_fill: HoleFillReport,
    /// The closing of loops left open.
    pub close: CloseReport,
    /// Components whose orientation was reversed at the end (see [`orient_components`]).
    pub components_flipped: usize,
    /// Faces in the output.
    pub faces_out: usize,
    /// Boundary loops left in the output.
    pub boundary_loops_out: usize,
}

/// Takes out faces folded back over a neighbour: of each edge whose two quads' normals
/// (the mesh is consistently oriented, so they are comparable across the edge) have a
/// dot under `min_dot`, the less probable face (`prob` by face index; ties: the higher
/// index), lowest probability first, in passes until no such edge is left or no face
/// can go. A removal that would split a vertex's fan is skipped (the mesh stays
/// manifold); when no less probable face can go, the more probable face of a fold goes
/// where it can. Faces without a normal are never judged. Returns how many faces went.
///
/// # Panics
/// If `prob` is shorter than the mesh's face capacity or a face's vertex has no
/// position in `pos`.
pub fn unfold(mesh: &mut HalfedgeMesh, pos: &[[f64; 3]], prob: &[f32], min_dot: f64) -> usize {
    let normal = |mesh: &HalfedgeMesh, f: FaceId| quad_normal(&mesh.face_vertices(f).map(|v| pos[v.idx()]));
    // Whether `f` is the less probable (`less`) or the more probable (`!less`) face of
    // one of its folded edges.
    let on_fold = |mesh: &HalfedgeMesh, f: FaceId, less: bool| -> bool {
        let Some(nf) = normal(mesh, f) else { return false };
        mesh.face_halfedges(f).iter().any(|h| {
            mesh.face(h.opposite()).is_some_and(|g| {
                normal(mesh, g).is_some_and(|ng| dot(nf, ng) < min_dot)
                    && ((prob[f.idx()], g.idx()) < (prob[g.idx()], f.idx())) == less
            })
        })
    };
    let mut removed = 0;
    // One pass over the less probable (`less`) or the more probable faces of the folds,
    // lowest probability first; whether any went.
    let mut take_out = |mesh: &mut HalfedgeMesh, less: bool| {
        let mut faces: Vec<FaceId> = mesh.faces().filter(|&f| on_fold(mesh, f, less)).collect();
        faces.sort_by(|a, b| prob[a.idx()].total_cmp(&prob[b.idx()]).then(b.idx().cmp(&a.idx())));
        let before = removed;
        for f in faces {
            // Still on a fold: an earlier removal may have freed it.
            if mesh.is_face_alive(f) && on_fold(mesh, f, less) && mesh.remove_face(f).is_ok() {
                removed += 1;
            }
        }
        removed > before
    };
    // Only when no fold's less probable face can go (each would split a vertex's fan)
    // does the more probable face of a fold go where it can (session 25).
    while take_out(mesh, true) || take_out(mesh, false) {}
    removed
}

/// The paper's score E_s = (E_b + 1)(10·E_n + 1) from a face's boundary and
/// non-manifold edge counts.
pub fn face_score(boundary_edges: usize, nonmanifold_edges: usize) -> u32 {
    ((boundary_edges + 1) * (10 * nonmanifold_edges + 1)) as u32
}

/// Checks faces and probabilities: lengths agree, indices in range, probabilities finite.
fn check_inputs(n_vertices: usize, faces: &[[u32; 4]], probs: &[f32]) -> Result<()> {
    if probs.len() != faces.len() {
        return Err(Error::invalid(format!(
            "postprocess: {} probabilities for {} faces",
            probs.len(),
            faces.len()
        )));
    }
    for (i, f) in faces.iter().enumerate() {
        if let Some(v) = f.iter().find(|&&v| v as usize >= n_vertices) {
            return Err(Error::invalid(format!(
                "postprocess: face {i} {f:?} uses vertex {v}, but there are {n_vertices} vertices"
            )));
        }
        if !probs[i].is_finite() {
            return Err(Error::invalid(format!("postprocess: face {i} has probability {}", probs[i])));
        }
    }
    Ok(())
}

fn is_degenerate(f: &[u32; 4]) -> bool {
    (0..4).any(|i| (i + 1..4).any(|j| f[i] == f[j]))
}

/// Step (a), the paper's filter: scores every face of the soup, then repeatedly deletes
/// the highest-scoring face while some score exceeds `score_limit`, re-scoring only the
/// faces sharing its edges (a max-heap with lazy invalidation). Ties: lower probability
/// first, then lower index. Faces with `keep[i] == false` on entry are treated as absent.
/// Returns how many faces it deleted; `keep` is updated in place.
///
/// # Panics
/// If `keep` or `probs` is shorter than `faces`.
pub fn score_filter(faces: &[[u32; 4]], probs: &[f32], keep: &mut [bool], score_limit: u32) -> usize {
    let soup = FaceSoup::new(faces);
    let mut count: Vec<u32> = (0..soup.n_edges()).map(|e| soup.edge_faces(e).len() as u32).collect();
    for (f, &k) in keep.iter().enumerate().take(faces.len()) {
        if !k {
            for e in soup.face_edges(f) {
                count[e as usize] -= 1;
            }
        }
    }
    let score_of = |f: usize, count: &[u32]| {
        let fe = soup.face_edges(f);
        let eb = fe.iter().filter(|&&e| count[e as usize] == 1).count();
        let en = fe.iter().filter(|&&e| count[e as usize] > 2).count();
        face_score(eb, en)
    };
    #[derive(PartialEq)]
    struct Entry {
        score: u32,
        prob: f32,
        idx: u32,
    }
    impl Eq for Entry {}
    impl Ord for Entry {
        fn cmp(&self, o: &Self) -> Ordering {
            // Max-heap: higher score, then lower probability, then lower index come out first.
            self.score
                .cmp(&o.score)
                .then_with(|| o.prob.total_cmp(&self.prob))
                .then_with(|| o.idx.cmp(&self.idx))
        }
    }
    impl PartialOrd for Entry {
        fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
            Some(self.cmp(o))
        }
    }
    let mut score = vec![0u32; faces.len()];
    let mut heap = BinaryHeap::with_capacity(faces.len());
    for f in 0..faces.len() {
        if keep[f] {
            score[f] = score_of(f, &count);
            if score[f] > score_limit {
                heap.push(Entry { score: score[f], prob: probs[f], idx: f as u32 });
            }
        }
    }
    let mut removed = 0;
    while let Some(Entry { score: s, idx, .. }) = heap.pop() {
        let f = idx as usize;
        if !keep[f] || s != score[f] {
            continue; // stale entry
        }
        keep[f] = false;
        removed += 1;
        let fe = soup.face_edges(f);
        for &e in &fe {
            count[e as usize] -= 1;
        }
        for &e in &fe {
            for &g in soup.edge_faces(e as usize) {
                let g = g as usize;
                if keep[g] {
                    let ns = score_of(g, &count);
                    if ns != score[g] {
                        score[g] = ns;
                        if ns > score_limit {
                            heap.push(Entry { score: ns, prob: probs[g], idx: g as u32 });
                        }
                    }
                }
            }
        }
    }
    removed
}

/// Insertion priorities `p + weight · support`: `support` is the mean, over the face's
/// four sides a → b, of the highest probability of another kept face running b → a
/// (0 where none, and for a side repeating a vertex). A face with `keep[i] == false`
/// gets `p` alone (the order never inserts it; computing its support cost time
/// quadratic in the faces on one edge). A true face of a surface has a
/// true neighbour across every interior edge; a wrong one (over a diagonal, or spanning
/// two cells) has sides no other face confirms. Candidates come oriented by consistently
/// propagated normals, so a neighbour runs a shared side the other way round.
///
/// # Panics
/// If `keep` or `probs` is shorter than `faces`.
///
/// With `positions` (the faces' corners), a face running the side the same way counts
/// as across it when the two faces' normals are opposite ([`opposite_normals`]), and
/// one running it the other way then does not, so a neighbour ordered against this
/// face's orientation (an orientation seam of the point normals) still confirms it;
/// without, by direction alone.
pub fn support_priority(
    positions: Option<&[[f64; 3]]>,
    faces: &[[u32; 4]],
    probs: &[f32],
    keep: &[bool],
    weight: f32,
) -> Vec<f32> {
    // Each face's unit normal from its own order (zero for a degenerate face).
    let nrm: Option<Vec<[f32; 3]>> = positions.map(|pos| {
        faces
            .iter()
            .map(|q| quad_normal(&q.map(|i| pos[i as usize])).map_or([0.0; 3], |n| n.map(|x| x as f32)))
            .collect()
    });
    let soup = FaceSoup::new(faces);
    // Whether face `g` runs from `a` to `b` along one of its sides.
    let runs = |g: &[u32; 4], a: u32, b: u32| (0..4).any(|i| g[i] == a && g[(i + 1) % 4] == b);
    (0..faces.len())
        .map(|f| {
            if !keep[f] {
                // Never inserted by this order; its support is not needed.
                return probs[f];
            }
            let fv = faces[f];
            let fe = soup.face_edges(f);
            let support: f32 = (0..4)
                .map(|i| {
                    let (a, b) = (fv[i], fv[(i + 1) % 4]);
                    if a == b {
                        return 0.0;
                    }
                    // The neighbour across side a → b runs it b → a (consistent
                    // orientation); a face running a → b lies on the same side: a rival.
                    soup.edge_faces(fe[i] as usize)
                        .iter()
                        .filter(|&&g| {
                            g as usize != f
                                && keep[g as usize]
                                && match &nrm {
                                    None => runs(&faces[g as usize], b, a),
                                    Some(n) => {
                                        let gf = &faces[g as usize];
                                        if opposite_normals(n[f], n[g as usize]) {
                                            runs(gf, a, b)
                                        } else {
                                            runs(gf, b, a)
                                        }
                                    }
                                }
                        })
                        .map(|&g| probs[g as usize])
                        .fold(0.0f32, f32::max)
                })
                .sum();
            probs[f] + weight * support / 4.0
        })
        .collect()
}

/// Whether two faces' unit normals (each from its own cyclic order) point opposite
/// ways: more than 120° apart (dot ≤ −0.5). Two faces sharing an edge normally lie on
/// the same side of it when they run it the same way (a rival) and across it when they
/// run it the opposite way (a neighbour), which holds where their orders are
/// consistently oriented; when their normals are opposite, one of them was ordered
/// against the other's orientation (an orientation seam of the propagated point
/// normals) and the reading is reversed. Between −0.5 and 1 the direction decides: at
/// a sharp 90° edge the normals say nothing. (Also the refinement rounds' rule:
/// [`crate::pipeline::refine::SideRule::Normals`].)
pub fn opposite_normals(nc: [f32; 3], nd: [f32; 3]) -> bool {
    nc[0] * nd[0] + nc[1] * nd[1] + nc[2] * nd[2] <= -0.5
}

/// The insertion order of step (b): faces with `keep[i]`, highest probability first,
/// ties by lower index.
pub fn insertion_order(probs: &[f32], keep: &[bool]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..keep.len()).filter(|&i| keep[i]).collect();
    order.sort_by(|&a, &b| probs[b].total_cmp(&probs[a]).then(a.cmp(&b)));
    order
}

/// Step (b): inserts `faces[order[..]]` into a fresh mesh of `n_vertices` vertices,
/// refusing what would break manifoldness (see [`HalfedgeMesh::insert_faces`]).
pub fn insert_by_priority(
    n_vertices: usize,
    faces: &[[u32; 4]],
    order: &[usize],
) -> (HalfedgeMesh, InsertOutcome) {
    let mut mesh = HalfedgeMesh::new(n_vertices);
    let out = mesh.insert_faces(faces, order);
    (mesh, out)
}

/// Gives each connected component a meaningful orientation: a closed component faces
/// outward (positive signed volume); an open one takes the orientation most of its inserted
/// faces had in the input (candidates come oriented by consistently propagated normals),
/// since insertion may have flipped patches to make them agree. Returns how many
/// components were flipped.
pub fn orient_components(
    mesh: &mut HalfedgeMesh,
    positions: &[[f64; 3]],
    faces: &[[u32; 4]],
    out: &InsertOutcome,
) -> usize {
    // The inserted faces as given, by corner set: face ids are not stable (a face taken
    // out and put back by the later steps gets a new id, and a freed id is reused).
    let given: std::collections::HashMap<[u32; 4], [u32; 4]> = out
        .inserted
        .iter()
        .zip(faces)
        .filter(|(f, _)| f.is_some())
        .map(|(_, q)| (corner_set(*q), *q))
        .collect();
    let mut as_given = vec![0i8; mesh.face_capacity()];
    for f in mesh.faces() {
        let got = mesh.face_vertices(f).map(|v| v.0);
        if let Some(&q) = given.get(&corner_set(got)) {
            as_given[f.idx()] = if same_cycle(got, q) { 1 } else { -1 };
        }
    }
    let mut flipped = 0;
    for comp in mesh.connected_components() {
        let closed =
            comp.iter().all(|&f| mesh.face_halfedges(f).iter().all(|h| !mesh.is_boundary(h.opposite())));
        let flip = if closed {
            let mut vol = 0.0;
            for &f in &comp {
                let p = mesh.face_vertices(f).map(|v| positions[v.idx()]);
                vol += dot(p[0], cross(p[1], p[2])) + dot(p[0], cross(p[2], p[3]));
            }
            vol < 0.0
        } else {
            comp.iter().map(|f| as_given[f.idx()] as i64).sum::<i64>() < 0
        };
        if flip {
            mesh.flip_component(comp[0]).expect("internal error: component face is live");
            flipped += 1;
        }
    }
    flipped
}

/// The whole post-process, after dropping faces that repeat a vertex or have no area
/// ([`PostprocessReport::degenerate`], [`PostprocessReport::zero_area`]): (a) score filter,
/// (b) manifold insertion by probability and removal of floaters, (c) hole filling, the
/// rescue of refused faces at holes, the closing of loops left open ([`close_holes`]),
/// hole filling again where those changed the loops and floaters again, then
/// [`orient_components`]. Same as [`postprocess_with_reserve`] with an empty reserve.
///
/// # Errors
/// As [`postprocess_with_reserve`].
pub fn postprocess(
    positions: &[[f64; 3]],
    faces: &[[u32; 4]],
    probs: &[f32],
    cfg: &PostprocessConfig,
) -> Result<(QuadMesh, PostprocessReport)> {
    postprocess_with_reserve(positions, faces, probs, &[], &[], cfg)
}

/// The post-process of `faces` (the predicted ones, with their probabilities), where
/// `reserve` holds candidates predicted not to be faces (with theirs): they never enter
/// by step (b), but the rescue after it may use them at holes, as it may use predicted
/// faces that step (b) refused. The output's vertices are `positions` (bit-identical, in
/// order) followed by any vertex the hole filling added; vertices no face uses stay in
/// place.
///
/// # Errors
/// `InvalidInput` when probabilities and faces differ in length, a face index is out of
/// range, a probability is not finite, or a position is not finite.
pub fn postprocess_with_reserve(
    positions: &[[f64; 3]],
    faces: &[[u32; 4]],
    probs: &[f32],
    reserve: &[[u32; 4]],
    reserve_probs: &[f32],
    cfg: &PostprocessConfig,
) -> Result<(QuadMesh, PostprocessReport)> {
    check_inputs(positions.len(), faces, probs)?;
    check_inputs(positions.len(), reserve, reserve_probs)?;
    if let Some(i) = positions.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::invalid(format!("postprocess: vertex {i} has a non-finite coordinate")));
    }
    let mut report = PostprocessReport { faces_in: faces.len(), ..Default::default() };
    let usable = |f: &[u32; 4]| !is_degenerate(f) && !is_degenerate_quad(&f.map(|v| positions[v as usize]));
    let mut keep: Vec<bool> = faces.iter().map(|f| !is_degenerate(f)).collect();
    report.degenerate = keep.iter().filter(|k| !**k).count();
    for (k, f) in keep.iter_mut().zip(faces) {
        if *k && is_degenerate_quad(&f.map(|v| positions[v as usize])) {
            *k = false;
            report.zero_area += 1;
        }
    }
    // Faces over the same corner set: one stays. Thousands of copies of a face otherwise
    // make the filter and the insertion quadratic (every copy re-scored at each removal).
    let mut by_set: std::collections::HashMap<[u32; 4], usize> = std::collections::HashMap::new();
    for i in 0..faces.len() {
        if !keep[i] {
            continue;
        }
        match by_set.entry(corner_set(faces[i])) {
            std::collections::hash_map::Entry::Vacant(e) => {
                e.insert(i);
            }
            std::collections::hash_map::Entry::Occupied(mut e) => {
                let j = *e.get();
                if probs[i] > probs[j] {
                    keep[j] = false;
                    e.insert(i);
                } else {
                    keep[i] = false;
                }
                report.duplicates += 1;
            }
        }
    }
    let usable_before_filter = keep.clone();
    if cfg.score_filter {
        report.removed_by_score = score_filter(faces, probs, &mut keep, cfg.score_limit);
    }
    let order = if cfg.support_weight != 0.0 {
        let at = cfg.support_normal_sides.then_some(positions);
        insertion_order(&support_priority(at, faces, probs, &keep, cfg.support_weight), &keep)
    } else {
        insertion_order(probs, &keep)
    };
    let (mut mesh, out) = insert_by_priority(positions.len(), faces, &order);
    report.inserted = mesh.n_faces();
    report.refused_on_insertion = out.refused.len();
    report.floater_faces_removed = remove_small_open_components(&mut mesh, cfg.max_floater_faces);
    if cfg.unfold_min_dot > -1.0 {
        let mut face_prob = vec![0.0f32; mesh.face_capacity()];
        for (i, h) in out.inserted.iter().enumerate() {
            if let Some(h) = h {
                face_prob[h.idx()] = probs[i];
            }
        }
        report.unfolded = unfold(&mut mesh, positions, &face_prob, cfg.unfold_min_dot);
    }
    let mut pos = positions.to_vec();
    if cfg.fill_holes {
        report.hole_fill = fill_holes(&mut mesh, &mut pos, &cfg.hole_fill)?;
    }
    if cfg.rescue.enabled {
        // One list: the predicted faces not in the mesh (refused, deleted by the score
        // filter, or floaters), then the reserve.
        let mut all: Vec<[u32; 4]> = Vec::with_capacity(faces.len() + reserve.len());
        let mut all_p: Vec<f32> = Vec::with_capacity(faces.len() + reserve.len());
        let mut pool = Vec::new();
        for (i, f) in faces.iter().enumerate() {
            if usable_before_filter[i] && out.inserted[i].map_or(true, |h| !mesh.is_face_alive(h)) {
                pool.push(all.len());
                all.push(*f);
                all_p.push(probs[i]);
            }
        }
        for (f, &p) in reserve.iter().zip(reserve_probs) {
            // Most of the reserve is far below min_prob: skip it before the area test.
            if p >= cfg.rescue.min_prob && usable(f) {
                pool.push(all.len());
                all.push(*f);
                all_p.push(p);
            }
        }
        report.rescued = rescue_faces(&mut mesh, &pos, &all, &all_p, &pool, &cfg.rescue).len();
    }
    report.close = close_holes(&mut mesh, &pos, &cfg.close);
    if cfg.fill_holes && (report.rescued > 0 || report.close.quads_added > 0) {
        // The rescue and the closing changed the loops: the patterns may now apply.
        // This last fill keeps what it can place of a loop it cannot close: nothing after
        // it fills with new vertices.
        let last = HoleFillConfig { undo_partial_fills: false, ..cfg.hole_fill.clone() };
        let again = fill_holes(&mut mesh, &mut pos, &last)?;
        report.hole_fill.absorb(&again);
    }
    // Rescued faces and removals can leave new floaters.
    report.floater_faces_removed += remove_small_open_components(&mut mesh, cfg.max_floater_faces);
    if cfg.close.enabled && cfg.close.seal {
        let table =
            support_near_loops(&mesh, cfg.close.seal_rings + 1, &[(faces, probs), (reserve, reserve_probs)]);
        seal(&mut mesh, &pos, &cfg.close, &|k| table.get(&k).copied().unwrap_or(0.0), &mut report.close);
    }
    if cfg.close.enabled && cfg.close.untangle {
        report.close.untangled = untangle_with_candidates(
            &mut mesh,
            &pos,
            &cfg.close,
            &[(faces, probs), (reserve, reserve_probs)],
        );
    }
    report.components_flipped = orient_components(&mut mesh, &pos, faces, &out);
    report.faces_out = mesh.n_faces();
    report.boundary_loops_out = mesh.boundary_loops().len();
    let qm = mesh.to_quad_mesh(&pos)?;
    Ok((qm, report))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Session 25's `unfold`: a strip of two unit squares and a third quad hinged on the
    /// strip's end edge at angle θ from the strip continued (θ = 180°: lying back over
    /// the second square; normal dot cos θ). At θ ≥ 170° the less probable of the two
    /// faces on the folded edge goes, whichever it is; creases (θ ≤ 150°) stay; the mesh
    /// stays valid; in any pose.
    #[test]
    fn unfold_takes_out_the_less_probable_face_of_a_fold() {
        let mut rng = crate::rng::Rng::new(25);
        for deg in [0.0f64, 90.0, 150.0, 170.0, 175.0, 180.0] {
            let t = deg.to_radians();
            let d = [t.cos(), 0.0, t.sin()];
            let r = rng.rotation();
            let p: Vec<[f64; 3]> = [
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [2.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
                [2.0, 1.0, 0.0],
                [2.0 + d[0], 0.0, d[2]],
                [2.0 + d[0], 1.0, d[2]],
            ]
            .iter()
            .map(|v| crate::math::mat_vec(&r, *v))
            .collect();
            let quads = [[0, 1, 4, 3], [1, 2, 5, 4], [2, 6, 7, 5]];
            let folded = deg > 165.0;
            for (probs, loser) in [([0.9f32, 0.8, 0.6], 2usize), ([0.9, 0.6, 0.8], 1)] {
                let mut mesh = HalfedgeMesh::from_quads(p.len(), &quads).unwrap();
                let n = unfold(&mut mesh, &p, &probs, -0.95);
                assert_eq!(n, usize::from(folded), "θ = {deg}°");
                super::super::validate::validate(&mesh).unwrap();
                let left: Vec<usize> = mesh.faces().map(|f| f.idx()).collect();
                let want: Vec<usize> = (0..3).filter(|&i| !(folded && i == loser)).collect();
                assert_eq!(left, want, "θ = {deg}°, probabilities {probs:?}");
            }
        }
        // Off: nothing goes.
        let p = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        let mut mesh = HalfedgeMesh::from_quads(6, &[[0, 1, 2, 3], [1, 4, 5, 2]]).unwrap();
        assert_eq!(unfold(&mut mesh, &p, &[0.5, 0.4], f64::NEG_INFINITY), 0);
        assert_eq!(unfold(&mut mesh, &p, &[0.5, 0.4], -0.95), 1);
    }

    #[test]
    fn score_matches_the_paper() {
        assert_eq!(face_score(0, 0), 1);
        assert_eq!(face_score(1, 0), 2);
        assert_eq!(face_score(2, 0), 3);
        assert_eq!(face_score(0, 1), 11);
        assert_eq!(face_score(1, 1), 22);
    }

    #[test]
    fn fin_face_with_most_boundary_goes_first() {
        // Strip of three quads; a fin quad on the middle edge (1, 5) makes it non-manifold.
        // vertices: bottom 0..3, top 4..7; fin uses 1, 5, 8, 9.
        let faces = [[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [1, 5, 9, 8]];
        // Face 0 and the fin both score (3 + 1)(10 + 1) = 44, face 1 scores 33: the tie goes
        // to the lower probability (the fin); after it, no edge is non-manifold.
        let probs = [0.9, 0.9, 0.9, 0.3];
        let mut keep = vec![true; 4];
        let removed = score_filter(&faces, &probs, &mut keep, 10);
        assert_eq!(removed, 1);
        assert_eq!(keep, [true, true, true, false]);
    }

    #[test]
    fn paper_rule_removes_floaters() {
        // Isolated floaters score 5 and go under the paper's rule, not under limit 10.
        let faces = [[0, 1, 2, 3], [10, 11, 12, 13]];
        let probs = [0.5, 0.9];
        let mut keep = vec![true, true];
        assert_eq!(score_filter(&faces, &probs, &mut keep, 10), 0);
        assert_eq!(score_filter(&faces, &probs, &mut keep, 2), 2);
        // A strip of two faces: each has 3 boundary edges (score 4); the lower probability
        // goes first, then the survivor has 4 boundary edges and goes too.
        let faces = [[0, 1, 4, 3], [1, 2, 5, 4]];
        let mut keep = vec![true, true];
        assert_eq!(score_filter(&faces, &[0.9, 0.1], &mut keep, 2), 2);
        // Faces already excluded count as absent.
        let mut keep = vec![true, false];
        assert_eq!(score_filter(&faces, &[0.9, 0.1], &mut keep, 10), 0);
        assert_eq!(keep, [true, false]);
    }

    #[test]
    fn postprocess_keeps_positions_and_rejects_bad_input() {
        let pos = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.5, 0.5]];
        let faces = [[0, 1, 2, 3]];
        let cfg = PostprocessConfig { score_limit: 10, ..Default::default() };
        let (qm, rep) = postprocess(&pos, &faces, &[0.9], &cfg).unwrap();
        assert_eq!(qm.vertices, pos);
        assert_eq!(qm.quads.len(), 1);
        assert_eq!(rep.inserted, 1);
        assert!(postprocess(&pos, &faces, &[f32::NAN], &cfg).is_err());
        assert!(postprocess(&pos, &[[0, 1, 2, 9]], &[0.5], &cfg).is_err());
        assert!(postprocess(&pos, &faces, &[], &cfg).is_err());
        let (qm, rep) = postprocess(&pos, &[[0, 1, 1, 3]], &[0.5], &cfg).unwrap();
        assert_eq!((qm.quads.len(), rep.degenerate), (0, 1));
        let (qm, _) = postprocess(&[], &[], &[], &cfg).unwrap();
        assert!(qm.quads.is_empty());
    }

    #[test]
    fn zero_area_quads_are_dropped_and_counted() {
        // A 2 × 1 strip plus, on extra vertices, a quad collapsed to one point, a
        // collinear quad and a triangle-shaped quad (two corners at one position).
        let mut pos: Vec<[f64; 3]> = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
            [2.0, 1.0, 0.0],
        ];
        pos.extend([[5.0, 5.0, 5.0]; 4]); // 6..10
        pos.extend((0..4).map(|i| [7.0 + i as f64, 3.0, 0.0])); // 10..14
        pos.extend([[0.0, 3.0, 0.0], [1.0, 3.0, 0.0], [1.0, 3.0, 0.0], [0.0, 4.0, 0.0]]); // 14..18
        let faces =
            [[0, 1, 4, 3], [1, 2, 5, 4], [6, 7, 8, 9], [10, 11, 12, 13], [14, 15, 16, 17], [0, 0, 1, 3]];
        for fill_holes in [false, true] {
            let cfg = PostprocessConfig { fill_holes, ..Default::default() };
            let (qm, rep) = postprocess(&pos, &faces, &[0.5; 6], &cfg).unwrap();
            assert_eq!((rep.degenerate, rep.zero_area, rep.inserted), (1, 3, 2), "{rep:?}");
            assert_eq!(qm.quads.len(), 2);
            assert!(qm.quads.iter().all(|q| !is_degenerate_quad(&q.map(|v| qm.vertices[v as usize]))));
            assert_eq!(qm.vertices, pos);
        }
    }

    #[test]
    fn hole_filling_does_not_put_a_zero_area_quad_back() {
        // A 3 × 3 grid whose centre quad has its corners on one slanted line (exactly
        // collinear on paper; rounding leaves its diagonals' cross product ~1e-17, so
        // pattern 1's own shape test sees a normal). Dropping it leaves a 4-edge hole
        // whose only closing quad is the same zero-area one: the hole must stay open.
        let mut pos: Vec<[f64; 3]> = (0..16).map(|i| [(i % 4) as f64, (i / 4) as f64, 0.0]).collect();
        let on_line = |t: f64| [1.5 + 0.1 * t, 1.5 + 0.3 * t, 0.0];
        for (v, t) in [(5, -1.0), (6, 0.7), (10, 2.0), (9, 0.3)] {
            pos[v] = on_line(t);
        }
        let id = |i: u32, j: u32| j * 4 + i;
        let faces: Vec<[u32; 4]> = (0..3)
            .flat_map(|j| (0..3).map(move |i| [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]))
            .collect();
        let centre = faces[4].map(|v| pos[v as usize]);
        assert!(is_degenerate_quad(&centre));
        let (d1, d2) = (crate::math::sub(centre[2], centre[0]), crate::math::sub(centre[3], centre[1]));
        assert_ne!(cross(d1, d2), [0.0; 3], "the case must exercise rounding");
        let probs = vec![0.5; faces.len()];
        let (qm, rep) = postprocess(&pos, &faces, &probs, &PostprocessConfig::default()).unwrap();
        assert_eq!((rep.zero_area, rep.inserted, qm.quads.len()), (1, 8, 8), "{rep:?}");
        assert!(qm.quads.iter().all(|q| !is_degenerate_quad(&q.map(|v| qm.vertices[v as usize]))));
    }

    #[test]
    fn edge_support_lets_a_confirmed_face_beat_a_likelier_rival() {
        // A 2 × 2 grid A B / C D (vertex (i, j) is 3j + i); the rival R shares B's sides
        // (1, 2) and (4, 1) but leaves through vertex 9, above the grid, where no face
        // confirms it.
        let mut pos: Vec<[f64; 3]> = (0..9).map(|v| [(v % 3) as f64, (v / 3) as f64, 0.0]).collect();
        pos.push([1.6, 0.6, 0.5]);
        let faces = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7], [1, 2, 9, 4]];
        let probs = [0.9, 0.6, 0.9, 0.9, 0.7];
        let pri = support_priority(None, &faces, &probs, &[true; 5], 2.0);
        // B: sides 5→4 and 4→1 confirmed by D and A (0.9 each); R: only 4→1.
        assert!((pri[1] - (0.6 + 2.0 * 1.8 / 4.0)).abs() < 1e-6, "{pri:?}");
        assert!((pri[4] - (0.7 + 2.0 * 0.9 / 4.0)).abs() < 1e-6, "{pri:?}");
        let keys = |cfg: &PostprocessConfig| {
            let (qm, _) = postprocess(&pos, &faces, &probs, cfg).unwrap();
            let mut k: Vec<[u32; 4]> = qm
                .quads
                .iter()
                .map(|q| {
                    let mut s = *q;
                    s.sort_unstable();
                    s
                })
                .collect();
            k.sort_unstable();
            k
        };
        // Step (b) alone (no score filter, no hole filling).
        let plain = PostprocessConfig {
            support_weight: 0.0,
            score_filter: false,
            fill_holes: false,
            ..Default::default()
        };
        let supported = PostprocessConfig { score_filter: false, fill_holes: false, ..Default::default() };
        assert!(keys(&plain).contains(&[1, 2, 4, 9]), "by probability alone the rival wins");
        assert_eq!(keys(&supported), vec![[0, 1, 3, 4], [1, 2, 4, 5], [3, 4, 6, 7], [4, 5, 7, 8]]);
    }

    #[test]
    fn insertion_prefers_higher_probability() {
        // Two quads over the same edge (0, 1) plus a third: only two fit on the edge.
        let faces = [[0, 1, 2, 3], [1, 0, 4, 5], [0, 1, 6, 7]];
        let probs = [0.2, 0.9, 0.8];
        let order = insertion_order(&probs, &[true; 3]);
        assert_eq!(order, vec![1, 2, 0]);
        let (m, out) = insert_by_priority(8, &faces, &order);
        assert_eq!(m.n_faces(), 2);
        assert_eq!(out.refused.len(), 1);
        assert_eq!(out.refused[0].0, 0);
    }
}
