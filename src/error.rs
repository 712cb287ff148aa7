//! The crate's one error type. Every variant carries the context a user needs to
//! find the problem: the file and line for parse errors, the element for topology
//! errors, the op and shapes for tensor errors.

use std::fmt;
use std::path::PathBuf;

/// Result alias used throughout the crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong in point2quad.
#[derive(Debug)]
pub enum Error {
    /// An operating-system I/O error on `path`.
    Io { path: PathBuf, source: std::io::Error },
    /// Malformed content in a file (or an in-memory buffer, where `path` is `<memory>`).
    /// `line` is 1-based; 0 when the location is an element rather than a line
    /// (then `msg` names the element, e.g. "vertex 12").
    Parse { path: PathBuf, line: usize, msg: String },
    /// Input data that cannot be processed (empty cloud, NaN coordinate, …).
    InvalidInput(String),
    /// A mesh operation refused because it would break an invariant; `msg` names the
    /// face, edge or vertex.
    Topology(String),
    /// A tensor operation got shapes it cannot combine.
    Shape { op: &'static str, msg: String },
    /// A checkpoint / weights file that is truncated, corrupted or does not match.
    Checkpoint { path: PathBuf, msg: String },
    /// Bad command-line usage; the message says what and how to get help.
    Usage(String),
}

impl Error {
    /// Parse error helper.
    pub fn parse(path: impl Into<PathBuf>, line: usize, msg: impl Into<String>) -> Self {
        Error::Parse { path: path.into(), line, msg: msg.into() }
    }
    /// I/O error helper.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    /// Invalid-input helper.
    pub fn invalid(msg: impl Into<String>) -> Self {
        Error::InvalidInput(msg.into())
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, source } => write!(f, "{}: {}", path.display(), source),
            Error::Parse { path, line, msg } => {
                if *line > 0 {
                    write!(f, "{}:{}: {}", path.display(), line, msg)
                } else {
                    write!(f, "{}: {}", path.display(), msg)
                }
            }
            Error::InvalidInput(msg) => write!(f, "invalid input: {msg}"),
            Error::Topology(msg) => write!(f, "topology: {msg}"),
            Error::Shape { op, msg } => write!(f, "shape error in {op}: {msg}"),
            Error::Checkpoint { path, msg } => write!(f, "{}: bad checkpoint: {}", path.display(), msg),
            Error::Usage(msg) => write!(f, "{msg}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}
