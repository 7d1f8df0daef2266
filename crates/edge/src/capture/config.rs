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

/// Which kind of source `[source]` names.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum SourceKind {
    /// From `path`: a V4L2 camera under `/dev`, else a recorded sequence directory.
    Auto,
    /// An IP camera's RTSP stream (`url`), H.264.
    Rtsp,
    /// An HTTP camera serving `multipart/x-mixed-replace` JPEGs (`url`).
    Mjpeg,
}

/// How an RTSP camera sends its RTP packets.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum RtspTransport {
    /// Interleaved on the RTSP TCP connection: passes NAT and firewalls, no packet loss.
    Tcp,
    /// UDP ports the camera sends to (LAN only: lost or reordered packets are frame losses).
    Udp,
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
    /// `auto` (`path` decides: camera or recording), `rtsp` or `mjpeg` (an IP camera at `url`).
    pub kind: SourceKind,
    /// IP cameras: `rtsp://host:554/path` or `http://host/path`, without user or password.
    pub url: String,
    /// IP cameras: a file holding `user:password` (one line); empty = no login. Only its path is
    /// ever shown (`fme config show`, the MQTT config topic, logs).
    pub credentials_file: PathBuf,
    /// RTSP cameras: `tcp` (interleaved, the default) or `udp`.
    pub transport: RtspTransport,
}

impl SourceConfig {
    /// Whether `path` names a V4L2 camera (anything under `/dev`) rather than a recorded sequence:
    /// the one rule every command uses to pick the frame source.
    pub fn is_camera(&self) -> bool {
        self.kind != SourceKind::Auto || self.path.starts_with("/dev")
    }

    /// What captions and logs call the source: an IP camera's URL (it holds no password), else `path`.
    pub fn name(&self) -> PathBuf {
        if self.is_ip_camera() { PathBuf::from(&self.url) } else { self.path.clone() }
    }

    /// Whether the source is an IP camera (`kind = "rtsp"` or `"mjpeg"`) rather than `path`.
    pub fn is_ip_camera(&self) -> bool {
        self.kind != SourceKind::Auto
    }

    /// What the ranges (`crate::config::ranges`) cannot check: a path, the reconnect delays' order.
    pub fn validate(&self) -> Result<(), KeyError> {
        if self.is_ip_camera() {
            return self.validate_url();
        }
        let path = !self.path.as_os_str().is_empty();
        ensure(path, "source.path", "must name a /dev/videoN device or a sequence directory")?;
        let delays = self.reconnect_min_ms <= self.reconnect_max_ms;
        ensure(delays, "source.reconnect_min_ms", "must be <= source.reconnect_max_ms")
    }
}

impl SourceConfig {
    /// `url` for `kind = "rtsp"` / `"mjpeg"`: the scheme that kind reads, a host, and no password
    /// in it (it would be shown by `fme config show` and logged: `credentials_file` holds it).
    fn validate_url(&self) -> Result<(), KeyError> {
        let scheme = if self.kind == SourceKind::Rtsp { "rtsp://" } else { "http://" };
        let rest = self.url.strip_prefix(scheme);
        ensure(rest.is_some(), "source.url", format!("must start with {scheme} for this source.kind"))?;
        let authority = rest.unwrap_or_default().split('/').next().unwrap_or_default();
        ensure(!authority.is_empty(), "source.url", "names no host")?;
        ensure(
            !authority.contains('@'),
            "source.url",
            "must not hold a user or password: put user:password in source.credentials_file",
        )?;
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
            kind: SourceKind::Auto,
            url: String::new(),
            credentials_file: PathBuf::new(),
            transport: RtspTransport::Tcp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ip_camera_urls_are_checked_and_hold_no_password() {
        let rtsp = |url: &str| SourceConfig { kind: SourceKind::Rtsp, url: url.into(), ..SourceConfig::default() };
        assert!(rtsp("rtsp://10.0.0.5:554/Streaming/Channels/102").validate().is_ok());
        let key = |c: SourceConfig| c.validate().map_err(|e| (e.key.clone(), e.to_string())).err();
        let (k, m) = key(rtsp("http://cam/video")).expect("wrong scheme");
        assert!(k == "source.url" && m.contains("rtsp://"), "{m}");
        let (_, m) = key(rtsp("rtsp://admin:hunter2@cam/live")).expect("password in the URL");
        assert!(m.contains("credentials_file"), "{m}");
        assert!(key(rtsp("rtsp:///path")).is_some(), "no host");
        let mjpeg =
            SourceConfig { kind: SourceKind::Mjpeg, url: "http://cam:8080/video".into(), ..SourceConfig::default() };
        assert!(mjpeg.validate().is_ok() && mjpeg.is_camera() && mjpeg.is_ip_camera());
        assert_eq!(mjpeg.name(), PathBuf::from("http://cam:8080/video"));
        assert!(!SourceConfig { path: "tests/data/swarm20".into(), ..SourceConfig::default() }.is_camera());
    }
}
