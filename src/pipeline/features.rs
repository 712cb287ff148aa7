//! Per-candidate input features of the face encoder: the paper's 29-value F_info
//! (DESIGN §2) and a cheap per-candidate context (DESIGN §8: +5 precision / +7.5
//! recall in the reference prototype). Both are row-major, one row per candidate,
//! in the order of `Candidates::quads`.

use crate::pipeline::candidates::{quad_geom, Candidates};

/// Width of an F_info row.
pub const F_INFO_DIM: usize = 29;

/// Width of a context row (columns documented at [`context_features`]).
pub const CONTEXT_DIM: usize = 16;

/// F_info of every candidate, `M × 29` row-major. For the corners p_0..p_3 in the
/// candidate's cyclic order, with e_i = p_{i+1} − p_i and c_i = e_{i−1} × e_i:
///
/// * columns 0–11: (p_i − p_0) / s for i = 0..3 (so columns 0–2 are zero), where s is
///   the mean local spacing (`Candidates::spacing`) of the four corners — scale-free;
/// * column 12: scaled Jacobian, min_i (c_i · n) / (|e_{i−1}||e_i|) with
///   n = normalize((p_2 − p_0) × (p_3 − p_1));
/// * columns 13–16: corner sines |c_i| / (|e_{i−1}||e_i|);
/// * columns 17–28: unit corner normals c_i / |c_i| (x, y, z per corner).
///
/// Degenerate corners (never produced by `generate`) give a zero sine and normal.
pub fn f_info(points: &[[f32; 3]], cands: &Candidates) -> Vec<f32> {
    let mut out = vec![0.0f32; cands.quads.len() * F_INFO_DIM];
    crate::par::for_each_chunk_mut(&mut out, F_INFO_DIM * 256, |ci, chunk| {
        for (r, row) in chunk.chunks_mut(F_INFO_DIM).enumerate() {
            f_info_row(points, &cands.spacing, cands.quads[ci * 256 + r], row);
        }
    });
    out
}

/// Writes the F_info of quad `q` (as [`f_info`]) into `row[..F_INFO_DIM]`, with
/// `spacing` the local spacing per point (`Candidates::spacing`, or one recomputed
/// for moved points by training augmentation).
///
/// # Panics
/// If `row` is shorter than [`F_INFO_DIM`] or a corner of `q` indexes beyond
/// `points` or `spacing` (callers check corners against the cloud first).
pub fn f_info_row(points: &[[f32; 3]], spacing: &[f32], q: [u32; 4], row: &mut [f32]) {
    let p = q.map(|v| points[v as usize]);
    let s = q.iter().map(|&v| spacing[v as usize]).sum::<f32>() / 4.0;
    let inv = if s > 0.0 { 1.0 / s } else { 1.0 };
    for i in 0..4 {
        for a in 0..3 {
            row[3 * i + a] = (p[i][a] - p[0][a]) * inv;
        }
    }
    let g = quad_geom(p);
    row[12] = g.jacobian;
    row[13..17].copy_from_slice(&g.sine);
    for i in 0..4 {
        row[17 + 3 * i..20 + 3 * i].copy_from_slice(&g.corner_normal[i]);
    }
}

/// Expresses an F_info row (`row[..F_INFO_DIM]`, as [`f_info_row`] writes it) in the
/// candidate's own frame instead of the cloud's: z = the diagonal normal
/// normalize((p_2 − p_0) × (p_3 − p_1)), x = the first edge p_1 − p_0 made orthogonal to
/// z, y = z × x. The corner offsets (columns 0–11) and the corner normals (17–28) are
/// rotated into that frame; the Jacobian and the sines are invariant already. The row
/// then no longer changes under a rotation of the cloud, so the network need not learn
/// rotation invariance from augmentation (DESIGN §2 allows stating another choice of
/// coordinates; `ModelConfig::local_frame` selects it). A row whose diagonals or first
/// edge are degenerate (never produced by `generate`) is left as it is.
///
/// # Panics
/// If `row` is shorter than [`F_INFO_DIM`].
pub fn to_local_frame(row: &mut [f32]) {
    let pos: [[f32; 3]; 4] = std::array::from_fn(|i| [row[3 * i], row[3 * i + 1], row[3 * i + 2]]);
    let p = |i: usize| pos[i];
    let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    };
    let unit = |a: [f32; 3]| {
        let l = dot(a, a).sqrt();
        (l > 1e-12 && l.is_finite()).then(|| [a[0] / l, a[1] / l, a[2] / l])
    };
    let Some(z) = unit(cross(sub(p(2), p(0)), sub(p(3), p(1)))) else { return };
    let e = sub(p(1), p(0));
    let ez = dot(e, z);
    let Some(x) = unit([e[0] - ez * z[0], e[1] - ez * z[1], e[2] - ez * z[2]]) else { return };
    let y = cross(z, x);
    let to_frame = |v: [f32; 3]| [dot(v, x), dot(v, y), dot(v, z)];
    for i in 0..4 {
        let v = to_frame(p(i));
        row[3 * i..3 * i + 3].copy_from_slice(&v);
        let c = 17 + 3 * i;
        let v = to_frame([row[c], row[c + 1], row[c + 2]]);
        row[c..c + 3].copy_from_slice(&v);
    }
}

