//! `fme synth`: Write a synthetic underwater fish sequence with exact ground truth.

use crate::cli::UsageError;
use crate::synth::{self, Layout, Preset, SynthConfig, WaterType};
use anyhow::Context;
use std::path::PathBuf;

/// Arguments of `fme synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {
    /// Motion preset.
    #[arg(long, value_enum)]
    pub preset: Preset,
    /// Output folder (must be empty or absent unless --force).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of fish (swarm, feeding; at most 200).
    #[arg(long, default_value_t = 20)]
    pub fish: usize,
    /// Frames per sequence.
    #[arg(long, default_value_t = 150)]
    pub frames: u32,
    /// Seed: the same arguments give byte-identical output.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Frame rate.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Image width, pixels.
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 384)]
    pub height: u32,
    /// Jerlov water type.
    #[arg(long, value_enum, ignore_case = true, default_value = "3C")]
    pub water: WaterType,
    /// Reference-cube layout (paper Fig. 7), or `none` for no reference objects.
    #[arg(long, value_enum, ignore_case = true, default_value = "F")]
    pub layout: Layout,
    /// Radial lens distortion k1 (OpenCV convention, negative = barrel; 0 = pinhole).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub k1: f64,
    /// Mean fish length of the cohort, m.
    #[arg(long, default_value_t = crate::synth::motion::MEAN_LENGTH_M)]
    pub fish_length: f64,
    /// Spread of the cohort's lengths: standard deviation over the mean.
    #[arg(long, default_value_t = 0.12)]
    pub fish_length_cv: f64,
    /// Replace an earlier fme output folder.
    #[arg(long)]
    pub force: bool,
}

/// Runs `fme synth`.
pub fn run(args: SynthArgs) -> anyhow::Result<()> {
    let cfg = SynthConfig {
        preset: args.preset,
        fish: args.fish,
        frames: args.frames,
        seed: args.seed,
        fps: args.fps,
        width: args.width,
        height: args.height,
        water: args.water,
        layout: args.layout,
        k1: args.k1,
        cohort: crate::synth::fish::Cohort { mean_length_m: args.fish_length, length_cv: args.fish_length_cv },
    };
    cfg.validate().map_err(|e| UsageError(e.to_string()))?;
    let total = u64::from(cfg.frames) * if cfg.preset == Preset::PostprocSuite { 18 } else { 1 };
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {bar:40} {pos}/{len} frames {per_sec} eta {eta}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let started = std::time::Instant::now();
    let result = synth::generate(&cfg, &args.out, args.force, &|n| bar.inc(n));
    bar.finish_and_clear();
    let summary = match result {
        Err(synth::Error::Config(msg)) => return Err(UsageError(msg).into()),
        r => r.with_context(|| format!("fme synth could not write {}", args.out.display()))?,
    };
    let secs = started.elapsed().as_secs_f64();
    super::write_stdout(&format!(
        "wrote {} sequence(s), {} frames to {} in {:.1} s ({:.1} frames/s)\n",
        summary.sequences.len(),
        summary.frames,
        summary.out.display(),
        secs,
        summary.frames as f64 / secs.max(1e-9)
    ))
}
