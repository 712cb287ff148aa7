//! Writing to stdout and stderr without `print!`, which panics when the reader has
//! gone away (`point2quad eval x.obj | head -c 10`, `| true`). A closed stdout pipe
//! ends the output quietly, as in other Unix tools; other stdout failures are errors.

#![allow(dead_code)] // some helpers are used by only some subcommands

use point2quad::{Error, Result};
use std::io::{ErrorKind, Write};

/// Writes `text` to stdout and flushes it. A broken pipe (the reader stopped
/// listening) is not an error: there is nobody left to tell.
///
/// # Errors
/// `Io` (path `<stdout>`) for any other write failure, e.g. a full disk behind `>`.
pub fn stdout(text: &str) -> Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != ErrorKind::BrokenPipe => Err(Error::io("<stdout>", e)),
        _ => Ok(()),
    }
}

/// Writes `text` to stderr; failures are ignored (there is no channel left to report them on).
pub fn stderr(text: &str) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_all(text.as_bytes()).and_then(|()| err.flush());
}
