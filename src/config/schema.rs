//! The configuration schema: one struct per section of `config/fme.toml`, in pipeline order.
//!
//! Every field has a default (documented next to it and in `config/fme.toml`), so an empty file is a
//! valid configuration. Unknown keys are errors: a typo must never be silently ignored on a box that
//! runs unattended for months.

use serde::Deserialize;
use std::path::PathBuf;

pub use super::stages::{DepthConfig, DetectorConfig, MotionConfig, PostprocessConfig, TrackerConfig};

/// The whole configuration of `fme run`.
#[derive(Debug, Clone, Default, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// `[source]`: camera or recorded sequence.
    pub source: SourceConfig,
    /// `[detector]`: ONNX fish detector.
    pub detector: DetectorConfig,
    /// `[depth]`: ONNX relative-depth network.
    pub depth: DepthConfig,
    /// `[tracker]`: Kalman tracking-by-detection.
    pub tracker: TrackerConfig,
    /// `[postprocess]`: box-fluctuation and depth-jump detectors (paper eq. 3-4).
    pub postprocess: PostprocessConfig,
    /// `[motion]`: speeds and the activity index (paper eq. 5).
    pub motion: MotionConfig,
    /// `[output]`: Modbus and serial line.
    pub output: OutputConfig,
    /// `[console]`: serial field-diagnostics console.
    pub console: ConsoleConfig,
    /// `[feeding]`: the feeding-recommended rule.
    pub feeding: FeedingConfig,
    /// `[service]`: watchdog, logging, threads.
    pub service: ServiceConfig,
}

/// Pixel format asked of a V4L2 camera.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CameraFormat {
    /// Motion JPEG (compressed; needed for 30 fps over USB 2.0 at 720p and above).
    Mjpeg,
    /// Packed YUV 4:2:2.
    Yuyv,
}

/// `[source]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
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
        }
    }
}

/// `[output]`: Modbus and serial line.
    pub output: OutputConfig,
    /// `[console]`: serial field-diagnostics console.
    pub console: ConsoleConfig,
    /// `[feeding]`: the feeding-recommended rule.
    pub feeding: FeedingConfig,
    /// `[service]`: watchdog, logging, threads.
    pub service: ServiceConfig,
}

/// Pixel format asked of a V4L2 camera.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum CameraFormat {
    /// Motion JPEG (compressed; needed for 30 fps over USB 2.0 at 720p and above).
    Mjpeg,
    /// Packed YUV 4:2:2.
    Yuyv,
}

/// `[source]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
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
        }
    }
}

/// `[detector]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DetectorConfig {
    /// ONNX model file (relative paths are relative to the working directory).
    pub model: PathBuf,
    /// Detection rate, Hz (decoupled from the camera rate; frames in between are only predicted).
    pub rate_hz: f64,
    /// Minimum detection confidence, 0..1.
    pub confidence: f64,
    /// Non-maximum-suppression IoU threshold, 0..1.
    pub nms_iou: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
}

impl Default for DetectorConfig {
    fn default() -> Self {
        Self { model: PathBuf::from("models/detector.onnx"), rate_hz: 10.0, confidence: 0.35, nms_iou: 0.5, threads: 1 }
    }
}

/// `[depth]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct DepthConfig {
    /// ONNX relative-depth model file.
    pub model: PathBuf,
    /// Depth rate, Hz.
    pub rate_hz: f64,
    /// ONNX Runtime intra-op threads.
    pub threads: usize,
    /// Metric fit of relative inverse depth (paper eq. 2): `linear`, `inverse` or `robust`.
    pub fit: String,
}

impl Default for DepthConfig {
    fn default() -> Self {
        Self { model: PathBuf::from("models/depth.onnx"), rate_hz: 5.0, threads: 1, fit: "robust".into() }
    }
}

/// `[tracker]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct TrackerConfig {
    /// Maximum simultaneous tracks (fixed capacity, no allocation per frame).
    pub max_tracks: usize,
    /// Minimum IoU to match a detection to a track, 0..1.
    pub iou_threshold: f64,
    /// Detections needed before a track is confirmed.
    pub min_hits: u32,
    /// A track not matched for this long is deleted, s.
    pub max_age_s: f64,
}

impl Default for TrackerConfig {
    fn default() -> Self {
        Self { max_tracks: 64, iou_threshold: 0.3, min_hits: 3, max_age_s: 1.0 }
    }
}

/// `[postprocess]` (paper eq. 3 and 4).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct PostprocessConfig {
    /// Window of the box-fluctuation detector (eq. 3), s.
    pub box_window_s: f64,
    /// Frames averaged by the EWMA that replaces an abnormal box size (eq. 3).
    pub box_ewma_frames: usize,
    /// Depth jump threshold delta (eq. 4), m.
    pub depth_jump_m: f64,
    /// Window of the depth EWMA that replaces a jump (eq. 4), s.
    pub depth_window_s: f64,
}

impl Default for PostprocessConfig {
    fn default() -> Self {
        Self { box_window_s: 1.0, box_ewma_frames: 5, depth_jump_m: 0.6, depth_window_s: 1.0 }
    }
}

/// `[motion]` (paper eq. 5 and the activity sample).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MotionConfig {
    /// Mean fish body length used for body lengths/s, m.
    pub body_length_m: f64,
    /// Fewer tracked fish than this raises the "too few fish" status bit.
    pub min_fish: u32,
    /// Time constant of the smoothed activity value (EWMA), s.
    pub smoothing_s: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        Self { body_length_m: 0.35, min_fish: 3, smoothing_s: 60.0 }
    }
}

