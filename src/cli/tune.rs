//! `fme tune`: Grid-search tracker thresholds on sequences with ground truth.

use crate::cli::ConfigArgs;
use crate::cli::UsageError;
use crate::cli::track::{METRICS_HEADER, metrics_line, tracker_config};
use crate::detection::Detection;
use crate::mot::MotMetrics;
use crate::sequence::{Meta, SeqInfo, read_gt, read_world};
use crate::track::TrackerConfig;
use crate::tune::{DetNoise, Grid, GtObs, TuneSequence, evaluate_with, pooled, synth_detections};
use anyhow::Context;
use rayon::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Metric to maximise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum TuneMetric {
    /// Identity F1.
    Idf1,
    /// Multiple-object tracking accuracy.
    Mota,
}

/// Arguments of `fme tune`.
#[derive(Debug, clap::Args)]
pub struct TuneArgs {
    /// Sequence folders (`seqinfo.ini`, `gt/gt.txt`; `gt/world.csv` + `meta.json` add depth).
    #[arg(long, num_args = 1.., required = true)]
    pub sequences: Vec<PathBuf>,
    /// TOML grid `key = [values]`; default: the paper's Table 1 (T_d, T_t, T_unt, T_unc, T_iou in 30-70%).
    #[arg(long)]
    pub grid: Option<PathBuf>,
    /// Metric to maximise (ties broken by the other one).
    #[arg(long, value_enum, default_value = "idf1")]
    pub metric: TuneMetric,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub jobs: Option<usize>,
    /// The configuration: the grid varies its `[tracker]` section.
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Tracker preset the grid varies (`--set tracker.preset=...`).
    #[arg(long, value_parser = super::choice::parser::<crate::track::TrackerPreset>())]
    pub preset: Option<crate::track::TrackerPreset>,
    /// Seed of the synthetic detector noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Probability of missing a fully visible fish.
    #[arg(long, default_value_t = 0.05)]
    pub miss: f64,
    /// Box jitter, fraction of the box size (standard deviation).
    #[arg(long, default_value_t = 0.05)]
    pub jitter: f64,
    /// False positives per frame (mean).
    #[arg(long, default_value_t = 0.5)]
    pub fp_per_frame: f64,
    /// Relative noise (standard deviation) of the depth attached to detections.
    #[arg(long, default_value_t = 0.05)]
    pub depth_noise: f64,
    /// Detect every k-th frame only.
    #[arg(long, default_value_t = 1)]
    pub every: u32,
    /// Ground-truth boxes less visible than this are dropped before scoring.
    #[arg(long, default_value_t = 0.1)]
    pub min_visibility: f64,
    /// Rows of the result table.
    #[arg(long, default_value_t = 10)]
    pub top: usize,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Use real detections instead of synthetic ones: a MOTChallenge file at this path inside each
    /// sequence folder (e.g. `det/det.txt`, as the detector writes it).
    #[arg(long)]
    pub detections: Option<PathBuf>,
}

/// Loads a sequence's ground truth (and true depths when `meta.json` and `gt/world.csv` exist).
pub fn load_sequence(dir: &Path, min_visibility: f64) -> anyhow::Result<TuneSequence> {
    let info = SeqInfo::read(&dir.join("seqinfo.ini"))?;
    let gt = read_gt(&dir.join("gt").join("gt.txt"))?;
    let mut depth: HashMap<(u32, u32), f64> = HashMap::new();
    let (meta_path, world_path) = (dir.join("meta.json"), dir.join("gt").join("world.csv"));
    if meta_path.is_file() && world_path.is_file() {
        let camera = Meta::read(&meta_path)?.camera(&meta_path)?;
        for w in read_world(&world_path)? {
            depth.insert((w.frame, w.id), camera.pose.to_camera(&w.position).depth().get());
        }
    }
    let gt = gt
        .into_iter()
        .filter(|g| g.visibility >= min_visibility)
        .map(|g| GtObs {
            frame: g.frame,
            id: i64::from(g.id),
            bbox: g.bbox,
            visibility: g.visibility,
            depth: depth.get(&(g.frame, g.id)).copied(),
        })
        .collect();
    Ok(TuneSequence {
        name: dir.file_name().map_or_else(|| dir.display().to_string(), |n| n.to_string_lossy().into_owned()),
        fps: info.frame_rate,
        frames: info.seq_length,
        width: f64::from(info.im_width),
        height: f64::from(info.im_height),
        gt,
    })
}

