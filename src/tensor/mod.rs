//! f32 tensors with reverse-mode automatic differentiation on a Wengert tape.
//!
//! - [`Tensor`]: flat row-major `Vec<f32>` + [`Shape`] (rank ≤ 4; most ops use the
//!   2-D view rows × channels).
//! - [`ParamStore`]: named parameters and buffers; layers hold [`ParamId`]s.
//! - [`Graph`]: the tape. Ops push nodes in execution order; `backward` is a reverse
//!   loop over one exhaustive `match` on [`Op`] (a new op cannot compile without its
//!   gradient); gradients accumulate into [`Grads`]. Layer kernels from other modules
//!   plug in through [`CustomOp`] (its `backward` is required); [`gradcheck()`] checks
//!   any of them against central finite differences.
//!
//! ```
//! use point2quad::tensor::{Graph, Grads, ParamKind, ParamStore, Tensor};
//! let mut params = ParamStore::new();
//! let w = params.add("w", ParamKind::Trainable, Tensor::new(&[2, 3], vec![0.1; 6])?)?;
//! let mut g = Graph::train(&mut params);                  // records; Graph::eval = no_grad
//! let x = g.input(Tensor::new(&[4, 3], vec![1.0; 12])?);  // 4 rows × 3 channels
//! let wv = g.param(w);
//! let y = g.matmul_t(x, wv)?;                             // [4 × 2] = x · wᵀ
//! let loss = g.mean(y)?;
//! let mut grads = Grads::new();
//! g.backward(loss, &mut grads)?;
//! assert_eq!(grads.get(w).unwrap().data(), &[0.5; 6]);     // ∂mean/∂w = Σ_rows x / 8
//! # Ok::<(), point2quad::Error>(())
//! ```
//!
//! Determinism: every reduction runs over fixed chunks combined in a fixed order and
//! the GEMMs are split in fixed row blocks, so the same inputs give bit-identical
//! results for ANY thread count (on the same CPU; the SIMD kernel is picked at run time).

pub mod conv_bn;
pub mod gemm;
pub mod gradcheck;
pub mod op;
pub mod params;
pub mod shape;
pub mod tape;
#[allow(clippy::module_inception)] // `tensor::tensor` holds the Tensor type (STYLE.md: one concept per file)
pub mod tensor;

pub use gradcheck::{gradcheck, GradCheckConfig, GradCheckReport};
pub use op::{Act, CustomOp, Op};
pub use params::{Grads, ParamId, ParamKind, ParamStore};
pub use shape::Shape;
pub use tape::{BnRefs, BnStats, Graph, Var};
pub use tensor::Tensor;
