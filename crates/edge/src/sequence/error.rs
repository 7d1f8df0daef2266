//! Errors of the sequence reader and writer; each names the file (and line where there is one).

use std::path::PathBuf;

/// Everything that can go wrong reading or writing a sequence.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A file or folder could not be read, written or created.
    #[error("{path}: {error}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The operating-system error (shown in the message, not chained, so `{:#}` says it once).
        error: std::io::Error,
    },
    /// A text row that does not parse (CSV, MOT rows, seqinfo.ini).
    #[error("{path}:{line}: {msg}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with the row.
        msg: String,
    },
    /// `meta.json` that is not valid JSON or lacks a required key (serde names line and column).
    #[error("{path}: {error}")]
    Json {
        /// The file.
        path: PathBuf,
        /// The JSON error, with line and column.
        error: serde_json::Error,
    },
    /// A PNG or JPEG that cannot be decoded or encoded.
    #[error("{path}: {error}")]
    Image {
        /// The file.
        path: PathBuf,
        /// The codec error.
        error: image::ImageError,
    },
    /// Files that parse but contradict each other or the format (wrong size, missing frame, ...).
    #[error("{path}: {msg}")]
    Invalid {
        /// The file or folder at fault.
        path: PathBuf,
        /// What is inconsistent.
        msg: String,
    },
}

impl Error {
    pub(crate) fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        Self::Io { path: path.into(), error }
    }
    pub(crate) fn parse(path: impl Into<PathBuf>, line: usize, msg: impl Into<String>) -> Self {
        Self::Parse { path: path.into(), line, msg: msg.into() }
    }
    pub(crate) fn invalid(path: impl Into<PathBuf>, msg: impl Into<String>) -> Self {
        Self::Invalid { path: path.into(), msg: msg.into() }
    }
}
