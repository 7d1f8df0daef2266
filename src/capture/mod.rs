//! Frame sources: V4L2 cameras and recorded sequences, behind one [`FrameSource`] trait, and the
//! bounded drop-oldest [`FrameQueue`] that decouples capture from inference.

mod queue;
mod recorded;
mod v4l2;

pub use queue::{FrameQueue, QueueStats};
pub use recorded::RecordedSource;
pub use v4l2::V4l2Source;

/// Frames are the pipeline's input type; capture produces them.
pub use crate::pipeline::{Frame, PixelFormat};

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

/// Exponential backoff between `min` and `max`, doubling after each failure, reset on success.
#[derive(Debug, Clone, Copy)]
pub struct Backoff {
    min: std::time::Duration,
    max: std::time::Duration,
    next: std::time::Duration,
}

impl Backoff {
    /// Backoff from `min` doubling up to `max`.
    pub fn new(min: std::time::Duration, max: std::time::Duration) -> Self {
        Self { min, max: max.max(min), next: min }
    }
    /// The delay to wait now; the following one is doubled (capped).
    pub fn next_delay(&mut self) -> std::time::Duration {
        let d = self.next;
        self.next = (self.next * 2).min(self.max);
        d
    }
    /// Back to the shortest delay after a success.
    pub fn reset(&mut self) {
        self.next = self.min;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn backoff_doubles_caps_and_resets() {
        let mut b = Backoff::new(Duration::from_millis(100), Duration::from_millis(350));
        let d: Vec<_> = (0..4).map(|_| b.next_delay().as_millis()).collect();
        assert_eq!(d, vec![100, 200, 350, 350]);
        b.reset();
        assert_eq!(b.next_delay().as_millis(), 100);
    }
}
