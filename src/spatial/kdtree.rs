//! Exact k-nearest-neighbour and radius search over 3-D `f32` points.
//!
//! A balanced kd-tree built once over a slice: it owns a permuted copy of the points (structure of
//! arrays), the permutation back to the caller's indices, an implicit breadth-first node array and
//! leaves ("buckets") of at most [`BUCKET`] points, each in a fixed slot padded with NaN points.
//!
//! Searches are depth-first without recursion (an explicit stack of pending far subtrees), near
//! child first, pruned by the squared distance to a subtree's cell from per-axis offsets updated
//! at each split (Arya & Mount's incremental distance, summed afresh so that it stays a lower
//! bound in floating point). A leaf is scanned by computing all its distances and a mask of those
//! within the current k-th distance in vector registers; only the few candidates are then
//! inserted into a sorted buffer, without branches on their position.
//!
//! Results are exact and deterministic: squared distances are computed by [`dist_sq`] (always the
//! same `f32` expression, no fused multiply-add), and among equal distances the smaller original
//! index comes first, so every answer equals a brute-force sort by `(dist_sq, index)`. Searches
//! keep results as packed `(dist_sq bits, index)` keys so that this order is one integer compare.
//! Batch queries run in the order of the leaves they fall in (cache locality), in parallel with
//! the `parallel` feature, and give exactly the single-query answers whatever the thread count.
//!
//! Non-finite input: points with a NaN or infinite coordinate are stored nowhere and never returned
//! (the pipeline rejects them before; the tree only promises not to panic). Queries with a NaN or
//! infinite coordinate have no neighbours.

use crate::par;

/// Most points in one leaf bucket. Leaves hold between about `BUCKET / 2` and `BUCKET` points.
pub const BUCKET: usize = 32;

/// Leaf slots are padded to a multiple of this many points, so that the distance loop of a leaf
/// scan is whole vector registers.
const LANES: usize = 4;

/// Index used in [`KnnTable`] rows of queries that have no neighbours (non-finite queries).
pub const NO_NEIGHBOR: u32 = u32::MAX;

/// Subtrees with more points than this are built on two threads (with `parallel`).
const PAR_BUILD_MIN: usize = 16 * 1024;

/// Points sampled to estimate a node's extent when choosing its split axis.
const EXTENT_SAMPLE: usize = 256;

/// Queries per parallel task in the batch functions (and the most a kNN task gathers at once).
const QUERY_BLOCK: usize = 512;

/// Padding of a kNN key buffer before it fills: `key(inf, u32::MAX)`, above every real key (real
/// indices are below `u32::MAX`), and its distance part reads back as `+inf`.
const SENTINEL: u64 = 0x7F80_0000_FFFF_FFFF;

/// Largest `k` whose search buffer lives on the stack in [`KdTree::knn`].
const STACK_K: usize = 64;

/// Largest leaf slot: [`BUCKET`] rounded up to a multiple of [`LANES`].
const SLOT_MAX: usize = BUCKET.div_ceil(LANES) * LANES;

/// `BITS[j] = 1 << j`, to build candidate masks in vector registers (a `u32` mask per leaf).
const BITS: [u32; SLOT_MAX] = {
    assert!(SLOT_MAX <= 32, "leaf masks are u32");
    let mut b = [0u32; SLOT_MAX];
    let mut j = 0;
    while j < SLOT_MAX {
        b[j] = 1 << j;
        j += 1;
    }
    b
};

/// Most levels of internal nodes: at most `u32::MAX` points and leaves of at least one point make
/// `depth <= 32`. A search keeps at most one pending subtree per level, so this bounds its stack.
const MAX_DEPTH: usize = 32;

/// A search result packed so that one integer comparison orders by `(dist_sq, index)`: squared
/// distances are never negative (nor -0 or NaN: finite points and queries only), and the bit
/// patterns of non-negative floats are ordered like their values.
#[inline(always)]
fn key(dist_sq: f32, index: u32) -> u64 {
    ((dist_sq.to_bits() as u64) << 32) | index as u64
}

/// The distance part of a key.
#[inline(always)]
fn kth_dist(key: u64) -> f32 {
    f32::from_bits((key >> 32) as u32)
}

#[inline(always)]
fn unkey(key: u64) -> Neighbor {
    Neighbor { index: key as u32, dist_sq: f32::from_bits((key >> 32) as u32) }
}

/// One search result: the caller's index of a point and its squared distance to the query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Neighbor {
    /// Index of the point in the slice given to [`KdTree::build`].
    pub index: u32,
    /// Squared Euclidean distance to the query, as computed by [`dist_sq`].
    pub dist_sq: f32,
}

