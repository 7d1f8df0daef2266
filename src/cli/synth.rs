//! `fme synth`: Write a synthetic underwater fish sequence with exact ground truth.

/// Arguments of `fme synth`.
#[derive(Debug, clap::Args)]
pub struct SynthArgs {}

/// Runs `fme synth`.
pub fn run(_args: SynthArgs) -> anyhow::Result<()> {
    anyhow::bail!("fme synth is not implemented yet (issue 2)")
}
