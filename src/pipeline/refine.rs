//! Refinement of the classifier's probabilities by the candidates' neighbourhood (our
//! addition to the paper; docs/EXPERIMENTS.md, "End to end: session 4 … and session 5").
//!
//! The classifier scores every candidate on its own. Whether a candidate is a face
//! depends on its rivals too: in a manifold, consistently oriented quad mesh a directed
//! edge belongs to at most one face and a face's sides are shared, reversed, with its
//! neighbours. A refinement round reads, per candidate, its current probability and
//! what the other candidates' probabilities say about it ([`refine_features`]: the best
//! rival on each of its directed edges, the best neighbour across each edge, rivals over
//! its diagonals, the probability mass at its corners; since session 18 also how that
//! neighbour continues the candidate's lattice lines, [`refine_features_with`]), and a
//! small MLP gives a new probability. Rounds chain (round r reads round r − 1's output), like a few steps of
//! message passing over the candidate graph; each is trained on the previous round's
//! output over the training samples ([`train_refiner`]), with the classifier frozen.
//!
//! Every aggregate is sorted over the candidate's 4 edges (or corners), so the features
//! do not depend on which corner a candidate's cyclic order starts at, nor on the order
//! of the candidate list (property-tested against a brute-force reference).
//!
//! **Sides** ([`SideRule`]). Candidates are ordered counter-clockwise about the proposing
//! point's normal, and those normals are oriented by propagation, which leaves
//! orientation seams: on 1.5% of the pairs of adjacent ground-truth faces of `train/`
//! (7–12% on armadillo, feline, monkey and the thin shells), the two candidates run their
//! shared edge the same way, so by direction alone the true neighbour reads as a rival.
//! [`SideRule::Normals`] (models refined since session 8) also compares the two
//! candidates' own normals ([`opposite_normals`]); [`SideRule::Direction`] is the session-5 rule
//! that older model files keep.

use crate::nn::conv1d::Conv1d;
use crate::nn::loss::weighted_cross_entropy;
use crate::nn::module::Module;
use crate::nn::optim::{ExpDecay, Sgd, SgdConfig};
use crate::pipeline::candidates::{canonical, dot as dot3, norm as norm3, sub as sub3, InsideTest};
use crate::rng::Rng;
use crate::tensor::{Grads, Graph, ParamId, ParamKind, ParamStore, Tensor, Var};
use crate::{Error, Result};

/// Values per candidate read by a refinement round of [`RefineInput::Base`]
/// ([`refine_features`]).
pub const REFINE_DIM: usize = 27;

/// Values per candidate read by a round of [`RefineInput::Flow`]: [`REFINE_DIM`] and
/// the 8 flow columns.
pub const FLOW_DIM: usize = REFINE_DIM + 8;

/// Values per candidate read by a round of [`RefineInput::Inside`]: [`FLOW_DIM`] and
/// the 2 inside columns.
pub const INSIDE_DIM: usize = FLOW_DIM + 2;

/// The inside test of the rounds' [`inside_points`]: the candidate ranking's default
/// plane tolerance and edge margin, as fractions of the mean edge length.
pub use crate::pipeline::candidates::{
    DEFAULT_INSIDE_MARGIN as INSIDE_MARGIN, DEFAULT_INSIDE_PLANE_TOL as INSIDE_PLANE_TOL,
};

/// What a refinement round reads, fixed when the rounds are trained (`refine_input` in
/// a model's config; models refined before session 18 have `Base`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RefineInput {
    /// The probability columns of [`refine_features`] ([`REFINE_DIM`]).
    Base,
    /// Those and, per edge, how the best neighbour across it continues the candidate's
    /// lattice ([`FLOW_DIM`]; [`refine_features_with`] documents the columns). Needs
    /// [`SideRule::Normals`].
    Flow,
    /// Those and how much the points inside the candidate look like vertices of the
    /// mesh ([`INSIDE_DIM`]; session 23): a quad spanning a point that likely faces use
    /// as a corner covers a vertex, so it is not a face. Needs [`SideRule::Normals`].
    Inside,
}

impl RefineInput {
    /// Columns per candidate.
    pub fn dim(self) -> usize {
        match self {
            RefineInput::Base => REFINE_DIM,
            RefineInput::Flow => FLOW_DIM,
            RefineInput::Inside => INSIDE_DIM,
        }
    }

    /// Whether the flow columns are read ([`RefineInput::Flow`] and
    /// [`RefineInput::Inside`]); they need [`SideRule::Normals`].
    pub fn reads_flow(self) -> bool {
        self != RefineInput::Base
    }

    /// `base` / `flow` / `inside`, as model files and `refine --features` spell it.
    pub fn name(self) -> &'static str {
        match self {
            RefineInput::Base => "base",
            RefineInput::Flow => "flow",
            RefineInput::Inside => "inside",
        }
    }

    /// Inverse of [`RefineInput::name`].
    pub fn from_name(s: &str) -> Option<RefineInput> {
        match s {
            "base" => Some(RefineInput::Base),
            "flow" => Some(RefineInput::Flow),
            "inside" => Some(RefineInput::Inside),
            _ => None,
        }
    }
}

/// Probabilities are clamped to `[EPS, 1 − EPS]` before taking logits.
const EPS: f32 = 1e-6;

fn logit(p: f32) -> f32 {
    let p = p.clamp(EPS, 1.0 - EPS);
    (p / (1.0 - p)).ln()
}

/// Candidates grouped by what they share, built once per candidate set: the
/// candidates holding each directed edge, and those holding each unordered pair of
/// points (as an edge or a diagonal). Each refinement round then only reads the
/// groups' best probabilities ([`CandidateGraph::features`]).
#[derive(Clone, Debug)]
pub struct CandidateGraph {
    quads: Vec<[u32; 4]>,
    n_points: usize,
    /// What [`CandidateGraph::features`] computes.
    input: RefineInput,
    /// The positions, kept for [`RefineInput::Flow`] and [`RefineInput::Inside`] (empty
    /// otherwise).
    pts: Vec<[f32; 3]>,
    /// Per candidate, the mean length of its four edges (the flow columns' size ratio;
    /// empty where the input has no flow columns).
    mean_edge: Vec<f32>,
    /// For [`RefineInput::Inside`], [`inside_points`]: per candidate the points inside
    /// it, as (starts, one more than the candidates; points). Empty otherwise.
    inside: (Vec<u32>, Vec<u32>),
    /// Unordered pairs; slot `6·c + j` is pair j of candidate c (edges 0–3, then the
    /// diagonals (q0, q2), (q1, q3)).
    pairs: Groups,
    /// What the graph's [`SideRule`] reads sides from.
    sides: Sides,
}

/// Candidates per chunk of feature rows (one task of the thread pool).
const FEATURE_ROWS: usize = 256;

/// What one round's feature rows read beyond their own candidates
/// (`CandidateGraph::round_context`).
struct RoundContext {
    /// Per group of directed edges (`SideRule::Direction` only), [`group_best`].
    dir_best: Vec<(f32, u32, f32)>,
    /// Per pair group, [`group_best`].
    pair: Vec<(f32, u32, f32)>,
    /// Per point, the summed probability of the candidates at it.
    mass: Vec<f64>,
    /// Per point, how many candidates at it are above 0.5.
    high: Vec<u32>,
}

/// The per-rule part of a [`CandidateGraph`].
#[derive(Clone, Debug)]
enum Sides {
    /// [`SideRule::Direction`]: the directed edges (slot `4·c + i` is edge
    /// (q_i → q_{i+1}) of candidate c), and per slot the group of the reversed edge
    /// (`NONE` when no candidate has it).
    Direction { dir: Groups, rev_group: Vec<u32> },
    /// [`SideRule::Normals`]: each candidate's [`quad_normal`], and per member of the
    /// pair groups how that member holds the pair ([`EDGE_DIAGONAL`], [`EDGE_LO_HI`],
    /// [`EDGE_HI_LO`]), so that a round's scan reads neither its corners nor diagonals.
    Normals(Vec<[f32; 3]>, Vec<u8>),
}

