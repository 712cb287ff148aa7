//! Greedy quad hole filling (DESIGN §4): (1) a 4-edge loop becomes one quad; (2) three
//! consecutive boundary edges with two near-right corners are closed by one quad; (3) a
//! near-right corner is completed by a parallelogram vertex (an unused input point near it
//! if there is one, else a new vertex). Every quad goes through `add_face`, so the mesh
//! stays manifold, and is kept only if well shaped and not folded against its neighbours.
//!
//! Which loops are holes: only loops of even length (an odd loop cannot be closed by
//! quads) and at most `max_hole_edges` edges are touched; patterns 2 and 3 need corners
//! that are convex seen from inside the loop *and* lie in the surface's tangent plane. An
//! open surface's outer border has reflex or straight corners seen from its "hole" side,
//! and the open end of a tube turns across the surface rather than in it, so nothing runs
//! away along a border. A 4-edge loop is always closed (pattern 1), so a square tube's end
//! is capped.

use std::collections::HashMap;

use super::halfedge::HalfedgeMesh;
use super::handles::{FaceId, HalfedgeId, VertexId};
use super::quality::is_degenerate_quad;
use crate::error::{Error, Result};
use crate::math::{add, cross, dist_sq, dot, norm, normalize, scale, sub};

/// Thresholds of the hole filling.
#[derive(Clone, Debug, PartialEq)]
pub struct HoleFillConfig {
    /// Loops with more edges are left open (they are borders, not holes).
    pub max_hole_edges: usize,
    /// A corner is near-right when its angle is within this many degrees of 90.
    pub right_angle_tol_deg: f64,
    /// Minimum scaled Jacobian of a filling quad (1 = square, ≤ 0 = inverted).
    pub min_scaled_jacobian: f64,
    /// Minimum dot product of a filling quad's unit normal with each neighbour's.
    pub min_normal_dot: f64,
    /// A corner counts as convex when the unit normal of the plane its two boundary edges
    /// span agrees with the surface normal there (mean of the neighbouring faces') by at
    /// least this much. A hole in a surface lies in the tangent plane (dot near 1); the open
    /// end of a tube lies across it (dot near 0) and is left open.
    pub min_corner_normal_dot: f64,
    /// Pattern 1 (a 4-edge loop) uses these bounds; the defaults (−1) accept any quad
    /// `add_face` accepts: the four corners are given, and a single-face hole must close
    /// even on spiky or twisted geometry. (A lone quad's own border is refused by
    /// `add_face` as a duplicate.)
    pub loop4_min_scaled_jacobian: f64,
    /// See `loop4_min_scaled_jacobian`.
    pub loop4_min_normal_dot: f64,
    /// Pattern 3 reuses an isolated vertex within this fraction of the corner's mean
    /// edge length from the parallelogram point instead of adding a vertex.
    pub snap_radius: f64,
    /// When the patterns cannot close a loop and invented a vertex on the way, the loop
    /// is put back as it was: a partial fill's new vertices can fold over the rest of the
    /// hole, and its quads stand in the way of the rescue and the closing that come
    /// after. A partial fill over existing points only (a border's notches) stays.
    pub undo_partial_fills: bool,
    /// Uniform Laplacian steps applied to the added vertices (and only to them).
    pub smoothing_steps: usize,
    /// Fills tried per loop are bounded by this many times its length.
    pub max_steps_per_edge: usize,
}

/// Defaults tuned on `train/` (remove 1–5% of faces, fill, compare): the normal bound is
/// loose because sharp-featured meshes need fills across creases; folds (normals near
/// opposite) and inverted quads are still refused.
impl Default for HoleFillConfig {
    fn default() -> Self {
        HoleFillConfig {
            max_hole_edges: 40,
            right_angle_tol_deg: 45.0,
            min_scaled_jacobian: 0.3,
            min_normal_dot: -0.3,
            min_corner_normal_dot: 0.5,
            loop4_min_scaled_jacobian: -1.0,
            loop4_min_normal_dot: -1.0,
            snap_radius: 0.5,
            undo_partial_fills: true,
            smoothing_steps: 3,
            max_steps_per_edge: 2,
        }
    }
}