/// `[output]`: update rate and staleness, plus `[output.modbus]` and `[output.serial]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    /// Activity updates sent to the outputs, Hz (the heartbeat register increments at this rate).
    pub rate_hz: f64,
    /// A value older than this is flagged stale and published as NaN, s.
    pub stale_after_s: f64,
    /// `[output.modbus]`.
    pub modbus: ModbusConfig,
    /// `[output.serial]`.
    pub serial: SerialLineConfig,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self { rate_hz: 1.0, stale_after_s: 5.0, modbus: ModbusConfig::default(), serial: SerialLineConfig::default() }
    }
}

/// Modbus role.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "kebab-case")]
pub enum ModbusMode {
    /// No Modbus.
    Off,
    /// TCP server: the PLC polls (default).
    TcpServer,
    /// TCP client: one FC16 write of the register block to the PLC per update.
    TcpClient,
    /// RTU server on a serial line (RS-485).
    RtuServer,
    /// RTU client on a serial line.
    RtuClient,
}

/// Order of the two 16-bit words of a float32/uint32.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum WordOrder {
    /// High word first (ABCD, "big endian"; default).
    #[default]
    HighFirst,
    /// Low word first (CDAB, "Modicon"/little-endian word order).
    LowFirst,
}

/// Serial parity.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    /// No parity.
    None,
    /// Even parity (the Modbus RTU default).
    Even,
    /// Odd parity.
    Odd,
}

/// `[output.modbus]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ModbusConfig {
    /// Role: `off`, `tcp-server`, `tcp-client`, `rtu-server`, `rtu-client`.
    pub mode: ModbusMode,
    /// TCP server: address to listen on, HOST:PORT.
    pub listen: String,
    /// TCP client: the PLC's address, HOST:PORT.
    pub peer: String,
    /// Unit (slave) id: served by the RTU server; addressed by the clients.
    pub unit_id: u8,
    /// Word order of float32/uint32 values.
    pub word_order: WordOrder,
    /// Client modes: first holding register of the block in the PLC (0-based PDU address).
    pub base_address: u16,
    /// RTU: serial device.
    pub serial_device: String,
    /// RTU: baud rate, bit/s.
    pub baud: u32,
    /// RTU: parity.
    pub parity: Parity,
    /// RTU: stop bits (1 or 2).
    pub stop_bits: u8,
    /// Timeout of every Modbus call, ms.
    pub timeout_ms: u64,
    /// First reconnect delay after losing the PLC, ms (doubles up to `reconnect_max_ms`).
    pub reconnect_min_ms: u64,
    /// Longest reconnect delay, ms.
    pub reconnect_max_ms: u64,
}

impl Default for ModbusConfig {
    fn default() -> Self {
        Self {
            mode: ModbusMode::TcpServer,
            listen: "0.0.0.0:502".into(),
            peer: "192.168.0.10:502".into(),
            unit_id: 1,
            word_order: WordOrder::HighFirst,
            base_address: 0,
            serial_device: "/dev/ttyUSB0".into(),
            baud: 19_200,
            parity: Parity::Even,
            stop_bits: 1,
            timeout_ms: 1000,
            reconnect_min_ms: 500,
            reconnect_max_ms: 30_000,
        }
    }
}

/// `[output.serial]`: one ASCII line per update for simple data loggers.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct SerialLineConfig {
    /// Write the line output.
    pub enabled: bool,
    /// Serial device.
    pub device: String,
    /// Baud rate, bit/s.
    pub baud: u32,
}

impl Default for SerialLineConfig {
    fn default() -> Self {
        Self { enabled: false, device: "/dev/ttyUSB1".into(), baud: 9600 }
    }
}

/// `[console]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ConsoleConfig {
    /// Serve the console.
    pub enabled: bool,
    /// Serial device (or a pty path).
    pub device: String,
    /// Baud rate, bit/s.
    pub baud: u32,
    /// Log lines kept for `log [n]`.
    pub log_lines: usize,
}

impl Default for ConsoleConfig {
    fn default() -> Self {
        Self { enabled: false, device: "/dev/ttyS0".into(), baud: 115_200, log_lines: 200 }
    }
}

/// `[feeding]`: hysteresis on the smoothed activity with minimum on/off times.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct FeedingConfig {
    /// Recommend feeding when the smoothed activity rises to this or above, m/s.
    pub on_above_mps: f64,
    /// Stop recommending when the smoothed activity falls to this or below, m/s.
    pub off_below_mps: f64,
    /// Shortest time the recommendation stays on, s.
    pub min_on_s: f64,
    /// Shortest time the recommendation stays off, s.
    pub min_off_s: f64,
}

impl Default for FeedingConfig {
    fn default() -> Self {
        Self { on_above_mps: 0.25, off_below_mps: 0.15, min_on_s: 300.0, min_off_s: 600.0 }
    }
}

/// `[service]`.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ServiceConfig {
    /// Notify systemd (READY, WATCHDOG pings from the frame loop) when started by it.
    pub systemd_notify: bool,
    /// The pipeline counts as stuck when it has not finished a frame for this long, s.
    pub stall_after_s: f64,
    /// Print a live one-line view of the activity on stderr (for demos), s between refreshes (0 = off).
    pub live_view_s: f64,
    /// On SIGTERM/SIGINT: keep serving the "stopped" registers this long before exiting, ms (<= 1500).
    pub stop_grace_ms: u64,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self { systemd_notify: true, stall_after_s: 5.0, live_view_s: 0.0, stop_grace_ms: 500 }
    }
}