/// How a refinement round decides which candidates sharing an edge lie on the same side
/// of it (a rival) and which across it (a neighbour). See the module header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SideRule {
    /// By the direction they run the edge alone: the same way = the same side (exact
    /// where the candidates' orders are consistently oriented).
    Direction,
    /// By direction, reversed where the two candidates' normals ([`quad_normal`]) point
    /// opposite ways ([`opposite_normals`]).
    Normals,
}

impl SideRule {
    /// `direction` / `normals`, as model files and `refine --sides` spell it.
    pub fn name(self) -> &'static str {
        match self {
            SideRule::Direction => "direction",
            SideRule::Normals => "normals",
        }
    }

    /// Inverse of [`SideRule::name`].
    pub fn from_name(s: &str) -> Option<SideRule> {
        match s {
            "direction" => Some(SideRule::Direction),
            "normals" => Some(SideRule::Normals),
            _ => None,
        }
    }
}

pub use crate::mesh::postprocess::opposite_normals;

/// Unit normal of quad `q` over `points` from its cyclic order: (q2 − q0) × (q3 − q1)
/// normalised; zero for a degenerate quad.
pub fn quad_normal(points: &[[f32; 3]], q: [u32; 4]) -> [f32; 3] {
    crate::pipeline::candidates::diagonal_normal(q.map(|i| points[i as usize]))
}

/// "No group" (a reversed edge no candidate has).
const NONE: u32 = u32::MAX;

/// A pair-group member that holds the pair as a diagonal.
const EDGE_DIAGONAL: u8 = 0;
/// ... as an edge running from the smaller point index to the larger.
const EDGE_LO_HI: u8 = 1;
/// ... as an edge running from the larger point index to the smaller.
const EDGE_HI_LO: u8 = 2;

/// Entries `(a, b, slot)` grouped by the pair (a, b): by a counting sort on `a`
/// (points index below `n`), then a sort on (b, slot) within each point's bucket, so
/// members of a group are in slot order.
#[derive(Clone, Debug)]
struct Groups {
    /// Member candidates (`slot / per`), group after group.
    members: Vec<u32>,
    /// Group starts in `members` (one more than the groups).
    start: Vec<u32>,
    /// Per slot: its group.
    of_slot: Vec<u32>,
    /// Per group: its `b`.
    second: Vec<u32>,
    /// Per point `a`: the range of its groups (`n + 1` offsets).
    by_first: Vec<u32>,
}

impl Groups {
    /// The groups of `entries()`'s (a, b, slot) triples (each slot once, slots below
    /// `len`), with member `slot / per`. `entries` is called twice (a count, then a
    /// fill) rather than collected: at millions of candidates the list would be the
    /// largest buffer of the graph.
    fn new<I: Iterator<Item = (u32, u32, u32)>>(
        n: usize,
        len: usize,
        entries: impl Fn() -> I,
        per: u32,
    ) -> Groups {
        let mut offs = vec![0u32; n + 1];
        for (a, _, _) in entries() {
            offs[a as usize + 1] += 1;
        }
        for i in 0..n {
            offs[i + 1] += offs[i];
        }
        let mut cursor = offs.clone();
        let mut sorted = vec![(0u32, 0u32); len];
        for (a, b, slot) in entries() {
            let c = &mut cursor[a as usize];
            sorted[*c as usize] = (b, slot);
            *c += 1;
        }
        let mut members = Vec::with_capacity(len);
        let mut start = Vec::new();
        let mut second = Vec::new();
        let mut of_slot = vec![0u32; len];
        let mut by_first = Vec::with_capacity(n + 1);
        for a in 0..n {
            by_first.push(start.len() as u32);
            let bucket = &mut sorted[offs[a] as usize..offs[a + 1] as usize];
            bucket.sort_unstable();
            for (i, &(b, slot)) in bucket.iter().enumerate() {
                if i == 0 || b != bucket[i - 1].0 {
                    start.push(members.len() as u32);
                    second.push(b);
                }
                of_slot[slot as usize] = (start.len() - 1) as u32;
                members.push(slot / per);
            }
        }
        by_first.push(start.len() as u32);
        start.push(members.len() as u32);
        Groups { members, start, of_slot, second, by_first }
    }

    /// The group of pair (a, b), `NONE` when no entry has it.
    fn find(&self, a: u32, b: u32) -> u32 {
        let (lo, hi) = (self.by_first[a as usize] as usize, self.by_first[a as usize + 1] as usize);
        match self.second[lo..hi].binary_search(&b) {
            Ok(i) => (lo + i) as u32,
            Err(_) => NONE,
        }
    }
}

/// Per group: the best probability, its owner, and the best of the others.
fn group_best(members: &[u32], start: &[u32], probs: &[f32]) -> Vec<(f32, u32, f32)> {
    crate::par::map(start.len().saturating_sub(1), |g| {
        let (mut top, mut owner, mut second) = (f32::NEG_INFINITY, NONE, 0.0f32);
        for &c in &members[start[g] as usize..start[g + 1] as usize] {
            let p = probs[c as usize];
            if p > top {
                second = second.max(top);
                top = p;
                owner = c;
            } else if p > second {
                second = p;
            }
        }
        (top, owner, second)
    })
}

/// The best probability in group `g` among candidates other than `me` (0 when none).
fn best_other(best: &[(f32, u32, f32)], g: u32, me: u32) -> f32 {
    if g == NONE {
        return 0.0;
    }
    let (top, owner, second) = best[g as usize];
    if owner == me {
        second
    } else {
        top
    }
}

fn sorted4(mut v: [f32; 4]) -> [f32; 4] {
    v.sort_unstable_by(f32::total_cmp);
    v
}

/// The mean length of quad `q`'s four edges (edge k from corner k to k + 1).
fn mean_edge(points: &[[f32; 3]], q: [u32; 4]) -> f32 {
    let p = |v: u32| points[v as usize];
    (0..4).map(|k| norm3(sub3(p(q[(k + 1) % 4]), p(q[k])))).sum::<f32>() / 4.0
}

impl CandidateGraph {
    /// Groups `quads` (corners index `points`) for rounds that read sides by `rule`
    /// (only [`SideRule::Normals`] reads the positions).
    ///
    /// # Errors
    /// `InvalidInput` naming the first candidate with a corner `>= points.len()` or a
    /// repeated corner, or for more than 2^29 candidates.
    pub fn new(quads: &[[u32; 4]], points: &[[f32; 3]], rule: SideRule) -> Result<CandidateGraph> {
        CandidateGraph::with_input(quads, points, rule, RefineInput::Base)
    }

