//! `Conv1d` with kernel size 1 (one linear map shared by every row: point or face), and
//! the fused `ConvBnAct` unary block (conv1d without bias + batch norm + activation in
//! one tape op with a hand-written backward) — the hot path of the face network.

use super::batch_norm::{BatchNorm1d, BatchNormConfig};
use super::module::Module;
use crate::rng::Rng;
use crate::tensor::{Act, Graph, ParamId, ParamKind, ParamStore, Tensor, Var};
use crate::{Error, Result};

/// `U(−b, b)` samples for an `n`-element tensor of shape `dims`.
fn uniform(dims: &[usize], bound: f32, rng: &mut Rng) -> Result<Tensor> {
    let n: usize = dims.iter().product();
    Tensor::new(dims, (0..n).map(|_| (rng.f32() * 2.0 - 1.0) * bound).collect())
}

/// PyTorch's default conv/linear initialisation: `kaiming_uniform_(a = √5)` gives
/// weights `U(−1/√fan_in, 1/√fan_in)` (gain √(2/(1+5)) · √(3/fan_in) = 1/√fan_in), and
/// the bias the same bound; `fan_in = C_in · kernel_size = C_in`.
pub fn kaiming_uniform(cout: usize, cin: usize, rng: &mut Rng) -> Result<Tensor> {
    uniform(&[cout, cin], 1.0 / (cin.max(1) as f32).sqrt(), rng)
}

/// Linear map per row: `[M × C_in] → [M × C_out]`, `y = x·Wᵀ (+ b)`; weight `[C_out × C_in]`.
#[derive(Clone, Debug)]
pub struct Conv1d {
    /// Weight `[C_out × C_in]` (`"{name}.weight"`).
    pub weight: ParamId,
    /// Optional bias `[C_out]` (`"{name}.bias"`).
    pub bias: Option<ParamId>,
    /// Input width.
    pub cin: usize,
    /// Output width.
    pub cout: usize,
}

impl Conv1d {
    /// Registers the weights under `name` with PyTorch's initialisation (see
    /// [`kaiming_uniform`]).
    ///
    /// # Errors
    /// `Error::InvalidInput` for a duplicate name or a zero width.
    pub fn new(
        store: &mut ParamStore,
        name: &str,
        cin: usize,
        cout: usize,
        bias: bool,
        rng: &mut Rng,
    ) -> Result<Conv1d> {
        if cin == 0 || cout == 0 {
            return Err(Error::invalid(format!("conv1d '{name}': widths must be positive ({cin} → {cout})")));
        }
        let weight =
            store.add(&format!("{name}.weight"), ParamKind::Trainable, kaiming_uniform(cout, cin, rng)?)?;
        let bias = if bias {
            let b = uniform(&[cout], 1.0 / (cin as f32).sqrt(), rng)?;
            Some(store.add(&format!("{name}.bias"), ParamKind::Trainable, b)?)
        } else {
            None
        };
        Ok(Conv1d { weight, bias, cin, cout })
    }
}

impl Module for Conv1d {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        let w = g.param(self.weight);
        let y = g.matmul_t(x, w)?;
        match self.bias {
            Some(b) => {
                let b = g.param(b);
                g.add(y, b)
            }
            None => Ok(y),
        }
    }
}

/// Fused unary block `act(BN(x·Wᵀ))`: no conv bias (batch norm's shift makes it
/// redundant, as in KPConv's `UnaryBlock`).
#[derive(Clone, Debug)]
pub struct ConvBnAct {
    /// Weight `[C_out × C_in]` (`"{name}.weight"`, Kaiming-uniform initialised).
    pub weight: ParamId,
    /// The batch norm (`"{name}.bn.*"`).
    pub bn: BatchNorm1d,
    /// The activation.
    pub act: Act,
    /// Input width.
    pub cin: usize,
    /// Output width.
    pub cout: usize,
}

impl ConvBnAct {
    /// Registers the block's tensors under `name`.
    ///
    /// # Errors
    /// `Error::InvalidInput` for a duplicate name, a zero width or a negative slope.
    pub fn new(
        store: &mut ParamStore,
        name: &str,
        cin: usize,
        cout: usize,
        act: Act,
        bn: BatchNormConfig,
        rng: &mut Rng,
    ) -> Result<ConvBnAct> {
        if cin == 0 || cout == 0 {
            return Err(Error::invalid(format!("block '{name}': widths must be positive ({cin} → {cout})")));
        }
        if let Act::LeakyRelu(s) = act {
            if s.is_nan() || s < 0.0 {
                return Err(Error::invalid(format!("block '{name}': leaky slope {s} must be ≥ 0")));
            }
        }
        let weight =
            store.add(&format!("{name}.weight"), ParamKind::Trainable, kaiming_uniform(cout, cin, rng)?)?;
        let bn = BatchNorm1d::new(store, &format!("{name}.bn"), cout, bn)?;
        Ok(ConvBnAct { weight, bn, act, cin, cout })
    }
}

impl Module for ConvBnAct {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        let w = g.param(self.weight);
        let (gamma, beta) = (g.param(self.bn.weight), g.param(self.bn.bias));
        g.conv_bn_act(x, Some(w), gamma, beta, self.bn.refs(), self.act)
    }
}
