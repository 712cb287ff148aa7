//! Closing every hole of a quad mesh (not in the paper; session 32; `reconstruct
//! --watertight`, `repair --watertight`).
//!
//! The post-process closes a hole only where the classifier's faces allow it: an odd
//! loop (a triangle, most often) can be closed by quads only together with another odd
//! loop, and the faces between two odd loops are usually believed, so the seal leaves
//! them (docs/EXPERIMENTS.md, "Session 27"). Users who need a closed mesh (simulation,
//! 3-D printing) can ask for one at the price of faces that are not the classifier's:
//!
//! 1. **Odd loops are paired by splitting a strip of faces.** From an odd loop A, the
//!    cheapest path of faces to another odd loop B (Dijkstra over faces, each costing
//!    `0.05 + support`, so the least believed faces first) is cut along its middle: every
//!    edge the path crosses, and A's and B's edges where it leaves and meets them, gets a
//!    new vertex, and each face of the path is split into two quads (entry and exit edges
//!    opposite) or three (adjacent: a new vertex in the middle of the face). The mesh
//!    stays a manifold of quads; A and B each gain one edge and become even. Paths within
//!    one round share no face; rounds repeat until no odd loop is left or none can be
//!    paired (an odd loop whose component holds no other: impossible in a quad mesh, whose
//!    border always has an even number of edges, so every component's odd loops pair up).
//! 2. **Candidates are rescued** into the holes, when asked for
//!    ([`WatertightConfig::rescue_min_prob`], off by default): those glued to the border
//!    on two or more edges, most probable first, where they leave no more odd loops than
//!    they found (quads over the input's points, which may be true faces).
//! 3. **Even loops are filled**: by a quadrangulation over each loop's own vertices
//!    ([`quadrangulate`], its shape bound only: fewest new faces, no new vertex), then
//!    the greedy hole filling with new vertices ([`fill_holes`], partial fills kept),
//!    then the quadrangulation again on what is left; a loop still open is cut by
//!    chords into pieces of at most 16 edges ([`WatertightConfig::split_long_loops`],
//!    session 33) and each piece gets a fan around one new vertex at its centroid:
//!    quads `(v₀, v₁, v₂, c), (v₂, v₃, v₄, c), …` (or `(v₁, v₂, v₃, c), …` when the
//!    first has a degenerate quad), which closes any even loop but one that only
//!    degenerate quads could close (its points on a line, or on one another).
//! 4. The added vertices are smoothed (guarded Laplacian steps), then each is moved by
//!    a pattern search that raises the worst scaled Jacobian of its quads
//!    ([`WatertightConfig::maximin_sweeps`], session 33).
//!
//! Only loops of at most `max_loop_edges` edges are touched (0: every loop). The input's
//! vertices keep their positions and indices; new vertices are appended.

use std::collections::{BinaryHeap, HashMap, HashSet};

use super::close::{add_all, quadrangulate, CloseConfig, Item};
use super::halfedge::{corner_set, HalfedgeMesh};
use super::handles::{FaceId, HalfedgeId, VertexId};
use super::hole_fill::{fill_holes, scaled_jacobian, HoleFillConfig};
use super::poly::QuadMesh;
use super::quality::{is_degenerate_quad, DEGENERATE_QUAD_TOL};
use super::rescue::{rescue_faces, RescueConfig};
use crate::error::{Error, Result};
use crate::math::{add, cross, norm, normalize, scale, sub};

/// Settings of [`close_all`].
#[derive(Clone, Debug, PartialEq)]
pub struct WatertightConfig {
    /// Loops with more edges stay open (the border of an open surface); 0 closes every
    /// loop.
    pub max_loop_edges: usize,
    /// Rounds of odd-loop pairing (each pairs as many loops as face-disjoint paths allow).
    pub max_rounds: usize,
    /// Loops up to this many edges are tried by the quadrangulation over their own
    /// vertices (its cost grows as the fourth power of the length); longer ones go to
    /// the greedy filling and the fan only.
    pub max_quadrangulate_edges: usize,
    /// Before the filling, candidates scored at least this are put in at holes where
    /// they glue to the border on two or more edges and leave no more odd loops than
    /// they found ([`rescue_faces`] with `keep_parity`): quads over the input's points,
    /// which may be true faces, where the filling would invent vertices. `None` (the
    /// default) skips it: on the held-out `train/` meshes it scored no better than
    /// without it (docs/EXPERIMENTS.md, "Session 32", rule 1).
    pub rescue_min_prob: Option<f32>,
    /// Steps of Laplacian smoothing of the added vertices at the end; a move is kept only
    /// when the worst scaled Jacobian of the vertex's quads does not drop.
    pub smoothing_steps: usize,
    /// Sweeps of a pattern search after the smoothing: each added vertex steps along
    /// two tangent directions and the normal of its quads (from a quarter of its mean
    /// edge length, halved when no step helps, [`MAXIMIN_HALVINGS`] times), a step kept
    /// only when the worst scaled Jacobian of its quads rises. 0 turns it off. On the
    /// held-out `train/` meshes (docs/EXPERIMENTS.md, "Session 33", rules 6 and 7) it cut
    /// the quads with SJ ≤ 0 from 219 to 93 at the same faces; the normal steps cost some
    /// Chamfer distance (mean 0.0107 → 0.0114), the tangent-only search kept more
    /// inverted quads (141).
    pub maximin_sweeps: usize,
    /// A loop that neither the quadrangulation nor the greedy filling closed is cut by
    /// chords into pieces (the shortest chord for the loop steps it spans, keeping both
    /// pieces even) until each is quadrangulated or short enough for a fan of its own,
    /// instead of one fan over the whole loop. On by default: on the held-out `train/`
    /// meshes it halved the quads with a scaled Jacobian ≤ 0 that the closing leaves
    /// (443 → 219 over six tables) at the same F1 (docs/EXPERIMENTS.md, "Session 32",
    /// rule 4, judged in session 33).
    pub split_long_loops: bool,
}