/// The squared distance used by every query: `(dx*dx + dy*dy) + dz*dz` in `f32`, with
/// `d = a - b`. Brute-force references must use this function to compare results exactly.
#[inline(always)]
pub fn dist_sq(a: [f32; 3], b: [f32; 3]) -> f32 {
    let dx = a[0] - b[0];
    let dy = a[1] - b[1];
    let dz = a[2] - b[2];
    dx * dx + dy * dy + dz * dz
}

/// Lower bound on [`dist_sq`] from the query to any point of a box, from the per-axis distances
/// `off` from the query to the box: rounding is monotonic, so this never exceeds the distance to
/// a point in the box, and pruning on it is exact.
#[inline(always)]
fn box_dist_sq(off: [f32; 3]) -> f32 {
    off[0] * off[0] + off[1] * off[1] + off[2] * off[2]
}

/// `UNIT[d]` is 1 in lane `d` and 0 elsewhere.
const UNIT: [[f32; 3]; 4] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0; 3]];

/// The per-axis distances to the far child of a node splitting axis `d`, whose split plane is at
/// distance `a` from the query, given `off` for the node: `off` with lane `d` raised to `a` (the
/// far cell lies beyond the plane and within the node's cell, so either bound holds). Lanes other
/// than `d` see `a * 0`, which is 0 or (for `a = inf`) NaN, and a NaN never wins the `>`.
/// Arithmetic instead of an indexed store: a store to a computed index followed by whole-array
/// loads would stall on store forwarding, on the search's hottest path.
#[inline(always)]
fn with_axis(off: [f32; 3], d: usize, a: f32) -> [f32; 3] {
    let u = UNIT[d & 3];
    std::array::from_fn(|i| {
        let v = a * u[i];
        if v > off[i] {
            v
        } else {
            off[i]
        }
    })
}

/// An internal node: points of the left child have `p[dim] <= val`, of the right `p[dim] >= val`.
#[derive(Clone, Copy, Debug, Default)]
struct Node {
    val: f32,
    dim: u32,
}

/// A subtree a search still has to visit: its node, the per-axis distances from the query to its
/// cell, and their [`box_dist_sq`].
#[derive(Clone, Copy, Default)]
struct Pending {
    off: [f32; 3],
    rd: f32,
    node: u32,
}

/// The explicit stack of a depth-first search (no recursion): it holds at most one pending
/// subtree per level, with levels increasing from bottom to top.
type SearchStack = [Pending; MAX_DEPTH];

/// A kd-tree over 3-D `f32` points for exact kNN and radius queries.
///
/// Layout: a complete binary tree of `depth` levels of internal nodes stored breadth-first (the
/// children of node `i` are `2i + 1` and `2i + 2`, node `2^depth - 1 + j` is leaf `j`); leaf `j`
/// owns the fixed slot `j * slot .. (j + 1) * slot` of the permuted point arrays, its points first
/// and then padding whose coordinates are NaN (so every distance comparison on them is false).
#[derive(Clone, Debug)]
pub struct KdTree {
    /// Number of points given to `build` (finite or not).
    n_input: usize,
    /// Number of finite points, the ones stored and returned.
    n_indexed: usize,
    /// Permuted finite points and padding, one array per coordinate, `slot << depth` entries.
    xs: Vec<f32>,
    ys: Vec<f32>,
    zs: Vec<f32>,
    /// `idx[p]` is the caller's index of permuted point `p` ([`NO_NEIGHBOR`] for padding).
    idx: Vec<u32>,
    /// Internal nodes breadth-first, `2^depth - 1` of them.
    nodes: Vec<Node>,
    /// Points per leaf slot: the largest leaf rounded up to a multiple of [`LANES`].
    slot: usize,
    /// Levels of internal nodes (0: the whole tree is one leaf).
    depth: u32,
}

/// Build-time record: a point and its caller index, kept together while partitioning.
#[derive(Clone, Copy)]
struct Item {
    p: [f32; 3],
    i: u32,
}

