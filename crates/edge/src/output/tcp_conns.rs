//! Connection management of the Modbus TCP server: at most `max_connections` at once and
//! `max_per_peer` from one address, each closed after `idle_timeout` without a complete request,
//! and one closed to make room for a new one: first those that never had a request answered
//! (a port scanner, an idle connection flood), then the least recently active, but never a
//! *priority* connection. A connection has priority once it has had requests answered for
//! `priority_after` with no gap longer than `priority_after` between two of them: a PLC polling
//! steadily. When every connection that could make room has priority, the newcomer is refused
//! (closed at accept and counted), not the PLC: clients polling faster than the PLC from several
//! addresses (an HMI, a SCADA poller, a misconfigured tool) no longer push it out.
//!
//! Modbus Messaging on TCP/IP Implementation Guide v1.0b, 4.2.1: a server limits its connections
//! and, when the limit is reached, closes the oldest unused connection rather than refusing the new
//! one; "priority" connections are kept. A PLC that reboots, or a switch that drops the link,
//! leaves half-open connections the box never hears closing; without these rules they would pile
//! up until the file-descriptor limit and the PLC's new connection could be refused. A half-open
//! connection answers nothing, so it loses its priority `priority_after` after its last request and
//! can then be closed for the PLC's new one.

use super::bank::RegisterBank;
use super::log_throttle::LogThrottle;
use super::peer_limit::PeerLimit;
use crate::config::allow::AllowList;
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tokio::sync::oneshot;
use tokio::time::{Instant, Sleep};

/// Limits of the Modbus TCP server (`[output.modbus] max_connections`, `max_connections_per_peer`,
/// `idle_timeout_ms`, `priority_after_ms`, `allow`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TcpLimits {
    /// Connections served at once; a new one beyond this closes another (see the module docs).
    pub max_connections: usize,
    /// Connections served at once from one IP address; a new one beyond this closes one of that
    /// address's own.
    pub max_per_peer: usize,
    /// A connection with no complete request for this long is closed; `None` keeps idle
    /// connections open. Bytes that do not complete a request do not count.
    pub idle_timeout: Option<Duration>,
    /// A connection answered steadily (no gap longer than this) for this long has priority: it is
    /// never closed for a newcomer. `None`: no connection has priority.
    pub priority_after: Option<Duration>,
    /// Addresses allowed to connect (empty = all); others are closed at accept and counted.
    pub allow: AllowList,
}

impl TcpLimits {
    /// The limits `[output.modbus]` configures (`idle_timeout_ms = 0`: never close idle connections).
    pub fn from_config(m: &crate::config::ModbusConfig) -> Self {
        Self {
            max_connections: m.max_connections as usize,
            max_per_peer: m.max_connections_per_peer as usize,
            idle_timeout: (m.idle_timeout_ms > 0).then(|| Duration::from_millis(m.idle_timeout_ms)),
            priority_after: (m.priority_after_ms > 0).then(|| Duration::from_millis(m.priority_after_ms)),
            // Checked by `Config::validate`; a bad entry here would allow nobody rather than everyone.
            allow: AllowList::parse(&m.allow).unwrap_or_else(|_| AllowList::nobody()),
        }
    }
}

impl Default for TcpLimits {
    fn default() -> Self {
        Self {
            max_connections: 8,
            max_per_peer: 4,
            idle_timeout: Some(Duration::from_secs(60)),
            priority_after: Some(Duration::from_secs(10)),
            allow: AllowList::default(),
        }
    }
}

#[derive(Debug)]
struct Entry {
    id: u64,
    peer: SocketAddr,
    last_activity: Instant,
    /// Whether a request on it has been answered without an exception.
    proven: bool,
    /// Start of the current run of answered requests no more than `priority_after` apart.
    steady_since: Option<Instant>,
    /// The last answered request.
    last_answer: Option<Instant>,
    close: oneshot::Sender<()>,
}

impl Entry {
    /// Eviction order: never-answered connections first, then the least recently active.
    fn eviction_key(&self) -> (bool, Instant) {
        (self.proven, self.last_activity)
    }

    /// Whether it has been answered steadily for `after` (see the module docs).
    fn priority(&self, after: Option<Duration>, now: Instant) -> bool {
        let (Some(after), Some(since), Some(last)) = (after, self.steady_since, self.last_answer) else {
            return false;
        };
        now.duration_since(since) >= after && now.duration_since(last) <= after
    }
}

/// At most one eviction warning per this period; the bank counts every eviction.
const EVICTION_LOG_PERIOD: Duration = Duration::from_secs(10);

