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

use super::bank::RegisterBank;
use super::log_throttle::LogThrottle;
use super::metrics::{CONTENT_TYPE, Scrape, render};
use crate::backoff::Backoff;
use crate::config::MetricsConfig;
use crate::config::allow::AllowList;
use crate::status::Shared;
use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use tokio::task::AbortHandle;
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
/// Addresses whose scrapes are remembered (the least recently answered is forgotten first).
const SCRAPERS_KEPT: usize = 64;

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

/// The answer to a request head.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// `GET /metrics` (`head`: `HEAD /metrics`, no body).
    Metrics {
        /// HEAD: headers only.
        head: bool,
    },
    /// An error status (400, 404, 405, 408, 431).
    Error(u16),
}

/// Routes a complete request head (request line first; headers are not needed). Never panics.
pub fn route(head: &[u8]) -> Route {
    let line_end = head.iter().position(|&c| c == b'\n').unwrap_or(head.len());
    let Ok(line) = std::str::from_utf8(&head[..line_end]) else { return Route::Error(400) };
    let mut parts = line.trim_end_matches('\r').split(' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Route::Error(400);
    };
    if method.is_empty() || !method.bytes().all(|c| c.is_ascii_uppercase()) || !target.starts_with('/') {
        return Route::Error(400);
    }
    if !matches!(version, "HTTP/1.0" | "HTTP/1.1") {
        return Route::Error(400);
    }
    let path = target.split_once('?').map_or(target, |(p, _)| p);
    if path != "/metrics" {
        return Route::Error(404);
    }
    match method {
        "GET" => Route::Metrics { head: false },
        "HEAD" => Route::Metrics { head: true },
        _ => Route::Error(405),
    }
}

/// The reason phrase of a status code.
fn reason(code: u16) -> &'static str {
    match code {
        200 => "OK",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        431 => "Request Header Fields Too Large",
        _ => "Bad Request",
    }
}

/// The complete response (head and, unless `head_only`, body).
fn response(code: u16, body: &str, head_only: bool) -> Vec<u8> {
    let ctype = if code == 200 { CONTENT_TYPE } else { "text/plain; charset=utf-8" };
    let mut out = format!(
        "HTTP/1.1 {code} {}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nConnection: close\r\nCache-Control: no-store\r\n",
        reason(code),
        body.len()
    );
    if code == 405 {
        out.push_str("Allow: GET, HEAD\r\n");
    }
    out.push_str("\r\n");
    let mut out = out.into_bytes();
    if !head_only {
        out.extend_from_slice(body.as_bytes());
    }
    out
}

/// How reading a request head ended.
#[derive(Debug, PartialEq, Eq)]
enum Head {
    /// Complete: this many bytes (up to and including the blank line).
    Complete(usize),
    /// [`MAX_HEAD`] bytes without the blank line.
    TooLarge,
    /// The peer closed (or reset) first.
    Closed,
}

/// Where the blank line ending a head is in `buf` (searching from `from`): the byte after it.
fn head_end(buf: &[u8], from: usize) -> Option<usize> {
    let start = from.saturating_sub(3);
    (start..buf.len()).find_map(|i| {
        if buf[i..].starts_with(b"\r\n\r\n") {
            Some(i + 4)
        } else if buf[i..].starts_with(b"\n\n") {
            Some(i + 2)
        } else {
            None
        }
    })
}

