//! Command-line front ends of the `fme` subcommands. Each file holds one subcommand's arguments and
//! its `run` function; `src/main.rs` only parses and dispatches.

pub mod calibrate;
pub mod choice;
pub mod config;
pub mod eval;
pub mod report;
pub mod run;
pub mod snapshot;
pub mod synth;
pub mod track;
pub mod tune;

/// Process exit code for an error: 2 for a problem with what fme was given (usage, configuration,
/// source, calibration, model files; the message names the file or key), 1 for everything else
/// (runtime faults).
pub fn exit_code(err: &anyhow::Error) -> u8 {
    if err.chain().any(|e| e.downcast_ref::<UsageError>().is_some()) { 2 } else { 1 }
}

/// An error in what the user gave fme (bad flag or configuration key, unreadable source,
/// calibration or model file): exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);

/// Writes a subcommand's report to stdout. A closed pipe (`fme eval ... | head`) is not an error:
/// the reader has what it wanted. Other write failures are.
pub fn write_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(anyhow::Error::new(e).context("writing to stdout")),
        _ => Ok(()),
    }
}

/// The one config of every command that estimates activity: a file and `--set` overrides.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ConfigArgs {
    /// Configuration file (TOML; see config/fme.toml for every key). Default: the built-in
    /// defaults, which config/fme.toml spells out.
    #[arg(long, short, value_name = "FILE")]
    pub config: Option<std::path::PathBuf>,
    /// Override one key after the file: `--set section.key=value` (repeatable), e.g.
    /// `--set detector.rate_hz=30`. Values are TOML (`10`, `true`, `"text"`) or plain text.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
}

impl ConfigArgs {
    /// Loads the config with the command's convenience flags (`sugar`, as `--set` assignments)
    /// applied first and the explicit `--set`s after them. Errors are [`UsageError`]s (exit 2) that
    /// name the file and line, or the `--set`.
    ///
    /// The file must be valid on its own, as `fme config check` sees it: a flag or `--set` that
    /// replaces a bad value (`mode = "udp"` under `--modbus-listen`) must not hide it, or the same
    /// file fails later where nothing replaces it (the service).
    pub fn load(&self, sugar: &[String]) -> anyhow::Result<(crate::config::Config, String)> {
        let usage = |e: crate::config::ConfigError| anyhow::Error::new(UsageError(e.to_string()));
        let sets: Vec<String> = sugar.iter().chain(&self.set).cloned().collect();
        if let (Some(file), false) = (self.config.as_deref(), sets.is_empty()) {
            crate::config::Config::load_with(Some(file), &[]).map_err(usage)?;
        }
        crate::config::Config::load_with(self.config.as_deref(), &sets).map_err(usage)
    }
}

/// A `--set` assignment of a text value, quoted as a TOML string (paths, names).
pub fn set_text(key: &str, value: &str) -> String {
    format!("{key}={}", toml_edit::Value::from(value))
}

/// The `--set`s of a `--source`: an `rtsp://` or `http://` URL is an IP camera (`source.kind` and
/// `source.url`), anything else `source.path` (a V4L2 device or a recording).
pub fn source_sets(source: &std::path::Path) -> Vec<String> {
    let text = source.to_string_lossy();
    match ["rtsp", "mjpeg"].into_iter().zip(["rtsp://", "http://"]).find(|(_, scheme)| text.starts_with(scheme)) {
        Some((kind, _)) => vec![set_text("source.kind", kind), set_text("source.url", &text)],
        None => vec![set_text("source.path", &text)],
    }
}

/// A `--set` assignment of a value that is already TOML (a number, a bool, an enum name).
pub fn set_value(key: &str, value: impl std::fmt::Display) -> String {
    format!("{key}={value}")
}
