//! Fixed-width neighbourhood tables for KPConv: radius neighbours (nearest first) capped at a
//! per-table maximum and padded with a *shadow* index (= the number of support points, whose
//! feature row is implicitly zero), plus nearest-point upsampling indices.
//!
//! The cap follows the KPConv authors' calibration: a high percentile of the neighbour counts,
//! so that the few points in dense spots lose only their farthest neighbours while the table
//! stays narrow. Percentile rule here: nearest rank on the sorted counts, i.e. the smallest count
//! c such that at least a fraction `p` of the queries have ≤ c neighbours (at least 1).

use crate::spatial::kdtree::{KdTree, RadiusTable};
use crate::{Error, Result};

/// How the width of a neighbourhood table is chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NeighborCap {
    /// Exactly this many slots per query (at least 1).
    Fixed(usize),
    /// The given percentile (in (0, 1]) of the neighbour counts; 0.9 in the `paper` preset.
    Percentile(f64),
}

/// A `n_queries × cap` row-major table of support indices. Row q lists q's neighbours nearest
/// first (ties by smaller index); unused slots hold [`Neighborhoods::shadow`] = `n_support`.
#[derive(Clone, Debug, PartialEq)]
pub struct Neighborhoods {
    /// Number of rows.
    pub n_queries: usize,
    /// Number of support points; also the shadow index.
    pub n_support: usize,
    /// Slots per row.
    pub cap: usize,
    /// `n_queries × cap` indices in `0..=n_support`.
    pub indices: Vec<u32>,
    /// How many queries had more neighbours than `cap` (and lost their farthest ones).
    pub n_truncated: usize,
}

impl Neighborhoods {
    /// The shadow index (padding; its features are zero).
    pub fn shadow(&self) -> u32 {
        self.n_support as u32
    }

    /// Slots of query `q`.
    ///
    /// # Panics
    /// If `q >= n_queries`.
    pub fn row(&self, q: usize) -> &[u32] {
        &self.indices[q * self.cap..(q + 1) * self.cap]
    }
}

/// The nearest-rank percentile `p` of `counts` (at least 1; 1 for an empty slice).
///
/// # Errors
/// `InvalidInput` when `p` is not in (0, 1].
pub fn percentile_cap(counts: &[usize], p: f64) -> Result<usize> {
    if !(p > 0.0 && p <= 1.0) {
        return Err(Error::invalid(format!("neighbour cap percentile must be in (0, 1], got {p}")));
    }
    if counts.is_empty() {
        return Ok(1);
    }
    let mut sorted = counts.to_vec();
    sorted.sort_unstable();
    let rank = ((p * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len());
    Ok(sorted[rank - 1].max(1))
}

/// Caps and pads a radius table whose rows are sorted nearest first.
///
/// # Errors
/// `InvalidInput` for a bad percentile or `Fixed(0)`.
pub fn cap_table(table: &RadiusTable, n_support: usize, rule: NeighborCap) -> Result<Neighborhoods> {
    let n_queries = table.offsets.len().saturating_sub(1);
    let counts: Vec<usize> = table.offsets.windows(2).map(|w| w[1] - w[0]).collect();
    let cap = match rule {
        NeighborCap::Fixed(0) => return Err(Error::invalid("a fixed neighbour cap must be at least 1")),
        NeighborCap::Fixed(c) => c,
        NeighborCap::Percentile(p) => percentile_cap(&counts, p)?,
    };
    let shadow = n_support as u32;
    let mut indices = vec![shadow; n_queries * cap];
    let mut n_truncated = 0;
    for (q, row) in indices.chunks_mut(cap).enumerate() {
        let src = &table.indices[table.offsets[q]..table.offsets[q + 1]];
        n_truncated += usize::from(src.len() > cap);
        let n = src.len().min(cap);
        row[..n].copy_from_slice(&src[..n]);
    }
    Ok(Neighborhoods { n_queries, n_support, cap, indices, n_truncated })
}

/// Radius neighbourhoods of `queries` among the points of `support_tree` (built over the support
/// cloud): every support point with squared distance ≤ `radius²`, nearest first, capped by `rule`.
///
/// # Errors
/// `InvalidInput` when `radius` is not finite and positive, a query is not finite, or the rule is bad.
pub fn radius_neighborhoods(
    support_tree: &KdTree,
    queries: &[[f32; 3]],
    radius: f32,
    rule: NeighborCap,
) -> Result<Neighborhoods> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(Error::invalid(format!("neighbourhood radius must be finite and > 0, got {radius}")));
    }
    if let Some(i) = queries.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid(format!("query point {i} has a non-finite coordinate")));
    }
    let table = support_tree.within_radius_batch(queries, radius * radius);
    cap_table(&table, support_tree.len(), rule)
}

