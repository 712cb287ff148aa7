//! Training: the compound loss (weighted cross-entropy + face loss, DESIGN §4), SGD
//! with momentum and exponential decay, one point cloud (sample) per step with at
//! most `max_candidates` candidates drawn uniformly from it, rotation augmentation,
//! validation precision/recall after every epoch, a checkpoint after every epoch,
//! and exact resumption (weights, momentum buffers, epoch, step and RNG state).
//!
//! Augmentation: a uniformly random rotation per step, applied to the vector-valued
//! F_info columns (the 4 relative corner positions and the 4 corner normals) — the
//! exact effect of rotating the cloud, since F_info's scalars (scaled Jacobian,
//! sines) and the context features are rotation invariant — and, for a model with a
//! point encoder, to the sample's points before the KPFCNN pyramid is built (about the
//! frame's origin, the cloud's centroid; grid subsampling is not rotation invariant, so
//! the pyramid is rebuilt every step). Anisotropic scaling and fresh noise would need
//! new candidates; they come from the dataset instead (`point2quad dataset` draws noise
//! per sample).
//!
//! With a point encoder each step runs the KPFCNN over all the sample's points (batch
//! norm in train mode over them) and gathers the features of the drawn candidates'
//! corners; evaluation uses running statistics, as `reconstruct` does.

use crate::nn::checkpoint::TrainState;
use crate::nn::kpfcnn::prepare;
use crate::nn::loss::{face_loss, weighted_cross_entropy};
use crate::nn::optim::{ExpDecay, Sgd, SgdConfig};
use crate::pipeline::dataset::Sample;
use crate::pipeline::model::{check_corners, corner_indices, Model};
use crate::rng::Rng;
use crate::tensor::{Grads, Graph, Tensor};
use crate::{Error, Result};

/// Training hyperparameters.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Epochs to reach (a resumed run continues up to this number).
    pub epochs: usize,
    /// Seed of the training RNG (sample order, candidate subsets, rotations).
    pub seed: u64,
    /// Optimiser settings (learning rate is the schedule's start).
    pub sgd: SgdConfig,
    /// Epochs per ×0.1 of the learning rate.
    pub decay_period: f32,
    /// Positive-class weight; `None`: 1.05 × #negatives / #positives of the training set.
    pub pos_weight: Option<f32>,
    /// Weight of the face loss term.
    pub face_loss_weight: f32,
    /// At most this many candidates per step (uniformly drawn).
    pub max_candidates: usize,
    /// Random rotation augmentation.
    pub rotate: bool,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            epochs: 40,
            seed: 0,
            sgd: SgdConfig {
                lr: 0.01,
                momentum: 0.95,
                weight_decay: 1e-4,
                clip: Some(100.0),
                nesterov: false,
            },
            decay_period: 30.0,
            pos_weight: None,
            face_loss_weight: 1.0,
            max_candidates: 12_000,
            rotate: true,
        }
    }
}

/// Classification figures of one evaluation pass.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ClassStats {
    /// Candidates predicted real that are real.
    pub tp: usize,
    /// Candidates predicted real that are not.
    pub fp: usize,
    /// Real candidates predicted not real.
    pub fn_: usize,
    /// Ground-truth faces (for recall against the mesh, coverage included).
    pub gt_faces: usize,
}

impl ClassStats {
    /// tp / (tp + fp).
    pub fn precision(&self) -> f64 {
        ratio(self.tp, self.tp + self.fp)
    }
    /// tp / (tp + fn): recall among the candidates.
    pub fn recall(&self) -> f64 {
        ratio(self.tp, self.tp + self.fn_)
    }
    /// tp / ground-truth faces: recall against the mesh (bounded by coverage).
    pub fn mesh_recall(&self) -> f64 {
        ratio(self.tp, self.gt_faces)
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        0.0
    } else {
        a as f64 / b as f64
    }
}

/// What one epoch did.
#[derive(Clone, Debug)]
pub struct EpochReport {
    /// 1-based epoch just completed.
    pub epoch: usize,
    /// Mean training loss.
    pub loss: f64,
    /// Learning rate used.
    pub lr: f32,
    /// Validation figures at probability > 0.5.
    pub val: ClassStats,
    /// Seconds the epoch took.
    pub seconds: f64,
}

/// Progress events for the caller (the CLI prints them).
pub enum Progress<'a> {
    /// A step finished: epoch (1-based), step within epoch, steps per epoch, loss.
    Step { epoch: usize, step: usize, steps: usize, loss: f64 },
    /// An epoch finished.
    Epoch(&'a EpochReport),
}

/// The positive-class weight DESIGN §4 asks for: slightly above #neg / #pos.
pub fn auto_pos_weight(samples: &[Sample]) -> f32 {
    let pos: usize = samples.iter().map(|s| s.positives()).sum();
    let all: usize = samples.iter().map(|s| s.labels.len()).sum();
    if pos == 0 {
        1.0
    } else {
        (1.05 * (all - pos) as f64 / pos as f64).max(1.0) as f32
    }
}