impl KdTree {
    /// Builds the tree over `points`. Never panics: empty and one-point clouds, duplicates and
    /// all-identical points are fine. Points with a non-finite coordinate are left out (never
    /// returned by any query). Uses two threads per level near the top with `parallel`; the tree
    /// is the same with any thread count.
    ///
    /// # Panics
    /// Only if `points.len()` exceeds `u32::MAX` (indices are `u32`).
    pub fn build(points: &[[f32; 3]]) -> KdTree {
        assert!(points.len() <= u32::MAX as usize, "KdTree::build: more than u32::MAX points");
        let mut items: Vec<Item> = points
            .iter()
            .enumerate()
            .filter(|(_, p)| p.iter().all(|c| c.is_finite()))
            .map(|(i, &p)| Item { p, i: i as u32 })
            .collect();
        let n = items.len();
        let mut depth = 0u32;
        // Middle splits give leaves of at most ceil(n / 2^depth) points.
        while n.div_ceil(1 << depth) > BUCKET {
            depth += 1;
        }
        let mut pre_order = vec![Node::default(); (1usize << depth) - 1];
        build_rec(&mut items, &mut pre_order, depth);
        let mut nodes = vec![Node::default(); pre_order.len()];
        breadth_first(&pre_order, depth, 0, &mut nodes);
        let mut leaf_start = Vec::with_capacity((1usize << depth) + 1);
        leaf_bounds(0, n, depth, &mut leaf_start);
        leaf_start.push(n);
        let slot = n.div_ceil(1 << depth).div_ceil(LANES) * LANES;
        let total = slot << depth;
        let (mut xs, mut ys, mut zs) = (vec![f32::NAN; total], vec![f32::NAN; total], vec![f32::NAN; total]);
        let mut idx = vec![NO_NEIGHBOR; total];
        for (leaf, w) in leaf_start.windows(2).enumerate() {
            for (p, it) in (leaf * slot..).zip(&items[w[0]..w[1]]) {
                xs[p] = it.p[0];
                ys[p] = it.p[1];
                zs[p] = it.p[2];
                idx[p] = it.i;
            }
        }
        KdTree { n_input: points.len(), n_indexed: n, xs, ys, zs, idx, nodes, slot, depth }
    }

    /// Number of points given to [`KdTree::build`], including any non-finite ones left out.
    pub fn len(&self) -> usize {
        self.n_input
    }

    /// `true` when built from an empty slice.
    pub fn is_empty(&self) -> bool {
        self.n_input == 0
    }

    /// Number of points that queries can return (the finite ones; equals `len()` for clean input).
    pub fn num_indexed(&self) -> usize {
        self.n_indexed
    }

    /// The `k` nearest points to `query`, into `out` (cleared first): `min(k, num_indexed())`
    /// results sorted by `(dist_sq, index)`. `k = 0` or a non-finite query gives no results.
    pub fn knn(&self, query: [f32; 3], k: usize, out: &mut Vec<Neighbor>) {
        out.clear();
        let k = k.min(self.n_indexed);
        if k == 0 || !query.iter().all(|c| c.is_finite()) {
            return;
        }
        let mut stack = [Pending::default(); MAX_DEPTH];
        if k <= STACK_K {
            let mut best = [SENTINEL; STACK_K];
            self.knn_into(query, &mut best[..k], &mut stack);
            out.extend(best[..k].iter().map(|&b| unkey(b)));
        } else {
            let mut best = vec![SENTINEL; k];
            self.knn_into(query, &mut best, &mut stack);
            out.extend(best.iter().map(|&b| unkey(b)));
        }
    }

    /// The nearest point to `query` (smallest index among equally near ones), or `None` for an
    /// empty tree or a non-finite query.
    pub fn nearest(&self, query: [f32; 3]) -> Option<Neighbor> {
        if self.n_indexed == 0 || !query.iter().all(|c| c.is_finite()) {
            return None;
        }
        let mut best = [SENTINEL];
        self.knn_into(query, &mut best, &mut [Pending::default(); MAX_DEPTH]);
        Some(unkey(best[0]))
    }

    /// All points with `dist_sq <= radius_sq`, into `out` (cleared first), sorted by
    /// `(dist_sq, index)`. A NaN or negative `radius_sq`, or a non-finite query, gives nothing.
    pub fn within_radius(&self, query: [f32; 3], radius_sq: f32, out: &mut Vec<Neighbor>) {
        self.within_radius_with(query, radius_sq, out, &mut [Pending::default(); MAX_DEPTH]);
    }

    /// [`KdTree::within_radius`] with the search stack given (reused across a batch).
    fn within_radius_with(
        &self,
        query: [f32; 3],
        radius_sq: f32,
        out: &mut Vec<Neighbor>,
        stack: &mut SearchStack,
    ) {
        out.clear();
        if self.n_indexed == 0
            || radius_sq.is_nan()
            || radius_sq < 0.0
            || !query.iter().all(|c| c.is_finite())
        {
            return;
        }
        self.radius_into(query, radius_sq, out, stack);
        out.sort_unstable_by(|a, b| a.dist_sq.total_cmp(&b.dist_sq).then(a.index.cmp(&b.index)));
    }