/// Reads `det/det.txt`-style detections (one implementation for `fme tune` and `fme eval`).
pub use crate::sequence::mot_text::read_detections;

fn key(m: &MotMetrics, metric: TuneMetric) -> (f64, f64) {
    match metric {
        TuneMetric::Idf1 => (m.idf1, m.mota),
        TuneMetric::Mota => (m.mota, m.idf1),
    }
}

/// Runs `fme tune`.
pub fn run(args: TuneArgs) -> anyhow::Result<()> {
    let base = tracker_config(&args.config, args.preset)?;
    let grid = read_grid(args.grid.as_deref())?;
    let noise = detector_noise(&args)?;
    let data = load_data(&args, &noise)?;
    let tuning = Tuning { base, grid, every: noise.every, data };
    let results = tuning.search(&args)?;
    let rep = tuning.report(&args, &noise, &results)?;
    super::write_stdout(&rep)?;
    Ok(())
}

/// One sequence and the detections the tracker is run on.
type SequenceData = (TuneSequence, Vec<Vec<Detection>>);

/// A grid point's settings and its pooled metrics.
type GridResult = (Vec<(String, f64)>, MotMetrics);

/// The grid given with `--grid`, or the paper's.
fn read_grid(path: Option<&Path>) -> anyhow::Result<Grid> {
    Ok(match path {
        Some(p) => {
            let text = std::fs::read_to_string(p).with_context(|| format!("reading {}", p.display()))?;
            Grid::from_toml(&text).map_err(|e| UsageError(format!("{}: {e}", p.display())))?
        }
        None => Grid::paper(),
    })
}

/// The synthetic detector's noise from the flags, each checked against its range.
fn detector_noise(args: &TuneArgs) -> anyhow::Result<DetNoise> {
    for (what, v, ok) in [
        ("--miss", args.miss, (0.0..=1.0).contains(&args.miss)),
        ("--jitter", args.jitter, (0.0..=1.0).contains(&args.jitter)),
        ("--fp-per-frame", args.fp_per_frame, (0.0..=100.0).contains(&args.fp_per_frame)),
        ("--depth-noise", args.depth_noise, (0.0..=1.0).contains(&args.depth_noise)),
    ] {
        if !ok {
            return Err(UsageError(format!("{what} {v} is out of range")).into());
        }
    }
    Ok(DetNoise {
        miss: args.miss,
        jitter: args.jitter,
        fp_per_frame: args.fp_per_frame,
        every: args.every.max(1),
        depth_noise: args.depth_noise,
    })
}

/// Each sequence's ground truth with its detections: read from `--detections` or synthesised
/// (seeded per sequence).
fn load_data(args: &TuneArgs, noise: &DetNoise) -> anyhow::Result<Vec<SequenceData>> {
    let mut data = Vec::new();
    for (k, dir) in args.sequences.iter().enumerate() {
        let seq = load_sequence(dir, args.min_visibility).with_context(|| format!("loading {}", dir.display()))?;
        let dets = match &args.detections {
            Some(rel) => read_detections(&dir.join(rel), seq.frames)?,
            None => synth_detections(&seq, noise, args.seed.wrapping_add(k as u64)),
        };
        data.push((seq, dets));
    }
    Ok(data)
}

/// The grid search: the configuration it varies, the grid and the sequences it scores on.
struct Tuning {
    base: TrackerConfig,
    grid: Grid,
    /// Detect every k-th frame only.
    every: u32,
    data: Vec<SequenceData>,
}

