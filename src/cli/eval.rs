//! `fme eval`: Run the estimator on a sequence and score it against ground truth.

use crate::eval::{
    BoxesChoice, DepthChoice, DepthSample, EvalOptions, EvalReport, FitChoice, evaluate, plot, write_series,
    write_tracks,
};
use crate::motion::{AlongRay, SpeedMethod};
use crate::postprocess::{BoxAnchor, PostprocessConfig};
use crate::sequence::Sequence;
use crate::units::MetresPerSecond;
use crate::units::Seconds;
use anyhow::Context;
use std::path::PathBuf;

/// Arguments of `fme eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Sequence folder (MOTChallenge layout plus `gt/world.csv`, `depth/`, `meta.json`).
    #[arg(long)]
    pub sequence: PathBuf,
    /// Box source: `gt` (gt/gt.txt with its ids), `tracker`, `model`, or a MOTChallenge track FILE.
    #[arg(long, default_value = "gt")]
    pub boxes: BoxesChoice,
    /// Depth source: `gt` (depth/ maps), `relative-gt` (noisy relative inverse depth + metric fit), `model`.
    #[arg(long, value_enum, default_value_t = DepthChoice::Gt)]
    pub depth: DepthChoice,
    /// Metric fit of relative inverse depth (eq. 1-2 and the paper's Table 4 regressors).
    #[arg(long, value_enum, default_value_t = FitChoice::Linear)]
    pub fit: FitChoice,
    /// Turn post-processing (eq. 3 and eq. 4) off.
    #[arg(long)]
    pub no_postprocess: bool,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write a PNG of estimated vs true swarm speed over time.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// Write the per-frame series (`frame,t,true_mps,est_mps,n_fish`) as CSV.
    #[arg(long, value_name = "FILE.csv")]
    pub series: Option<PathBuf>,
    /// Write one row per tracked fish and frame (`frame,t,id,u,v,w,h,depth_raw_m,depth_m,speed_mps`:
    /// box centre and size in pixels after eq. 3, depth before and after eq. 4 and the smoothing) as
    /// CSV, for diagnosing the speed error fish by fish.
    #[arg(long, value_name = "FILE.csv")]
    pub tracks: Option<PathBuf>,
    /// Speed span in seconds (0 = frame to frame, the paper's choice; default 1).
    #[arg(long)]
    pub speed_span: Option<f64>,
    /// A fish enters the swarm mean once it has been tracked this many seconds (0 = at once, as the
    /// paper; default 1, `--paper` 0).
    #[arg(long)]
    pub min_age: Option<f64>,
    /// The paper's settings: frame-to-frame speed from the depth change, every fish at once, eq. 3 and eq. 4
    /// on (other flags still apply).
    #[arg(long)]
    pub paper: bool,
    /// Turn the box-fluctuation detector (eq. 3) on (off by default: it raised the RMSE in our measurements).
    #[arg(long, conflicts_with = "no_box_fluctuation")]
    pub box_fluctuation: bool,
    /// How a fish's depth is read: `centre` (5x5 median at the box centre, the paper), `box` (near
    /// quarter of the central half of the box) or `visible` (as `box`, minus where other fish's boxes
    /// cover it; no depth for a fish hidden that way). Default: `visible` with `--depth model`, else `centre`.
    #[arg(long, value_enum)]
    pub depth_sample: Option<DepthSample>,
    /// Speed from the chord over the span (the paper, with span 0) or a least-squares regression.
    #[arg(long, value_enum, default_value_t = SpeedMethod::Chord)]
    pub speed_method: SpeedMethod,
    /// Where each fish's speed along the line of sight comes from: `heading` (its speed across the
    /// image over the box's foreshortening: fish swim head first) or `depth` (the change of its depth,
    /// the paper). Default `heading`, `depth` with `--paper`.
    #[arg(long, value_enum)]
    pub along_ray: Option<AlongRay>,
    /// Per-fish speeds above this (m/s) are glitches left out of the mean.
    #[arg(long, default_value_t = 10.0)]
    pub max_speed: f64,
    /// Turn only the box-fluctuation detector (eq. 3) off.
    #[arg(long)]
    pub no_box_fluctuation: bool,
    /// Turn only the depth-jump detector (eq. 4) off.
    #[arg(long)]
    pub no_depth_jump: bool,
    /// What stays put when eq. 3 replaces a box dimension.
    #[arg(long, value_enum, default_value_t = BoxAnchor::LeastMoved)]
    pub box_anchor: BoxAnchor,
    /// relative-gt: foul this many reference objects (their relative depth reads 50% nearer).
    #[arg(long, default_value_t = 0)]
    pub foul_refs: usize,
    /// relative-gt: per-pixel multiplicative noise on the inverse depth (standard deviation).
    #[arg(long, default_value_t = 0.01)]
    pub rel_noise: f64,
    /// relative-gt: amplitude of the smooth multiplicative distortion of the inverse depth.
    #[arg(long, default_value_t = 0.03)]
    pub rel_distortion: f64,
    /// `--boxes model`: the detector (YOLO-layout ONNX).
    #[arg(long, default_value = "models/fish_det_int8.onnx")]
    pub det_model: PathBuf,
    /// `--boxes model`: minimum detection confidence, 0..1.
    #[arg(long, default_value_t = 0.3)]
    pub det_conf: f32,
    /// `--depth model`: the relative-depth network (MiDaS-layout ONNX, ImageNet normalisation).
    #[arg(long, default_value = "models/fish_depth_int8.onnx")]
    pub depth_model: PathBuf,
    /// `--depth model`: also run the depth network on the mirrored frame and average the maps.
    #[arg(long)]
    pub depth_flip: bool,
    /// ONNX Runtime intra-op threads.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// `--boxes tracker|model`: tracker preset (`default` or `sort`).
    #[arg(long, default_value = "default")]
    pub tracker: String,
    /// Time constant (s) of the per-track depth smoothing after eq. 4 (0 = off; default: 1 s with
    /// `--depth model`, off otherwise).
    #[arg(long)]
    pub depth_smoothing: Option<f64>,
    /// `--boxes tracker|model`: tracker keys over the preset (TOML, as `fme track --config`).
    #[arg(long, value_name = "FILE")]
    pub tracker_config: Option<PathBuf>,
}

