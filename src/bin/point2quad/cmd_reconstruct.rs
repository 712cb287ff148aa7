//! `point2quad reconstruct` (to be written).

#[allow(unused_imports)]
use crate::args::Args;
use point2quad::{Error, Result};

pub const HELP: &str = "point2quad reconstruct: not available yet";

pub fn run(_args: &[String]) -> Result<()> {
    Err(Error::Usage("point2quad reconstruct: not implemented yet".into()))
}
