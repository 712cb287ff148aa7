//! Grid subsampling (KPConv's pooling pyramid): one point per occupied voxel, at the barycentre
//! of the points inside it, features averaged. Output order is by voxel key (lexicographic
//! (i, j, k) with i = ⌊x / cell⌋ as `i64`), and each voxel's points are summed in a canonical order
//! (sorted by coordinates, then features), so the result does not depend on the input order at all:
//! the subsampled cloud of a shuffled input is bit-identical.

use crate::{Error, Result};

/// Largest |coordinate / cell| accepted, so voxel keys stay far from `i64` overflow and the
/// barycentre sums keep their precision.
const MAX_CELL_COORD: f64 = (1u64 << 52) as f64;

/// The result of [`grid_subsample`].
#[derive(Clone, Debug, PartialEq)]
pub struct Subsampled {
    /// One barycentre per occupied voxel, in voxel-key order.
    pub points: Vec<[f32; 3]>,
    /// Averaged features, `points.len() × channels`, row-major (empty when there were none).
    pub features: Vec<f32>,
    /// Feature channels per point (0 when no features were given).
    pub channels: usize,
    /// For each input point, the index of its voxel in `points`.
    pub cluster: Vec<u32>,
}

/// Checks that every point is finite, returning the index of the first that is not.
fn check_points(points: &[[f32; 3]]) -> Result<()> {
    if let Some(i) = points.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid(format!("point {i} has a non-finite coordinate: {:?}", points[i])));
    }
    Ok(())
}

/// Voxel key of `p` for cell size `cell`: ⌊p / cell⌋ per axis, robust to negative coordinates.
#[inline]
pub fn voxel_key(p: [f32; 3], cell: f32) -> [i64; 3] {
    let c = cell as f64;
    [(p[0] as f64 / c).floor() as i64, (p[1] as f64 / c).floor() as i64, (p[2] as f64 / c).floor() as i64]
}

