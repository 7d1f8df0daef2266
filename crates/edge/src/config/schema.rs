//! The configuration schema: one struct per section of `config/fme.toml`, in pipeline order.
//!
//! Every field has a default (documented next to it and in `config/fme.toml`), so an empty file is a
//! valid configuration. Unknown keys are errors: a typo must never be silently ignored on a box that
//! runs unattended for months.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

pub use super::stages::CameraConfig;
pub use fme_core::familiarity::FamiliarityConfig;
pub use fme_core::infer::{DepthConfig, DetectorConfig};
pub use fme_core::motion::MotionConfig;
pub use fme_core::postprocess::PostprocessConfig;
pub use fme_core::track::TrackerConfig;

/// The whole configuration: `fme run`, `fme eval`, `fme track` and `fme tune` read this one type.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// `[source]`: camera or recorded sequence.
    pub source: SourceConfig,
    /// `[camera]`: calibration and reference objects for metric depth (paper eq. 1-2).
    pub camera: CameraConfig,
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
    /// `[familiarity]`: "detections look unlike fish" (status bit 10; the feeding rule holds off).
    pub familiarity: FamiliarityConfig,
    /// `[output]`: Modbus and serial line.
    pub output: OutputConfig,
    /// `[console]`: serial field-diagnostics console.
    pub console: ConsoleConfig,
    /// `[feeding]`: the feeding-recommended rule.
    pub feeding: FeedingConfig,
    /// `[service]`: watchdog, logging, threads, state directory.
    pub service: ServiceConfig,
    /// `[record]`: black box (rolling ring of frames), frozen recordings and snapshots.
    pub record: RecordConfig,
    /// `[history]`: a daily CSV row per output update (`docs/history.md`).
    pub history: HistoryConfig,
}

impl Config {
    /// The pipeline's sections and the frame size: what [`fme_core::pipeline::FishPipeline`] reads.
    pub fn pipeline(&self) -> fme_core::pipeline::PipelineConfig {
        fme_core::pipeline::PipelineConfig {
            frame_width: self.source.width,
            frame_height: self.source.height,
            detector: self.detector.clone(),
            depth: self.depth.clone(),
            tracker: self.tracker,
            postprocess: self.postprocess,
            motion: self.motion,
            familiarity: self.familiarity,
        }
    }
}

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

/// `[output]`: update rate and staleness, plus `[output.modbus]`, `[output.serial]` and
/// `[output.metrics]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
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
    /// `[output.mqtt]`: fleet telemetry to an MQTT broker (docs/mqtt.md).
    pub mqtt: MqttConfig,
    /// `[output.metrics]`: the Prometheus endpoint (`docs/metrics.md`).
    pub metrics: MetricsConfig,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            rate_hz: 1.0,
            stale_after_s: 5.0,
            modbus: ModbusConfig::default(),
            serial: SerialLineConfig::default(),
            mqtt: MqttConfig::default(),
            metrics: MetricsConfig::default(),
        }
    }
}

/// `[output.mqtt]`: activity, status, events and the effective config published to an MQTT broker
/// under `<prefix>/<box_id>/` (docs/mqtt.md). The pipeline and Modbus never wait on it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MqttConfig {
    /// Publish to the broker.
    pub enabled: bool,
    /// The broker, HOST:PORT (a name is resolved at each connect).
    pub broker: String,
    /// Client id and topic level of this box; empty = the host name.
    pub box_id: String,
    /// First topic level.
    pub prefix: String,
    /// QoS of every message: 0 (at most once) or 1 (at least once).
    pub qos: u8,
    /// MQTT keep-alive, s: the broker publishes the Last Will ("offline") after 1.5 x this without
    /// a packet from a box that vanished without closing its connection.
    pub keepalive_s: u64,
    /// Longest wait for the broker's CONNACK after starting a connection (TCP, TLS and CONNECT
    /// together), s. Generous, for slow links (4G, satellite: 300-700 ms round trip); a connection
    /// that takes longer is closed and retried after the backoff.
    pub connect_timeout_s: u64,
    /// Messages held while the broker is away; when full, the oldest is dropped and counted.
    pub queue_messages: usize,
    /// First reconnect delay, ms (doubles up to `reconnect_max_ms`).
    pub reconnect_min_ms: u64,
    /// Longest reconnect delay, ms.
    pub reconnect_max_ms: u64,
    /// User name; empty = none.
    pub username: String,
    /// File holding the password (first line; read at each connect, never logged); empty = none.
    pub password_file: PathBuf,
    /// Connect with TLS (rustls).
    pub tls: bool,
    /// TLS: CA certificate(s) (PEM) the broker's certificate must chain to; empty = the system's roots.
    pub ca_file: PathBuf,
    /// TLS: client certificate chain (PEM), for brokers that require one; empty = none.
    pub cert_file: PathBuf,
    /// TLS: the client certificate's private key (PEM); needed with `cert_file`.
    pub key_file: PathBuf,
}

