//! `fme track`: Run the tracker on MOTChallenge detections.

use crate::cli::{ConfigArgs, UsageError, set_text};
use crate::mot::{MotAccumulator, MotMetrics};
use crate::sequence::mot_text::{self, MotRow, ReadOptions};
use crate::track::{Detection, Tracker, TrackerConfig, TrackerPreset};
use crate::units::Seconds;
use anyhow::Context;
use std::io::Write;
use std::path::PathBuf;

/// Arguments of `fme track`.
#[derive(Debug, clap::Args)]
pub struct TrackArgs {
    /// MOTChallenge detections `frame,-1,x,y,w,h,score,...` (sorted by frame).
    #[arg(long, required_unless_present = "hyp")]
    pub det: Option<PathBuf>,
    /// Where to write the tracks `frame,id,x,y,w,h,score,-1,-1,-1` (stdout when neither `--out`
    /// nor `--gt` is given).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The configuration: its `[tracker]` section is the tracker's.
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Tracker preset (`--set tracker.preset=...`): `sort` (exact SORT) or `default`.
    #[arg(long, value_parser = super::choice::parser::<TrackerPreset>())]
    pub preset: Option<TrackerPreset>,
    /// Frame rate of the detections, frames per second (frame times are `(frame - 1) / fps`).
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Ground truth to score the tracks against (prints MOTA, IDF1, ...).
    #[arg(long)]
    pub gt: Option<PathBuf>,
    /// Score this existing result file against `--gt` instead of tracking.
    #[arg(long, requires = "gt", conflicts_with = "det")]
    pub hyp: Option<PathBuf>,
    /// Print the metrics as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// The tracker settings of the one config, with `--preset` as a `--set`.
pub fn tracker_config(config: &ConfigArgs, preset: Option<TrackerPreset>) -> anyhow::Result<TrackerConfig> {
    let sugar: Vec<String> = preset
        .iter()
        .map(|p| set_text("tracker.preset", if *p == TrackerPreset::Sort { "sort" } else { "default" }))
        .collect();
    Ok(config.load(&sugar)?.0.tracker)
}

/// Runs the tracker over detection rows; returns result rows `(frame, id, box, score)`.
pub fn track_rows(cfg: TrackerConfig, dets: &mut [MotRow], fps: f64) -> anyhow::Result<Vec<MotRow>> {
    let mut tracker = Tracker::new(cfg);
    let mut out = Vec::new();
    let mut frame_dets: Vec<Detection> = Vec::with_capacity(crate::track::MAX_DETS);
    let groups = mot_text::group_by_frame(dets);
    let mut next = 0usize;
    let last = groups.last().map_or(0, |g| g.0);
    let mut frame = 1u32;
    while frame <= last {
        frame_dets.clear();
        if groups.get(next).is_some_and(|g| g.0 == frame) {
            frame_dets.extend(dets[groups[next].1.clone()].iter().map(|r| Detection::new(r.bbox, r.score)));
            next += 1;
        } else if tracker.live_tracks() == 0 && frame > cfg.min_hits.saturating_add(1) {
            // Nothing alive and past SORT's warm-up: empty frames change nothing, jump ahead.
            match groups.get(next) {
                Some(g) => frame = g.0,
                None => break,
            }
            continue;
        }
        // Frames without detections still run (tracks age and get lost, as in SORT's loop).
        let t = Seconds(f64::from(frame - 1) / fps);
        let tracks = tracker.update(t, &frame_dets).with_context(|| format!("frame {frame}"))?;
        out.extend(tracks.iter().map(|o| MotRow::new(frame, i64::from(o.id), o.bbox, o.score)));
        let Some(f) = frame.checked_add(1) else { break };
        frame = f;
    }
    let s = tracker.stats();
    if s.det_overflow + s.track_overflow + s.invalid_dets > 0 {
        tracing::warn!(
            det_overflow = s.det_overflow,
            track_overflow = s.track_overflow,
            invalid = s.invalid_dets,
            "capacity or input problems"
        );
    }
    Ok(out)
}

/// Scores result rows against ground-truth rows (IoU 0.5).
pub fn score(gt: &[MotRow], hyp: &[MotRow]) -> MotMetrics {
    let mut acc = MotAccumulator::new();
    acc.update_rows(gt, hyp);
    acc.metrics()
}

/// One-line table header of [`metrics_line`].
pub const METRICS_HEADER: &str = "  IDF1   MOTA   MOTP  IDSW    FP    FN  MT  ML   Rcll   Prcn   HOTA";

/// The main metrics in one line, percentages (MOTP as motmetrics' mean 1 - IoU).
pub fn metrics_line(m: &MotMetrics) -> String {
    format!(
        "{:6.2} {:6.2} {:6.3} {:5} {:5} {:5} {:3} {:3} {:6.2} {:6.2} {:6.2}",
        m.idf1 * 100.0,
        m.mota * 100.0,
        m.motp,
        m.num_switches,
        m.num_false_positives,
        m.num_misses,
        m.mostly_tracked,
        m.mostly_lost,
        m.recall * 100.0,
        m.precision * 100.0,
        m.hota * 100.0
    )
}

/// A bad input file is a usage problem (exit 2); the message names the file and line.
fn input(e: impl std::fmt::Display) -> UsageError {
    UsageError(e.to_string())
}

/// Runs `fme track`.
pub fn run(args: TrackArgs) -> anyhow::Result<()> {
    if !(args.fps > 0.0 && args.fps.is_finite()) {
        return Err(UsageError(format!("--fps {} must be a positive number", args.fps)).into());
    }
    let result = if let Some(hyp) = &args.hyp {
        mot_text::read_file(hyp, ReadOptions::default()).map_err(input)?
    } else {
        let det = args.det.as_deref().ok_or_else(|| UsageError("--det is required".into()))?;
        let cfg = tracker_config(&args.config, args.preset)?;
        let mut dets = mot_text::read_file(det, ReadOptions { require_sorted: true }).map_err(input)?;
        let rows = track_rows(cfg, &mut dets, args.fps).map_err(|e| UsageError(format!("{}: {e:#}", det.display())))?;
        if let Some(out) = &args.out {
            let f = std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
            let mut w = std::io::BufWriter::new(f);
            for r in &rows {
                mot_text::write_row(&mut w, r, mot_text::RowLayout::Result)
                    .with_context(|| format!("writing {}", out.display()))?;
            }
            w.flush().with_context(|| format!("writing {}", out.display()))?;
        } else if args.gt.is_none() {
            // Neither a file nor a score asked for: the tracks go to stdout.
            let mut text = Vec::new();
            for r in &rows {
                mot_text::write_row(&mut text, r, mot_text::RowLayout::Result)?;
            }
            super::write_stdout(&String::from_utf8_lossy(&text))?;
        }
        rows
    };
    if let Some(gt) = &args.gt {
        let gt = mot_text::read_file(gt, ReadOptions::default()).map_err(input)?;
        let m = score(&gt, &result);
        let text = if args.json {
            format!("{}\n", serde_json::to_string(&m)?)
        } else {
            format!("{METRICS_HEADER}\n{}\n", metrics_line(&m))
        };
        super::write_stdout(&text)?;
    }
    Ok(())
}
