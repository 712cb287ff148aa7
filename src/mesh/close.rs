//! Closing what the greedy hole filling leaves (not in the paper; README "Deviations"):
//! - **Odd loops in pairs.** A loop with an odd number of edges cannot be closed by
//!   quads: every quad patch has an even number of border edges. Odd loops come in pairs
//!   (a quad mesh has an even number of border edges in all), and the common case is a
//!   wrong quad over the diagonal of two true ones, which leaves a triangle on each side.
//!   A path of at most `max_path_faces` faces from one odd loop to another is removed,
//!   which merges them into one even loop; that loop is then quadrangulated. If it cannot
//!   be, the faces are put back.
//! - **Even loops by quadrangulation.** An even loop of at most `max_loop_edges` edges is
//!   split into quads over its own vertices (no new vertex) by dynamic programming over
//!   its chords, minimising Σ(1 − scaled Jacobian) under the hole filling's shape and fold
//!   bounds; chords that are already edges of the mesh are not used.

use super::halfedge::{corner_set, same_cycle, HalfedgeMesh};
use super::handles::{FaceId, HalfedgeId, VertexId};
use super::hole_fill::{quad_normal, scaled_jacobian};
use super::quality::is_degenerate_quad;
use crate::math::{add, cross, dot, norm, normalize, scale, sub};

/// Settings of [`close_holes`].
#[derive(Clone, Debug, PartialEq)]
pub struct CloseConfig {
    /// Whether it runs.
    pub enabled: bool,
    /// Longer loops are left open (borders of open surfaces; the dynamic programme costs
    /// O(n⁴) in the loop length).
    pub max_loop_edges: usize,
    /// Minimum scaled Jacobian of each quad of a quadrangulation (0 would let a corner
    /// be straight: a triangle drawn as a quad).
    pub min_scaled_jacobian: f64,
    /// Minimum dot product of a quad's unit normal with the face across each loop edge
    /// it takes (folds are refused).
    pub min_normal_dot: f64,
    /// A loop is a hole, not a border, only when the unit normals of the faces across its
    /// edges agree: |Σ n| ≥ this × their count. The open end of a tube has normals all
    /// round (Σ n ≈ 0) and stays open.
    pub min_loop_coherence: f64,
    /// ... and when the loop, in the order the new faces would take, turns about that mean
    /// normal: (vector area / its norm) · (Σ n / its norm) ≥ this. The outer border of an
    /// open sheet turns the other way (its "hole" is the outside) and stays open.
    pub min_loop_alignment: f64,
    /// Whether odd loops are paired by removing faces between them.
    pub pair_odd_loops: bool,
    /// At most this many faces are removed to join two odd loops (a path across edges).
    pub max_path_faces: usize,
    /// Whether [`untangle`] runs at the end of the post-process: a face whose scaled
    /// Jacobian is under `min_scaled_jacobian` (inverted, folded or flat-cornered) and up
    /// to four faces around it are re-split over the same vertices into better-shaped
    /// quads the classifier believes at least as much.
    pub untangle: bool,
    /// Whether [`seal`] runs after the closing: a loop still open is re-closed by taking
    /// out the faces around it (up to `seal_rings` rings) and quadrangulating the larger
    /// loop that leaves, preferring quads the classifier supports.
    pub seal: bool,
    /// Rings of faces around a loop that [`seal`] may take out (1 = the faces touching
    /// the loop's vertices).
    pub seal_rings: usize,
    /// Most faces [`seal`] takes out around one loop.
    pub seal_max_faces: usize,
    /// Longest loop [`seal`] quadrangulates (after taking faces out).
    pub seal_max_loop_edges: usize,
    /// Weight of (1 − support) in [`seal`]'s quadrangulation cost, beside
    /// (1 − scaled Jacobian): support is the classifier's probability of the quad (0 for
    /// a quad that is no candidate).
    pub seal_support_weight: f64,
    /// Longest path of faces [`seal`] takes out to join an odd loop to another.
    pub seal_max_path_faces: usize,
    /// [`seal`]'s quads go in only if their summed support is at least this times the
    /// summed support of the faces they replace.
    pub seal_keep_support: f64,
}

impl Default for CloseConfig {
    fn default() -> Self {
        CloseConfig {
            enabled: true,
            max_loop_edges: 40,
            min_scaled_jacobian: 0.02,
            min_normal_dot: -0.3,
            min_loop_coherence: 0.5,
            min_loop_alignment: 0.5,
            pair_odd_loops: true,
            max_path_faces: 2,
            untangle: true,
            seal: true,
            seal_rings: 2,
            seal_max_faces: 40,
            seal_max_loop_edges: 60,
            seal_support_weight: 1.0,
            seal_max_path_faces: 8,
            seal_keep_support: 0.8,
        }
    }
}

/// What [`close_holes`] did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CloseReport {
    /// Faces removed to merge two odd loops (and not put back).
    pub faces_removed: usize,
    /// Loops closed by quadrangulation (a merged pair counts once).
    pub loops_closed: usize,
    /// Quads added.
    pub quads_added: usize,
    /// Faces replaced by [`untangle`] (each bad face and the neighbours re-split with it).
    pub untangled: usize,
    /// Loops [`seal`] closed.
    pub sealed: usize,
    /// Faces [`seal`] took out (and did not put back), and quads it added.
    pub seal_removed: usize,
    /// See `seal_removed`.
    pub seal_added: usize,
}

