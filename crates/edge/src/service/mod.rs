//! Wiring of `fme run`: threads, queues, health and status, watchdog, shutdown.
//!
//! ```text
//! capture thread --Frame--> FrameQueue (drop oldest, count) --> pipeline thread (Pipeline::process)
//!     -> Publisher (status bits, feeding rule, heartbeat) -> RegisterBank (watch: latest block)
//!         -> Modbus TCP/RTU server tasks (PLC polls) | client task (FC16 per update) | serial line
//!     -> Shared health <- console thread, keepalive task, live view
//!     -> HistorySender (bounded, drop and count) -> fme-history thread -> day files (docs/history.md)
//!     -> MqttSender (bounded, drop oldest and count) -> fme-mqtt thread -> broker (docs/mqtt.md)
//! Shared health + RegisterBank counters <- metrics task (GET /metrics, a copy per scrape; docs/metrics.md)
//! ```
//! The pipeline thread pings the systemd watchdog each loop turn (a stuck `Pipeline::process` stops
//! the pings and systemd restarts the service); a camera outage does not (the loop keeps turning).
//!
//! [`build_pipeline`] returns the pipeline `fme run` uses ([`fme_core::pipeline::FishPipeline`]).

pub mod config;
pub mod publish;
pub mod signals;
pub mod timing;

use crate::capture::{Backoff, CaptureError, FrameQueue, FrameSource};
use crate::config::Config;
use crate::output::bank::RegisterBank;
use crate::output::roles::RoleError;
use crate::status::Shared;
use fme_core::pipeline::{FishPipeline, Pipeline};
use publish::{Publish, Publisher, publish_and_send};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tracing::Level;