impl Default for WatertightConfig {
    fn default() -> Self {
        WatertightConfig {
            max_loop_edges: 0,
            max_rounds: 8,
            max_quadrangulate_edges: 64,
            rescue_min_prob: None,
            smoothing_steps: 10,
            maximin_sweeps: 3,
            split_long_loops: true,
        }
    }
}

/// What [`close_all`] did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct WatertightReport {
    /// Pairs of odd loops made even by a split strip.
    pub odd_pairs: usize,
    /// Faces split on those strips (each into two or three quads).
    pub faces_split: usize,
    /// Candidates put in at holes before the filling.
    pub rescued: usize,
    /// Loops closed by the greedy hole filling, the quadrangulation or the fan.
    pub loops_filled: usize,
    /// Edges of the longest loop the filling met (after the strips): where that is the
    /// border of an open surface, `max_loop_edges` keeps it open.
    pub longest_loop: usize,
    /// Quads the filling added (the rescued candidates not counted).
    pub quads_added: usize,
    /// Vertices added (strip splits, hole filling and fans) that some face of the result
    /// uses; the others are not in the result.
    pub vertices_added: usize,
    /// Boundary loops still open at the end: those longer than the bound, and any the
    /// filling could not close (only degenerate quads would: both fans unsound).
    pub loops_left: usize,
}

/// Closes every hole of `mesh` (module docs). `candidates` (corner lists over `mesh`'s
/// vertices) with their `probs` say how much each quad is believed (the classifier's
/// probabilities; a face that is no candidate counts 0): the strips run through the
/// least believed faces, and the rescue takes its quads from them. The result's first
/// `mesh.vertices.len()` vertices are `mesh`'s, unchanged.
///
/// # Errors
/// `InvalidInput` when `mesh` is not a manifold, oriented quad mesh (as
/// [`HalfedgeMesh::from_quads`] checks it) or has a non-finite coordinate, or when the
/// candidates and probabilities differ in number, a candidate's corner is out of range
/// or a probability is not finite.
pub fn close_all(
    mesh: &QuadMesh,
    cfg: &WatertightConfig,
    candidates: &[[u32; 4]],
    probs: &[f32],
) -> Result<(QuadMesh, WatertightReport)> {
    if let Some(i) = mesh.vertices.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::invalid(format!("watertight: vertex {i} has a non-finite coordinate")));
    }
    if candidates.len() != probs.len() {
        return Err(Error::invalid(format!(
            "watertight: {} candidates but {} probabilities",
            candidates.len(),
            probs.len()
        )));
    }
    let n = mesh.vertices.len();
    if let Some(i) = candidates.iter().position(|q| q.iter().any(|&v| v as usize >= n)) {
        return Err(Error::invalid(format!(
            "watertight: candidate {i} has a corner beyond the {n} vertices"
        )));
    }
    if let Some(i) = probs.iter().position(|p| !p.is_finite()) {
        return Err(Error::invalid(format!("watertight: candidate {i} has a non-finite probability")));
    }
    let mut belief: HashMap<[u32; 4], f32> = HashMap::with_capacity(candidates.len());
    for (&q, &p) in candidates.iter().zip(probs) {
        let e = belief.entry(corner_set(q)).or_insert(p);
        *e = e.max(p);
    }
    let support = |k: [u32; 4]| belief.get(&k).map_or(0.0, |&p| p as f64);
    let mut pos = mesh.vertices.clone();
    let mut quads = mesh.quads.clone();
    let mut report = WatertightReport::default();
    let limit = if cfg.max_loop_edges == 0 { usize::MAX } else { cfg.max_loop_edges };
    for _ in 0..cfg.max_rounds {
        let hm = HalfedgeMesh::from_quads(pos.len(), &quads)?;
        let strips = pair_odd_loops(&hm, limit, &support);
        if strips.is_empty() {
            break;
        }
        report.odd_pairs += strips.len();
        report.faces_split += strips.iter().map(|s| s.faces.len()).sum::<usize>();
        quads = split_strips(&hm, &mut pos, &strips);
    }
    let mut hm = HalfedgeMesh::from_quads(pos.len(), &quads)?;
    let faces_before = hm.n_faces();
    let open_before = open_loops(&hm, limit);
    let loops_before = open_before.len();
    report.longest_loop = open_before.iter().map(Vec::len).max().unwrap_or(0);
    if let Some(min_prob) = cfg.rescue_min_prob {
        let distinct = |q: &[u32; 4]| q.iter().collect::<HashSet<_>>().len() == 4;
        let pool: Vec<usize> =
            (0..candidates.len()).filter(|&i| probs[i] >= min_prob && distinct(&candidates[i])).collect();
        let rc = RescueConfig { min_prob, keep_parity: true, ..RescueConfig::default() };
        report.rescued = rescue_faces(&mut hm, &pos, candidates, probs, &pool, &rc).len();
    }
    // Over the loops' own vertices first (fewest new faces, no new vertex), then the
    // greedy filling with new vertices (partial fills kept: their quads are well shaped),
    // then over own vertices again (what the filling left), then the fans.
    let shape_only = CloseConfig { min_normal_dot: -1.0, ..CloseConfig::default() };
    let own_vertices = |hm: &mut HalfedgeMesh, pos: &[[f64; 3]]| {
        for lp in open_loops(hm, limit) {
            let vs: Vec<u32> = lp.iter().map(|&h| hm.from_vertex(h).0).collect();
            if vs.len() % 2 == 1 || has_repeat(&vs) || vs.len() > cfg.max_quadrangulate_edges {
                continue;
            }
            let across = vec![None; vs.len()];
            if let Some(q) = quadrangulate(hm, pos, &vs, &across, &shape_only) {
                add_all(hm, &q);
            }
        }
    };
    own_vertices(&mut hm, &pos);
    let fill =
        HoleFillConfig { max_hole_edges: limit, undo_partial_fills: false, ..HoleFillConfig::default() };
    fill_holes(&mut hm, &mut pos, &fill)?;
    own_vertices(&mut hm, &pos);
    for lp in open_loops(&hm, limit) {
        let vs: Vec<u32> = lp.iter().map(|&h| hm.from_vertex(h).0).collect();
        if vs.len() % 2 == 1 || has_repeat(&vs) {
            continue;
        }
        if cfg.split_long_loops {
            if let Some(pieces) = split_and_fill(&hm, &pos, &vs, cfg.max_quadrangulate_edges, &shape_only) {
                let quads = commit_pieces(&mut hm, &mut pos, pieces);
                if add_all(&mut hm, &quads) {
                    continue;
                }
            }
        }
        fan(&mut hm, &mut pos, &vs);
    }
    smooth_added(&hm, &mut pos, mesh.vertices.len(), cfg.smoothing_steps);
    maximin_added(&hm, &mut pos, mesh.vertices.len(), cfg.maximin_sweeps);
    separate_added(&hm, &mut pos, mesh.vertices.len());
    report.loops_filled = loops_before.saturating_sub(open_loops(&hm, limit).len());
    report.loops_left = hm.boundary_loops().len();
    report.quads_added = hm.n_faces() - faces_before - report.rescued;
    // A fan that did not go in leaves its centre with no face: only the added vertices
    // some face uses stay, and only those are counted (session 41).
    let closed = hm.to_quad_mesh(&pos)?.without_unused_from(mesh.vertices.len()).0;
    report.vertices_added = closed.vertices.len() - mesh.vertices.len();
    Ok((closed, report))
}

