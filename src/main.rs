//! The `fme` binary: a thin command-line layer over the `fme` library.

use clap::{Parser, Subcommand};
use fme::cli;
use std::process::ExitCode;

#[derive(Debug, Parser)]
#[command(name = "fme", version = fme::infer::backend::VERSION, about = "Fish motion estimation: activity index for fish-farm PLCs")]
struct Cli {
    /// Log filter (tracing env-filter syntax), e.g. `info`, `fme=debug`. RUST_LOG overrides it.
    #[arg(long, global = true, default_value = "info")]
    log: String,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Write a synthetic underwater fish sequence with exact ground truth.
    Synth(cli::synth::SynthArgs),
    /// Run the daemon's pipeline on a recorded sequence and score it against ground truth.
    Eval(cli::eval::EvalArgs),
    /// Run the tracker on MOTChallenge detections.
    Track(cli::track::TrackArgs),
    /// Grid-search tracker thresholds on sequences with ground truth.
    Tune(cli::tune::TuneArgs),
    /// Run the edge daemon: camera or recording in, PLC and serial out.
    Run(cli::run::RunArgs),
    /// Write one snapshot (frame with overlays + metric depth map) from the configured source.
    Snapshot(cli::snapshot::SnapshotArgs),
    /// Check a configuration file or show the effective configuration.
    Config(cli::config::ConfigCmdArgs),
    /// Solve the camera calibration from measured reference objects, or check it (--check).
    Calibrate(cli::calibrate::CalibrateArgs),
    /// Summarise and plot one day of the activity history (docs/history.md).
    Report(cli::report::ReportArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(&cli.log))
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    // No colour codes when stderr is not a terminal (journald, pipes).
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    tracing_subscriber::fmt().with_env_filter(filter).with_ansi(ansi).with_writer(std::io::stderr).init();
    fme::output::log_throttle::throttle_panic_messages(std::time::Duration::from_secs(10));
    let result = match cli.command {
        Command::Synth(a) => cli::synth::run(a),
        Command::Eval(a) => cli::eval::run(a),
        Command::Track(a) => cli::track::run(a),
        Command::Tune(a) => cli::tune::run(a),
        Command::Run(a) => cli::run::run(a),
        Command::Snapshot(a) => cli::snapshot::run(a),
        Command::Config(a) => cli::config::run(a),
        Command::Calibrate(a) => cli::calibrate::run(a),
        Command::Report(a) => cli::report::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            ExitCode::from(cli::exit_code(&err))
        }
    }
}
