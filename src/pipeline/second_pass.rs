//! The second pass of [`crate::pipeline::reconstruct`] (session 26; not in the paper):
//! which points of the cloud the first pass's mesh says are noise.
//!
//! A point no output face uses, lying inside an output face (projecting into it, close
//! to its plane), sits where the surface is already tiled: a true vertex there would be
//! a corner of the faces around it, so it is taken for a noise point. Noise points
//! displace true faces (a candidate with a noise corner can outscore the true face, and
//! noise points fill the k nearest neighbours the candidates are proposed from); the
//! second pass proposes and scores the candidates again without them. Points in holes
//! (no face over them) are kept: they may be the true vertices the first pass missed.
//! The faces are those of the first pass's finished mesh, so a hole the post-process
//! filled or closed covers the points in it too.

use crate::math::{cross, dot, norm, sub};
use crate::mesh::hole_fill::quad_normal;

/// The points among `positions[..n_points]` that no face of `quads` uses and that lie
/// inside some face: their projection onto the face's plane (the plane through its
/// first corner whose normal is the cross product of its diagonals) falls in the convex
/// hull of its corners projected onto that plane (the union of the four triangles of
/// three corners each, boundary included), and their distance from that plane is at
/// most `tau` times the face's mean edge length. Faces with a zero or non-finite normal
/// or slack contain nothing, and so does every face for a `tau` that is negative or not
/// finite. Positions past `n_points` (vertices the hole filling added) are never marked.
///
/// # Panics
/// If a face index is out of range of `positions`.
pub fn covered_unused(positions: &[[f64; 3]], n_points: usize, quads: &[[u32; 4]], tau: f64) -> Vec<bool> {
    covered_unused_by(positions, n_points, quads, quads, tau)
}

/// [`covered_unused`] with the faces that cover apart from those that use: the points
/// no face of `quads` uses that lie inside a face of `covering` (any faces, e.g. a
/// subset of `quads`).
///
/// # Panics
/// If a face index is out of range of `positions`.
pub fn covered_unused_by(
    positions: &[[f64; 3]],
    n_points: usize,
    quads: &[[u32; 4]],
    covering: &[[u32; 4]],
    tau: f64,
) -> Vec<bool> {
    let n_points = n_points.min(positions.len());
    let mut used = vec![false; positions.len()];
    for q in quads {
        q.iter().for_each(|&v| used[v as usize] = true);
    }
    let mut out = vec![false; n_points];
    if !(tau >= 0.0 && tau.is_finite()) {
        return out;
    }
    let faces: Vec<FacePlane> = covering.iter().filter_map(|q| FacePlane::new(positions, q, tau)).collect();
    if faces.is_empty() {
        return out;
    }
    // Faces into a uniform grid of their boxes; a point is tested against the faces
    // of its own cell, and against the few faces too large for the grid.
    let grid = Grid::new(&faces);
    for (i, o) in out.iter_mut().enumerate() {
        if used[i] {
            continue;
        }
        let p = positions[i];
        let in_cell = grid.cell_of(p).is_some_and(|c| grid.faces_in(c).iter().any(|&f| faces[f].contains(p)));
        *o = in_cell || grid.big.iter().any(|&f| faces[f].contains(p));
    }
    out
}

/// One face, ready for point-in-face tests.
struct FacePlane {
    corners: [[f64; 3]; 4],
    normal: [f64; 3],
    slack: f64,
    lo: [f64; 3],
    hi: [f64; 3],
}