/// Errors starting the daemon (everything after start-up is logged and retried instead).
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// A Modbus role (or the serial line) could not start.
    #[error(transparent)]
    Roles(#[from] RoleError),
    /// The frame source could not be opened.
    #[error("source: {0}")]
    Capture(#[from] CaptureError),
    /// The pipeline could not be built.
    #[error("pipeline: {0}")]
    Pipeline(String),
    /// A configured duration no timer can hold (names the key; exit 2).
    #[error(transparent)]
    Timing(#[from] timing::TimingError),
    /// The `--series` file could not be created.
    #[error("--series: {0}")]
    Series(String),
    /// A thread could not be spawned.
    #[error("cannot spawn {what}: {error}")]
    Spawn {
        /// Which thread.
        what: &'static str,
        /// The I/O error (in the message, not a separate cause: printed once).
        error: std::io::Error,
    },
}

/// What to say when the calibration has fewer references than the metric depth fit needs (2), so
/// the fish set the scale: said at start (journal and console `log`), not left to be discovered.
pub fn scale_note(cfg: &Config) -> Option<String> {
    let c = cfg.calibration().ok()??;
    (c.references.len() < 2).then(|| {
        format!(
            "calibration {}: {} reference object(s), the metric depth fit needs at least 2: the fish set the scale \
             (depth.scale = \"{}\", motion.body_length_m = {} m); speeds are only as right as that length \
             (docs/pipeline.md, \"The fish as the ruler\")",
            c.path.display(),
            c.references.len(),
            format!("{:?}", cfg.depth.scale).to_lowercase(),
            cfg.motion.body_length_m.get(),
        )
    })
}

/// Builds the pipeline `fme run` uses: detector + tracker + depth + post-processing + motion (paper
/// eq. 1-5), see [`fme_core::pipeline`]. Model, calibration and ONNX Runtime problems are
/// [`ServiceError::Pipeline`] naming the config key and the file.
pub fn build_pipeline(cfg: &Config) -> Result<Box<dyn Pipeline>, ServiceError> {
    let calibration = cfg.calibration().map_err(ServiceError::Pipeline)?;
    match &calibration {
        Some(c) => tracing::info!(file = %c.path.display(), references = c.references.len(), "camera calibration"),
        None => tracing::warn!("{}", uncalibrated_message(cfg)),
    }
    let p = FishPipeline::new(&cfg.pipeline(), calibration).map_err(ServiceError::Pipeline)?;
    Ok(Box::new(p))
}

/// What the box does without a camera calibration, for the start-up warning: with a fish length
/// and `depth.scale` other than `references` the fish are the ruler and speeds are reported;
/// otherwise fish are only counted.
pub fn uncalibrated_message(cfg: &Config) -> String {
    match (cfg.depth.scale, cfg.motion.body_length()) {
        (fme_core::metric::DepthScale::Fish | fme_core::metric::DepthScale::Auto, Some(len)) => format!(
            "no camera calibration (camera.calibration): the fish are the ruler (depth.scale = {}, \
             motion.body_length_m = {} m, assumed lens): speeds in m/s and BL/s are reported once the fish fit \
             holds (status bits 3 and 8 set); reference objects make m/s more accurate (docs/calibration.md)",
            format!("{:?}", cfg.depth.scale).to_lowercase(),
            len.0
        ),
        _ => "no camera calibration (camera.calibration) and no fish ruler (depth.scale = references or \
              motion.body_length_m = 0): fish are tracked and counted but no speed is reported (status bit 3 clear)"
            .to_string(),
    }
}

/// The activity history's directory (`docs/history.md`): `history.dir` if set, else `history/` in
/// the state directory ([`crate::status::state_dir`]: `$STATE_DIRECTORY`, else
/// `service.state_dir`); `None` (history off) when neither is set or `history.enabled` is false.
pub fn history_dir(cfg: &Config) -> Option<std::path::PathBuf> {
    if !cfg.history.enabled {
        return None;
    }
    if !cfg.history.dir.as_os_str().is_empty() {
        return Some(cfg.history.dir.clone());
    }
    crate::status::state_dir(cfg).map(|d| d.join("history"))
}

/// Run-time options not in the config file.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stop after this many processed frames (benchmarks).
    pub max_frames: Option<u64>,
    /// Write every frame's sample to this CSV (`fme run --series`).
    pub series: Option<std::path::PathBuf>,
    /// Writes the black box's ring frames instead of the file system (tests: a stalled or failing
    /// disk); `None` = the file system.
    pub ring_writer: Option<crate::record::ring::WriteFile>,
}

/// A running daemon.
pub struct Daemon {
    cfg: Config,
    shared: Arc<Shared>,
    bank: Arc<RegisterBank>,
    publisher: Arc<Mutex<Publisher>>,
    modbus_addr: Option<SocketAddr>,
    stop_tx: tokio::sync::watch::Sender<bool>,
    server_stops: Vec<tokio::sync::oneshot::Sender<()>>,
    server_tasks: Vec<tokio::task::JoinHandle<()>>,
    client_task: Option<tokio::task::JoinHandle<()>>,
    metrics: Option<crate::output::metrics_http::MetricsServer>,
    aux_tasks: Vec<tokio::task::JoinHandle<()>>,
    pipeline_thread: Option<std::thread::JoinHandle<()>>,
    other_threads: Vec<std::thread::JoinHandle<()>>,
    finished: tokio::sync::watch::Receiver<bool>,
    serial_tx: Option<std::sync::mpsc::SyncSender<String>>,
}

impl std::fmt::Debug for Daemon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Daemon")
            .field("modbus_addr", &self.modbus_addr)
            .field("metrics_addr", &self.metrics_addr())
            .finish_non_exhaustive()
    }
}

/// Sleeps `d` in small steps, returning early (true) when a stop is requested.
fn sleep_unless_stopping(shared: &Shared, d: Duration) -> bool {
    let end = Instant::now() + d;
    while Instant::now() < end {
        if shared.stopping() {
            return true;
        }
        std::thread::sleep((end - Instant::now()).min(Duration::from_millis(50)));
    }
    shared.stopping()
}

/// The message of a caught panic.
fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    let msg = p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned());
    format!("panicked: {}", msg.unwrap_or_else(|| "(no message)".into()))
}

/// Runs the capture loop, restarting it (after the reconnect backoff) if a source panics.
fn capture_thread(
    mut source: Box<dyn FrameSource>,
    queue: Arc<FrameQueue>,
    shared: Arc<Shared>,
    backoff: Backoff,
    size: SizeLimit,
) {
    loop {
        let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            capture_loop(&mut source, &queue, &shared, backoff, size);
        }));
        match run {
            Ok(()) => return,
            Err(p) => {
                shared.with_health(|h| {
                    h.camera_ok = false;
                    h.capture_errors += 1;
                });
                shared.log(Level::ERROR, format!("capture {}; restarting capture", panic_text(&*p)));
                let mut b = backoff;
                if sleep_unless_stopping(&shared, b.next_delay()) {
                    queue.close();
                    return;
                }
                if let Err(e) = source.reopen() {
                    shared.log(Level::WARN, format!("camera reconnect failed: {e}"));
                }
            }
        }
    }
}

