//! Command-line front ends of the `fme` subcommands. Each file holds one subcommand's arguments and
//! its `run` function; `src/main.rs` only parses and dispatches.

pub mod eval;
pub mod run;
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