/// Makes a network input row blind to the sign of the point normals (the model's
/// [`crate::pipeline::model::ModelConfig::sign_free_normals`]): each corner normal
/// (F_info columns 17–28) that points against the face normal
/// (p_2 − p_0) × (p_3 − p_1) is negated, and, when the row carries the context columns,
/// their corner-agreement dots (10–13 of [`context_features`]) become absolute values.
/// Point normals get their signs by propagation, which leaves orientation seams (on
/// `train/`, 11–18% of the true faces of amo, armadillo, botijo, feline and monkey have a
/// corner whose normal points against the face; `examples/coverage_diagnostics.rs
/// agreement`); after this a corner across a seam reads like any other.
/// Works in either frame (the face normal is taken from the row's own corners).
///
/// # Panics
/// If `row` is shorter than [`F_INFO_DIM`] (or than `F_INFO_DIM + CONTEXT_DIM` with
/// `with_context`).
pub fn sign_free_normals(row: &mut [f32], with_context: bool) {
    use crate::pipeline::candidates::{cross, sub};
    let p = |i: usize| [row[3 * i], row[3 * i + 1], row[3 * i + 2]];
    let n = cross(sub(p(2), p(0)), sub(p(3), p(1)));
    for i in 0..4 {
        let c = 17 + 3 * i;
        if row[c] * n[0] + row[c + 1] * n[1] + row[c + 2] * n[2] < 0.0 {
            for v in &mut row[c..c + 3] {
                *v = -*v;
            }
        }
    }
    if with_context {
        for v in &mut row[F_INFO_DIM + 10..F_INFO_DIM + 14] {
            *v = v.abs();
        }
    }
}

/// Undirected edge key.
#[inline]
fn edge_key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    ((lo as u64) << 32) | hi as u64
}

/// Context of every candidate, `M × CONTEXT_DIM` row-major. Columns:
///
/// * 0–3: how many *other* candidates contain edge i (p_i, p_{i+1}) — a true edge has
///   few competitors on each side;
/// * 4: the candidate's best 0-based rank among the lists of the points that kept it
///   (`Candidates::rank`);
/// * 5: how many of its corners kept it (`Candidates::proposers`, 1–4);
/// * 6–9: length of edge i over the mean local spacing of its two endpoints;
/// * 10–13: dot product of corner i's PCA normal (`Candidates::normals`) with the face
///   normal n = normalize((p_2 − p_0) × (p_3 − p_1)) — agreement with the surface;
/// * 14: the inside count of the ranking (`Candidates::inside`): other points
///   projecting into the quad near its plane;
/// * 15: the ranking score (`Candidates::score`, lower is better).
pub fn context_features(points: &[[f32; 3]], cands: &Candidates) -> Vec<f32> {
    let edges = sorted_edges(cands);
    let mut out = vec![0.0f32; cands.quads.len() * CONTEXT_DIM];
    crate::par::for_each_chunk_mut(&mut out, CONTEXT_DIM * 256, |ci, chunk| {
        for (r, row) in chunk.chunks_mut(CONTEXT_DIM).enumerate() {
            context_row(points, cands, &edges, ci * 256 + r, row);
        }
    });
    out
}