/// The human-readable report, one line per measure.
fn table(r: &EvalReport) -> String {
    let mut lines: Vec<String> = Vec::new();
    let opt = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |x| format!("{x:.p$}"));
    lines.push(format!("sequence          {}", r.sequence));
    lines.push(format!(
        "input             boxes {}, depth {:?}{}, post-processing {}",
        r.boxes,
        r.depth,
        r.fit.map_or(String::new(), |f| format!(", fit {f:?}")),
        if r.postprocess { "on" } else { "off" }
    ));
    lines.push(format!("frames scored     {} (mean {:.1} fish)", r.frames, r.mean_fish));
    lines.push(format!("                  {:>10} {:>10}", "fme", "no-postp"));
    lines.push(format!("speed RMSE m/s    {:>10.4} {:>10.4}", r.speed_rmse_mps, r.speed_rmse_raw_mps));
    lines.push(format!("DistCorr          {:>10.4} {:>10.4}", r.speed_distcorr, r.speed_distcorr_raw));
    lines.push(format!(
        "error 95% m/s     [{:.4}, {:.4}]  bias {:.4}",
        r.error_ci95_mps[0], r.error_ci95_mps[1], r.speed_bias_mps
    ));
    lines.push(format!("mean speed m/s    true {:.4}  estimated {:.4}", r.mean_true_mps, r.mean_est_mps));
    if r.depth_rmse_m.is_some() {
        lines.push(format!(
            "depth at fish     RMSE {} m  d<1.25 {}  d<1.25^2 {}  fit residual {} m, {} failed fits, {} refs visible, {} rejections",
            opt(r.depth_rmse_m, 3),
            opt(r.depth_delta_1_25, 3),
            opt(r.depth_delta_1_25_2, 3),
            opt(r.fit_residual_m, 3),
            r.fit_failures,
            r.references_visible,
            r.references_rejected
        ));
    }
    if r.depth_body_rmse_m.is_some() {
        lines.push(format!(
            "depth at body     RMSE {} m  d<1.25 {}  for {} of the fish (against each body centre, gt/world.csv)",
            opt(r.depth_body_rmse_m, 3),
            opt(r.depth_body_delta_1_25, 3),
            r.depth_body_coverage.map_or("-".to_string(), |c| format!("{:.0}%", 100.0 * c))
        ));
    }
    lines.push(format!("corrections       {} boxes (eq. 3), {} depths (eq. 4)", r.boxes_corrected, r.depths_corrected));
    if let Some(d) = &r.detection {
        lines.push(format!(
            "detection         precision {:.3}  recall {:.3}  (IoU 0.5; {} TP, {} FP, {} FN)",
            d.precision, d.recall, d.tp, d.fp, d.fn_
        ));
    }
    if let Some(m) = &r.mot {
        lines.push(format!(
            "tracking          IDF1 {:.2}%  MOTA {:.2}%  MOTP {:.3}  HOTA {:.2}%  {} ID switches, {} FP, {} misses",
            100.0 * m.idf1,
            100.0 * m.mota,
            m.motp,
            100.0 * m.hota,
            m.id_switches,
            m.false_positives,
            m.misses
        ));
    }
    lines.push(String::new());
    lines.join("\n")
}

