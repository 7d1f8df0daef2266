//! `fme eval`: run the daemon's pipeline on a recorded sequence and score it against ground truth.

use super::choice::{self, name};
use super::{ConfigArgs, UsageError, set_text, set_value};
use crate::eval::{
    BoxesChoice, DepthChoice, EvalError, EvalOptions, EvalReport, evaluate, plot, write_series, write_tracks,
};
use crate::metric::{DepthSample, FitMethod};
use crate::motion::{AlongRay, SpeedMethod};
use crate::sequence::Sequence;
use anyhow::Context;
use std::path::PathBuf;

/// Arguments of `fme eval`. Everything about the pipeline comes from the one config (`--config`,
/// `--set`); the convenience flags below are `--set`s and carry no defaults of their own.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {
    /// Sequence folder: MOTChallenge layout (`seqinfo.ini`, `img1/`, `gt/gt.txt`), and fme's
    /// `meta.json` (calibration), `gt/world.csv` (speed truth), `depth/` (depth truth) when present.
    #[arg(long)]
    pub sequence: PathBuf,
    /// The configuration.
    #[command(flatten)]
    pub config: ConfigArgs,
    /// Box source: `model` (the pipeline's detector and tracker), `gt` (gt/gt.txt with its ids),
    /// `tracker` (the tracker on det/det.txt, or on noisy detections made from ground truth), or a
    /// MOTChallenge track FILE.
    #[arg(long, default_value = "gt")]
    pub boxes: BoxesChoice,
    /// Depth source: `model` (the pipeline's depth network and fit), `gt` (depth/ maps),
    /// `relative-gt` (noisy relative inverse depth made from depth/, then the fit).
    #[arg(long, value_enum, default_value_t = DepthChoice::Gt)]
    pub depth: DepthChoice,
    /// Run the networks (or read ground truth) on every frame instead of the configured rates
    /// (`--set detector.rate_hz=0 --set depth.rate_hz=0`).
    #[arg(long)]
    pub every_frame: bool,
    /// The paper's settings: frame-to-frame speed from the depth change, every fish at once, eq. 3
    /// and eq. 4 on (`--set`s of postprocess.box_fluctuation, motion.speed_span_s, motion.min_age_s,
    /// motion.along_ray; other flags still apply).
    #[arg(long)]
    pub paper: bool,
    /// Post-processing (eq. 3 and eq. 4) off (`--set postprocess.box_fluctuation=false --set
    /// postprocess.depth_jump=false`).
    #[arg(long)]
    pub no_postprocess: bool,
    /// The box-fluctuation detector (eq. 3) on (`--set postprocess.box_fluctuation=true`).
    #[arg(long)]
    pub box_fluctuation: bool,
    /// Metric fit (`--set depth.fit=...`).
    #[arg(long, value_parser = choice::parser::<FitMethod>())]
    pub fit: Option<FitMethod>,
    /// How a fish's depth is read (`--set depth.sample=...`).
    #[arg(long, value_parser = choice::parser::<DepthSample>())]
    pub depth_sample: Option<DepthSample>,
    /// Speed span, s (`--set motion.speed_span_s=...`).
    #[arg(long)]
    pub speed_span: Option<f64>,
    /// A fish enters the mean once tracked this long, s (`--set motion.min_age_s=...`).
    #[arg(long)]
    pub min_age: Option<f64>,
    /// Where the speed along the line of sight comes from (`--set motion.along_ray=...`).
    #[arg(long, value_parser = choice::parser::<AlongRay>())]
    pub along_ray: Option<AlongRay>,
    /// Chord or regression over the span (`--set motion.speed_method=...`).
    #[arg(long, value_parser = choice::parser::<SpeedMethod>())]
    pub speed_method: Option<SpeedMethod>,
    /// The detector (`--set detector.model=...`).
    #[arg(long)]
    pub det_model: Option<PathBuf>,
    /// The depth network (`--set depth.model=...`).
    #[arg(long)]
    pub depth_model: Option<PathBuf>,
    /// ONNX Runtime threads of both networks (`--set detector.threads=N --set depth.threads=N`).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Tracker preset (`--set tracker.preset=...`), as `fme track --preset`.
    #[arg(long, value_parser = choice::parser::<crate::track::TrackerPreset>())]
    pub preset: Option<crate::track::TrackerPreset>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Write a PNG of estimated vs true swarm speed over time.
    #[arg(long, value_name = "FILE.png")]
    pub plot: Option<PathBuf>,
    /// Write the per-frame series: the columns of `fme run --series`, then `true_mps` (the truth at
    /// `t - latency`) and `true_now_mps` (at `t`).
    #[arg(long, value_name = "FILE.csv")]
    pub series: Option<PathBuf>,
    /// Write one row per tracked fish and frame (`frame,t,id,u,v,w,h,depth_raw_m,depth_m,speed_mps`:
    /// box centre and size in pixels after eq. 3, depth before and after eq. 4 and the smoothing).
    #[arg(long, value_name = "FILE.csv")]
    pub tracks: Option<PathBuf>,
    /// relative-gt: foul this many reference objects (their relative depth reads 50% nearer).
    #[arg(long, default_value_t = 0)]
    pub foul_refs: usize,
    /// Run without the sequence's calibration (no intrinsics, no references): the box's board default
    /// camera and `depth.scale = "fish"` (docs/pipeline.md, "The fish as the ruler").
    #[arg(long)]
    pub no_calibration: bool,
    /// Hide reference objects from a time on: `N@T` hides the first N from T seconds (as if fouled
    /// over or out of sight; the depth fit no longer sees them).
    #[arg(long, value_name = "N@T")]
    pub hide_refs: Option<String>,
    /// Make the recorded positions of reference objects wrong from a time on: `N@T` moves the first
    /// N from T seconds (each one's depth off by its own factor, 0.7-1.3: moved with the net, or
    /// fouled), so the references' fit goes bad rather than short of references.
    #[arg(long, value_name = "N@T")]
    pub move_refs: Option<String>,
    /// relative-gt: per-pixel multiplicative noise on the inverse depth (standard deviation).
    #[arg(long, default_value_t = 0.01)]
    pub rel_noise: f64,
    /// relative-gt: amplitude of the smooth multiplicative distortion of the inverse depth.
    #[arg(long, default_value_t = 0.03)]
    pub rel_distortion: f64,
}

