//! The black box and snapshots (docs/recording.md): what the box saw, kept on disk under the state
//! directory ([`crate::status::state_dir`]).
//!
//! ```text
//! pipeline thread --FrameRecord (try_send; full: dropped and counted)--> writer thread
//!     writer: ring/ (one JPEG per frame, rows in memory; bounded by record.ring_s and max_disk_mb)
//!             snapshots/ (console `snap`, record.snapshot_every_s)
//!             recordings/<UTC>-<label>/ (console `record save`, alarms, faults: a MOTChallenge sequence)
//! ```
//! The pipeline thread never waits on the disk: records go through a bounded queue and come back
//! through a pool for reuse; every disk operation (opening the ring, clearing it, freezing) runs on
//! the writer thread, so a stalled disk holds only that thread (shown as status bit 7 after
//! `service.disk_stall_s`). The ring keeps `record.reserve_mb` free and drops its oldest frames on
//! a full disk. A write error it cannot shed is logged once a minute at most, shown in the status
//! (bit 7, console `record`) and pauses recording, retried with backoff (1 s doubling to 30 s);
//! the activity index keeps flowing to the outputs.

pub mod config;
pub mod freeze;
mod overlays;
pub mod ring;
pub mod snapshot;

use crate::config::Config;
use crate::status::Shared;
use fme_core::pipeline::{ActivitySample, Frame, Pipeline, PixelFormat, StageHealth};
use freeze::FreezeInputs;
pub use overlays::Overlays;
use ring::{Ring, RingEntry};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::time::{Duration, Instant};
use tracing::Level;

/// One processed frame handed to the writer.
#[derive(Debug, Default)]
pub struct FrameRecord {
    /// The frame (bytes as received).
    pub frame: Option<Frame>,
    /// What the pipeline produced on it, as drawn.
    pub overlays: Overlays,
    /// Its activity sample.
    pub sample: Option<ActivitySample>,
    /// Write it to the ring.
    pub ring: bool,
    /// Write a snapshot of it.
    pub snapshot: bool,
    /// Metric depth on [`snapshot::DEPTH_GRID`] (snapshots only; empty when unknown).
    pub depth: Vec<f32>,
}

/// The pipeline thread's side of the recorder.
#[derive(Debug)]
pub struct Recorder {
    tx: Option<SyncSender<Box<FrameRecord>>>,
    pool: Receiver<Box<FrameRecord>>,
    shared: Arc<Shared>,
    /// The ring is on (`record.enabled`); cleared by the writer when it cannot open the ring.
    ring: Arc<AtomicBool>,
    snapshot_every_s: f64,
    next_snapshot_t: Option<f64>,
    alarm: (f64, f64),
    freeze_on_fault: bool,
    freeze_gap: Duration,
    last_auto: Option<Instant>,
    last_seen: (bool, StageHealth, u64),
    thread: Option<std::thread::JoinHandle<()>>,
}

/// Pause after a write error before trying again: short at first (space may come back at once,
/// the ring sheds frames), doubling to the longest.
const RETRY_MIN: Duration = Duration::from_secs(1);
const RETRY_MAX: Duration = Duration::from_secs(30);

struct Writer {
    dir: PathBuf,
    ring: Option<Ring>,
    inputs: FreezeInputs,
    shared: Arc<Shared>,
    keep_snapshots: usize,
    keep_recordings: usize,
    paused_until: Option<Instant>,
    retry: crate::backoff::Backoff,
    last_error_log: Option<Instant>,
    jpeg: Vec<u8>,
    /// The camera's source (named in the snapshots' top bar).
    source: PathBuf,
}

/// Marks a write to the state directory in flight (health `disk.record_since`) while it lives.
struct InFlight(Arc<Shared>);

impl InFlight {
    fn new(shared: &Arc<Shared>) -> Self {
        shared.with_health(|h| h.disk.record_since = Some(Instant::now()));
        Self(shared.clone())
    }
}

impl Drop for InFlight {
    fn drop(&mut self) {
        self.0.with_health(|h| h.disk.record_since = None);
    }
}

impl Writer {
    /// Opens the ring (deleting an earlier run's frames) and removes the staged folders of freezes
    /// that were killed or failed: on this thread, since either may wait on a stalled disk.
    fn open(&mut self, rc: &crate::config::RecordConfig, write: Option<ring::WriteFile>, ring_on: &AtomicBool) {
        let _busy = InFlight::new(&self.shared);
        let removed = freeze::remove_partials(&self.dir.join("recordings"));
        if removed > 0 {
            self.shared.log(
                Level::WARN,
                format!("recorder: removed {removed} unfinished recording(s) (.partial-*) left by a freeze that failed or was killed"),
            );
        }
        if !rc.enabled {
            return;
        }
        let dir = self.dir.join("ring");
        match Ring::open(&dir, rc.ring_s, rc.max_disk_mb.saturating_mul(1_000_000)) {
            Ok(r) => {
                let r = r.with_reserve(rc.reserve_mb.saturating_mul(1_000_000));
                self.ring = Some(match write {
                    Some(w) => r.with_writer(w),
                    None => r,
                });
            }
            Err(e) => {
                ring_on.store(false, Ordering::Relaxed);
                self.shared.log(Level::ERROR, format!("recorder: {}: {e}; the black box is off", dir.display()));
                self.shared.with_health(|h| {
                    h.record.active = false;
                    h.record.disk_fault = true;
                    h.record.write_errors += 1;
                });
            }
        }
    }

