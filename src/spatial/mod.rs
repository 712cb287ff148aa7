//! Spatial search: a kd-tree for exact kNN and radius queries, and grid subsampling.

pub mod kdtree;
pub mod neighborhoods;
pub mod subsample;
