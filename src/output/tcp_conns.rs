//! Connection management of the Modbus TCP server: at most `max_connections` at once, each closed
//! after `idle_timeout` without a request, and the least recently active one closed to make room for
//! a new one.
//!
//! Modbus Messaging on TCP/IP Implementation Guide v1.0b, 4.2.1: a server limits its connections
//! and, when the limit is reached, closes the oldest unused connection rather than refusing the new
//! one. A PLC that reboots, or a switch that drops the link, leaves half-open connections the box
//! never hears closing; without these rules they would pile up until the file-descriptor limit and
//! the PLC's new connection could be refused.

use super::bank::RegisterBank;
use super::log_throttle::LogThrottle;
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

/// Limits of the Modbus TCP server (`[output.modbus] max_connections`, `idle_timeout_ms`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TcpLimits {
    /// Connections served at once; a new one beyond this closes the least recently active one.
    pub max_connections: usize,
    /// A connection with no request for this long is closed; `None` keeps idle connections open.
    pub idle_timeout: Option<Duration>,
}

impl TcpLimits {
    /// The limits `[output.modbus]` configures (`idle_timeout_ms = 0`: never close idle connections).
    pub fn from_config(m: &crate::config::ModbusConfig) -> Self {
        Self {
            max_connections: m.max_connections as usize,
            idle_timeout: (m.idle_timeout_ms > 0).then(|| Duration::from_millis(m.idle_timeout_ms)),
        }
    }
}

impl Default for TcpLimits {
    fn default() -> Self {
        Self { max_connections: 8, idle_timeout: Some(Duration::from_secs(60)) }
    }
}

#[derive(Debug)]
struct Entry {
    id: u64,
    peer: SocketAddr,
    last_activity: Instant,
    close: oneshot::Sender<()>,
}

/// At most one eviction warning per this period; the bank counts every eviction.
const EVICTION_LOG_PERIOD: Duration = Duration::from_secs(10);

#[derive(Debug)]
struct Table {
    next_id: u64,
    open: Vec<Entry>,
    eviction_log: LogThrottle,
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
        let table = Table { next_id: 0, open: Vec::new(), eviction_log: LogThrottle::new(EVICTION_LOG_PERIOD) };
        Self { table: Arc::new(Mutex::new(table)), limits, bank }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Table> {
        self.table.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Number of connections open now.
    pub fn open(&self) -> usize {
        self.lock().open.len()
    }

    /// Registers an accepted stream, closing the least recently active connection first when the
    /// table is full, and returns the stream wrapped so that it reports activity and obeys the idle
    /// timeout and eviction.
    pub fn admit(&self, stream: TcpStream, peer: SocketAddr) -> GuardedStream {
        let (tx, rx) = oneshot::channel();
        let now = Instant::now();
        let id = {
            let mut t = self.lock();
            while t.open.len() >= self.limits.max_connections.max(1) {
                let Some(oldest) = (0..t.open.len()).min_by_key(|&i| t.open[i].last_activity) else { break };
                let e = t.open.swap_remove(oldest);
                if let Some(held_back) = t.eviction_log.allow(now) {
                    tracing::warn!(
                        "modbus tcp: {} connections open (the limit); closing the least recently active, {} (idle {:.1} s), for {peer} ({held_back} more evictions since the last message)",
                        self.limits.max_connections,
                        e.peer,
                        now.duration_since(e.last_activity).as_secs_f64()
                    );
                }
                let _ = e.close.send(());
                self.bank.note_tcp_evicted();
            }
            let id = t.next_id;
            t.next_id += 1;
            t.open.push(Entry { id, peer, last_activity: now, close: tx });
            self.bank.set_tcp_open(t.open.len());
            id
        };
        tracing::debug!("modbus tcp: connection from {peer}");
        GuardedStream {
            stream,
            peer,
            id,
            conns: self.clone(),
            eviction: Eviction::Watching(rx),
            idle: self.limits.idle_timeout.map(|d| (d, Box::pin(tokio::time::sleep(d)))),
        }
    }

    fn touch(&self, id: u64) {
        let now = Instant::now();
        if let Some(e) = self.lock().open.iter_mut().find(|e| e.id == id) {
            e.last_activity = now;
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

/// A server-side TCP stream that ends with an error when it is idle for longer than the timeout or
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
        let before = buf.filled().len();
        match Pin::new(&mut this.stream).poll_read(cx, buf) {
            Poll::Ready(Ok(())) => {
                if buf.filled().len() > before {
                    if let Some((d, sleep)) = this.idle.as_mut() {
                        sleep.as_mut().reset(Instant::now() + *d);
                    }
                    this.conns.touch(this.id);
                }
                Poll::Ready(Ok(()))
            }
            Poll::Ready(Err(e)) => Poll::Ready(Err(e)),
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
