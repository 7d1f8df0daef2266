//! The HTTP/1.1 server of the Prometheus endpoint (`[output.metrics]`; the exposition itself is
//! [`super::metrics`]): `GET /metrics` and `HEAD /metrics`, one request per connection
//! (`Connection: close`).
//!
//! A hostile LAN is expected, and two hosts must not be able to lock the scraper out:
//! - `allow` filters peers at accept;
//! - at most `max_connections_per_peer` connections from one address and `max_connections` in all
//!   (more are closed at accept and counted), so a few hosts holding connections open take a few
//!   slots, not all of them;
//! - a request head not complete within `header_timeout_ms` is answered 408 (slowloris: a head
//!   trickled a byte at a time), one over [`MAX_HEAD`] bytes 431, and an answer not read within
//!   [`WRITE_TIMEOUT`] ends the connection;
//! - a *steady scraper* (an address answered [`PRIORITY_SCRAPES`] times or more, the last within
//!   [`PRIORITY_WINDOW`]) is never refused for the total limit while a connection of another
//!   address is still sending its request head: the oldest of those is closed for it (counted as
//!   refused). A Prometheus server asks for its answer at once; only a stalling client is slow.
//!
//! Nothing on these paths panics on outside input; should a connection task panic anyway, it ends
//! alone.

mod admission;
mod request;

pub use request::{Route, route};

use super::bank::RegisterBank;
use super::log_throttle::LogThrottle;
use super::metrics::{Scrape, render};
use crate::backoff::Backoff;
use crate::config::MetricsConfig;
use crate::config::allow::AllowList;
use crate::status::Shared;
use admission::{Conns, Slot, admit, set_abort};
use request::{Head, read_head, response};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::time::Instant;
use tracing::Level;

/// Largest request head (request line and headers), bytes; a longer one is answered 431.
pub const MAX_HEAD: usize = 8 * 1024;
/// An answer not written within this (a peer that does not read) ends the connection.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// Answered scrapes that make an address a steady scraper.
pub const PRIORITY_SCRAPES: u32 = 2;
/// A steady scraper whose last answer is older than this is a newcomer again.
pub const PRIORITY_WINDOW: Duration = Duration::from_secs(600);

/// The connection limits of the endpoint (`[output.metrics]`).
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
    /// The limits `cfg` configures.
    pub fn from_config(cfg: &MetricsConfig) -> Self {
        Self {
            max_connections: (cfg.max_connections as usize).max(1),
            max_per_peer: (cfg.max_connections_per_peer as usize).max(1),
            header_timeout: Duration::from_millis(cfg.header_timeout_ms),
            // Checked by `Config::validate`; a bad entry here would allow nobody rather than everyone.
            allow: AllowList::parse(&cfg.allow).unwrap_or_else(|_| AllowList::nobody()),
        }
    }
}

/// What a connection needs: the shared state, the bank and the staleness limit.
#[derive(Debug, Clone)]
struct Ctx {
    shared: Arc<Shared>,
    bank: Arc<RegisterBank>,
    stale_after: Duration,
    header_timeout: Duration,
}

async fn serve_connection(mut stream: tokio::net::TcpStream, ctx: Ctx, slot: Slot) {
    let mut buf = Box::new([0u8; MAX_HEAD]);
    let deadline = Instant::now() + ctx.header_timeout;
    let head = tokio::time::timeout_at(deadline, read_head(&mut stream, &mut buf)).await;
    slot.head_done();
    let (code, head_only) = match head {
        Ok(Head::Complete(n)) => match route(&buf[..n]) {
            Route::Metrics { head } => (200, head),
            Route::Error(c) => (c, false),
        },
        Ok(Head::TooLarge) => (431, false),
        Ok(Head::Closed) => {
            ctx.shared.metrics.aborted.fetch_add(1, Ordering::Relaxed);
            return;
        }
        Err(_) => (408, false),
    };
    let out = if code == 200 {
        let scrape = Scrape::take(&ctx.shared, &ctx.bank, ctx.stale_after);
        response(200, &render(&scrape), head_only)
    } else {
        let body = match code {
            404 => "not found: the metrics are at /metrics\n",
            405 => "method not allowed: use GET or HEAD\n",
            408 => "request timeout\n",
            431 => "request head too large\n",
            _ => "bad request\n",
        };
        response(code, body, false)
    };
    ctx.shared.metrics.note_response(code);
    let written = tokio::time::timeout(WRITE_TIMEOUT, async {
        stream.write_all(&out).await?;
        stream.shutdown().await
    })
    .await;
    let written = matches!(written, Ok(Ok(())));
    if written && code == 200 {
        slot.answered();
    }
    if written && code != 200 {
        // The peer may still be sending (a body, an oversized head): read a little of it so that
        // closing does not reset the connection before the peer has read the answer.
        let mut sink = [0u8; 1024];
        let _ = tokio::time::timeout(Duration::from_millis(200), async {
            let mut left = 64 * 1024usize;
            while left > 0 {
                match stream.read(&mut sink).await {
                    Ok(0) | Err(_) => break,
                    Ok(n) => left = left.saturating_sub(n),
                }
            }
        })
        .await;
    }
}

/// The running endpoint: its address, its task and its stop signal.
#[derive(Debug)]
pub struct MetricsServer {
    /// The bound address (useful with port 0).
    pub addr: SocketAddr,
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<()>,
}

