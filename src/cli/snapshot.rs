//! `fme snapshot`: one snapshot from the command line when the daemon is not running: reads frames
//! from the configured source, runs the pipeline on them so tracks exist, and writes the last frame
//! with overlays (JPEG) and the metric depth map (colour PNG) into `<state>/snapshots/`.
//! docs/recording.md.

use crate::capture::CaptureError;
use crate::cli::{ConfigArgs, UsageError};
use std::path::PathBuf;

/// Arguments of `fme snapshot`.
#[derive(Debug, clap::Args)]
pub struct SnapshotArgs {
    /// The configuration.
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Frame source (`--set source.path=...`): a V4L2 device, a recording, or an IP camera's
    /// `rtsp://` or `http://` (MJPEG) URL (`--set source.kind=... --set source.url=...`).
    #[arg(long)]
    pub source: Option<PathBuf>,
    /// Frames run through the pipeline before the snapshot (so tracks, a depth fit and an activity
    /// value exist: the mean needs about a second of tracking).
    #[arg(long, default_value_t = 90)]
    pub frames: u32,
    /// Write into this folder instead of `<state directory>/snapshots/`.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs `fme snapshot`; prints the JPEG's path. Exit 2 for bad inputs (config, source, no folder).
pub fn run(args: SnapshotArgs) -> anyhow::Result<()> {
    let mut sugar = vec![crate::cli::set_value("source.realtime", false), crate::cli::set_value("source.loop", false)];
    if let Some(p) = &args.source {
        sugar.extend(crate::cli::source_sets(p));
    }
    let (cfg, _) = args.config.load(&sugar)?;
    let dir = match (&args.out, crate::status::state_dir(&cfg)) {
        (Some(d), _) => d.clone(),
        (None, Some(s)) => s.join("snapshots"),
        (None, None) => {
            return Err(UsageError(
                "no state directory: set service.state_dir (--set service.state_dir=DIR) or give --out DIR".into(),
            )
            .into());
        }
    };
    if args.frames == 0 {
        return Err(UsageError("--frames: must be >= 1".into()).into());
    }
    // A camera that cannot be opened is the command's error here (the daemon would retry).
    let mut source = if cfg.source.is_camera() {
        let mut cam = crate::capture::camera(&cfg.source).map_err(|e| UsageError(format!("source: {e}")))?;
        cam.reopen().map_err(|e| UsageError(format!("source: {e}")))?;
        cam
    } else {
        crate::cli::run::open_source(&cfg)?
    };
    let mut pipeline = crate::service::build_pipeline(&cfg).map_err(|e| UsageError(e.to_string()))?;
    let mut last = None;
    let mut buf = Vec::new();
    let mut overlays = crate::record::Overlays::default();
    for _ in 0..args.frames {
        match source.next_frame(std::mem::take(&mut buf)) {
            Ok(frame) => {
                let sample = match pipeline.process(&frame) {
                    Ok(o) => {
                        overlays.copy_from(&o);
                        o.sample
                    }
                    Err(e) => {
                        tracing::warn!("frame {}: {e}", frame.seq);
                        overlays.clear();
                        None
                    }
                };
                if let Some((old, _)) = last.replace((frame, sample)) {
                    buf = old.data;
                }
            }
            Err(CaptureError::End) => break,
            Err(e) => return Err(UsageError(format!("source {}: {e}", source.describe())).into()),
        }
    }
    let Some((frame, sample)) = last else {
        return Err(UsageError(format!("source {}: no frame", source.describe())).into());
    };
    let path = crate::record::snapshot_now(
        &dir,
        &cfg.source.name(),
        &frame,
        &overlays,
        &*pipeline,
        sample.as_ref(),
        cfg.record.keep_snapshots,
    )
    .map_err(|e| anyhow::anyhow!("snapshot: {e}"))?;
    crate::cli::write_stdout(&format!("{}\n", path.display()))
}
