//! `fme run`: Run the edge daemon: camera or recording in, PLC and serial out.

use crate::capture::{CaptureError, FrameSource, RecordedSource};
use crate::cli::{ConfigArgs, UsageError, set_text, set_value};
use crate::config::Config;
use crate::service::signals::{SignalEvent, Signals};
use crate::service::{self, Daemon, RunOptions};
use anyhow::Context as _;
use std::path::PathBuf;

/// Arguments of `fme run`. The flags other than `--max-frames` and `--series` are `--set`s.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The configuration.
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Frame source (`--set source.path=...`): a V4L2 device (/dev/videoN), a MOTChallenge
    /// sequence directory, or an IP camera's `rtsp://` or `http://` (MJPEG) URL (`--set
    /// source.kind=... --set source.url=...`).
    #[arg(long)]
    pub source: Option<PathBuf>,
    /// Serve Modbus TCP on HOST:PORT (`--set output.modbus.mode=tcp-server --set
    /// output.modbus.listen=...`).
    #[arg(long)]
    pub modbus_listen: Option<String>,
    /// Recordings: replay as fast as possible (`--set source.realtime=false`); frames then wait for
    /// the pipeline instead of being dropped.
    #[arg(long)]
    pub fast: bool,
    /// Recordings: stop at the end (`--set source.loop=false`).
    #[arg(long)]
    pub no_loop: bool,
    /// Print a live one-line view of the activity index on stderr (`--set service.live_view_s=0.5`).
    #[arg(long)]
    pub live: bool,
    /// Stop after this many processed frames (benchmarks).
    #[arg(long)]
    pub max_frames: Option<u64>,
    /// Write the per-frame series the pipeline computed as CSV
    /// (`frame,t,activity_mps,smoothed_mps,ci95_mps,n_fish,bls,latency_s,too_few_fish,uncalibrated,scale,unlike_fish`).
    #[arg(long, value_name = "FILE.csv")]
    pub series: Option<PathBuf>,
}

impl RunArgs {
    /// The convenience flags as `--set` assignments.
    fn sugar(&self) -> anyhow::Result<Vec<String>> {
        let mut s = Vec::new();
        if let Some(p) = &self.source {
            s.extend(crate::cli::source_sets(p));
        }
        if let Some(l) = &self.modbus_listen {
            if !crate::config::is_host_port(l) {
                return Err(UsageError(format!("--modbus-listen: must be HOST:PORT, got {l:?}")).into());
            }
            s.push(set_text("output.modbus.mode", "tcp-server"));
            s.push(set_text("output.modbus.listen", l));
        }
        if self.fast {
            s.push(set_value("source.realtime", false));
        }
        if self.no_loop {
            s.push(set_value("source.loop", false));
        }
        if self.live {
            s.push(set_value("service.live_view_s", 0.5));
        }
        Ok(s)
    }
}

/// Loads the config with the command-line overrides; errors name the file and line, or the flag.
pub fn effective_config(args: &RunArgs) -> anyhow::Result<(Config, String)> {
    args.config.load(&args.sugar()?)
}

/// Opens the frame source. A missing camera is not fatal (it is retried with backoff and reported
/// in the status registers: cameras enumerate late after power-up); a missing recording is.
pub fn open_source(cfg: &Config) -> anyhow::Result<Box<dyn FrameSource>> {
    let path = &cfg.source.path;
    if cfg.source.is_camera() {
        let mut cam = crate::capture::camera(&cfg.source).map_err(|e| UsageError(format!("source: {e}")))?;
        if let Err(e) = cam.reopen() {
            tracing::error!("camera: {e}; retrying with backoff (status bit 1 clear, fault code 1)");
        }
        return Ok(cam);
    }
    match RecordedSource::open(path, cfg.source.realtime, cfg.source.looping) {
        Ok(s) => Ok(Box::new(s)),
        Err(e @ CaptureError::NotFound { .. }) => Err(UsageError(format!("source.path / --source: {e}")).into()),
        // A recording that cannot be read (no seqinfo.ini, bad frames list) is a start-up input problem.
        Err(e) => Err(UsageError(format!("source.path / --source: {e}")).into()),
    }
}

/// Reads VmRSS and VmHWM (kB) from /proc/self/status.
pub fn memory_kb() -> Option<(u64, u64)> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let get = |k: &str| s.lines().find(|l| l.starts_with(k))?.split_whitespace().nth(1)?.parse::<u64>().ok();
    Some((get("VmRSS:")?, get("VmHWM:")?))
}

/// Runs `fme run`. Exit codes ([`crate::cli::exit_code`]): 2 for a start-up input problem
/// (usage, configuration, source, calibration, model; the message names the file or key), 1 for a
/// runtime fault (port in use, a thread that died, a stop by an unexpected signal: systemd's
/// `Restart=on-failure` restarts fme), 0 for a stop that was asked for (SIGTERM, SIGINT, end of a
/// recording).
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let (cfg, text) = effective_config(&args)?;
    // Before the (slow) source and model loading: a duration no timer holds is a config error (exit 2).
    service::timing::Timing::from_config(&cfg).map_err(|e| UsageError(e.to_string()))?;
    let rt = tokio::runtime::Builder::new_current_thread().enable_all().build().context("tokio runtime")?;
    let opts = RunOptions { max_frames: args.max_frames, series: args.series.clone(), ring_writer: None };
    rt.block_on(async move {
        // First, so that no signal during the (slow) model loading ends the process uncleanly.
        let mut signals = Signals::install().context("installing the signal handlers")?;
        let source = open_source(&cfg)?;
        let pipeline = service::build_pipeline(&cfg).map_err(|e| UsageError(e.to_string()))?;
        let mut daemon = Daemon::start(cfg, text, source, pipeline, opts).await.map_err(|e| match e {
            e @ service::ServiceError::Timing(_) => anyhow::Error::new(UsageError(e.to_string())),
            e => anyhow::Error::new(e),
        })?;
        let (reason, fault) = loop {
            tokio::select! {
                ev = signals.next() => match ev {
                    SignalEvent::Hangup => daemon.on_hangup(),
                    SignalEvent::Stop(name) => break (name, false),
                    SignalEvent::Unexpected(name) => break (name, true),
                },
                ok = daemon.finished() => break if ok { ("end of input", false) } else { ("pipeline thread died", true) },
            }
        };
        if fault {
            daemon.shared().log(tracing::Level::ERROR, format!("{reason}: shutting down (not asked for: exit code 1)"));
        } else {
            tracing::info!("{reason}: shutting down");
        }
        let shared = daemon.shared().clone();
        let t0 = std::time::Instant::now();
        daemon.shutdown().await;
        let h = shared.health();
        let (rss, hwm) = memory_kb().unwrap_or((0, 0));
        eprintln!(
            "\nfme run: {} frames captured, {} processed, {} dropped, {} updates, latency p50 {} ms p99 {} ms max {:.1} ms, rss {} kB (peak {} kB), shutdown {} ms",
            h.frames_captured,
            h.frames_processed,
            h.frames_dropped,
            h.updates,
            h.latency.quantile_ms(0.5).map_or("n/a".into(), |v| format!("{v:.0}")),
            h.latency.quantile_ms(0.99).map_or("n/a".into(), |v| format!("{v:.0}")),
            h.latency.max_ms(),
            rss,
            hwm,
            t0.elapsed().as_millis()
        );
        if fault {
            anyhow::bail!("{reason}: exiting with an error so that the service manager restarts fme");
        }
        Ok::<(), anyhow::Error>(())
    })
}
