//! f32 tensors with reverse-mode automatic differentiation on a Wengert tape.

pub mod tensor;