    fn fault(&mut self, what: &str, e: &str) {
        let wait = self.retry.next_delay();
        self.paused_until = Some(Instant::now() + wait);
        let log = self.last_error_log.is_none_or(|t| t.elapsed() >= Duration::from_secs(60));
        self.shared.with_health(|h| {
            h.record.write_errors += 1;
            h.record.disk_fault = true;
            h.record.last = format!("error: {e}");
        });
        if log {
            self.last_error_log = Some(Instant::now());
            self.shared.log(
                Level::ERROR,
                format!(
                    "recorder: {what}: {e}; recording paused (retried after {} s, then with backoff up to {} s; outputs unaffected)",
                    wait.as_secs(),
                    RETRY_MAX.as_secs()
                ),
            );
        }
    }

    fn recovered(&mut self) {
        self.retry.reset();
        if self.paused_until.take().is_some() {
            self.shared.with_health(|h| h.record.disk_fault = false);
            self.shared.log(Level::INFO, "recorder: writing again");
        }
    }

    fn paused(&self) -> bool {
        self.paused_until.is_some_and(|t| Instant::now() < t)
    }

    fn handle(&mut self, r: &mut FrameRecord) {
        let Some(frame) = r.frame.as_ref() else { return };
        if r.ring && self.ring.is_some() {
            if self.paused() {
                self.shared.with_health(|h| h.record.frames_dropped += 1);
            } else {
                let bytes: &[u8] = match frame.format {
                    PixelFormat::Jpeg => &frame.data,
                    _ => match frame.to_luma().map_err(|e| e.to_string()).and_then(|g| {
                        self.jpeg.clear();
                        let enc = image::codecs::jpeg::JpegEncoder::new_with_quality(&mut self.jpeg, 90);
                        g.write_with_encoder(enc).map_err(|e| e.to_string())
                    }) {
                        Ok(()) => &self.jpeg,
                        Err(_) => &[],
                    },
                };
                let entry = RingEntry {
                    seq: frame.seq,
                    t: frame.timestamp.get(),
                    size: (frame.width, frame.height),
                    bytes: 0,
                    overlays: r.overlays.clone(),
                    sample: r.sample,
                };
                let result = match self.ring.as_mut() {
                    Some(ring) if !bytes.is_empty() => {
                        let _busy = InFlight::new(&self.shared);
                        ring.push(entry, bytes).map(|()| (ring.bytes(), ring.entries().len()))
                    }
                    _ => Err(std::io::Error::other("frame cannot be encoded")),
                };
                match result {
                    Ok((b, n)) => {
                        self.recovered();
                        self.shared.with_health(|h| {
                            h.record.frames_written += 1;
                            h.record.ring_bytes = b;
                            h.record.ring_frames = n as u64;
                        });
                    }
                    Err(e) => {
                        self.shared.with_health(|h| h.record.frames_dropped += 1);
                        self.fault("ring", &e.to_string());
                    }
                }
            }
        }
        if r.snapshot {
            let name = format!("{}-{:08}", freeze::utc_stamp(std::time::SystemTime::now()), frame.seq);
            let depth = (!r.depth.is_empty()).then_some(r.depth.as_slice());
            let dir = self.dir.join("snapshots");
            let _busy = InFlight::new(&self.shared);
            let caption = snapshot::Caption::now(&self.source, r.sample.as_ref());
            match snapshot::write(&dir, &name, frame, &r.overlays, &caption, depth, self.keep_snapshots) {
                Ok(p) => {
                    self.recovered();
                    self.shared.with_health(|h| {
                        h.record.snapshots += 1;
                        h.record.last = p.display().to_string();
                    });
                    self.shared.log(Level::INFO, format!("snapshot {}", p.display()));
                }
                Err(e) => self.fault("snapshot", &e),
            }
        }
    }