/// `source.max_pixels` and the configured size ([`crate::capture::Frame::check_size`]).
#[derive(Debug, Clone, Copy)]
struct SizeLimit {
    max_pixels: u64,
    configured: (u32, u32),
}

fn capture_loop(
    source: &mut Box<dyn FrameSource>,
    queue: &FrameQueue,
    shared: &Shared,
    mut backoff: Backoff,
    size: SizeLimit,
) {
    let mut window_start = Instant::now();
    let mut window_frames = 0u32;
    let mut oversized = 0u64;
    let paced = source.paced();
    while !shared.stopping() {
        match source.next_frame(queue.take_buffer()) {
            Ok(frame) => {
                backoff.reset();
                // Checked from the header before anything decodes it: a bad frame, not a decode.
                if let Err(e) = frame.check_size(size.max_pixels, size.configured) {
                    oversized += 1;
                    shared.with_health(|h| h.capture_errors += 1);
                    if oversized == 1 || oversized.is_multiple_of(100) {
                        shared.log(Level::WARN, format!("bad frame #{oversized} dropped: {e}"));
                    }
                    queue.recycle(frame.data);
                    continue;
                }
                let now = frame.arrived;
                if paced {
                    if let Some(old) = queue.push(frame) {
                        queue.recycle(old.data);
                    }
                } else {
                    let mut f = frame;
                    while let Err(back) = queue.push_wait(f, Duration::from_millis(100)) {
                        if shared.stopping() || queue.is_closed() {
                            break;
                        }
                        f = back;
                    }
                }
                let dropped = queue.stats().dropped + source.source_dropped();
                window_frames += 1;
                let elapsed = now.saturating_duration_since(window_start).as_secs_f64();
                shared.with_health(|h| {
                    h.camera_ok = true;
                    h.frames_captured += 1;
                    h.frames_dropped = dropped;
                    if elapsed >= 1.0 {
                        h.camera_fps = f64::from(window_frames) / elapsed;
                    }
                });
                if elapsed >= 1.0 {
                    window_start = now;
                    window_frames = 0;
                }
            }
            Err(CaptureError::End) => {
                shared.log(Level::INFO, format!("{}: end of recording", source.describe()));
                break;
            }
            Err(e) => {
                shared.with_health(|h| {
                    h.camera_ok = false;
                    h.camera_fps = 0.0;
                    h.capture_errors += 1;
                });
                shared.log(Level::WARN, format!("camera: {e}"));
                loop {
                    let d = backoff.next_delay();
                    if sleep_unless_stopping(shared, d) {
                        break;
                    }
                    match source.reopen() {
                        Ok(()) => {
                            shared.with_health(|h| {
                                h.reconnects += 1;
                                h.source = source.describe();
                            });
                            shared.log(Level::INFO, format!("camera back: {}", source.describe()));
                            window_start = Instant::now();
                            window_frames = 0;
                            break;
                        }
                        Err(e) => shared.log(Level::WARN, format!("camera reconnect failed: {e}")),
                    }
                }
            }
        }
    }
    queue.close();
}

struct PipelineCtx {
    pipeline: Box<dyn Pipeline>,
    queue: Arc<FrameQueue>,
    shared: Arc<Shared>,
    publisher: Arc<Mutex<Publisher>>,
    serial_tx: Option<std::sync::mpsc::SyncSender<String>>,
    output_period_s: f64,
    max_frames: Option<u64>,
    series: Option<std::sync::mpsc::SyncSender<crate::sequence::SeriesRow>>,
    series_dropped: u64,
    watchdog: Option<Duration>,
    finished: tokio::sync::watch::Sender<bool>,
    recorder: Option<crate::record::Recorder>,
}

