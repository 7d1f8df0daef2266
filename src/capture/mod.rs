//! Frame sources: V4L2 cameras and recorded sequences, behind one [`FrameSource`] trait, and the
//! bounded drop-oldest [`FrameQueue`] that decouples capture from inference.

mod queue;
mod recorded;
mod v4l2;

pub use queue::{FrameQueue, QueueStats};
pub use recorded::RecordedSource;
pub use v4l2::V4l2Source;

use crate::units::Seconds;
use std::path::PathBuf;

/// How the bytes of a [`Frame`] are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelFormat {
    /// A JPEG image (recorded `img1/*.jpg` or MJPEG camera frames).
    Jpeg,
    /// Packed YUYV 4:2:2, `width * height * 2` bytes.
    Yuyv,
    /// 8-bit grey, `width * height` bytes.
    Gray8,
}

/// One captured frame. The bytes stay encoded: decoding is the pipeline's job, so capture never
/// waits on CPU work.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Sequence number from the source (monotonic, never reset by a loop or reconnect).
    pub seq: u64,
    /// Capture time (kernel timestamp for V4L2; frame index / fps for recordings).
    pub timestamp: Seconds,
    /// When the frame reached user space (start of the frame-to-register latency).
    pub arrived: std::time::Instant,
    /// Width, px.
    pub width: u32,
    /// Height, px.
    pub height: u32,
    /// Encoding of `data`.
    pub format: PixelFormat,
    /// The bytes, cut to the valid length (V4L2 `bytesused`).
    pub data: Vec<u8>,
}

impl Frame {
    /// Decodes to 8-bit grey (YUYV: the Y samples; JPEG: decoded then converted).
    pub fn to_luma(&self) -> Result<image::GrayImage, String> {
        let (w, h) = (self.width as usize, self.height as usize);
        match self.format {
            PixelFormat::Jpeg => image::load_from_memory_with_format(&self.data, image::ImageFormat::Jpeg)
                .map(|i| i.to_luma8())
                .map_err(|e| e.to_string()),
            PixelFormat::Yuyv => {
                if self.data.len() < w * h * 2 {
                    return Err(format!("YUYV frame has {} bytes, expected {}", self.data.len(), w * h * 2));
                }
                let y: Vec<u8> = self.data.iter().step_by(2).take(w * h).copied().collect();
                image::GrayImage::from_raw(self.width, self.height, y).ok_or_else(|| "bad YUYV size".to_string())
            }
            PixelFormat::Gray8 => image::GrayImage::from_raw(self.width, self.height, self.data.clone())
                .ok_or_else(|| format!("grey frame has {} bytes, expected {}", self.data.len(), w * h)),
        }
    }
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

    #[test]
    fn yuyv_to_luma_takes_y_samples() {
        let f = Frame {
            seq: 0,
            timestamp: Seconds(0.0),
            arrived: std::time::Instant::now(),
            width: 2,
            height: 1,
            format: PixelFormat::Yuyv,
            data: vec![10, 128, 20, 128],
        };
        assert_eq!(f.to_luma().map(|i| i.into_raw()), Ok(vec![10, 20]));
        let short = Frame { data: vec![1, 2], ..f };
        assert!(short.to_luma().is_err());
    }
}
