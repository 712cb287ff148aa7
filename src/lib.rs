//! point2quad: point cloud → pure-quad manifold mesh by learned face prediction
//! (Point2Quad, Li et al.), on a from-scratch engine: tensors with reverse-mode
//! autodiff, KPConv, a kd-tree and a half-edge quad mesh. See `README.md`.

mod clock;
pub mod error;
pub mod math;
pub mod par;
pub mod rng;

pub mod io;
pub mod mesh;
pub mod nn;
pub mod pipeline;
pub mod spatial;
pub mod tensor;

pub use error::{Error, Result};
