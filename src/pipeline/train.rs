//! Training: the compound loss (weighted cross-entropy + face loss, DESIGN §4), SGD
//! with momentum and exponential decay, one point cloud (sample) per step with at
//! most `max_candidates` candidates drawn uniformly from it, geometric augmentation,
//! validation precision/recall after every epoch, a checkpoint after every epoch,
//! and exact resumption (weights, momentum buffers, epoch, step and RNG state).
//!
//! Augmentation, per step, drawn from the training RNG (so resuming replays it):
//! * a uniformly random rotation (`rotate`);
//! * an anisotropic scale, each axis of a random orthonormal frame scaled by a factor
//!   uniform in `scale` (default 0.9–1.1);
//! * a Gaussian jitter of every point, σ = `jitter` × its local spacing (default 0.01).
//!
//! With scale or jitter on, the sample's points are moved (jitter, then rotation ·
//! scale) and the face input of the drawn candidates is recomputed from the moved points
//! ([`crate::pipeline::augment`]: F_info and the position-dependent context columns,
//! with normals and spacing recomputed over the dataset's kNN rows, cached per sample at
//! the start of training); the candidates and labels stay the dataset's. With rotation
//! alone it is cheaper and exact to rotate F_info's vector columns (the 4 relative
//! corner positions and the 4 corner normals): F_info's scalars and the context are
//! rotation invariant. A model with a point encoder gets the same moved points (about
//! the frame's origin, the cloud's centroid; grid subsampling is not rotation invariant,
//! so the pyramid is rebuilt every step). Fresh noise points per epoch would need new
//! candidates (about a second per 10k-point cloud), so noise comes from the dataset
//! (`point2quad dataset` draws it per sample); a dataset written with
//! `--noise-variants N` holds N draws of each sample (`NAME`, `NAME~2`, …), and epoch e
//! trains on draw e mod N of each ([`variant_groups`]), so the noise changes from one
//! epoch to the next at the cost of one sample per step.
//!
//! With a point encoder each step runs the KPFCNN over all the sample's points (batch
//! norm in train mode over them) and gathers the features of the drawn candidates'
//! corners; evaluation uses running statistics, as `reconstruct` does.

use crate::nn::checkpoint::TrainState;
use crate::nn::kpfcnn::prepare;
use crate::nn::loss::{face_loss, weighted_cross_entropy};
use crate::nn::optim::{ExpDecay, Sgd, SgdConfig};
use crate::pipeline::augment::{self, Augmentation, SampleGeometry};
use crate::pipeline::candidates::CandidateConfig;
use crate::pipeline::dataset::{noise_variant, Sample};
use crate::pipeline::model::{check_corners, corner_indices, Model};
use crate::rng::Rng;
use crate::tensor::{Grads, Graph, Tensor};
use crate::{Error, Result};

/// Training hyperparameters.
#[derive(Clone, Debug)]
pub struct TrainConfig {
    /// Epochs to reach (a resumed run continues up to this number).
    pub epochs: usize,
    /// Seed of the training RNG (sample order, candidate subsets, augmentation).
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
    /// Anisotropic scale augmentation: each axis of a random orthonormal frame scaled
    /// by a factor uniform in `[min, max)` (finite, 0 < min <= max); `None`: off.
    pub scale: Option<(f32, f32)>,
    /// Jitter augmentation: Gaussian offsets of every point with σ = `jitter` × the
    /// point's local spacing (finite, >= 0; 0: off).
    pub jitter: f32,
    /// The candidate settings the dataset was built with: with scale or jitter on, its
    /// `k`, `normal_k` and `spacing_k` rebuild the neighbours of the recomputed normals
    /// and spacing (`point2quad dataset` uses the default).
    pub candidates: CandidateConfig,
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
            scale: Some((0.9, 1.1)),
            jitter: 0.01,
            candidates: CandidateConfig::default(),
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
///
/// # Errors
/// `InvalidInput` naming the first sample that does not fit.
pub fn check_samples(samples: &[Sample], model: &Model) -> Result<()> {
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
    evaluate_checked(model, samples, threshold)?.map_err(Error::invalid)
}

/// [`evaluate`], with a non-finite probability as the inner error (its message), apart
/// from the errors of the samples and the network.
fn evaluate_checked(
    model: &Model,
    samples: &[Sample],
    threshold: f32,
) -> Result<std::result::Result<ClassStats, String>> {
    check_samples(samples, model)?;
    let mut st = ClassStats::default();
    for s in samples {
        let x = sample_input(s, model.config().face_in());
        let p = match finite_probabilities(model, s, &x)? {
            Ok(p) => p,
            Err(why) => return Ok(Err(why)),
        };
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
    Ok(Ok(st))
}

/// The model's probabilities for the candidates of `s` (`x`: their input rows); the
/// inner error (its message) when one is NaN or infinite: finite weights can still
/// overflow f32 on the way (a learning rate far too large), and such a model must not be
/// scored or saved.
fn finite_probabilities(
    model: &Model,
    s: &Sample,
    x: &[f32],
) -> Result<std::result::Result<Vec<f32>, String>> {
    let p = model
        .predict_with_points(&s.points, &s.candidates, x)
        .map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))?;
    Ok(match p.iter().position(|v| !v.is_finite()) {
        None => Ok(p),
        Some(i) => Err(format!(
            "sample {}: the model gives a non-finite probability ({}) for candidate {i}",
            s.name, p[i]
        )),
    })
}