/// Checks that every sample fits `model`: enough features per candidate, and, with a
/// point encoder, corner indices within the sample's points.
fn check_samples(samples: &[Sample], model: &Model) -> Result<()> {
    let fin = model.config().face_in();
    for s in samples {
        if (s.feature_dim as usize) < fin {
            return Err(Error::invalid(format!(
                "sample {}: {} features per candidate, the model reads {fin}",
                s.name, s.feature_dim
            )));
        }
        if model.config().point_dim > 0 {
            check_corners(&s.candidates, s.points.len())
                .map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))?;
        }
    }
    Ok(())
}

/// `points` rotated by `r` (in f64, rounded back to f32, as F_info's vectors are).
fn rotate_points(points: &[[f32; 3]], r: &[[f64; 3]; 3]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| crate::math::to_f32(crate::math::mat_vec(r, [p[0] as f64, p[1] as f64, p[2] as f64])))
        .collect()
}

/// The first `fin` columns of candidate `c`'s feature row (samples store F_info then
/// the context features; a model without context reads only F_info).
fn row(s: &Sample, c: usize, fin: usize) -> &[f32] {
    let fd = s.feature_dim as usize;
    &s.features[c * fd..c * fd + fin]
}

/// All candidates' model inputs of a sample, `M × fin`.
pub fn sample_input(s: &Sample, fin: usize) -> Vec<f32> {
    (0..s.labels.len()).flat_map(|c| row(s, c, fin).iter().copied()).collect()
}

/// Rotates the vector columns of one F_info row in place (see the module header).
fn rotate_row(row: &mut [f32], r: &[[f64; 3]; 3]) {
    for base in [0, 3, 6, 9, 17, 20, 23, 26] {
        let v = [row[base] as f64, row[base + 1] as f64, row[base + 2] as f64];
        let w = crate::math::mat_vec(r, v);
        row[base] = w[0] as f32;
        row[base + 1] = w[1] as f32;
        row[base + 2] = w[2] as f32;
    }
}

/// Classifies every candidate of `samples` (inference mode) and counts against labels.
///
/// # Errors
/// `InvalidInput` naming the sample when its features or candidates do not fit the
/// model, or its cloud cannot be encoded.
pub fn evaluate(model: &Model, samples: &[Sample], threshold: f32) -> Result<ClassStats> {
    check_samples(samples, model)?;
    let mut st = ClassStats::default();
    for s in samples {
        let x = sample_input(s, model.config().face_in());
        let p = model
            .predict_with_points(&s.points, &s.candidates, &x)
            .map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))?;
        for (&pi, &y) in p.iter().zip(&s.labels) {
            match (pi > threshold, y == 1) {
                (true, true) => st.tp += 1,
                (true, false) => st.fp += 1,
                (false, true) => st.fn_ += 1,
                (false, false) => {}
            }
        }
        st.gt_faces += s.gt_faces.len();
    }
    Ok(st)
}

