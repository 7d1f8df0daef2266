//! Frame sources: V4L2 cameras and recorded sequences, behind one [`FrameSource`] trait, and the
//! bounded drop-oldest [`FrameQueue`] that decouples capture from inference.

pub mod config;
mod queue;
mod recorded;
mod v4l2;

pub use queue::{FrameQueue, QueueStats};
pub use recorded::RecordedSource;
pub use v4l2::V4l2Source;

/// Frames are the pipeline's input type; capture produces them.
pub use fme_core::pipeline::{Frame, PixelFormat};

/// The reconnect policy the sources share with the other edges.
pub use crate::backoff::Backoff;

use std::path::PathBuf;

/// A capture failure. Sources recover from these themselves where they can (reconnect with backoff).
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The device or sequence does not exist.
    #[error("{path}: not found (no camera device or sequence directory there)")]
    NotFound {
        /// The path given.
        path: PathBuf,
    },
    /// Opening or configuring failed.
    #[error("{path}: {message}")]
    Open {
        /// The path.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// No frame within the capture timeout.
    #[error("{path}: no frame within {timeout_ms} ms (camera stalled)")]
    Timeout {
        /// The path.
        path: PathBuf,
        /// The timeout, ms.
        timeout_ms: u64,
    },
    /// Reading a frame failed.
    #[error("{path}: {message}")]
    Read {
        /// The path.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// A finite source has no more frames.
    #[error("end of sequence")]
    End,
}

/// A source of timestamped frames. `next_frame` blocks until a frame is ready (paced sources sleep).
pub trait FrameSource: Send {
    /// The next frame, written into `buf` (a cleared, possibly recycled buffer: no allocation once
    /// its capacity fits a frame).
    fn next_frame(&mut self, buf: Vec<u8>) -> Result<Frame, CaptureError>;
    /// (Re)opens the source after an error; called by the capture loop with backoff between tries.
    fn reopen(&mut self) -> Result<(), CaptureError>;
    /// A short description for logs and the console.
    fn describe(&self) -> String;
    /// Whether frames come on their own clock (camera, real-time replay): then a full queue drops the
    /// oldest frame. Unpaced sources (replay as fast as possible) are back-pressured instead.
    fn paced(&self) -> bool {
        true
    }
    /// Frames lost before they reached us (V4L2: gaps in the driver's sequence numbers).
    fn source_dropped(&self) -> u64 {
        0
    }
}
