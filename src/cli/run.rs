//! `fme run`: Run the edge daemon: camera or recording in, PLC and serial out.

/// Arguments of `fme run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {}

/// Runs `fme run`.
pub fn run(_args: RunArgs) -> anyhow::Result<()> {
    anyhow::bail!("fme run is not implemented yet (issue 6)")
}
