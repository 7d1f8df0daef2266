//! Signals of `fme run`. Every catchable signal whose default action would end the process ends it
//! the SIGTERM way instead (registers set to "stopped", summary, bounded shutdown), so a stray
//! `kill -USR1` never leaves the PLC reading a frozen block:
//!
//! - SIGTERM, SIGINT: a stop that was asked for (exit 0).
//! - SIGHUP: does not stop fme. The calibration file is read again: a good one is applied to the
//!   running pipeline, a bad one is refused and the one in use kept; either is logged (journal and
//!   console `log`).
//! - SIGXFSZ (a file grew past the file-size limit) is ignored: the write fails with `EFBIG`
//!   instead, and the recorder pauses like on a full disk (docs/recording.md); the outputs go on.
//! - SIGQUIT, SIGUSR1, SIGUSR2, SIGALRM, SIGVTALRM, SIGPROF, SIGXCPU, SIGIO, SIGPWR,
//!   SIGSTKFLT and the real-time signals: a stop nobody asked fme for; it shuts down cleanly and
//!   exits 1, so that systemd's `Restart=on-failure` starts it again.
//! - SIGPIPE stays ignored (the Rust runtime ignores it; a closed socket is an `EPIPE` error).
//! - Faults (SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGSYS, SIGTRAP) keep their default action.

use tokio::signal::unix::{SignalKind, signal};
use tokio::sync::mpsc;

/// What a received signal asks of the daemon.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalEvent {
    /// SIGHUP: reload the calibration, keep running.
    Hangup,
    /// A stop that was asked for (SIGTERM, SIGINT): exit 0.
    Stop(&'static str),
    /// Any other terminating signal: stop cleanly, then exit non-zero so the service is restarted.
    Unexpected(&'static str),
}

const UNEXPECTED: &[(i32, &str)] = &[
    (libc_sig::SIGQUIT, "SIGQUIT"),
    (libc_sig::SIGUSR1, "SIGUSR1"),
    (libc_sig::SIGUSR2, "SIGUSR2"),
    (libc_sig::SIGALRM, "SIGALRM"),
    (libc_sig::SIGVTALRM, "SIGVTALRM"),
    (libc_sig::SIGPROF, "SIGPROF"),
    (libc_sig::SIGXCPU, "SIGXCPU"),
    (libc_sig::SIGIO, "SIGIO"),
    (libc_sig::SIGPWR, "SIGPWR"),
    (libc_sig::SIGSTKFLT, "SIGSTKFLT"),
];

/// Linux signal numbers (x86-64 and aarch64 agree on these).
mod libc_sig {
    pub const SIGHUP: i32 = 1;
    pub const SIGINT: i32 = 2;
    pub const SIGQUIT: i32 = 3;
    pub const SIGUSR1: i32 = 10;
    pub const SIGUSR2: i32 = 12;
    pub const SIGALRM: i32 = 14;
    pub const SIGTERM: i32 = 15;
    pub const SIGSTKFLT: i32 = 16;
    pub const SIGXCPU: i32 = 24;
    pub const SIGVTALRM: i32 = 26;
    pub const SIGPROF: i32 = 27;
    pub const SIGIO: i32 = 29;
    pub const SIGPWR: i32 = 30;
    /// SIGRTMIN as glibc reports it (the two below are reserved by the threading library).
    pub const SIGRTMIN: i32 = 34;
    pub const SIGRTMAX: i32 = 64;
}

/// The installed handlers; [`Signals::next`] yields the events in arrival order.
#[derive(Debug)]
pub struct Signals {
    rx: mpsc::UnboundedReceiver<SignalEvent>,
}

impl Signals {
    /// Installs the handlers (inside a tokio runtime). From this call on none of these signals
    /// ends the process by itself.
    pub fn install() -> std::io::Result<Self> {
        // SAFETY: setting a signal's disposition to SIG_IGN has no preconditions.
        unsafe { libc::signal(libc::SIGXFSZ, libc::SIG_IGN) };
        let (tx, rx) = mpsc::unbounded_channel();
        let mut kinds: Vec<(i32, SignalEvent)> = vec![
            (libc_sig::SIGHUP, SignalEvent::Hangup),
            (libc_sig::SIGTERM, SignalEvent::Stop("SIGTERM")),
            (libc_sig::SIGINT, SignalEvent::Stop("SIGINT")),
        ];
        kinds.extend(UNEXPECTED.iter().map(|&(n, name)| (n, SignalEvent::Unexpected(name))));
        kinds.extend(
            (libc_sig::SIGRTMIN..=libc_sig::SIGRTMAX).map(|n| (n, SignalEvent::Unexpected("a real-time signal"))),
        );
        for (n, ev) in kinds {
            let mut s = match signal(SignalKind::from_raw(n)) {
                Ok(s) => s,
                // Real-time signals the platform lacks: nothing to catch.
                Err(_) if n >= libc_sig::SIGRTMIN => continue,
                Err(e) => return Err(e),
            };
            let tx = tx.clone();
            tokio::spawn(async move {
                while s.recv().await.is_some() {
                    if tx.send(ev).is_err() {
                        return;
                    }
                }
            });
        }
        Ok(Self { rx })
    }

    /// The next signal event (pending forever if the handlers are gone).
    pub async fn next(&mut self) -> SignalEvent {
        match self.rx.recv().await {
            Some(ev) => ev,
            None => std::future::pending().await,
        }
    }
}
