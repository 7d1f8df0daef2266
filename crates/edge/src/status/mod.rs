//! Health as first-class status: one shared snapshot that the service writes and the registers,
//! the console and the watchdog read, plus a small ring of recent log lines for the console `log`
//! command, and the fault codes. A low module: the pipeline's types below it, and the service,
//! output and console above it all use it, so none of them imports another upwards.

mod state_dir;

pub use state_dir::state_dir;

use fme_core::pipeline::{ActivitySample, DepthFitState, StageHealth};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::Instant;

/// Frame-to-register latency histogram: 1 ms buckets up to 1 s, one overflow bucket. Fixed size.
#[derive(Debug, Clone)]
pub struct LatencyHistogram {
    buckets: [u32; 1001],
    count: u64,
    max_ms: f64,
    sum_ms: f64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self { buckets: [0; 1001], count: 0, max_ms: 0.0, sum_ms: 0.0 }
    }
}

impl LatencyHistogram {
    /// Records one latency, ms.
    pub fn record(&mut self, ms: f64) {
        let i = if ms.is_finite() && ms >= 0.0 { (ms as usize).min(1000) } else { 1000 };
        self.buckets[i] = self.buckets[i].saturating_add(1);
        self.count += 1;
        self.max_ms = self.max_ms.max(ms);
        if ms.is_finite() && ms >= 0.0 {
            self.sum_ms += ms;
        }
    }
    /// Samples recorded.
    pub fn count(&self) -> u64 {
        self.count
    }
    /// Largest latency seen, ms.
    pub fn max_ms(&self) -> f64 {
        self.max_ms
    }
    /// Sum of the latencies recorded (finite ones), ms: with [`Self::count`], the mean.
    pub fn sum_ms(&self) -> f64 {
        self.sum_ms
    }
    /// Samples below `ms` (whole milliseconds, the bucket resolution); from 1000 ms on, every sample
    /// below 1 s (the overflow bucket holds the rest).
    pub fn count_below_ms(&self, ms: u32) -> u64 {
        self.buckets[..(ms as usize).min(1000)].iter().map(|&b| u64::from(b)).sum()
    }
    /// Upper bound of the 1 ms bucket holding quantile `q` (0..1), capped at the maximum, ms; `None` when empty.
    pub fn quantile_ms(&self, q: f64) -> Option<f64> {
        if self.count == 0 {
            return None;
        }
        let target = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut acc = 0u64;
        for (i, b) in self.buckets.iter().enumerate() {
            acc += u64::from(*b);
            if acc >= target {
                // Upper bucket edge, but never above the largest value actually seen.
                return Some(if i == 1000 { self.max_ms } else { ((i + 1) as f64).min(self.max_ms) });
            }
        }
        Some(self.max_ms)
    }
}

/// The health snapshot.
#[derive(Debug, Clone)]
pub struct Health {
    /// Process start.
    pub started: Instant,
    /// Source description.
    pub source: String,
    /// The networks the pipeline runs (file, numeric form, backend), set at start.
    pub networks: fme_core::pipeline::Networks,
    /// The camera delivers frames.
    pub camera_ok: bool,
    /// Camera frame rate over the last second, frames/s.
    pub camera_fps: f64,
    /// Frames captured.
    pub frames_captured: u64,
    /// Frames processed by the pipeline.
    pub frames_processed: u64,
    /// Frames dropped by the capture queue.
    pub frames_dropped: u64,
    /// Capture errors (timeouts, read errors).
    pub capture_errors: u64,
    /// Camera reconnects.
    pub reconnects: u64,
    /// Pipeline errors (bad frames, stage failures).
    pub pipeline_errors: u64,
    /// Updates published to the registers.
    pub updates: u64,
    /// Last activity sample.
    pub last_sample: Option<ActivitySample>,
    /// When it arrived.
    pub last_sample_at: Option<Instant>,
    /// When the pipeline last finished a frame.
    pub last_processed_at: Option<Instant>,
    /// Stage health.
    pub stage: StageHealth,
    /// Calibration.
    pub fit_state: DepthFitState,
    /// Frame-to-register latency.
    pub latency: LatencyHistogram,
    /// The fish the estimator follows (console `tracks`; at most [`crate::console::TRACK_ROWS`]),
    /// refreshed at the output rate.
    pub fish: Vec<fme_core::motion::Fish>,
    /// The recorder (black box, snapshots).
    pub record: RecordHealth,
    /// Writes to the state directory in flight and the history's write state (status bit 7).
    pub disk: DiskHealth,
    /// The MQTT telemetry link (docs/mqtt.md).
    pub mqtt: MqttHealth,
}