    fn save(&mut self, label: &str) {
        let Some(ring) = self.ring.as_ref() else {
            self.shared.log(Level::WARN, "record save: the ring is off (record.enabled = false)");
            return;
        };
        let dir = self.dir.join("recordings");
        let stamp = freeze::utc_stamp(std::time::SystemTime::now());
        let _busy = InFlight::new(&self.shared);
        let result = std::fs::create_dir_all(&dir)
            .map_err(|e| format!("{}: {e}", dir.display()))
            .and_then(|()| freeze::freeze(ring, &dir, &stamp, label, &self.inputs));
        match result {
            Ok(p) => {
                freeze::rotate(&dir, self.keep_recordings);
                self.shared.with_health(|h| {
                    h.record.saved += 1;
                    h.record.last = p.display().to_string();
                });
                self.shared
                    .log(Level::WARN, format!("recording saved: {} ({} frames)", p.display(), ring.entries().len()));
            }
            Err(e) if ring.entries().is_empty() => self.shared.log(Level::WARN, format!("record save: {e}")),
            Err(e) => self.fault("record save", &e),
        }
    }
}

impl Recorder {
    /// Starts the writer thread when there is a state directory; `None` when there is none (nothing
    /// is written to disk). The writer opens the ring; one that cannot be opened is logged and
    /// recording stays off. `write` replaces the ring's frame writer (tests: a stalled disk).
    pub fn start(
        cfg: &Config,
        freeze_gap: Duration,
        shared: Arc<Shared>,
        write: Option<ring::WriteFile>,
    ) -> Option<Self> {
        let dir = crate::status::state_dir(cfg)?;
        let rc = &cfg.record;
        let calibration = cfg.calibration().ok().flatten().map(|c| c.path);
        let (tx, rx) = std::sync::mpsc::sync_channel::<Box<FrameRecord>>(rc.queue_frames);
        let (pool_tx, pool) = std::sync::mpsc::sync_channel::<Box<FrameRecord>>(rc.queue_frames + 2);
        let ring_on = Arc::new(AtomicBool::new(rc.enabled));
        shared.with_health(|h| h.record.active = rc.enabled);
        let mut w = Writer {
            dir: dir.clone(),
            ring: None,
            inputs: FreezeInputs { calibration, config_text: shared.config_text.clone() },
            shared: shared.clone(),
            keep_snapshots: rc.keep_snapshots,
            keep_recordings: rc.keep_recordings,
            paused_until: None,
            retry: crate::backoff::Backoff::new(RETRY_MIN, RETRY_MAX),
            last_error_log: None,
            jpeg: Vec::new(),
            source: cfg.source.name(),
        };
        let sh = shared.clone();
        let (rc2, on) = (rc.clone(), ring_on.clone());
        let thread = std::thread::Builder::new().name("fme-recorder".into()).spawn(move || {
            w.open(&rc2, write, &on);
            loop {
                match rx.recv_timeout(Duration::from_millis(100)) {
                    Ok(mut r) => {
                        w.handle(&mut r);
                        let _ = pool_tx.try_send(r);
                    }
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => {
                        if let Some(label) = sh.requests.take_save() {
                            w.save(&label);
                        }
                        if sh.stopping() {
                            return;
                        }
                        std::thread::sleep(Duration::from_millis(100));
                        continue;
                    }
                }
                if let Some(label) = sh.requests.take_save() {
                    // Everything handed over before the request goes into the recording.
                    while let Ok(mut r) = rx.try_recv() {
                        w.handle(&mut r);
                        let _ = pool_tx.try_send(r);
                    }
                    w.save(&label);
                }
                if sh.stopping() {
                    return;
                }
            }
        });
        let thread = match thread {
            Ok(t) => t,
            Err(e) => {
                shared.log(Level::ERROR, format!("recorder: cannot start its thread: {e}"));
                return None;
            }
        };
        shared.log(
            Level::INFO,
            format!("recorder: state directory {}{}", dir.display(), if rc.enabled { "" } else { " (ring off)" }),
        );
        Some(Self {
            tx: Some(tx),
            pool,
            shared,
            ring: ring_on,
            snapshot_every_s: rc.snapshot_every_s,
            next_snapshot_t: None,
            alarm: (rc.alarm_low_mps, rc.alarm_high_mps),
            freeze_on_fault: rc.freeze_on_fault,
            freeze_gap,
            last_auto: None,
            last_seen: (false, StageHealth::default(), 0),
            thread: Some(thread),
        })
    }