impl Default for MqttConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            broker: "localhost:1883".into(),
            box_id: String::new(),
            prefix: "fme".into(),
            qos: 1,
            keepalive_s: 30,
            connect_timeout_s: 20,
            queue_messages: 1000,
            reconnect_min_ms: 1000,
            reconnect_max_ms: 60_000,
            username: String::new(),
            password_file: PathBuf::new(),
            tls: false,
            ca_file: PathBuf::new(),
            cert_file: PathBuf::new(),
            key_file: PathBuf::new(),
        }
    }
}

/// Modbus role.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
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
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum WordOrder {
    /// High word first (ABCD, "big endian"; default).
    #[default]
    HighFirst,
    /// Low word first (CDAB, "Modicon"/little-endian word order).
    LowFirst,
}

/// Serial parity.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq, Eq)]
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
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct ModbusConfig {
    /// Role: `off`, `tcp-server`, `tcp-client`, `rtu-server`, `rtu-client`.
    pub mode: ModbusMode,
    /// TCP server: address to listen on, HOST:PORT. The built-in default is `127.0.0.1:5020` (this
    /// box only, an unprivileged port: a replay needs no root and does not collide with the
    /// service); `boards/*.toml` set `0.0.0.0:502` for the PLC.
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
    /// TCP server: connections served at once; one more closes the least recently active
    /// (Modbus TCP implementation guide 4.2.1).
    pub max_connections: u32,
    /// TCP server: connections served at once from one IP address (at most `max_connections`); one
    /// more closes one of that address's own.
    pub max_connections_per_peer: u32,
    /// TCP server: close a connection with no complete request for this long, ms (0 = never);
    /// keep it well above the PLC's poll interval.
    pub idle_timeout_ms: u64,
    /// TCP server: a connection whose requests have been answered for this long, no two more than
    /// this apart (a PLC polling steadily), has priority: it is never closed for a newcomer, which
    /// is refused instead when no other connection can make room, ms (0 = no priority). Keep it
    /// above the PLC's poll interval.
    pub priority_after_ms: u64,
    /// TCP server: addresses or CIDR ranges allowed to connect (`["192.168.1.0/24"]`); empty =
    /// everyone. Others are closed at accept and counted (console `counters`).
    pub allow: Vec<String>,
}

impl Default for ModbusConfig {
    fn default() -> Self {
        Self {
            mode: ModbusMode::TcpServer,
            listen: "127.0.0.1:5020".into(),
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
            max_connections: 8,
            max_connections_per_peer: 4,
            idle_timeout_ms: 60_000,
            priority_after_ms: 10_000,
            allow: Vec::new(),
        }
    }
}

/// `[output.serial]`: one ASCII line per update for simple data loggers.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
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

/// `[output.metrics]`: a Prometheus endpoint (`GET /metrics`, text format 0.0.4; `docs/metrics.md`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct MetricsConfig {
    /// Address to serve on, HOST:PORT (e.g. `"127.0.0.1:9464"`); empty = off (default).
    pub listen: String,
    /// Addresses or CIDR ranges allowed to connect (`["192.168.1.0/24"]`); empty = everyone. Others
    /// are closed at accept and counted.
    pub allow: Vec<String>,
    /// Connections served at once; more are refused, except that a steady scraper's new connection
    /// closes the oldest one still sending its request head.
    pub max_connections: u32,
    /// Connections served at once from one IP address (at most `max_connections`); more are refused.
    pub max_connections_per_peer: u32,
    /// A request head not complete within this long is answered 408 and the connection closed, ms.
    pub header_timeout_ms: u64,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        Self {
            listen: String::new(),
            allow: Vec::new(),
            max_connections: 32,
            max_connections_per_peer: 2,
            header_timeout_ms: 2000,
        }
    }
}