#[derive(Debug)]
struct Table {
    next_id: u64,
    open: Vec<Entry>,
    eviction_log: LogThrottle,
    refusal_log: LogThrottle,
}

/// The open connections of one server. Registering a connection beyond the limit signals the least
/// recently active one to close.
#[derive(Debug, Clone)]
pub struct Connections {
    table: Arc<Mutex<Table>>,
    limits: TcpLimits,
    bank: Arc<RegisterBank>,
}

impl Connections {
    /// An empty table; the bank counts open, idle-closed and evicted connections.
    pub fn new(limits: TcpLimits, bank: Arc<RegisterBank>) -> Self {
        let table = Table {
            next_id: 0,
            open: Vec::new(),
            eviction_log: LogThrottle::new(EVICTION_LOG_PERIOD),
            refusal_log: LogThrottle::new(EVICTION_LOG_PERIOD),
        };
        Self { table: Arc::new(Mutex::new(table)), limits, bank }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Table> {
        self.table.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Number of connections open now.
    pub fn open(&self) -> usize {
        self.lock().open.len()
    }

    /// Whether a peer at this address may connect at all (`allow`).
    pub fn permits(&self, peer: SocketAddr) -> bool {
        self.limits.allow.permits(peer.ip())
    }

    /// Registers an accepted stream, first closing one connection of the same address when it is
    /// at `max_per_peer`, then one of any address while the table is full (never-answered
    /// connections first, then the least recently active; never one with priority), and returns
    /// the stream wrapped so that it obeys the idle timeout and eviction. `None`: refused (closed,
    /// counted) because every connection that could make room has priority.
    pub fn admit(&self, stream: TcpStream, peer: SocketAddr) -> Option<GuardedStream> {
        let (tx, rx) = oneshot::channel();
        let now = Instant::now();
        let id = {
            let mut t = self.lock();
            let per_peer = PeerLimit::new(self.limits.max_per_peer, self.limits.max_connections);
            if per_peer.reached(peer.ip(), t.open.iter().map(|e| e.peer.ip())) {
                let Some(i) = self.victim(&t, now, Some(peer)) else {
                    return self.refuse(&mut t, peer, now, "per-address limit");
                };
                self.evict(&mut t, i, peer, now, "per-address limit");
            }
            while t.open.len() >= self.limits.max_connections.max(1) {
                let Some(i) = self.victim(&t, now, None) else {
                    return self.refuse(&mut t, peer, now, "connection limit");
                };
                self.evict(&mut t, i, peer, now, "connection limit");
            }
            let id = t.next_id;
            t.next_id += 1;
            let entry =
                Entry { id, peer, last_activity: now, proven: false, steady_since: None, last_answer: None, close: tx };
            t.open.push(entry);
            self.bank.set_tcp_open(t.open.len());
            id
        };
        tracing::debug!("modbus tcp: connection from {peer}");
        Some(GuardedStream {
            stream,
            peer,
            id,
            conns: self.clone(),
            eviction: Eviction::Watching(rx),
            idle: self.limits.idle_timeout.map(|d| (d, Box::pin(tokio::time::sleep(d)))),
        })
    }

    /// The connection to close for a newcomer (of `same`'s address only, when given): the first in
    /// eviction order without priority.
    fn victim(&self, t: &Table, now: Instant, same: Option<SocketAddr>) -> Option<usize> {
        (0..t.open.len())
            .filter(|&i| same.is_none_or(|p| t.open[i].peer.ip() == p.ip()))
            .filter(|&i| !t.open[i].priority(self.limits.priority_after, now))
            .min_by_key(|&i| t.open[i].eviction_key())
    }

    fn refuse(&self, t: &mut Table, peer: SocketAddr, now: Instant, why: &str) -> Option<GuardedStream> {
        if let Some(held_back) = t.refusal_log.allow(now) {
            tracing::warn!(
                "modbus tcp: {why} reached and every connection that could make room has priority \
                 (answered steadily); refusing {peer} ({held_back} more refusals since the last message)"
            );
        }
        self.bank.note_tcp_refused();
        None
    }

    fn evict(&self, t: &mut Table, i: usize, peer: SocketAddr, now: Instant, why: &str) {
        let e = t.open.swap_remove(i);
        if let Some(held_back) = t.eviction_log.allow(now) {
            tracing::warn!(
                "modbus tcp: {why} reached; closing {} ({}, idle {:.1} s) for {peer} ({held_back} more evictions since the last message)",
                e.peer,
                if e.proven { "least recently active" } else { "no request answered yet" },
                now.duration_since(e.last_activity).as_secs_f64()
            );
        }
        let _ = e.close.send(());
        self.bank.note_tcp_evicted();
    }

    fn touch(&self, id: u64, answered: bool) {
        let now = Instant::now();
        let after = self.limits.priority_after;
        if let Some(e) = self.lock().open.iter_mut().find(|e| e.id == id) {
            e.last_activity = now;
            e.proven |= answered;
            if answered {
                // A gap longer than `priority_after` starts the steady run again.
                let gap = e.last_answer.map(|l| now.duration_since(l));
                if e.steady_since.is_none() || after.is_some_and(|a| gap.is_none_or(|g| g > a)) {
                    e.steady_since = Some(now);
                }
                e.last_answer = Some(now);
            }
        }
    }

    fn remove(&self, id: u64) {
        let mut t = self.lock();
        if let Some(i) = t.open.iter().position(|e| e.id == id) {
            t.open.swap_remove(i);
        }
        self.bank.set_tcp_open(t.open.len());
    }
}

/// Whether a connection has been evicted by [`Connections::admit`].
#[derive(Debug)]
enum Eviction {
    /// Not yet; the table signals through this receiver.
    Watching(oneshot::Receiver<()>),
    /// Evicted: every read and write fails from now on.
    Evicted,
    /// Can no longer happen (the table dropped its sender).
    Never,
}

/// A server-side TCP stream that ends with an error when no request completes within the timeout or
/// when [`Connections`] evicts it; dropping it unregisters the connection.
#[derive(Debug)]
pub struct GuardedStream {
    stream: TcpStream,
    peer: SocketAddr,
    id: u64,
    conns: Connections,
    eviction: Eviction,
    idle: Option<(Duration, Pin<Box<Sleep>>)>,
}

impl GuardedStream {
    /// Notes a complete request on this connection: restarts the idle timeout and marks the
    /// connection active; `answered` (no exception) also protects it from eviction before
    /// connections that never had a request answered.
    pub fn note_request(&mut self, answered: bool) {
        if let Some((d, sleep)) = self.idle.as_mut() {
            sleep.as_mut().reset(Instant::now() + *d);
        }
        self.conns.touch(self.id, answered);
    }

    /// The peer's address.
    pub fn peer(&self) -> SocketAddr {
        self.peer
    }

    /// `Some(error)` once this connection was evicted for a newer one (and on every poll after).
    fn evicted(&mut self, cx: &mut Context<'_>) -> Option<io::Error> {
        if let Eviction::Watching(rx) = &mut self.eviction {
            // A oneshot receiver must not be polled again once it has completed.
            match Pin::new(rx).poll(cx) {
                Poll::Ready(Ok(())) => self.eviction = Eviction::Evicted,
                // The sender went away without a signal: nothing more to wait for.
                Poll::Ready(Err(_)) => self.eviction = Eviction::Never,
                Poll::Pending => {}
            }
        }
        matches!(self.eviction, Eviction::Evicted).then(|| {
            io::Error::new(
                io::ErrorKind::ConnectionAborted,
                format!("modbus tcp {}: closed to make room for a newer connection", self.peer),
            )
        })
    }
}

impl AsyncRead for GuardedStream {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let this = &mut *self;
        if let Some(e) = this.evicted(cx) {
            return Poll::Ready(Err(e));
        }
        // Bytes alone do not restart the idle timeout (a peer trickling one byte at a time would
        // keep its connection forever): only a complete request does (`note_request`).
        match Pin::new(&mut this.stream).poll_read(cx, buf) {
            Poll::Ready(r) => Poll::Ready(r),
            Poll::Pending => {
                let Some((d, sleep)) = this.idle.as_mut() else { return Poll::Pending };
                if sleep.as_mut().poll(cx).is_pending() {
                    return Poll::Pending;
                }
                let secs = d.as_secs_f64();
                tracing::info!("modbus tcp {}: no request for {secs:.1} s, closing", this.peer);
                this.conns.bank.note_tcp_idle_closed();
                Poll::Ready(Err(io::Error::new(
                    io::ErrorKind::TimedOut,
                    format!("modbus tcp {}: idle for {secs:.1} s", this.peer),
                )))
            }
        }
    }
}

impl AsyncWrite for GuardedStream {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        if let Some(e) = self.evicted(cx) {
            return Poll::Ready(Err(e));
        }
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

impl Drop for GuardedStream {
    fn drop(&mut self) {
        self.conns.remove(self.id);
    }
}