/// Loops up to this many edges that the quadrangulation cannot close get a fan
/// ([`split_and_fill`]).
const FAN_EDGES: usize = 16;

/// How [`split_and_fill`] closes one piece of a loop: quads over its own vertices, or a
/// fan round a new vertex at the centroid of these loop vertices.
enum Piece {
    Quads(Vec<[u32; 4]>),
    Fan(Vec<u32>),
}

/// How to close the even loop `vs` (from-vertices of its boundary half-edges, in
/// order): its quadrangulation over its own vertices where one meets the shape bound
/// (up to `max_dp` edges); else, above [`FAN_EDGES`] edges, the loop is cut by the chord
/// (i, j) with j − i odd (both pieces even, at least 4 edges, neither [`flat`]) and no
/// edge of the mesh already, of least length per loop step on the shorter side, and
/// each piece is closed the same way; else a fan round a new vertex at its centroid.
/// The pieces share the chords, so together they close the loop. `None` when a piece
/// can only be closed by a degenerate quad ([`sound_fan`]; session 37: a flat
/// sheet's straight border cut into collinear pieces gave quads of no area); nothing
/// is added to the mesh either way ([`commit_pieces`] does that).
fn split_and_fill(
    hm: &HalfedgeMesh,
    pos: &[[f64; 3]],
    vs: &[u32],
    max_dp: usize,
    shape: &CloseConfig,
) -> Option<Vec<Piece>> {
    let n = vs.len();
    if n == 4 {
        let q = [vs[0], vs[1], vs[2], vs[3]];
        return (!is_degenerate_quad(&q.map(|v| pos[v as usize]))).then(|| vec![Piece::Quads(vec![q])]);
    }
    if n <= max_dp {
        let across = vec![None; n];
        if let Some(q) = quadrangulate(hm, pos, vs, &across, shape) {
            return Some(vec![Piece::Quads(q)]);
        }
    }
    if n > FAN_EDGES {
        let mut best: Option<(f64, usize, usize)> = None;
        for i in 0..n {
            for d in (3..=n - 3).step_by(2) {
                let j = i + d;
                if j >= n {
                    break;
                }
                if hm.find_halfedge(VertexId(vs[i]), VertexId(vs[j])).is_some() {
                    continue;
                }
                let (a, b) = (pos[vs[i] as usize], pos[vs[j] as usize]);
                let len = norm(sub(a, b));
                let score = len / d.min(n - d) as f64;
                if best.map_or(true, |(s, _, _)| score < s)
                    && !flat(pos, &vs[i..=j])
                    && !flat(pos, &vs[j..].iter().chain(&vs[..=i]).copied().collect::<Vec<u32>>())
                {
                    best = Some((score, i, j));
                }
            }
        }
        if let Some((_, i, j)) = best {
            let first: Vec<u32> = vs[i..=j].to_vec();
            let second: Vec<u32> = vs[j..].iter().chain(&vs[..=i]).copied().collect();
            let mut pieces = split_and_fill(hm, pos, &first, max_dp, shape)?;
            pieces.extend(split_and_fill(hm, pos, &second, max_dp, shape)?);
            return Some(pieces);
        }
    }
    sound_fan(pos, vs).map(|vs| vec![Piece::Fan(vs)])
}