impl EvalArgs {
    /// The convenience flags as `--set` assignments.
    fn sugar(&self) -> Vec<String> {
        let mut s = Vec::new();
        if self.every_frame {
            s.push(set_value("detector.rate_hz", 0));
            s.push(set_value("depth.rate_hz", 0));
        }
        if self.paper {
            s.push(set_value("postprocess.box_fluctuation", true));
            s.push(set_value("motion.speed_span_s", 0));
            s.push(set_value("motion.min_age_s", 0));
            s.push(set_text("motion.along_ray", "depth"));
        }
        if self.no_postprocess {
            s.push(set_value("postprocess.box_fluctuation", false));
            s.push(set_value("postprocess.depth_jump", false));
        }
        if self.box_fluctuation {
            s.push(set_value("postprocess.box_fluctuation", true));
        }
        if let Some(f) = &self.fit {
            s.push(set_text("depth.fit", &name(f)));
        }
        if let Some(v) = &self.depth_sample {
            s.push(set_text("depth.sample", &name(v)));
        }
        if let Some(v) = self.speed_span {
            s.push(set_value("motion.speed_span_s", v));
        }
        if let Some(v) = self.min_age {
            s.push(set_value("motion.min_age_s", v));
        }
        if let Some(v) = &self.along_ray {
            s.push(set_text("motion.along_ray", &name(v)));
        }
        if let Some(v) = &self.speed_method {
            s.push(set_text("motion.speed_method", &name(v)));
        }
        if let Some(p) = &self.det_model {
            s.push(set_text("detector.model", &p.to_string_lossy()));
        }
        if let Some(p) = &self.depth_model {
            s.push(set_text("depth.model", &p.to_string_lossy()));
        }
        if let Some(n) = self.threads {
            s.push(set_value("detector.threads", n));
            s.push(set_value("depth.threads", n));
        }
        if let Some(v) = &self.preset {
            s.push(set_text("tracker.preset", &name(v)));
        }
        s
    }
}

