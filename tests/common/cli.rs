//! Shared checks of the CLI's failure output (used by `cli_robustness.rs` and
//! `cli_audit.rs`).

#![allow(dead_code)]

use std::process::Output;

/// The process's stderr as text.
pub fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Asserts a clean failure: exit `code`, each of `needles` in stderr, no panic text,
/// nothing on stdout.
pub fn assert_fails(out: &Output, code: i32, needles: &[&str], what: &str) {
    let err = stderr(out);
    assert_eq!(out.status.code(), Some(code), "{what}: exit status {:?}, stderr: {err}", out.status);
    for n in needles {
        assert!(err.contains(n), "{what}: stderr lacks {n:?}: {err}");
    }
    for bad in ["panicked", "RUST_BACKTRACE", "stack backtrace", "memory allocation"] {
        assert!(!err.contains(bad), "{what}: panic/abort text in stderr: {err}");
    }
    assert!(out.stdout.is_empty(), "{what}: stdout on failure: {}", String::from_utf8_lossy(&out.stdout));
}

/// Which of the child's output pipes [`run_with_closed_pipe`] closes before it writes.
#[derive(Clone, Copy, Debug)]
pub enum Pipe {
    Stdout,
    Stderr,
}

/// Runs the binary with `args` and the `closed` pipe's read end dropped at once (a
/// consumer that went away, `| head`); returns what it left: exit status and the
/// other pipe's text.
pub fn run_with_closed_pipe(args: &[&str], closed: Pipe) -> Output {
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_point2quad"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("test: run the binary");
    match closed {
        Pipe::Stdout => drop(child.stdout.take()),
        Pipe::Stderr => drop(child.stderr.take()),
    }
    child.wait_with_output().expect("test: wait")
}