/// State of the recorder (docs/recording.md), shown by the console `record` and `counters`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordHealth {
    /// The recorder runs (`record.enabled` and a state directory).
    pub active: bool,
    /// Frames written to the ring.
    pub frames_written: u64,
    /// Frames handed to the recorder and not written: its queue was full, or the disk failed.
    pub frames_dropped: u64,
    /// Bytes in the ring now.
    pub ring_bytes: u64,
    /// Frames in the ring now.
    pub ring_frames: u64,
    /// Write errors (disk full, read-only, ...).
    pub write_errors: u64,
    /// Recording is paused after a write error (retried later); the outputs are unaffected.
    pub disk_fault: bool,
    /// Frozen recordings written.
    pub saved: u64,
    /// The last frozen recording or snapshot written, or the last error.
    pub last: String,
    /// Snapshots written.
    pub snapshots: u64,
}

/// Writes to the state directory in flight: a write that has not returned for
/// `service.disk_stall_s` is a stalled disk (frozen file system, dying SD card), shown as status
/// bit 7. The writers are threads of their own, so a stall never holds the PLC side or a shutdown.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DiskHealth {
    /// The recorder's current write (ring frame, snapshot, freeze) began then.
    pub record_since: Option<Instant>,
    /// The history's current write or fsync began then.
    pub history_since: Option<Instant>,
    /// The history cannot write (disk full, read-only) and holds its rows in memory meanwhile.
    pub history_fault: bool,
}

impl DiskHealth {
    /// How long the oldest write in flight has been waiting at `now` (zero when none is).
    pub fn stalled_for(&self, now: Instant) -> std::time::Duration {
        [self.record_since, self.history_since]
            .into_iter()
            .flatten()
            .map(|t| now.saturating_duration_since(t))
            .max()
            .unwrap_or_default()
    }
}

/// State of the MQTT link (`[output.mqtt]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MqttLink {
    /// `output.mqtt.enabled = false`.
    #[default]
    Disabled,
    /// Connecting or waiting to reconnect (broker away, network down).
    Connecting,
    /// Connected: messages flow.
    Connected,
    /// The broker refused the login (bad user name or password, not authorized) or the TLS
    /// handshake failed: retried with backoff; status bit 9 is set.
    AuthFailed,
}

impl MqttLink {
    /// Name shown on the console and in the metrics (spelled as MQTT spells its names).
    pub fn name(self) -> &'static str {
        match self {
            Self::Disabled => "disabled",
            Self::Connecting => "connecting",
            Self::Connected => "connected",
            Self::AuthFailed => "auth_failed",
        }
    }
}

/// Counters of the MQTT publisher (docs/mqtt.md), shown by the console `mqtt`.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MqttHealth {
    /// Link state.
    pub link: MqttLink,
    /// The broker, HOST:PORT (empty when disabled).
    pub broker: String,
    /// Messages waiting in the queue now.
    pub queued: u64,
    /// Messages the broker acknowledged (QoS 1) or that were written to it (QoS 0).
    pub published: u64,
    /// Of those, messages that had waited in the queue while the link was down.
    pub delivered_after_reconnect: u64,
    /// Messages dropped: the queue was full (the oldest goes first).
    pub dropped: u64,
    /// Connections made after the first one.
    pub reconnects: u64,
    /// Connection attempts (successful or not).
    pub connect_attempts: u64,
    /// Connection attempts refused for the login or the certificate.
    pub auth_failures: u64,
    /// Wall-clock time of the last acknowledged message, ms since 1970 UTC.
    pub last_publish_unix_ms: Option<i64>,
    /// The last connection error (never contains the password).
    pub last_error: String,
}

/// Requests from the console to the service (the console never calls the service directly): the
/// service's threads poll this mailbox.
#[derive(Debug, Default)]
pub struct Requests {
    snap: AtomicBool,
    save: Mutex<Option<String>>,
}

