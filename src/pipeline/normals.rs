//! Point normals from the points alone: PCA of each point's k nearest neighbours
//! (the eigenvector of the smallest covariance eigenvalue), then a consistent sign by
//! propagation over the kNN graph (Hoppe et al. 1992): a minimum spanning tree on the
//! weight 1 − |n_i·n_j|, grown by Prim from one root per connected component, so the
//! sign travels along the smoothest paths first.
//!
//! Outward rule, per connected component: after propagating the signs from a root (the
//! point farthest from the component's centroid, ties broken by coordinates), the whole
//! component is flipped if Σ n_v · (p_v − centroid) < 0, so closed surfaces face out
//! and open ones take the side their bulk bulges to, whatever the pose; when the sum is
//! near zero (a flat patch) the root normal's largest-magnitude coordinate is made
//! positive instead.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use crate::spatial::kdtree::KnnTable;

/// Number of neighbours per point stored in `knn` (robust to a table whose `k`
/// field disagrees with its length).
fn row_len(points: usize, knn: &KnnTable) -> usize {
    knn.indices.len().checked_div(points).unwrap_or(0)
}

/// Unit normal of each point by PCA of its row of `knn` (the row may include the
/// point itself; duplicates are harmless). Degenerate neighbourhoods (fewer than 3
/// distinct points, collinear) still get a unit vector, perpendicular to the line
/// when there is one, else `[0, 0, 1]`. The sign is arbitrary; see [`orient_normals`].
///
/// # Panics
/// Never for finite input; `knn` must hold rows for every point with indices
/// `< points.len()` (an internal invariant of the pipeline: it is built from `points`).
pub fn estimate_normals(points: &[[f32; 3]], knn: &KnnTable) -> Vec<[f32; 3]> {
    let k = row_len(points.len(), knn);
    let whole = k >= points.len();
    crate::par::map(points.len(), |i| {
        let row = &knn.indices[i * k..(i + 1) * k];
        pca_normal(points, points[i], row, whole)
    })
}

/// A neighbourhood whose smallest covariance eigenvalue is at least this share of its
/// largest is nearly isotropic: no plane fits it, and the PCA step takes the
/// direction from the neighbourhood's mean to the point instead (session 37; 0.8 was
/// chosen before any result, and the held-out judge sets' reconstructions did not
/// change: real surfaces' neighbourhoods are far flatter).
pub const ISOTROPIC_RATIO: f64 = 0.8;

/// Where the neighbourhood is the whole cloud (a cloud of at
/// most `normal_k` + 1 points), the offset from the mean is the normal also when the
/// smallest covariance eigenvalue is at least this share of the middle one: a tiny
/// closed shape, such as a box's 8 corners (1 × 1 × 3 or 1 × 2 × 3 boxes gave 2 and 0
/// faces), whose plane fit is an axis of the box (session 37, arm TINY). On larger
/// clouds the same rule changed real neighbourhoods and failed its judge (arms ROD and
/// VOL, docs/EXPERIMENTS.md).
pub const WHOLE_CLOUD_RATIO: f64 = 0.2;

/// ... and the middle eigenvalue at least this share of the largest: points on one line
/// have no outward offset either.
pub const NOT_A_LINE_RATIO: f64 = 0.01;

/// The offset from the neighbourhood's mean must exceed this share of the
/// neighbourhood's spread (the square root of its summed squared deviations from the mean) for
/// [`ISOTROPIC_RATIO`]'s rule: a point at the centre of a symmetric blob has no
/// outward direction either, and keeps the PCA normal.
pub const ISOTROPIC_MIN_OFFSET: f64 = 1e-3;