    /// As [`CandidateGraph::new`], for rounds that read `input`.
    ///
    /// # Errors
    /// As [`CandidateGraph::new`]; `InvalidInput` for [`RefineInput::Flow`] or
    /// [`RefineInput::Inside`] with [`SideRule::Direction`] (the flow columns need each
    /// neighbour's identity, which only the normals rule scans for).
    pub fn with_input(
        quads: &[[u32; 4]],
        points: &[[f32; 3]],
        rule: SideRule,
        input: RefineInput,
    ) -> Result<CandidateGraph> {
        if input.reads_flow() && rule != SideRule::Normals {
            return Err(Error::invalid(format!(
                "refinement input {} needs sides read by normals",
                input.name()
            )));
        }
        let n_points = points.len();
        crate::pipeline::model::check_corners(quads, n_points)?;
        if let Some(c) = quads.iter().position(|q| (0..4).any(|i| (i + 1..4).any(|j| q[i] == q[j]))) {
            return Err(Error::invalid(format!("candidate {c} {:?} repeats a corner", quads[c])));
        }
        let m = quads.len();
        if m >= (1 << 29) {
            return Err(Error::invalid("refine: more than 2^29 candidates"));
        }
        // Directed edges (a, b, 4·c + i) and unordered pairs (lo, hi, 6·c + j): edges
        // 0–3, then the diagonals (q0, q2), (q1, q3).
        let directed = || {
            quads
                .iter()
                .zip(0u32..)
                .flat_map(|(q, c)| (0..4).map(move |i| (q[i], q[(i + 1) % 4], 4 * c + i as u32)))
        };
        let unordered = || {
            quads.iter().zip(0u32..).flat_map(|(q, c)| {
                let ends =
                    [(q[0], q[1]), (q[1], q[2]), (q[2], q[3]), (q[3], q[0]), (q[0], q[2]), (q[1], q[3])];
                (0..6).map(move |j| {
                    let (a, b) = ends[j];
                    (a.min(b), a.max(b), 6 * c + j as u32)
                })
            })
        };
        let (sides, pairs) = match rule {
            SideRule::Direction => {
                let (dir, pairs) = crate::par::join(
                    || Groups::new(n_points, 4 * m, directed, 4),
                    || Groups::new(n_points, 6 * m, unordered, 6),
                );
                let rev_group =
                    quads.iter().flat_map(|q| (0..4).map(|i| dir.find(q[(i + 1) % 4], q[i]))).collect();
                (Sides::Direction { dir, rev_group }, pairs)
            }
            SideRule::Normals => {
                let pairs = Groups::new(n_points, 6 * m, unordered, 6);
                // Which of member d's pairs group g is: the slot of d that maps to g.
                let mut tags = Vec::with_capacity(pairs.members.len());
                for g in 0..pairs.start.len() - 1 {
                    for &d in &pairs.members[pairs.start[g] as usize..pairs.start[g + 1] as usize] {
                        let (q, d) = (quads[d as usize], d as usize);
                        tags.push(match (0..6).position(|j| pairs.of_slot[6 * d + j] as usize == g) {
                            Some(j) if j < 4 && q[j] < q[(j + 1) % 4] => EDGE_LO_HI,
                            Some(j) if j < 4 => EDGE_HI_LO,
                            _ => EDGE_DIAGONAL,
                        });
                    }
                }
                (Sides::Normals(crate::par::map(quads.len(), |c| quad_normal(points, quads[c])), tags), pairs)
            }
        };
        let pts = if input.reads_flow() { points.to_vec() } else { Vec::new() };
        let mean_edge =
            if input.reads_flow() { crate::par::map(m, |c| mean_edge(points, quads[c])) } else { Vec::new() };
        let inside = if input == RefineInput::Inside {
            inside_points(points, quads, INSIDE_PLANE_TOL, INSIDE_MARGIN)
        } else {
            (Vec::new(), Vec::new())
        };
        Ok(CandidateGraph { quads: quads.to_vec(), n_points, input, pts, mean_edge, inside, pairs, sides })
    }

    /// Under [`SideRule::Normals`]: the best rival and the best neighbour of candidate
    /// `c` on its edge `i` (and that neighbour; `NONE` when there is none), scanning the
    /// other candidates that hold that pair of points as an edge.
    fn sides_by_normals(
        &self,
        nrm: &[[f32; 3]],
        tags: &[u8],
        probs: &[f32],
        c: usize,
        i: usize,
    ) -> (f32, f32, u32) {
        let q = self.quads[c];
        let (a, b) = (q[i], q[(i + 1) % 4]);
        // How a member running the pair as c does (a → b) is tagged.
        let same_way = if a < b { EDGE_LO_HI } else { EDGE_HI_LO };
        let g = self.pairs.of_slot[6 * c + i] as usize;
        let (mut rival, mut across, mut across_id) = (0.0f32, 0.0f32, NONE);
        let range = self.pairs.start[g] as usize..self.pairs.start[g + 1] as usize;
        for (&d, &tag) in self.pairs.members[range.clone()].iter().zip(&tags[range]) {
            // A member holding the pair as its diagonal is neither rival nor neighbour.
            if tag == EDGE_DIAGONAL || d as usize == c {
                continue;
            }
            let fwd = tag == same_way;
            let pd = probs[d as usize];
            let opp = opposite_normals(nrm[c], nrm[d as usize]);
            if fwd != opp {
                rival = rival.max(pd);
            } else {
                // Among equally probable neighbours the flow columns take the one whose
                // cyclic order, started at its smallest corner, is smallest: the first
                // of them in `candidates::generate`'s order, and independent of the
                // order of the list.
                let better = across_id == NONE
                    || pd > across
                    || (pd == across
                        && canonical(self.quads[d as usize]) < canonical(self.quads[across_id as usize]));
                if better {
                    across = pd;
                    across_id = d;
                }
            }
        }
        (rival, across, across_id)
    }

    /// How neighbour `d` continues candidate `c` across c's edge i = (a, b): at a, the
    /// cosine between c's side arriving at a (q_{i−1} → a) and d's other side leaving a;
    /// the same at b (q_{i+2} → b); the smaller of the two (1: both lattice lines go
    /// straight on), and ln(mean edge of d / mean edge of c). (0, 0) when d does not
    /// hold (a, b) as an edge or a length is zero.
    fn flow(&self, c: usize, i: usize, d: u32) -> (f32, f32) {
        let p = |v: u32| self.pts[v as usize];
        let q = self.quads[c];
        let qd = self.quads[d as usize];
        let (a, b) = (q[i], q[(i + 1) % 4]);
        let other = |v: u32, w: u32| -> Option<u32> {
            let j = qd.iter().position(|&x| x == v)?;
            let (n1, n2) = (qd[(j + 1) % 4], qd[(j + 3) % 4]);
            if n1 == w {
                Some(n2)
            } else if n2 == w {
                Some(n1)
            } else {
                None
            }
        };
        let cosv = |u: [f32; 3], v: [f32; 3]| {
            let l = norm3(u) * norm3(v);
            if l > 0.0 {
                dot3(u, v) / l
            } else {
                0.0
            }
        };
        let (Some(x), Some(y)) = (other(a, b), other(b, a)) else { return (0.0, 0.0) };
        let sa = cosv(sub3(p(a), p(q[(i + 3) % 4])), sub3(p(x), p(a)));
        let sb = cosv(sub3(p(b), p(q[(i + 2) % 4])), sub3(p(y), p(b)));
        let (lc, ld) = (self.mean_edge[c], self.mean_edge[d as usize]);
        let ratio = if lc > 0.0 && ld > 0.0 { (ld / lc).ln() } else { 0.0 };
        (sa.min(sb), ratio)
    }

    /// The refinement input of every candidate ([`refine_features`] documents the
    /// columns) from the current probabilities `probs` and the classifier's `base`.
    ///
    /// # Errors
    /// `InvalidInput` when a length differs from the candidate count or a probability
    /// is not a number in [0, 1] (naming the candidate).
    pub fn features(&self, probs: &[f32], base: &[f32]) -> Result<Vec<f32>> {
        let ctx = self.round_context(probs, base)?;
        let dim = self.input.dim();
        let mut out = vec![0.0f32; self.quads.len() * dim];
        crate::par::for_each_chunk_mut(&mut out, dim * FEATURE_ROWS, |ch, chunk| {
            self.fill_rows(&ctx, probs, base, ch * FEATURE_ROWS, chunk);
        });
        Ok(out)
    }

    /// What every row of a round reads beyond its own candidate: the checks of
    /// [`CandidateGraph::features`], the best members of the groups, and the per-point
    /// probability mass and count above 0.5.
    fn round_context(&self, probs: &[f32], base: &[f32]) -> Result<RoundContext> {
        let m = self.quads.len();
        if probs.len() != m || base.len() != m {
            return Err(Error::invalid(format!(
                "refine features: {m} candidates, {} probabilities, {} base probabilities",
                probs.len(),
                base.len()
            )));
        }
        for (what, v) in [("probability", probs), ("base probability", base)] {
            if let Some(c) = v.iter().position(|p| !(0.0..=1.0).contains(p)) {
                return Err(Error::invalid(format!("refine features: candidate {c} has {what} {}", v[c])));
            }
        }
        let dir_best = match &self.sides {
            Sides::Direction { dir, .. } => group_best(&dir.members, &dir.start, probs),
            Sides::Normals(..) => Vec::new(),
        };
        let pair = group_best(&self.pairs.members, &self.pairs.start, probs);
        let mut mass = vec![0.0f64; self.n_points];
        let mut high = vec![0u32; self.n_points];
        for (q, &p) in self.quads.iter().zip(probs) {
            for &v in q {
                mass[v as usize] += p as f64;
                high[v as usize] += (p > 0.5) as u32;
            }
        }
        Ok(RoundContext { dir_best, pair, mass, high })
    }