impl FacePlane {
    fn new(pos: &[[f64; 3]], q: &[u32; 4], tau: f64) -> Option<FacePlane> {
        let c = q.map(|v| pos[v as usize]);
        let normal = quad_normal(&c)?;
        let edge = (0..4).map(|k| norm(sub(c[k], c[(k + 1) % 4]))).sum::<f64>() / 4.0;
        let slack = tau * edge;
        // The region a contained point lies in: the quad projected onto its plane
        // (through the first corner), thickened by the slack both ways along the
        // normal. Its box is that of those eight points, grown by a rounding margin.
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &c {
            let h = dot(sub(*p, c[0]), normal);
            for t in [-slack, slack] {
                for a in 0..3 {
                    let x = p[a] + (t - h) * normal[a];
                    lo[a] = lo[a].min(x);
                    hi[a] = hi[a].max(x);
                }
            }
        }
        // Rounding: relative to the face's size and to its coordinates' magnitude.
        let magnitude = c.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        let margin = 1e-9 * (0..3).map(|a| hi[a] - lo[a]).fold(edge.max(magnitude), f64::max);
        for a in 0..3 {
            lo[a] -= margin;
            hi[a] += margin;
        }
        if !(slack.is_finite() && lo.iter().chain(&hi).all(|x| x.is_finite())) {
            return None;
        }
        Some(FacePlane { corners: c, normal, slack, lo, hi })
    }

    fn contains(&self, p: [f64; 3]) -> bool {
        let d = dot(sub(p, self.corners[0]), self.normal);
        if d.abs() > self.slack {
            return false;
        }
        let proj = sub(p, self.normal.map(|x| x * d));
        let c = &self.corners;
        [[0, 1, 2], [0, 2, 3], [0, 1, 3], [1, 2, 3]]
            .iter()
            .any(|t| in_triangle(proj, c[t[0]], c[t[1]], c[t[2]], self.normal))
    }
}

/// `p` (in the plane) inside the triangle, boundary included, for either winding of the
/// triangle about `n`.
fn in_triangle(p: [f64; 3], a: [f64; 3], b: [f64; 3], c: [f64; 3], n: [f64; 3]) -> bool {
    let s = [
        dot(cross(sub(b, a), sub(p, a)), n),
        dot(cross(sub(c, b), sub(p, b)), n),
        dot(cross(sub(a, c), sub(p, c)), n),
    ];
    s.iter().all(|&x| x >= 0.0) || s.iter().all(|&x| x <= 0.0)
}

/// A uniform grid over the faces' boxes: about four cells per face at most, each face
/// listed in every cell its box touches, except faces whose box touches more than
/// [`MAX_CELLS_PER_FACE`] cells, which are kept apart (`big`) and tested for every
/// point: at most that many entries per face in all.
struct Grid {
    lo: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    start: Vec<usize>,
    items: Vec<usize>,
    big: Vec<usize>,
}

/// See [`Grid`].
const MAX_CELLS_PER_FACE: usize = 64;

