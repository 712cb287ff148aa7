//! Inverted dropout: in train mode each element is zeroed with probability `p` and the
//! survivors scaled by `1/(1 − p)`; in eval mode it is the identity. The mask comes
//! from an explicit [`Rng`], so a seed fixes it.

use crate::rng::Rng;
use crate::tensor::{Graph, Tensor, Var};
use crate::{Error, Result};

/// Dropout with drop probability `p`.
#[derive(Clone, Copy, Debug)]
pub struct Dropout {
    /// Probability of zeroing an element, in `[0, 1)`.
    pub p: f32,
}

impl Dropout {
    /// A dropout layer.
    ///
    /// # Errors
    /// `Error::InvalidInput` unless `0 ≤ p < 1`.
    pub fn new(p: f32) -> Result<Dropout> {
        if !(0.0..1.0).contains(&p) {
            return Err(Error::invalid(format!("dropout probability {p} not in [0, 1)")));
        }
        Ok(Dropout { p })
    }

    /// Applies dropout (train mode only), drawing the mask from `rng`.
    ///
    /// # Errors
    /// `Error::Shape` when `x` was freed.
    pub fn forward(&self, g: &mut Graph, x: Var, rng: &mut Rng) -> Result<Var> {
        if !g.is_train() || self.p == 0.0 {
            return Ok(x);
        }
        let shape = g.value(x).shape();
        let keep = 1.0 / (1.0 - self.p);
        let mask: Vec<f32> =
            (0..shape.numel()).map(|_| if rng.f32() < self.p { 0.0 } else { keep }).collect();
        let m = g.input(Tensor::from_shape(shape, mask)?);
        g.mul(x, m)
    }
}