impl Tuning {
    /// Metrics of `cfg` pooled over the sequences.
    fn score_with(&self, cfg: TrackerConfig, hota: bool) -> MotMetrics {
        let ms: Vec<MotMetrics> = self.data.iter().map(|(s, d)| evaluate_with(cfg, s, d, self.every, hota)).collect();
        pooled(&ms)
    }

    /// Every valid grid point scored in parallel, best first. Grid points are ranked without HOTA
    /// (it stores every frame); the rows shown get it.
    fn search(&self, args: &TuneArgs) -> anyhow::Result<Vec<GridResult>> {
        let mut pool = rayon::ThreadPoolBuilder::new();
        if let Some(j) = args.jobs {
            pool = pool.num_threads(j.max(1));
        }
        let pool = pool.build().context("starting worker threads")?;
        let grid = &self.grid;
        let bar =
            if args.quiet { indicatif::ProgressBar::hidden() } else { indicatif::ProgressBar::new(grid.len() as u64) };
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} grid points, {elapsed} (eta {eta})")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        let mut results: Vec<GridResult> = pool.install(|| {
            (0..grid.len())
                .into_par_iter()
                .map(|i| {
                    let (cfg, set) = grid.point(i, self.base);
                    let valid = cfg.validate().is_ok();
                    let m = if valid { Some(self.score_with(cfg, false)) } else { None };
                    bar.inc(1);
                    m.map(|m| (set, m))
                })
                .flatten()
                .collect()
        });
        bar.finish_and_clear();
        if results.is_empty() {
            return Err(UsageError("no valid grid point".into()).into());
        }
        results.sort_by(|a, b| {
            key(&b.1, args.metric).partial_cmp(&key(&a.1, args.metric)).unwrap_or(std::cmp::Ordering::Equal)
        });
        Ok(results)
    }

    /// The result table (the top rows rescored with HOTA, then the two presets) and the best
    /// settings as a `[tracker]` section.
    fn report(&self, args: &TuneArgs, noise: &DetNoise, results: &[GridResult]) -> anyhow::Result<String> {
        let score = |cfg: TrackerConfig| self.score_with(cfg, true);
        let frames: u32 = self.data.iter().map(|(s, _)| s.frames).sum();
        use std::fmt::Write as _;
        let mut rep = String::new();
        writeln!(
            rep,
            "fme tune: {} sequences, {frames} frames, {} grid points, metric {:?}, {} (seed {}, miss {}, jitter {}, fp/frame {}, every {})",
            self.data.len(),
            self.grid.len(),
            args.metric,
            match &args.detections {
                Some(p) => format!("detections from <sequence>/{}", p.display()),
                None => "detections from ground truth".into(),
            },
            args.seed,
            noise.miss,
            noise.jitter,
            noise.fp_per_frame,
            noise.every
        )?;
        writeln!(rep, "{:<8} {METRICS_HEADER}  settings", "rank")?;
        for (r, (set, _)) in results.iter().take(args.top).enumerate() {
            let s: Vec<String> = set.iter().map(|(k, v)| format!("{k}={v}")).collect();
            let mut cfg = self.base;
            for (k, v) in set {
                crate::tune::set_key(&mut cfg, k, *v).map_err(UsageError)?;
            }
            writeln!(rep, "{:<8} {}  {}", r + 1, metrics_line(&score(cfg)), s.join(" "))?;
        }
        writeln!(rep, "{:<8} {}  (preset sort)", "sort", metrics_line(&score(TrackerConfig::sort())))?;
        writeln!(rep, "{:<8} {}  (preset default)", "default", metrics_line(&score(TrackerConfig::default_preset())))?;
        let preset = if self.base.preset == crate::track::TrackerPreset::Sort { "sort" } else { "default" };
        writeln!(rep, "# best settings, for the config file:\n[tracker]\npreset = \"{preset}\"")?;
        for (k, v) in &results[0].0 {
            writeln!(rep, "{k} = {v}")?;
        }
        Ok(rep)
    }
}