impl Grid {
    /// `faces` must not be empty, and their boxes finite ([`FacePlane::new`]).
    fn new(faces: &[FacePlane]) -> Grid {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut sizes: Vec<f64> = Vec::with_capacity(faces.len());
        for f in faces {
            for a in 0..3 {
                lo[a] = lo[a].min(f.lo[a]);
                hi[a] = hi[a].max(f.hi[a]);
            }
            sizes.push((0..3).map(|a| f.hi[a] - f.lo[a]).fold(0.0, f64::max));
        }
        let mid = sizes.len() / 2;
        let typical = *sizes.select_nth_unstable_by(mid, f64::total_cmp).1;
        let extent: Vec<f64> = (0..3).map(|a| (hi[a] - lo[a]).max(0.0)).collect();
        // Cells about the size of a typical face, but no more than 4 per face in all.
        // The extents are finite, so doubling ends (a cell as large as the largest
        // extent gives one cell).
        let budget = (4 * faces.len()).max(1) as f64;
        let widest = extent.iter().fold(0.0f64, |m, &e| m.max(e));
        let mut cell = typical.max(f64::MIN_POSITIVE);
        let count = |cell: f64| extent.iter().map(|e| (e / cell).floor() + 1.0).product::<f64>();
        while count(cell) > budget && cell < widest {
            cell *= 2.0;
        }
        let dims = [0, 1, 2].map(|a| (extent[a] / cell).floor() as usize + 1);
        let index = |c: [usize; 3]| (c[2] * dims[1] + c[1]) * dims[0] + c[0];
        let range = |f: &FacePlane, a: usize| {
            let clamp = |x: f64| (((x - lo[a]) / cell).floor().max(0.0) as usize).min(dims[a] - 1);
            (clamp(f.lo[a]), clamp(f.hi[a]))
        };
        let cells_of = |f: &FacePlane| -> Vec<usize> {
            let (x0, x1) = range(f, 0);
            let (y0, y1) = range(f, 1);
            let (z0, z1) = range(f, 2);
            if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) > MAX_CELLS_PER_FACE {
                return Vec::new();
            }
            let mut v = Vec::new();
            for z in z0..=z1 {
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        v.push(index([x, y, z]));
                    }
                }
            }
            v
        };
        let ncells = dims.iter().product::<usize>();
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        let mut big = Vec::new();
        for (k, f) in faces.iter().enumerate() {
            let cells = cells_of(f);
            if cells.is_empty() {
                big.push(k);
            }
            pairs.extend(cells.into_iter().map(|c| (c, k)));
        }
        let mut start = vec![0usize; ncells + 1];
        pairs.iter().for_each(|&(c, _)| start[c + 1] += 1);
        for c in 0..ncells {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut items = vec![0usize; pairs.len()];
        for &(c, k) in &pairs {
            items[fill[c]] = k;
            fill[c] += 1;
        }
        Grid { lo, cell, dims, start, items, big }
    }

    fn cell_of(&self, p: [f64; 3]) -> Option<usize> {
        let mut c = [0usize; 3];
        for a in 0..3 {
            let x = ((p[a] - self.lo[a]) / self.cell).floor();
            if !(x >= 0.0 && x < self.dims[a] as f64) {
                return None;
            }
            c[a] = x as usize;
        }
        Some((c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0])
    }

    fn faces_in(&self, c: usize) -> &[usize] {
        &self.items[self.start[c]..self.start[c + 1]]
    }
}

/// Values per point that [`learned_noise`] reads ([`point_features`]).
pub const NOISE_FEATURES: usize = 16;

/// The learned test's weights, in [`point_features`]' column order (the last multiplies
/// the constant column). Session 35: a logistic regression (Newton, L2 10⁻³) fitted on
/// 787,489 points of clouds none of the judge's twelve meshes are in (40 random synthetic
/// shapes, the other 38 `train/` meshes, their chord-collapsed and jittered copies),
/// the values read with a held-out judge model (docs/EXPERIMENTS.md, "Session 35").
pub const LEARNED_WEIGHTS: [f32; NOISE_FEATURES] = [
    -0.335959, 0.919518, 0.91421, -1.92306, -1.57704, 0.0103905, -0.608237, -0.996397, -0.126796, -0.245259,
    -0.143231, 0.555859, -0.143185, 1.37065, 1.02701, -0.558313,
];

/// A point is noise under the learned test when its weighted sum is above this (0: a
/// probability above 0.5).
pub const LEARNED_CUTOFF: f32 = 0.0;

/// Candidates below this probability are not read by the "held strictly inside" column.
const SPAN_MIN_PROB: f32 = 0.05;