/// Every candidate's four edges as [`edge_key`]s, sorted (what [`context_row`] counts
/// in).
fn sorted_edges(cands: &Candidates) -> Vec<u64> {
    let mut edges: Vec<u64> = Vec::with_capacity(cands.quads.len() * 4);
    for q in &cands.quads {
        for i in 0..4 {
            edges.push(edge_key(q[i], q[(i + 1) % 4]));
        }
    }
    edges.sort_unstable();
    edges
}

/// The [`context_features`] row of candidate `c` into `row[..CONTEXT_DIM]`, `edges` from
/// [`sorted_edges`].
fn context_row(points: &[[f32; 3]], cands: &Candidates, edges: &[u64], c: usize, row: &mut [f32]) {
    let count = |k: u64| edges.partition_point(|&e| e <= k) - edges.partition_point(|&e| e < k);
    let q = cands.quads[c];
    for i in 0..4 {
        row[i] = (count(edge_key(q[i], q[(i + 1) % 4])) - 1) as f32;
    }
    context_geometry_row(points, &cands.spacing, &cands.normals, q, row);
    row[4] = cands.rank[c] as f32;
    row[5] = cands.proposers[c] as f32;
    row[14] = cands.inside[c] as f32;
    row[15] = cands.score[c];
}

/// The context columns of quad `q` that depend on the point positions (6–13 of
/// [`context_features`]: edge lengths over the local spacing and the agreement of the
/// corners' normals with the face normal), written into `row[6..14]`; the other
/// columns (edge sharing, rank, proposers, inside count, score) describe candidate
/// generation and are left alone. `spacing` and `normals` are per point
/// (`Candidates::spacing` and `Candidates::normals`, or recomputed for moved points).
///
/// # Panics
/// If `row` is shorter than 14 or a corner of `q` indexes beyond `points`, `spacing`
/// or `normals`.
pub fn context_geometry_row(
    points: &[[f32; 3]],
    spacing: &[f32],
    normals: &[[f32; 3]],
    q: [u32; 4],
    row: &mut [f32],
) {
    let g = quad_geom(q.map(|v| points[v as usize]));
    for i in 0..4 {
        let (a, b) = (q[i], q[(i + 1) % 4]);
        let s = 0.5 * (spacing[a as usize] + spacing[b as usize]);
        row[6 + i] = if s > 0.0 { g.len[i] / s } else { 0.0 };
        let nv = normals[q[i] as usize];
        row[10 + i] = nv[0] * g.normal[0] + nv[1] * g.normal[1] + nv[2] * g.normal[2];
    }
}

/// The network input rows for `cands`: F_info, then (if `with_context`) the context
/// features, `F_INFO_DIM (+ CONTEXT_DIM)` values per candidate.
pub fn face_input(points: &[[f32; 3]], cands: &Candidates, with_context: bool) -> Vec<f32> {
    FaceRows::new(points, cands, with_context).rows(0, cands.len())
}

/// The rows of [`face_input`] one candidate at a time, for a caller that needs only some
/// of them at once (`reconstruct` scores the candidates in chunks and makes each
/// chunk's rows as it goes: at millions of candidates the whole matrix was the
/// largest buffer of the run).
pub struct FaceRows<'a> {
    points: &'a [[f32; 3]],
    cands: &'a Candidates,
    /// [`sorted_edges`] with context, empty without.
    edges: Vec<u64>,
    with_context: bool,
}