    /// [`KdTree::knn`] for every query, in parallel with `parallel`. The table has
    /// `k = min(k, num_indexed())` columns; rows of non-finite queries are filled with
    /// [`NO_NEIGHBOR`] and `f32::INFINITY`.
    pub fn knn_batch(&self, queries: &[[f32; 3]], k: usize) -> KnnTable {
        let k = k.min(self.n_indexed);
        let nq = queries.len();
        if k == 0 {
            return KnnTable { k, n_queries: nq, indices: Vec::new(), dist_sq: Vec::new() };
        }
        // Queries are answered in the order of the leaves they fall in, so that consecutive
        // searches touch the same nodes and points (cache locality), then rows are put back.
        let order = self.leaf_order(queries);
        let mut sorted = vec![0u64; nq * k];
        par::for_each_chunk_mut(&mut sorted, QUERY_BLOCK * k, |b, rows| {
            let mut stack = [Pending::default(); MAX_DEPTH];
            // Gathered first: these scattered loads overlap, where one per search would stall it.
            let block = &order[b * QUERY_BLOCK..(b * QUERY_BLOCK + rows.len() / k)];
            let mut qs = [[0.0f32; 3]; QUERY_BLOCK];
            for (q, &i) in qs.iter_mut().zip(block) {
                *q = queries[i as usize];
            }
            for (best, &q) in rows.chunks_exact_mut(k).zip(&qs) {
                if q.iter().all(|c| c.is_finite()) {
                    self.knn_into(q, best, &mut stack);
                } else {
                    best.fill(key(f32::INFINITY, NO_NEIGHBOR));
                }
            }
        });
        let mut rank = vec![0u32; nq];
        for (r, &q) in order.iter().enumerate() {
            rank[q as usize] = r as u32;
        }
        let mut indices = vec![0u32; nq * k];
        let mut dists = vec![0.0f32; nq * k];
        par::for_each_chunk_mut(&mut indices, QUERY_BLOCK * k, |b, rows| {
            for (r, row) in rows.chunks_exact_mut(k).enumerate() {
                let src = rank[b * QUERY_BLOCK + r] as usize * k;
                for (o, nb) in row.iter_mut().zip(&sorted[src..src + k]) {
                    *o = *nb as u32;
                }
            }
        });
        par::for_each_chunk_mut(&mut dists, QUERY_BLOCK * k, |b, rows| {
            for (r, row) in rows.chunks_exact_mut(k).enumerate() {
                let src = rank[b * QUERY_BLOCK + r] as usize * k;
                for (o, nb) in row.iter_mut().zip(&sorted[src..src + k]) {
                    *o = kth_dist(*nb);
                }
            }
        });
        KnnTable { k, n_queries: nq, indices, dist_sq: dists }
    }

    /// The leaf whose slot `q` descends to (the first one a search scans).
    fn leaf_of(&self, q: [f32; 3]) -> usize {
        let mut node = 0usize;
        while node < self.nodes.len() {
            let nd = self.nodes[node];
            node = 2 * node + 1 + usize::from(q[nd.dim as usize] >= nd.val);
        }
        node - self.nodes.len()
    }

    /// Query indices sorted by the leaf each descends to (a stable counting sort).
    fn leaf_order(&self, queries: &[[f32; 3]]) -> Vec<u32> {
        let n_leaves = 1usize << self.depth;
        let leaves: Vec<u32> = par::map(queries.len(), |i| self.leaf_of(queries[i]) as u32);
        let mut start = vec![0u32; n_leaves + 1];
        for &l in &leaves {
            start[l as usize + 1] += 1;
        }
        for l in 0..n_leaves {
            start[l + 1] += start[l];
        }
        let mut order = vec![0u32; queries.len()];
        for (i, &l) in leaves.iter().enumerate() {
            order[start[l as usize] as usize] = i as u32;
            start[l as usize] += 1;
        }
        order
    }

    /// [`KdTree::within_radius`] for every query, in parallel with `parallel`, as a CSR table.
    pub fn within_radius_batch(&self, queries: &[[f32; 3]], radius_sq: f32) -> RadiusTable {
        let n_blocks = queries.len().div_ceil(QUERY_BLOCK);
        let parts = par::map(n_blocks, |b| {
            let qs = &queries[b * QUERY_BLOCK..((b + 1) * QUERY_BLOCK).min(queries.len())];
            let mut counts = Vec::with_capacity(qs.len());
            let mut ii = Vec::new();
            let mut dd = Vec::new();
            let mut buf = Vec::new();
            let mut stack = [Pending::default(); MAX_DEPTH];
            for q in qs {
                self.within_radius_with(*q, radius_sq, &mut buf, &mut stack);
                counts.push(buf.len());
                ii.extend(buf.iter().map(|nb| nb.index));
                dd.extend(buf.iter().map(|nb| nb.dist_sq));
            }
            (counts, ii, dd)
        });
        let total: usize = parts.iter().map(|p| p.1.len()).sum();
        let mut offsets = Vec::with_capacity(queries.len() + 1);
        offsets.push(0);
        let mut indices = Vec::with_capacity(total);
        let mut dists = Vec::with_capacity(total);
        for (counts, ii, dd) in parts {
            for c in counts {
                offsets.push(offsets[offsets.len() - 1] + c);
            }
            indices.extend_from_slice(&ii);
            dists.extend_from_slice(&dd);
        }
        RadiusTable { offsets, indices, dist_sq: dists }
    }

