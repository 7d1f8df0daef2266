//! The web server in process on a fake state (no pipeline, no camera) and the raw-socket clients of
//! a LAN, shared by the web tests (`#[path]`-included).
#![allow(dead_code)]

use fme::config::Config;
use fme::output::bank::RegisterBank;
use fme::status::Shared;
use fme::web::routes::RouteLimits;
use fme::web::{WebServer, WebState};
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _};
use tokio::net::{TcpSocket, TcpStream};

/// A running server, its `[web] listen` address and the state it reads.
pub struct Fixture {
    pub server: WebServer,
    pub addr: SocketAddr,
    pub shared: Arc<Shared>,
    pub bank: Arc<RegisterBank>,
}

/// Serves `[web]` on a loopback port with `tweak` applied to the default configuration; `None`
/// when the server does not start (e.g. unusable TLS files).
pub async fn start(tweak: impl FnOnce(&mut Config)) -> Option<Fixture> {
    start_with_token(None, tweak).await
}

/// As [`start`], with the actions' token (`None`: actions refused).
pub async fn start_with_token(token: Option<&str>, tweak: impl FnOnce(&mut Config)) -> Option<Fixture> {
    let mut cfg = Config::default();
    cfg.web.listen = "127.0.0.1:0".into();
    tweak(&mut cfg);
    let shared = Arc::new(Shared::new(String::new(), 64));
    let bank = Arc::new(RegisterBank::new());
    let state = WebState {
        shared: shared.clone(),
        bank: bank.clone(),
        stale_after: Duration::from_secs(5),
        token: token.map(str::to_string),
        feeding: (0.3, 0.2),
        source: "tests/data/swarm20".into(),
        limits: RouteLimits::from_config(&cfg.web),
    };
    let server = fme::web::spawn_with(&cfg, Arc::new(state)).await?;
    let addr = server.web_addr?;
    Some(Fixture { server, addr, shared, bank })
}

/// A TCP connection from a chosen loopback address (127.0.0.0/8 is all local on Linux); `None`
/// when it cannot be made within 2 s.
pub async fn connect_from(from: &str, to: SocketAddr) -> Option<TcpStream> {
    let s = TcpSocket::new_v4().ok()?;
    s.bind(format!("{from}:0").parse().ok()?).ok()?;
    tokio::time::timeout(Duration::from_secs(2), s.connect(to)).await.ok()?.ok()
}

/// Writes `raw` on `s` and reads the answer to the end (at most 5 s): (code, head, body); code 0
/// when nothing parseable came back.
pub async fn exchange<S: AsyncRead + AsyncWrite + Unpin>(s: &mut S, raw: &[u8]) -> (u16, String, Vec<u8>) {
    let _ = s.write_all(raw).await;
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf)).await;
    let split = buf.windows(4).position(|w| w == b"\r\n\r\n").map_or(buf.len(), |i| i + 4);
    let head = String::from_utf8_lossy(&buf[..split]).into_owned();
    let code = head.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0);
    (code, head, buf[split..].to_vec())
}

/// A `GET path` with `Connection: close`.
pub fn get(path: &str) -> Vec<u8> {
    format!("GET {path} HTTP/1.1\r\nHost: box\r\nConnection: close\r\n\r\n").into_bytes()
}

/// The code of `GET path` from 127.0.0.1 over plain HTTP (0: no answer).
pub async fn get_code(addr: SocketAddr, path: &str) -> u16 {
    match connect_from("127.0.0.1", addr).await {
        Some(mut s) => exchange(&mut s, &get(path)).await.0,
        None => 0,
    }
}

/// One slowloris connection loop from `from`: a `GET path` request line, then one header byte every
/// 100 ms, a new connection as soon as the server closes or answers this one; until `stop`.
pub async fn slowloris(from: &'static str, addr: SocketAddr, path: &str, stop: Arc<std::sync::atomic::AtomicBool>) {
    use std::sync::atomic::Ordering;
    while !stop.load(Ordering::Relaxed) {
        let Some(mut s) = connect_from(from, addr).await else {
            tokio::time::sleep(Duration::from_millis(20)).await;
            continue;
        };
        let mut ok = s.write_all(format!("GET {path} HTTP/1.1\r\nX-Slow: ").as_bytes()).await.is_ok();
        while ok && !stop.load(Ordering::Relaxed) {
            tokio::time::sleep(Duration::from_millis(100)).await;
            ok = s.write_all(b"a").await.is_ok();
            let mut b = [0u8; 64];
            if tokio::time::timeout(Duration::from_millis(1), s.read(&mut b)).await.is_ok() {
                ok = false;
            }
        }
    }
}

/// Sends `raw` from `from` on a new connection, again and again (each answer read or 1 s waited),
/// until `stop`: a client of huge heads or garbage.
pub async fn repeat(from: &'static str, addr: SocketAddr, raw: Vec<u8>, stop: Arc<std::sync::atomic::AtomicBool>) {
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        let Some(mut s) = connect_from(from, addr).await else {
            tokio::time::sleep(Duration::from_millis(20)).await;
            continue;
        };
        let _ = s.write_all(&raw).await;
        let mut b = [0u8; 256];
        let _ = tokio::time::timeout(Duration::from_secs(1), s.read(&mut b)).await;
    }
}