/// What the hole filling did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HoleFillReport {
    /// Boundary loops before filling.
    pub loops_before: usize,
    /// Loops that were eligible (even length, at most `max_hole_edges`).
    pub loops_eligible: usize,
    /// Loops closed completely.
    pub loops_closed: usize,
    /// Quads added, per pattern (1, 2, 3).
    pub quads_by_pattern: [usize; 3],
    /// Pattern-3 corners completed with an existing isolated vertex.
    pub vertices_reused: usize,
    /// Vertices added (appended to the positions).
    pub vertices_added: usize,
}

impl HoleFillReport {
    /// Total quads added.
    pub fn quads_added(&self) -> usize {
        self.quads_by_pattern.iter().sum()
    }

    /// Adds the counts of a later run over the same mesh (loops are counted per run).
    pub fn absorb(&mut self, later: &HoleFillReport) {
        self.loops_before += later.loops_before;
        self.loops_eligible += later.loops_eligible;
        self.loops_closed += later.loops_closed;
        for (a, b) in self.quads_by_pattern.iter_mut().zip(later.quads_by_pattern) {
            *a += b;
        }
        self.vertices_reused += later.vertices_reused;
        self.vertices_added += later.vertices_added;
    }
}

/// Isolated vertices in a uniform grid, for pattern 3's reuse of unused input points.
struct IsolatedGrid {
    cell: f64,
    cells: HashMap<(i64, i64, i64), Vec<u32>>,
}

impl IsolatedGrid {
    fn key(&self, p: [f64; 3]) -> (i64, i64, i64) {
        (
            (p[0] / self.cell).floor() as i64,
            (p[1] / self.cell).floor() as i64,
            (p[2] / self.cell).floor() as i64,
        )
    }
    fn nearest(&self, p: [f64; 3], radius: f64, pos: &[[f64; 3]], mesh: &HalfedgeMesh) -> Option<u32> {
        let k = self.key(p);
        // Capped so that one long edge among short ones cannot make the scan explode; beyond
        // the cap, far candidates are simply not considered.
        let r = ((radius / self.cell).ceil() as i64).clamp(0, 3);
        let mut best: Option<(f64, u32)> = None;
        for dx in -r..=r {
            for dy in -r..=r {
                for dz in -r..=r {
                    let Some(list) = self.cells.get(&(k.0 + dx, k.1 + dy, k.2 + dz)) else { continue };
                    for &v in list {
                        if !mesh.is_isolated(VertexId(v)) {
                            continue;
                        }
                        let d = dist_sq(pos[v as usize], p);
                        if d <= radius * radius && best.map_or(true, |(bd, bv)| (d, v) < (bd, bv)) {
                            best = Some((d, v));
                        }
                    }
                }
            }
        }
        best.map(|(_, v)| v)
    }
}

/// Unit normal of a quad: normalize((p2 − p0) × (p3 − p1)).
pub(crate) fn quad_normal(p: &[[f64; 3]; 4]) -> Option<[f64; 3]> {
    normalize(cross(sub(p[2], p[0]), sub(p[3], p[1])))
}

/// Scaled Jacobian (DESIGN §2): min over corners of (c_i · n)/(|e_{i−1}||e_i|).
pub(crate) fn scaled_jacobian(p: &[[f64; 3]; 4]) -> f64 {
    let Some(n) = quad_normal(p) else { return -1.0 };
    let mut sj = f64::INFINITY;
    for i in 0..4 {
        let e0 = sub(p[i], p[(i + 3) % 4]);
        let e1 = sub(p[(i + 1) % 4], p[i]);
        let l = norm(e0) * norm(e1);
        if l <= 0.0 || !l.is_finite() {
            return -1.0;
        }
        sj = sj.min(dot(cross(e0, e1), n) / l);
    }
    sj
}

struct Filler<'a> {
    mesh: &'a mut HalfedgeMesh,
    pos: &'a mut Vec<[f64; 3]>,
    cfg: &'a HoleFillConfig,
    grid: IsolatedGrid,
    cos_tol: f64,
    report: HoleFillReport,
    added: Vec<u32>,
    /// Faces placed while filling the current loop.
    placed: Vec<FaceId>,
}

