//! A slow link (satellite, 4G) between the box and the broker, through the delaying proxy.

use super::*;

/// The box's MQTT part alone (no pipeline) publishing to `127.0.0.1:port`, with a backoff of
/// `min_ms` doubling to `max_ms`.
fn slow_link_config(port: u16, prefix: &str, box_id: &str, min_ms: u64, max_ms: u64) -> Config {
    let mut c = Config::default();
    let m = &mut c.output.mqtt;
    m.enabled = true;
    m.broker = format!("127.0.0.1:{port}");
    m.prefix = prefix.into();
    m.box_id = box_id.into();
    m.reconnect_min_ms = min_ms;
    m.reconnect_max_ms = max_ms;
    c
}

/// One output update, stamped now.
fn update() -> Update {
    Update {
        unix_ms: fme::history::now_unix_ms(),
        mean_mps: 0.12,
        smoothed_mps: 0.11,
        ci95_half_mps: 0.01,
        fish: 9,
        mean_bls: 0.4,
        status: StatusBits::RUNNING,
        scale: ScaleSource::References,
        ..Update::default()
    }
}

/// Sends an update every 200 ms (5 Hz) until `cond` holds or `limit` passes; returns whether it held.
async fn feed_until(tx: &mut MqttSender, limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let end = Instant::now() + limit;
    while Instant::now() < end {
        if cond() {
            return true;
        }
        tx.send(update());
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    cond()
}

/// The most connection attempts a box can start within `elapsed`: the first at once, each next one
/// at least one backoff step (`min_ms` doubling to `max_ms`) after the previous one.
fn most_attempts(elapsed: Duration, min_ms: u64, max_ms: u64) -> usize {
    let mut b = Backoff::new(Duration::from_millis(min_ms), Duration::from_millis(max_ms));
    let (mut at, mut n) = (Duration::ZERO, 1);
    loop {
        at += b.next_delay();
        if at > elapsed {
            return n;
        }
        n += 1;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn slow_link_700ms_round_trip_connects_and_delivers_over_one_tcp_connection() {
    let broker = Broker::start("");
    let sub = Sub::start(broker.port, "sub-slow", "t5/#", true);
    // 350 ms each way: the CONNACK comes 700 ms after the CONNECT, like a cage on a satellite link.
    let proxy = DelayProxy::start(broker.port, Duration::from_millis(350)).await;
    tokio::time::sleep(Duration::from_millis(300)).await; // subscribed before the box starts
    let cfg = slow_link_config(proxy.port, "t5", "box5", 500, 4000);
    let shared = Arc::new(Shared::new(String::new(), 50));
    let (mut tx, _thread) = fme::output::mqtt::spawn(&cfg, shared.clone()).expect("spawn");
    let delivered = feed_until(&mut tx, Duration::from_secs(30), || sub.on("t5/box5/activity").len() >= 10).await;
    let m = shared.health().mqtt;
    assert!(
        delivered,
        "10 activity messages within 30 s over a 700 ms round trip: got {}, {} TCP connections, {m:?}",
        sub.on("t5/box5/activity").len(),
        proxy.accepts()
    );
    // Nothing failed, so nothing was retried: one attempt, one TCP connection.
    assert_eq!((proxy.accepts(), m.connect_attempts, m.reconnects), (1, 1, 0), "{m:?}");
    assert_eq!(m.link, MqttLink::Connected);
    let seqs = check_all(&sub.all(), "t5", "box5");
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "in order, no gap: {seqs:?}");
    // A clean stop still says "offline" through the slow link.
    drop(tx);
    assert!(
        wait_for(Duration::from_secs(10), || sub.on("t5/box5/status").last().is_some_and(|m| m.payload == "offline"))
            .await,
        "{:?}",
        sub.on("t5/box5/status")
    );
    assert_eq!(proxy.accepts(), 1, "the stop opens no connection");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broker_down_then_up_behind_a_slow_link_one_connection_per_backoff_step() {
    let (min_ms, max_ms) = (250, 2000);
    let mut broker = Broker::start("");
    broker.stop();
    // The box reaches the proxy at once; the broker behind it is down, so each connection is
    // closed 350 ms later, as a slow link shows a broker that is away.
    let proxy = DelayProxy::start(broker.port, Duration::from_millis(350)).await;
    let cfg = slow_link_config(proxy.port, "t6", "box6", min_ms, max_ms);
    let shared = Arc::new(Shared::new(String::new(), 50));
    let start = Instant::now();
    let (mut tx, _thread) = fme::output::mqtt::spawn(&cfg, shared.clone()).expect("spawn");
    feed_until(&mut tx, Duration::from_secs(6), || false).await;
    let (accepts, down) = (proxy.accepts(), start.elapsed());
    let m = shared.health().mqtt;
    let bound = most_attempts(down, min_ms, max_ms);
    assert!(accepts >= 2, "it keeps trying: {accepts} connections, {m:?}");
    assert!(accepts <= bound, "{accepts} TCP connections in {down:?}; the backoff allows {bound}: {m:?}");
    assert!(accepts as u64 <= m.connect_attempts, "one TCP connection per attempt: {accepts}, {m:?}");
    assert_ne!(m.link, MqttLink::Connected);

    broker.restart();
    let sub = Sub::start(broker.port, "sub-down-up", "t6/#", true);
    // The broker's PUBACKs come a round trip after the subscriber sees the messages.
    let delivered = feed_until(&mut tx, Duration::from_secs(30), || {
        sub.on("t6/box6/activity").len() >= 5 && shared.health().mqtt.delivered_after_reconnect >= 5
    })
    .await;
    let (accepts, total) = (proxy.accepts(), start.elapsed());
    let m = shared.health().mqtt;
    assert!(delivered, "connects once the broker is up and delivers: {accepts} connections, {m:?}\n{}", broker.log());
    let bound = most_attempts(total, min_ms, max_ms);
    assert!(accepts <= bound, "{accepts} TCP connections in {total:?}; the backoff allows {bound}: {m:?}");
    assert_eq!(accepts as u64, m.connect_attempts, "one TCP connection per attempt: {m:?}");
    assert_eq!(m.link, MqttLink::Connected);
    check_all(&sub.all(), "t6", "box6");
    eprintln!("down then up: {accepts} connections in {total:?} (backoff bound {bound}); {m:?}");
}

/// The figures of docs/mqtt.md ("Slow links"): messages delivered and TCP connections in 30 s
/// through the delaying proxy at 300 and 700 ms round trip, with the shipped backoff, 5 updates/s.
/// `cargo test --release --test mqtt -- --ignored --nocapture slow_link_figures`
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "a 60 s measurement, run by hand"]
async fn slow_link_figures_30s() {
    for rtt_ms in [300, 700] {
        let broker = Broker::start("");
        let box_id = format!("fig{rtt_ms}");
        let sub = Sub::start(broker.port, &format!("sub-{box_id}"), "t7/#", true);
        let proxy = DelayProxy::start(broker.port, Duration::from_millis(rtt_ms / 2)).await;
        tokio::time::sleep(Duration::from_millis(300)).await;
        let defaults = fme::config::MqttConfig::default();
        let cfg = slow_link_config(proxy.port, "t7", &box_id, defaults.reconnect_min_ms, defaults.reconnect_max_ms);
        let shared = Arc::new(Shared::new(String::new(), 50));
        let (mut tx, _thread) = fme::output::mqtt::spawn(&cfg, shared.clone()).expect("spawn");
        let start = Instant::now();
        let mut sent = 0;
        while start.elapsed() < Duration::from_secs(30) {
            tx.send(update());
            sent += 1;
            tokio::time::sleep(Duration::from_millis(200)).await;
        }
        let mut seqs = check_all(&sub.all(), "t7", &box_id);
        seqs.sort_unstable();
        seqs.dedup();
        let m = shared.health().mqtt;
        eprintln!(
            "rtt {rtt_ms} ms: {} of {sent} activity messages delivered in 30 s, {} TCP connections, \
             {} connect attempts, link {:?}",
            seqs.len(),
            proxy.accepts(),
            m.connect_attempts,
            m.link
        );
        drop(tx);
        shared.request_stop();
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_link_slower_than_connect_timeout_s_ends_each_attempt_then_backs_off() {
    let (min_ms, max_ms) = (300, 600);
    let broker = Broker::start("");
    // 3 s round trip: no CONNACK within the 1 s allowed.
    let proxy = DelayProxy::start(broker.port, Duration::from_millis(1500)).await;
    let mut cfg = slow_link_config(proxy.port, "t8", "box8", min_ms, max_ms);
    cfg.output.mqtt.connect_timeout_s = 1;
    let shared = Arc::new(Shared::new(String::new(), 50));
    let start = Instant::now();
    let (mut tx, _thread) = fme::output::mqtt::spawn(&cfg, shared.clone()).expect("spawn");
    let timed_out = feed_until(&mut tx, Duration::from_secs(15), || {
        let m = shared.health().mqtt;
        m.connect_attempts >= 3 && m.last_error.contains("no CONNACK within 1 s (output.mqtt.connect_timeout_s)")
    })
    .await;
    let (accepts, elapsed) = (proxy.accepts(), start.elapsed());
    let m = shared.health().mqtt;
    assert!(timed_out, "each attempt ends after connect_timeout_s and says so: {m:?}");
    assert_ne!(m.link, MqttLink::Connected);
    let bound = most_attempts(elapsed, min_ms, max_ms);
    assert!(accepts <= bound, "{accepts} TCP connections in {elapsed:?}; the backoff allows {bound}: {m:?}");
    assert!(accepts as u64 <= m.connect_attempts, "one TCP connection per attempt: {accepts}, {m:?}");
}