    /// Depth-first kNN search into `best` (length k, `1 <= k <= num_indexed()`, finite query):
    /// on return it holds the keys of the k nearest, sorted. It descends to the query's leaf first,
    /// pushing each far child whose cell may still hold a nearer point, then pops them; a subtree
    /// is skipped when its [`box_dist_sq`] exceeds the k-th distance found so far (ties with the
    /// k-th distance are searched because a smaller index may win them).
    fn knn_into(&self, q: [f32; 3], best: &mut [u64], stack: &mut SearchStack) {
        best.fill(SENTINEL);
        let last = best.len() - 1;
        let n_internal = self.nodes.len();
        let mut sp = 0usize;
        let mut node = 0usize;
        let mut off = [0.0f32; 3];
        // Small buffers fill unsorted first (see `scan_leaf_knn`); larger ones by insertion.
        let mut filled = if best.len() <= NET_MAX { 0 } else { best.len() };
        loop {
            while node < n_internal {
                let nd = self.nodes[node];
                let d = nd.dim as usize;
                let diff = q[d] - nd.val;
                let right = usize::from(diff >= 0.0);
                let far_off = with_axis(off, d, diff.abs());
                let rd = box_dist_sq(far_off);
                // `rd <= k-th distance`, in key space (a sentinel lets everything through).
                if ((rd.to_bits() as u64) << 32) <= best[last] {
                    stack[sp] = Pending { off: far_off, rd, node: (2 * node + 2 - right) as u32 };
                    sp += 1;
                }
                node = 2 * node + 1 + right;
            }
            self.scan_leaf_knn(node - n_internal, &q, best, &mut filled);
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let p = stack[sp];
                if ((p.rd.to_bits() as u64) << 32) <= best[last] {
                    node = p.node as usize;
                    off = p.off;
                    break;
                }
            }
        }
    }

    /// The squared distances from `q` to the slots of leaf `leaf`, the mask of the slots
    /// within `bound` (`<=`; padding is NaN and never compares), and the leaf's indices.
    /// Distances and mask are built in loops the compiler vectorises, so that callers
    /// look only at the (few) candidates one by one.
    #[inline(always)]
    fn leaf_within(&self, leaf: usize, q: &[f32; 3], bound: f32) -> ([f32; SLOT_MAX], u32, &[u32]) {
        let (s, e) = (leaf * self.slot, (leaf + 1) * self.slot);
        let mut ds = [f32::NAN; SLOT_MAX];
        for (((d, &x), &y), &z) in ds.iter_mut().zip(&self.xs[s..e]).zip(&self.ys[s..e]).zip(&self.zs[s..e]) {
            *d = dist_sq(*q, [x, y, z]);
        }
        let mut mask = 0u32;
        for (&d, &bit) in ds.iter().zip(&BITS) {
            mask |= if d <= bound { bit } else { 0 };
        }
        (ds, mask, &self.idx[s..e])
    }

    /// Offers every point of leaf `leaf` to the sorted key buffer `best`.
    #[inline(always)]
    fn scan_leaf_knn(&self, leaf: usize, q: &[f32; 3], best: &mut [u64], filled: &mut usize) {
        let last = best.len() - 1;
        let (ds, mut mask, ids) = self.leaf_within(leaf, q, kth_dist(best[last]));
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let kk = key(ds[j], ids[j]);
            if *filled < best.len() {
                // The first k candidates are taken unsorted, then sorted at once.
                best[*filled] = kk;
                *filled += 1;
                if *filled == best.len() {
                    sort_small(best);
                }
            } else if kk < best[last] {
                insert_sorted(best, kk);
            }
        }
    }

    /// Pushes the points of leaf `leaf` within `radius_sq` of `q` to `out`.
    #[inline(always)]
    fn scan_leaf_radius(&self, leaf: usize, q: &[f32; 3], radius_sq: f32, out: &mut Vec<Neighbor>) {
        let (ds, mut mask, ids) = self.leaf_within(leaf, q, radius_sq);
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            out.push(Neighbor { index: ids[j], dist_sq: ds[j] });
        }
    }

    /// Depth-first radius search into `out` (unsorted), traversed and pruned like
    /// [`KdTree::knn_into`] with the fixed bound `radius_sq`.
    fn radius_into(&self, q: [f32; 3], radius_sq: f32, out: &mut Vec<Neighbor>, stack: &mut SearchStack) {
        let n_internal = self.nodes.len();
        let mut sp = 0usize;
        let mut node = 0usize;
        let mut off = [0.0f32; 3];
        loop {
            while node < n_internal {
                let nd = self.nodes[node];
                let d = nd.dim as usize;
                let diff = q[d] - nd.val;
                let right = usize::from(diff >= 0.0);
                let far_off = with_axis(off, d, diff.abs());
                let rd = box_dist_sq(far_off);
                if rd <= radius_sq {
                    stack[sp] = Pending { off: far_off, rd, node: (2 * node + 2 - right) as u32 };
                    sp += 1;
                }
                node = 2 * node + 1 + right;
            }
            self.scan_leaf_radius(node - n_internal, &q, radius_sq, out);
            if sp == 0 {
                return;
            }
            sp -= 1;
            node = stack[sp].node as usize;
            off = stack[sp].off;
        }
    }
}

