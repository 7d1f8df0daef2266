//! `fme config`: check a configuration file, or show the effective configuration.

use super::ConfigArgs;
use std::path::PathBuf;

/// Arguments of `fme config`.
#[derive(Debug, clap::Args)]
pub struct ConfigCmdArgs {
    /// What to do.
    #[command(subcommand)]
    pub action: Action,
}

/// `fme config` actions.
#[derive(Debug, clap::Subcommand)]
pub enum Action {
    /// Validate a file and every file it names (calibration, models, recording, MQTT TLS and
    /// password files): exit 0, or 2 with a message naming the file, the line and the key.
    Check {
        /// The configuration file.
        file: PathBuf,
    },
    /// Print the effective configuration as TOML: the defaults, the file (if given) and the `--set`s.
    Show {
        /// The configuration file (default: the built-in defaults).
        #[arg(conflicts_with = "config")]
        file: Option<PathBuf>,
        /// The same as FILE, as every other command spells it.
        #[arg(long, short, value_name = "FILE")]
        config: Option<PathBuf>,
        /// Override one key: `--set section.key=value` (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
}

/// Runs `fme config`.
pub fn run(args: ConfigCmdArgs) -> anyhow::Result<()> {
    match args.action {
        Action::Check { file } => {
            let c = ConfigArgs { config: Some(file.clone()), set: Vec::new() };
            let (cfg, _) = c.load(&[])?;
            // The files it names, so that `fme run` with this file cannot stop at start for one.
            crate::config::files::check(&cfg)
                .map_err(|(key, message)| super::UsageError(format!("{}: key `{key}`: {message}", file.display())))?;
            // Warnings do not fail the check: a lab box may serve everyone on purpose.
            for (key, message) in cfg.warnings() {
                eprintln!("{}: warning: key `{key}`: {message}", file.display());
            }
            super::write_stdout(&format!("{}: ok\n", file.display()))
        }
        Action::Show { file, config, set } => {
            let file = file.or(config);
            let (cfg, _) = ConfigArgs { config: file, set }.load(&[])?;
            super::write_stdout(&cfg.to_toml())
        }
    }
}