impl Requests {
    /// Asks for a snapshot of the next processed frame (console `snap`).
    pub fn request_snapshot(&self) {
        self.snap.store(true, Ordering::SeqCst);
    }
    /// Takes a pending snapshot request.
    pub fn take_snapshot(&self) -> bool {
        self.snap.swap(false, Ordering::SeqCst)
    }
    /// Puts back a snapshot request that could not be served yet.
    pub fn restore_snapshot(&self) {
        self.request_snapshot();
    }
    /// Asks to freeze the black box under `label` (console `record save`, alarms, faults); a
    /// pending request is replaced.
    pub fn request_save(&self, label: &str) {
        *self.save.lock().unwrap_or_else(|p| p.into_inner()) = Some(label.to_string());
    }
    /// Takes a pending freeze request (its label).
    pub fn take_save(&self) -> Option<String> {
        self.save.lock().unwrap_or_else(|p| p.into_inner()).take()
    }
}

impl Health {
    fn new() -> Self {
        Self {
            started: Instant::now(),
            source: String::new(),
            networks: fme_core::pipeline::Networks::default(),
            camera_ok: false,
            camera_fps: 0.0,
            frames_captured: 0,
            frames_processed: 0,
            frames_dropped: 0,
            capture_errors: 0,
            reconnects: 0,
            pipeline_errors: 0,
            updates: 0,
            last_sample: None,
            last_sample_at: None,
            last_processed_at: None,
            stage: StageHealth::default(),
            fit_state: DepthFitState::default(),
            latency: LatencyHistogram::default(),
            fish: Vec::new(),
            record: RecordHealth::default(),
            disk: DiskHealth::default(),
            mqtt: MqttHealth::default(),
        }
    }
}

/// The activity history's state (`docs/history.md`): its directory, set once when the writer
/// starts (the console's `history` reads it), and its counters.
#[derive(Debug, Default)]
pub struct HistoryStatus {
    dir: OnceLock<PathBuf>,
    /// Rows written.
    pub written: AtomicU64,
    /// Rows dropped because the writer's queue was full (the disk was too slow).
    pub dropped: AtomicU64,
    /// Rows that met a write error (disk full, read-only) or came while paused after one: held in
    /// memory (up to `history::PENDING_ROWS`) and written late once the disk takes writes again.
    pub failed: AtomicU64,
    /// Paused after a write error (retried later).
    pub paused: AtomicBool,
}

impl HistoryStatus {
    /// Records the history directory (the first call wins).
    pub fn set_dir(&self, dir: &Path) {
        let _ = self.dir.set(dir.to_path_buf());
    }

    /// The history directory, if the history is on.
    pub fn dir(&self) -> Option<&Path> {
        self.dir.get().map(PathBuf::as_path)
    }

    /// One line for the console's `status`: `off`, `on DIR` or `paused DIR`.
    pub fn describe(&self) -> String {
        match self.dir() {
            None => "off".into(),
            Some(d) if self.paused.load(Ordering::Relaxed) => format!("paused (write error) {}", d.display()),
            Some(d) => format!("on {}", d.display()),
        }
    }
}

/// The Prometheus endpoint's state (`docs/metrics.md`): what it serves on, set once when it starts
/// or fails to (the console's `status` reads it), and its counters (exported by the endpoint itself).
#[derive(Debug, Default)]
pub struct MetricsStatus {
    state: OnceLock<String>,
    /// Responses sent, by status code, in the order of [`MetricsStatus::CODES`].
    pub responses: [AtomicU64; 6],
    /// Connections closed at accept (over a connection limit, or not in `output.metrics.allow`),
    /// or closed before their request head was complete to make room for a steady scraper.
    pub refused: AtomicU64,
    /// Connections that ended before a complete request arrived (closed or reset by the peer).
    pub aborted: AtomicU64,
}

impl MetricsStatus {
    /// The status codes the endpoint answers with.
    pub const CODES: [u16; 6] = [200, 400, 404, 405, 408, 431];

    /// Records what the endpoint does (`on ADDR`, or why it is not serving); the first call wins.
    pub fn set_state(&self, state: String) {
        let _ = self.state.set(state);
    }

    /// One line for the console's `status`: `off`, `on ADDR (GET /metrics)` or why it failed.
    pub fn describe(&self) -> &str {
        self.state.get().map_or("off", String::as_str)
    }

    /// Counts one response with status `code` (a code outside [`Self::CODES`] counts as 400).
    pub fn note_response(&self, code: u16) {
        let i = Self::CODES.iter().position(|&c| c == code).unwrap_or(1);
        self.responses[i].fetch_add(1, Ordering::Relaxed);
    }
}