/// A candidate quad closing part of a loop.
struct Candidate {
    quad: [u32; 4],
    /// `Some(p)` when the fourth corner is a new vertex at `p`.
    new_pos: Option<[f64; 3]>,
    pattern: usize,
    score: f64,
    /// A boundary half-edge expected on the loop after the fill: (from, to).
    anchor: (u32, u32),
}

impl Filler<'_> {
    fn face_normal_across(&self, h: HalfedgeId) -> Option<[f64; 3]> {
        let f = self.mesh.face(h.opposite())?;
        let p = self.mesh.face_vertices(f).map(|v| self.pos[v.idx()]);
        quad_normal(&p)
    }

    /// Scaled Jacobian of the quad if it passes the shape and normal checks.
    fn quad_quality(&self, p: &[[f64; 3]; 4], neighbours: &[HalfedgeId]) -> Option<f64> {
        let (min_sj, min_dot) = if neighbours.len() == 4 {
            (self.cfg.loop4_min_scaled_jacobian, self.cfg.loop4_min_normal_dot)
        } else {
            (self.cfg.min_scaled_jacobian, self.cfg.min_normal_dot)
        };
        // Never a quad without area, even where pattern 1 accepts any shape: closing a
        // hole left by a dropped zero-area quad must not put it back.
        if is_degenerate_quad(p) {
            return None;
        }
        let sj = scaled_jacobian(p);
        if sj < min_sj {
            return None;
        }
        let n = quad_normal(p)?;
        for &h in neighbours {
            if let Some(m) = self.face_normal_across(h) {
                if dot(n, m) < min_dot {
                    return None;
                }
            }
        }
        Some(sj)
    }

    /// Is the corner at the end of `hin` (start of `hout`) near-right and convex seen from
    /// the hole? The hole lies left of the boundary direction about the neighbours' normal.
    fn near_right(&self, hin: HalfedgeId, hout: HalfedgeId) -> bool {
        let a = self.pos[self.mesh.from_vertex(hin).idx()];
        let b = self.pos[self.mesh.to_vertex(hin).idx()];
        let c = self.pos[self.mesh.to_vertex(hout).idx()];
        let (d0, d1) = (sub(a, b), sub(c, b));
        let l = norm(d0) * norm(d1);
        if l <= 0.0 || !l.is_finite() {
            return false;
        }
        if (dot(d0, d1) / l).abs() > self.cos_tol {
            return false;
        }
        let n = match (self.face_normal_across(hin), self.face_normal_across(hout)) {
            (Some(x), Some(y)) => add(x, y),
            (Some(x), None) | (None, Some(x)) => x,
            (None, None) => return false,
        };
        match (normalize(cross(sub(b, a), sub(c, b))), normalize(n)) {
            (Some(t), Some(n)) => dot(t, n) >= self.cfg.min_corner_normal_dot,
            _ => false,
        }
    }

    fn walk(&self, start: HalfedgeId) -> Vec<HalfedgeId> {
        let mut lp = vec![start];
        let mut h = self.mesh.next(start);
        while h != start && lp.len() <= self.cfg.max_hole_edges {
            lp.push(h);
            h = self.mesh.next(h);
        }
        lp
    }

    fn best_candidate(&self, lp: &[HalfedgeId]) -> Option<Candidate> {
        let l = lp.len();
        let from = |k: usize| self.mesh.from_vertex(lp[k % l]).0;
        let p = |v: u32| self.pos[v as usize];
        if l == 4 {
            let quad = [from(0), from(1), from(2), from(3)];
            let score = self.quad_quality(&quad.map(p), lp)?;
            return Some(Candidate { quad, new_pos: None, pattern: 1, score, anchor: (quad[0], quad[1]) });
        }
        let right: Vec<bool> = (0..l).map(|k| self.near_right(lp[k], lp[(k + 1) % l])).collect();
        // right[k]: corner at the end of lp[k], i.e. at vertex from(k + 1).
        let mut best: Option<Candidate> = None;
        let better = |c: &Candidate, b: &Option<Candidate>| b.as_ref().map_or(true, |b| c.score > b.score);
        if l >= 6 {
            for k in 0..l {
                if right[k] && right[(k + 1) % l] {
                    let quad = [from(k), from(k + 1), from(k + 2), from(k + 3)];
                    let nb = [lp[k], lp[(k + 1) % l], lp[(k + 2) % l]];
                    if let Some(score) = self.quad_quality(&quad.map(p), &nb) {
                        let c =
                            Candidate { quad, new_pos: None, pattern: 2, score, anchor: (quad[0], quad[3]) };
                        if better(&c, &best) {
                            best = Some(c);
                        }
                    }
                }
            }
            if best.is_some() {
                return best;
            }
        }
        for k in 0..l {
            if !right[k] {
                continue;
            }
            let (u0, u1, u2) = (from(k), from(k + 1), from(k + 2));
            let target = sub(add(p(u0), p(u2)), p(u1));
            let mean_len = 0.5 * (norm(sub(p(u0), p(u1))) + norm(sub(p(u2), p(u1))));
            let r = self.cfg.snap_radius * mean_len;
            let near = |v: u32| dist_sq(p(v), target) <= r * r;
            let mut nb = vec![lp[k], lp[(k + 1) % l]];
            // The completion point may be the loop's next or previous vertex (the fill then
            // closes three edges), an unused input point, or else a new vertex.
            let (quad, new_pos, bonus, anchor) = if l >= 6 && near(from(k + 3)) {
                let q = [u0, u1, u2, from(k + 3)];
                nb.push(lp[(k + 2) % l]);
                (q, None, 2.0, (u0, q[3]))
            } else if l >= 6 && near(from(k + l - 1)) {
                let q = [from(k + l - 1), u0, u1, u2];
                nb.push(lp[(k + l - 1) % l]);
                (q, None, 2.0, (q[0], u2))
            } else if let Some(v) = self.grid.nearest(target, r, self.pos, self.mesh) {
                ([u0, u1, u2, v], None, 1.0, (u0, v))
            } else {
                ([u0, u1, u2, u32::MAX], Some(target), 0.0, (u0, u32::MAX))
            };
            let pts = [0, 1, 2, 3].map(|i| if quad[i] == u32::MAX { target } else { p(quad[i]) });
            if let Some(sj) = self.quad_quality(&pts, &nb) {
                let c = Candidate { quad, new_pos, pattern: 3, score: sj + bonus, anchor };
                if better(&c, &best) {
                    best = Some(c);
                }
            }
        }
        best
    }

    /// Fills one loop as far as the patterns allow; returns whether it closed.
    fn fill_loop(&mut self, start: HalfedgeId) -> bool {
        let mut anchor = start;
        let first_len = self.walk(start).len();
        for _ in 0..self.cfg.max_steps_per_edge * first_len + 4 {
            let lp = self.walk(anchor);
            if lp.len() > self.cfg.max_hole_edges || lp.len() % 2 == 1 {
                return false;
            }
            let Some(mut c) = self.best_candidate(&lp) else { return false };
            let mut new_vertex = None;
            if let Some(np) = c.new_pos {
                let v = self.mesh.add_vertex();
                self.pos.push(np);
                c.quad[3] = v.0;
                c.anchor.1 = v.0;
                new_vertex = Some(v);
            }
            match self.mesh.add_face(c.quad.map(VertexId)) {
                Ok(face) => {
                    self.placed.push(face);
                    self.report.quads_by_pattern[c.pattern - 1] += 1;
                    if let Some(v) = new_vertex {
                        self.report.vertices_added += 1;
                        self.added.push(v.0);
                    } else if c.pattern == 3 {
                        self.report.vertices_reused += 1;
                    }
                }
                Err(_) => {
                    if new_vertex.is_some() {
                        // The vertex was appended last; nothing refers to it yet.
                        self.mesh.v_out.pop();
                        self.pos.pop();
                    }
                    return false;
                }
            }
            if c.pattern == 1 {
                return true;
            }
            match self.mesh.find_halfedge(VertexId(c.anchor.0), VertexId(c.anchor.1)) {
                Some(h) if self.mesh.is_boundary(h) => anchor = h,
                _ => return self.mesh.find_halfedge(VertexId(c.anchor.1), VertexId(c.anchor.0)).is_some(),
            }
        }
        false
    }

    /// Laplacian steps on the added vertices. A step is kept only if no face at the
    /// vertex ends with a scaled Jacobian below min(`min_scaled_jacobian`, its value
    /// before the step) or loses its area: a vertex on a border has two neighbours, and
    /// their mean would put it on the line between them (a flat, degenerate corner).
    fn smooth(&mut self) {
        for _ in 0..self.cfg.smoothing_steps {
            for &v in &self.added {
                let mut sum = [0.0; 3];
                let mut n = 0usize;
                for h in self.mesh.vertex_outgoing(VertexId(v)) {
                    sum = add(sum, self.pos[self.mesh.to_vertex(h).idx()]);
                    n += 1;
                }
                if n == 0 {
                    continue;
                }
                let faces: Vec<[VertexId; 4]> =
                    self.mesh.vertex_faces(VertexId(v)).map(|f| self.mesh.face_vertices(f)).collect();
                let shape = |pos: &[[f64; 3]], q: &[VertexId; 4]| {
                    let p = q.map(|x| pos[x.idx()]);
                    if is_degenerate_quad(&p) {
                        f64::NEG_INFINITY
                    } else {
                        scaled_jacobian(&p)
                    }
                };
                let before: Vec<f64> = faces.iter().map(|q| shape(self.pos, q)).collect();
                let old = self.pos[v as usize];
                self.pos[v as usize] = scale(sum, 1.0 / n as f64);
                let worse = faces
                    .iter()
                    .zip(&before)
                    .any(|(q, &b)| shape(self.pos, q) < b.min(self.cfg.min_scaled_jacobian));
                if worse {
                    self.pos[v as usize] = old;
                }
            }
        }
    }
}