impl MetricsServer {
    /// Stops accepting and ends the open connections (waits at most 200 ms).
    pub async fn stop(self) {
        let _ = self.stop.send(());
        let _ = tokio::time::timeout(Duration::from_millis(200), self.task).await;
    }
}

/// At most one message per this period about refused connections or panicked tasks (each counted).
const LOG_PERIOD: Duration = Duration::from_secs(10);

/// Starts the endpoint of `cfg` (inside a tokio runtime); `None` when `listen` is empty or the
/// address cannot be bound. A bind failure is logged (journal and console `log`) and shown by the
/// console's `status`; it never stops the daemon. An endpoint open to every address (`allow`
/// empty, `listen` not loopback) is logged as a warning and shown by `status`.
pub async fn spawn(
    cfg: &MetricsConfig,
    stale_after: Duration,
    shared: &Arc<Shared>,
    bank: &Arc<RegisterBank>,
) -> Option<MetricsServer> {
    if cfg.listen.is_empty() {
        return None;
    }
    let limits = HttpLimits::from_config(cfg);
    let bound = match tokio::net::TcpListener::bind(&cfg.listen).await {
        Ok(l) => l.local_addr().map(|a| (l, a)),
        Err(e) => Err(e),
    };
    let (listener, addr) = match bound {
        Ok(x) => x,
        Err(e) => {
            let hint = super::listen_hint::listen_hint(&e, "output.metrics.listen");
            let msg = format!("cannot listen on {} (output.metrics.listen): {e}{hint}", cfg.listen);
            shared.log(Level::ERROR, format!("metrics: {msg}; the Prometheus endpoint is off, everything else runs"));
            shared.metrics.set_state(format!("failed: {msg}"));
            return None;
        }
    };
    let open = crate::config::allow::open_to_all(&addr.to_string(), &cfg.allow);
    let reach = if open {
        ", OPEN TO EVERY ADDRESS (output.metrics.allow is empty)".to_string()
    } else if cfg.allow.is_empty() {
        " (this box only)".to_string()
    } else {
        format!(", allow {}", cfg.allow.join(", "))
    };
    shared.metrics.set_state(format!("on {addr} (GET /metrics){reach}"));
    shared.log(Level::INFO, format!("metrics: Prometheus endpoint on http://{addr}/metrics"));
    if open {
        shared.log(
            Level::WARN,
            format!(
                "metrics: the endpoint on {addr} is open to every address (output.metrics.allow is empty); \
                 list the Prometheus server's address there"
            ),
        );
    }
    let ctx = Ctx { shared: shared.clone(), bank: bank.clone(), stale_after, header_timeout: limits.header_timeout };
    let (stop, rx) = tokio::sync::oneshot::channel::<()>();
    let task = tokio::spawn(serve(listener, limits, ctx, async move {
        let _ = rx.await;
    }));
    Some(MetricsServer { addr, stop, task })
}

async fn serve(
    listener: tokio::net::TcpListener,
    limits: HttpLimits,
    ctx: Ctx,
    shutdown: impl std::future::Future<Output = ()>,
) {
    let mut tasks = tokio::task::JoinSet::new();
    let table = Conns::default();
    let mut shutdown = std::pin::pin!(shutdown);
    let mut backoff = Backoff::new(Duration::from_millis(100), Duration::from_secs(5));
    let mut refused_log = LogThrottle::new(LOG_PERIOD);
    let mut closed_log = LogThrottle::new(LOG_PERIOD);
    let mut panic_log = LogThrottle::new(LOG_PERIOD);
    let note_done = |done: Result<(), tokio::task::JoinError>, log: &mut LogThrottle| {
        if let Err(e) = done
            && e.is_panic()
            && let Some(n) = log.allow(Instant::now())
        {
            ctx.shared
                .log(Level::ERROR, format!("metrics: a connection task panicked ({n} more since the last message)"));
        }
    };
    loop {
        tokio::select! {
            () = &mut shutdown => return, // dropping the JoinSet aborts the connection tasks
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
                        Err("not in output.metrics.allow")
                    };
                    match admitted {
                        Ok((slot, closed)) => {
                            let id = slot.id;
                            let _ = stream.set_nodelay(true);
                            let abort = tasks.spawn(serve_connection(stream, ctx.clone(), slot));
                            set_abort(&table, id, abort);
                            if let Some(from) = closed {
                                ctx.shared.metrics.refused.fetch_add(1, Ordering::Relaxed);
                                if let Some(n) = closed_log.allow(now) {
                                    tracing::warn!("metrics: connection limit reached; closed a connection from {from} still sending its request head for steady scraper {peer} ({n} more since the last message)");
                                }
                            }
                        }
                        Err(why) => {
                            ctx.shared.metrics.refused.fetch_add(1, Ordering::Relaxed);
                            if let Some(n) = refused_log.allow(now) {
                                tracing::warn!("metrics: connection from {peer} refused ({why}; {n} more since the last message)");
                            }
                            drop(stream);
                        }
                    }
                }
                Err(e) => {
                    let pause = backoff.next_delay();
                    tracing::warn!("metrics: accept failed: {e}; accepting again in {:.1} s", pause.as_secs_f64());
                    tokio::select! {
                        _ = tokio::time::sleep(pause) => {},
                        () = &mut shutdown => return,
                    }
                }
            },
        }
    }
}

#[cfg(test)]
mod tests;
