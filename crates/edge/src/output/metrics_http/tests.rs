use super::request::head_end;
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