fn pipeline_loop(mut c: PipelineCtx) {
    let mut next_out: Option<f64> = None;
    let mut last_ping: Option<Instant> = None;
    let mut processed = 0u64;
    let mut errors = 0u64;
    let mut tracks = String::with_capacity(1024);
    // Copies of the last outcome's fish (console `tracks`) and overlays (the recorder), allocated once.
    let mut fish = Vec::with_capacity(fme_core::motion::MAX_FISH);
    let mut overlays = crate::record::Overlays::default();
    let mut fit_state = fme_core::pipeline::DepthFitState::default();
    while !c.shared.stopping() {
        if let Some(wd) = c.watchdog
            && last_ping.is_none_or(|t| t.elapsed() >= wd / 2)
        {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            last_ping = Some(Instant::now());
        }
        let Some(frame) = c.queue.pop(Duration::from_millis(100)) else {
            if let Some(r) = c.recorder.as_mut() {
                r.watch(None, errors);
            }
            if c.queue.is_closed() && c.queue.is_empty() {
                break;
            }
            continue;
        };
        // A panic in a stage on one bad frame must not end the pipeline: count it as an error. The
        // outcome borrows the pipeline: what the loop keeps of it is copied out here.
        let (fish, overlays, record) = (&mut fish, &mut overlays, c.recorder.is_some());
        let result = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            c.pipeline.process(&frame).map(|o| {
                fish.clear();
                fish.extend_from_slice(o.fish);
                if record {
                    overlays.copy_from(&o);
                }
                (o.sample, o.fit)
            })
        })) {
            Ok(r) => r,
            Err(p) => Err(fme_core::pipeline::PipelineError::Stage { stage: "pipeline", message: panic_text(&*p) }),
        };
        let now = Instant::now();
        processed += 1;
        let mut due = false;
        let ts = frame.timestamp.get();
        let stage = c.pipeline.health();
        match &result {
            Ok((_, fit)) => fit_state = *fit,
            Err(_) => overlays.clear(),
        }
        let sample = match result.map(|(s, _)| s) {
            Ok(s) => {
                if let (Some(tx), Some(sample)) = (&c.series, s) {
                    // The writer thread has the disk; the pipeline never waits on it.
                    let row = crate::sequence::SeriesRow { frame: frame.seq + 1, sample };
                    match tx.try_send(row) {
                        Ok(()) => {}
                        Err(std::sync::mpsc::TrySendError::Full(_)) => {
                            c.series_dropped += 1;
                            if c.series_dropped == 1 || c.series_dropped.is_multiple_of(1000) {
                                c.shared.log(
                                    Level::WARN,
                                    format!("--series: {} rows dropped (disk slow)", c.series_dropped),
                                );
                            }
                        }
                        Err(std::sync::mpsc::TrySendError::Disconnected(_)) => c.series = None,
                    }
                }
                s
            }
            Err(e) => {
                errors += 1;
                // First error and then every 100th: a flood of bad frames must not flood the journal.
                if errors == 1 || errors.is_multiple_of(100) {
                    c.shared.log(Level::WARN, format!("pipeline error #{errors}: {e}"));
                }
                None
            }
        };
        if let Some(r) = c.recorder.as_mut() {
            // Never waits: a full queue drops the frame from the recording (counted).
            r.after_frame(&frame, overlays, &*c.pipeline, sample);
            r.watch(sample.as_ref(), errors);
        }
        if sample.is_some() {
            let next = next_out.get_or_insert(ts);
            if ts + 1e-9 >= *next || ts < *next - 2.0 * c.output_period_s {
                due = true;
                // Next slot on the frame clock; resynchronise after gaps or a clock jump.
                *next = if ts - *next > c.output_period_s || ts < *next - 2.0 * c.output_period_s {
                    ts + c.output_period_s
                } else {
                    *next + c.output_period_s
                };
            }
        }
        if due {
            tracks.clear();
            crate::console::tracks::describe_fish(&mut tracks, fish, crate::console::TRACK_ROWS);
        }
        c.shared.with_health(|h| {
            h.frames_processed = processed;
            h.pipeline_errors = errors;
            h.last_processed_at = Some(now);
            h.stage = stage;
            h.fit_state = fit_state;
            if let Some(s) = sample {
                h.last_sample = Some(s);
                h.last_sample_at = Some(now);
            }
            if due {
                std::mem::swap(&mut h.tracks_text, &mut tracks);
            }
        });
        if due {
            publish_and_send(&c.publisher, &c.shared, c.serial_tx.as_ref(), Publish::Update);
            let ms = frame.arrived.elapsed().as_secs_f64() * 1000.0;
            c.shared.with_health(|h| h.latency.record(ms));
        }
        c.queue.recycle(frame.data);
        if c.max_frames.is_some_and(|m| processed >= m) {
            c.shared.log(Level::INFO, format!("processed {processed} frames: stopping as asked"));
            break;
        }
    }
    drop(c.series.take()); // the writer thread drains what is queued and finishes the file
    if let Some(r) = c.recorder.as_mut() {
        r.close();
    }
    let _ = c.finished.send(true);
}

