//! The Prometheus endpoint on a hostile LAN: slowloris clients from four addresses (each holding as
//! many connections as it can, a request head trickled a byte at a time, reconnecting whenever the
//! server closes one) do not keep a steady scraper from its answers, with the shipped limits.

#[path = "common/web_lan.rs"]
mod web_lan;

use fme::config::MetricsConfig;
use fme::output::bank::RegisterBank;
use fme::status::Shared;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};
use web_lan::{connect_from, slowloris};

/// Whether one scrape from 127.0.0.1 is answered 200 within 2 s.
async fn scrape(addr: SocketAddr) -> bool {
    let Some(mut s) = connect_from("127.0.0.1", addr).await else { return false };
    if s.write_all(b"GET /metrics HTTP/1.1\r\nHost: fme\r\n\r\n").await.is_err() {
        return false;
    }
    let mut buf = Vec::new();
    let _ = tokio::time::timeout(Duration::from_secs(2), s.read_to_end(&mut buf)).await;
    buf.starts_with(b"HTTP/1.1 200 OK\r\n")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_steady_scraper_is_answered_through_slowloris_from_four_addresses() {
    let metrics = MetricsConfig { listen: "127.0.0.1:0".into(), ..MetricsConfig::default() };
    let mut cfg = fme::config::Config::default();
    cfg.output.metrics = metrics;
    let shared = Arc::new(Shared::new(String::new(), 64));
    let bank = Arc::new(RegisterBank::new());
    let server = fme::web::spawn(&cfg, Duration::from_secs(5), &shared, &bank).await.expect("the endpoint serves");
    let addr = server.metrics_addr.expect("the metrics listener");
    // A scraper that has been scraping steadily.
    for _ in 0..2 {
        assert!(scrape(addr).await, "before the attack");
    }
    let stop = Arc::new(AtomicBool::new(false));
    let mut attackers = Vec::new();
    for host in ["127.0.0.2", "127.0.0.3", "127.0.0.4", "127.0.0.5"] {
        for _ in 0..8 {
            attackers.push(tokio::spawn(slowloris(host, addr, "/metrics", stop.clone())));
        }
    }
    tokio::time::sleep(Duration::from_millis(500)).await; // every slot the attackers can get, taken
    let mut answered = 0;
    for _ in 0..20 {
        if scrape(addr).await {
            answered += 1;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    stop.store(true, Ordering::Relaxed);
    for a in attackers {
        let _ = tokio::time::timeout(Duration::from_secs(3), a).await;
    }
    let refused = shared.metrics.refused.load(Ordering::Relaxed);
    eprintln!("slowloris: {answered} of 20 scrapes answered; {refused} connections refused");
    assert!(answered >= 19, "{answered} of 20 scrapes answered under slowloris ({refused} refused)");
    assert!(refused > 0, "the attack really hit the limits");
    server.stop().await;
}
