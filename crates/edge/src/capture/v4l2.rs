//! V4L2 camera source (`v4l` crate): MMAP streaming, MJPEG or YUYV, resolution and fps from the
//! config, buffers cut to `bytesused`, a capture timeout, kernel timestamps. Errors are returned to
//! the capture loop, which raises the camera status bit and calls [`FrameSource::reopen`] with backoff.

use super::{CaptureError, Frame, FrameSource, PixelFormat};
use crate::config::{CameraFormat, SourceConfig};
use fme_core::units::Seconds;
use std::time::Duration;
use v4l::buffer::Type;
use v4l::io::mmap::Stream;
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::{Device, FourCC};

struct Open {
    // Field order matters: the stream is dropped (see Drop) before the device.
    stream: Option<Stream<'static>>,
    _dev: Device,
    width: u32,
    height: u32,
    format: PixelFormat,
}

impl Drop for Open {
    fn drop(&mut self) {
        // v4l's Stream::drop panics when STREAMOFF fails with anything but ENODEV (libv4l-rs #98);
        // a camera that misbehaves must never take the daemon down.
        if let Some(s) = self.stream.take() {
            let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(move || drop(s)));
        }
    }
}

/// A V4L2 camera.
pub struct V4l2Source {
    cfg: SourceConfig,
    open: Option<Open>,
    seq: u64,
    /// Driver sequence number of the last frame since (re)open, to count frames the driver dropped.
    last_kernel_seq: Option<u32>,
    kernel_dropped: u64,
}

impl std::fmt::Debug for V4l2Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("V4l2Source").field("path", &self.cfg.path).field("open", &self.open.is_some()).finish()
    }
}

impl V4l2Source {
    /// A camera source for `cfg.path`; nothing is opened until [`FrameSource::reopen`].
    pub fn new(cfg: SourceConfig) -> Self {
        Self { cfg, open: None, seq: 0, last_kernel_seq: None, kernel_dropped: 0 }
    }

    fn open_device(&self) -> Result<Open, CaptureError> {
        let path = &self.cfg.path;
        let err =
            |what: &str, e: std::io::Error| CaptureError::Open { path: path.clone(), message: format!("{what}: {e}") };
        if !path.exists() {
            return Err(CaptureError::NotFound { path: path.clone() });
        }
        let dev = Device::with_path(path).map_err(|e| err("open", e))?;
        let mut fmt = dev.format().map_err(|e| err("get format", e))?;
        fmt.width = self.cfg.width;
        fmt.height = self.cfg.height;
        fmt.fourcc = match self.cfg.format {
            CameraFormat::Mjpeg => FourCC::new(b"MJPG"),
            CameraFormat::Yuyv => FourCC::new(b"YUYV"),
        };
        // The driver may adjust the request: read back what it chose.
        let got = dev.set_format(&fmt).map_err(|e| err("set format", e))?;
        let format = match &got.fourcc.repr {
            b"MJPG" | b"JPEG" => PixelFormat::Jpeg,
            b"YUYV" => PixelFormat::Yuyv,
            other => {
                return Err(CaptureError::Open {
                    path: path.clone(),
                    message: format!("driver chose unsupported pixel format {}", String::from_utf8_lossy(other)),
                });
            }
        };
        if got.width != self.cfg.width || got.height != self.cfg.height {
            tracing::warn!(
                camera = %path.display(),
                "driver gave {}x{} instead of {}x{}",
                got.width,
                got.height,
                self.cfg.width,
                self.cfg.height
            );
        }
        let params = v4l::video::capture::Parameters::with_fps(self.cfg.fps);
        if let Err(e) = dev.set_params(&params) {
            tracing::warn!(camera = %path.display(), "cannot set {} fps: {e}", self.cfg.fps);
        }
        let mut stream =
            Stream::with_buffers(&dev, Type::VideoCapture, self.cfg.buffers).map_err(|e| err("mmap", e))?;
        stream.set_timeout(Duration::from_millis(self.cfg.timeout_ms));
        Ok(Open { stream: Some(stream), _dev: dev, width: got.width, height: got.height, format })
    }
}

impl FrameSource for V4l2Source {
    fn next_frame(&mut self, mut data: Vec<u8>) -> Result<Frame, CaptureError> {
        let path = self.cfg.path.clone();
        let Some(open) = self.open.as_mut() else {
            return Err(CaptureError::Read { path, message: "camera not open".into() });
        };
        let Some(stream) = open.stream.as_mut() else {
            return Err(CaptureError::Read { path, message: "camera not streaming".into() });
        };
        let result = match CaptureStream::next(stream) {
            Ok((buf, meta)) => {
                // The buffer is the whole mapping: only `bytesused` bytes are the frame (matters for MJPEG).
                let used = (meta.bytesused as usize).min(buf.len());
                let ts = Seconds(meta.timestamp.sec as f64 + meta.timestamp.usec as f64 * 1e-6);
                data.clear();
                data.extend_from_slice(&buf[..used]);
                if let Some(last) = self.last_kernel_seq.replace(meta.sequence) {
                    self.kernel_dropped += u64::from(meta.sequence.wrapping_sub(last).saturating_sub(1));
                }
                Ok(Frame {
                    seq: self.seq,
                    timestamp: ts,
                    arrived: std::time::Instant::now(),
                    width: open.width,
                    height: open.height,
                    format: open.format,
                    data,
                })
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {
                Err(CaptureError::Timeout { path, timeout_ms: self.cfg.timeout_ms })
            }
            Err(e) => Err(CaptureError::Read { path, message: e.to_string() }),
        };
        match &result {
            Ok(_) => self.seq += 1,
            Err(_) => self.open = None, // force a clean reopen
        }
        result
    }

    fn reopen(&mut self) -> Result<(), CaptureError> {
        self.open = None;
        self.last_kernel_seq = None; // the driver restarts its sequence numbers
        self.open = Some(self.open_device()?);
        Ok(())
    }

    fn source_dropped(&self) -> u64 {
        self.kernel_dropped
    }

    fn describe(&self) -> String {
        match &self.open {
            Some(o) => format!("camera {} ({}x{} {:?})", self.cfg.path.display(), o.width, o.height, o.format),
            None => format!("camera {} (closed)", self.cfg.path.display()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn not_a_camera_is_an_error_not_a_panic() {
        let cfg = SourceConfig { path: "/dev/null".into(), ..SourceConfig::default() };
        let mut s = V4l2Source::new(cfg);
        assert!(matches!(s.reopen(), Err(CaptureError::Open { .. })));
        assert!(matches!(s.next_frame(Vec::new()), Err(CaptureError::Read { .. })));
        let missing = SourceConfig { path: "/dev/video-fme-none".into(), ..SourceConfig::default() };
        assert!(matches!(V4l2Source::new(missing).reopen(), Err(CaptureError::NotFound { .. })));
    }
}