/// `[console]`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
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
    /// Echo typed characters back (picocom/screen do not echo locally).
    pub echo: bool,
}

impl Default for ConsoleConfig {
    fn default() -> Self {
        Self { enabled: false, device: "/dev/ttyS0".into(), baud: 115_200, log_lines: 200, echo: true }
    }
}

/// `[feeding]`: hysteresis on the smoothed activity with minimum on/off times.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
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
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
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
    /// A write to the state directory (ring frame, snapshot, history row) still in flight after this
    /// long is a stalled disk: status bit 7, s.
    pub disk_stall_s: f64,
    /// Directory for recordings, snapshots and history when `$STATE_DIRECTORY` (systemd's
    /// `StateDirectory=`) is not set; empty = none (nothing is written to disk). See
    /// [`crate::status::state_dir`].
    pub state_dir: PathBuf,
}

impl Default for ServiceConfig {
    fn default() -> Self {
        Self {
            systemd_notify: true,
            stall_after_s: 5.0,
            live_view_s: 0.0,
            stop_grace_ms: 500,
            disk_stall_s: 3.0,
            state_dir: PathBuf::new(),
        }
    }
}

/// `[record]`: the black box (docs/recording.md). Active only with a state directory.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct RecordConfig {
    /// Keep a rolling on-disk ring of the frames the pipeline processed, with their detections,
    /// tracks and activity samples.
    pub enabled: bool,
    /// Seconds of frames kept in the ring (frame time), s.
    pub ring_s: f64,
    /// Largest size of the ring on disk, MB (10^6 bytes); the oldest frames go first.
    pub max_disk_mb: u64,
    /// Free space the ring leaves on its file system for the history, snapshots and recordings, MB
    /// (at most a quarter of the file system, so a small disk still keeps a ring).
    pub reserve_mb: u64,
    /// Write a snapshot (frame with overlays + metric depth map) every this many seconds (0 = off), s.
    pub snapshot_every_s: f64,
    /// Snapshots kept (older ones are deleted).
    pub keep_snapshots: usize,
    /// Frozen recordings kept (older ones are deleted; 0 = keep all).
    pub keep_recordings: usize,
    /// Freeze the ring when the smoothed activity falls below this, m/s (0 = off).
    pub alarm_low_mps: f64,
    /// Freeze the ring when the smoothed activity rises above this, m/s (0 = off).
    pub alarm_high_mps: f64,
    /// Freeze the ring on a fault: camera lost or stalled, detector or depth failure, pipeline error.
    pub freeze_on_fault: bool,
    /// At least this long between two automatic freezes (alarms, faults), s.
    pub freeze_min_gap_s: f64,
    /// Frames held between the pipeline and the recorder's writer thread; when full, frames are
    /// dropped from the recording and counted (console `counters`); the pipeline never waits.
    pub queue_frames: usize,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            ring_s: 60.0,
            max_disk_mb: 500,
            reserve_mb: 64,
            snapshot_every_s: 0.0,
            keep_snapshots: 20,
            keep_recordings: 20,
            alarm_low_mps: 0.0,
            alarm_high_mps: 0.0,
            freeze_on_fault: true,
            freeze_min_gap_s: 600.0,
            queue_frames: 32,
        }
    }
}

/// `[history]`: one CSV row per output update in daily files `YYYY-MM-DD.csv` (`docs/history.md`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct HistoryConfig {
    /// Write the history (when a directory resolves: `dir`, else the state directory's `history/`).
    pub enabled: bool,
    /// Days of files kept (today included); older day files are deleted.
    pub keep_days: u32,
    /// Directory of the day files; empty = `history/` in the state directory.
    pub dir: PathBuf,
    /// fsync the day file at most this often, s (0 = after every row). A killed process loses at
    /// most the row in flight; a power cut at most this many seconds of rows.
    pub fsync_s: f64,
}

impl Default for HistoryConfig {
    fn default() -> Self {
        Self { enabled: true, keep_days: 90, dir: PathBuf::new(), fsync_s: 10.0 }
    }
}
