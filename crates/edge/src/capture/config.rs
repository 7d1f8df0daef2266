//! `[source]`: the camera or recorded sequence the frames come from, and its check.

use crate::config::{KeyError, ensure};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Pixel format asked of a V4L2 camera.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CameraFormat {
    /// Motion JPEG (compressed; needed for 30 fps over USB 2.0 at 720p and above).
    Mjpeg,
    /// Packed YUV 4:2:2.
    Yuyv,
}

/// `[source]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SourceConfig {
    /// A V4L2 device (`/dev/videoN`) or a MOTChallenge sequence directory (`img1/`, `seqinfo.ini`).
    pub path: PathBuf,
    /// Requested width, px (camera only; the driver may pick another, which is logged).
    pub width: u32,
    /// Requested height, px (camera only).
    pub height: u32,
    /// Requested frame rate, frames/s (camera only).
    pub fps: u32,
    /// Camera pixel format.
    pub format: CameraFormat,
    /// Number of MMAP buffers (camera only).
    pub buffers: u32,
    /// Capture timeout, ms: no frame for this long = camera stalled -> reconnect.
    pub timeout_ms: u64,
    /// Recorded sequences: pace frames at the sequence's fps (true) or as fast as possible (false).
    pub realtime: bool,
    /// Recorded sequences: start again at the end, like a camera that never stops.
    #[serde(rename = "loop")]
    pub looping: bool,
    /// Frames held between capture and pipeline; when full the oldest is dropped and counted.
    pub queue_frames: usize,
    /// First reconnect delay after a camera failure, ms (doubles up to `reconnect_max_ms`).
    pub reconnect_min_ms: u64,
    /// Longest reconnect delay, ms.
    pub reconnect_max_ms: u64,
    /// Largest frame accepted, pixels (read from the JPEG header before decoding); larger frames
    /// are dropped as bad frames. 0 = 4 x the larger of `width` x `height` and the source's size.
    pub max_pixels: u64,
}

impl SourceConfig {
    /// Whether `path` names a V4L2 camera (anything under `/dev`) rather than a recorded sequence:
    /// the one rule every command uses to pick the frame source.
    pub fn is_camera(&self) -> bool {
        self.path.starts_with("/dev")
    }

    /// What the ranges (`crate::config::ranges`) cannot check: a path, the reconnect delays' order.
    pub fn validate(&self) -> Result<(), KeyError> {
        let path = !self.path.as_os_str().is_empty();
        ensure(path, "source.path", "must name a /dev/videoN device or a sequence directory")?;
        let delays = self.reconnect_min_ms <= self.reconnect_max_ms;
        ensure(delays, "source.reconnect_min_ms", "must be <= source.reconnect_max_ms")
    }
}

impl Default for SourceConfig {
    fn default() -> Self {
        Self {
            path: PathBuf::from("/dev/video0"),
            width: 640,
            height: 384,
            fps: 30,
            format: CameraFormat::Mjpeg,
            buffers: 4,
            timeout_ms: 2000,
            realtime: true,
            looping: true,
            queue_frames: 4,
            reconnect_min_ms: 500,
            reconnect_max_ms: 30_000,
            max_pixels: 0,
        }
    }
}
