//! Refinement of the classifier's probabilities by the candidates' neighbourhood (our
//! addition to the paper; README "Refinement").
//!
//! The classifier scores every candidate on its own. Whether a candidate is a face
//! depends on its rivals too: in a manifold, consistently oriented quad mesh a directed
//! edge belongs to at most one face and a face's sides are shared, reversed, with its
//! neighbours. A refinement round reads, per candidate, its current probability and
//! what the other candidates' probabilities say about it ([`refine_features`]: the best
//! rival on each of its directed edges, the best neighbour across each edge, rivals over
//! its diagonals, the probability mass at its corners), and a small MLP gives a new
//! probability. Rounds chain (round r reads round r − 1's output), like a few steps of
//! message passing over the candidate graph; each is trained on the previous round's
//! output over the training samples ([`train_refiner`]), with the classifier frozen.
//!
//! Every aggregate is sorted over the candidate's 4 edges (or corners), so the features
//! do not depend on which corner a candidate's cyclic order starts at, nor on the order
//! of the candidate list (property-tested against a brute-force reference).

use crate::nn::conv1d::Conv1d;
use crate::nn::loss::weighted_cross_entropy;
use crate::nn::module::Module;
use crate::nn::optim::{ExpDecay, Sgd, SgdConfig};
use crate::rng::Rng;
use crate::tensor::{Grads, Graph, ParamId, ParamKind, ParamStore, Tensor, Var};
use crate::{Error, Result};

/// Values per candidate read by a refinement round ([`refine_features`]).
pub const REFINE_DIM: usize = 27;

/// Probabilities are clamped to `[EPS, 1 − EPS]` before taking logits.
const EPS: f32 = 1e-6;

fn logit(p: f32) -> f32 {
    let p = p.clamp(EPS, 1.0 - EPS);
    (p / (1.0 - p)).ln()
}

fn pair_key(a: u32, b: u32) -> u64 {
    ((a as u64) << 32) | b as u64
}

fn unordered(a: u32, b: u32) -> u64 {
    if a < b {
        pair_key(a, b)
    } else {
        pair_key(b, a)
    }
}

/// Per key: the two best (value, owner) among the entries with that key.
struct Best2 {
    keys: Vec<u64>,
    top: Vec<(f32, u32, f32)>,
}

impl Best2 {
    /// From (key, value, owner) entries.
    fn new(mut e: Vec<(u64, f32, u32)>) -> Best2 {
        e.sort_unstable_by(|a, b| a.0.cmp(&b.0).then(b.1.total_cmp(&a.1)).then(a.2.cmp(&b.2)));
        let (mut keys, mut top) = (Vec::new(), Vec::new());
        let mut i = 0;
        while i < e.len() {
            let mut j = i + 1;
            while j < e.len() && e[j].0 == e[i].0 {
                j += 1;
            }
            // Several entries of one owner under a key cannot happen for edges; for the
            // pair table an owner appears once per pair as well (4 distinct corners).
            let second = if j > i + 1 { e[i + 1].1 } else { 0.0 };
            keys.push(e[i].0);
            top.push((e[i].1, e[i].2, second));
            i = j;
        }
        Best2 { keys, top }
    }

    /// The best value under `key` among owners other than `me` (0 when none).
    fn best_other(&self, key: u64, me: u32) -> f32 {
        match self.keys.binary_search(&key) {
            Ok(i) => {
                let (v, owner, second) = self.top[i];
                if owner == me {
                    second
                } else {
                    v
                }
            }
            Err(_) => 0.0,
        }
    }
}

fn sorted4(mut v: [f32; 4]) -> [f32; 4] {
    v.sort_unstable_by(f32::total_cmp);
    v
}