/// The loop `vs` from its first vertex, or from its second when the fan from the first
/// has a degenerate quad ([`fan_is_sound`]): the quads' middle corners are then the other
/// half of the loop's vertices (session 41's audit: a loop with three vertices on a line
/// was left open). `None` when both fans have a degenerate quad.
fn sound_fan(pos: &[[f64; 3]], vs: &[u32]) -> Option<Vec<u32>> {
    if fan_is_sound(pos, vs) {
        return Some(vs.to_vec());
    }
    let rotated: Vec<u32> = vs.iter().skip(1).chain(vs.first()).copied().collect();
    fan_is_sound(pos, &rotated).then_some(rotated)
}

/// Adds the fans' centres of `pieces` to `hm` and `pos` and returns every piece's quads.
fn commit_pieces(hm: &mut HalfedgeMesh, pos: &mut Vec<[f64; 3]>, pieces: Vec<Piece>) -> Vec<[u32; 4]> {
    let mut quads = Vec::new();
    for p in pieces {
        match p {
            Piece::Quads(q) => quads.extend(q),
            Piece::Fan(vs) => quads.extend(fan_quads(hm, pos, &vs)),
        }
    }
    quads
}

/// True when the polygon `vs` has no area to speak of: the norm of its vector area
/// (half the sum of the cross products of consecutive corners about the first) at most
/// [`DEGENERATE_QUAD_TOL`] times its diameter squared (the largest distance from its
/// first corner, doubled). Four or more corners on one line are flat; a fan over them
/// has quads of no area.
fn flat(pos: &[[f64; 3]], vs: &[u32]) -> bool {
    let o = pos[vs[0] as usize];
    let mut area = [0.0f64; 3];
    let mut reach = 0.0f64;
    for w in vs.windows(2) {
        let (a, b) = (sub(pos[w[0] as usize], o), sub(pos[w[1] as usize], o));
        area = add(area, cross(a, b));
        reach = reach.max(norm(b));
    }
    let d = 2.0 * reach;
    // NaN counts as flat.
    let a = norm(area);
    a.is_nan() || a <= 2.0 * DEGENERATE_QUAD_TOL * d * d
}

/// The centroid of the loop vertices `vs`.
fn centroid(pos: &[[f64; 3]], vs: &[u32]) -> [f64; 3] {
    scale(vs.iter().fold([0.0; 3], |s, &v| add(s, pos[v as usize])), 1.0 / vs.len() as f64)
}

/// Whether the fan [`fan_quads`] would build over the even loop `vs` has no
/// degenerate quad ([`is_degenerate_quad`]).
fn fan_is_sound(pos: &[[f64; 3]], vs: &[u32]) -> bool {
    let n = vs.len();
    let c = centroid(pos, vs);
    n >= 4
        && n % 2 == 0
        && (0..n / 2).all(|i| {
            let p =
                [pos[vs[2 * i] as usize], pos[vs[2 * i + 1] as usize], pos[vs[(2 * i + 2) % n] as usize], c];
            !is_degenerate_quad(&p)
        })
}

/// The worst scaled Jacobian of `faces` (−∞ for a degenerate one).
fn worst(pos: &[[f64; 3]], faces: &[[usize; 4]]) -> f64 {
    faces
        .iter()
        .map(|q| {
            let p = q.map(|v| pos[v]);
            if is_degenerate_quad(&p) {
                f64::NEG_INFINITY
            } else {
                scaled_jacobian(&p)
            }
        })
        .fold(f64::INFINITY, f64::min)
}

/// Halvings of the pattern search's step ([`WatertightConfig::maximin_sweeps`]).
pub const MAXIMIN_HALVINGS: usize = 6;

/// The pattern search of [`WatertightConfig::maximin_sweeps`] over the vertices from
/// `first` on.
fn maximin_added(hm: &HalfedgeMesh, pos: &mut [[f64; 3]], first: usize, sweeps: usize) {
    for _ in 0..sweeps {
        for v in first..pos.len() {
            let vid = VertexId(v as u32);
            let faces: Vec<[usize; 4]> =
                hm.vertex_faces(vid).map(|f| hm.face_vertices(f).map(|x| x.idx())).collect();
            let nbrs: Vec<usize> = hm.vertex_outgoing(vid).map(|h| hm.to_vertex(h).idx()).collect();
            if nbrs.is_empty() {
                continue;
            }
            let Some(dirs) = step_directions(pos, &faces) else { continue };
            let mut h = 0.25 * mean_reach(pos, v, &nbrs);
            let mut best = worst(pos, &faces);
            for _ in 0..MAXIMIN_HALVINGS {
                // At most a few steps at one size, then a smaller one.
                for _ in 0..4 {
                    let old = pos[v];
                    let mut pick: Option<([f64; 3], f64)> = None;
                    for d in dirs {
                        pos[v] = add(old, scale(d, h));
                        let w = worst(pos, &faces);
                        if w > pick.map_or(best, |(_, b)| b) {
                            pick = Some((pos[v], w));
                        }
                    }
                    match pick {
                        Some((p, w)) => {
                            pos[v] = p;
                            best = w;
                        }
                        None => {
                            pos[v] = old;
                            break;
                        }
                    }
                }
                h *= 0.5;
            }
        }
    }
}

