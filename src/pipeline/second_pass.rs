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