/// The refinement input of every candidate, `M × REFINE_DIM` row-major, from the
/// current probabilities `probs` and the classifier's own `base` (both one per
/// candidate). `n_points` bounds the corner indices. Columns (each group of four sorted
/// ascending; "other" = any candidate but this one):
///
/// * 0: logit of this candidate's current probability;
/// * 1–4: per directed edge (q_i → q_{i+1}), the best other candidate with the same
///   directed edge (a rival on the same side: at most one of them can be a face);
/// * 5–8: per directed edge, the best candidate with the reversed edge (a neighbour
///   across it);
/// * 9–12: per edge, neighbour minus rival (columns 5–8 minus 1–4, edge by edge);
/// * 13: the best other candidate holding both ends of one of this one's diagonals
///   (as an edge or a diagonal: it overlaps this one);
/// * 14–17: per corner, the sum of the other candidates' probabilities at that point;
/// * 18–21: per corner, the number of other candidates above 0.5 at that point, / 4;
/// * 22–25: per edge, the best other candidate holding both its ends (as an edge
///   either way, or as a diagonal);
/// * 26: logit of the classifier's probability.
///
/// # Errors
/// `InvalidInput` when the lengths differ or a corner index is `>= n_points`.
pub fn refine_features(quads: &[[u32; 4]], probs: &[f32], base: &[f32], n_points: usize) -> Result<Vec<f32>> {
    let m = quads.len();
    if probs.len() != m || base.len() != m {
        return Err(Error::invalid(format!(
            "refine features: {m} candidates, {} probabilities, {} base probabilities",
            probs.len(),
            base.len()
        )));
    }
    crate::pipeline::model::check_corners(quads, n_points)?;
    if m > u32::MAX as usize {
        return Err(Error::invalid("refine features: more than 2^32 candidates"));
    }
    let mut directed = Vec::with_capacity(4 * m);
    let mut pairs = Vec::with_capacity(6 * m);
    let mut mass = vec![0.0f64; n_points];
    let mut high = vec![0u32; n_points];
    for (c, (q, &p)) in quads.iter().zip(probs).enumerate() {
        let c = c as u32;
        for i in 0..4 {
            let (a, b) = (q[i], q[(i + 1) % 4]);
            directed.push((pair_key(a, b), p, c));
            pairs.push((unordered(a, b), p, c));
            mass[a as usize] += p as f64;
            high[a as usize] += (p > 0.5) as u32;
        }
        pairs.push((unordered(q[0], q[2]), p, c));
        pairs.push((unordered(q[1], q[3]), p, c));
    }
    let directed = Best2::new(directed);
    let pairs = Best2::new(pairs);
    let mut out = vec![0.0f32; m * REFINE_DIM];
    crate::par::for_each_chunk_mut(&mut out, REFINE_DIM * 256, |ch, chunk| {
        for (r, row) in chunk.chunks_exact_mut(REFINE_DIM).enumerate() {
            let c = ch * 256 + r;
            let (q, p) = (quads[c], probs[c]);
            let me = c as u32;
            let (mut rival, mut across, mut shared) = ([0.0f32; 4], [0.0f32; 4], [0.0f32; 4]);
            let (mut at, mut hi) = ([0.0f32; 4], [0.0f32; 4]);
            for i in 0..4 {
                let (a, b) = (q[i], q[(i + 1) % 4]);
                rival[i] = directed.best_other(pair_key(a, b), me);
                across[i] = directed.best_other(pair_key(b, a), me);
                shared[i] = pairs.best_other(unordered(a, b), me);
                at[i] = (mass[a as usize] - p as f64) as f32;
                hi[i] = (high[a as usize] - (p > 0.5) as u32) as f32 / 4.0;
            }
            let diff = [0, 1, 2, 3].map(|i| across[i] - rival[i]);
            let diag =
                pairs.best_other(unordered(q[0], q[2]), me).max(pairs.best_other(unordered(q[1], q[3]), me));
            row[0] = logit(p);
            row[1..5].copy_from_slice(&sorted4(rival));
            row[5..9].copy_from_slice(&sorted4(across));
            row[9..13].copy_from_slice(&sorted4(diff));
            row[13] = diag;
            row[14..18].copy_from_slice(&sorted4(at));
            row[18..22].copy_from_slice(&sorted4(hi));
            row[22..26].copy_from_slice(&sorted4(shared));
            row[26] = logit(base[c]);
        }
    });
    Ok(out)
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
}

impl Refiner {
    /// `rounds` rounds of hidden `widths`, registered as `refine.{r}.*`.
    ///
    /// # Errors
    /// `InvalidInput` for a zero width or a name clash.
    pub fn new(params: &mut ParamStore, rounds: usize, widths: &[usize], rng: &mut Rng) -> Result<Refiner> {
        let mut out = Vec::with_capacity(rounds);
        for r in 0..rounds {
            let name = format!("refine.{r}");
            let mean =
                params.add(&format!("{name}.mean"), ParamKind::Buffer, Tensor::zeros(&[REFINE_DIM])?)?;
            let scale =
                params.add(&format!("{name}.scale"), ParamKind::Buffer, Tensor::full(&[REFINE_DIM], 1.0)?)?;
            let mut layers = Vec::new();
            let mut cin = REFINE_DIM;
            for (l, &w) in widths.iter().chain(std::iter::once(&2)).enumerate() {
                layers.push(Conv1d::new(params, &format!("{name}.{l}"), cin, w, true, rng)?);
                cin = w;
            }
            out.push(RefineRound { mean, scale, layers });
        }
        Ok(Refiner { rounds: out })
    }

    /// Standardised rows of `x` for round `r`.
    fn standardise(&self, params: &ParamStore, r: usize, mut x: Vec<f32>) -> Vec<f32> {
        let mean = params.get(self.rounds[r].mean).data().to_vec();
        let scale = params.get(self.rounds[r].scale).data().to_vec();
        crate::par::for_each_chunk_mut(&mut x, REFINE_DIM * 1024, |_, chunk| {
            for row in chunk.chunks_exact_mut(REFINE_DIM) {
                for ((v, m), s) in row.iter_mut().zip(&mean).zip(&scale) {
                    *v = (*v - m) * s;
                }
            }
        });
        x
    }