/// For each point of `fine`, the index of its nearest point in the tree built over the coarse
/// cloud (smallest index among equally near ones): the source row for nearest upsampling.
///
/// # Errors
/// `InvalidInput` when the coarse tree is empty or a fine point is not finite.
pub fn nearest_upsampling(coarse_tree: &KdTree, fine: &[[f32; 3]]) -> Result<Vec<u32>> {
    if coarse_tree.num_indexed() == 0 {
        return Err(Error::invalid("nearest upsampling from an empty coarse cloud"));
    }
    if let Some(i) = fine.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::invalid(format!("fine point {i} has a non-finite coordinate")));
    }
    Ok(coarse_tree.knn_batch(fine, 1).indices)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_is_nearest_rank() {
        let c: Vec<usize> = (1..=10).collect();
        assert_eq!(percentile_cap(&c, 0.9).unwrap(), 9);
        assert_eq!(percentile_cap(&c, 1.0).unwrap(), 10);
        assert_eq!(percentile_cap(&c, 0.05).unwrap(), 1);
        assert_eq!(percentile_cap(&[0, 0], 0.9).unwrap(), 1);
        assert_eq!(percentile_cap(&[], 0.9).unwrap(), 1);
        assert!(percentile_cap(&c, 0.0).is_err());
        assert!(percentile_cap(&c, f64::NAN).is_err());
    }

    #[test]
    fn cap_keeps_nearest_and_pads_with_shadow() {
        let t = RadiusTable {
            offsets: vec![0, 3, 3, 4],
            indices: vec![5, 2, 7, 1],
            dist_sq: vec![0.0, 0.1, 0.2, 0.0],
        };
        let nb = cap_table(&t, 8, NeighborCap::Fixed(2)).unwrap();
        assert_eq!(nb.indices, vec![5, 2, 8, 8, 1, 8]);
        assert_eq!(nb.n_truncated, 1);
        assert_eq!(nb.row(2), &[1, 8]);
        assert!(cap_table(&t, 8, NeighborCap::Fixed(0)).is_err());
    }

    #[test]
    fn radius_and_upsampling_on_a_line() {
        let pts: Vec<[f32; 3]> = (0..10).map(|i| [i as f32, 0.0, 0.0]).collect();
        let tree = KdTree::build(&pts);
        let nb =
            radius_neighborhoods(&tree, &[[0.0; 3], [4.4, 0.0, 0.0]], 1.5, NeighborCap::Fixed(4)).unwrap();
        assert_eq!(nb.indices, vec![0, 1, 10, 10, 4, 5, 3, 10]);
        let coarse = [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]];
        let up = nearest_upsampling(&KdTree::build(&coarse), &pts).unwrap();
        assert_eq!(up, vec![0, 0, 0, 1, 1, 1, 1, 1, 1, 1]);
        assert!(radius_neighborhoods(&tree, &[[f32::NAN; 3]], 1.0, NeighborCap::Fixed(1)).is_err());
        assert!(nearest_upsampling(&KdTree::build(&[]), &pts).is_err());
    }
}
