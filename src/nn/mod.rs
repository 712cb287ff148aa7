//! Neural-network layers over the tensor engine: conv1d, batch norm, activations, KPConv and its kernel points, losses, the SGD optimiser and checkpoints.

pub mod module;