/// The quads (corner lists in loop order) that close the loop `vs` (the from-vertices of
/// its boundary half-edges, in order), or `None` when no quadrangulation meets the bounds.
/// `across[k]` is the unit normal of the face across the loop's edge `vs[k] → vs[k + 1]`
/// (oriented as the new faces will be), if there is one. Chords that are edges of `mesh`
/// are not used. Of all quadrangulations over the loop's vertices that meet the bounds
/// it returns one of least Σ(1 − scaled Jacobian).
///
/// # Panics
/// If `across` is shorter than `vs` or a vertex of `vs` has no position.
pub fn quadrangulate(
    mesh: &HalfedgeMesh,
    pos: &[[f64; 3]],
    vs: &[u32],
    across: &[Option<[f64; 3]>],
    cfg: &CloseConfig,
) -> Option<Vec<[u32; 4]>> {
    quadrangulate_with(mesh, pos, vs, across, cfg, &|_| 0.0)
}

/// [`quadrangulate`] with `extra(q)` (≥ 0, finite) added to the cost of each quad `q`
/// (corners in loop order): of the quadrangulations that meet the bounds it returns one
/// of least Σ(1 − scaled Jacobian + extra).
///
/// # Panics
/// As [`quadrangulate`].
pub fn quadrangulate_with(
    mesh: &HalfedgeMesh,
    pos: &[[f64; 3]],
    vs: &[u32],
    across: &[Option<[f64; 3]>],
    cfg: &CloseConfig,
    extra: &dyn Fn([u32; 4]) -> f64,
) -> Option<Vec<[u32; 4]>> {
    let n = vs.len();
    if n < 4 || n % 2 == 1 {
        return None;
    }
    // A chord (i, j) is usable when it joins two distinct vertices not already joined.
    let chord_ok = |i: usize, j: usize| {
        if j == i + 1 || (i == 0 && j == n - 1) {
            return true; // a loop edge
        }
        vs[i] != vs[j] && mesh.find_halfedge(VertexId(vs[i]), VertexId(vs[j])).is_none()
    };
    let quad_cost = |c: [usize; 4]| -> Option<f64> {
        let q = c.map(|k| vs[k]);
        if (0..4).any(|a| (a + 1..4).any(|b| q[a] == q[b])) {
            return None;
        }
        let p = q.map(|v| pos[v as usize]);
        if is_degenerate_quad(&p) {
            return None;
        }
        let sj = scaled_jacobian(&p);
        if sj.is_nan() || sj < cfg.min_scaled_jacobian {
            return None;
        }
        let nq = quad_normal(&p)?;
        for s in 0..4 {
            let (a, b) = (c[s], c[(s + 1) % 4]);
            let k = if b == a + 1 {
                a
            } else if a == n - 1 && b == 0 {
                n - 1
            } else {
                continue;
            };
            if let Some(m) = across[k] {
                if dot(nq, m) < cfg.min_normal_dot {
                    return None;
                }
            }
        }
        Some(1.0 - sj + extra(q))
    };
    // best[i][j] for the sub-polygon vs[i..=j] closed by the chord (i, j), j − i odd.
    const NONE: f64 = f64::INFINITY;
    let mut best = vec![vec![NONE; n]; n];
    let mut arg = vec![vec![(0usize, 0usize); n]; n];
    for i in 0..n - 1 {
        best[i][i + 1] = 0.0;
    }
    for len in (3..n).step_by(2) {
        for i in 0..n - len {
            let j = i + len;
            if !chord_ok(i, j) {
                continue;
            }
            let mut b_cost = NONE;
            let mut b_arg = (0, 0);
            for a in (i + 1..j).step_by(2) {
                if best[i][a] == NONE {
                    continue;
                }
                for b in (a + 1..j).step_by(2) {
                    let rest = best[i][a] + best[a][b] + best[b][j];
                    if rest >= b_cost {
                        continue;
                    }
                    if let Some(c) = quad_cost([i, a, b, j]) {
                        if rest + c < b_cost {
                            b_cost = rest + c;
                            b_arg = (a, b);
                        }
                    }
                }
            }
            best[i][j] = b_cost;
            arg[i][j] = b_arg;
        }
    }
    if best[0][n - 1] == NONE {
        return None;
    }
    let mut quads = Vec::with_capacity(n / 2 - 1);
    let mut stack = vec![(0usize, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j == i + 1 {
            continue;
        }
        let (a, b) = arg[i][j];
        quads.push([vs[i], vs[a], vs[b], vs[j]]);
        stack.extend([(i, a), (a, b), (b, j)]);
    }
    Some(quads)
}

/// Whether the loop `vs` (with the normals across its edges) is a hole in a surface
/// rather than a border of it: see [`CloseConfig::min_loop_coherence`] and
/// [`CloseConfig::min_loop_alignment`].
fn is_hole(pos: &[[f64; 3]], vs: &[u32], across: &[Option<[f64; 3]>], cfg: &CloseConfig) -> bool {
    let mut sum = [0.0; 3];
    let mut count = 0usize;
    for n in across.iter().flatten() {
        sum = add(sum, *n);
        count += 1;
    }
    if count == 0 || norm(sum) < cfg.min_loop_coherence * count as f64 {
        return false;
    }
    // Vector area about the loop's centroid (translation-invariant, well conditioned).
    let c = vs.iter().fold([0.0; 3], |acc, &v| add(acc, pos[v as usize]));
    let c = scale(c, 1.0 / vs.len() as f64);
    let mut area = [0.0; 3];
    for k in 0..vs.len() {
        let a = sub(pos[vs[k] as usize], c);
        let b = sub(pos[vs[(k + 1) % vs.len()] as usize], c);
        area = add(area, cross(a, b));
    }
    match (normalize(area), normalize(sum)) {
        (Some(a), Some(n)) => dot(a, n) >= cfg.min_loop_alignment,
        _ => false,
    }
}

/// Unit normal of the face across boundary half-edge `h`, if any.
fn normal_across(mesh: &HalfedgeMesh, pos: &[[f64; 3]], h: HalfedgeId) -> Option<[f64; 3]> {
    let f = mesh.face(h.opposite())?;
    quad_normal(&mesh.face_vertices(f).map(|v| pos[v.idx()]))
}

/// Closes the loop through boundary half-edge `start` by quadrangulation; on failure
/// the mesh is unchanged. Returns the number of quads added (0 = not closed).
fn close_loop(mesh: &mut HalfedgeMesh, pos: &[[f64; 3]], start: HalfedgeId, cfg: &CloseConfig) -> usize {
    let Some(lp) = walk_loop(mesh, start, cfg.max_loop_edges + 1) else { return 0 };
    let vs: Vec<u32> = lp.iter().map(|&h| mesh.from_vertex(h).0).collect();
    let across: Vec<Option<[f64; 3]>> = lp.iter().map(|&h| normal_across(mesh, pos, h)).collect();
    if !is_hole(pos, &vs, &across, cfg) {
        return 0;
    }
    let Some(quads) = quadrangulate(mesh, pos, &vs, &across, cfg) else { return 0 };
    let mut added: Vec<FaceId> = Vec::with_capacity(quads.len());
    for q in &quads {
        match mesh.add_face(q.map(VertexId)) {
            Ok(f) => added.push(f),
            Err(_) => {
                for &f in added.iter().rev() {
                    mesh.remove_face(f).expect("internal error: a face just added comes off again");
                }
                return 0;
            }
        }
    }
    added.len()
}

/// The loop of half-edge `h` in a table of [`loop_ids`], if it is a boundary half-edge
/// (the table may be older than the mesh: half-edges added since have none).
fn loop_of(mesh: &HalfedgeMesh, id: &[u32], h: HalfedgeId) -> Option<usize> {
    let m = id.get(h.idx()).copied().unwrap_or(u32::MAX);
    (m != u32::MAX && mesh.is_boundary(h)).then_some(m as usize)
}

/// Which loop each boundary half-edge is on (index into `loops`), by half-edge index.
fn loop_ids(mesh: &HalfedgeMesh, loops: &[Vec<HalfedgeId>]) -> Vec<u32> {
    let mut id = vec![u32::MAX; mesh.halfedge_capacity()];
    for (l, lp) in loops.iter().enumerate() {
        for h in lp {
            id[h.idx()] = l as u32;
        }
    }
    id
}

/// Pairs odd loops and quadrangulates even ones, as the module documentation says.
/// `positions` has one entry per mesh vertex; nothing is added to it.
pub fn close_holes(mesh: &mut HalfedgeMesh, positions: &[[f64; 3]], cfg: &CloseConfig) -> CloseReport {
    let mut report = CloseReport::default();
    if !cfg.enabled {
        return report;
    }
    if cfg.pair_odd_loops {
        pair_odd_loops(mesh, positions, cfg, &mut report);
    }
    for lp in mesh.boundary_loops() {
        if lp.len() % 2 == 1 || lp.len() > cfg.max_loop_edges || !mesh.is_boundary(lp[0]) {
            continue;
        }
        let q = close_loop(mesh, positions, lp[0], cfg);
        if q > 0 {
            report.loops_closed += 1;
            report.quads_added += q;
        }
    }
    report
}

/// Merges odd loops in pairs through a face between them and closes the merged loop (see
/// the module documentation). Passes over the loops until one changes nothing; a face
/// whose removal did not lead to a closed loop is put back and not tried again.
fn pair_odd_loops(mesh: &mut HalfedgeMesh, pos: &[[f64; 3]], cfg: &CloseConfig, report: &mut CloseReport) {
    let mut failed: std::collections::HashSet<[u32; 4]> = std::collections::HashSet::new();
    let key = |c: [VertexId; 4]| corner_set(c.map(|v| v.0));
    for _pass in 0..16 {
        let loops = mesh.boundary_loops();
        let id = loop_ids(mesh, &loops);
        // Loops whose half-edge ids may be stale after a removal (or put back) this pass.
        let mut touched = vec![false; loops.len()];
        let odd = |m: usize| loops[m].len() % 2 == 1 && loops[m].len() <= cfg.max_loop_edges;
        let mut changed = false;
        for (l, lp) in loops.iter().enumerate() {
            if touched[l] || !odd(l) {
                continue;
            }
            for path in face_paths(mesh, lp, l, &id, &|m| !touched[m] && odd(m), cfg.max_path_faces) {
                if path.iter().any(|&f| !mesh.is_face_alive(f)) {
                    continue;
                }
                let corners: Vec<[VertexId; 4]> = path.iter().map(|&f| mesh.face_vertices(f)).collect();
                if corners.iter().any(|c| failed.contains(&key(*c))) {
                    continue;
                }
                let around: Vec<usize> = path
                    .iter()
                    .flat_map(|&f| mesh.face_halfedges(f))
                    .filter_map(|g| loop_of(mesh, &id, g.opposite()))
                    .collect();
                if around.iter().any(|&m| touched[m]) {
                    continue;
                }
                // Removed from the loop's side outward, so each face borders the hole.
                let mut removed = 0;
                while removed < path.len() && mesh.remove_face(path[removed]).is_ok() {
                    removed += 1;
                }
                let closed = if removed == path.len() {
                    for &m in &around {
                        touched[m] = true;
                    }
                    // The merged loop runs through the removed faces' corners.
                    let start = corners[removed - 1]
                        .iter()
                        .find_map(|&v| mesh.vertex_outgoing(v).find(|&h| mesh.is_boundary(h)));
                    start.map_or(0, |s| close_loop(mesh, pos, s, cfg))
                } else {
                    0
                };
                if closed > 0 {
                    report.faces_removed += removed;
                    report.loops_closed += 1;
                    report.quads_added += closed;
                    changed = true;
                    break;
                }
                for c in corners[..removed].iter().rev() {
                    mesh.add_face(*c).expect("internal error: a face just removed goes back");
                }
                if removed == path.len() {
                    for c in &corners {
                        failed.insert(key(*c));
                    }
                    break;
                }
            }
        }
        if !changed {
            break;
        }
    }
}

/// Paths of faces (at most `max_faces` long, shortest first, each starting at a face
/// across loop `l` and moving across interior edges) whose last face has an edge on a
/// loop `m != l` with `want(m)`. Breadth-first; at most a few dozen paths.
fn face_paths(
    mesh: &HalfedgeMesh,
    lp: &[HalfedgeId],
    l: usize,
    id: &[u32],
    want: &dyn Fn(usize) -> bool,
    max_faces: usize,
) -> Vec<Vec<FaceId>> {
    use std::collections::HashMap;
    let mut parent: HashMap<u32, Option<FaceId>> = HashMap::new();
    let mut frontier: Vec<FaceId> = Vec::new();
    for &h in lp {
        if let Some(f) = mesh.face(h.opposite()) {
            if parent.insert(f.0, None).is_none() {
                frontier.push(f);
            }
        }
    }
    let mut paths = Vec::new();
    for depth in 1..=max_faces {
        for &f in &frontier {
            if touches_wanted_loop(mesh, id, f, l, want) {
                paths.push(path_to(f, |c| parent.get(&c.0).copied().flatten()));
                if paths.len() >= 32 {
                    return paths;
                }
            }
        }
        if depth == max_faces {
            break;
        }
        let mut next = Vec::new();
        for &f in &frontier {
            for g in mesh.face_halfedges(f) {
                if let Some(n) = mesh.face(g.opposite()) {
                    if let std::collections::hash_map::Entry::Vacant(e) = parent.entry(n.0) {
                        e.insert(Some(f));
                        next.push(n);
                    }
                }
            }
        }
        frontier = next;
    }
    paths
}

/// The live face whose corners are `c` in this cyclic order, if there is one.
fn face_with_corners(mesh: &HalfedgeMesh, c: [VertexId; 4]) -> Option<FaceId> {
    let f = mesh.face(mesh.find_halfedge(c[0], c[1])?)?;
    same_cycle(mesh.face_vertices(f).map(|v| v.0), c.map(|v| v.0)).then_some(f)
}

/// Whether face `f` has an edge on a loop `m != l` with `want(m)` ([`loop_ids`] table `id`).
fn touches_wanted_loop(
    mesh: &HalfedgeMesh,
    id: &[u32],
    f: FaceId,
    l: usize,
    want: &dyn Fn(usize) -> bool,
) -> bool {
    mesh.face_halfedges(f).iter().any(|g| loop_of(mesh, id, g.opposite()).is_some_and(|m| m != l && want(m)))
}

/// The path of faces ending at `end`, from the first face with no `parent`.
fn path_to(end: FaceId, parent: impl Fn(FaceId) -> Option<FaceId>) -> Vec<FaceId> {
    let mut path = vec![end];
    let mut c = end;
    while let Some(p) = parent(c) {
        path.push(p);
        c = p;
    }
    path.reverse();
    path
}

/// Scaled Jacobian of live face `f`.
fn face_sj(mesh: &HalfedgeMesh, pos: &[[f64; 3]], f: FaceId) -> f64 {
    scaled_jacobian(&mesh.face_vertices(f).map(|v| pos[v.idx()]))
}

/// The border of the faces `set` (live, distinct) as one simple loop: the from-vertices of
/// its half-edges in order, and the half-edges. `None` when the border is not one simple
/// loop through every corner of the set (a corner inside the region would be lost).
fn region_border(mesh: &HalfedgeMesh, set: &[FaceId]) -> Option<(Vec<u32>, Vec<HalfedgeId>)> {
    let inside = |h: HalfedgeId| mesh.face(h.opposite()).is_some_and(|g| set.contains(&g));
    let border: Vec<HalfedgeId> =
        set.iter().flat_map(|&f| mesh.face_halfedges(f)).filter(|&h| !inside(h)).collect();
    let start = *border.first()?;
    let mut lp = vec![start];
    let mut h = start;
    loop {
        let to = mesh.to_vertex(h);
        let mut next = border.iter().filter(|&&e| mesh.from_vertex(e) == to);
        let n = *next.next()?;
        if next.next().is_some() {
            return None; // the border touches itself at `to`
        }
        if n == start {
            break;
        }
        lp.push(n);
        h = n;
        if lp.len() > border.len() {
            return None;
        }
    }
    if lp.len() != border.len() {
        return None;
    }
    let vs: Vec<u32> = lp.iter().map(|&e| mesh.from_vertex(e).0).collect();
    let corners = set.iter().flat_map(|&f| mesh.face_vertices(f)).all(|v| vs.contains(&v.0));
    corners.then_some((vs, lp))
}

/// Largest region [`untangle`] re-splits around a bad face.
const UNTANGLE_MAX_FACES: usize = 5;

/// A re-split of a region: what it gains and its quads.
struct Resplit {
    /// (classifier support gained, Σ(1 − scaled Jacobian) lost), compared in that order.
    gain: (f64, f64),
    /// The region's faces.
    region: Vec<FaceId>,
    /// The quads that replace them.
    quads: Vec<[u32; 4]>,
}

/// The re-split of the region `set` (see [`untangle`]), when its border is one simple
/// loop through all its corners and [`quadrangulate`] finds a split of it into as many
/// quads that meets the bounds, has better shape and no less support.
fn resplit(
    mesh: &HalfedgeMesh,
    pos: &[[f64; 3]],
    set: &[FaceId],
    cfg: &CloseConfig,
    support: &dyn Fn([u32; 4]) -> f32,
) -> Option<Resplit> {
    let (vs, lp) = region_border(mesh, set)?;
    if vs.len() != 2 * set.len() + 2 {
        return None;
    }
    let across: Vec<Option<[f64; 3]>> = lp.iter().map(|&e| normal_across(mesh, pos, e)).collect();
    let quads = quadrangulate(mesh, pos, &vs, &across, cfg)?;
    let new: f64 = quads.iter().map(|q| 1.0 - scaled_jacobian(&q.map(|v| pos[v as usize]))).sum();
    let old: f64 = set.iter().map(|&g| 1.0 - face_sj(mesh, pos, g)).sum();
    let had: f64 = set.iter().map(|&g| support(corner_set(mesh.face_vertices(g).map(|v| v.0))) as f64).sum();
    let gets: f64 = quads.iter().map(|&q| support(corner_set(q)) as f64).sum();
    // Never trade faces the classifier believes for ones it believes less.
    (old - new > 0.0 && gets >= had - 1e-6).then(|| Resplit {
        gain: (gets - had, old - new),
        region: set.to_vec(),
        quads,
    })
}

/// Re-splits badly shaped faces with their neighbours. For each face `f` whose scaled
/// Jacobian is under `cfg.min_scaled_jacobian` (inverted, folded over a crease, or with a
/// straight corner; mostly 4-edge holes that the hole filling closed with the only quad
/// over their corners), and for each edge-connected region of 2 to 5 faces holding it, the
/// region's border (one simple loop through all its corners) is split by
/// [`quadrangulate`] into as many quads as the region has, over the same vertices and
/// meeting its bounds (and, since chords that are edges are refused, never along the
/// region's inner edges). A split that lowers Σ(1 − scaled Jacobian) replaces the
/// region, provided the classifier's support for the region's faces does not drop:
/// `support(k)` is the probability of the candidate with sorted corners `k` (0 for faces
/// that are no candidate, like the hole filling's), and the new quads' sum must be at
/// least the old faces' (most support gained first, then most shape). The surface's
/// border and vertex set do not change, so neither does its closure, and the bad face is
/// always among those replaced. Returns the number of faces replaced.
pub fn untangle(
    mesh: &mut HalfedgeMesh,
    pos: &[[f64; 3]],
    cfg: &CloseConfig,
    support: &dyn Fn([u32; 4]) -> f32,
) -> usize {
    let bad = bad_faces(mesh, pos, cfg);
    untangle_faces(mesh, pos, cfg, bad, support)
}

/// The faces whose scaled Jacobian is under `cfg.min_scaled_jacobian`.
fn bad_faces(mesh: &HalfedgeMesh, pos: &[[f64; 3]], cfg: &CloseConfig) -> Vec<FaceId> {
    mesh.faces().filter(|&f| face_sj(mesh, pos, f) < cfg.min_scaled_jacobian).collect()
}

/// [`untangle`] over the bad faces `bad` (as [`bad_faces`] lists them).
fn untangle_faces(
    mesh: &mut HalfedgeMesh,
    pos: &[[f64; 3]],
    cfg: &CloseConfig,
    bad: Vec<FaceId>,
    support: &dyn Fn([u32; 4]) -> f32,
) -> usize {
    let mut replaced = 0;
    for f in bad {
        if !mesh.is_face_alive(f) || face_sj(mesh, pos, f) >= cfg.min_scaled_jacobian {
            continue;
        }
        // Every edge-connected set of at most UNTANGLE_MAX_FACES faces holding f, grown
        // one face across an edge at a time.
        let mut best: Option<Resplit> = None;
        let mut seen: std::collections::HashSet<Vec<u32>> = std::collections::HashSet::new();
        let mut frontier: Vec<Vec<FaceId>> = vec![vec![f]];
        for _ in 1..UNTANGLE_MAX_FACES {
            let mut next: Vec<Vec<FaceId>> = Vec::new();
            for set in &frontier {
                for &g in set {
                    for h in mesh.face_halfedges(g) {
                        let Some(n) = mesh.face(h.opposite()) else { continue };
                        if set.contains(&n) {
                            continue;
                        }
                        let mut grown = set.clone();
                        grown.push(n);
                        let mut key: Vec<u32> = grown.iter().map(|x| x.0).collect();
                        key.sort_unstable();
                        if !seen.insert(key) {
                            continue;
                        }
                        if let Some(r) = resplit(mesh, pos, &grown, cfg, support) {
                            if best.as_ref().map_or(true, |b| r.gain > b.gain) {
                                best = Some(r);
                            }
                        }
                        next.push(grown);
                    }
                }
            }
            frontier = next;
        }
        let Some(Resplit { region: set, quads, .. }) = best else { continue };
        let old: Vec<[VertexId; 4]> = set.iter().map(|&g| mesh.face_vertices(g)).collect();
        let mut removed = 0;
        while removed < set.len() && mesh.remove_face(set[removed]).is_ok() {
            removed += 1;
        }
        let mut added: Vec<FaceId> = Vec::with_capacity(quads.len());
        if removed == set.len() {
            for q in &quads {
                match mesh.add_face(q.map(VertexId)) {
                    Ok(n) => added.push(n),
                    Err(_) => break,
                }
            }
        }
        if removed == set.len() && added.len() == quads.len() {
            replaced += set.len();
        } else {
            for &n in added.iter().rev() {
                mesh.remove_face(n).expect("internal error: a face just added comes off again");
            }
            for c in old[..removed].iter().rev() {
                mesh.add_face(*c).expect("internal error: a face just removed goes back");
            }
        }
    }
    replaced
}

/// [`untangle`] with the support read from candidate lists: `lists` holds (quads,
/// probabilities) pairs, and a vertex set's support is the highest probability of its
/// entries. Only candidates whose corners all lie on faces within reach of a badly shaped
/// face (the faces a region around it can hold) are looked at, so a mesh without bad
/// faces costs one pass over its faces.
pub fn untangle_with_candidates(
    mesh: &mut HalfedgeMesh,
    pos: &[[f64; 3]],
    cfg: &CloseConfig,
    lists: &[(&[[u32; 4]], &[f32])],
) -> usize {
    let bad = bad_faces(mesh, pos, cfg);
    if bad.is_empty() {
        return 0;
    }
    // Faces within UNTANGLE_MAX_FACES − 1 steps across edges of a bad face, and their corners.
    let mut near = vec![false; mesh.n_vertices()];
    let mut seen: std::collections::HashSet<FaceId> = bad.iter().copied().collect();
    let mut frontier = bad.clone();
    for step in 0..UNTANGLE_MAX_FACES {
        let mut next = Vec::new();
        for &f in &frontier {
            for v in mesh.face_vertices(f) {
                near[v.idx()] = true;
            }
            if step + 1 == UNTANGLE_MAX_FACES {
                continue;
            }
            for h in mesh.face_halfedges(f) {
                if let Some(g) = mesh.face(h.opposite()) {
                    if seen.insert(g) {
                        next.push(g);
                    }
                }
            }
        }
        frontier = next;
    }
    let table = support_table(&near, lists);
    untangle_faces(mesh, pos, cfg, bad, &|k| table.get(&k).copied().unwrap_or(0.0))
}

/// The loop through boundary half-edge `start`: its half-edges in order, or `None` when it
/// has more than `max` edges.
pub(crate) fn walk_loop(mesh: &HalfedgeMesh, start: HalfedgeId, max: usize) -> Option<Vec<HalfedgeId>> {
    let mut lp = vec![start];
    let mut h = mesh.next(start);
    while h != start {
        if lp.len() >= max {
            return None;
        }
        lp.push(h);
        h = mesh.next(h);
    }
    Some(lp)
}

/// Takes the faces `region` out of `mesh` ([`HalfedgeMesh::remove_faces`]): the corners of
/// the faces taken out, in order; when not all could go, they are put back and `None` is
/// returned.
fn take_out(mesh: &mut HalfedgeMesh, region: &[FaceId]) -> Option<Vec<[VertexId; 4]>> {
    let out = mesh.remove_faces(region);
    if out.len() == region.len() {
        Some(out)
    } else {
        put_back(mesh, &out);
        None
    }
}

/// Puts faces taken out by [`take_out`] back, last first.
fn put_back(mesh: &mut HalfedgeMesh, out: &[[VertexId; 4]]) {
    for c in out.iter().rev() {
        mesh.add_face(*c).expect("internal error: a face just taken out goes back");
    }
}

/// Adds all of `quads` or none of them; whether they went in. A quad `add_face` refuses
/// at first (a corner whose fan it would split) is tried again after the others.
pub(crate) fn add_all(mesh: &mut HalfedgeMesh, quads: &[[u32; 4]]) -> bool {
    let mut added: Vec<FaceId> = Vec::with_capacity(quads.len());
    let mut left: Vec<[u32; 4]> = quads.to_vec();
    while !left.is_empty() {
        let before = left.len();
        left.retain(|q| match mesh.add_face(q.map(VertexId)) {
            Ok(f) => {
                added.push(f);
                false
            }
            Err(_) => true,
        });
        if left.len() == before {
            // Taken out again in reverse order of insertion, which always succeeds.
            for &f in added.iter().rev() {
                mesh.remove_face(f).expect("internal error: a face just added comes off again");
            }
            return false;
        }
    }
    true
}

/// Closes the loops that the closing left open where the faces around them are the
/// trouble (not in the paper; docs/EXPERIMENTS.md, "Session 12"):
/// - an **odd** loop is joined to another odd loop by taking out a path of at most
///   `cfg.seal_max_path_faces` faces between them, the least supported path first
///   (Dijkstra over faces, each costing 0.05 + its support);
/// - an **even** loop that no quadrangulation of its own vertices closes (or whose border
///   turns the wrong way: a face folded over the hole) loses the faces with a corner on
///   it, then (second ring) the faces with a corner on those.
///
/// Either way the faces taken out (at most `cfg.seal_max_faces`) must leave a single loop
/// through their corners, of even length, at most `cfg.seal_max_loop_edges` edges, that
/// is a hole ([`CloseConfig::min_loop_coherence`]); it is quadrangulated over its own
/// vertices at least cost Σ(1 − scaled Jacobian + `cfg.seal_support_weight` · (1 −
/// support)), within the closing's shape and fold bounds, and the quads go in only if
/// their summed support is at least `cfg.seal_keep_support` times that of the faces taken
/// out. Otherwise the faces go back. `support(k)` is the classifier's probability of the
/// quad with sorted corners `k` (0 when none, e.g. for hole-filling quads). Loops are
/// visited shortest first, in up to four passes. Adds no vertex; points that lose all
/// their faces stay isolated; the mesh stays manifold and oriented (every face goes
/// through `add_face`). Returns nothing; counts go to `report`.
pub fn seal(
    mesh: &mut HalfedgeMesh,
    pos: &[[f64; 3]],
    cfg: &CloseConfig,
    support: &dyn Fn([u32; 4]) -> f32,
    report: &mut CloseReport,
) {
    if !cfg.enabled || !cfg.seal {
        return;
    }
    let sup = |q: [u32; 4]| f64::from(support(corner_set(q))).clamp(0.0, 1.0);
    let mut s = Sealer { mesh, pos, cfg, sup: &sup, report };
    for _pass in 0..4 {
        let mut loops: Vec<Vec<HalfedgeId>> =
            s.mesh.boundary_loops().into_iter().filter(|l| l.len() <= cfg.seal_max_loop_edges).collect();
        loops.sort_by_key(Vec::len);
        let mut changed = false;
        for lp in loops {
            // An earlier seal this pass may have changed this loop.
            let unchanged = s.mesh.is_boundary(lp[0])
                && walk_loop(s.mesh, lp[0], cfg.seal_max_loop_edges).is_some_and(|cur| cur == lp);
            if unchanged {
                changed |= if lp.len() % 2 == 1 { s.odd(&lp) } else { s.even(&lp) };
            }
        }
        if !changed {
            break;
        }
    }
}

/// The state [`seal`] works with.
struct Sealer<'a> {
    mesh: &'a mut HalfedgeMesh,
    pos: &'a [[f64; 3]],
    cfg: &'a CloseConfig,
    /// Support of a quad (any corner order), in [0, 1].
    sup: &'a dyn Fn([u32; 4]) -> f64,
    report: &'a mut CloseReport,
}