/// What the first pass says about each of the distinct points `positions[..u]`, for the
/// learned noise test. `local` are the same points in f32 (the candidates' frame),
/// `cands` / `probs` the first pass's candidates and probabilities, `mesh_quads` its
/// finished mesh (corners may be vertices the hole filling added, past `u`),
/// `believed_mesh` those of its faces the classifier predicted real. Columns:
///
/// | # | value |
/// |---|---|
/// | 0 | 1 when a face of the mesh uses the point |
/// | 1 | 1 when no face uses it and a believed face holds it ([`covered_unused_by`], the default rule) |
/// | 2 | 1 when no face uses it and any face holds it |
/// | 3, 4, 5 | the largest probability of the candidates it is a corner of, their sum / 4, their count / 10 |
/// | 6, 7 | how many faces of the mesh, and how many believed faces, use it, / 4 |
/// | 8, 9 | 1 when a candidate above `threshold`, above 0.9, holds it (a candidate's own corners lie on its boundary, where the test may go either way) |
/// | 10, 11 | the distance to its nearest and second-nearest other point over the mean distance of its 9 nearest |
/// | 12 | the mean probability of the candidates it is a corner of (0 for none) |
/// | 13 | the largest probability (at least 0.05) of a candidate holding it strictly inside (not as a corner) |
/// | 14 | 1 when a face of the mesh holds it strictly inside |
/// | 15 | 1 (the constant) |
///
/// "Holds": the point lies within `tau` × the face's mean edge length of its plane and
/// projects into it ([`covered_unused`]).
///
/// # Panics
/// If a candidate's or face's index is out of range of `positions`, `u` exceeds
/// `positions.len()` or `local.len()`, or `probs` is shorter than `cands`.
#[allow(clippy::too_many_arguments)]
pub fn point_features(
    local: &[[f32; 3]],
    positions: &[[f64; 3]],
    u: usize,
    cands: &[[u32; 4]],
    probs: &[f32],
    mesh_quads: &[[u32; 4]],
    believed_mesh: &[[u32; 4]],
    threshold: f32,
    tau: f64,
) -> Vec<[f32; NOISE_FEATURES]> {
    let rule = covered_unused_by(positions, u, mesh_quads, believed_mesh, tau);
    let any_face = covered_unused_by(positions, u, mesh_quads, mesh_quads, tau);
    let above = |t: f32| -> Vec<[u32; 4]> {
        cands.iter().zip(probs).filter(|(_, &p)| p > t).map(|(q, _)| *q).collect()
    };
    let in_above = covered_unused_by(positions, u, &[], &above(threshold), tau);
    let in_above9 = covered_unused_by(positions, u, &[], &above(0.9), tau);
    let (mut maxp, mut sump, mut count) = (vec![0f32; u], vec![0f32; u], vec![0f32; u]);
    for (q, &p) in cands.iter().zip(probs) {
        for &v in q.iter().filter(|&&v| (v as usize) < u) {
            let v = v as usize;
            maxp[v] = maxp[v].max(p);
            sump[v] += p;
            count[v] += 1.0;
        }
    }
    let degree = |quads: &[[u32; 4]]| {
        let mut d = vec![0f32; u];
        quads.iter().flatten().filter(|&&v| (v as usize) < u).for_each(|&v| d[v as usize] += 1.0);
        d
    };
    let (mesh_degree, believed_degree) = (degree(mesh_quads), degree(believed_mesh));
    // One tree for the neighbour columns and the "strictly inside" searches; the rows
    // are `candidates::knn_table(&local[..u], 9)`'s (the point itself, then 9 others).
    let tree = crate::spatial::kdtree::KdTree::build(&local[..u]);
    let knn = tree.knn_batch(&local[..u], 9.min(u.saturating_sub(1)) + 1);
    let span = strictly_inside(&tree, positions, u, cands, probs, tau);
    let span_mesh = strictly_inside(&tree, positions, u, mesh_quads, &vec![1.0; mesh_quads.len()], tau);
    (0..u)
        .map(|i| {
            // The first neighbour is the point itself (the points are distinct).
            let ds: Vec<f32> = knn.row(i).1.iter().skip(1).map(|x| x.sqrt()).collect();
            let mean = if ds.is_empty() { 1.0 } else { ds.iter().sum::<f32>() / ds.len() as f32 };
            let near = |k: usize| ds.get(k).copied().unwrap_or(0.0) / mean.max(1e-12);
            let flag = |b: bool| b as u8 as f32;
            [
                flag(mesh_degree[i] > 0.0),
                flag(rule[i]),
                flag(any_face[i]),
                maxp[i],
                sump[i] / 4.0,
                count[i] / 10.0,
                mesh_degree[i] / 4.0,
                believed_degree[i] / 4.0,
                flag(in_above[i]),
                flag(in_above9[i]),
                near(0),
                near(1),
                if count[i] > 0.0 { sump[i] / count[i] } else { 0.0 },
                span[i],
                span_mesh[i],
                1.0,
            ]
        })
        .collect()
}