/// Inserts `kk` into the sorted `best`, dropping its last element (which `kk` is below).
/// Branch-free: every slot takes its left neighbour, `kk` or itself, so the loop runs the same
/// way whatever the position (no mispredicted exit) and its iterations are independent.
#[inline(always)]
fn insert_sorted(best: &mut [u64], kk: u64) {
    for j in (1..best.len()).rev() {
        let (prev, cur) = (best[j - 1], best[j]);
        best[j] = if kk < prev {
            prev
        } else if kk < cur {
            kk
        } else {
            cur
        };
    }
    best[0] = best[0].min(kk);
}

/// Largest buffer that [`sort_small`] sorts.
const NET_MAX: usize = 16;

/// Batcher's odd-even merge sorting network on `NET_MAX` inputs, restricted for each `n` to the
/// comparators within `0..n`: `NETS[n].0[..NETS[n].1]`. The restriction sorts `n` inputs because
/// padding the input with maximal values makes every dropped comparator a no-op.
const NETS: [([(u8, u8); 63], usize); NET_MAX + 1] = {
    let mut nets = [([(0u8, 0u8); 63], 0usize); NET_MAX + 1];
    let mut n = 0;
    while n <= NET_MAX {
        let mut p = 1;
        while p < NET_MAX {
            let mut k = p;
            while k >= 1 {
                let mut j = k % p;
                while j + k < NET_MAX {
                    let mut i = 0;
                    while i < k && i + j + k < NET_MAX {
                        let (a, b) = (i + j, i + j + k);
                        if a / (2 * p) == b / (2 * p) && b < n {
                            nets[n].0[nets[n].1] = (a as u8, b as u8);
                            nets[n].1 += 1;
                        }
                        i += 1;
                    }
                    j += 2 * k;
                }
                k /= 2;
            }
            p *= 2;
        }
        n += 1;
    }
    nets
};

/// Sorts `keys` (at most [`NET_MAX`] of them) with a fixed sequence of branch-free
/// compare-exchanges.
#[inline(always)]
fn sort_small(keys: &mut [u64]) {
    let (net, len) = &NETS[keys.len()];
    for &(a, b) in &net[..*len] {
        let (x, y) = (keys[a as usize], keys[b as usize]);
        keys[a as usize] = x.min(y);
        keys[b as usize] = x.max(y);
    }
}

/// Partitions `items` for a subtree with `levels` levels of internal nodes, whose nodes (in
/// pre-order, `2^levels - 1` of them) are `nodes`. Each node splits its range at the middle along
/// the axis of widest extent, so left points are `<= val` and right points `>= val` on that axis.
fn build_rec(items: &mut [Item], nodes: &mut [Node], levels: u32) {
    if levels == 0 {
        return;
    }
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    // The extent only picks the split axis (any axis keeps the tree exact), so large ranges
    // estimate it from an evenly strided sample of about `EXTENT_SAMPLE` points.
    for it in items.iter().step_by((items.len() / EXTENT_SAMPLE).max(1)) {
        for a in 0..3 {
            lo[a] = lo[a].min(it.p[a]);
            hi[a] = hi[a].max(it.p[a]);
        }
    }
    let mut dim = 0;
    let mut best = f32::NEG_INFINITY;
    for a in 0..3 {
        // Finite points only, so the extent is never NaN (it may overflow to +inf, still ordered).
        let ext = hi[a] - lo[a];
        if ext > best {
            best = ext;
            dim = a;
        }
    }
    let mid = items.len() / 2;
    let val = if mid < items.len() {
        items.select_nth_unstable_by(mid, |a, b| a.p[dim].total_cmp(&b.p[dim]));
        items[mid].p[dim]
    } else {
        0.0
    };
    nodes[0] = Node { val, dim: dim as u32 };
    let n = items.len();
    let (left_items, right_items) = items.split_at_mut(mid);
    let rest = &mut nodes[1..];
    let (left_nodes, right_nodes) = rest.split_at_mut(rest.len() / 2);
    if n > PAR_BUILD_MIN {
        par::join(
            || build_rec(left_items, left_nodes, levels - 1),
            || build_rec(right_items, right_nodes, levels - 1),
        );
    } else {
        build_rec(left_items, left_nodes, levels - 1);
        build_rec(right_items, right_nodes, levels - 1);
    }
}

