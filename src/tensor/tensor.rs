//! `Tensor`: f32 values in one flat, contiguous, row-major `Vec<f32>` plus a [`Shape`].
//! Tensors are plain values; autodiff lives in the tape (`tape.rs`), which stores them.

use super::shape::Shape;
use crate::{Error, Result};

/// A dense f32 tensor (row-major, contiguous). Invariant: `data.len() == shape.numel()`.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    shape: Shape,
    data: Vec<f32>,
}

impl Tensor {
    /// A tensor from its dimensions and row-major data.
    ///
    /// # Errors
    /// `Error::Shape` when `data.len()` differs from the product of `dims` or the
    /// rank exceeds 4.
    pub fn new(dims: &[usize], data: Vec<f32>) -> Result<Tensor> {
        let shape = Shape::new(dims)?;
        Tensor::from_shape(shape, data)
    }

    /// A tensor from a [`Shape`] and data.
    ///
    /// # Errors
    /// `Error::Shape` when `data.len() != shape.numel()`.
    pub fn from_shape(shape: Shape, data: Vec<f32>) -> Result<Tensor> {
        if data.len() != shape.numel() {
            return Err(Error::Shape {
                op: "tensor",
                msg: format!("{} values for shape {shape} ({} elements)", data.len(), shape.numel()),
            });
        }
        Ok(Tensor { shape, data })
    }

    /// A tensor of zeros.
    ///
    /// # Errors
    /// `Error::Shape` for a rank above 4 or an overflowing element count.
    pub fn zeros(dims: &[usize]) -> Result<Tensor> {
        Tensor::full(dims, 0.0)
    }

    /// A tensor filled with `value`.
    ///
    /// # Errors
    /// `Error::Shape` for a rank above 4 or an overflowing element count.
    pub fn full(dims: &[usize], value: f32) -> Result<Tensor> {
        let shape = Shape::new(dims)?;
        Ok(Tensor { shape, data: vec![value; shape.numel()] })
    }

    /// A zero tensor of an existing shape.
    pub fn zeros_like_shape(shape: Shape) -> Tensor {
        Tensor { shape, data: vec![0.0; shape.numel()] }
    }

    /// A rank-0 tensor holding `v`.
    pub fn scalar(v: f32) -> Tensor {
        Tensor { shape: Shape::scalar(), data: vec![v] }
    }

    /// A `rows × cols` matrix from row-major data.
    ///
    /// # Errors
    /// `Error::Shape` when `data.len() != rows · cols`.
    pub fn matrix(rows: usize, cols: usize, data: Vec<f32>) -> Result<Tensor> {
        Tensor::new(&[rows, cols], data)
    }

    /// The shape.
    pub fn shape(&self) -> Shape {
        self.shape
    }

    /// The dimensions.
    pub fn dims(&self) -> &[usize] {
        self.shape.dims()
    }

    /// Rows of the 2-D view (all dimensions but the last).
    pub fn rows(&self) -> usize {
        self.shape.rows()
    }

    /// Columns of the 2-D view (the last dimension).
    pub fn cols(&self) -> usize {
        self.shape.cols()
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        self.data.len()
    }

    /// True when the tensor holds no element (some dimension is 0).
    pub fn is_empty(&self) -> bool {
        self.data.is_empty()
    }

    /// The row-major values.
    pub fn data(&self) -> &[f32] {
        &self.data
    }

    /// The row-major values, mutable (the shape cannot change through this).
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }

    /// Consumes the tensor, returning its values.
    pub fn into_data(self) -> Vec<f32> {
        self.data
    }

    /// Row `r` of the 2-D view.
    ///
    /// # Panics
    /// When `r >= self.rows()`.
    pub fn row(&self, r: usize) -> &[f32] {
        let c = self.cols();
        &self.data[r * c..(r + 1) * c]
    }

    /// The single value of a one-element tensor.
    ///
    /// # Errors
    /// `Error::Shape` when the tensor does not hold exactly one element.
    pub fn item(&self) -> Result<f32> {
        if self.data.len() != 1 {
            return Err(Error::Shape {
                op: "item",
                msg: format!("tensor of shape {} is not a scalar", self.shape),
            });
        }
        Ok(self.data[0])
    }

    /// Same data under another shape with the same element count.
    ///
    /// # Errors
    /// `Error::Shape` when the element counts differ.
    pub fn reshape(self, dims: &[usize]) -> Result<Tensor> {
        let shape = Shape::new(dims)?;
        if shape.numel() != self.data.len() {
            return Err(Error::Shape { op: "reshape", msg: format!("{} to {shape}", self.shape) });
        }
        Ok(Tensor { shape, data: self.data })
    }

    /// `self += other`, element-wise, same shape.
    ///
    /// # Errors
    /// `Error::Shape` when the element counts differ.
    pub fn add_assign(&mut self, other: &Tensor) -> Result<()> {
        if self.data.len() != other.data.len() {
            return Err(Error::Shape { op: "add_assign", msg: format!("{} += {}", self.shape, other.shape) });
        }
        for (a, b) in self.data.iter_mut().zip(&other.data) {
            *a += b;
        }
        Ok(())
    }

    /// True when every value is finite.
    pub fn all_finite(&self) -> bool {
        self.data.iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn construction_checks_lengths() {
        assert!(Tensor::new(&[2, 3], vec![0.0; 5]).is_err());
        let t = Tensor::new(&[2, 3], (0..6).map(|i| i as f32).collect()).unwrap();
        assert_eq!(t.row(1), &[3.0, 4.0, 5.0]);
        assert!(t.clone().reshape(&[4]).is_err());
        assert_eq!(t.reshape(&[3, 2]).unwrap().row(2), &[4.0, 5.0]);
        assert_eq!(Tensor::scalar(2.5).item().unwrap(), 2.5);
    }
}