    /// The feature rows of candidates `first..` into `chunk` (whole rows of
    /// `self.input.dim()` values; as many as fit).
    fn fill_rows(&self, ctx: &RoundContext, probs: &[f32], base: &[f32], first: usize, chunk: &mut [f32]) {
        let RoundContext { dir_best, pair, mass, high } = ctx;
        let dim = self.input.dim();
        let flow = self.input.reads_flow();
        let inside = self.input == RefineInput::Inside;
        for (r, row) in chunk.chunks_exact_mut(dim).enumerate() {
            let c = first + r;
            let (q, p) = (self.quads[c], probs[c]);
            let me = c as u32;
            let (mut rival, mut across, mut shared) = ([0.0f32; 4], [0.0f32; 4], [0.0f32; 4]);
            let (mut at, mut hi) = ([0.0f32; 4], [0.0f32; 4]);
            let (mut fl, mut sz) = ([0.0f32; 4], [0.0f32; 4]);
            for i in 0..4 {
                let nb;
                (rival[i], across[i], nb) = match &self.sides {
                    Sides::Direction { dir, rev_group } => (
                        best_other(dir_best, dir.of_slot[4 * c + i], me),
                        best_other(dir_best, rev_group[4 * c + i], me),
                        NONE,
                    ),
                    Sides::Normals(nrm, tags) => self.sides_by_normals(nrm, tags, probs, c, i),
                };
                if flow && nb != NONE {
                    let (f, r) = self.flow(c, i, nb);
                    fl[i] = across[i] * f;
                    sz[i] = across[i] * r.abs();
                }
                shared[i] = best_other(pair, self.pairs.of_slot[6 * c + i], me);
                let a = q[i] as usize;
                at[i] = (mass[a] - p as f64) as f32;
                hi[i] = (high[a] - (p > 0.5) as u32) as f32 / 4.0;
            }
            let diff = [0, 1, 2, 3].map(|i| across[i] - rival[i]);
            let diag = best_other(pair, self.pairs.of_slot[6 * c + 4], me).max(best_other(
                pair,
                self.pairs.of_slot[6 * c + 5],
                me,
            ));
            row[0] = logit(p);
            row[1..5].copy_from_slice(&sorted4(rival));
            row[5..9].copy_from_slice(&sorted4(across));
            row[9..13].copy_from_slice(&sorted4(diff));
            row[13] = diag;
            row[14..18].copy_from_slice(&sorted4(at));
            row[18..22].copy_from_slice(&sorted4(hi));
            row[22..26].copy_from_slice(&sorted4(shared));
            row[26] = logit(base[c]);
            if flow {
                row[27..31].copy_from_slice(&sorted4(fl));
                row[31..35].copy_from_slice(&sorted4(sz));
            }
            if inside {
                let (start, pts) = &self.inside;
                let (mut m_in, mut h_in) = (0.0f64, 0u32);
                for &v in &pts[start[c] as usize..start[c + 1] as usize] {
                    m_in = m_in.max(mass[v as usize]);
                    h_in = h_in.max(high[v as usize]);
                }
                row[35] = m_in as f32;
                row[36] = h_in as f32 / 4.0;
            }
        }
    }
}

/// The refinement input of every candidate, `M × REFINE_DIM` row-major, from the
/// current probabilities `probs` and the classifier's own `base` (both one per
/// candidate, in [0, 1]). `n_points` bounds the corner indices. Columns (each group of
/// four sorted ascending; "other" = any candidate but this one):
///
/// * 0: logit of this candidate's current probability;
/// * 1–4: per edge (q_i → q_{i+1}), the best other candidate with that edge on the
///   same side (a rival: at most one of them can be a face). Sides by the graph's
///   [`SideRule`]: under `Direction`, the candidates with the same directed edge;
/// * 5–8: per edge, the best other candidate with that edge on the other side (a
///   neighbour across it; under `Direction`, those with the reversed edge);
/// * 9–12: per edge, neighbour minus rival (columns 5–8 minus 1–4, edge by edge);
/// * 13: the best other candidate holding both ends of one of this one's diagonals
///   (as an edge or a diagonal: it overlaps this one);
/// * 14–17: per corner, the sum of the other candidates' probabilities at that point;
/// * 18–21: per corner, the number of other candidates above 0.5 at that point, / 4;
/// * 22–25: per edge, the best other candidate holding both its ends (as an edge
///   either way, or as a diagonal);
/// * 26: logit of the classifier's probability.
///
/// ("Best" is the highest probability, 0 when there is none.) Rounds over one
/// candidate set build the [`CandidateGraph`] once and call its `features`.
///
/// # Errors
/// As [`CandidateGraph::new`] and [`CandidateGraph::features`].
pub fn refine_features(
    quads: &[[u32; 4]],
    points: &[[f32; 3]],
    rule: SideRule,
    probs: &[f32],
    base: &[f32],
) -> Result<Vec<f32>> {
    CandidateGraph::new(quads, points, rule)?.features(probs, base)
}

/// The input of rounds that read `input`, `M × input.dim()` row-major. For
/// [`RefineInput::Base`] the columns of [`refine_features`]; for [`RefineInput::Flow`]
/// those 27 and (each group of four sorted ascending; n_i = the best neighbour across
/// edge i under [`SideRule::Normals`] — among equally probable ones the one whose
/// cyclic order started at its smallest corner is lexicographically smallest — and p_i
/// its probability, column 5 + i before sorting; both 0 when edge i has none):
///
/// * 27–30: per edge, p_i × the straightness of the lattice lines n_i continues: at each
///   end of the edge, the cosine between the candidate's side arriving there and n_i's
///   other side leaving it; the smaller of the two (1 on a regular grid);
/// * 31–34: per edge, p_i × |ln(mean edge length of n_i / that of the candidate)|.
///
/// For [`RefineInput::Inside`] those 35 and (session 23; the points inside a candidate
/// are those of [`inside_points`], none of its corners):
///
/// * 35: the largest probability mass (column 14's sum, over all candidates) at a
///   point inside the candidate, 0 when none is: a vertex the likely faces use;
/// * 36: the largest number of candidates above 0.5 at a point inside it, / 4.
///
/// The flow and inside columns are invariant under rotation, translation and uniform
/// scaling of the points, like the rest.
///
/// # Errors
/// As [`CandidateGraph::with_input`] and [`CandidateGraph::features`].
pub fn refine_features_with(
    quads: &[[u32; 4]],
    points: &[[f32; 3]],
    rule: SideRule,
    input: RefineInput,
    probs: &[f32],
    base: &[f32],
) -> Result<Vec<f32>> {
    CandidateGraph::with_input(quads, points, rule, input)?.features(probs, base)
}