    /// Round `r`'s logits `[M × 2]` for standardised rows `x` `[M × REFINE_DIM]`.
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

    /// Round `r`'s probabilities from raw feature rows (inference).
    fn round_probs(&self, params: &ParamStore, r: usize, feats: Vec<f32>) -> Result<Vec<f32>> {
        let m = feats.len() / REFINE_DIM;
        if m == 0 {
            return Ok(Vec::new());
        }
        let x = self.standardise(params, r, feats);
        let mut g = Graph::eval_shared(params);
        let xv = g.input(Tensor::new(&[m, REFINE_DIM], x)?);
        let logits = self.forward(&mut g, r, xv)?;
        Ok(crate::pipeline::model::probabilities(g.value(logits).data()))
    }

    /// Runs rounds `0..upto` from the classifier's probabilities `base`; returns the
    /// last round's probabilities (`base` itself when `upto` is 0).
    ///
    /// # Errors
    /// As [`refine_features`].
    pub fn apply_upto(
        &self,
        params: &ParamStore,
        quads: &[[u32; 4]],
        base: &[f32],
        n_points: usize,
        upto: usize,
    ) -> Result<Vec<f32>> {
        let mut p = base.to_vec();
        for r in 0..upto.min(self.rounds.len()) {
            let f = refine_features(quads, &p, base, n_points)?;
            p = self.round_probs(params, r, f)?;
        }
        Ok(p)
    }

    /// Runs every round ([`Refiner::apply_upto`] with all rounds).
    ///
    /// # Errors
    /// As [`refine_features`].
    pub fn apply(
        &self,
        params: &ParamStore,
        quads: &[[u32; 4]],
        base: &[f32],
        n_points: usize,
    ) -> Result<Vec<f32>> {
        self.apply_upto(params, quads, base, n_points, self.rounds.len())
    }
}

/// One sample's part in refinement training: candidates, labels and the classifier's
/// probabilities.
#[derive(Clone, Debug)]
pub struct RefineSample {
    /// For messages.
    pub name: String,
    /// Number of points (bounds the corner indices).
    pub n_points: usize,
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
            batch: 2048,
            sgd: SgdConfig {
                lr: 0.05,
                momentum: 0.9,
                weight_decay: 1e-5,
                clip: Some(100.0),
                nesterov: false,
            },
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
    let div = |a: usize, b: usize| if b == 0 { 0.0 } else { a as f64 / b as f64 };
    ScoreStats { precision: div(tp, sel), recall: div(tp, pos), average_precision: div_f(ap, pos) }
}

fn div_f(a: f64, b: usize) -> f64 {
    if b == 0 {
        0.0
    } else {
        a / b as f64
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

fn all_features(refiner: &Refiner, samples: &[RefineSample], current: &[Vec<f32>]) -> Result<Vec<Vec<f32>>> {
    let _ = refiner;
    samples
        .iter()
        .zip(current)
        .map(|(s, p)| {
            refine_features(&s.quads, p, &s.base, s.n_points)
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
    let mut cur_train: Vec<Vec<f32>> = train.iter().map(|s| s.base.clone()).collect();
    let mut cur_val: Vec<Vec<f32>> = val.iter().map(|s| s.base.clone()).collect();
    let mut rng = Rng::new(cfg.seed);
    let mut reports = Vec::new();
    for r in 0..refiner.rounds.len() {
        let x: Vec<f32> = all_features(refiner, train, &cur_train)?.concat();
        // Standardisation from the training rows (f64 sums).
        let (mut mean, mut sq) = (vec![0.0f64; REFINE_DIM], vec![0.0f64; REFINE_DIM]);
        for row in x.chunks_exact(REFINE_DIM) {
            for j in 0..REFINE_DIM {
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
        params.set(refiner.rounds[r].mean, Tensor::new(&[REFINE_DIM], mean)?)?;
        params.set(refiner.rounds[r].scale, Tensor::new(&[REFINE_DIM], scale)?)?;
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
                let mut xb = Vec::with_capacity(batch.len() * REFINE_DIM);
                let mut yb = Vec::with_capacity(batch.len());
                for &i in batch {
                    let i = i as usize;
                    xb.extend_from_slice(&x[i * REFINE_DIM..(i + 1) * REFINE_DIM]);
                    yb.push(labels[i]);
                }
                let mut g = Graph::train(params);
                let xv = g.input(Tensor::new(&[batch.len(), REFINE_DIM], xb)?);
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
        let next = |feats: Vec<Vec<f32>>| -> Result<Vec<Vec<f32>>> {
            feats.into_iter().map(|f| refiner.round_probs(params, r, f)).collect()
        };
        cur_train = next(all_features(refiner, train, &cur_train)?)?;
        cur_val = next(all_features(refiner, val, &cur_val)?)?;
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
