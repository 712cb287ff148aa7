//! f32 tensors with reverse-mode automatic differentiation on a Wengert tape.

#[allow(clippy::module_inception)] // `tensor::tensor` holds the Tensor type (STYLE.md: one concept per file)
pub mod tensor;
