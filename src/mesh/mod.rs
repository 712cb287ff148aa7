//! Quad meshes: plain indexed meshes, the half-edge core with its validator, face soups, and the algorithms over them (post-process, hole filling, quality metrics, synthetic shapes).

pub mod close;
pub mod coarsen;
pub mod halfedge;
pub mod handles;
pub mod hole_fill;
pub mod poly;
pub mod postprocess;
pub mod quality;
pub mod rescue;
pub mod shapes;
pub mod soup;
pub mod validate;
pub mod watertight;