/// For each of the points `positions[..u]` (indexed by `tree`, built over them in f32),
/// the largest probability (at least [`SPAN_MIN_PROB`]) of a quad that holds it strictly
/// inside: not as a corner, within `tau` × the quad's mean edge length of its plane,
/// projecting into it. 0 where none does.
fn strictly_inside(
    tree: &crate::spatial::kdtree::KdTree,
    positions: &[[f64; 3]],
    u: usize,
    quads: &[[u32; 4]],
    probs: &[f32],
    tau: f64,
) -> Vec<f32> {
    let mut best = vec![0f32; u];
    let mut near = Vec::new();
    for (q, &p) in quads.iter().zip(probs) {
        if p < SPAN_MIN_PROB {
            continue;
        }
        let Some(face) = FacePlane::new(positions, q, tau) else { continue };
        let c = q.map(|v| positions[v as usize]);
        let centre = [0, 1, 2].map(|a| (c[0][a] + c[1][a] + c[2][a] + c[3][a]) / 4.0);
        let r2 = c.iter().map(|x| dot(sub(*x, centre), sub(*x, centre))).fold(0.0, f64::max);
        // A point the quad holds projects into the corners' hull (within r of the
        // centre) and lies within the slack of the plane; the margin covers f32 rounding.
        let reach = ((r2.sqrt() + face.slack) * 1.0001).powi(2) as f32;
        tree.within_radius(centre.map(|x| x as f32), reach, &mut near);
        for n in &near {
            let i = n.index as usize;
            if i < u && !q.contains(&(i as u32)) && p > best[i] && face.contains(positions[i]) {
                best[i] = p;
            }
        }
    }
    best
}

/// The learned test: which points are noise, from their [`point_features`]
/// ([`LEARNED_WEIGHTS`], [`LEARNED_CUTOFF`]).
pub fn learned_noise(features: &[[f32; NOISE_FEATURES]]) -> Vec<bool> {
    features
        .iter()
        .map(|x| x.iter().zip(&LEARNED_WEIGHTS).map(|(a, b)| a * b).sum::<f32>() > LEARNED_CUTOFF)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> (Vec<[f64; 3]>, Vec<[u32; 4]>) {
        let mut p = Vec::new();
        for y in 0..n {
            for x in 0..n {
                p.push([x as f64, y as f64, 0.0]);
            }
        }
        let mut q = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let v = (y * n + x) as u32;
                q.push([v, v + 1, v + 1 + n as u32, v + n as u32]);
            }
        }
        (p, q)
    }

    #[test]
    fn a_point_over_a_face_is_covered_and_one_in_a_hole_or_off_the_plane_is_not() {
        let (mut p, mut q) = grid(4);
        // Take out the middle face: a hole over (1..2, 1..2).
        q.retain(|f| f[0] != 5);
        let n = p.len() as u32;
        p.push([0.5, 0.5, 0.05]); // over face 0, near its plane
        p.push([1.5, 1.5, 0.0]); // in the hole
        p.push([2.5, 0.5, 0.4]); // over a face, too far off its plane
        p.push([7.0, 7.0, 0.0]); // outside everything
        let c = covered_unused(&p, p.len(), &q, 0.25);
        assert_eq!(&c[n as usize..], &[true, false, false, false]);
        // Used points are never marked.
        assert!(c[..n as usize].iter().all(|&x| !x));
        // Points past n_points are not looked at.
        assert_eq!(covered_unused(&p, n as usize, &q, 0.25).len(), n as usize);
    }
}