/// Per candidate, the points other than its corners that lie in it by the candidate
/// ranking's inside test (`candidates::InsideTest`): within `plane_tol · L̄` of the plane through its centre normal
/// to [`quad_normal`], and no farther than `margin · L̄` outside any of its edge lines
/// (L̄ its mean edge length). As (starts, one more than the candidates; points, each
/// candidate's ascending). A candidate with a zero-length edge or a zero normal has
/// none. The search reaches every passing point of a convex quad (every candidate is
/// one): its corners widened by the margin, m / sin(θ/2) for a corner of angle θ in the
/// plane; a quad with a corner under 0.1° or a reflex one gets the whole cloud
/// searched.
///
/// # Panics
/// If a corner indexes beyond `points`.
pub fn inside_points(
    points: &[[f32; 3]],
    quads: &[[u32; 4]],
    plane_tol: f32,
    margin: f32,
) -> (Vec<u32>, Vec<u32>) {
    let tree = crate::spatial::kdtree::KdTree::build(points);
    const CHUNK: usize = 1024;
    let lists: Vec<(Vec<u32>, Vec<u32>)> = crate::par::map(quads.len().div_ceil(CHUNK), |ch| {
        let (mut counts, mut members, mut near) = (Vec::new(), Vec::new(), Vec::new());
        for &q in &quads[ch * CHUNK..((ch + 1) * CHUNK).min(quads.len())] {
            let before = members.len();
            let p = q.map(|v| points[v as usize]);
            let n = quad_normal(points, q);
            let len = [0, 1, 2, 3].map(|e| norm3(sub3(p[(e + 1) % 4], p[e])));
            if n != [0.0; 3] && len.iter().all(|&l| l > 0.0 && l.is_finite()) {
                let test = InsideTest::new(p, n, len, plane_tol, margin);
                let (centre, (tol, m)) = (test.centre(), test.bounds());
                // A search radius that holds every passing point: a corner of the quad
                // widened by the margin lies within m / sin(half its angle) of the
                // corner (angles in the plane normal to n).
                let flat = |d: [f32; 3]| sub3(d, n.map(|x| x * dot3(d, n)));
                let mut widen = 0.0f32;
                for k in 0..4 {
                    let (u, v) = (flat(sub3(p[(k + 1) % 4], p[k])), flat(sub3(p[(k + 3) % 4], p[k])));
                    let c = crate::pipeline::candidates::cross(u, v);
                    let angle = norm3(c).atan2(dot3(u, v));
                    let half = (0.5 * angle).sin();
                    // A reflex corner (the turn against n) or one under 0.1°: search all.
                    let convex = dot3(c, n) > 0.0 && half > 1e-3;
                    widen = widen.max(if convex { m / half } else { f32::INFINITY });
                }
                let reach = p.iter().map(|c| norm3(sub3(*c, centre))).fold(0.0f32, f32::max) + widen;
                let r2 = reach * reach + tol * tol;
                tree.within_radius(centre, if r2.is_finite() { r2 } else { f32::MAX }, &mut near);
                for x in &near {
                    let v = x.index;
                    if q.contains(&v) {
                        continue;
                    }
                    if test.holds(&points[v as usize]) {
                        members.push(v);
                    }
                }
                members[before..].sort_unstable();
            }
            counts.push((members.len() - before) as u32);
        }
        (counts, members)
    });
    let mut start = Vec::with_capacity(quads.len() + 1);
    start.push(0u32);
    let mut all = Vec::new();
    for (counts, members) in lists {
        for c in counts {
            start.push(start.last().copied().unwrap_or(0) + c);
        }
        all.extend(members);
    }
    (start, all)
}

/// A layer's weight transposed (`[cin × cout]`), bias (borrowed from the store), `cin`
/// and `cout`.
type LayerRef<'a> = (Vec<f32>, Option<&'a [f32]>, usize, usize);

/// [`affine_row`] for `y.len() == N`.
#[inline]
fn affine_row_fixed<const N: usize>(wt: &[f32], bias: Option<&[f32]>, x: &[f32], y: &mut [f32]) {
    let mut acc = [0.0f32; N];
    if let Some(b) = bias {
        acc.copy_from_slice(b);
    }
    for (xj, col) in x.iter().zip(wt.chunks_exact(N)) {
        for (yk, wk) in acc.iter_mut().zip(col) {
            *yk += wk * xj;
        }
    }
    y.copy_from_slice(&acc);
}

/// One round's MLP for row-by-row inference (`Refiner::round_mlp`).
struct RoundMlp<'p> {
    /// The input standardisation: `(x − mean) · scale`.
    mean: &'p [f32],
    scale: &'p [f32],
    layers: Vec<LayerRef<'p>>,
    /// The widest layer or input: the length of each work buffer.
    width: usize,
}

impl RoundMlp<'_> {
    /// Two work buffers for [`RoundMlp::row`].
    fn buffers(&self) -> (Vec<f32>, Vec<f32>) {
        (vec![0.0f32; self.width], vec![0.0f32; self.width])
    }

    /// The face probability of one feature row (`standardised`: the row went through
    /// the round's standardisation already).
    fn row(&self, row: &[f32], standardised: bool, buf: &mut (Vec<f32>, Vec<f32>)) -> f32 {
        let (x, y) = buf;
        for (j, &v) in row.iter().enumerate() {
            x[j] = if standardised { v } else { (v - self.mean[j]) * self.scale[j] };
        }
        for (l, (wt, b, cin, cout)) in self.layers.iter().enumerate() {
            affine_row(wt, *b, &x[..*cin], &mut y[..*cout]);
            if l + 1 < self.layers.len() {
                for v in &mut y[..*cout] {
                    *v = v.max(0.0);
                }
            }
            std::mem::swap(x, y);
        }
        crate::pipeline::model::face_probability(x[0], x[1])
    }
}

/// `y[..cout] = bias + W x` for one row, with `wt` the weight transposed (`[cin × cout]`,
/// so that the inner loop runs over contiguous outputs and vectorises). Each output is
/// summed in input order, bias first, a product and then a sum per input.
///
/// Until session 38 inputs that are exactly 0 (ReLU's, about half of them) were
/// skipped; the branch cost more than the products it saved. With finite weights the
/// two give the same values: adding 0 · w = ±0 changes a partial sum only where that
/// sum is itself ±0, and then only the sign of that zero, which the next layer cannot
/// see (a ±0 input adds ±0 again) and the final logits' difference cannot either.
/// `affine_row_equals_the_sum_that_skips_zero_inputs` and the shipped weights' outputs
/// (byte-identical meshes on `eval/` and the probe) check it.
fn affine_row(wt: &[f32], bias: Option<&[f32]>, x: &[f32], y: &mut [f32]) {
    // The widths the shipped rounds use get an accumulator of fixed size, which stays
    // in registers; the arithmetic is the same, output by output and input by input.
    match y.len() {
        32 => affine_row_fixed::<32>(wt, bias, x, y),
        2 => affine_row_fixed::<2>(wt, bias, x, y),
        cout => {
            match bias {
                Some(b) => y.copy_from_slice(b),
                None => y.fill(0.0),
            }
            for (xj, col) in x.iter().zip(wt.chunks_exact(cout)) {
                for (yk, wk) in y.iter_mut().zip(col) {
                    *yk += wk * xj;
                }
            }
        }
    }
}

/// One refinement round: input standardisation (stored buffers) and an MLP
/// (linear + ReLU per hidden width, then a linear map to 2 logits).
#[derive(Clone, Debug)]
pub struct RefineRound {
    /// Per-column mean subtracted from the input (`"{name}.mean"`, buffer).
    pub mean: ParamId,
    /// Per-column factor applied after it (`"{name}.scale"`, buffer; 1 / std).
    pub scale: ParamId,
    /// The layers; ReLU after each but the last.
    pub layers: Vec<Conv1d>,
}

/// The refinement rounds of a model.
#[derive(Clone, Debug)]
pub struct Refiner {
    /// In application order.
    pub rounds: Vec<RefineRound>,
    /// How the rounds read rivals and neighbours (fixed when they are trained).
    pub sides: SideRule,
    /// What the rounds read (fixed when they are trained).
    pub input: RefineInput,
}

impl Refiner {
    /// `rounds` rounds of hidden `widths`, registered as `refine.{r}.*`.
    ///
    /// # Errors
    /// `InvalidInput` for a zero width or a name clash.
    pub fn new(
        params: &mut ParamStore,
        rounds: usize,
        widths: &[usize],
        sides: SideRule,
        input: RefineInput,
        rng: &mut Rng,
    ) -> Result<Refiner> {
        if input.reads_flow() && sides != SideRule::Normals {
            return Err(Error::invalid(format!(
                "refinement input {} needs sides read by normals",
                input.name()
            )));
        }
        let dim = input.dim();
        let mut out = Vec::with_capacity(rounds);
        for r in 0..rounds {
            let name = format!("refine.{r}");
            let mean = params.add(&format!("{name}.mean"), ParamKind::Buffer, Tensor::zeros(&[dim])?)?;
            let scale =
                params.add(&format!("{name}.scale"), ParamKind::Buffer, Tensor::full(&[dim], 1.0)?)?;
            let mut layers = Vec::new();
            let mut cin = dim;
            for (l, &w) in widths.iter().chain(std::iter::once(&2)).enumerate() {
                layers.push(Conv1d::new(params, &format!("{name}.{l}"), cin, w, true, rng)?);
                cin = w;
            }
            out.push(RefineRound { mean, scale, layers });
        }
        Ok(Refiner { rounds: out, sides, input })
    }

