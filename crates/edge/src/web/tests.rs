use super::request::{Head, head_end, read_head};
use super::*;
use crate::config::allow::AllowList;
use std::sync::atomic::Ordering;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

/// The status code of a raw request sent to the metrics listener at `addr` (0: closed unanswered).
async fn code_of(addr: SocketAddr, raw: &[u8]) -> (u16, String) {
    let mut s = connect_from([127, 0, 0, 1], addr).await;
    let _ = s.write_all(raw).await;
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(5), s.read_to_end(&mut buf)).await;
    let text = String::from_utf8_lossy(&buf).into_owned();
    let code = text.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0);
    (code, text)
}

#[tokio::test]
async fn routes() {
    let (addr, _shared, _stop) = start(limits(8, 8)).await;
    let r = |s: &'static str| code_of(addr, s.as_bytes());
    assert_eq!(r("GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n").await.0, 200);
    assert_eq!(r("GET /metrics?x=1 HTTP/1.0\n\n").await.0, 200);
    assert_eq!(r("HEAD /metrics HTTP/1.1\r\n\r\n").await.0, 200);
    assert_eq!(r("POST /metrics HTTP/1.1\r\n\r\n").await.0, 405);
    assert_eq!(r("DELETE /metrics HTTP/1.1\r\n\r\n").await.0, 405);
    assert_eq!(r("GET / HTTP/1.1\r\n\r\n").await.0, 404);
    assert_eq!(r("GET /metricsx HTTP/1.1\r\n\r\n").await.0, 404);
    assert_eq!(r("POST /other HTTP/1.1\r\n\r\n").await.0, 404);
    for bad in [
        "\r\n\r\n",
        "GET\r\n\r\n",
        "GET /metrics\r\n\r\n",
        "GET /metrics HTTP/2\r\n\r\n",
        "get /metrics HTTP/1.1\r\n\r\n",
        "GET metrics HTTP/1.1\r\n\r\n",
        "GET  /metrics HTTP/1.1\r\n\r\n",
        "GET /metrics HTTP/1.1 x\r\n\r\n",
    ] {
        assert_eq!(r(bad).await.0, 400, "{bad:?}");
    }
    assert!(!request_line_ok(b""));
    assert_eq!(code_of(addr, b"GET /\xff\xfe HTTP/1.1\r\n\r\n").await.0, 400);
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
    let mut len = 0;
    let big = vec![b'A'; MAX_HEAD + 10];
    assert_eq!(read_head(&mut big.as_slice(), &mut buf, &mut len).await, Head::TooLarge);
    assert_eq!(read_head(&mut &b"GET /metrics HTTP/1.1\r\n"[..], &mut buf, &mut len).await, Head::Closed);
    assert_eq!(read_head(&mut &b"GET /metrics HTTP/1.1\r\n\r\n"[..], &mut buf, &mut len).await, Head::Complete(25));
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

/// Serves the metrics listener on a loopback port within `limits`; the shared state and the task.
async fn start(limits: HttpLimits) -> (SocketAddr, Arc<Shared>, tokio::task::JoinHandle<()>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.expect("bind");
    let addr = listener.local_addr().expect("addr");
    let shared = Arc::new(Shared::new(String::new(), 16));
    let cfg = Config::default();
    let state = Arc::new(WebState::new(&cfg, Duration::from_secs(5), &shared, &Arc::new(RegisterBank::new())));
    let ctx = ConnCtx {
        kind: Kind::Metrics,
        state: state.clone(),
        router: routes::metrics_only(state),
        header_timeout: limits.header_timeout,
        tls: None,
    };
    let task = tokio::spawn(listener::serve(listener, limits, Arc::new(ctx)));
    (addr, shared, task)
}

fn limits(max_connections: usize, max_per_peer: usize) -> HttpLimits {
    HttpLimits { max_connections, max_per_peer, header_timeout: Duration::from_secs(5), allow: AllowList::default() }
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

#[tokio::test]
async fn responses_carry_length_and_type() {
    let (addr, _shared, _stop) = start(limits(8, 8)).await;
    let (code, r) = code_of(addr, b"GET /metrics HTTP/1.1\r\n\r\n").await;
    assert_eq!(code, 200, "{r}");
    assert!(r.starts_with("HTTP/1.1 200 OK\r\n"), "{r}");
    assert!(r.contains("Content-Type: text/plain; version=0.0.4; charset=utf-8\r\n"), "{r}");
    let (head, body) = r.split_once("\r\n\r\n").unwrap_or_default();
    assert!(head.contains(&format!("Content-Length: {}", body.len())), "{r}");
    let (_, h) = code_of(addr, b"HEAD /metrics HTTP/1.1\r\n\r\n").await;
    assert!(h.contains("Content-Length: ") && h.ends_with("\r\n\r\n"), "HEAD: no body: {h}");
    let (code, e) = code_of(addr, b"POST /metrics HTTP/1.1\r\nContent-Length: 2\r\n\r\nno").await;
    assert!(
        code == 405 && e.starts_with("HTTP/1.1 405 Method Not Allowed\r\n") && e.contains("Allow: GET, HEAD\r\n"),
        "{e}"
    );
}
