//! Neural-network layers over the tensor engine: conv1d, batch norm, activations, KPConv and its kernel points, losses, the SGD optimiser and checkpoints.

pub mod activation;
pub mod batch_norm;
pub mod checkpoint;
pub mod conv1d;
pub mod dropout;
pub mod kernel_points;
pub mod kpconv;
pub mod kpfcnn;
pub mod loss;
pub mod module;
pub mod optim;