impl Sealer<'_> {
    /// [`seal`] for an odd loop (its half-edges); whether it was closed.
    fn odd(&mut self, lp: &[HalfedgeId]) -> bool {
        let (mesh, cfg, sup) = (&*self.mesh, self.cfg, self.sup);
        // Which boundary half-edges lie on another odd loop of at most
        // `seal_max_loop_edges` edges: walked where the search meets them, each loop
        // once, not listed for the whole mesh per loop sealed.
        let mut other_odd: std::collections::HashMap<HalfedgeId, bool> = std::collections::HashMap::new();
        let mut hits = |f: FaceId| {
            mesh.face_halfedges(f).iter().any(|g| {
                let h = g.opposite();
                if !mesh.is_boundary(h) {
                    return false;
                }
                if let Some(&known) = other_odd.get(&h) {
                    return known;
                }
                let walked = walk_loop(mesh, h, cfg.seal_max_loop_edges);
                let yes = walked.as_ref().is_some_and(|l| l.len() % 2 == 1 && !l.contains(&lp[0]));
                for e in walked.unwrap_or_else(|| vec![h]) {
                    other_odd.insert(e, yes);
                }
                yes
            })
        };
        let cost = |f: FaceId| 0.05 + sup(mesh.face_vertices(f).map(|v| v.0));
        // By corners: a failed attempt puts its faces back under new ids (and a freed id
        // may go to another face), so face ids do not outlive an attempt.
        let paths: Vec<Vec<[VertexId; 4]>> =
            cheap_face_paths(mesh, lp, &mut hits, cfg.seal_max_path_faces, &cost)
                .into_iter()
                .map(|p| p.iter().map(|&f| mesh.face_vertices(f)).collect())
                .collect();
        paths.into_iter().any(|corners| {
            let path: Option<Vec<FaceId>> =
                corners.iter().map(|&c| face_with_corners(self.mesh, c)).collect();
            path.is_some_and(|p| p.len() <= cfg.seal_max_faces && self.reclose(&p))
        })
    }

    /// [`seal`] for an even loop (its half-edges); whether it was closed.
    fn even(&mut self, lp: &[HalfedgeId]) -> bool {
        // The vertices whose faces go: the loop's, then the corners of those faces.
        // (Faces are listed afresh each ring: faces put back get new ids.)
        let mut verts: Vec<VertexId> = lp.iter().map(|&h| self.mesh.from_vertex(h)).collect();
        let mut last = 0;
        for _ring in 0..self.cfg.seal_rings {
            let mut region: Vec<FaceId> = Vec::new();
            for &v in &verts {
                for f in self.mesh.vertex_faces(v) {
                    if !region.contains(&f) {
                        region.push(f);
                    }
                }
            }
            if region.len() == last || region.len() > self.cfg.seal_max_faces {
                return false;
            }
            last = region.len();
            verts = region.iter().flat_map(|&f| self.mesh.face_vertices(f)).collect();
            verts.sort_unstable_by_key(|v| v.0);
            verts.dedup();
            if self.reclose(&region) {
                return true;
            }
        }
        false
    }

    /// Takes `region` out and closes the one loop that leaves through its corners, as
    /// [`seal`] says; on failure the mesh is as before. Whether it closed.
    fn reclose(&mut self, region: &[FaceId]) -> bool {
        let (pos, cfg, sup) = (self.pos, self.cfg, self.sup);
        let mut corners: Vec<VertexId> = region.iter().flat_map(|&f| self.mesh.face_vertices(f)).collect();
        corners.sort_unstable_by_key(|v| v.0);
        corners.dedup();
        let Some(out) = take_out(self.mesh, region) else { return false };
        let had: f64 = out.iter().map(|c| sup(c.map(|v| v.0))).sum();
        let mesh = &mut *self.mesh;
        let added = the_one_loop(mesh, &corners, cfg.seal_max_loop_edges).and_then(|l| {
            let vs: Vec<u32> = l.iter().map(|&h| mesh.from_vertex(h).0).collect();
            let across: Vec<Option<[f64; 3]>> = l.iter().map(|&h| normal_across(mesh, pos, h)).collect();
            if vs.len() % 2 == 1 || !is_hole(pos, &vs, &across, cfg) {
                return None;
            }
            let extra = |q: [u32; 4]| cfg.seal_support_weight * (1.0 - sup(q));
            let quads = quadrangulate_with(mesh, pos, &vs, &across, cfg, &extra)?;
            let gets: f64 = quads.iter().map(|&q| sup(q)).sum();
            (gets >= cfg.seal_keep_support * had - 1e-9 && add_all(mesh, &quads)).then_some(quads.len())
        });
        match added {
            Some(n) => {
                self.report.sealed += 1;
                self.report.seal_removed += out.len();
                self.report.seal_added += n;
                true
            }
            None => {
                put_back(self.mesh, &out);
                false
            }
        }
    }
}

