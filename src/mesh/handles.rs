//! Typed handles into the half-edge mesh: `VertexId`, `HalfedgeId`, `FaceId`, each a
//! `u32` index. Twin half-edges are allocated in pairs, so the opposite of half-edge
//! `h` is `h ^ 1` and the edge index is `h >> 1`.

use std::fmt;

/// A vertex of a [`crate::mesh::halfedge::HalfedgeMesh`] (index into its vertex arrays).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct VertexId(pub u32);

/// A half-edge (directed edge) of a half-edge mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct HalfedgeId(pub u32);

/// A face (quad) of a half-edge mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FaceId(pub u32);

impl VertexId {
    /// The index as `usize`, for indexing arrays.
    #[inline]
    pub fn idx(self) -> usize {
        self.0 as usize
    }
}

impl HalfedgeId {
    /// The index as `usize`, for indexing arrays.
    #[inline]
    pub fn idx(self) -> usize {
        self.0 as usize
    }
    /// The twin half-edge (same edge, other direction).
    #[inline]
    pub fn opposite(self) -> HalfedgeId {
        HalfedgeId(self.0 ^ 1)
    }
    /// The index of the undirected edge this half-edge belongs to.
    #[inline]
    pub fn edge(self) -> usize {
        (self.0 >> 1) as usize
    }
}

impl FaceId {
    /// The index as `usize`, for indexing arrays.
    #[inline]
    pub fn idx(self) -> usize {
        self.0 as usize
    }
}

/// The twin of `h`: `h ^ 1`.
#[inline]
pub fn opposite(h: HalfedgeId) -> HalfedgeId {
    h.opposite()
}

impl fmt::Display for VertexId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "vertex {}", self.0)
    }
}
impl fmt::Display for HalfedgeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "half-edge {}", self.0)
    }
}
impl fmt::Display for FaceId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "face {}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn twins_pair_up_and_share_an_edge() {
        for i in 0..10u32 {
            let h = HalfedgeId(i);
            assert_eq!(opposite(opposite(h)), h);
            assert_ne!(opposite(h), h);
            assert_eq!(opposite(h).edge(), h.edge());
        }
        assert_eq!(FaceId(3).to_string(), "face 3");
    }
}