async fn read_head<R: tokio::io::AsyncRead + Unpin>(r: &mut R, buf: &mut [u8; MAX_HEAD]) -> Head {
    let mut len = 0;
    loop {
        if len == buf.len() {
            return Head::TooLarge;
        }
        match r.read(&mut buf[len..]).await {
            Ok(0) | Err(_) => return Head::Closed,
            Ok(n) => {
                let from = len;
                len += n;
                if let Some(end) = head_end(&buf[..len], from) {
                    return Head::Complete(end);
                }
            }
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

/// One open connection.
#[derive(Debug)]
struct Conn {
    id: u64,
    ip: IpAddr,
    opened: Instant,
    /// Its request head is complete (or too large): it is being answered and closes soon.
    head_done: bool,
    /// Set once its task is spawned.
    abort: Option<AbortHandle>,
}

/// An address's answered scrapes.
#[derive(Debug, Clone, Copy)]
struct Scraper {
    answered: u32,
    last: Instant,
}

/// The open connections and the addresses that scraped.
#[derive(Debug, Default)]
struct Table {
    next_id: u64,
    conns: Vec<Conn>,
    scrapers: HashMap<IpAddr, Scraper>,
}

impl Table {
    fn steady(&self, ip: IpAddr, now: Instant) -> bool {
        self.scrapers
            .get(&ip)
            .is_some_and(|s| s.answered >= PRIORITY_SCRAPES && now.duration_since(s.last) <= PRIORITY_WINDOW)
    }

    fn note_scrape(&mut self, ip: IpAddr, now: Instant) {
        if !self.scrapers.contains_key(&ip)
            && self.scrapers.len() >= SCRAPERS_KEPT
            && let Some(oldest) = self.scrapers.iter().min_by_key(|(_, s)| s.last).map(|(ip, _)| *ip)
        {
            self.scrapers.remove(&oldest);
        }
        let s = self.scrapers.entry(ip).or_insert(Scraper { answered: 0, last: now });
        s.answered = s.answered.saturating_add(1);
        s.last = now;
    }
}

type Conns = Arc<Mutex<Table>>;

fn lock(t: &Conns) -> std::sync::MutexGuard<'_, Table> {
    t.lock().unwrap_or_else(|p| p.into_inner())
}

/// One connection's place in the [`Table`], given back when its task ends (also by a panic or an
/// abort).
#[derive(Debug)]
struct Slot {
    table: Conns,
    id: u64,
    ip: IpAddr,
}

impl Slot {
    fn head_done(&self) {
        if let Some(c) = lock(&self.table).conns.iter_mut().find(|c| c.id == self.id) {
            c.head_done = true;
        }
    }

    fn answered(&self) {
        lock(&self.table).note_scrape(self.ip, Instant::now());
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut t = lock(&self.table);
        if let Some(i) = t.conns.iter().position(|c| c.id == self.id) {
            t.conns.swap_remove(i);
        }
    }
}

/// The outcome of [`admit`]: the new connection's slot and the address of a connection closed
/// for it, or why it is refused.
type Admission = Result<(Slot, Option<IpAddr>), &'static str>;

/// Admits a connection from `ip` within `limits` (see the module docs).
fn admit(table: &Conns, limits: &HttpLimits, ip: IpAddr, now: Instant) -> Admission {
    let mut t = lock(table);
    if t.conns.iter().filter(|c| c.ip == ip).count() >= limits.max_per_peer.min(limits.max_connections) {
        return Err("per-address limit reached");
    }
    let mut closed = None;
    if t.conns.len() >= limits.max_connections {
        if !t.steady(ip, now) {
            return Err("connection limit reached");
        }
        let victim = (0..t.conns.len())
            .filter(|&i| !t.conns[i].head_done && !t.steady(t.conns[i].ip, now))
            .min_by_key(|&i| t.conns[i].opened);
        let Some(i) = victim else {
            return Err("connection limit reached, every connection is a steady scraper's or being answered");
        };
        let c = t.conns.swap_remove(i);
        if let Some(a) = c.abort {
            a.abort();
        }
        closed = Some(c.ip);
    }
    let id = t.next_id;
    t.next_id += 1;
    t.conns.push(Conn { id, ip, opened: now, head_done: false, abort: None });
    Ok((Slot { table: table.clone(), id, ip }, closed))
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
                            if let Some(c) = lock(&table).conns.iter_mut().find(|c| c.id == id) {
                                c.abort = Some(abort);
                            }
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
mod tests {
    use super::*;

    #[test]
    fn routes() {
        let r = |s: &str| route(s.as_bytes());
        assert_eq!(r("GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n"), Route::Metrics { head: false });
        assert_eq!(r("GET /metrics?x=1 HTTP/1.0\n\n"), Route::Metrics { head: false });
        assert_eq!(r("HEAD /metrics HTTP/1.1\r\n\r\n"), Route::Metrics { head: true });
        assert_eq!(r("POST /metrics HTTP/1.1\r\n\r\n"), Route::Error(405));
        assert_eq!(r("DELETE /metrics HTTP/1.1\r\n\r\n"), Route::Error(405));
        assert_eq!(r("GET / HTTP/1.1\r\n\r\n"), Route::Error(404));
        assert_eq!(r("GET /metricsx HTTP/1.1\r\n\r\n"), Route::Error(404));
        assert_eq!(r("POST /other HTTP/1.1\r\n\r\n"), Route::Error(404));
        for bad in [
            "",
            "\r\n\r\n",
            "GET\r\n\r\n",
            "GET /metrics\r\n\r\n",
            "GET /metrics HTTP/2\r\n\r\n",
            "get /metrics HTTP/1.1\r\n\r\n",
            "GET metrics HTTP/1.1\r\n\r\n",
            "GET  /metrics HTTP/1.1\r\n\r\n",
            "GET /metrics HTTP/1.1 x\r\n\r\n",
        ] {
            assert_eq!(r(bad), Route::Error(400), "{bad:?}");
        }
        assert_eq!(route(b"GET /\xff\xfe HTTP/1.1\r\n\r\n"), Route::Error(400));
    }

    #[test]
    fn head_end_across_reads() {
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n\r\nrest", 0), Some(18));
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n\r\n", 17), Some(18), "terminator split over two reads");
        assert_eq!(head_end(b"GET / HTTP/1.1\n\n", 0), Some(16));
        assert_eq!(head_end(b"GET / HTTP/1.1\r\n", 0), None);
    }

    #[tokio::test]
    async fn oversized_and_truncated_heads() {
        let mut buf = Box::new([0u8; MAX_HEAD]);
        let big = vec![b'A'; MAX_HEAD + 10];
        assert_eq!(read_head(&mut big.as_slice(), &mut buf).await, Head::TooLarge);
        assert_eq!(read_head(&mut &b"GET /metrics HTTP/1.1\r\n"[..], &mut buf).await, Head::Closed);
        assert_eq!(read_head(&mut &b"GET /metrics HTTP/1.1\r\n\r\n"[..], &mut buf).await, Head::Complete(25));
    }

    /// Connects from `ip` (any 127/8 address reaches a loopback listener on Linux).
    async fn connect_from(ip: [u8; 4], to: SocketAddr) -> tokio::net::TcpStream {
        let sock = tokio::net::TcpSocket::new_v4().expect("socket");
        sock.bind(SocketAddr::from((ip, 0))).expect("bind source");
        sock.connect(to).await.expect("connect")
    }

    /// Whether the server closes `s` without an answer (after a complete request).
    async fn closed_unanswered(mut s: tokio::net::TcpStream) -> bool {
        let _ = s.write_all(b"GET /metrics HTTP/1.1\r\n\r\n").await;
        let mut buf = Vec::new();
        let r = tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf)).await;
        matches!(r, Ok(Ok(0)) | Ok(Err(_)))
    }

    /// Serves on a loopback port within `limits`; the shared state and the stop signal.
    async fn start(limits: HttpLimits) -> (SocketAddr, Arc<Shared>, tokio::sync::oneshot::Sender<()>) {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("addr");
        let shared = Arc::new(Shared::new(String::new(), 16));
        let ctx = Ctx {
            shared: shared.clone(),
            bank: Arc::new(RegisterBank::new()),
            stale_after: Duration::from_secs(5),
            header_timeout: limits.header_timeout,
        };
        let (stop, rx) = tokio::sync::oneshot::channel::<()>();
        tokio::spawn(serve(listener, limits, ctx, async move {
            let _ = rx.await;
        }));
        (addr, shared, stop)
    }

    fn limits(max_connections: usize, max_per_peer: usize) -> HttpLimits {
        HttpLimits {
            max_connections,
            max_per_peer,
            header_timeout: Duration::from_secs(5),
            allow: AllowList::default(),
        }
    }

    /// Whether a scrape from `ip` is answered 200.
    async fn scraped(ip: [u8; 4], addr: SocketAddr) -> bool {
        let mut s = connect_from(ip, addr).await;
        let _ = s.write_all(b"GET /metrics HTTP/1.1\r\n\r\n").await;
        let mut buf = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf)).await;
        buf.starts_with(b"HTTP/1.1 200 OK\r\n")
    }

    #[tokio::test]
    async fn connection_limits_per_peer_and_in_all() {
        let (addr, shared, _stop) = start(limits(4, 2)).await;
        // One address: 2 held open, the next one from it is refused.
        let mut held = Vec::new();
        for _ in 0..2 {
            held.push(connect_from([127, 0, 0, 1], addr).await);
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
        assert!(closed_unanswered(connect_from([127, 0, 0, 1], addr).await).await, "per-address limit");
        // Another address still gets in, up to the total.
        for _ in 0..2 {
            held.push(connect_from([127, 0, 0, 2], addr).await);
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
        assert!(closed_unanswered(connect_from([127, 0, 0, 3], addr).await).await, "total limit");
        assert_eq!(shared.metrics.refused.load(Ordering::Relaxed), 2);
        // Freed slots serve again.
        drop(held);
        tokio::time::sleep(Duration::from_millis(50)).await;
        assert!(scraped([127, 0, 0, 3], addr).await);
        assert_eq!(shared.metrics.aborted.load(Ordering::Relaxed), 4, "the held connections");
    }

    #[tokio::test]
    async fn a_steady_scraper_closes_a_stalling_connection_for_its_own() {
        let (addr, shared, _stop) = start(limits(4, 2)).await;
        for _ in 0..PRIORITY_SCRAPES {
            assert!(scraped([127, 0, 0, 1], addr).await, "before the stall");
        }
        // Every slot held by heads that never complete, from more hosts than the slots.
        let mut stalls = Vec::new();
        for host in 2..=5u8 {
            for _ in 0..2 {
                let mut s = connect_from([127, 0, 0, host], addr).await;
                let _ = s.write_all(b"GET /metrics HTTP/1.1\r\n").await;
                stalls.push(s);
            }
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
        assert!(closed_unanswered(connect_from([127, 0, 0, 6], addr).await).await, "a newcomer is refused");
        for i in 0..5 {
            assert!(scraped([127, 0, 0, 1], addr).await, "steady scrape {i} during the stall");
        }
        // 5 refused at accept (the stalls over the total, the newcomer), at least one stall closed
        // for the scraper (later scrapes may find the slot of the previous one free).
        let refused = shared.metrics.refused.load(Ordering::Relaxed);
        assert!((6..=10).contains(&refused), "{refused}");
    }

    #[tokio::test]
    async fn allow_list_refuses_others() {
        let allow = AllowList::parse(&["127.0.0.2".into()]).expect("allow");
        let (addr, shared, _stop) = start(HttpLimits { allow, ..limits(4, 2) }).await;
        assert!(closed_unanswered(connect_from([127, 0, 0, 1], addr).await).await);
        assert!(!closed_unanswered(connect_from([127, 0, 0, 2], addr).await).await);
        assert_eq!(shared.metrics.refused.load(Ordering::Relaxed), 1);
    }

    #[test]
    fn responses_carry_length_and_type() {
        let r = String::from_utf8(response(200, "abc\n", false)).unwrap_or_default();
        assert!(r.starts_with("HTTP/1.1 200 OK\r\n"), "{r}");
        assert!(r.contains("Content-Type: text/plain; version=0.0.4; charset=utf-8\r\n"), "{r}");
        assert!(r.contains("Content-Length: 4\r\n") && r.ends_with("\r\n\r\nabc\n"), "{r}");
        let h = String::from_utf8(response(200, "abc\n", true)).unwrap_or_default();
        assert!(h.contains("Content-Length: 4\r\n") && h.ends_with("\r\n\r\n"), "HEAD: no body: {h}");
        let e = String::from_utf8(response(405, "no\n", false)).unwrap_or_default();
        assert!(e.starts_with("HTTP/1.1 405 Method Not Allowed\r\n") && e.contains("Allow: GET, HEAD\r\n"), "{e}");
    }
}