/// The boundary loop through `corners` when there is exactly one and it has at most
/// `max` edges.
fn the_one_loop(mesh: &HalfedgeMesh, corners: &[VertexId], max: usize) -> Option<Vec<HalfedgeId>> {
    let mut found: Option<Vec<HalfedgeId>> = None;
    for &v in corners {
        for h in mesh.vertex_outgoing(v).filter(|&h| mesh.is_boundary(h)) {
            if found.as_ref().is_some_and(|l| l.contains(&h)) {
                continue;
            }
            if found.is_some() {
                return None; // a second loop
            }
            found = Some(walk_loop(mesh, h, max)?);
        }
    }
    found
}

/// The support table [`seal`] reads: for each candidate of `lists` ((quads,
/// probabilities) pairs) whose corners all lie within `rings` rings of faces around a
/// boundary loop, its sorted corners and highest probability. Empty when the mesh is
/// closed, so a closed mesh costs one pass over its half-edges.
pub fn support_near_loops(
    mesh: &HalfedgeMesh,
    rings: usize,
    lists: &[(&[[u32; 4]], &[f32])],
) -> std::collections::HashMap<[u32; 4], f32> {
    let mut near = vec![false; mesh.n_vertices()];
    let mut frontier: Vec<VertexId> =
        mesh.boundary_loops().iter().flatten().map(|&h| mesh.from_vertex(h)).collect();
    if frontier.is_empty() {
        return std::collections::HashMap::new();
    }
    for &v in &frontier {
        near[v.idx()] = true;
    }
    for _ in 0..rings {
        let mut next = Vec::new();
        for &v in &frontier {
            for f in mesh.vertex_faces(v) {
                for w in mesh.face_vertices(f) {
                    if !near[w.idx()] {
                        near[w.idx()] = true;
                        next.push(w);
                    }
                }
            }
        }
        frontier = next;
    }
    support_table(&near, lists)
}

