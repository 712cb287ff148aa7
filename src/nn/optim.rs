//! SGD with momentum, weight decay and element-wise gradient clipping, exactly as
//! PyTorch's `SGD(dampening=0)` after `clip_grad_value_`: for each trainable tensor
//! with a gradient,
//!
//! ```text
//! g  = clamp(∇θ, −clip, clip)          (when clip is set)
//! d  = g + wd·θ
//! buf = d                 (first step)   buf = m·buf + d   (later steps)
//! d  = buf                (nesterov: d = d + m·buf)
//! θ −= lr·d
//! ```
//!
//! and the exponential learning-rate schedule `lr_e = lr0 · factor^(e / period)`
//! (×0.1 every 150 epochs by default, DESIGN §4).

use crate::tensor::{Grads, ParamKind, ParamStore, Tensor};
use crate::{Error, Result};

/// SGD hyperparameters (DESIGN §4 defaults).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SgdConfig {
    /// Base learning rate (the schedule scales it).
    pub lr: f32,
    /// Momentum `m`.
    pub momentum: f32,
    /// L2 weight decay added to the gradient.
    pub weight_decay: f32,
    /// Element-wise gradient clip value (`None`: no clipping).
    pub clip: Option<f32>,
    /// Nesterov momentum.
    pub nesterov: bool,
}

impl Default for SgdConfig {
    fn default() -> Self {
        SgdConfig { lr: 1e-3, momentum: 0.98, weight_decay: 1e-3, clip: Some(100.0), nesterov: false }
    }
}

/// Exponential decay: `lr(e) = lr0 · factor^(e / period)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExpDecay {
    /// Learning rate at epoch 0.
    pub lr0: f32,
    /// Factor reached after `period` epochs (0.1).
    pub factor: f32,
    /// Epochs per `factor` (150).
    pub period: f32,
}

impl ExpDecay {
    /// The default schedule from `lr0`: ×0.1 every 150 epochs.
    pub fn new(lr0: f32) -> ExpDecay {
        ExpDecay { lr0, factor: 0.1, period: 150.0 }
    }

    /// Learning rate at (possibly fractional) epoch `e`.
    pub fn lr(&self, epoch: f64) -> f32 {
        (self.lr0 as f64 * (self.factor as f64).powf(epoch / self.period as f64)) as f32
    }
}

/// The optimiser: configuration plus one momentum buffer per trainable tensor.
#[derive(Clone, Debug)]
pub struct Sgd {
    /// Hyperparameters.
    pub cfg: SgdConfig,
    bufs: Vec<Option<Vec<f32>>>,
    steps: u64,
}

impl Sgd {
    /// An optimiser with empty momentum buffers.
    ///
    /// # Errors
    /// `Error::InvalidInput` for a negative or non-finite hyperparameter, a momentum
    /// ≥ 1, or Nesterov without momentum.
    pub fn new(cfg: SgdConfig) -> Result<Sgd> {
        let ok = |v: f32| v.is_finite() && v >= 0.0;
        if !ok(cfg.lr) || !ok(cfg.momentum) || cfg.momentum >= 1.0 || !ok(cfg.weight_decay) {
            return Err(Error::invalid(format!("bad SGD config {cfg:?}")));
        }
        if cfg.clip.is_some_and(|c| c.is_nan() || c <= 0.0) || (cfg.nesterov && cfg.momentum == 0.0) {
            return Err(Error::invalid(format!("bad SGD config {cfg:?}")));
        }
        Ok(Sgd { cfg, bufs: Vec::new(), steps: 0 })
    }

    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// One update with learning rate `lr` (from a schedule; `cfg.lr` is not used here).
    ///
    /// # Errors
    /// `Error::InvalidInput` when a gradient holds NaN/inf (nothing is updated then),
    /// `Error::Shape` when a gradient's size differs from its parameter's.
    pub fn step(&mut self, params: &mut ParamStore, grads: &Grads, lr: f32) -> Result<()> {
        let ids: Vec<_> = params.ids().filter(|&id| params.kind(id) == ParamKind::Trainable).collect();
        for &id in &ids {
            if let Some(g) = grads.get(id) {
                if g.len() != params.get(id).len() {
                    return Err(Error::Shape {
                        op: "sgd",
                        msg: format!(
                            "gradient {} for '{}' {}",
                            g.shape(),
                            params.name(id),
                            params.get(id).shape()
                        ),
                    });
                }
                if let Some(i) = g.data().iter().position(|v| !v.is_finite()) {
                    return Err(Error::invalid(format!(
                        "non-finite gradient in '{}' at element {i}",
                        params.name(id)
                    )));
                }
            }
        }
        let SgdConfig { momentum: m, weight_decay: wd, clip, nesterov, .. } = self.cfg;
        if self.bufs.len() < params.len() {
            self.bufs.resize(params.len(), None);
        }
        for id in ids {
            let Some(g) = grads.get(id) else { continue };
            let theta = params.get_mut(id).data_mut();
            let buf = &mut self.bufs[id.0];
            let first = buf.is_none();
            let b = buf.get_or_insert_with(|| vec![0.0; theta.len()]);
            for ((t, &gi), bi) in theta.iter_mut().zip(g.data()).zip(b.iter_mut()) {
                let gi = match clip {
                    Some(c) => gi.clamp(-c, c),
                    None => gi,
                };
                let mut d = gi + wd * *t;
                if m != 0.0 {
                    *bi = if first { d } else { m * *bi + d };
                    d = if nesterov { d + m * *bi } else { *bi };
                }
                *t -= lr * d;
            }
        }
        self.steps += 1;
        Ok(())
    }

    /// The momentum buffers by parameter name (for checkpoints).
    pub fn buffers(&self, params: &ParamStore) -> Vec<(String, Tensor)> {
        let mut out = Vec::new();
        for (i, b) in self.bufs.iter().enumerate() {
            if let (Some(b), true) = (b, i < params.len()) {
                let id = crate::tensor::ParamId(i);
                if let Ok(t) = Tensor::from_shape(params.get(id).shape(), b.clone()) {
                    out.push((params.name(id).to_string(), t));
                }
            }
        }
        out
    }

    /// Restores buffers saved by [`Sgd::buffers`] and the step count.
    ///
    /// # Errors
    /// `Error::InvalidInput` for an unknown name or a non-trainable tensor,
    /// `Error::Shape` for a size mismatch.
    pub fn set_buffers(&mut self, params: &ParamStore, bufs: &[(String, Tensor)], steps: u64) -> Result<()> {
        let mut new = vec![None; params.len()];
        for (name, t) in bufs {
            let id = params
                .find(name)
                .ok_or_else(|| Error::invalid(format!("momentum buffer for unknown '{name}'")))?;
            if params.kind(id) != ParamKind::Trainable {
                return Err(Error::invalid(format!("momentum buffer for non-trainable '{name}'")));
            }
            if params.get(id).shape() != t.shape() {
                return Err(Error::Shape {
                    op: "sgd",
                    msg: format!("momentum '{name}' {} vs parameter {}", t.shape(), params.get(id).shape()),
                });
            }
            new[id.0] = Some(t.data().to_vec());
        }
        self.bufs = new;
        self.steps = steps;
        Ok(())
    }
}
