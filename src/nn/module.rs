//! The [`Module`] trait (a layer's forward on a tape), [`Sequential`] composition and
//! the [`ResidualBlock`] of the face encoder.
//!
//! ```
//! use point2quad::nn::{batch_norm::BatchNormConfig, conv1d::ConvBnAct, module::{Module, Sequential}};
//! use point2quad::tensor::{Act, Graph, Grads, ParamStore, Tensor};
//! use point2quad::rng::Rng;
//! let (mut params, mut rng) = (ParamStore::new(), Rng::new(0));
//! let net = Sequential::new(vec![
//!     Box::new(ConvBnAct::new(&mut params, "l0", 3, 8, Act::LeakyRelu(0.1), BatchNormConfig::default(), &mut rng)?),
//!     Box::new(ConvBnAct::new(&mut params, "l1", 8, 2, Act::Identity, BatchNormConfig::default(), &mut rng)?),
//! ]);
//! let mut g = Graph::train(&mut params);
//! let x = g.input(Tensor::new(&[5, 3], (0..15).map(|i| i as f32).collect())?);
//! let y = net.forward(&mut g, x)?;
//! let loss = g.mean(y)?;
//! let mut grads = Grads::new();
//! g.backward(loss, &mut grads)?;
//! # Ok::<(), point2quad::Error>(())
//! ```

use super::batch_norm::BatchNormConfig;
use super::conv1d::ConvBnAct;
use crate::rng::Rng;
use crate::tensor::{Act, Graph, ParamStore, Var};
use crate::Result;

/// A layer: builds its output on the tape from its input.
pub trait Module: Send + Sync {
    /// The forward pass.
    ///
    /// # Errors
    /// Shape errors of the input.
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var>;
}

/// Layers applied one after the other. In a non-recording graph each intermediate
/// is freed as soon as the next layer has consumed it.
pub struct Sequential {
    /// The layers, in order.
    pub layers: Vec<Box<dyn Module>>,
}

impl Sequential {
    /// A sequence of layers.
    pub fn new(layers: Vec<Box<dyn Module>>) -> Sequential {
        Sequential { layers }
    }
}

impl Module for Sequential {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        let mut h = x;
        for (i, l) in self.layers.iter().enumerate() {
            let next = l.forward(g, h)?;
            if i > 0 {
                g.free(h);
            }
            h = next;
        }
        Ok(h)
    }
}

/// `act(x + BN(conv(act(BN(conv(x))))))` at constant width (two fused blocks and a
/// skip connection).
pub struct ResidualBlock {
    /// First block (with activation).
    pub a: ConvBnAct,
    /// Second block (no activation before the sum).
    pub b: ConvBnAct,
    /// Activation after the sum.
    pub act: Act,
}

impl ResidualBlock {
    /// Registers `"{name}.a.*"` and `"{name}.b.*"`.
    ///
    /// # Errors
    /// As [`ConvBnAct::new`].
    pub fn new(
        store: &mut ParamStore,
        name: &str,
        width: usize,
        act: Act,
        bn: BatchNormConfig,
        rng: &mut Rng,
    ) -> Result<Self> {
        let a = ConvBnAct::new(store, &format!("{name}.a"), width, width, act, bn, rng)?;
        let b = ConvBnAct::new(store, &format!("{name}.b"), width, width, Act::Identity, bn, rng)?;
        Ok(ResidualBlock { a, b, act })
    }
}

impl Module for ResidualBlock {
    fn forward(&self, g: &mut Graph, x: Var) -> Result<Var> {
        let h = self.a.forward(g, x)?;
        let h2 = self.b.forward(g, h)?;
        g.free(h);
        let s = g.add(x, h2)?;
        g.free(h2);
        let y = match self.act {
            Act::Identity => return Ok(s),
            Act::Relu => g.relu(s)?,
            Act::LeakyRelu(k) => g.leaky_relu(s, k)?,
        };
        g.free(s);
        Ok(y)
    }
}