/// PCA normal of the point `center` and the points `row` index (in f64: the
/// covariance of a tight neighbourhood loses digits in f32). A nearly isotropic
/// neighbourhood ([`ISOTROPIC_RATIO`]), or a volumetric one that is the whole cloud
/// (`whole`; [`WHOLE_CLOUD_RATIO`]), gives the unit offset of the point from the
/// neighbourhood's mean instead, when that is not negligible ([`ISOTROPIC_MIN_OFFSET`]).
pub(crate) fn pca_normal(points: &[[f32; 3]], center: [f32; 3], row: &[u32], whole: bool) -> [f32; 3] {
    let mut mean = [0.0f64; 3];
    let mut n = 0.0f64;
    for &j in row {
        let p = points[j as usize];
        for a in 0..3 {
            mean[a] += (p[a] - center[a]) as f64;
        }
        n += 1.0;
    }
    if n < 3.0 {
        return [0.0, 0.0, 1.0];
    }
    for m in &mut mean {
        *m /= n;
    }
    let mut c = [[0.0f64; 3]; 3];
    for &j in row {
        let p = points[j as usize];
        let d = [
            (p[0] - center[0]) as f64 - mean[0],
            (p[1] - center[1]) as f64 - mean[1],
            (p[2] - center[2]) as f64 - mean[2],
        ];
        for a in 0..3 {
            for b in a..3 {
                c[a][b] += d[a] * d[b];
            }
        }
    }
    let m = nalgebra::Matrix3::new(
        c[0][0], c[0][1], c[0][2], c[0][1], c[1][1], c[1][2], c[0][2], c[1][2], c[2][2],
    );
    let trace = c[0][0] + c[1][1] + c[2][2];
    if trace.is_nan() || trace <= 0.0 || !trace.is_finite() {
        return [0.0, 0.0, 1.0];
    }
    let eig = nalgebra::SymmetricEigen::new(m);
    let mut imin = 0;
    for a in 1..3 {
        if eig.eigenvalues[a] < eig.eigenvalues[imin] {
            imin = a;
        }
    }
    // No plane to fit (session 37): the 8 corners of a cube are each other's whole
    // neighbourhood, isotropic, and the eigenvector the solver returns was arbitrary;
    // 4 of the 6 candidates then crossed the inside. The offset from the
    // neighbourhood's mean points out of a convex corner.
    let mut l = [eig.eigenvalues[0], eig.eigenvalues[1], eig.eigenvalues[2]];
    l.sort_by(f64::total_cmp);
    let no_plane = l[0] >= ISOTROPIC_RATIO * l[2]
        || (whole && l[0] >= WHOLE_CLOUD_RATIO * l[1] && l[1] >= NOT_A_LINE_RATIO * l[2]);
    let off = (mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2]).sqrt();
    if no_plane && off > ISOTROPIC_MIN_OFFSET * trace.sqrt() {
        return [(-mean[0] / off) as f32, (-mean[1] / off) as f32, (-mean[2] / off) as f32];
    }
    let v = eig.eigenvectors.column(imin);
    let len = v.norm();
    if len.is_nan() || len <= 0.0 || !len.is_finite() {
        return [0.0, 0.0, 1.0];
    }
    [(v[0] / len) as f32, (v[1] / len) as f32, (v[2] / len) as f32]
}

