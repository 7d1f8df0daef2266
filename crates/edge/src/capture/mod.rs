//! Frame sources: V4L2 cameras, IP cameras (RTSP/H.264, MJPEG over HTTP) and recorded sequences,
//! behind one [`FrameSource`] trait, and the bounded drop-oldest [`FrameQueue`] that decouples
//! capture from inference.

mod clock;
pub mod config;
mod credentials;
mod mjpeg;
mod queue;
mod recorded;
mod rtsp;
mod v4l2;

pub use clock::StreamClock;
pub use credentials::{Login, basic_auth, read_login};
pub use mjpeg::MjpegSource;
pub use queue::{FrameQueue, QueueStats};
pub use recorded::RecordedSource;
pub use rtsp::RtspSource;
pub use v4l2::V4l2Source;

/// Frames are the pipeline's input type; capture produces them.
pub use fme_core::pipeline::{Frame, PixelFormat};

/// The reconnect policy the sources share with the other edges.
pub use crate::backoff::Backoff;

use std::path::PathBuf;

/// The live camera `cfg` names (`kind = "rtsp"`, `"mjpeg"`, else the V4L2 device at `path`),
/// not yet opened: the caller calls [`FrameSource::reopen`] (a camera that is not there yet is
/// retried with backoff by the capture loop).
pub fn camera(cfg: &config::SourceConfig) -> Result<Box<dyn FrameSource>, CaptureError> {
    Ok(match cfg.kind {
        config::SourceKind::Rtsp => Box::new(RtspSource::new(cfg.clone())?),
        config::SourceKind::Mjpeg => Box::new(MjpegSource::new(cfg.clone())),
        config::SourceKind::Auto => Box::new(V4l2Source::new(cfg.clone())),
    })
}

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
