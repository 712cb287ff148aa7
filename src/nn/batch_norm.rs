//! `BatchNorm1d` over the channels of `[M × C]` rows, as PyTorch: train mode normalises
//! with the batch mean and biased variance and updates the running statistics
//! (`running = (1 − momentum)·running + momentum·batch`, unbiased variance for the
//! running variance); eval mode uses the running statistics. Affine weight starts at
//! 1, bias at 0, running mean 0, running variance 1.

use super::module::Module;
use crate::tensor::{Act, BnRefs, Graph, ParamId, ParamKind, ParamStore, Tensor, Var};
use crate::{Error, Result};

/// Batch-norm hyperparameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BatchNormConfig {
    /// Added to the variance (PyTorch default 1e-5).
    pub eps: f32,
    /// Weight of the new batch in the running statistics (PyTorch default 0.1;
    /// DESIGN's `paper` preset uses 0.02).
    pub momentum: f32,
}

impl Default for BatchNormConfig {
    fn default() -> Self {
        BatchNormConfig { eps: 1e-5, momentum: 0.1 }
    }
}

/// Batch normalisation of `C` channels. Tensors: `"{name}.weight"`, `"{name}.bias"`
/// (trainable), `"{name}.running_mean"`, `"{name}.running_var"` (buffers).
#[derive(Clone, Debug)]
pub struct BatchNorm1d {
    /// γ `[C]`.
    pub weight: ParamId,
    /// β `[C]`.
    pub bias: ParamId,
    /// Running mean `[C]`.
    pub running_mean: ParamId,
    /// Running variance `[C]`.
    pub running_var: ParamId,
    /// Channels.
    pub channels: usize,
    /// Hyperparameters.
    pub cfg: BatchNormConfig,
}

impl BatchNorm1d {
    /// Registers the tensors under `name`.
    ///
    /// # Errors
    /// `Error::InvalidInput` for a duplicate name, zero channels or a momentum outside [0, 1].
    pub fn new(
        store: &mut ParamStore,
        name: &str,
        channels: usize,
        cfg: BatchNormConfig,
    ) -> Result<BatchNorm1d> {
        if channels == 0 {
            return Err(Error::invalid(format!("batch norm '{name}' with 0 channels")));
        }
        if !(0.0..=1.0).contains(&cfg.momentum) || cfg.eps.is_nan() || cfg.eps < 0.0 {
            return Err(Error::invalid(format!(
                "batch norm '{name}': momentum {} / eps {}",
                cfg.momentum, cfg.eps
            )));
        }
        let c = channels;
        Ok(BatchNorm1d {
            weight: store.add(&format!("{name}.weight"), ParamKind::Trainable, Tensor::full(&[c], 1.0)?)?,
            bias: store.add(&format!("{name}.bias"), ParamKind::Trainable, Tensor::zeros(&[c])?)?,
            running_mean: store.add(
                &format!("{name}.running_mean"),
                ParamKind::Buffer,
                Tensor::zeros(&[c])?,
            )?,
            running_var: store.add(
                &format!("{name}.running_var"),
                ParamKind::Buffer,
                Tensor::full(&[c], 1.0)?,
            )?,
            channels,
            cfg,
        })
    }

    /// The references the fused tape op needs.
    pub fn refs(&self) -> BnRefs {
        BnRefs {
            running_mean: self.running_mean,
            running_var: self.running_var,
            eps: self.cfg.eps,
            momentum: self.cfg.momentum,
        }
    }

    /// Batch norm followed by `act`, one tape op.
    ///
    /// # Errors
    /// As [`Graph::conv_bn_act`].
    pub fn forward_act(&self, g: &mut Graph, x: Var, act: Act) -> Result<Var> {
        let (gamma, beta) = (g.param(self.weight), g.param(self.bias));
        g.conv_bn_act(x, None, gamma, beta, self.refs(), act)
    }
}

impl Module for BatchNorm1d {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        self.forward_act(g, x, Act::Identity)
    }
}