/// Fills the holes of `mesh` (whose vertex positions are `positions`) greedily with the
/// three patterns; added vertices are appended to `positions` (existing entries are never
/// changed) and smoothed.
///
/// # Errors
/// `InvalidInput` when `positions` does not have one finite entry per mesh vertex.
pub fn fill_holes(
    mesh: &mut HalfedgeMesh,
    positions: &mut Vec<[f64; 3]>,
    cfg: &HoleFillConfig,
) -> Result<HoleFillReport> {
    if positions.len() != mesh.n_vertices() {
        return Err(Error::invalid(format!(
            "fill_holes: {} positions for {} vertices",
            positions.len(),
            mesh.n_vertices()
        )));
    }
    if let Some(i) = positions.iter().position(|p| p.iter().any(|x| !x.is_finite())) {
        return Err(Error::invalid(format!("fill_holes: vertex {i} has a non-finite coordinate")));
    }
    let mut edge_sum = 0.0;
    let mut edge_n = 0usize;
    for e in 0..mesh.halfedge_capacity() / 2 {
        if mesh.is_edge_alive(e) {
            let h = HalfedgeId(2 * e as u32);
            edge_sum += norm(sub(positions[mesh.to_vertex(h).idx()], positions[mesh.from_vertex(h).idx()]));
            edge_n += 1;
        }
    }
    let cell = if edge_n > 0 && edge_sum > 0.0 { edge_sum / edge_n as f64 } else { 1.0 };
    let mut grid = IsolatedGrid { cell, cells: HashMap::new() };
    for (v, &p) in positions.iter().enumerate() {
        if mesh.is_isolated(VertexId(v as u32)) {
            let k = grid.key(p);
            grid.cells.entry(k).or_default().push(v as u32);
        }
    }
    let loops = mesh.boundary_loops();
    let mut f = Filler {
        mesh,
        pos: positions,
        cfg,
        grid,
        cos_tol: cfg.right_angle_tol_deg.to_radians().sin(),
        report: HoleFillReport { loops_before: loops.len(), ..Default::default() },
        added: Vec::new(),
        placed: Vec::new(),
    };
    for lp in loops {
        if lp.len() > cfg.max_hole_edges || lp.len() % 2 == 1 {
            continue;
        }
        // An earlier fill may have merged this loop into another one.
        if !f.mesh.is_boundary(lp[0]) || !f.mesh.is_edge_alive(lp[0].edge()) {
            continue;
        }
        f.report.loops_eligible += 1;
        let (report, added, n_pos) = (f.report.clone(), f.added.len(), f.pos.len());
        f.placed.clear();
        if f.fill_loop(lp[0]) {
            f.report.loops_closed += 1;
        } else if cfg.undo_partial_fills && f.pos.len() > n_pos {
            // A partial fill that invented vertices goes back out, last face first, with
            // its new vertices (the last ones appended; nothing else refers to them then).
            for &face in f.placed.iter().rev() {
                f.mesh.remove_face(face).expect("internal error: a fill quad comes off again");
            }
            while f.pos.len() > n_pos {
                f.pos.pop();
                f.mesh.v_out.pop();
            }
            f.added.truncate(added);
            f.report = report;
        }
    }
    f.smooth();
    Ok(f.report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::handles::FaceId;
    use crate::mesh::validate::validate;

    /// n×n quads on the unit grid, vertex (i, j) = (n + 1) j + i.
    fn grid(n: u32) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        let m = crate::mesh::shapes::grid(n as usize, n as usize, n as f64, n as f64);
        (m.vertices, m.quads)
    }

    fn keys(m: &HalfedgeMesh) -> Vec<[u32; 4]> {
        m.corner_sets()
    }

    #[test]
    fn single_face_hole_is_restored_exactly() {
        let (mut p, q) = grid(4);
        let full = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
        let mut m = full.clone();
        m.remove_face(FaceId(5)).unwrap();
        let r = fill_holes(&mut m, &mut p, &HoleFillConfig::default()).unwrap();
        validate(&m).unwrap();
        assert_eq!(r.quads_by_pattern, [1, 0, 0]);
        assert_eq!(keys(&m), keys(&full));
    }

    #[test]
    fn patch_holes_restore_with_interior_points() {
        // In a 6×6 grid remove the 2×2 block around vertex 16 (it stays as an isolated
        // point) and a vertical pair of faces elsewhere.
        let (mut p, q) = grid(6);
        let full = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
        let mut m = full.clone();
        for f in [7, 8, 13, 14, 27, 33] {
            m.remove_face(FaceId(f)).unwrap();
        }
        let n_before = p.len();
        let r = fill_holes(&mut m, &mut p, &HoleFillConfig::default()).unwrap();
        validate(&m).unwrap();
        assert_eq!(r.vertices_added, 0, "{r:?}");
        assert_eq!(p.len(), n_before);
        assert_eq!(keys(&m), keys(&full), "{r:?}");
    }

    /// A hole the patterns give up on after inventing a vertex is put back as it was
    /// (`undo_partial_fills`); without it the partial fill stays. Here a 2×3 block with
    /// its interior points moved away, and a step bound too small to finish it.
    #[test]
    fn a_partial_fill_that_invented_vertices_is_undone() {
        let (mut p, q) = grid(6);
        let mut m = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
        for f in [7, 8, 9, 13, 14, 15] {
            m.remove_face(FaceId(f)).unwrap();
        }
        for v in [16, 17] {
            p[v] = [50.0, 50.0, 50.0];
        }
        let holed = keys(&m);
        let cfg = HoleFillConfig { max_steps_per_edge: 0, ..HoleFillConfig::default() };
        let (mut m1, mut p1) = (m.clone(), p.clone());
        let r = fill_holes(&mut m1, &mut p1, &cfg).unwrap();
        validate(&m1).unwrap();
        assert_eq!((r.quads_added(), r.vertices_added, r.loops_closed), (0, 0, 0), "{r:?}");
        assert_eq!(keys(&m1), holed);
        assert_eq!((p1.len(), m1.n_vertices()), (p.len(), p.len()));
        let keep = HoleFillConfig { undo_partial_fills: false, ..cfg };
        let r = fill_holes(&mut m, &mut p, &keep).unwrap();
        validate(&m).unwrap();
        assert_eq!(r.loops_closed, 0, "{r:?}");
        assert!(r.vertices_added > 0 && r.quads_added() > 0, "{r:?}");
    }

    #[test]
    fn open_border_is_left_alone() {
        let (mut p, q) = grid(3);
        let mut m = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
        let before = m.clone();
        let r = fill_holes(&mut m, &mut p, &HoleFillConfig::default()).unwrap();
        assert_eq!(r.quads_added(), 0, "{r:?}");
        assert_eq!(m, before);
        // A single quad's border is a 4-loop too: closing it would fold a face onto it.
        let mut p1 = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        let mut m1 = HalfedgeMesh::from_quads(4, &[[0, 1, 2, 3]]).unwrap();
        assert_eq!(fill_holes(&mut m1, &mut p1, &HoleFillConfig::default()).unwrap().quads_added(), 0);
    }

    #[test]
    fn corner_completion_adds_and_smooths_a_vertex() {
        // Remove the 2×2 block around vertex 12 of a 4×4 grid, then drop that vertex's
        // position far away so it cannot be reused: pattern 3 must invent one.
        let (mut p, q) = grid(4);
        let mut m = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
        for f in [5, 6, 9, 10] {
            m.remove_face(FaceId(f)).unwrap();
        }
        p[12] = [50.0, 50.0, 50.0];
        let r = fill_holes(&mut m, &mut p, &HoleFillConfig::default()).unwrap();
        validate(&m).unwrap();
        assert!(m.is_closed() || m.boundary_loops().len() == 1);
        assert_eq!(m.n_faces(), 16, "{r:?}");
        assert_eq!(r.vertices_added, 1);
        let v = p.len() - 1;
        assert!(dist_sq(p[v], [2.0, 2.0, 0.0]) < 1e-18, "{:?}", p[v]);
        assert_eq!(p[12], [50.0, 50.0, 50.0], "existing positions unchanged");
    }

    /// Smoothing never flattens a corner: an added vertex on a border has two
    /// neighbours, and their mean would put it on the line between them (scaled
    /// Jacobian 0); that step is refused. An interior added vertex still moves.
    #[test]
    fn smoothing_keeps_border_vertices_from_flattening_corners() {
        let cfg = HoleFillConfig::default();
        let run = |p: &mut Vec<[f64; 3]>, q: &[[u32; 4]], added: Vec<u32>| {
            let mut m = HalfedgeMesh::from_quads(p.len(), q).unwrap();
            let mut f = Filler {
                mesh: &mut m,
                pos: p,
                cfg: &cfg,
                grid: IsolatedGrid { cell: 1.0, cells: HashMap::new() },
                cos_tol: 0.0,
                report: HoleFillReport::default(),
                added,
                placed: Vec::new(),
            };
            f.smooth();
        };
        // One unit square [c, a, v, b]; v (index 2) was added. Its neighbours' mean is
        // (0.5, 0.5), on the diagonal a–b: the corner at v would be flat.
        let mut p = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
        run(&mut p, &[[0, 1, 2, 3]], vec![2]);
        assert_eq!(p[2], [1.0, 1.0, 0.0], "the border vertex moved");
        assert!(scaled_jacobian(&[p[0], p[1], p[2], p[3]]) > 0.99);
        // The centre of a 2×2 grid, added off centre, goes to the centre.
        let (mut p, q) = grid(2);
        p[4] = [1.3, 0.8, 0.0];
        run(&mut p, &q, vec![4]);
        assert!(dist_sq(p[4], [1.0, 1.0, 0.0]) < 1e-18, "{:?}", p[4]);
    }

    #[test]
    fn mismatched_positions_are_an_error() {
        let (mut p, q) = grid(1);
        let mut m = HalfedgeMesh::from_quads(p.len(), &q).unwrap();
        p.pop();
        assert!(fill_holes(&mut m, &mut p, &HoleFillConfig::default()).is_err());
        p.push([f64::NAN, 0.0, 0.0]);
        assert!(fill_holes(&mut m, &mut p, &HoleFillConfig::default()).is_err());
    }
}
