//! `point2quad candidates` (to be written).

#[allow(unused_imports)]
use crate::args::Args;
use point2quad::{Error, Result};

pub const HELP: &str = "point2quad candidates: not available yet";

pub fn run(_args: &[String]) -> Result<()> {
    Err(Error::Usage("point2quad candidates: not implemented yet".into()))
}
