//! `fme eval`: Run the estimator on a sequence and score it against ground truth.

/// Arguments of `fme eval`.
#[derive(Debug, clap::Args)]
pub struct EvalArgs {}

/// Runs `fme eval`.
pub fn run(_args: EvalArgs) -> anyhow::Result<()> {
    anyhow::bail!("fme eval is not implemented yet (issue 3)")
}