impl<'a> FaceRows<'a> {
    /// The rows of `cands`' candidates (corners indexing `points`), with the context
    /// columns when `with_context`.
    pub fn new(points: &'a [[f32; 3]], cands: &'a Candidates, with_context: bool) -> FaceRows<'a> {
        let edges = if with_context { sorted_edges(cands) } else { Vec::new() };
        FaceRows { points, cands, edges, with_context }
    }

    /// Values per row: `F_INFO_DIM`, plus `CONTEXT_DIM` with context.
    pub fn dim(&self) -> usize {
        F_INFO_DIM + if self.with_context { CONTEXT_DIM } else { 0 }
    }

    /// Number of rows (candidates).
    pub fn len(&self) -> usize {
        self.cands.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.cands.is_empty()
    }

    /// The candidates the rows describe, in row order.
    pub fn quads(&self) -> &[[u32; 4]] {
        &self.cands.quads
    }

    /// The rows of candidates `lo..hi`, row-major (made in parallel).
    ///
    /// # Panics
    /// If `lo > hi` or `hi` is beyond the last candidate.
    pub fn rows(&self, lo: usize, hi: usize) -> Vec<f32> {
        let dim = self.dim();
        let mut out = vec![0.0f32; (hi - lo) * dim];
        crate::par::for_each_chunk_mut(&mut out, dim * 256, |ci, chunk| {
            for (r, row) in chunk.chunks_mut(dim).enumerate() {
                self.fill(lo + ci * 256 + r, row);
            }
        });
        out
    }

    /// Candidate `c`'s row into `row[..self.dim()]`.
    ///
    /// # Panics
    /// If `c` is not a candidate or `row` is shorter than [`FaceRows::dim`].
    pub fn fill(&self, c: usize, row: &mut [f32]) {
        let (fi, ctx) = row.split_at_mut(F_INFO_DIM);
        f_info_row(self.points, &self.cands.spacing, self.cands.quads[c], fi);
        if self.with_context {
            context_row(self.points, self.cands, &self.edges, c, ctx);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::candidates::{generate, CandidateConfig};

    /// The network input with context is F_info's row followed by the context row,
    /// candidate by candidate, bit for bit (it is written in place, not concatenated),
    /// over more candidates than one chunk of rows.
    #[test]
    fn face_input_interleaves_f_info_and_the_context_rows() {
        let mut rng = crate::rng::Rng::new(5);
        let pts: Vec<[f32; 3]> = (0..400)
            .map(|i| {
                let (x, y) = ((i % 20) as f32, (i / 20) as f32);
                [x + 0.2 * rng.f32(), y + 0.2 * rng.f32(), 0.3 * (0.5 * x).sin() + 0.05 * rng.f32()]
            })
            .collect();
        let c = generate(&pts, &CandidateConfig::default()).unwrap();
        assert!(c.len() > 512, "{} candidates: one chunk only", c.len());
        let (fi, ctx) = (f_info(&pts, &c), context_features(&pts, &c));
        let want: Vec<u32> = (0..c.len())
            .flat_map(|i| {
                fi[i * F_INFO_DIM..(i + 1) * F_INFO_DIM]
                    .iter()
                    .chain(&ctx[i * CONTEXT_DIM..(i + 1) * CONTEXT_DIM])
            })
            .map(|v| v.to_bits())
            .collect();
        let got: Vec<u32> = face_input(&pts, &c, true).iter().map(|v| v.to_bits()).collect();
        assert_eq!(got, want);
        assert_eq!(face_input(&pts, &c, false), fi);
    }

    #[test]
    fn square_has_textbook_features() {
        // A 6 × 6 unit grid: interior cells are unit squares.
        let mut pts = Vec::new();
        for y in 0..6 {
            for x in 0..6 {
                pts.push([x as f32 + 0.01 * ((x * 7 + y * 3) % 5) as f32, y as f32, 0.0]);
            }
        }
        let c = generate(&pts, &CandidateConfig::default()).unwrap();
        let f = f_info(&pts, &c);
        let ctx = context_features(&pts, &c);
        assert_eq!(f.len(), c.len() * F_INFO_DIM);
        assert_eq!(ctx.len(), c.len() * CONTEXT_DIM);
        // Find the cell with corners 14, 15, 21, 20 (all spacings ≈ 1).
        let want = [14u32, 15, 20, 21];
        let ci = c
            .quads
            .iter()
            .position(|q| {
                let mut k = *q;
                k.sort_unstable();
                k == want
            })
            .expect("cell present");
        let row = &f[ci * F_INFO_DIM..(ci + 1) * F_INFO_DIM];
        assert!(row[..3].iter().all(|&x| x == 0.0));
        assert!(row[12] > 0.99, "jacobian {}", row[12]);
        assert!(row[13..17].iter().all(|&s| s > 0.99));
        for i in 0..4 {
            let n = &row[17 + 3 * i..20 + 3 * i];
            assert!((n[2].abs() - 1.0).abs() < 1e-4);
            // Counter-clockwise about the (oriented) point normal.
            assert!(n[2] * c.normals[14][2] > 0.0);
        }
        let crow = &ctx[ci * CONTEXT_DIM..(ci + 1) * CONTEXT_DIM];
        assert!(crow[6..10].iter().all(|&l| (l - 1.0).abs() < 0.05), "{crow:?}");
        assert!(crow[10..14].iter().all(|&d| d > 0.99));
        assert!(crow[5] >= 1.0 && crow[5] <= 4.0);
    }
}