/// Grid-subsamples `points` with voxel size `cell`. `features`, when given, is
/// `points.len() × channels` row-major and is averaged per voxel.
///
/// # Errors
/// `InvalidInput` when `cell` is not finite and positive, a coordinate or feature is not finite
/// (the message names the point), the feature buffer has the wrong length, or a coordinate is so
/// large relative to `cell` that voxel keys would lose precision. An empty cloud gives an empty result.
pub fn grid_subsample(
    points: &[[f32; 3]],
    features: Option<(&[f32], usize)>,
    cell: f32,
) -> Result<Subsampled> {
    if !(cell.is_finite() && cell > 0.0) {
        return Err(Error::invalid(format!("grid cell must be finite and > 0, got {cell}")));
    }
    check_points(points)?;
    let (feats, channels) = features.unwrap_or((&[], 0));
    if feats.len() != points.len() * channels {
        return Err(Error::invalid(format!(
            "features have {} values, expected {} points × {channels} channels",
            feats.len(),
            points.len()
        )));
    }
    if let Some(i) = feats.iter().position(|f| !f.is_finite()) {
        return Err(Error::invalid(format!("feature of point {} is not finite", i / channels.max(1))));
    }
    if points.len() > u32::MAX as usize {
        return Err(Error::invalid(format!("too many points for u32 indices: {}", points.len())));
    }
    if let Some(i) =
        points.iter().position(|p| p.iter().any(|&c| (c as f64 / cell as f64).abs() > MAX_CELL_COORD))
    {
        return Err(Error::invalid(format!(
            "point {i} ({:?}) is too far from the origin for grid cell {cell}",
            points[i]
        )));
    }
    let keys: Vec<[i64; 3]> = points.iter().map(|&p| voxel_key(p, cell)).collect();
    let mut order: Vec<u32> = (0..points.len() as u32).collect();
    // Canonical order: voxel key, then coordinates, then features (total orders on floats),
    // so that neither voxel order nor summation order depends on the input order.
    order.sort_unstable_by(|&a, &b| {
        let (a, b) = (a as usize, b as usize);
        keys[a]
            .cmp(&keys[b])
            .then_with(|| {
                (0..3)
                    .map(|d| points[a][d].total_cmp(&points[b][d]))
                    .find(|o| o.is_ne())
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
            .then_with(|| {
                let (fa, fb) =
                    (&feats[a * channels..(a + 1) * channels], &feats[b * channels..(b + 1) * channels]);
                fa.iter()
                    .zip(fb)
                    .map(|(x, y)| x.total_cmp(y))
                    .find(|o| o.is_ne())
                    .unwrap_or(std::cmp::Ordering::Equal)
            })
    });
    let mut out =
        Subsampled { points: Vec::new(), features: Vec::new(), channels, cluster: vec![0; points.len()] };
    let mut fsum = vec![0.0f64; channels];
    let mut start = 0;
    while start < order.len() {
        let key = keys[order[start] as usize];
        let mut end = start;
        let mut psum = [0.0f64; 3];
        fsum.iter_mut().for_each(|f| *f = 0.0);
        while end < order.len() && keys[order[end] as usize] == key {
            let i = order[end] as usize;
            for d in 0..3 {
                psum[d] += points[i][d] as f64;
            }
            for (s, &f) in fsum.iter_mut().zip(&feats[i * channels..(i + 1) * channels]) {
                *s += f as f64;
            }
            out.cluster[i] = out.points.len() as u32;
            end += 1;
        }
        let n = (end - start) as f64;
        out.points.push([(psum[0] / n) as f32, (psum[1] / n) as f32, (psum[2] / n) as f32]);
        out.features.extend(fsum.iter().map(|s| (s / n) as f32));
        start = end;
    }
    Ok(out)
}

/// A subsampling pyramid: level 0 is the input cloud itself, level `l ≥ 1` is level `l − 1`
/// grid-subsampled with cell `cells[l]` (chained, as KPConv does, so every coarse point is the
/// barycentre of fine-level barycentres).
#[derive(Clone, Debug, PartialEq)]
pub struct SubsamplePyramid {
    /// Points per level; `levels[0]` is the input.
    pub levels: Vec<Vec<[f32; 3]>>,
    /// Nominal cell size per level (`cells[0]` is nominal too: level 0 is not subsampled).
    pub cells: Vec<f32>,
}

/// Builds the pyramid with `n_levels` levels and cell `first_cell × 2^l` at level `l`
/// (level 0 keeps the raw points; its nominal cell sets its convolution radius).
///
/// # Errors
/// `InvalidInput` for an empty cloud, `n_levels == 0`, a bad cell or non-finite points.
pub fn subsample_pyramid(points: &[[f32; 3]], first_cell: f32, n_levels: usize) -> Result<SubsamplePyramid> {
    if points.is_empty() {
        return Err(Error::invalid("cannot build a subsampling pyramid of an empty cloud"));
    }
    if n_levels == 0 {
        return Err(Error::invalid("a subsampling pyramid needs at least one level"));
    }
    if !(first_cell.is_finite() && first_cell > 0.0) {
        return Err(Error::invalid(format!("grid cell must be finite and > 0, got {first_cell}")));
    }
    check_points(points)?;
    let cells: Vec<f32> = (0..n_levels).map(|l| first_cell * (1u64 << l.min(62)) as f32).collect();
    let mut levels = vec![points.to_vec()];
    for &cell in &cells[1..] {
        let prev = levels.last().expect("internal error: level 0 present");
        let next = grid_subsample(prev, None, cell)?.points;
        levels.push(next);
    }
    Ok(SubsamplePyramid { levels, cells })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn negative_coordinates_get_their_own_voxels() {
        let pts = [[-0.01, 0.0, 0.0], [0.01, 0.0, 0.0], [-0.99, 0.5, 0.2]];
        let s = grid_subsample(&pts, None, 1.0).unwrap();
        assert_eq!(s.points.len(), 2);
        assert_eq!(s.cluster[0], s.cluster[2]);
        assert_ne!(s.cluster[0], s.cluster[1]);
        let want = [-0.5, 0.25, 0.1];
        assert!((0..3).all(|d| (s.points[0][d] - want[d]).abs() < 1e-6), "{:?}", s.points[0]);
    }

    #[test]
    fn features_averaged_and_input_order_irrelevant() {
        let pts = [[0.1, 0.1, 0.1], [0.3, 0.2, 0.1], [1.5, 0.0, 0.0], [0.3, 0.2, 0.1]];
        let f = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0];
        let s = grid_subsample(&pts, Some((&f, 2)), 1.0).unwrap();
        assert_eq!(s.points.len(), 2);
        assert_eq!(&s.features[..2], &[11.0 / 3.0, 14.0 / 3.0]);
        assert_eq!(&s.features[2..], &[5.0, 6.0]);
        let perm = [3, 2, 0, 1];
        let p2: Vec<_> = perm.iter().map(|&i| pts[i]).collect();
        let f2: Vec<_> = perm.iter().flat_map(|&i| [f[2 * i], f[2 * i + 1]]).collect();
        let s2 = grid_subsample(&p2, Some((&f2, 2)), 1.0).unwrap();
        assert_eq!(s.points, s2.points);
        assert_eq!(s.features, s2.features);
    }

    #[test]
    fn bad_inputs_are_errors() {
        assert!(grid_subsample(&[[f32::NAN, 0.0, 0.0]], None, 1.0).is_err());
        assert!(grid_subsample(&[[0.0; 3]], None, 0.0).is_err());
        assert!(grid_subsample(&[[0.0; 3]], Some((&[1.0, 2.0], 1)), 1.0).is_err());
        assert!(grid_subsample(&[[1e30, 0.0, 0.0]], None, 1e-10).is_err());
        assert!(grid_subsample(&[], None, 1.0).unwrap().points.is_empty());
        assert!(subsample_pyramid(&[], 0.1, 3).is_err());
        assert!(subsample_pyramid(&[[0.0; 3]], 0.1, 0).is_err());
    }

    #[test]
    fn pyramid_levels_shrink_and_cells_double() {
        let pts: Vec<[f32; 3]> = (0..1000)
            .map(|i| [(i % 10) as f32 * 0.1, ((i / 10) % 10) as f32 * 0.1, (i / 100) as f32 * 0.1])
            .collect();
        let p = subsample_pyramid(&pts, 0.1, 4).unwrap();
        assert_eq!(p.cells, vec![0.1, 0.2, 0.4, 0.8]);
        assert_eq!(p.levels[0].len(), 1000);
        for l in 1..4 {
            assert!(p.levels[l].len() < p.levels[l - 1].len());
        }
        let one = subsample_pyramid(&[[1.0, 2.0, 3.0]], 0.1, 3).unwrap();
        assert!(one.levels.iter().all(|l| l == &vec![[1.0, 2.0, 3.0]]));
    }
}