/// Trains `model` on `train` (validating on `val`) until `cfg.epochs`, continuing
/// from `resume` when given. `progress` sees every step and epoch; `checkpoint` is
/// called after every epoch with the state to save.
///
/// # Errors
/// Inconsistent samples, an empty training set, non-finite losses (diverged), and
/// whatever `checkpoint` returns.
pub fn train(
    model: &mut Model,
    train: &[Sample],
    val: &[Sample],
    cfg: &TrainConfig,
    resume: Option<TrainState>,
    progress: &mut dyn FnMut(Progress),
    checkpoint: &mut dyn FnMut(&Model, &TrainState) -> Result<()>,
) -> Result<Vec<EpochReport>> {
    let fin = model.config().face_in();
    check_samples(train, model)?;
    check_samples(val, model)?;
    let usable: Vec<usize> = (0..train.len()).filter(|&i| !train[i].labels.is_empty()).collect();
    if usable.is_empty() {
        return Err(Error::invalid("no training sample has candidates"));
    }
    let pos_weight = cfg.pos_weight.unwrap_or_else(|| auto_pos_weight(train));
    let mut sgd = Sgd::new(cfg.sgd)?;
    let schedule = ExpDecay { lr0: cfg.sgd.lr, factor: 0.1, period: cfg.decay_period };
    let (mut rng, start_epoch) = match &resume {
        Some(st) => {
            sgd.set_buffers(&model.params, &st.momentum, st.step)?;
            (Rng::from_state(st.rng), st.epoch as usize)
        }
        None => (Rng::new(cfg.seed), 0),
    };
    let mut reports = Vec::new();
    let mut grads = Grads::new();
    for epoch in start_epoch..cfg.epochs {
        let t0 = std::time::Instant::now();
        let lr = schedule.lr(epoch as f64);
        let mut order = usable.clone();
        rng.shuffle(&mut order);
        let mut loss_sum = 0.0;
        for (step, &si) in order.iter().enumerate() {
            let s = &train[si];
            let m = s.labels.len();
            let mut pick: Vec<usize> = (0..m).collect();
            if m > cfg.max_candidates {
                rng.shuffle(&mut pick);
                pick.truncate(cfg.max_candidates);
                pick.sort_unstable();
            }
            let rot = if cfg.rotate { Some(rng.rotation()) } else { None };
            let mut x = Vec::with_capacity(pick.len() * fin);
            let mut labels = Vec::with_capacity(pick.len());
            for &c in &pick {
                let start = x.len();
                x.extend_from_slice(row(s, c, fin));
                if let Some(r) = &rot {
                    rotate_row(&mut x[start..], r);
                }
                labels.push(s.labels[c]);
            }
            let Model { net, params } = &mut *model;
            let pyramid = match net.point_encoder() {
                Some(kp) => {
                    let pts = match &rot {
                        Some(r) => prepare(&rotate_points(&s.points, r), kp.config()),
                        None => prepare(&s.points, kp.config()),
                    };
                    Some(pts.map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))?)
                }
                None => None,
            };
            let mut g = Graph::train(params);
            let point = match (net.point_encoder(), &pyramid) {
                (Some(kp), Some(pyr)) => {
                    let pf = kp
                        .forward(&mut g, pyr)
                        .map_err(|e| Error::invalid(format!("sample {}: point encoder: {e}", s.name)))?;
                    let corners: Vec<[u32; 4]> = pick.iter().map(|&c| s.candidates[c]).collect();
                    Some((pf, corner_indices(&corners)))
                }
                _ => None,
            };
            let xv = g.input(Tensor::new(&[pick.len(), fin], x)?);
            let logits = net.forward(&mut g, xv, point)?;
            let ce = weighted_cross_entropy(&mut g, logits, &labels, pos_weight)?;
            let fl = face_loss(&mut g, logits, &labels)?;
            let fl = g.scale(fl, cfg.face_loss_weight)?;
            let loss = g.add(ce, fl)?;
            let lv = g.value(loss).item()? as f64;
            if !lv.is_finite() {
                return Err(Error::invalid(format!(
                    "training diverged: loss {lv} at epoch {} step {step} (sample {})",
                    epoch + 1,
                    s.name
                )));
            }
            grads.zero();
            g.backward(loss, &mut grads)?;
            drop(g);
            sgd.step(&mut model.params, &grads, lr)?;
            loss_sum += lv;
            progress(Progress::Step { epoch: epoch + 1, step: step + 1, steps: order.len(), loss: lv });
        }
        let val_stats = evaluate(model, val, 0.5)?;
        let report = EpochReport {
            epoch: epoch + 1,
            loss: loss_sum / order.len() as f64,
            lr,
            val: val_stats,
            seconds: t0.elapsed().as_secs_f64(),
        };
        progress(Progress::Epoch(&report));
        let state = TrainState {
            epoch: (epoch + 1) as u64,
            step: sgd.steps(),
            rng: rng.state(),
            momentum: sgd.buffers(&model.params),
        };
        checkpoint(model, &state)?;
        reports.push(report);
    }
    Ok(reports)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::candidates::{generate, CandidateConfig};
    use crate::pipeline::features::{face_input, F_INFO_DIM};

    /// The augmentation rotates the points (what the point encoder sees) and F_info's
    /// vectors by the same rotation: F_info recomputed from the rotated points equals the
    /// rotated F_info (a transposed or different rotation would not).
    #[test]
    fn point_rotation_matches_f_info_rotation() {
        let mesh = crate::mesh::shapes::torus(12, 6, 1.0, 0.4);
        let pts: Vec<[f32; 3]> = mesh.vertices.iter().map(|&p| crate::math::to_f32(p)).collect();
        let cands =
            generate(&pts, &CandidateConfig { k: 12, per_point: 6, ..CandidateConfig::default() }).unwrap();
        assert!(cands.len() > 50);
        let r = Rng::new(3).rotation();
        let rotated_pts = rotate_points(&pts, &r);
        let want = face_input(&rotated_pts, &cands, false);
        let mut got = face_input(&pts, &cands, false);
        let mut moved = 0.0f32;
        for (row, want_row) in got.chunks_exact_mut(F_INFO_DIM).zip(want.chunks_exact(F_INFO_DIM)) {
            let before = row.to_vec();
            rotate_row(row, &r);
            for (j, (a, b)) in row.iter().zip(want_row).enumerate() {
                assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()), "column {j}: {a} vs {b}");
                moved = moved.max((before[j] - b).abs());
            }
        }
        assert!(moved > 0.1, "the rotation moved nothing: the check could not fail");
    }
}
