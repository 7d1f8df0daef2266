//! Wiring of `fme run`: threads, queues, health and status, watchdog, shutdown.
//!
//! ```text
//! capture thread --Frame--> FrameQueue (drop oldest, count) --> pipeline thread (Pipeline::process)
//!     -> Publisher (status bits, feeding rule, heartbeat) -> RegisterBank (watch: latest block)
//!         -> Modbus TCP/RTU server tasks (PLC polls) | client task (FC16 per update) | serial line
//!     -> Shared health <- console thread, keepalive task, live view
//!     -> HistorySender (bounded, drop and count) -> fme-history thread -> day files (docs/history.md)
//!     -> MqttSender (bounded, drop oldest and count) -> fme-mqtt thread -> broker (docs/mqtt.md)
//! Shared health + RegisterBank counters <- web server task (pages, JSON API, GET /metrics; docs/web.md)
//! ```
//! The pipeline thread pings the systemd watchdog each loop turn (a stuck `Pipeline::process` stops
//! the pings and systemd restarts the service); a camera outage does not (the loop keeps turning).
//!
//! [`build_pipeline`] returns the pipeline `fme run` uses ([`fme_core::pipeline::FishPipeline`]).

mod capture_loop;
pub mod config;
mod pipeline_loop;
pub mod publish;
pub mod signals;
pub mod subsystem;
pub mod timing;

use crate::capture::{CaptureError, FrameSource};
use crate::config::Config;
use crate::output::bank::RegisterBank;
use crate::output::roles::RoleError;
use crate::status::Shared;
use fme_core::pipeline::{FishPipeline, Pipeline};
use pipeline_loop::PipelineCtx;
use publish::{Publish, Publisher, publish_and_send};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use subsystem::Subsystem;
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
    /// The HTTP server's bound addresses (`[web] listen`, `[output.metrics] listen`).
    http_addrs: (Option<SocketAddr>, Option<SocketAddr>),
    /// Every thread and task, each stopped by the shutdown (tasks first).
    parts: Vec<Subsystem>,
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
        let networks = pipeline.networks();
        shared.with_health(|h| {
            h.source = source.describe();
            h.networks = networks.clone();
        });
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
        shared.log(Level::INFO, format!("networks: {networks}"));
        if let Some(note) = scale_note(&cfg) {
            shared.log(Level::WARN, note);
        }
        // What the pipeline was built with (read again: the pipeline keeps its own copy).
        shared.calibration.start(&cfg, cfg.calibration().ok().flatten());
        let publisher = Arc::new(Mutex::new(Publisher::new(&cfg, &timing, bank.clone())));
        // Threads and tasks, in start order; the shutdown stops the tasks first, then the threads.
        let mut parts: Vec<Subsystem> = Vec::new();
        parts.extend(subsystem::start_history(&cfg, &shared, &publisher)?);
        // Publish a first block at once so a PLC never reads all zeros from a running box.
        publish_and_send(&publisher, &shared, None, Publish::Update);
        // After the first block: the broker hears from the box once its capture runs.
        parts.extend(subsystem::start_mqtt(&cfg, &shared, &publisher)?);
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let roles = crate::output::roles::spawn(&cfg, &bank, &shared, stop_rx).await?;
        let modbus_addr = roles.modbus_addr;
        let (server_stops, server_tasks, client_task) = (roles.server_stops, roles.server_tasks, roles.client_task);
        let serial_tx = roles.serial_tx;
        parts.extend(roles.serial_thread.map(Subsystem::Thread));
        // The web pages and the Prometheus endpoint: a port it cannot bind is logged and shown, never fatal.
        let http = crate::web::spawn(&cfg, timing.stale_after, &shared, &bank).await;
        let http_addrs = http.as_ref().map_or((None, None), |h| (h.web_addr, h.metrics_addr));
        parts.extend(http.map(crate::web::WebServer::into_subsystem));
        parts.extend(subsystem::start_console(&cfg, &shared, &bank)?);
        let (queue, capture) = subsystem::start_capture(&cfg, source, &shared)?;
        parts.push(capture);
        let (series, series_thread) = subsystem::start_series(series_file, &shared)?;
        parts.extend(series_thread);
        let (finished_tx, finished) = tokio::sync::watch::channel(false);
        let mut recorder = crate::record::Recorder::start(&cfg, timing.freeze_gap, shared.clone(), opts.ring_writer);
        parts.extend(recorder.as_mut().and_then(crate::record::Recorder::take_thread).map(Subsystem::Thread));
        // The pipeline's thread is stopped first among the threads, as it was started last.
        parts.insert(
            0,
            subsystem::start_pipeline(PipelineCtx {
                pipeline,
                queue,
                shared: shared.clone(),
                publisher: publisher.clone(),
                serial_tx: serial_tx.clone(),
                output_period_s: timing.output_period.as_secs_f64(),
                max_frames: opts.max_frames,
                series,
                watchdog: if cfg.service.systemd_notify { sd_notify::watchdog_enabled() } else { None },
                finished: finished_tx,
                recorder,
            })?,
        );
        let mut tasks = vec![subsystem::start_keepalive(timing.output_period, &shared, &publisher, serial_tx.clone())];
        tasks.extend(subsystem::start_live_view(timing.live_view, &shared, &bank));
        tasks.append(&mut parts);
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
            http_addrs,
            parts: tasks,
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

    /// SIGHUP: reads the calibration file again and hands a good one to the running pipeline
    /// ([`crate::calibration::live::reload`]); a bad one is refused, logged, and the calibration in
    /// use keeps running.
    pub fn on_hangup(&self) {
        let _ = crate::calibration::live::reload(&self.shared, "SIGHUP: not stopping; calibration reload");
    }

    /// The bound Modbus TCP server address (useful with port 0).
    pub fn modbus_addr(&self) -> Option<SocketAddr> {
        self.modbus_addr
    }

    /// The bound address of the Prometheus endpoint (`output.metrics.listen`), if it serves.
    pub fn metrics_addr(&self) -> Option<SocketAddr> {
        self.http_addrs.1
    }

    /// The bound address of the web pages (`web.listen`), if they serve.
    pub fn web_addr(&self) -> Option<SocketAddr> {
        self.http_addrs.0
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
        self.serial_tx = None;
        // Threads notice `stopping` within ~100 ms; a camera blocked in the driver is not waited for.
        let deadline = Instant::now() + Duration::from_millis(400);
        for part in self.parts.drain(..) {
            part.stop(deadline).await;
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
