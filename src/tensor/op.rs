//! The closed set of differentiable operations recorded on the tape. The backward
//! pass (`tape.rs`) is one exhaustive `match` over [`Op`], so adding a variant does
//! not compile until its gradient is written. Layer kernels written elsewhere (KPConv)
//! enter through [`Op::Custom`] and the [`CustomOp`] trait, whose `backward` is a
//! required method — the same guarantee for code outside this module.
//!
//! # Adding a custom op
//! 1. A struct owning the op's non-differentiable data (neighbour indices, influence
//!    weights…) and whatever `forward` wants to save for `backward`.
//! 2. `impl CustomOp`: `forward(&mut self, inputs)` computes the output (and may store
//!    saved buffers in `self`); `backward(&self, inputs, output, grad_output,
//!    needs_grad)` returns one `Option<Tensor>` per input, shaped like that input
//!    (`None` where `needs_grad[i]` is false). The tape adds them (`+=`).
//! 3. Call it with `graph.custom(Box::new(op), &[features, weights])`.
//! 4. Check it with [`crate::tensor::gradcheck()`] on random shapes (see `tests/tensor_ops.rs`).

use super::tape::Var;
use super::tensor::Tensor;
use crate::Result;
use std::sync::Arc;

/// Activation applied by the fused [`Op::ConvBnAct`] and available as an op.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Act {
    /// No activation.
    Identity,
    /// `max(0, y)`.
    Relu,
    /// `y` for `y > 0`, `slope · y` otherwise; `slope ≥ 0`.
    LeakyRelu(f32),
}

impl Act {
    /// The activation of `y`.
    #[inline]
    pub fn apply(self, y: f32) -> f32 {
        match self {
            Act::Identity => y,
            Act::Relu => y.max(0.0),
            Act::LeakyRelu(s) => {
                if y > 0.0 {
                    y
                } else {
                    s * y
                }
            }
        }
    }

    /// The derivative, read from the activation's OUTPUT `a` (valid because every
    /// variant with `slope ≥ 0` keeps the sign: `a > 0 ⇔ y > 0`).
    #[inline]
    pub fn grad_from_output(self, a: f32) -> f32 {
        match self {
            Act::Identity => 1.0,
            Act::Relu => {
                if a > 0.0 {
                    1.0
                } else {
                    0.0
                }
            }
            Act::LeakyRelu(s) => {
                if a > 0.0 {
                    1.0
                } else {
                    s
                }
            }
        }
    }
}

/// A user-defined differentiable operation with a hand-written gradient.
pub trait CustomOp: Send + Sync {
    /// Name used in error messages.
    fn name(&self) -> &'static str;

    /// Computes the output from the input values. May keep what `backward` needs in `self`.
    ///
    /// # Errors
    /// Shape or data errors of the inputs.
    fn forward(&mut self, inputs: &[&Tensor]) -> Result<Tensor>;

    /// Gradients of the inputs given the gradient of the output: one entry per input,
    /// shaped like it, `None` allowed where `needs_grad[i]` is false.
    ///
    /// # Errors
    /// Internal shape mismatches.
    fn backward(
        &self,
        inputs: &[&Tensor],
        output: &Tensor,
        grad_output: &Tensor,
        needs_grad: &[bool],
    ) -> Result<Vec<Option<Tensor>>>;
}

/// What the fused conv1d + batch norm + activation keeps for its backward pass.
pub struct ConvBnSaved {
    /// Input features `[M × C_in]`.
    pub x: Var,
    /// Weight `[C_out × C_in]`, or `None` for batch norm alone (`C_in = C_out`).
    pub w: Option<Var>,
    /// Batch-norm scale `[C_out]`.
    pub gamma: Var,
    /// Batch-norm shift `[C_out]`.
    pub beta: Var,
    /// Activation after the affine step.
    pub act: Act,
    /// True when batch statistics normalised (train mode), false for running statistics.
    pub batch_stats: bool,
    /// Pre-normalisation values `z = x·Wᵀ`, `[M × C_out]`.
    pub z: Vec<f32>,
    /// Per-channel mean used to normalise.
    pub mean: Vec<f32>,
    /// Per-channel `1/sqrt(var + eps)` used to normalise.
    pub invstd: Vec<f32>,
}

/// One recorded operation; `Var`s name its inputs on the tape.
pub enum Op {
    /// An input or parameter: no inputs.
    Leaf,
    /// `a · b` (`trans_b`: `a · bᵀ`), 2-D.
    MatMul { a: Var, b: Var, trans_b: bool },
    /// `a + b` with row/column/scalar broadcasting of either side.
    Add { a: Var, b: Var },
    /// `a − b`, broadcasting.
    Sub { a: Var, b: Var },
    /// `a ⊙ b`, broadcasting.
    Mul { a: Var, b: Var },
    /// `a ⊘ b`, broadcasting.
    Div { a: Var, b: Var },
    /// `s · a`.
    Scale { a: Var, s: f32 },
    /// `a + s`.
    AddScalar { a: Var },
    /// Sum of all elements (scalar).
    Sum { a: Var },
    /// Mean of all elements (scalar).
    Mean { a: Var },
    /// Sum (or mean) over rows (`axis 0` → `[1 × C]`) or columns (`axis 1` → `[R × 1]`).
    SumAxis { a: Var, axis: usize, mean: bool },
    /// `exp(a)`.
    Exp { a: Var },
    /// `ln(a)`.
    Log { a: Var },
    /// Log-softmax over the last dimension, row by row.
    LogSoftmax { a: Var },
    /// `max(0, a)`.
    Relu { a: Var },
    /// Leaky ReLU.
    LeakyRelu { a: Var, slope: f32 },
    /// Rows of `a` picked by `idx`; with `padded`, index `rows(a)` selects a zero row.
    GatherRows { a: Var, idx: Arc<[u32]>, padded: bool },
    /// Concatenation along the last dimension.
    ConcatCols { parts: Vec<Var> },
    /// Per output row and channel, the max over `k` neighbour rows of `a`; `argmax`
    /// holds the winning source row (`rows(a)` = the zero shadow row).
    MaxNeighbors { a: Var, argmax: Vec<u32> },
    /// Same data, new shape.
    Reshape { a: Var },
    /// Fused conv1d (k = 1, no bias) + batch norm + activation.
    ConvBnAct(Box<ConvBnSaved>),
    /// A [`CustomOp`] over `inputs`.
    Custom { inputs: Vec<Var>, op: Box<dyn CustomOp> },
}

impl Op {
    /// The inputs of this op, in order.
    pub fn inputs(&self) -> Vec<Var> {
        match self {
            Op::Leaf => vec![],
            Op::MatMul { a, b, .. }
            | Op::Add { a, b }
            | Op::Sub { a, b }
            | Op::Mul { a, b }
            | Op::Div { a, b } => {
                vec![*a, *b]
            }
            Op::Scale { a, .. }
            | Op::AddScalar { a }
            | Op::Sum { a }
            | Op::Mean { a }
            | Op::SumAxis { a, .. }
            | Op::Exp { a }
            | Op::Log { a }
            | Op::LogSoftmax { a }
            | Op::Relu { a }
            | Op::LeakyRelu { a, .. }
            | Op::GatherRows { a, .. }
            | Op::MaxNeighbors { a, .. }
            | Op::Reshape { a } => vec![*a],
            Op::ConcatCols { parts } => parts.clone(),
            Op::ConvBnAct(s) => {
                let mut v = vec![s.x];
                v.extend(s.w);
                v.push(s.gamma);
                v.push(s.beta);
                v
            }
            Op::Custom { inputs, .. } => inputs.clone(),
        }
    }
}