/// Runs `fme eval`.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    if let Some(span) = args.speed_span.filter(|s| !(s.is_finite() && *s >= 0.0)) {
        return Err(super::UsageError(format!("--speed-span must be >= 0 seconds, got {span}")).into());
    }
    if !(args.rel_noise.is_finite() && args.rel_noise >= 0.0 && args.rel_distortion.is_finite()) {
        return Err(super::UsageError("--rel-noise must be >= 0 and --rel-distortion finite".into()).into());
    }
    if !(0.0..=1.0).contains(&args.det_conf) {
        return Err(super::UsageError(format!("--det-conf must be within 0..1, got {}", args.det_conf)).into());
    }
    let tracker = super::track::load_config(&args.tracker, args.tracker_config.as_deref())
        .context("--tracker / --tracker-config")?;
    let seq =
        Sequence::open(&args.sequence).with_context(|| format!("opening sequence {}", args.sequence.display()))?;
    let mut opts = EvalOptions {
        boxes: args.boxes.clone(),
        depth: args.depth,
        fit: args.fit,
        postprocess: match (args.no_postprocess, args.paper) {
            (true, _) => PostprocessConfig::off(),
            (false, true) => PostprocessConfig::paper(),
            (false, false) => PostprocessConfig::default(),
        },
        foul_refs: args.foul_refs,
        depth_sample: args.depth_sample.unwrap_or(if args.depth == DepthChoice::Model {
            DepthSample::Visible
        } else {
            DepthSample::Centre
        }),
        threads: args.threads,
        tracker,
        ..Default::default()
    };
    opts.detector.model = crate::infer::runtime::resolve_model(&args.det_model);
    opts.detector.conf_threshold = args.det_conf;
    opts.depth_model.model = crate::infer::runtime::resolve_model(&args.depth_model);
    opts.depth_model.flip = args.depth_flip;
    if args.paper {
        opts.motion.speed_span = Seconds(0.0);
        opts.motion.min_age = Seconds(0.0);
    }
    if let Some(span) = args.speed_span {
        opts.motion.speed_span = Seconds(span);
    }
    if let Some(a) = args.min_age {
        opts.motion.min_age = Seconds(a);
    }
    opts.motion.speed_method = args.speed_method;
    opts.motion.along_ray = args.along_ray.unwrap_or(if args.paper { AlongRay::Depth } else { opts.motion.along_ray });
    opts.motion.max_speed = MetresPerSecond(args.max_speed);
    opts.postprocess.box_anchor = args.box_anchor;
    opts.postprocess.box_fluctuation =
        (opts.postprocess.box_fluctuation || args.box_fluctuation) && !args.no_box_fluctuation && !args.no_postprocess;
    opts.postprocess.depth_jump &= !args.no_depth_jump;
    let default_smoothing =
        if args.depth == DepthChoice::Model { crate::postprocess::ESTIMATED_DEPTH_SMOOTHING.0 } else { 0.0 };
    let smoothing = args.depth_smoothing.unwrap_or(default_smoothing);
    if !(smoothing.is_finite() && smoothing >= 0.0) {
        return Err(super::UsageError(format!("--depth-smoothing must be >= 0 seconds, got {smoothing}")).into());
    }
    opts.postprocess.depth_smoothing = Seconds(smoothing);
    opts.motion.validate().map_err(|e| super::UsageError(e.into()))?;
    opts.relative.pixel_noise = args.rel_noise;
    opts.relative.low_freq = args.rel_distortion;
    opts.relative.seed = seq.meta.seed ^ 0x5eed;
    opts.track_rows = args.tracks.is_some();
    let outputs: Vec<&PathBuf> = [&args.tracks, &args.series, &args.plot].into_iter().flatten().collect();
    let created = open_outputs(&outputs)?;
    let report = evaluate(&seq, &opts).inspect_err(|_| remove_all(&created))?;
    if let Some(p) = &args.tracks {
        write_tracks(p, &report.tracks)?;
    }
    if let Some(p) = &args.series {
        write_series(p, &report.series)?;
    }
    if let Some(p) = &args.plot {
        plot::plot_series(p, &report)?;
    }
    // A closed pipe (`fme eval ... | head`) is not an error (`write_stdout`).
    let text = if args.json { format!("{}\n", serde_json::to_string(&report)?) } else { table(&report) };
    super::write_stdout(&text)?;
    Ok(())
}

/// Opens every output before the evaluation, so a path that cannot be written fails now rather than
/// after minutes of work. Existing files are opened without truncation (an evaluation that then
/// fails leaves them as they were); returns the files this created, for [`remove_all`] on failure.
fn open_outputs(paths: &[&PathBuf]) -> anyhow::Result<Vec<PathBuf>> {
    let mut created = Vec::new();
    for p in paths {
        let existed = p.exists();
        if let Err(e) = std::fs::OpenOptions::new().append(true).create(true).open(p) {
            remove_all(&created);
            return Err(e).with_context(|| format!("{}: cannot create this output", p.display()));
        }
        if !existed {
            created.push(p.to_path_buf());
        }
    }
    Ok(created)
}

/// Removes the outputs [`open_outputs`] created (the evaluation failed; nothing was written to them).
fn remove_all(created: &[PathBuf]) {
    for p in created {
        let _ = std::fs::remove_file(p);
    }
}