    /// Standardised rows of `x` for round `r`.
    fn standardise(&self, params: &ParamStore, r: usize, mut x: Vec<f32>) -> Vec<f32> {
        let mean = params.get(self.rounds[r].mean).data().to_vec();
        let scale = params.get(self.rounds[r].scale).data().to_vec();
        let dim = self.input.dim();
        crate::par::for_each_chunk_mut(&mut x, dim * 1024, |_, chunk| {
            for row in chunk.chunks_exact_mut(dim) {
                for ((v, m), s) in row.iter_mut().zip(&mean).zip(&scale) {
                    *v = (*v - m) * s;
                }
            }
        });
        x
    }

    /// Round `r`'s logits `[M × 2]` for standardised rows `x` `[M × input.dim()]`.
    fn forward(&self, g: &mut Graph, r: usize, x: Var) -> Result<Var> {
        let layers = &self.rounds[r].layers;
        let mut h = x;
        for (l, layer) in layers.iter().enumerate() {
            let y = layer.forward(g, h)?;
            if l > 0 {
                g.free(h);
            }
            h = if l + 1 < layers.len() {
                let a = g.relu(y)?;
                g.free(y);
                a
            } else {
                y
            };
        }
        Ok(h)
    }

    /// Round `r`'s probabilities from feature rows (inference; `standardised`: the rows
    /// went through [`Refiner::standardise`] already): the MLP row by row (equal to
    /// [`Refiner::forward`] on standardised rows up to float rounding; an `[M × dim]`
    /// GEMM through the tape is slower than [`affine_row`] on rows kept in cache).
    fn round_probs(
        &self,
        params: &ParamStore,
        r: usize,
        feats: &[f32],
        standardised: bool,
    ) -> Result<Vec<f32>> {
        let dim = self.input.dim();
        if feats.len() % dim != 0 {
            return Err(Error::Shape { op: "refine", msg: "rows or last layer do not fit".into() });
        }
        let mlp = self.round_mlp(params, r)?;
        const ROWS: usize = 512;
        let mut out = vec![0.0f32; feats.len() / dim];
        crate::par::for_each_chunk_mut(&mut out, ROWS, |ch, chunk| {
            let mut buf = mlp.buffers();
            for (i, o) in chunk.iter_mut().enumerate() {
                *o = mlp.row(&feats[(ch * ROWS + i) * dim..][..dim], standardised, &mut buf);
            }
        });
        Ok(out)
    }

    /// Round `r`'s MLP, checked against the input width and ready for rows.
    fn round_mlp<'p>(&self, params: &'p ParamStore, r: usize) -> Result<RoundMlp<'p>> {
        let round = &self.rounds[r];
        let fits = round.layers.iter().all(|l| {
            params.get(l.weight).data().len() == l.cin * l.cout
                && l.bias.map_or(true, |b| params.get(b).data().len() == l.cout)
        });
        if round.layers.last().map(|l| l.cout) != Some(2) || !fits {
            return Err(Error::Shape { op: "refine", msg: "rows or last layer do not fit".into() });
        }
        let dim = self.input.dim();
        // Weights transposed once per call (`[cin × cout]`), for [`affine_row`].
        let layers: Vec<LayerRef> = round
            .layers
            .iter()
            .map(|l| {
                let (w, cin, cout) = (params.get(l.weight).data(), l.cin, l.cout);
                let wt = (0..cin * cout).map(|i| w[(i % cout) * cin + i / cout]).collect();
                (wt, l.bias.map(|b| params.get(b).data()), cin, cout)
            })
            .collect();
        let width = layers.iter().map(|l| l.2.max(l.3)).max().unwrap_or(0).max(dim);
        Ok(RoundMlp {
            mean: params.get(round.mean).data(),
            scale: params.get(round.scale).data(),
            layers,
            width,
        })
    }

    /// Round `r` on the graph's candidates: each chunk's feature rows are computed and
    /// scored in turn, so no `[M × dim]` matrix is held (the same probabilities as
    /// [`CandidateGraph::features`] followed by the round's MLP, bit for bit: the
    /// same rows, the same arithmetic).
    fn round_on_graph(
        &self,
        params: &ParamStore,
        r: usize,
        graph: &CandidateGraph,
        probs: &[f32],
        base: &[f32],
    ) -> Result<Vec<f32>> {
        let ctx = graph.round_context(probs, base)?;
        let mlp = self.round_mlp(params, r)?;
        let dim = graph.input.dim();
        let mut out = vec![0.0f32; probs.len()];
        crate::par::for_each_chunk_mut(&mut out, FEATURE_ROWS, |ch, chunk| {
            let mut feats = vec![0.0f32; chunk.len() * dim];
            graph.fill_rows(&ctx, probs, base, ch * FEATURE_ROWS, &mut feats);
            let mut buf = mlp.buffers();
            for (o, row) in chunk.iter_mut().zip(feats.chunks_exact(dim)) {
                *o = mlp.row(row, false, &mut buf);
            }
        });
        Ok(out)
    }

    /// Runs every round from the classifier's probabilities `base`; returns the last
    /// round's probabilities (`base` itself without rounds).
    ///
    /// # Errors
    /// As [`refine_features`].
    pub fn apply(
        &self,
        params: &ParamStore,
        points: &[[f32; 3]],
        quads: &[[u32; 4]],
        base: &[f32],
    ) -> Result<Vec<f32>> {
        self.apply_first(params, points, quads, base, self.rounds.len())
    }

    /// As [`Refiner::apply`], running only the first `n` rounds (all of them when `n`
    /// is at least their number; `base` itself for 0): what a model refined with `n`
    /// rounds gives, since a round is trained without reading the rounds after it.
    ///
    /// # Errors
    /// As [`refine_features`].
    pub fn apply_first(
        &self,
        params: &ParamStore,
        points: &[[f32; 3]],
        quads: &[[u32; 4]],
        base: &[f32],
        n: usize,
    ) -> Result<Vec<f32>> {
        let n = n.min(self.rounds.len());
        if n == 0 {
            return Ok(base.to_vec());
        }
        let graph = CandidateGraph::with_input(quads, points, self.sides, self.input)?;
        let mut p = base.to_vec();
        for r in 0..n {
            p = self.round_on_graph(params, r, &graph, &p, base)?;
        }
        Ok(p)
    }
}

/// One sample's part in refinement training: candidates, labels and the classifier's
/// probabilities.
#[derive(Clone, Debug)]
pub struct RefineSample {
    /// For messages.
    pub name: String,
    /// The points the corners index (positions in the classifier's frame).
    pub points: Vec<[f32; 3]>,
    /// Candidate quads.
    pub quads: Vec<[u32; 4]>,
    /// 1 for a ground-truth face.
    pub labels: Vec<u8>,
    /// The classifier's probability per candidate.
    pub base: Vec<f32>,
}

/// Refinement training settings.
#[derive(Clone, Debug)]
pub struct RefineTrainConfig {
    /// Passes over the training candidates per round.
    pub epochs: usize,
    /// Candidates per step.
    pub batch: usize,
    /// Optimiser (its `lr` is the start; ×0.1 over the round's epochs).
    pub sgd: SgdConfig,
    /// Seed of the shuffling.
    pub seed: u64,
}

impl Default for RefineTrainConfig {
    fn default() -> Self {
        RefineTrainConfig {
            epochs: 4,
            batch: 4096,
            sgd: SgdConfig { lr: 0.1, momentum: 0.9, weight_decay: 1e-5, clip: Some(100.0), nesterov: false },
            seed: 0,
        }
    }
}

/// Counts at one threshold and the average precision of a set of scored candidates.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ScoreStats {
    /// Precision at p > 0.5.
    pub precision: f64,
    /// Recall (of the positive candidates) at p > 0.5.
    pub recall: f64,
    /// Average precision over the ranking by probability.
    pub average_precision: f64,
}

