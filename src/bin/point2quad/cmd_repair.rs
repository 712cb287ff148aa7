//! `point2quad repair` (to be written).

#[allow(unused_imports)]
use crate::args::Args;
use point2quad::{Error, Result};

pub const HELP: &str = "point2quad repair: not available yet";

pub fn run(_args: &[String]) -> Result<()> {
    Err(Error::Usage("point2quad repair: not implemented yet".into()))
}
