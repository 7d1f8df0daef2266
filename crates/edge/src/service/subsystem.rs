//! The daemon's parts, each started as a [`Subsystem`] handle that `Daemon::shutdown` ends with
//! [`Subsystem::stop`]. Threads watch `Shared::stopping` (or their channel closing) and end by
//! themselves; tasks are aborted.

use super::ServiceError;
use super::capture_loop::{SizeLimit, capture_thread};
use super::pipeline_loop::{PipelineCtx, pipeline_loop};
use super::publish::{Publish, Publisher, publish_and_send};
use crate::capture::{Backoff, FrameQueue, FrameSource};
use crate::config::Config;
use crate::output::bank::RegisterBank;
use crate::sequence::{SeriesRow, SeriesWriter};
use crate::status::Shared;
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tracing::Level;

/// One running part of the daemon.
#[derive(Debug)]
pub enum Subsystem {
    /// A thread that ends by itself once the daemon stops.
    Thread(std::thread::JoinHandle<()>),
    /// A tokio task that runs until stopped.
    Task(tokio::task::JoinHandle<()>),
}

impl Subsystem {
    /// Spawns `f` on a thread named `fme-<name>`; `what` names it in the error.
    pub fn spawn(name: &str, what: &'static str, f: impl FnOnce() + Send + 'static) -> Result<Self, ServiceError> {
        std::thread::Builder::new()
            .name(format!("fme-{name}"))
            .spawn(f)
            .map(Self::Thread)
            .map_err(|error| ServiceError::Spawn { what, error })
    }

    /// Ends it: a task is aborted; a thread is given until `deadline` to notice the stop and joined
    /// when it has ended (a camera blocked in its driver is not waited for).
    pub async fn stop(self, deadline: Instant) {
        match self {
            Self::Task(t) => t.abort(),
            Self::Thread(t) => {
                while Instant::now() < deadline && !t.is_finished() {
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
                if t.is_finished() {
                    let _ = t.join();
                }
            }
        }
    }
}

/// The history writer (`[history]`), when a directory resolves; the publisher feeds it.
pub(super) fn start_history(
    cfg: &Config,
    shared: &Arc<Shared>,
    publisher: &Mutex<Publisher>,
) -> Result<Option<Subsystem>, ServiceError> {
    let Some(dir) = super::history_dir(cfg) else { return Ok(None) };
    let h = &cfg.history;
    let (tx, thread) = crate::history::spawn(dir.clone(), h.keep_days, h.fsync_s, shared.clone())
        .map_err(|error| ServiceError::Spawn { what: "history", error })?;
    publisher.lock().unwrap_or_else(|p| p.into_inner()).set_history(Some(tx));
    shared.log(Level::INFO, format!("history: one row per update in {}", dir.display()));
    Ok(Some(Subsystem::Thread(thread)))
}

/// The MQTT client (`[output.mqtt]`), when enabled; the publisher feeds it.
pub(super) fn start_mqtt(
    cfg: &Config,
    shared: &Arc<Shared>,
    publisher: &Mutex<Publisher>,
) -> Result<Option<Subsystem>, ServiceError> {
    if !cfg.output.mqtt.enabled {
        return Ok(None);
    }
    let (tx, thread) =
        crate::output::mqtt::spawn(cfg, shared.clone()).map_err(|error| ServiceError::Spawn { what: "mqtt", error })?;
    publisher.lock().unwrap_or_else(|p| p.into_inner()).set_mqtt(Some(tx));
    Ok(Some(Subsystem::Thread(thread)))
}

/// The field console (`[console]`), when enabled.
pub(super) fn start_console(
    cfg: &Config,
    shared: &Arc<Shared>,
    bank: &Arc<RegisterBank>,
) -> Result<Option<Subsystem>, ServiceError> {
    if !cfg.console.enabled {
        return Ok(None);
    }
    let (dev, baud, echo, sh, bk) =
        (cfg.console.device.clone(), cfg.console.baud, cfg.console.echo, shared.clone(), bank.clone());
    Subsystem::spawn("console", "console", move || crate::console::run_on_device(&dev, baud, echo, &sh, &bk)).map(Some)
}

/// The capture thread feeding a new frame queue (`[source]`).
pub(super) fn start_capture(
    cfg: &Config,
    source: Box<dyn FrameSource>,
    shared: &Arc<Shared>,
) -> Result<(Arc<FrameQueue>, Subsystem), ServiceError> {
    let queue = Arc::new(FrameQueue::new(cfg.source.queue_frames));
    let backoff = Backoff::new(
        Duration::from_millis(cfg.source.reconnect_min_ms),
        Duration::from_millis(cfg.source.reconnect_max_ms),
    );
    let (q, sh) = (queue.clone(), shared.clone());
    let size = SizeLimit { max_pixels: cfg.source.max_pixels, configured: (cfg.source.width, cfg.source.height) };
    let thread = Subsystem::spawn("capture", "capture", move || capture_thread(source, q, sh, backoff, size))?;
    Ok((queue, thread))
}

/// `--series`: a writer thread with a bounded queue, so the pipeline never waits on the disk.
pub(super) fn start_series(
    file: Option<SeriesWriter>,
    shared: &Arc<Shared>,
) -> Result<(Option<SyncSender<SeriesRow>>, Option<Subsystem>), ServiceError> {
    let Some(mut w) = file else { return Ok((None, None)) };
    let (tx, rx) = std::sync::mpsc::sync_channel::<SeriesRow>(4096);
    let sh = shared.clone();
    let thread = Subsystem::spawn("series", "series writer", move || {
        let result = rx.iter().try_for_each(|row| w.write(&row)).and_then(|()| w.finish());
        if let Err(e) = result {
            sh.log(Level::ERROR, format!("--series: {e}; no more rows are written"));
        }
    })?;
    Ok((Some(tx), Some(thread)))
}

/// The pipeline thread.
pub(super) fn start_pipeline(ctx: PipelineCtx) -> Result<Subsystem, ServiceError> {
    Subsystem::spawn("pipeline", "pipeline", move || pipeline_loop(ctx))
}

/// Keepalive: with no samples (camera down, pipeline failing) the registers still update, so the
/// PLC sees the heartbeat, the stale bit and the fault code.
pub(super) fn start_keepalive(
    period: Duration,
    shared: &Arc<Shared>,
    publisher: &Arc<Mutex<Publisher>>,
    serial_tx: Option<SyncSender<String>>,
) -> Subsystem {
    let (sh, pb) = (shared.clone(), publisher.clone());
    Subsystem::Task(tokio::spawn(async move {
        let mut tick = tokio::time::interval(period / 2);
        loop {
            tick.tick().await;
            if sh.stopping() {
                return;
            }
            publish_and_send(&pb, &sh, serial_tx.as_ref(), Publish::IfQuietFor(period + period / 2));
        }
    }))
}

/// The live one-line view on stderr (`service.live_view_s`), when on.
pub(super) fn start_live_view(
    every: Option<Duration>,
    shared: &Arc<Shared>,
    bank: &Arc<RegisterBank>,
) -> Option<Subsystem> {
    let every = every?;
    let (sh, bk) = (shared.clone(), bank.clone());
    Some(Subsystem::Task(tokio::spawn(async move {
        let mut tick = tokio::time::interval(every);
        loop {
            tick.tick().await;
            if sh.stopping() {
                return;
            }
            eprint!("\r{}   ", crate::console::activity_line(&sh, &bk));
        }
    })))
}
