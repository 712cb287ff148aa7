//! Activation layers (ReLU, LeakyReLU) as [`Module`]s over the tape's element-wise ops.

use super::module::Module;
use crate::tensor::{Graph, Var};
use crate::Result;

/// `max(0, x)`.
#[derive(Clone, Copy, Debug, Default)]
pub struct Relu;

impl Module for Relu {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        g.relu(x)
    }
}

/// `x` for `x > 0`, `slope·x` otherwise (the network uses 0.1).
#[derive(Clone, Copy, Debug)]
pub struct LeakyRelu {
    /// Slope on the negative side.
    pub slope: f32,
}

impl Module for LeakyRelu {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        g.leaky_relu(x, self.slope)
    }
}
