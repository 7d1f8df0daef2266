//! `fme track`: Run the tracker on MOTChallenge detections.

/// Arguments of `fme track`.
#[derive(Debug, clap::Args)]
pub struct TrackArgs {}

/// Runs `fme track`.
pub fn run(_args: TrackArgs) -> anyhow::Result<()> {
    anyhow::bail!("fme track is not implemented yet (issue 4)")
}