/// The human-readable report, one line per measure.
fn table(r: &EvalReport) -> String {
    let mut lines: Vec<String> = Vec::new();
    let opt = |v: Option<f64>, p: usize| v.map_or("-".to_string(), |x| format!("{x:.p$}"));
    lines.push(format!("sequence          {}", r.sequence));
    lines.push(format!(
        "input             boxes {}, depth {:?}{}, post-processing {}, detector {} Hz, depth {} Hz",
        r.boxes,
        r.depth,
        r.fit.map_or(String::new(), |f| format!(", fit {f:?}")),
        if r.postprocess { "on" } else { "off" },
        rate(r.rates_hz[0]),
        rate(r.rates_hz[1]),
    ));
    lines.push(format!(
        "activity          {:.4} m/s  {:.3} BL/s  (mean over {} frames with an estimate; scale from {})",
        r.mean_activity_mps, r.mean_activity_bls, r.activity_frames, r.scale_source
    ));
    if r.frames > 0 {
        lines.push(format!("frames scored     {} (mean {:.1} fish)", r.frames, r.mean_fish));
        lines.push(format!(
            "speed RMSE m/s    {:.4} (truth at t - {:.2} s latency), {:.4} (truth at t)",
            r.speed_rmse_mps, r.latency_s, r.speed_rmse_now_mps
        ));
        lines.push(format!("DistCorr          {:.4}", r.speed_distcorr));
        lines.push(format!(
            "error 95% m/s     [{:.4}, {:.4}]  bias {:.4}",
            r.error_ci95_mps[0], r.error_ci95_mps[1], r.speed_bias_mps
        ));
        lines.push(format!("mean speed m/s    true {:.4}  estimated {:.4}", r.mean_true_mps, r.mean_est_mps));
    }
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
    if let Some(c) = r.depth_consistency {
        lines.push(format!(
            "depth consistency {c:+.3}  (Spearman, inverse depth vs box length, mean of {} frames)",
            r.depth_consistency_frames
        ));
    }
    lines.push(format!("corrections       {} boxes (eq. 3), {} depths (eq. 4)", r.boxes_corrected, r.depths_corrected));
    lines.push(format!("pipeline CPU      {:.2} ms per frame", r.cpu_ms_per_frame));
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
    for a in &r.absent {
        lines.push(format!("not scored        {a}"));
    }
    lines.push(String::new());
    lines.join("\n")
}

fn rate(hz: f64) -> String {
    if hz > 0.0 { format!("{hz}") } else { "every frame".into() }
}

/// Parses `N@T` of `--hide-refs` and `--move-refs`; the error names the option.
fn parse_refs_at(option: &str, text: Option<&String>) -> Result<Option<(usize, f64)>, UsageError> {
    let Some(text) = text else { return Ok(None) };
    let parsed = text.split_once('@').and_then(|(n, t)| {
        let (n, t) = (n.trim().parse().ok()?, t.trim().parse::<f64>().ok()?);
        (t.is_finite() && t >= 0.0).then_some((n, t))
    });
    parsed
        .map(Some)
        .ok_or_else(|| UsageError(format!("{option} {text:?}: expected N@T (e.g. 8@5: eight references from 5 s)")))
}

/// Runs `fme eval`.
pub fn run(args: EvalArgs) -> anyhow::Result<()> {
    if !(args.rel_noise.is_finite() && args.rel_noise >= 0.0 && args.rel_distortion.is_finite()) {
        return Err(UsageError("--rel-noise must be >= 0 and --rel-distortion finite".into()).into());
    }
    let (cfg, _) = args.config.load(&args.sugar())?;
    let seq = Sequence::open(&args.sequence)
        .map_err(|e| UsageError(format!("opening sequence {}: {e}", args.sequence.display())))?;
    let mut opts = EvalOptions {
        boxes: args.boxes.clone(),
        depth: args.depth,
        foul_refs: args.foul_refs,
        track_rows: args.tracks.is_some(),
        no_calibration: args.no_calibration,
        hide_refs: parse_refs_at("--hide-refs", args.hide_refs.as_ref())?,
        move_refs: parse_refs_at("--move-refs", args.move_refs.as_ref())?,
        ..Default::default()
    };
    opts.relative.pixel_noise = args.rel_noise;
    opts.relative.low_freq = args.rel_distortion;
    opts.relative.seed = seq.meta.as_ref().map_or(0, |m| m.seed) ^ 0x5eed;
    let outputs: Vec<&PathBuf> = [&args.tracks, &args.series, &args.plot].into_iter().flatten().collect();
    let created = open_outputs(&outputs)?;
    // Bad inputs (sequence, box file, model, calibration) are usage problems: exit 2.
    let report = evaluate(&seq, &cfg, &opts).inspect_err(|_| remove_all(&created)).map_err(|e| match e {
        EvalError::Output { .. } => anyhow::Error::new(e),
        other => anyhow::Error::new(UsageError(other.to_string())),
    })?;
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
