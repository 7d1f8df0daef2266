//! Evaluation against ground truth (paper section 4.5): speed RMSE, Szekely's distance correlation,
//! the error interval, depth accuracy at fish centres, depth consistency where there is no depth
//! truth, plots and per-frame series, and the driver behind `fme eval`.
//!
//! The driver runs the daemon's own [`fme_core::pipeline::FishPipeline`] with the one config, ground
//! truth swapped in where asked ([`inputs`]), so what is scored is what the PLC receives.

mod boxes;
pub mod consistency;
pub mod inputs;
pub mod live;
pub mod metrics;
mod options;
mod output;
pub mod plot;
pub mod relative;
mod report;
mod run;
pub mod score;

pub use boxes::{BoxesChoice, IndexedBoxes};
pub use metrics::{DepthAccuracy, distance_correlation, quantile, rmse};
pub use options::{DepthChoice, EvalOptions};
pub use output::{write_series, write_tracks};
pub use relative::RelativeGtParams;
pub use report::{EvalReport, FishRow, MotSummary, ScoredRow};
pub use run::evaluate;

use std::path::PathBuf;

/// Errors of the evaluation; each names the file (and line, through the sequence reader's errors).
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The sequence or a box file could not be read or parsed.
    #[error(transparent)]
    Sequence(#[from] fme_edge::sequence::Error),
    /// An input that parses but cannot be used.
    #[error("{path}: {msg}")]
    Input {
        /// The file at fault.
        path: PathBuf,
        /// What is wrong.
        msg: String,
    },
    /// A detection or track file could not be read or parsed (names the file and line).
    #[error(transparent)]
    Mot(#[from] fme_edge::sequence::mot_text::MotError),
    /// A model or ONNX Runtime problem (the message names the file).
    #[error("{0}")]
    Model(String),
    /// Writing an output (series, plot) failed.
    #[error("{path}: {msg}")]
    Output {
        /// The file being written.
        path: PathBuf,
        /// What went wrong.
        msg: String,
    },
    /// Nothing to score (no frame has both a true and an estimated swarm speed).
    #[error("{0}")]
    NothingToScore(String),
}