/// Copies the subtree with `levels` internal levels from pre-order (`pre`, as [`build_rec`] lays it
/// out) to breadth-first order in `out`, its root going to `out[at]`.
fn breadth_first(pre: &[Node], levels: u32, at: usize, out: &mut [Node]) {
    if levels == 0 {
        return;
    }
    out[at] = pre[0];
    let (left, right) = pre[1..].split_at(pre.len() / 2);
    breadth_first(left, levels - 1, 2 * at + 1, out);
    breadth_first(right, levels - 1, 2 * at + 2, out);
}

/// Pushes the start of every leaf of the subtree over `lo..hi` with `levels` internal levels,
/// left to right, following the same middle split as [`build_rec`].
fn leaf_bounds(lo: usize, hi: usize, levels: u32, out: &mut Vec<usize>) {
    if levels == 0 {
        out.push(lo);
        return;
    }
    let mid = lo + (hi - lo) / 2;
    leaf_bounds(lo, mid, levels - 1, out);
    leaf_bounds(mid, hi, levels - 1, out);
}

/// Results of [`KdTree::knn_batch`]: `n_queries` rows of `k` neighbours, row-major, each row
/// sorted by `(dist_sq, index)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct KnnTable {
    /// Columns per row: `min(requested k, KdTree::num_indexed())`.
    pub k: usize,
    /// Number of rows (queries).
    pub n_queries: usize,
    /// `n_queries * k` caller indices.
    pub indices: Vec<u32>,
    /// `n_queries * k` squared distances.
    pub dist_sq: Vec<f32>,
}

impl KnnTable {
    /// Indices and squared distances of the neighbours of query `i`.
    ///
    /// # Panics
    /// If `i >= n_queries`.
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        assert!(i < self.n_queries, "KnnTable::row: row {i} out of {}", self.n_queries);
        let r = i * self.k..(i + 1) * self.k;
        (&self.indices[r.clone()], &self.dist_sq[r])
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.n_queries
    }

    /// `true` when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.n_queries == 0
    }
}

/// Results of [`KdTree::within_radius_batch`] in compressed rows: the neighbours of query `i` are
/// `offsets[i]..offsets[i + 1]` of `indices` and `dist_sq`, sorted by `(dist_sq, index)`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RadiusTable {
    /// `n_queries + 1` non-decreasing row starts, the first 0 and the last `indices.len()`.
    pub offsets: Vec<usize>,
    /// Caller indices of all rows, concatenated.
    pub indices: Vec<u32>,
    /// Squared distances, parallel to `indices`.
    pub dist_sq: Vec<f32>,
}