/// [`ScoreStats`] of `probs` against `labels`.
pub fn score_stats(probs: &[f32], labels: &[u8]) -> ScoreStats {
    let pos = labels.iter().filter(|&&y| y == 1).count();
    let (mut tp, mut sel) = (0usize, 0usize);
    for (&p, &y) in probs.iter().zip(labels) {
        if p > 0.5 {
            sel += 1;
            tp += (y == 1) as usize;
        }
    }
    let mut order: Vec<usize> = (0..probs.len()).collect();
    order.sort_unstable_by(|&a, &b| probs[b].total_cmp(&probs[a]).then(a.cmp(&b)));
    let (mut hits, mut ap) = (0usize, 0.0f64);
    for (rank, &i) in order.iter().enumerate() {
        if labels[i] == 1 {
            hits += 1;
            ap += hits as f64 / (rank + 1) as f64;
        }
    }
    let div = |a: f64, b: usize| if b == 0 { 0.0 } else { a / b as f64 };
    ScoreStats {
        precision: div(tp as f64, sel),
        recall: div(tp as f64, pos),
        average_precision: div(ap, pos),
    }
}

/// What one trained round achieved.
#[derive(Clone, Debug)]
pub struct RoundReport {
    /// 1-based round.
    pub round: usize,
    /// Mean training loss of the last epoch.
    pub loss: f64,
    /// Validation figures of the round's input (the previous round or the classifier).
    pub val_before: ScoreStats,
    /// Validation figures of its output.
    pub val_after: ScoreStats,
}

/// Progress of [`train_refiner`].
#[derive(Clone, Debug)]
pub enum RefineProgress {
    /// An epoch of a round finished.
    Epoch {
        /// 1-based round.
        round: usize,
        /// 1-based epoch.
        epoch: usize,
        /// Mean loss.
        loss: f64,
    },
    /// A round finished.
    Round(RoundReport),
}

fn all_features(
    graphs: &[CandidateGraph],
    samples: &[RefineSample],
    current: &[Vec<f32>],
) -> Result<Vec<Vec<f32>>> {
    graphs
        .iter()
        .zip(samples)
        .zip(current)
        .map(|((g, s), p)| {
            g.features(p, &s.base).map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))
        })
        .collect()
}

fn graphs_of(samples: &[RefineSample], sides: SideRule, input: RefineInput) -> Result<Vec<CandidateGraph>> {
    samples
        .iter()
        .map(|s| {
            CandidateGraph::with_input(&s.quads, &s.points, sides, input)
                .map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))
        })
        .collect()
}