    /// Called by the pipeline thread after each frame: hands the frame, what the pipeline made of it
    /// (`overlays`, copied from its outcome) and its sample to the writer (never waits: a full queue
    /// drops the frame and counts it), and serves snapshot requests (console `snap`,
    /// `record.snapshot_every_s` on frame time), for which `pipeline` gives the references and depth.
    pub fn after_frame(
        &mut self,
        frame: &Frame,
        overlays: &Overlays,
        pipeline: &dyn Pipeline,
        sample: Option<ActivitySample>,
    ) {
        let t = frame.timestamp.get();
        let mut snap = self.shared.requests.take_snapshot();
        if self.snapshot_every_s > 0.0 {
            let next = *self.next_snapshot_t.get_or_insert(t + self.snapshot_every_s);
            if t >= next || t < next - 2.0 * self.snapshot_every_s {
                snap = true;
                self.next_snapshot_t = Some(t + self.snapshot_every_s);
            }
        }
        let ring = self.ring.load(Ordering::Relaxed);
        if !(ring || snap) {
            return;
        }
        let Some(tx) = &self.tx else { return };
        let mut r = self.pool.try_recv().unwrap_or_default();
        match r.frame.as_mut() {
            Some(f) => {
                f.data.clear();
                f.data.extend_from_slice(&frame.data);
                (f.seq, f.timestamp, f.arrived, f.width, f.height, f.format) =
                    (frame.seq, frame.timestamp, frame.arrived, frame.width, frame.height, frame.format);
            }
            None => r.frame = Some(frame.clone()),
        }
        r.overlays.clone_from(overlays);
        if snap {
            pipeline.reference_residuals(&mut r.overlays.references);
        }
        r.sample = sample;
        r.ring = ring;
        r.snapshot = snap;
        r.depth.clear();
        if snap && !pipeline.depth_grid((frame.width, frame.height), snapshot::DEPTH_GRID, &mut r.depth) {
            r.depth.clear();
        }
        match tx.try_send(r) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {
                self.shared.with_health(|h| h.record.frames_dropped += 1);
                if snap {
                    self.shared.requests.restore_snapshot();
                }
            }
        }
    }

    /// Called by the pipeline thread every loop turn (with or without a frame): asks for a freeze
    /// on the chosen faults (camera lost or stalled, detector or depth failure, a pipeline error)
    /// and alarms (smoothed activity outside `record.alarm_*`), at most one per
    /// `record.freeze_min_gap_s`.
    pub fn watch(&mut self, sample: Option<&ActivitySample>, errors: u64) {
        if !self.ring.load(Ordering::Relaxed) {
            return;
        }
        let (camera_ok, stage) = self.shared.with_health(|h| (h.camera_ok, h.stage));
        let (was_camera, was_stage, was_errors) = self.last_seen;
        self.last_seen = (camera_ok, stage, errors);
        let mut label = None;
        if self.freeze_on_fault {
            if was_camera && !camera_ok {
                label = Some("fault-camera");
            } else if was_stage.detector_ok && !stage.detector_ok {
                label = Some("fault-detector");
            } else if was_stage.depth_ok && !stage.depth_ok {
                label = Some("fault-depth");
            } else if errors > was_errors {
                label = Some("fault-pipeline");
            }
        }
        if let Some(s) = sample
            && label.is_none()
            && !s.flags.too_few_fish
            && !s.flags.unfitted
            && s.smoothed.0.is_finite()
        {
            let (low, high) = self.alarm;
            if low > 0.0 && s.smoothed.0 < low {
                label = Some("alarm-low");
            } else if high > 0.0 && s.smoothed.0 > high {
                label = Some("alarm-high");
            }
        }
        if let Some(l) = label
            && self.last_auto.is_none_or(|t| t.elapsed() >= self.freeze_gap)
        {
            self.last_auto = Some(Instant::now());
            self.shared.log(Level::WARN, format!("recorder: {l}: freezing the black box"));
            self.shared.requests.request_save(l);
        }
    }

    /// Ends the pipeline's side; the writer finishes the queue, serves pending requests and stops
    /// when the service stops.
    pub fn close(&mut self) {
        self.tx = None;
    }

    /// The writer thread (joined at shutdown when finished).
    pub fn take_thread(&mut self) -> Option<std::thread::JoinHandle<()>> {
        self.thread.take()
    }
}

/// Writes one snapshot now (`fme snapshot`): the frame with what `pipeline` produced on it
/// (`overlays`, the references added) and its metric depth map into `dir`, keeping `keep`; the top
/// bar names the camera of `source`. Returns the JPEG's path.
pub fn snapshot_now(
    dir: &Path,
    source: &Path,
    frame: &Frame,
    overlays: &Overlays,
    pipeline: &dyn Pipeline,
    sample: Option<&ActivitySample>,
    keep: usize,
) -> Result<PathBuf, String> {
    let mut overlays_now = overlays.clone();
    pipeline.reference_residuals(&mut overlays_now.references);
    let mut depth = Vec::new();
    let has_depth = pipeline.depth_grid((frame.width, frame.height), snapshot::DEPTH_GRID, &mut depth);
    let name = format!("{}-{:08}", freeze::utc_stamp(std::time::SystemTime::now()), frame.seq);
    let caption = snapshot::Caption::now(source, sample);
    snapshot::write(dir, &name, frame, &overlays_now, &caption, has_depth.then_some(depth.as_slice()), keep)
}
