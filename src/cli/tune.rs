//! `fme tune`: Grid-search tracker thresholds on sequences with ground truth.

/// Arguments of `fme tune`.
#[derive(Debug, clap::Args)]
pub struct TuneArgs {}

/// Runs `fme tune`.
pub fn run(_args: TuneArgs) -> anyhow::Result<()> {
    anyhow::bail!("fme tune is not implemented yet (issue 4)")
}