/// State shared by every thread and task of the daemon.
#[derive(Debug)]
pub struct Shared {
    health: Mutex<Health>,
    log: Mutex<VecDeque<String>>,
    log_cap: usize,
    /// The configuration text as loaded (console `config`).
    pub config_text: String,
    /// Console-to-service requests.
    pub requests: Requests,
    stopping: AtomicBool,
    /// The activity history's directory and counters.
    pub history: HistoryStatus,
    /// The Prometheus endpoint's state and counters.
    pub metrics: MetricsStatus,
    /// Word order of the published register block (`output.modbus.word_order`), set once at start:
    /// the console decodes the block with it.
    word_order: OnceLock<crate::config::WordOrder>,
    /// The Modbus role's state for the console's `status` (set once at start: the role, where it
    /// serves, and whether it is open to every address); unset = off.
    pub modbus: OnceLock<String>,
    /// The web page's state for the console's `status` (set once at start: where it serves, or why
    /// it is off); unset = off.
    pub web: OnceLock<String>,
    /// The latest frame the web page asked for (`/api/latest.jpg`), handed over by the pipeline.
    pub preview: crate::web::preview::Preview,
    /// The calibration in use and a reload waiting for the pipeline.
    pub calibration: crate::calibration::live::LiveCalibration,
}

impl Shared {
    /// New shared state keeping `log_lines` log lines.
    pub fn new(config_text: String, log_lines: usize) -> Self {
        Self {
            health: Mutex::new(Health::new()),
            log: Mutex::new(VecDeque::with_capacity(log_lines.max(1))),
            log_cap: log_lines.max(1),
            config_text,
            requests: Requests::default(),
            stopping: AtomicBool::new(false),
            history: HistoryStatus::default(),
            metrics: MetricsStatus::default(),
            word_order: OnceLock::new(),
            modbus: OnceLock::new(),
            web: OnceLock::new(),
            preview: crate::web::preview::Preview::default(),
            calibration: Default::default(),
        }
    }

    /// Records the word order the register block is encoded with (the first call wins).
    pub fn set_word_order(&self, order: crate::config::WordOrder) {
        let _ = self.word_order.set(order);
    }

    /// The word order of the register block (the default, high word first, until set).
    pub fn word_order(&self) -> crate::config::WordOrder {
        self.word_order.get().copied().unwrap_or_default()
    }

    /// Runs `f` on the health snapshot under its lock (keep `f` short).
    pub fn with_health<R>(&self, f: impl FnOnce(&mut Health) -> R) -> R {
        f(&mut self.health.lock().unwrap_or_else(|p| p.into_inner()))
    }

    /// A copy of the health snapshot.
    pub fn health(&self) -> Health {
        self.with_health(|h| h.clone())
    }

    /// Logs an event to tracing and to the console's log ring.
    pub fn log(&self, level: tracing::Level, msg: impl Into<String>) {
        let msg = msg.into();
        match level {
            tracing::Level::ERROR => tracing::error!("{msg}"),
            tracing::Level::WARN => tracing::warn!("{msg}"),
            tracing::Level::INFO => tracing::info!("{msg}"),
            _ => tracing::debug!("{msg}"),
        }
        let up = self.with_health(|h| h.started.elapsed().as_secs_f64());
        let mut ring = self.log.lock().unwrap_or_else(|p| p.into_inner());
        if ring.len() >= self.log_cap {
            ring.pop_front();
        }
        ring.push_back(format!("[{up:9.1}s] {level:5} {msg}"));
    }

    /// The last `n` log lines, oldest first.
    pub fn last_logs(&self, n: usize) -> Vec<String> {
        let ring = self.log.lock().unwrap_or_else(|p| p.into_inner());
        ring.iter().skip(ring.len().saturating_sub(n)).cloned().collect()
    }

    /// Asks every thread to stop.
    pub fn request_stop(&self) {
        self.stopping.store(true, Ordering::SeqCst);
    }

    /// Whether a stop was requested.
    pub fn stopping(&self) -> bool {
        self.stopping.load(Ordering::SeqCst)
    }
}

