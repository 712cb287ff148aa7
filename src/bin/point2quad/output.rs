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

/// Progress and summary lines (`eprintln!` through [`info`]): silenced by `--quiet`.
/// Not `eprintln!`, which panics when stderr is a closed pipe (`train ... 2>&1 | head`)
/// and so killed a training run at its next progress line.
macro_rules! say {
    ($($t:tt)*) => { $crate::output::info(&format!("{}\n", format_args!($($t)*))) };
}
pub(crate) use say;

/// Notes and warnings (`eprintln!` through [`stderr`]): shown even with `--quiet`.
macro_rules! note {
    ($($t:tt)*) => { $crate::output::stderr(&format!("{}\n", format_args!($($t)*))) };
}
pub(crate) use note;

static QUIET: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// `--quiet`: from now on [`info`] writes nothing.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, std::sync::atomic::Ordering::Relaxed);
}

/// Writes a progress or summary line to stderr through [`stderr`], unless `--quiet`.
pub fn info(text: &str) {
    if !QUIET.load(std::sync::atomic::Ordering::Relaxed) {
        stderr(text);
    }
}

/// Writes `text` to stderr; failures are ignored (there is no channel left to report them on).
pub fn stderr(text: &str) {
    let mut err = std::io::stderr().lock();
    let _ = err.write_all(text.as_bytes()).and_then(|()| err.flush());
}

/// Checks, before any work, that `path` can be an output file: its folder exists and
/// it is not itself a folder. A long run (training, a large reconstruction) otherwise
/// learns of a typo in the output folder only when it writes, at the very end.
///
/// # Errors
/// `Io` naming `path`: "no such folder" when its parent is missing, "not a folder" when
/// the parent is a file, "names a folder" when it ends with a separator, "is a directory"
/// when `path` is one, "not a regular file" when it exists as a device, pipe or socket.
pub fn check_output_path(path: &std::path::Path) -> Result<()> {
    let parent = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    let fail = |kind: ErrorKind, msg: &str| Err(Error::io(path, std::io::Error::new(kind, msg)));
    // `p.svg/` (or `p.svg/.`) names a folder: the path's components drop the slash, so
    // the temporary file was written as `p.svg` and only the final rename failed, after
    // the outputs committed before it had replaced their targets.
    if point2quad::io::atomic::names_a_folder(path) {
        return fail(
            ErrorKind::Other,
            "ends with a path separator, `.` or `..`, so it names a folder; give a file name",
        );
    }
    match std::fs::metadata(parent) {
        Err(e) if e.kind() == ErrorKind::NotFound => {
            return fail(ErrorKind::NotFound, &format!("no such folder {}", parent.display()))
        }
        Err(e) => return Err(Error::io(path, e)),
        Ok(m) if !m.is_dir() => {
            return fail(ErrorKind::Other, &format!("{} is not a folder", parent.display()))
        }
        Ok(_) => {}
    }
    if path.is_dir() {
        return fail(ErrorKind::Other, "is a directory");
    }
    // An existing device, pipe or socket would be replaced by the rename that ends an
    // atomic write (`train --out /dev/null`, run as root, replaced the system's
    // /dev/null with a regular file). A symbolic link to a regular file passes (the
    // rename replaces the link, not its target; `check_not_input` refuses a link to an
    // input).
    if let Ok(m) = std::fs::metadata(path) {
        if !m.is_file() {
            return fail(
                ErrorKind::Other,
                "exists and is not a regular file (a device, pipe or socket); outputs are written \
                 to a temporary file and renamed over it, so choose a file name",
            );
        }
    }
    Ok(())
}

/// Refuses an output that is the input file itself (the same file under any name):
/// `reconstruct m.obj -o m.obj` would replace the input with the result.
///
/// # Errors
/// `Usage` naming both when `out` exists and is the same file as `input`.
pub fn check_not_input(cmd: &str, out: &std::path::Path, input: &std::path::Path) -> Result<()> {
    if let (Ok(a), Ok(b)) = (std::fs::canonicalize(out), std::fs::canonicalize(input)) {
        if a == b || same_file(&a, &b) {
            return Err(Error::Usage(format!(
                "{cmd}: output {} is the input file {}; choose another output name",
                out.display(),
                input.display()
            )));
        }
    }
    Ok(())
}

/// Whether two existing paths are one file under two names (a hard link): same device
/// and inode. Unix only; elsewhere only the canonical paths are compared.
#[cfg(unix)]
fn same_file(a: &std::path::Path, b: &std::path::Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
    }
}

#[cfg(not(unix))]
fn same_file(_: &std::path::Path, _: &std::path::Path) -> bool {
    false
}

/// Refuses an output that would replace part of the dataset folder `data` that
/// `train`/`refine` read: a `.p2qs` sample or `index.txt` in it (`train --data D --out
/// D/x.p2qs` replaced a sample with weights, and the next run failed on it).
///
/// # Errors
/// `Usage` naming the output and the folder.
pub fn check_not_in_dataset(cmd: &str, out: &std::path::Path, data: &std::path::Path) -> Result<()> {
    let parent = match out.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    let sample = out.extension().is_some_and(|e| e.eq_ignore_ascii_case("p2qs"))
        || out.file_name().is_some_and(|n| n == "index.txt");
    if let (true, Ok(a), Ok(b)) = (sample, std::fs::canonicalize(parent), std::fs::canonicalize(data)) {
        if a == b {
            return Err(Error::Usage(format!(
                "{cmd}: output {} would replace a file of the dataset folder {}; choose another output name",
                out.display(),
                data.display()
            )));
        }
    }
    Ok(())
}
