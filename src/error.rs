//! The library's error type. Every variant carries what a user needs to fix the problem:
//! the file, the field and what to write instead.
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error("unknown environment '{name}'; known environments: {known}")]
    UnknownEnv { name: String, known: String },

    #[error("{what}: expected {expected} values, got {got}{hint}")]
    Shape { what: String, expected: usize, got: usize, hint: String },

    #[error("MuJoCo model file {path} could not be loaded: {reason}")]
    Model { path: PathBuf, reason: String },

    #[error("{path}: {reason}")]
    File { path: PathBuf, reason: String },

    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{0}")]
    Invalid(String),

    /// Training produced non-finite or exploding numbers: a result, but not one to publish.
    #[error("{0}")]
    Diverged(String),

    #[error(transparent)]
    Tch(#[from] tch::TchError),
}

pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    /// A refusal about a file, on one line: a newline inside the reason (a parser quoting the
    /// bad value) is written as `\n`.
    pub fn file(path: impl Into<PathBuf>, reason: impl Into<String>) -> Self {
        Error::File { path: path.into(), reason: one_line(reason.into()) }
    }
}

/// `s` with its line breaks escaped, so that a message stays one line.
pub fn one_line(s: String) -> String {
    if s.contains(['\n', '\r']) { s.replace('\r', "\\r").replace('\n', "\\n") } else { s }
}