/// For each quad of `lists` ((quads, probabilities) pairs) whose corners are all marked in
/// `near`, its corner set and highest probability.
fn support_table(near: &[bool], lists: &[(&[[u32; 4]], &[f32])]) -> std::collections::HashMap<[u32; 4], f32> {
    let mut table = std::collections::HashMap::new();
    for (quads, probs) in lists {
        for (q, &p) in quads.iter().zip(probs.iter()) {
            if q.iter().all(|&v| near.get(v as usize).copied().unwrap_or(false)) {
                let e = table.entry(corner_set(*q)).or_insert(p);
                *e = e.max(p);
            }
        }
    }
    table
}

/// A face on a Dijkstra heap over faces: (path cost, face index, path length). The
/// heap pops the least cost first, ties by the lower face index (deterministic).
#[derive(PartialEq)]
pub(crate) struct Item(pub(crate) f64, pub(crate) u32, pub(crate) usize);
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Item {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Paths of faces (at most `max_faces` long), each from a face across the loop `lp` to a
/// face where `hits` holds, moving across interior edges, in order of least total `cost`
/// (Dijkstra; one path per end face, at most 32).
fn cheap_face_paths(
    mesh: &HalfedgeMesh,
    lp: &[HalfedgeId],
    hits: &mut dyn FnMut(FaceId) -> bool,
    max_faces: usize,
    cost: &dyn Fn(FaceId) -> f64,
) -> Vec<Vec<FaceId>> {
    use std::collections::{BinaryHeap, HashMap};
    // face -> (best cost, parent, length)
    let mut best: HashMap<u32, (f64, Option<FaceId>, usize)> = HashMap::new();
    let mut heap = BinaryHeap::new();
    for &h in lp {
        if let Some(f) = mesh.face(h.opposite()) {
            let c = cost(f);
            if best.get(&f.0).map_or(true, |b| c < b.0) {
                best.insert(f.0, (c, None, 1));
                heap.push(Item(c, f.0, 1));
            }
        }
    }
    let mut done: std::collections::HashSet<u32> = std::collections::HashSet::new();
    let mut paths = Vec::new();
    while let Some(Item(c, f, len)) = heap.pop() {
        if !done.insert(f) {
            continue;
        }
        let face = FaceId(f);
        if hits(face) {
            paths.push(path_to(face, |c| best.get(&c.0).and_then(|b| b.1)));
            if paths.len() >= 32 {
                break;
            }
            continue;
        }
        if len >= max_faces {
            continue;
        }
        for g in mesh.face_halfedges(face) {
            if let Some(n) = mesh.face(g.opposite()) {
                let nc = c + cost(n);
                if !done.contains(&n.0) && best.get(&n.0).map_or(true, |b| nc < b.0) {
                    best.insert(n.0, (nc, Some(face), len + 1));
                    heap.push(Item(nc, n.0, len + 1));
                }
            }
        }
    }
    paths
}