/// Trains every round of `refiner` (parameters in `params`) on `train`, round after
/// round, each on the previous round's output; `val` is only scored. Deterministic for
/// a seed.
///
/// # Errors
/// Inconsistent samples (lengths, corner indices), no training candidate, a zero
/// batch or epoch count, a diverged loss.
pub fn train_refiner(
    refiner: &Refiner,
    params: &mut ParamStore,
    train: &[RefineSample],
    val: &[RefineSample],
    cfg: &RefineTrainConfig,
    progress: &mut dyn FnMut(RefineProgress),
) -> Result<Vec<RoundReport>> {
    if cfg.epochs == 0 || cfg.batch == 0 {
        return Err(Error::invalid("refine training: epochs and batch must be positive"));
    }
    let total: usize = train.iter().map(|s| s.quads.len()).sum();
    if total == 0 {
        return Err(Error::invalid("refine training: no training candidates"));
    }
    for s in train.iter().chain(val) {
        if s.labels.len() != s.quads.len() || s.base.len() != s.quads.len() {
            return Err(Error::invalid(format!(
                "sample {}: candidates, labels and probabilities differ in count",
                s.name
            )));
        }
    }
    let labels: Vec<u8> = train.iter().flat_map(|s| s.labels.iter().copied()).collect();
    let val_labels: Vec<u8> = val.iter().flat_map(|s| s.labels.iter().copied()).collect();
    let (train_graphs, val_graphs) =
        (graphs_of(train, refiner.sides, refiner.input)?, graphs_of(val, refiner.sides, refiner.input)?);
    let dim = refiner.input.dim();
    let mut cur_train: Vec<Vec<f32>> = train.iter().map(|s| s.base.clone()).collect();
    let mut cur_val: Vec<Vec<f32>> = val.iter().map(|s| s.base.clone()).collect();
    let mut rng = Rng::new(cfg.seed);
    let mut reports = Vec::new();
    for r in 0..refiner.rounds.len() {
        let x: Vec<f32> = all_features(&train_graphs, train, &cur_train)?.concat();
        // Standardisation from the training rows (f64 sums).
        let (mut mean, mut sq) = (vec![0.0f64; dim], vec![0.0f64; dim]);
        for row in x.chunks_exact(dim) {
            for j in 0..dim {
                mean[j] += row[j] as f64;
                sq[j] += (row[j] as f64) * (row[j] as f64);
            }
        }
        let n = total as f64;
        let mean: Vec<f32> = mean.iter().map(|&s| (s / n) as f32).collect();
        let scale: Vec<f32> = sq
            .iter()
            .zip(&mean)
            .map(|(&s, &mu)| {
                let var = (s / n - (mu as f64) * (mu as f64)).max(0.0);
                (1.0 / (var.sqrt() + 1e-6)) as f32
            })
            .collect();
        params.set(refiner.rounds[r].mean, Tensor::new(&[dim], mean)?)?;
        params.set(refiner.rounds[r].scale, Tensor::new(&[dim], scale)?)?;
        let x = refiner.standardise(params, r, x);
        let mut sgd = Sgd::new(cfg.sgd)?;
        let schedule = ExpDecay { lr0: cfg.sgd.lr, factor: 0.1, period: cfg.epochs as f32 };
        let mut grads = Grads::new();
        let mut order: Vec<u32> = (0..total as u32).collect();
        let mut last_loss = 0.0;
        for epoch in 0..cfg.epochs {
            let lr = schedule.lr(epoch as f64);
            rng.shuffle(&mut order);
            let (mut loss_sum, mut steps) = (0.0f64, 0usize);
            for batch in order.chunks(cfg.batch) {
                let mut xb = Vec::with_capacity(batch.len() * dim);
                let mut yb = Vec::with_capacity(batch.len());
                for &i in batch {
                    let i = i as usize;
                    xb.extend_from_slice(&x[i * dim..(i + 1) * dim]);
                    yb.push(labels[i]);
                }
                let mut g = Graph::train(params);
                let xv = g.input(Tensor::new(&[batch.len(), dim], xb)?);
                let logits = refiner.forward(&mut g, r, xv)?;
                let loss = weighted_cross_entropy(&mut g, logits, &yb, 1.0)?;
                let lv = g.value(loss).item()? as f64;
                if !lv.is_finite() {
                    return Err(Error::invalid(format!(
                        "refine training diverged: loss {lv} in round {} epoch {}",
                        r + 1,
                        epoch + 1
                    )));
                }
                grads.zero();
                g.backward(loss, &mut grads)?;
                drop(g);
                sgd.step(params, &grads, lr)?;
                loss_sum += lv;
                steps += 1;
            }
            last_loss = loss_sum / steps.max(1) as f64;
            progress(RefineProgress::Epoch { round: r + 1, epoch: epoch + 1, loss: last_loss });
        }
        let before = score_stats(&cur_val.concat(), &val_labels);
        // The round's output on the training rows already built (and standardised).
        let mut all = refiner.round_probs(params, r, &x, true)?.into_iter();
        for (cur, s) in cur_train.iter_mut().zip(train) {
            *cur = all.by_ref().take(s.quads.len()).collect();
        }
        cur_val = all_features(&val_graphs, val, &cur_val)?
            .iter()
            .map(|f| refiner.round_probs(params, r, f, false))
            .collect::<Result<_>>()?;
        let report = RoundReport {
            round: r + 1,
            loss: last_loss,
            val_before: before,
            val_after: score_stats(&cur_val.concat(), &val_labels),
        };
        progress(RefineProgress::Round(report.clone()));
        reports.push(report);
    }
    Ok(reports)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The row-by-row inference equals the tape's forward on standardised rows (the
    /// training path) up to float rounding, and a wrong weight would show.
    #[test]
    fn row_inference_equals_the_tape_forward() {
        for input in [RefineInput::Base, RefineInput::Flow, RefineInput::Inside] {
            row_inference_case(input);
        }
    }

    fn row_inference_case(input: RefineInput) {
        let mut params = ParamStore::new();
        let mut rng = Rng::new(4);
        let refiner = Refiner::new(&mut params, 2, &[32, 16], SideRule::Normals, input, &mut rng).unwrap();
        let dim = input.dim();
        let m = 700;
        let feats: Vec<f32> = (0..m * dim).map(|_| rng.uniform(-3.0, 3.0) as f32).collect();
        let mean: Vec<f32> = (0..dim).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        let scale: Vec<f32> = (0..dim).map(|_| rng.uniform(0.5, 2.0) as f32).collect();
        params.set(refiner.rounds[1].mean, Tensor::new(&[dim], mean).unwrap()).unwrap();
        params.set(refiner.rounds[1].scale, Tensor::new(&[dim], scale).unwrap()).unwrap();
        let tape = |params: &ParamStore| {
            let x = refiner.standardise(params, 1, feats.clone());
            let mut g = Graph::eval_shared(params);
            let xv = g.input(Tensor::new(&[m, dim], x).unwrap());
            let logits = refiner.forward(&mut g, 1, xv).unwrap();
            crate::pipeline::model::probabilities(g.value(logits).data())
        };
        let want = tape(&params);
        let got = refiner.round_probs(&params, 1, &feats, false).unwrap();
        let worst = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "worst difference {worst}");
        // A changed weight changes the answer well beyond that.
        let w = refiner.rounds[1].layers[1].weight;
        let mut t = params.get(w).clone();
        t.data_mut()[3] += 0.5;
        params.set(w, t).unwrap();
        let moved = refiner.round_probs(&params, 1, &feats, false).unwrap();
        let diff = moved.iter().zip(&got).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(diff > 1e-3, "the check could not fail: {diff}");
    }

    /// Running the first `n` rounds equals running a copy of the rounds cut to `n`
    /// (what a model refined with `n` rounds holds), for every `n`, on random
    /// candidates of a random cloud; and the rounds differ, so the check can fail.
    #[test]
    fn the_first_rounds_equal_the_rounds_cut_short() {
        let mut params = ParamStore::new();
        let mut rng = Rng::new(11);
        let refiner =
            Refiner::new(&mut params, 4, &[16, 8], SideRule::Normals, RefineInput::Flow, &mut rng).unwrap();
        let n_points = 60u32;
        let points: Vec<[f32; 3]> = (0..n_points)
            .map(|_| {
                [rng.uniform(-1.0, 1.0) as f32, rng.uniform(-1.0, 1.0) as f32, rng.uniform(-0.1, 0.1) as f32]
            })
            .collect();
        let mut quads = Vec::new();
        while quads.len() < 300 {
            let q = [0; 4].map(|_| rng.below(n_points as usize) as u32);
            if (0..4).all(|i| (i + 1..4).all(|j| q[i] != q[j])) {
                quads.push(q);
            }
        }
        let base: Vec<f32> = quads.iter().map(|_| rng.uniform(0.0, 1.0) as f32).collect();
        let mut previous: Option<Vec<f32>> = None;
        for n in 0..=5 {
            let got = refiner.apply_first(&params, &points, &quads, &base, n).unwrap();
            let mut cut = refiner.clone();
            cut.rounds.truncate(n);
            let want = cut.apply(&params, &points, &quads, &base).unwrap();
            assert_eq!(got, want, "first {n} rounds");
            if let Some(prev) = previous.filter(|_| n <= 4) {
                assert_ne!(prev, got, "round {n} changed nothing: the check could not fail");
            }
            previous = Some(got);
        }
        assert_eq!(refiner.apply(&params, &points, &quads, &base).unwrap(), previous.unwrap());
    }

    /// [`affine_row`] (every input, the fixed-width paths included) against the sum that
    /// skips inputs equal to 0, as it ran before session 38: the same values (equal as
    /// numbers; a zero may differ only in sign), on rows half of whose inputs are ±0.
    #[test]
    fn affine_row_equals_the_sum_that_skips_zero_inputs() {
        let mut rng = Rng::new(38);
        let mut nonzero = 0;
        for &(cin, cout) in &[(35usize, 32usize), (32, 32), (32, 2), (9, 7), (5, 1)] {
            for trial in 0..50 {
                let wt: Vec<f32> = (0..cin * cout).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
                let bias: Vec<f32> = (0..cout).map(|_| rng.uniform(-0.5, 0.5) as f32).collect();
                let x: Vec<f32> = (0..cin)
                    .map(|_| match rng.below(4) {
                        0 => 0.0,
                        1 => -0.0,
                        _ => rng.uniform(-2.0, 2.0) as f32,
                    })
                    .collect();
                let b = (trial % 2 == 0).then_some(&bias[..]);
                let mut want = b.map_or(vec![0.0f32; cout], <[f32]>::to_vec);
                for (xj, col) in x.iter().zip(wt.chunks_exact(cout)) {
                    if *xj != 0.0 {
                        for (yk, wk) in want.iter_mut().zip(col) {
                            *yk += wk * xj;
                        }
                    }
                }
                let mut got = vec![f32::NAN; cout];
                affine_row(&wt, b, &x, &mut got);
                assert_eq!(got, want, "{cin} -> {cout}, trial {trial}");
                nonzero += got.iter().filter(|v| **v != 0.0).count();
            }
        }
        assert!(nonzero > 1000, "the sums were mostly zero: the check could not fail");
    }

    /// The rounds as `apply` runs them (each chunk's rows computed and scored in turn,
    /// no feature matrix) give the probabilities of the plain two steps, the whole
    /// feature matrix and then the round's MLP, bit for bit, for each input kind and
    /// more candidates than one chunk holds.
    #[test]
    fn chunked_rounds_equal_the_feature_matrix_and_the_mlp() {
        for (input, seed) in [(RefineInput::Base, 1), (RefineInput::Flow, 2), (RefineInput::Inside, 3)] {
            let mut params = ParamStore::new();
            let mut rng = Rng::new(seed);
            let refiner = Refiner::new(&mut params, 3, &[16, 8], SideRule::Normals, input, &mut rng).unwrap();
            // A standardisation that is not the identity, so skipping it would show.
            for round in &refiner.rounds {
                for v in params.get_mut(round.mean).data_mut() {
                    *v = rng.uniform(-0.5, 0.5) as f32;
                }
                for v in params.get_mut(round.scale).data_mut() {
                    *v = rng.uniform(0.5, 2.0) as f32;
                }
            }
            let n_points = 200u32;
            let points: Vec<[f32; 3]> = (0..n_points)
                .map(|_| {
                    [
                        rng.uniform(-1.0, 1.0) as f32,
                        rng.uniform(-1.0, 1.0) as f32,
                        rng.uniform(-0.1, 0.1) as f32,
                    ]
                })
                .collect();
            let mut quads = Vec::new();
            while quads.len() < 3 * FEATURE_ROWS + 17 {
                let q = [0; 4].map(|_| rng.below(n_points as usize) as u32);
                if (0..4).all(|i| (i + 1..4).all(|j| q[i] != q[j])) {
                    quads.push(q);
                }
            }
            let base: Vec<f32> = quads.iter().map(|_| rng.uniform(0.0, 1.0) as f32).collect();
            let graph = CandidateGraph::with_input(&quads, &points, SideRule::Normals, input).unwrap();
            let mut p = base.clone();
            for r in 0..3 {
                let want =
                    refiner.round_probs(&params, r, &graph.features(&p, &base).unwrap(), false).unwrap();
                let got = refiner.round_on_graph(&params, r, &graph, &p, &base).unwrap();
                assert_eq!(
                    got.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    want.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    "{input:?} round {r}"
                );
                assert_ne!(got, p, "{input:?} round {r} changed nothing: the check could not fail");
                p = got;
            }
        }
    }
}