impl RadiusTable {
    /// Indices and squared distances of the neighbours of query `i`.
    ///
    /// # Panics
    /// If `i` is not a row.
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        assert!(i + 1 < self.offsets.len(), "RadiusTable::row: row {i} out of {}", self.len());
        let r = self.offsets[i]..self.offsets[i + 1];
        (&self.indices[r.clone()], &self.dist_sq[r])
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// `true` when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    fn brute_knn(points: &[[f32; 3]], q: [f32; 3], k: usize) -> Vec<Neighbor> {
        let mut all: Vec<Neighbor> = points
            .iter()
            .enumerate()
            .map(|(i, &p)| Neighbor { index: i as u32, dist_sq: dist_sq(q, p) })
            .collect();
        all.sort_by(|a, b| a.dist_sq.total_cmp(&b.dist_sq).then(a.index.cmp(&b.index)));
        all.truncate(k);
        all
    }

    fn cloud(n: usize, seed: u64) -> Vec<[f32; 3]> {
        let mut r = Rng::new(seed);
        (0..n).map(|_| [r.f32(), r.f32(), r.f32()]).collect()
    }

    #[test]
    fn leaves_never_exceed_bucket() {
        for n in (0..300).chain([1023, 1024, 1025, 4097, 4159, 100_001]) {
            let t = KdTree::build(&vec![[1.0f32; 3]; n]);
            let n_leaves = 1usize << t.depth;
            assert_eq!(t.nodes.len(), n_leaves - 1);
            assert_eq!((t.slot % LANES, t.idx.len()), (0, t.slot * n_leaves));
            let mut count = 0;
            for leaf in t.idx.chunks_exact(t.slot.max(1)) {
                // Points first, then padding.
                let used = leaf.iter().take_while(|&&i| i != NO_NEIGHBOR).count();
                assert!(used <= BUCKET && leaf[used..].iter().all(|&i| i == NO_NEIGHBOR), "n = {n}");
                count += used;
            }
            assert_eq!(count, n);
            let mut seen: Vec<u32> = t.idx.iter().copied().filter(|&i| i != NO_NEIGHBOR).collect();
            seen.sort_unstable();
            assert!(seen.iter().copied().eq(0..n as u32));
        }
    }

    #[test]
    fn small_sorting_networks_sort() {
        let mut r = Rng::new(7);
        for n in 0..=NET_MAX {
            for _ in 0..200 {
                // Few distinct values, so that ties are common.
                let mut v: Vec<u64> = (0..n).map(|_| r.below(6) as u64).collect();
                let mut want = v.clone();
                want.sort_unstable();
                sort_small(&mut v);
                assert_eq!(v, want, "n = {n}");
            }
        }
    }

    #[test]
    fn empty_and_one_point() {
        let t = KdTree::build(&[]);
        assert!(t.is_empty());
        let mut out = vec![Neighbor { index: 9, dist_sq: 1.0 }];
        t.knn([0.0; 3], 5, &mut out);
        assert!(out.is_empty());
        assert_eq!(t.nearest([0.0; 3]), None);
        let tab = t.knn_batch(&[[0.0; 3], [1.0; 3]], 3);
        assert_eq!((tab.k, tab.len()), (0, 2));
        assert!(tab.row(1).0.is_empty());
        let t = KdTree::build(&[[1.0, 2.0, 3.0]]);
        assert_eq!(t.nearest([1.0, 2.0, 4.0]), Some(Neighbor { index: 0, dist_sq: 1.0 }));
        t.within_radius([1.0, 2.0, 4.0], 0.5, &mut out);
        assert!(out.is_empty());
        t.within_radius([1.0, 2.0, 4.0], 1.0, &mut out);
        assert_eq!(out.len(), 1);
    }

    #[test]
    fn all_identical_points_tie_by_index() {
        let pts = vec![[0.5f32, -1.0, 2.0]; 1000];
        let t = KdTree::build(&pts);
        let mut out = Vec::new();
        t.knn([0.0; 3], 7, &mut out);
        assert_eq!(out.iter().map(|n| n.index).collect::<Vec<_>>(), (0..7).collect::<Vec<u32>>());
        t.within_radius([0.5, -1.0, 2.0], 0.0, &mut out);
        assert_eq!(out.len(), 1000);
        assert!(out.windows(2).all(|w| w[0].index < w[1].index));
    }

    #[test]
    fn non_finite_points_and_queries() {
        let mut pts = cloud(200, 3);
        pts[5] = [f32::NAN, 0.0, 0.0];
        pts[17] = [0.0, f32::INFINITY, 0.0];
        let t = KdTree::build(&pts);
        assert_eq!((t.len(), t.num_indexed()), (200, 198));
        let mut out = Vec::new();
        t.knn([0.5; 3], 500, &mut out);
        assert_eq!(out.len(), 198);
        assert!(out.iter().all(|n| n.index != 5 && n.index != 17));
        for q in [[f32::NAN, 0.0, 0.0], [0.0, 0.0, f32::NEG_INFINITY]] {
            t.knn(q, 3, &mut out);
            assert!(out.is_empty());
            t.within_radius(q, f32::INFINITY, &mut out);
            assert!(out.is_empty());
            assert_eq!(t.nearest(q), None);
        }
        t.within_radius([0.5; 3], f32::NAN, &mut out);
        assert!(out.is_empty());
        let tab = t.knn_batch(&[[f32::NAN; 3]], 2);
        assert_eq!(tab.row(0), (&[NO_NEIGHBOR; 2][..], &[f32::INFINITY; 2][..]));
    }

    #[test]
    fn huge_coordinates_overflowing_distances() {
        let pts = vec![[3e38f32, 0.0, 0.0], [-3e38, 0.0, 0.0], [0.0, 3e38, -3e38], [1.0, 1.0, 1.0]];
        let t = KdTree::build(&pts);
        let mut out = Vec::new();
        for q in [[-3e38f32, 1.0, 0.0], [0.0; 3], [3e38, 3e38, 3e38]] {
            for k in 0..6 {
                t.knn(q, k, &mut out);
                assert_eq!(out, brute_knn(&pts, q, k));
            }
        }
    }

    #[test]
    fn batch_equals_single_queries() {
        let pts = cloud(5000, 1);
        let qs = cloud(1500, 2);
        let t = KdTree::build(&pts);
        let tab = t.knn_batch(&qs, 9);
        let rt = t.within_radius_batch(&qs, 0.004);
        let mut out = Vec::new();
        for (i, &q) in qs.iter().enumerate() {
            t.knn(q, 9, &mut out);
            let (ii, dd) = tab.row(i);
            assert_eq!(ii, out.iter().map(|n| n.index).collect::<Vec<_>>());
            assert_eq!(dd, out.iter().map(|n| n.dist_sq).collect::<Vec<_>>());
            assert_eq!(out, brute_knn(&pts, q, 9));
            t.within_radius(q, 0.004, &mut out);
            let (ii, dd) = rt.row(i);
            assert_eq!(ii, out.iter().map(|n| n.index).collect::<Vec<_>>());
            assert_eq!(dd, out.iter().map(|n| n.dist_sq).collect::<Vec<_>>());
        }
    }
}