/// Trains `model` on `train` (validating on `val`) until `cfg.epochs`, continuing
/// from `resume` when given. `progress` sees every step and epoch; `checkpoint` is
/// called after every epoch with the state to save.
///
/// # Errors
/// Inconsistent samples, an empty training set, bad augmentation settings
/// ([`augment::check_settings`]), non-finite losses (diverged), and whatever
/// `checkpoint` returns.
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
    augment::check_settings(cfg.scale, cfg.jitter)?;
    if cfg.max_candidates < 2 {
        return Err(Error::invalid(format!(
            "max_candidates must be at least 2 (batch norm needs two rows), got {}",
            cfg.max_candidates
        )));
    }
    // A sample needs two candidates: batch norm in train mode normalises over the drawn
    // rows (a one-quad mesh's sample failed mid-epoch). Smaller ones are skipped.
    let usable: Vec<usize> = (0..train.len()).filter(|&i| train[i].labels.len() >= 2).collect();
    if usable.is_empty() {
        return Err(Error::invalid("no training sample has two or more candidates"));
    }
    // Noise variants of one sample (`NAME`, `NAME~2`, …) are one group, and an epoch
    // takes one of each group, in turn: fresh noise points every epoch at the cost of
    // one sample. Without variants every group is one sample, so the epochs (and the
    // random draws) are exactly those of a dataset without the option.
    let groups = variant_groups(train, &usable);
    // Moving points needs each sample's neighbours, normals and spacing: built once
    // (deterministic, no RNG), so a resumed run rebuilds the same.
    let moves_points = cfg.scale.is_some() || cfg.jitter > 0.0;
    let mut geometry: Vec<Option<SampleGeometry>> = vec![None; train.len()];
    if moves_points {
        for &i in &usable {
            let s = &train[i];
            geometry[i] = Some(
                SampleGeometry::new(&s.points, &s.candidates, &cfg.candidates)
                    .map_err(|e| Error::invalid(format!("sample {}: {e}", s.name)))?,
            );
        }
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
        // No clock on wasm32 (session 39's audit: `Instant::now` panics there).
        let t0 = crate::clock::Stopwatch::start();
        let lr = schedule.lr(epoch as f64);
        let mut order: Vec<usize> = groups.iter().map(|g| g[epoch % g.len()]).collect();
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
            let labels: Vec<u8> = pick.iter().map(|&c| s.labels[c]).collect();
            // The face input and the points the point encoder sees (`None`: the stored ones).
            let (x, moved) = match &geometry[si] {
                Some(geo) => {
                    let aug = Augmentation::draw(&mut rng, cfg.rotate, cfg.scale, cfg.jitter, geo.spacing())?;
                    let moved = aug.apply(&s.points);
                    let (normals, spacing) = geo.recompute(&moved, &aug);
                    (augment::face_rows(s, &pick, fin, &moved, &normals, &spacing), Some(moved))
                }
                None => {
                    let rot = if cfg.rotate { Some(rng.rotation()) } else { None };
                    let mut x = Vec::with_capacity(pick.len() * fin);
                    for &c in &pick {
                        let start = x.len();
                        x.extend_from_slice(row(s, c, fin));
                        if let Some(r) = &rot {
                            rotate_row(&mut x[start..], r);
                        }
                    }
                    let encoded = model.net.point_encoder().is_some();
                    (x, rot.filter(|_| encoded).map(|r| rotate_points(&s.points, &r)))
                }
            };
            // F_info in each candidate's frame when the model reads it so.
            let x = model.framed(x);
            let Model { net, params } = &mut *model;
            let pyramid = match net.point_encoder() {
                Some(kp) => {
                    let pts = prepare(moved.as_deref().unwrap_or(&s.points), kp.config());
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
        // Weights that left f32's range (a learning rate far too large) are a
        // divergence too, even when this epoch's losses stayed finite: never saved.
        for id in model.params.ids() {
            if let Some(x) = model.params.get(id).data().iter().find(|x| !x.is_finite()) {
                return Err(Error::invalid(format!(
                    "training diverged: weight {} became {x} in epoch {} (nothing saved for it; try a smaller --lr)",
                    model.params.name(id),
                    epoch + 1
                )));
            }
        }
        // Finite weights whose products overflow f32 give NaN probabilities: a
        // divergence too (session 24's audit: `--lr 1e15` saved such weights). The
        // validation pass checks every validation sample; without any, the first
        // training sample that trains is checked.
        let diverged = |why: String| {
            Error::invalid(format!(
                "training diverged in epoch {}: {why} (nothing saved for it; try a smaller --lr)",
                epoch + 1
            ))
        };
        let val_stats = evaluate_checked(model, val, 0.5)?.map_err(diverged)?;
        if val.is_empty() {
            let s = &train[usable[0]];
            finite_probabilities(model, s, &sample_input(s, fin))?.map_err(diverged)?;
        }
        let report = EpochReport {
            epoch: epoch + 1,
            loss: loss_sum / order.len() as f64,
            lr,
            val: val_stats,
            seconds: t0.seconds(),
        };
        progress(Progress::Epoch(&report));
        let state = TrainState {
            epoch: (epoch + 1) as u64,
            step: sgd.steps(),
            rng: rng.state(),
            momentum: sgd.buffers(&model.params),
            run: Vec::new(),
        };
        checkpoint(model, &state)?;
        reports.push(report);
    }
    Ok(reports)
}

/// The samples of `usable` (indices into `samples`) grouped by the sample their noise
/// variant was drawn for ([`noise_variant`]): groups in the order of their first member,
/// members by variant number. Only the members' variant numbers order a group, so the
/// order of the samples within the slice does not matter.
pub fn variant_groups(samples: &[Sample], usable: &[usize]) -> Vec<Vec<usize>> {
    let mut at: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    let mut groups: Vec<Vec<(usize, usize)>> = Vec::new();
    for &i in usable {
        let (base, v) = noise_variant(&samples[i].name);
        let g = *at.entry(base).or_insert_with(|| {
            groups.push(Vec::new());
            groups.len() - 1
        });
        groups[g].push((v, i));
    }
    groups
        .into_iter()
        .map(|mut g| {
            g.sort_unstable();
            g.into_iter().map(|(_, i)| i).collect()
        })
        .collect()
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

    /// The two augmentation paths agree on a rotation: the face input recomputed from
    /// rotated points (the path taken with scale or jitter on) equals the stored input
    /// with F_info's vectors rotated (the rotation-only path), context included.
    #[test]
    fn recomputed_input_under_a_rotation_equals_the_rotated_stored_input() {
        use crate::pipeline::augment::{face_rows, Augmentation, SampleGeometry};
        use crate::pipeline::dataset::build_sample;
        use crate::pipeline::features::CONTEXT_DIM;
        let cfg = CandidateConfig { k: 12, per_point: 6, ..CandidateConfig::default() };
        let mesh = crate::mesh::shapes::torus(14, 7, 1.0, 0.4);
        let s = build_sample("torus", &mesh, &Default::default(), &cfg, &mut Rng::new(2)).unwrap();
        let fin = F_INFO_DIM + CONTEXT_DIM;
        let geo = SampleGeometry::new(&s.points, &s.candidates, &cfg).unwrap();
        let r = Rng::new(5).rotation();
        let aug = Augmentation::linear(r).unwrap();
        let moved = aug.apply(&s.points);
        let (normals, spacing) = geo.recompute(&moved, &aug);
        let picks: Vec<usize> = (0..s.labels.len()).collect();
        let got = face_rows(&s, &picks, fin, &moved, &normals, &spacing);
        let mut want = sample_input(&s, fin);
        let mut changed = 0.0f32;
        for (g, w) in got.chunks_exact(fin).zip(want.chunks_exact_mut(fin)) {
            let before = w.to_vec();
            rotate_row(w, &r);
            for (j, (a, b)) in g.iter().zip(w.iter()).enumerate() {
                assert!((a - b).abs() <= 1e-4 * (1.0 + b.abs()), "column {j}: {a} vs {b}");
                changed = changed.max((a - before[j]).abs());
            }
        }
        assert!(changed > 0.1, "the rotation changed nothing: the check could not fail");
    }
}