/// The unit directions the pattern search steps along from a vertex whose quads are
/// `faces`: two tangents of the quads' mean normal (summed diagonal cross products)
/// and the normal, each both ways. `None` when the normal is undefined.
fn step_directions(pos: &[[f64; 3]], faces: &[[usize; 4]]) -> Option<[[f64; 3]; 6]> {
    if faces.is_empty() {
        return None;
    }
    let n = faces
        .iter()
        .fold([0.0; 3], |acc, q| add(acc, cross(sub(pos[q[2]], pos[q[0]]), sub(pos[q[3]], pos[q[1]]))));
    let n = normalize(n)?;
    let helper = if n[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let t1 = normalize(cross(n, helper))?;
    let t2 = cross(n, t1);
    Some([t1, scale(t1, -1.0), t2, scale(t2, -1.0), n, scale(n, -1.0)])
}

/// The mean distance from vertex `v` to its neighbours `nbrs`.
fn mean_reach(pos: &[[f64; 3]], v: usize, nbrs: &[usize]) -> f64 {
    nbrs.iter().map(|&u| norm(sub(pos[u], pos[v]))).sum::<f64>() / nbrs.len() as f64
}

/// How much [`separate_added`] may lower the worst scaled Jacobian of a vertex's quads.
const SEPARATE_SLACK: f64 = 0.01;

/// Two vertices closer than this share of an added vertex's mean edge length count as
/// one position for [`separate_added`].
const SAME_POSITION: f64 = 1e-6;

/// Moves each vertex from `first` on that lies on another vertex (within
/// [`SAME_POSITION`] of its mean edge length; session 37's audit: a fan's centre on a
/// flat sheet's closing landed on a point of the sheet, which a metric that matches
/// vertices by position cannot tell apart) off it: along the best of the
/// [`step_directions`] that lands on no vertex and lowers the worst scaled Jacobian of
/// its quads by at most [`SEPARATE_SLACK`] (a degenerate quad is never allowed), at
/// 10⁻³ of its mean edge length, halved up to 20 times. A vertex no step frees stays
/// where it is.
fn separate_added(hm: &HalfedgeMesh, pos: &mut [[f64; 3]], first: usize) {
    if first >= pos.len() {
        return;
    }
    // Every vertex by x, to find those near a position; added vertices move by less
    // than `drift` in all, which widens the window.
    let mut by_x: Vec<usize> = (0..pos.len()).collect();
    by_x.sort_by(|&a, &b| pos[a][0].total_cmp(&pos[b][0]));
    let xs: Vec<f64> = by_x.iter().map(|&i| pos[i][0]).collect();
    let mut drift = 0.0f64;
    let near = |pos: &[[f64; 3]], v: usize, p: [f64; 3], tol: f64, drift: f64| {
        let lo = xs.partition_point(|&x| x < p[0] - tol - drift);
        let hi = xs.partition_point(|&x| x <= p[0] + tol + drift);
        by_x[lo..hi].iter().any(|&j| j != v && norm(sub(pos[j], p)) <= tol)
    };
    for v in first..pos.len() {
        let vid = VertexId(v as u32);
        let nbrs: Vec<usize> = hm.vertex_outgoing(vid).map(|h| hm.to_vertex(h).idx()).collect();
        if nbrs.is_empty() {
            continue;
        }
        let reach = mean_reach(pos, v, &nbrs);
        let tol = SAME_POSITION * reach;
        if !(tol > 0.0 && tol.is_finite() && near(pos, v, pos[v], tol, drift)) {
            continue;
        }
        let faces: Vec<[usize; 4]> =
            hm.vertex_faces(vid).map(|f| hm.face_vertices(f).map(|x| x.idx())).collect();
        let Some(dirs) = step_directions(pos, &faces) else { continue };
        let old = pos[v];
        let before = worst(pos, &faces);
        let mut h = 1e-3 * reach;
        let mut moved = None;
        for _ in 0..20 {
            let mut pick: Option<([f64; 3], f64)> = None;
            for d in dirs {
                let p = add(old, scale(d, h));
                if near(pos, v, p, tol, drift) {
                    continue;
                }
                pos[v] = p;
                let w = worst(pos, &faces);
                if w >= before - SEPARATE_SLACK && pick.map_or(true, |(_, b)| w > b) {
                    pick = Some((p, w));
                }
            }
            if let Some((p, _)) = pick {
                moved = Some(p);
                break;
            }
            h *= 0.5;
        }
        pos[v] = moved.unwrap_or(old);
        if moved.is_some() {
            drift = drift.max(2.0 * h);
        }
    }
}

/// Guarded Laplacian smoothing of the vertices from `first` on: each moves to the mean
/// of its neighbours when that does not lower the worst scaled Jacobian of its quads.
fn smooth_added(hm: &HalfedgeMesh, pos: &mut [[f64; 3]], first: usize, steps: usize) {
    for _ in 0..steps {
        for v in first..pos.len() {
            let vid = VertexId(v as u32);
            let nbrs: Vec<usize> = hm.vertex_outgoing(vid).map(|h| hm.to_vertex(h).idx()).collect();
            if nbrs.is_empty() {
                continue;
            }
            let faces: Vec<[usize; 4]> =
                hm.vertex_faces(vid).map(|f| hm.face_vertices(f).map(|x| x.idx())).collect();
            let before = worst(pos, &faces);
            let old = pos[v];
            pos[v] = scale(nbrs.iter().fold([0.0; 3], |s, &n| add(s, pos[n])), 1.0 / nbrs.len() as f64);
            if worst(pos, &faces) < before {
                pos[v] = old;
            }
        }
    }
}

/// The boundary loops of at most `limit` edges.
fn open_loops(hm: &HalfedgeMesh, limit: usize) -> Vec<Vec<HalfedgeId>> {
    hm.boundary_loops().into_iter().filter(|l| l.len() <= limit).collect()
}

fn has_repeat(vs: &[u32]) -> bool {
    let set: HashSet<u32> = vs.iter().copied().collect();
    set.len() != vs.len()
}

/// Closes the even loop `vs` (from-vertices of its boundary half-edges, in order) by a
/// fan of quads around a new vertex at its centroid, from its first vertex or, when that
/// fan has a degenerate quad, from its second; no face changes when they do not all go
/// in, and nothing at all when both fans have a degenerate quad.
fn fan(hm: &mut HalfedgeMesh, pos: &mut Vec<[f64; 3]>, vs: &[u32]) {
    let Some(vs) = sound_fan(pos, vs) else {
        return;
    };
    let quads = fan_quads(hm, pos, &vs);
    // When they do not go in, the vertex stays, isolated (no face uses it).
    add_all(hm, &quads);
}

/// The quads `(v₀, v₁, v₂, c), (v₂, v₃, v₄, c), …` of a fan over the even loop `vs`
/// round a new vertex `c` at its centroid (added to `hm` and `pos`).
fn fan_quads(hm: &mut HalfedgeMesh, pos: &mut Vec<[f64; 3]>, vs: &[u32]) -> Vec<[u32; 4]> {
    let n = vs.len();
    let centre = centroid(pos, vs);
    let c = hm.add_vertex();
    pos.push(centre);
    (0..n / 2).map(|i| [vs[2 * i], vs[2 * i + 1], vs[(2 * i + 2) % n], c.0]).collect()
}

/// One strip to split: its faces from the first odd loop to the second, with the
/// half-edge (of that face) through which each is entered and left.
struct Strip {
    faces: Vec<FaceId>,
    entry: Vec<HalfedgeId>,
    exit: Vec<HalfedgeId>,
}

/// Face-disjoint strips pairing the odd loops of at most `limit` edges, shortest loops
/// first.
fn pair_odd_loops(hm: &HalfedgeMesh, limit: usize, support: &dyn Fn([u32; 4]) -> f64) -> Vec<Strip> {
    let loops = open_loops(hm, limit);
    // Boundary half-edge → index of its odd loop.
    let mut odd_of: HashMap<u32, usize> = HashMap::new();
    let mut odd: Vec<usize> = Vec::new();
    for (i, lp) in loops.iter().enumerate() {
        if lp.len() % 2 == 1 {
            odd.push(i);
            for h in lp {
                odd_of.insert(h.0, i);
            }
        }
    }
    odd.sort_by_key(|&i| (loops[i].len(), loops[i][0].0));
    let cost = |f: FaceId| 0.05 + support(corner_set(hm.face_vertices(f).map(|v| v.0))).max(0.0);
    let mut used_face: HashSet<u32> = HashSet::new();
    let mut used_loop: HashSet<usize> = HashSet::new();
    let mut strips = Vec::new();
    for &a in &odd {
        if used_loop.contains(&a) {
            continue;
        }
        // Dijkstra over faces; per face: (cost, parent, entry half-edge).
        let mut best: HashMap<u32, (f64, Option<FaceId>, HalfedgeId)> = HashMap::new();
        let mut heap = BinaryHeap::new();
        for &h in &loops[a] {
            let g = h.opposite();
            if let Some(f) = hm.face(g) {
                if used_face.contains(&f.0) {
                    continue;
                }
                let c = cost(f);
                if best.get(&f.0).map_or(true, |b| c < b.0) {
                    best.insert(f.0, (c, None, g));
                    heap.push(Item(c, f.0, 0));
                }
            }
        }
        let mut done: HashSet<u32> = HashSet::new();
        let mut found: Option<(FaceId, HalfedgeId, usize)> = None;
        while let Some(Item(c, f, _)) = heap.pop() {
            if !done.insert(f) {
                continue;
            }
            let face = FaceId(f);
            let entry = best[&f].2;
            // A side of this face on another odd loop, not yet paired, ends the strip.
            let end = hm.face_halfedges(face).into_iter().find_map(|g| {
                let b = *odd_of.get(&g.opposite().0)?;
                (g != entry && b != a && !used_loop.contains(&b)).then_some((g, b))
            });
            if let Some((g, b)) = end {
                found = Some((face, g, b));
                break;
            }
            for g in hm.face_halfedges(face) {
                if let Some(n) = hm.face(g.opposite()) {
                    if used_face.contains(&n.0) || done.contains(&n.0) {
                        continue;
                    }
                    let nc = c + cost(n);
                    if best.get(&n.0).map_or(true, |b| nc < b.0) {
                        best.insert(n.0, (nc, Some(face), g.opposite()));
                        heap.push(Item(nc, n.0, 0));
                    }
                }
            }
        }
        let Some((last, out, b)) = found else { continue };
        let mut faces = vec![last];
        let mut entry = vec![best[&last.0].2];
        let mut exit = vec![out];
        let mut cur = last;
        while let Some(p) = best[&cur.0].1 {
            exit.push(best[&cur.0].2.opposite());
            faces.push(p);
            entry.push(best[&p.0].2);
            cur = p;
        }
        faces.reverse();
        entry.reverse();
        exit.reverse();
        used_face.extend(faces.iter().map(|f| f.0));
        used_loop.insert(a);
        used_loop.insert(b);
        strips.push(Strip { faces, entry, exit });
    }
    strips
}

/// The quads of `hm` with every strip's faces split (module docs); new vertices are
/// appended to `pos`.
fn split_strips(hm: &HalfedgeMesh, pos: &mut Vec<[f64; 3]>, strips: &[Strip]) -> Vec<[u32; 4]> {
    let on_strip: HashSet<u32> = strips.iter().flat_map(|s| s.faces.iter().map(|f| f.0)).collect();
    let mut out: Vec<[u32; 4]> =
        hm.faces().filter(|f| !on_strip.contains(&f.0)).map(|f| hm.face_vertices(f).map(|v| v.0)).collect();
    for s in strips {
        // One new vertex per crossed edge: at its midpoint inside the strip; where the
        // strip leaves or meets a loop, moved a quarter of the way towards the face's
        // centre, so that the quad that later closes the loop has no straight corner.
        let mut mid: HashMap<usize, u32> = HashMap::new();
        let n = s.faces.len();
        for (i, &f) in s.faces.iter().enumerate() {
            let corners = hm.face_vertices(f);
            let centre = scale(corners.iter().fold([0.0; 3], |acc, v| add(acc, pos[v.idx()])), 0.25);
            for (g, at_loop) in [(s.entry[i], i == 0), (s.exit[i], i + 1 == n)] {
                mid.entry(g.edge()).or_insert_with(|| {
                    let m = scale(add(pos[hm.from_vertex(g).idx()], pos[hm.to_vertex(g).idx()]), 0.5);
                    let p = if at_loop { add(scale(m, 0.75), scale(centre, 0.25)) } else { m };
                    pos.push(p);
                    (pos.len() - 1) as u32
                });
            }
            let hs = hm.face_halfedges(f);
            let j = hs.iter().position(|&h| h == s.entry[i]).expect("entry half-edge of the face");
            let k = hs.iter().position(|&h| h == s.exit[i]).expect("exit half-edge of the face");
            let q = |t: usize| corners[(j + t) % 4].0;
            let a = mid[&s.entry[i].edge()];
            let b = mid[&s.exit[i].edge()];
            match (k + 4 - j) % 4 {
                2 => {
                    // Entry q0→q1, exit q2→q3.
                    out.push([q(0), a, b, q(3)]);
                    out.push([a, q(1), q(2), b]);
                }
                1 => {
                    // Entry q0→q1, exit q1→q2: three quads around a centre vertex.
                    pos.push(centre);
                    let c = (pos.len() - 1) as u32;
                    out.push([q(0), a, c, q(3)]);
                    out.push([a, q(1), b, c]);
                    out.push([c, b, q(2), q(3)]);
                }
                3 => {
                    // Entry q0→q1, exit q3→q0.
                    pos.push(centre);
                    let c = (pos.len() - 1) as u32;
                    out.push([q(0), a, c, b]);
                    out.push([a, q(1), q(2), c]);
                    out.push([c, q(2), q(3), b]);
                }
                _ => unreachable!("a strip enters and leaves a face through different sides"),
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::validate::validate;

    /// The border of a `nu` × `nv` grid sheet (its from-vertices in loop order), with the
    /// sheet as a half-edge mesh and its positions lifted by `bump` along z.
    fn sheet(nu: usize, nv: usize, bump: f64) -> (HalfedgeMesh, Vec<[f64; 3]>, Vec<u32>) {
        let g = crate::mesh::shapes::grid(nu, nv, nu as f64, nv as f64);
        let hm = HalfedgeMesh::from_quads(g.vertices.len(), &g.quads).unwrap();
        let pos: Vec<[f64; 3]> =
            g.vertices.iter().map(|p| [p[0], p[1], p[2] + bump * (p[0] * 0.7 + p[1] * 1.3).sin()]).collect();
        let loops = hm.boundary_loops();
        assert_eq!(loops.len(), 1);
        let vs = loops[0].iter().map(|&h| hm.from_vertex(h).0).collect();
        (hm, pos, vs)
    }

    /// `split_and_fill` without the quadrangulation (`max_dp` 0): the sheet's border is
    /// cut by chords into pieces of at most [`FAN_EDGES`] edges, each fanned; the quads
    /// close the sheet into a valid sphere (Euler characteristic 2), every added vertex is
    /// a fan's centre of degree at most `FAN_EDGES / 2`, the pieces' edges add up to the
    /// border's plus both sides of every chord. One fan over the whole border (what
    /// `close_all` did without `split_long_loops`) fails the degree bound above 16 edges.
    #[test]
    fn long_loops_are_cut_into_short_fans() {
        let shape = CloseConfig { min_normal_dot: -1.0, ..CloseConfig::default() };
        for nu in 2..12 {
            for nv in 2..12 {
                let (mut hm, mut pos, vs) = sheet(nu, nv, 0.3);
                let n = vs.len();
                let first_new = pos.len();
                let pieces = split_and_fill(&hm, &pos, &vs, 0, &shape).expect("a sound split");
                let quads = commit_pieces(&mut hm, &mut pos, pieces);
                assert!(add_all(&mut hm, &quads), "{nu}x{nv}: the quads do not go in");
                validate(&hm).unwrap();
                assert!(hm.boundary_loops().is_empty(), "{nu}x{nv}");
                let chi = hm.n_vertices() as i64 - hm.n_edges() as i64 + hm.n_faces() as i64;
                assert_eq!(chi, 2, "{nu}x{nv}");
                let pieces = pos.len() - first_new;
                assert!(pieces >= n.div_ceil(FAN_EDGES), "{nu}x{nv}: {pieces} pieces for {n} edges");
                let mut edges = 0;
                for c in first_new..pos.len() {
                    let degree = hm.vertex_outgoing(VertexId(c as u32)).count();
                    assert!((2..=FAN_EDGES / 2).contains(&degree), "{nu}x{nv}: centre of degree {degree}");
                    edges += 2 * degree;
                }
                // Each piece's loop has twice as many edges as its centre has spokes;
                // the chords are counted on both sides.
                assert_eq!(edges, n + 2 * (pieces - 1), "{nu}x{nv}");
                assert!(pos[first_new..].iter().flatten().all(|x| x.is_finite()));
            }
        }
    }

    /// Session 41's audit: a loop whose fan from its first vertex has a degenerate quad
    /// (here `(v0, v1, v2, c)`: its diagonals `v2 − v0` and `c − v1` are parallel) was
    /// left open; the fan from its second vertex is sound and closes it.
    #[test]
    fn the_fan_starts_at_the_second_vertex_when_the_first_gives_a_degenerate_quad() {
        // A hexagon with a notch at v1; its vertex mean c = (1.1, 2) lies level with v1.
        let mut pos: Vec<[f64; 3]> = vec![
            [0.0, 0.0, 0.0],
            [1.0, 2.0, 0.0],
            [2.0, 0.0, 0.0],
            [2.0, 3.0, 0.0],
            [1.6, 4.0, 0.0],
            [0.0, 3.0, 0.0],
        ];
        let vs = [0u32, 1, 2, 3, 4, 5];
        assert!(!fan_is_sound(&pos, &vs), "the premise: the first fan has a degenerate quad");
        let mut hm = HalfedgeMesh::from_quads(6, &[]).unwrap();
        fan(&mut hm, &mut pos, &vs);
        assert_eq!(hm.n_faces(), 3);
        validate(&hm).unwrap();
        let quads = hm.to_quad_mesh(&pos).unwrap().quads;
        for q in &quads {
            assert!(!is_degenerate_quad(&q.map(|v| pos[v as usize])), "{q:?}");
            assert!(q.contains(&6), "{q:?}: not round the new centre");
        }
        assert!(quads.iter().any(|q| q[0] == 1), "{quads:?}: not the fan from v1");
    }

    /// A fan of quads over a convex `n`-gon (n even) round a centre vertex (index n)
    /// at `centre`: the half-edge mesh and the positions.
    fn fan_mesh(n: usize, radius: impl Fn(usize) -> f64, centre: [f64; 3]) -> (HalfedgeMesh, Vec<[f64; 3]>) {
        let mut pos: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let t = std::f64::consts::TAU * i as f64 / n as f64;
                [radius(i) * t.cos(), radius(i) * t.sin(), 0.0]
            })
            .collect();
        pos.push(centre);
        let quads: Vec<[u32; 4]> = (0..n / 2)
            .map(|i| [2 * i as u32, 2 * i as u32 + 1, ((2 * i + 2) % n) as u32, n as u32])
            .collect();
        (HalfedgeMesh::from_quads(n + 1, &quads).unwrap(), pos)
    }

    fn worst_of(hm: &HalfedgeMesh, pos: &[[f64; 3]]) -> f64 {
        let faces: Vec<[usize; 4]> = hm.faces().map(|f| hm.face_vertices(f).map(|v| v.idx())).collect();
        worst(pos, &faces)
    }

    /// The pattern search never lowers the worst scaled Jacobian of the added vertex's
    /// quads and moves nothing else, for centres anywhere near convex polygons of 6 to 16
    /// sides; an octagon's centre pushed past one side (two quads inverted) comes back
    /// inside (every quad's scaled Jacobian > 0.3).
    #[test]
    fn the_pattern_search_only_improves_the_worst_quad() {
        let mut rng = crate::rng::Rng::new(5);
        for case in 0..200 {
            let n = 2 * (3 + case % 6);
            let radii: Vec<f64> = (0..n).map(|_| rng.uniform(0.8, 1.2)).collect();
            let c = [rng.uniform(-1.5, 1.5), rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 0.5)];
            let (hm, mut pos) = fan_mesh(n, |i| radii[i], c);
            let before = pos.clone();
            let w0 = worst_of(&hm, &pos);
            maximin_added(&hm, &mut pos, n, 3);
            let w1 = worst_of(&hm, &pos);
            assert!(w1 >= w0, "case {case}: worst {w0} -> {w1}");
            assert_eq!(&pos[..n], &before[..n], "case {case}: an input vertex moved");
            assert!(pos[n].iter().all(|x| x.is_finite()));
        }
        let (hm, mut pos) = fan_mesh(8, |_| 1.0, [1.3, 0.2, 0.0]);
        assert!(worst_of(&hm, &pos) < 0.0);
        maximin_added(&hm, &mut pos, 8, 3);
        let w = worst_of(&hm, &pos);
        assert!(w > 0.3, "worst {w} at {:?}", pos[8]);
    }
}