impl Daemon {
    /// Starts every part of the daemon. Must be called inside a tokio runtime. Start-up errors (bind,
    /// serial open of an RTU server) are returned; later failures are logged and retried.
    pub async fn start(
        cfg: Config,
        config_text: String,
        source: Box<dyn FrameSource>,
        pipeline: Box<dyn Pipeline>,
        opts: RunOptions,
    ) -> Result<Self, ServiceError> {
        let timing = timing::Timing::from_config(&cfg)?;
        let series_file = match &opts.series {
            Some(p) => Some(crate::sequence::SeriesWriter::create(p, "").map_err(ServiceError::Series)?),
            None => None,
        };
        let bank = Arc::new(RegisterBank::new());
        let shared = Arc::new(Shared::new(config_text, cfg.console.log_lines));
        shared.with_health(|h| h.source = source.describe());
        shared.set_word_order(cfg.output.modbus.word_order);
        shared.log(
            Level::INFO,
            format!(
                "fme {} ({}) starting on {}",
                env!("CARGO_PKG_VERSION"),
                fme_core::infer::backend::BUILD,
                source.describe()
            ),
        );
        if let Some(note) = scale_note(&cfg) {
            shared.log(Level::WARN, note);
        }
        let publisher = Arc::new(Mutex::new(Publisher::new(&cfg, &timing, bank.clone())));
        let mut other_threads = Vec::new();
        if let Some(dir) = history_dir(&cfg) {
            let h = &cfg.history;
            let (tx, thread) = crate::history::spawn(dir.clone(), h.keep_days, h.fsync_s, shared.clone())
                .map_err(|error| ServiceError::Spawn { what: "history", error })?;
            publisher.lock().unwrap_or_else(|p| p.into_inner()).set_history(Some(tx));
            other_threads.push(thread);
            shared.log(Level::INFO, format!("history: one row per update in {}", dir.display()));
        }
        // Publish a first block at once so a PLC never reads all zeros from a running box.
        publish_and_send(&publisher, &shared, None, Publish::Update);
        if cfg.output.mqtt.enabled {
            // After the first block: the broker hears from the box once its capture runs.
            let (tx, thread) = crate::output::mqtt::spawn(&cfg, shared.clone())
                .map_err(|error| ServiceError::Spawn { what: "mqtt", error })?;
            publisher.lock().unwrap_or_else(|p| p.into_inner()).set_mqtt(Some(tx));
            other_threads.push(thread);
        }

        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let roles = crate::output::roles::spawn(&cfg, &bank, &shared, stop_rx).await?;
        let modbus_addr = roles.modbus_addr;
        let (server_stops, server_tasks, client_task) = (roles.server_stops, roles.server_tasks, roles.client_task);
        let serial_tx = roles.serial_tx;
        other_threads.extend(roles.serial_thread);
        // The Prometheus endpoint: a port it cannot bind is logged and shown, never fatal.
        let metrics = crate::output::metrics_http::spawn(&cfg.output.metrics, timing.stale_after, &shared, &bank).await;
        if cfg.console.enabled {
            let (dev, baud, echo, sh, bk) =
                (cfg.console.device.clone(), cfg.console.baud, cfg.console.echo, shared.clone(), bank.clone());
            other_threads.push(
                std::thread::Builder::new()
                    .name("fme-console".into())
                    .spawn(move || crate::console::run_on_device(&dev, baud, echo, &sh, &bk))
                    .map_err(|error| ServiceError::Spawn { what: "console", error })?,
            );
        }

        let queue = Arc::new(FrameQueue::new(cfg.source.queue_frames));
        let backoff = Backoff::new(
            Duration::from_millis(cfg.source.reconnect_min_ms),
            Duration::from_millis(cfg.source.reconnect_max_ms),
        );
        let (q, sh) = (queue.clone(), shared.clone());
        let size = SizeLimit { max_pixels: cfg.source.max_pixels, configured: (cfg.source.width, cfg.source.height) };
        other_threads.push(
            std::thread::Builder::new()
                .name("fme-capture".into())
                .spawn(move || capture_thread(source, q, sh, backoff, size))
                .map_err(|error| ServiceError::Spawn { what: "capture", error })?,
        );
        let watchdog = if cfg.service.systemd_notify { sd_notify::watchdog_enabled() } else { None };
        // `--series`: a writer thread with a bounded queue, so the pipeline never waits on the disk.
        let series = match series_file {
            Some(mut w) => {
                let (tx, rx) = std::sync::mpsc::sync_channel::<crate::sequence::SeriesRow>(4096);
                let sh = shared.clone();
                other_threads.push(
                    std::thread::Builder::new()
                        .name("fme-series".into())
                        .spawn(move || {
                            let result = rx.iter().try_for_each(|row| w.write(&row)).and_then(|()| w.finish());
                            if let Err(e) = result {
                                sh.log(Level::ERROR, format!("--series: {e}; no more rows are written"));
                            }
                        })
                        .map_err(|error| ServiceError::Spawn { what: "series writer", error })?,
                );
                Some(tx)
            }
            None => None,
        };
        let (finished_tx, finished) = tokio::sync::watch::channel(false);
        let mut recorder = crate::record::Recorder::start(&cfg, timing.freeze_gap, shared.clone(), opts.ring_writer);
        if let Some(t) = recorder.as_mut().and_then(crate::record::Recorder::take_thread) {
            other_threads.push(t);
        }
        let ctx = PipelineCtx {
            pipeline,
            queue,
            shared: shared.clone(),
            publisher: publisher.clone(),
            serial_tx: serial_tx.clone(),
            output_period_s: timing.output_period.as_secs_f64(),
            max_frames: opts.max_frames,
            series,
            series_dropped: 0,
            watchdog,
            finished: finished_tx,
            recorder,
        };
        let pipeline_thread = Some(
            std::thread::Builder::new()
                .name("fme-pipeline".into())
                .spawn(move || pipeline_loop(ctx))
                .map_err(|error| ServiceError::Spawn { what: "pipeline", error })?,
        );

        // Keepalive: with no samples (camera down, pipeline failing) the registers still update, so
        // the PLC sees the heartbeat, the stale bit and the fault code.
        let mut aux_tasks = Vec::new();
        let period = timing.output_period;
        let (sh, pb, stx) = (shared.clone(), publisher.clone(), serial_tx.clone());
        aux_tasks.push(tokio::spawn(async move {
            let mut tick = tokio::time::interval(period / 2);
            loop {
                tick.tick().await;
                if sh.stopping() {
                    return;
                }
                publish_and_send(&pb, &sh, stx.as_ref(), Publish::IfQuietFor(period + period / 2));
            }
        }));
        if let Some(every) = timing.live_view {
            let (sh, bk) = (shared.clone(), bank.clone());
            aux_tasks.push(tokio::spawn(async move {
                let mut tick = tokio::time::interval(every);
                loop {
                    tick.tick().await;
                    if sh.stopping() {
                        return;
                    }
                    eprint!("\r{}   ", crate::console::activity_line(&sh, &bk));
                }
            }));
        }
        if cfg.service.systemd_notify {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Ready, sd_notify::NotifyState::Status("running")]);
        }
        Ok(Self {
            cfg,
            shared,
            bank,
            publisher,
            modbus_addr,
            stop_tx,
            server_stops,
            server_tasks,
            client_task,
            metrics,
            aux_tasks,
            pipeline_thread,
            other_threads,
            finished,
            serial_tx,
        })
    }

    /// Shared state (health, logs).
    pub fn shared(&self) -> &Arc<Shared> {
        &self.shared
    }

    /// The register bank the Modbus roles serve.
    pub fn bank(&self) -> &Arc<RegisterBank> {
        &self.bank
    }

    /// SIGHUP: checks the calibration file again and says what it found (journal and console
    /// `log`). The running pipeline keeps its calibration: applying a changed one needs a restart.
    pub fn on_hangup(&self) {
        let what = match self.cfg.calibration() {
            Ok(Some(c)) => format!(
                "{} reads OK ({} reference objects); restart fme to apply a changed calibration",
                c.path.display(),
                c.references.len()
            ),
            Ok(None) => "no calibration configured (camera.calibration)".to_string(),
            Err(e) => format!("{e}; the running calibration is kept"),
        };
        self.shared.log(Level::WARN, format!("SIGHUP: not stopping; calibration check: {what}"));
    }

    /// The bound Modbus TCP server address (useful with port 0).
    pub fn modbus_addr(&self) -> Option<SocketAddr> {
        self.modbus_addr
    }

    /// The bound address of the Prometheus endpoint (`output.metrics.listen`), if it serves.
    pub fn metrics_addr(&self) -> Option<SocketAddr> {
        self.metrics.as_ref().map(|m| m.addr)
    }

    /// Resolves when the pipeline thread ends by itself: `true` at the end of a non-looping recording
    /// or after `max_frames`; `false` if the thread died (the caller should exit non-zero so that
    /// systemd's `Restart=on-failure` restarts the service).
    pub async fn finished(&mut self) -> bool {
        self.finished.wait_for(|f| *f).await.is_ok()
    }

    /// Clean shutdown (SIGTERM/SIGINT): writes status "stopped" to the registers first (running bit
    /// cleared, fault code 6, feeding off), lets clients write it and polling PLCs read it for
    /// `service.stop_grace_ms`, then stops everything. Bounded to well under 2 s.
    pub async fn shutdown(mut self) {
        let t0 = Instant::now();
        if self.cfg.service.systemd_notify {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Stopping]);
        }
        self.shared.request_stop();
        // The "stopped" update, the history's and MQTT's last.
        publish_and_send(&self.publisher, &self.shared, self.serial_tx.as_ref(), Publish::Stopped);
        let _ = self.stop_tx.send(true);
        if let Some(t) = self.client_task.take() {
            let limit = Duration::from_millis(self.cfg.output.modbus.timeout_ms.min(800) + 100);
            if tokio::time::timeout(limit, t).await.is_err() {
                tracing::warn!("plc client did not finish its final write in time");
            }
        }
        if !self.server_tasks.is_empty() {
            tokio::time::sleep(Duration::from_millis(self.cfg.service.stop_grace_ms)).await;
        }
        for s in self.server_stops.drain(..) {
            let _ = s.send(());
        }
        for t in self.server_tasks.drain(..) {
            let _ = tokio::time::timeout(Duration::from_millis(200), t).await;
        }
        if let Some(m) = self.metrics.take() {
            m.stop().await;
        }
        for t in self.aux_tasks.drain(..) {
            t.abort();
        }
        self.serial_tx = None;
        // Threads notice `stopping` within ~100 ms; a camera blocked in the driver is not waited for.
        let deadline = Instant::now() + Duration::from_millis(400);
        let mut threads: Vec<_> = self.pipeline_thread.take().into_iter().chain(self.other_threads.drain(..)).collect();
        while Instant::now() < deadline && threads.iter().any(|t| !t.is_finished()) {
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        for t in threads.drain(..) {
            if t.is_finished() {
                let _ = t.join();
            }
        }
        self.shared.log(Level::INFO, format!("stopped in {} ms", t0.elapsed().as_millis()));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_uncalibrated_warning_says_what_the_box_will_do_with_its_scale() {
        let cfg = Config::default();
        let m = uncalibrated_message(&cfg);
        assert!(m.contains("the fish are the ruler") && m.contains("are reported"), "{m}");
        assert!(!m.contains("no speed"), "{m}");
        let mut refs_only = cfg.clone();
        refs_only.depth.scale = fme_core::metric::DepthScale::References;
        let m = uncalibrated_message(&refs_only);
        assert!(m.contains("no speed is reported") && m.contains("status bit 3 clear"), "{m}");
    }
}
