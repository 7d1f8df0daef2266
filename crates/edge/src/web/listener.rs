//! One listening socket of the server and who it lets in. A hostile LAN is expected, and a few
//! hosts must not be able to lock the browser or the scraper out:
//! - `allow` filters peers at accept;
//! - at most `max_connections_per_peer` connections from one address and `max_connections` in all
//!   (more are closed at accept and counted), so a few hosts holding connections open take a few
//!   slots, not all of them;
//! - a *steady client* (an address answered [`PRIORITY_SCRAPES`] times or more, the last within
//!   [`PRIORITY_WINDOW`]) is never refused for the total limit while a connection of another
//!   address is still sending its first request head: the oldest of those is closed for it
//!   (counted as refused). A Prometheus server or a browser asks at once; only a stalling client
//!   is slow.
//!
//! The head timeout, the head size limit and the garbage check are per connection ([`super::conn`]).

use super::admission::{Conns, admit, set_abort};
use super::conn::{ConnCtx, serve_connection};
use crate::backoff::Backoff;
use crate::config::allow::AllowList;
use crate::output::log_throttle::LogThrottle;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::time::Instant;
use tracing::Level;

/// Answered requests that make an address a steady client.
pub const PRIORITY_SCRAPES: u32 = 2;
/// A steady client whose last answer is older than this is a newcomer again.
pub const PRIORITY_WINDOW: Duration = Duration::from_secs(600);
/// At most one message per this period about refused connections or panicked tasks (each counted).
const LOG_PERIOD: Duration = Duration::from_secs(10);

/// The connection limits of one listener (`[web]` or `[output.metrics]`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HttpLimits {
    /// Connections served at once (`max_connections`).
    pub max_connections: usize,
    /// Connections served at once from one address (`max_connections_per_peer`).
    pub max_per_peer: usize,
    /// Time to send a complete request head (`header_timeout_ms`).
    pub header_timeout: Duration,
    /// Addresses allowed to connect (empty = all).
    pub allow: AllowList,
}

impl HttpLimits {
    /// The limits of `[output.metrics]`.
    pub fn metrics(cfg: &crate::config::MetricsConfig) -> Self {
        Self::new(cfg.max_connections, cfg.max_connections_per_peer, cfg.header_timeout_ms, &cfg.allow)
    }

    /// The limits of `[web]`.
    pub fn web(cfg: &super::config::WebConfig) -> Self {
        Self::new(cfg.max_connections, cfg.max_connections_per_peer, cfg.header_timeout_ms, &cfg.allow)
    }

    fn new(total: u32, per_peer: u32, header_timeout_ms: u64, allow: &[String]) -> Self {
        Self {
            max_connections: (total as usize).max(1),
            max_per_peer: (per_peer as usize).max(1),
            header_timeout: Duration::from_millis(header_timeout_ms),
            // Checked by `Config::validate`; a bad entry here would allow nobody rather than everyone.
            allow: AllowList::parse(allow).unwrap_or_else(|_| AllowList::nobody()),
        }
    }
}

/// Accepts on `listener` until the task is aborted (dropping the set aborts the connections).
pub(super) async fn serve(listener: tokio::net::TcpListener, limits: HttpLimits, ctx: Arc<ConnCtx>) {
    let mut tasks = tokio::task::JoinSet::new();
    let table = Conns::default();
    let mut backoff = Backoff::new(Duration::from_millis(100), Duration::from_secs(5));
    let mut refused_log = LogThrottle::new(LOG_PERIOD);
    let mut closed_log = LogThrottle::new(LOG_PERIOD);
    let mut panic_log = LogThrottle::new(LOG_PERIOD);
    let name = ctx.kind.name();
    let note_done = |done: Result<(), tokio::task::JoinError>, log: &mut LogThrottle| {
        if let Err(e) = done
            && e.is_panic()
            && let Some(n) = log.allow(Instant::now())
        {
            let msg = format!("{name}: a connection task panicked ({n} more since the last message)");
            ctx.state.shared.log(Level::ERROR, msg);
        }
    };
    loop {
        tokio::select! {
            Some(done) = tasks.join_next(), if !tasks.is_empty() => note_done(done, &mut panic_log),
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    backoff.reset();
                    while let Some(done) = tasks.try_join_next() {
                        note_done(done, &mut panic_log);
                    }
                    let now = Instant::now();
                    let admitted = if limits.allow.permits(peer.ip()) {
                        admit(&table, &limits, peer.ip(), now)
                    } else {
                        Err("not in the allow list")
                    };
                    match admitted {
                        Ok((slot, closed)) => {
                            let id = slot.id;
                            let _ = stream.set_nodelay(true);
                            let abort = tasks.spawn(serve_connection(stream, ctx.clone(), slot));
                            set_abort(&table, id, abort);
                            if let Some(from) = closed {
                                ctx.count_refused();
                                if let Some(n) = closed_log.allow(now) {
                                    tracing::warn!("{name}: connection limit reached; closed a connection from {from} still sending its request head for steady client {peer} ({n} more since the last message)");
                                }
                            }
                        }
                        Err(why) => {
                            ctx.count_refused();
                            if let Some(n) = refused_log.allow(now) {
                                tracing::warn!("{name}: connection from {peer} refused ({why}; {n} more since the last message)");
                            }
                            drop(stream);
                        }
                    }
                }
                Err(e) => {
                    let pause = backoff.next_delay();
                    tracing::warn!("{name}: accept failed: {e}; accepting again in {:.1} s", pause.as_secs_f64());
                    tokio::time::sleep(pause).await;
                }
            },
        }
    }
}

impl ConnCtx {
    /// Counts a connection refused at accept (the metrics listener's counter).
    fn count_refused(&self) {
        if self.kind == super::Kind::Metrics {
            self.state.shared.metrics.refused.fetch_add(1, Ordering::Relaxed);
        }
    }
}
