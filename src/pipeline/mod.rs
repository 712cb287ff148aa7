//! The Point2Quad pipeline: normalising frame, normals, candidate quads and their features, noise and datasets, the model, training and reconstruction.

pub mod augment;
pub mod candidates;
pub mod dataset;
pub mod features;
pub mod frame;
pub mod model;
pub mod noise;
pub mod normals;
pub mod reconstruct;
pub mod refine;
pub mod second_pass;
pub mod train;
