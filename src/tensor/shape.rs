//! Tensor shapes: up to four dimensions, row-major. Most of the engine works on the
//! 2-D view `rows × cols`, where `cols` is the last dimension (channels) and `rows`
//! the product of the others (points or faces).

use crate::{Error, Result};
use std::fmt;

/// Largest rank a [`Shape`] can hold.
pub const MAX_RANK: usize = 4;

/// The dimensions of a tensor (rank 0 to [`MAX_RANK`]). `Copy`, so ops pass it freely.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Shape {
    dims: [usize; MAX_RANK],
    rank: u8,
}

impl Shape {
    /// A shape from its dimensions.
    ///
    /// # Errors
    /// `Error::Shape` when `dims` has more than [`MAX_RANK`] entries or the element
    /// count overflows `usize`.
    pub fn new(dims: &[usize]) -> Result<Shape> {
        if dims.len() > MAX_RANK {
            return Err(Error::Shape {
                op: "shape",
                msg: format!("rank {} > {MAX_RANK}: {dims:?}", dims.len()),
            });
        }
        let mut n: usize = 1;
        for &d in dims {
            n = n.checked_mul(d).ok_or_else(|| Error::Shape {
                op: "shape",
                msg: format!("element count of {dims:?} overflows"),
            })?;
        }
        let mut a = [0usize; MAX_RANK];
        a[..dims.len()].copy_from_slice(dims);
        Ok(Shape { dims: a, rank: dims.len() as u8 })
    }

    /// The rank-0 (scalar) shape.
    pub fn scalar() -> Shape {
        Shape { dims: [0; MAX_RANK], rank: 0 }
    }

    /// A 2-D shape `rows × cols` (always valid unless the product overflows).
    ///
    /// # Errors
    /// `Error::Shape` if `rows · cols` overflows.
    pub fn matrix(rows: usize, cols: usize) -> Result<Shape> {
        Shape::new(&[rows, cols])
    }

    /// The dimensions.
    pub fn dims(&self) -> &[usize] {
        &self.dims[..self.rank as usize]
    }

    /// Number of dimensions.
    pub fn rank(&self) -> usize {
        self.rank as usize
    }

    /// Number of elements (1 for a scalar).
    pub fn numel(&self) -> usize {
        self.dims().iter().product()
    }

    /// Columns of the 2-D view: the last dimension (1 for a scalar).
    pub fn cols(&self) -> usize {
        self.dims().last().copied().unwrap_or(1)
    }

    /// Rows of the 2-D view: the product of all dimensions but the last (1 for rank ≤ 1).
    pub fn rows(&self) -> usize {
        let d = self.dims();
        if d.len() <= 1 {
            1
        } else {
            d[..d.len() - 1].iter().product()
        }
    }
}

impl fmt::Debug for Shape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.dims())
    }
}

impl fmt::Display for Shape {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.dims())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_and_limits() {
        let s = Shape::new(&[2, 3, 4]).unwrap();
        assert_eq!((s.rows(), s.cols(), s.numel(), s.rank()), (6, 4, 24, 3));
        let v = Shape::new(&[5]).unwrap();
        assert_eq!((v.rows(), v.cols()), (1, 5));
        assert_eq!(Shape::scalar().numel(), 1);
        assert!(Shape::new(&[1, 1, 1, 1, 1]).is_err());
        assert!(Shape::new(&[usize::MAX, 2]).is_err());
    }
}