#[inline]
fn dot3(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Symmetrised kNN graph in compressed rows (self-loops dropped, duplicates removed).
fn symmetric_graph(n: usize, knn: &KnnTable) -> (Vec<usize>, Vec<u32>) {
    let k = row_len(n, knn);
    let mut deg = vec![0usize; n + 1];
    for i in 0..n {
        for &j in &knn.indices[i * k..(i + 1) * k] {
            if j as usize != i {
                deg[i] += 1;
                deg[j as usize] += 1;
            }
        }
    }
    let mut start = vec![0usize; n + 1];
    for i in 0..n {
        start[i + 1] = start[i] + deg[i];
    }
    let mut fill = start.clone();
    let mut adj = vec![0u32; start[n]];
    for i in 0..n {
        for &j in &knn.indices[i * k..(i + 1) * k] {
            let j = j as usize;
            if j != i {
                adj[fill[i]] = j as u32;
                fill[i] += 1;
                adj[fill[j]] = i as u32;
                fill[j] += 1;
            }
        }
    }
    // Sort and de-duplicate each row in place, then compact.
    let mut out_start = vec![0usize; n + 1];
    let mut out = Vec::with_capacity(adj.len());
    for i in 0..n {
        let row = &mut adj[start[i]..start[i + 1]];
        row.sort_unstable();
        let mut last = u32::MAX;
        for &j in row.iter() {
            if j != last {
                out.push(j);
                last = j;
            }
        }
        out_start[i + 1] = out.len();
    }
    (out_start, out)
}

/// Lexicographic "greater" on coordinates, for tie-breaks that do not depend on
/// point indices.
fn coord_gt(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(b.iter()).map(|(x, y)| x.total_cmp(y)).find(|o| o.is_ne())
        == Some(std::cmp::Ordering::Greater)
}

/// Flips normals so that neighbours agree in sign: Prim's minimum spanning tree on
/// 1 − |n_i·n_j| over the symmetrised kNN graph, one tree per connected component,
/// each rooted and oriented by the outward rule in the module header. A child takes
/// the sign that makes its dot product with its tree parent non-negative.
///
/// # Panics
/// If `normals.len() != points.len()` (internal error: both come from the same cloud).
pub fn orient_normals(points: &[[f32; 3]], knn: &KnnTable, normals: &mut [[f32; 3]]) {
    let n = points.len();
    assert_eq!(normals.len(), n, "internal error: one normal per point");
    if n == 0 {
        return;
    }
    let (start, adj) = symmetric_graph(n, knn);
    // Components by breadth-first search.
    let mut comp = vec![u32::MAX; n];
    let mut comps: Vec<Vec<u32>> = Vec::new();
    for s in 0..n {
        if comp[s] != u32::MAX {
            continue;
        }
        let id = comps.len() as u32;
        let mut members = vec![s as u32];
        comp[s] = id;
        let mut head = 0;
        while head < members.len() {
            let v = members[head] as usize;
            head += 1;
            for &w in &adj[start[v]..start[v + 1]] {
                if comp[w as usize] == u32::MAX {
                    comp[w as usize] = id;
                    members.push(w);
                }
            }
        }
        comps.push(members);
    }
    let mut done = vec![false; n];
    let mut heap: BinaryHeap<Reverse<(u32, u32, u32)>> = BinaryHeap::new();
    for members in &comps {
        let mut c = [0.0f64; 3];
        for &v in members {
            for a in 0..3 {
                c[a] += points[v as usize][a] as f64;
            }
        }
        let c = [
            (c[0] / members.len() as f64) as f32,
            (c[1] / members.len() as f64) as f32,
            (c[2] / members.len() as f64) as f32,
        ];
        let mut root = members[0] as usize;
        let mut best = -1.0f32;
        for &v in members {
            let p = points[v as usize];
            let d = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let r = dot3(d, d);
            if r > best || (r == best && coord_gt(p, points[root])) {
                best = r;
                root = v as usize;
            }
        }
        // The root keeps its PCA sign; the component's sign is decided after the
        // propagation (below), from all its points.
        // Prim: the heap holds (weight bits, target, parent). Weights are ≥ 0, so
        // their f32 bit patterns order like the values.
        done[root] = true;
        let push = |heap: &mut BinaryHeap<_>, v: usize, normals: &[[f32; 3]], done: &[bool]| {
            for &w in &adj[start[v]..start[v + 1]] {
                if !done[w as usize] {
                    let wt = (1.0 - dot3(normals[v], normals[w as usize]).abs()).max(0.0);
                    heap.push(Reverse((wt.to_bits(), w, v as u32)));
                }
            }
        };
        push(&mut heap, root, normals, &done);
        while let Some(Reverse((_, w, parent))) = heap.pop() {
            let w = w as usize;
            if done[w] {
                continue;
            }
            done[w] = true;
            if dot3(normals[w], normals[parent as usize]) < 0.0 {
                let m = normals[w];
                normals[w] = [-m[0], -m[1], -m[2]];
            }
            push(&mut heap, w, normals, &done);
        }
        // Outward rule: the sign that makes Σ n_v · (p_v − c) positive. A sum over the
        // whole component does not change with the pose (a rotation moves the normals
        // and the offsets alike), unlike any one point's normal, which rounding can tip
        // when it is nearly perpendicular to its offset. Near zero (a flat patch) the
        // root's normal decides: its largest-magnitude coordinate positive.
        let (mut sum, mut scale) = (0.0f64, 0.0f64);
        for &v in members {
            let (p, nv) = (points[v as usize], normals[v as usize]);
            let d = [(p[0] - c[0]) as f64, (p[1] - c[1]) as f64, (p[2] - c[2]) as f64];
            sum += nv[0] as f64 * d[0] + nv[1] as f64 * d[1] + nv[2] as f64 * d[2];
            scale += (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        }
        let flip = if sum.abs() > 1e-5 * scale {
            sum < 0.0
        } else {
            let nr = normals[root];
            let mut big = 0;
            for a in 1..3 {
                if nr[a].abs() > nr[big].abs() {
                    big = a;
                }
            }
            nr[big] < 0.0
        };
        if flip {
            for &v in members {
                let m = normals[v as usize];
                normals[v as usize] = [-m[0], -m[1], -m[2]];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spatial::kdtree::KdTree;

    fn sphere(n: usize) -> Vec<[f32; 3]> {
        // Fibonacci sphere: evenly spread, no ties.
        let ga = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let t = ga * i as f64;
                [(r * t.cos()) as f32, (r * t.sin()) as f32, z as f32]
            })
            .collect()
    }

    #[test]
    fn sphere_normals_are_radial_and_outward() {
        let pts = sphere(800);
        let knn = KdTree::build(&pts).knn_batch(&pts, 12);
        let mut nrm = estimate_normals(&pts, &knn);
        orient_normals(&pts, &knn, &mut nrm);
        for (p, n) in pts.iter().zip(&nrm) {
            assert!((dot3(*n, *n) - 1.0).abs() < 1e-5);
            assert!(dot3(*p, *n) > 0.98, "normal {n:?} at {p:?} not outward radial");
        }
    }

    /// The 8 corners of a cube, rotated, scaled and moved at random: each point's
    /// neighbourhood is the whole cube, isotropic, and its normal is the outward
    /// diagonal through its corner (before session 37 it was whatever the eigen-solver
    /// returned). (The orientation's propagation may flip them: antipodal corners'
    /// normals are parallel lines, the MST's cheapest edges; the reconstruction test
    /// `cli_audit::eight_cube_corners_give_the_six_faces` checks what comes out.)
    /// Beside them, a sphere's and a noisy plane's normals are the PCA normals bit for
    /// bit: their neighbourhoods are far from isotropic.
    #[test]
    fn isotropic_neighbourhoods_point_away_from_their_mean() {
        let mut rng = crate::rng::Rng::new(3);
        for case in 0..50 {
            let (a, b, c) = (rng.uniform(0.0, 6.3), rng.uniform(0.0, 6.3), rng.uniform(0.0, 6.3));
            let rot = nalgebra::Rotation3::from_euler_angles(a, b, c);
            let s = 10f64.powf(rng.uniform(-3.0, 3.0));
            let t = [rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0), rng.uniform(-5.0, 5.0)];
            let dirs: Vec<nalgebra::Vector3<f64>> = (0..8)
                .map(|i| {
                    rot * nalgebra::Vector3::new(
                        [-1.0, 1.0][i & 1],
                        [-1.0, 1.0][(i >> 1) & 1],
                        [-1.0, 1.0][i >> 2],
                    )
                })
                .collect();
            let pts: Vec<[f32; 3]> = dirs
                .iter()
                .map(|d| [(t[0] + s * d[0]) as f32, (t[1] + s * d[1]) as f32, (t[2] + s * d[2]) as f32])
                .collect();
            let knn = KdTree::build(&pts).knn_batch(&pts, 8);
            for (d, n) in dirs.iter().zip(&estimate_normals(&pts, &knn)) {
                let u = d / d.norm();
                let cos = u[0] * n[0] as f64 + u[1] * n[1] as f64 + u[2] * n[2] as f64;
                assert!(cos > 0.999, "case {case}: normal {n:?}, corner direction {u:?}");
            }
        }
        let mut plane: Vec<[f32; 3]> = (0..400)
            .map(|i| [(i % 20) as f32, (i / 20) as f32, 0.05 * rng.uniform(-1.0, 1.0) as f32])
            .collect();
        plane.extend(sphere(400).iter().map(|p| [p[0] * 3.0 + 40.0, p[1] * 3.0, p[2] * 3.0]));
        let knn = KdTree::build(&plane).knn_batch(&plane, 13);
        let k = row_len(plane.len(), &knn);
        for (i, n) in estimate_normals(&plane, &knn).iter().enumerate() {
            let row = &knn.indices[i * k..(i + 1) * k];
            let v = plain_pca(&plane, plane[i], row);
            assert_eq!(n.map(f32::to_bits), v.map(f32::to_bits), "point {i}");
        }
    }

    /// The 8 corners of 1 × 1 × 3 and 1 × 2 × 3 boxes (turned, moved): as a whole cloud,
    /// each normal is the offset of its corner from the box's centre; a 12-point flat
    /// grid and a shallow trough keep their plane fit; and the same box corners inside
    /// a larger table (rows that are not the whole cloud) keep the plain PCA normals.
    #[test]
    fn whole_cloud_volumes_point_away_from_their_mean() {
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, 1.1, -0.7);
        for size in [[1.0, 1.0, 3.0], [1.0, 2.0, 3.0]] {
            let rel: Vec<nalgebra::Vector3<f64>> = (0..8)
                .map(|i| {
                    let b = [(i & 1) as f64, ((i >> 1) & 1) as f64, (i >> 2) as f64];
                    rot * nalgebra::Vector3::new(
                        (b[0] - 0.5) * size[0],
                        (b[1] - 0.5) * size[1],
                        (b[2] - 0.5) * size[2],
                    )
                })
                .collect();
            let pts: Vec<[f32; 3]> =
                rel.iter().map(|d| [(d[0] + 2.0) as f32, (d[1] - 1.0) as f32, (d[2] + 0.5) as f32]).collect();
            let knn = KdTree::build(&pts).knn_batch(&pts, 8);
            for (d, n) in rel.iter().zip(&estimate_normals(&pts, &knn)) {
                let u = d / d.norm();
                let cos = u[0] * n[0] as f64 + u[1] * n[1] as f64 + u[2] * n[2] as f64;
                assert!(cos > 0.999, "{size:?}: normal {n:?}, offset {u:?}");
            }
            // Rows of 7 of the 8 points: not the whole cloud, the plain fit stays.
            let knn = KdTree::build(&pts).knn_batch(&pts, 7);
            let k = row_len(pts.len(), &knn);
            for (i, n) in estimate_normals(&pts, &knn).iter().enumerate() {
                let v = plain_pca(&pts, pts[i], &knn.indices[i * k..(i + 1) * k]);
                assert_eq!(n.map(f32::to_bits), v.map(f32::to_bits), "{size:?}, point {i}");
            }
        }
        for bend in [0.0f32, 0.05] {
            let pts: Vec<[f32; 3]> = (0..12)
                .map(|i| {
                    let (x, y) = ((i % 4) as f32, (i / 4) as f32);
                    [x, y, bend * (x - 1.5) * (x - 1.5)]
                })
                .collect();
            let knn = KdTree::build(&pts).knn_batch(&pts, 12);
            for (i, n) in estimate_normals(&pts, &knn).iter().enumerate() {
                let v = plain_pca(&pts, pts[i], &knn.indices[i * 12..(i + 1) * 12]);
                assert_eq!(n.map(f32::to_bits), v.map(f32::to_bits), "bend {bend}, point {i}");
            }
        }
    }

    /// The PCA normal without the isotropic rule: the smallest eigenvector.
    fn plain_pca(points: &[[f32; 3]], center: [f32; 3], row: &[u32]) -> [f32; 3] {
        let n = row.len() as f64;
        let rel: Vec<[f64; 3]> = row
            .iter()
            .map(|&j| std::array::from_fn(|a| (points[j as usize][a] - center[a]) as f64))
            .collect();
        let mean: [f64; 3] = std::array::from_fn(|a| rel.iter().map(|r| r[a]).sum::<f64>() / n);
        let mut c = nalgebra::Matrix3::<f64>::zeros();
        for r in &rel {
            let d = nalgebra::Vector3::new(r[0] - mean[0], r[1] - mean[1], r[2] - mean[2]);
            c += d * d.transpose();
        }
        let eig = nalgebra::SymmetricEigen::new(c);
        let imin = (0..3).min_by(|&x, &y| eig.eigenvalues[x].total_cmp(&eig.eigenvalues[y])).unwrap();
        let v = eig.eigenvectors.column(imin);
        let l = v.norm();
        [(v[0] / l) as f32, (v[1] / l) as f32, (v[2] / l) as f32]
    }

    #[test]
    fn degenerate_neighbourhoods_give_unit_vectors() {
        // Collinear and duplicated points.
        let mut pts: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        pts.extend(std::iter::repeat([3.0, 0.0, 0.0]).take(5));
        let knn = KdTree::build(&pts).knn_batch(&pts, 6);
        let mut nrm = estimate_normals(&pts, &knn);
        orient_normals(&pts, &knn, &mut nrm);
        for n in &nrm {
            assert!((dot3(*n, *n) - 1.0).abs() < 1e-5);
            assert!(n[0].abs() < 1e-4, "normal {n:?} not perpendicular to the line");
        }
    }

    /// An open wavy sheet with a slight bulge: the orientation must not depend on the
    /// pose. Rotated 64 ways, every normal equals the rotated normal of the unrotated
    /// sheet's (a pose-dependent rule, such as a fixed coordinate's sign, fails this).
    /// The case where the earlier farthest-point rule flipped a whole sheet under a
    /// similarity is a committed entry of `tests/candidates_props.proptest-regressions`.
    #[test]
    fn open_sheet_orientation_does_not_depend_on_the_pose() {
        let mut pts = Vec::new();
        for y in 0..9 {
            for x in 0..12 {
                let (px, py) = (x as f64 + 0.1 * ((x * 7 + y * 3) % 5) as f64, y as f64 * 1.3);
                pts.push([px, py, 1.5 * (0.4 * px).sin() * (0.3 * py).cos()]);
            }
        }
        let run = |p: &[[f64; 3]]| {
            let f: Vec<[f32; 3]> = p.iter().map(|v| [v[0] as f32, v[1] as f32, v[2] as f32]).collect();
            let knn = KdTree::build(&f).knn_batch(&f, 12);
            let mut nrm = estimate_normals(&f, &knn);
            orient_normals(&f, &knn, &mut nrm);
            nrm
        };
        let base = run(&pts);
        let mut rng = crate::rng::Rng::new(11);
        for _ in 0..64 {
            let r = rng.rotation();
            let moved: Vec<[f64; 3]> = pts.iter().map(|&p| crate::math::mat_vec(&r, p)).collect();
            let got = run(&moved);
            for (i, (a, b)) in base.iter().zip(&got).enumerate() {
                let ra = crate::math::mat_vec(&r, [a[0] as f64, a[1] as f64, a[2] as f64]);
                let d = ra[0] * b[0] as f64 + ra[1] * b[1] as f64 + ra[2] * b[2] as f64;
                assert!(d > 0.99, "point {i}: normal {b:?} vs rotated {ra:?}");
            }
        }
    }
}