/// Fault code of register 11: the most severe current problem.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u16)]
pub enum FaultCode {
    /// 0: no fault.
    #[default]
    None = 0,
    /// 1: camera lost or stalled (reconnecting).
    Camera = 1,
    /// 2: detector failed.
    Detector = 2,
    /// 3: depth network failed.
    Depth = 3,
    /// 4: pipeline stalled (no frame processed within `service.stall_after_s`).
    PipelineStalled = 4,
    /// 5: PLC link down (client modes).
    PlcLink = 5,
    /// 6: the daemon has stopped (final write before exit).
    Stopped = 6,
    /// 7: the detections look unlike fish (status bit 10, `[familiarity]`).
    UnlikeFish = 7,
}

impl FaultCode {
    /// Every code, in code order.
    pub const ALL: [Self; 8] = [
        Self::None,
        Self::Camera,
        Self::Detector,
        Self::Depth,
        Self::PipelineStalled,
        Self::PlcLink,
        Self::Stopped,
        Self::UnlikeFish,
    ];

    /// The code of register 11 value `code`; `None` for a code this version does not know.
    pub fn from_code(code: u16) -> Option<Self> {
        Self::ALL.iter().copied().find(|c| *c as u16 == code)
    }

    /// Whether this code is a fault: the one definition the history summaries (console `history`,
    /// `fme report` and its plot), the console and the MQTT events use. 0 (none) and 6 (stopped:
    /// an orderly stop, the final write before exit) are states, not faults.
    pub const fn is_fault(self) -> bool {
        !matches!(self, Self::None | Self::Stopped)
    }

    /// The name of the code as MQTT and the metrics spell it (`camera`, `pipeline_stalled`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Camera => "camera",
            Self::Detector => "detector",
            Self::Depth => "depth",
            Self::PipelineStalled => "pipeline_stalled",
            Self::PlcLink => "plc_link",
            Self::Stopped => "stopped",
            Self::UnlikeFish => "unlike_fish",
        }
    }
}

/// Whether register 11 value `code` is a fault ([`FaultCode::is_fault`]); a code this version does
/// not know counts as one (written by a newer version: better shown than hidden).
pub fn is_fault_code(code: u16) -> bool {
    FaultCode::from_code(code).is_none_or(FaultCode::is_fault)
}

/// Name of register 11 value `code` ([`FaultCode::name`]; `unknown` for a code this version does
/// not know).
pub fn fault_name(code: u16) -> &'static str {
    FaultCode::from_code(code).map_or("unknown", FaultCode::name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn latency_quantiles() {
        let mut h = LatencyHistogram::default();
        assert_eq!(h.quantile_ms(0.5), None);
        for ms in 0..100 {
            h.record(ms as f64 + 0.5);
        }
        assert_eq!(h.quantile_ms(0.5), Some(50.0));
        assert_eq!(h.quantile_ms(0.99), Some(99.0));
        h.record(5000.0);
        assert_eq!(h.quantile_ms(1.0), Some(5000.0));
    }

    #[test]
    fn latency_sum_and_cumulative_counts() {
        let mut h = LatencyHistogram::default();
        for ms in [0.2, 4.9, 5.0, 999.9, 1000.0, f64::NAN] {
            h.record(ms);
        }
        assert_eq!(h.count(), 6);
        assert!((h.sum_ms() - 2010.0).abs() < 1e-9, "NaN is counted but not summed: {}", h.sum_ms());
        assert_eq!(h.count_below_ms(0), 0);
        assert_eq!(h.count_below_ms(5), 2, "below 5 ms: 0.2 and 4.9");
        assert_eq!(h.count_below_ms(1000), 4);
        assert_eq!(h.count_below_ms(u32::MAX), 4, "the overflow bucket (1000 ms, NaN) is never below a bound");
    }

    #[test]
    fn start_up_and_stop_are_not_faults() {
        let faults: Vec<u16> = (0..10).filter(|&c| is_fault_code(c)).collect();
        assert_eq!(faults, [1, 2, 3, 4, 5, 7, 8, 9], "0 none and 6 stopped are no faults; unknown codes are");
        assert_eq!(fault_name(4), "pipeline_stalled");
        assert_eq!(fault_name(99), "unknown");
    }

    #[test]
    fn log_ring_keeps_last() {
        let s = Shared::new(String::new(), 3);
        for i in 0..5 {
            s.log(tracing::Level::INFO, format!("m{i}"));
        }
        let l = s.last_logs(10);
        assert_eq!(l.len(), 3);
        assert!(l[0].ends_with("m2") && l[2].ends_with("m4"), "{l:?}");
        assert_eq!(s.last_logs(1).len(), 1);
    }
}
