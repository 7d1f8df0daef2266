//! MQTT telemetry against a real broker (docs/mqtt.md): every test starts its own Mosquitto on a
//! free loopback port with its own config file in a temp dir, and kills it at the end. A subscriber
//! checks every message against the documented JSON schema while `fme run` runs on the bundled
//! recording; the retained "online"; the Last Will after SIGKILL; a 10 s broker outage (queue
//! delivered after the reconnect, the rest dropped and counted, the Modbus heartbeat never stalls,
//! "offline" on a clean stop); a wrong password (status bit 9, one log line, backoff, recovery once
//! the password file is fixed); TLS with a CA made at test time, a broker that requires a client
//! certificate, and a broker certificate from another CA (status bit 9); a slow link (a delaying
//! proxy, 700 ms round trip) that must connect, deliver and open one TCP connection per attempt,
//! also while the broker behind it is down and then up, and ending each attempt after
//! `connect_timeout_s` on a link slower than that.
//!
//! Mosquitto comes from Debian's package (`make setup`); without it these tests fail, naming it.

#[path = "mqtt/broker.rs"]
mod broker;
#[path = "mqtt/delay_proxy.rs"]
mod delay_proxy;
#[path = "mqtt/slow_link.rs"]
mod slow_link;
#[path = "daemon/support.rs"]
mod support;
#[path = "mqtt/tls.rs"]
mod tls;

use broker::{Broker, Msg, Sub, free_port, mosquitto_program};
use delay_proxy::DelayProxy;
use fme::backoff::Backoff;
use fme::capture::{FrameSource, RecordedSource};
use fme::config::Config;
use fme::output::mqtt::MqttSender;
use fme::output::{StatusBits, Update};
use fme::pipeline::ScaleSource;
use fme::service::{Daemon, RunOptions};
use fme::status::{MqttLink, Shared};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio_modbus::prelude::*;

/// Waits up to `limit` for `cond`; returns whether it became true.
async fn wait_for(limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let end = Instant::now() + limit;
    while Instant::now() < end {
        if cond() {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    cond()
}

/// The status bits by name, in bit order, as documented in docs/mqtt.md.
const STATUS_NAMES: [&str; 11] = [
    "running",
    "camera_ok",
    "detector_ok",
    "depth_calibrated",
    "stale",
    "plc_link_ok",
    "too_few_fish",
    "record_fault",
    "scale_from_fish",
    "telemetry_fault",
    "unlike_fish",
];
const FAULTS: [&str; 8] =
    ["none", "camera", "detector", "depth", "pipeline_stalled", "plc_link", "stopped", "unlike_fish"];

fn keys(v: &Value) -> Vec<&str> {
    let mut k: Vec<&str> = v.as_object().map(|o| o.keys().map(String::as_str).collect()).unwrap_or_default();
    k.sort_unstable();
    k
}

fn check_time(v: &Value) -> Result<(), String> {
    let t = v["time"].as_str().ok_or("time: not a string")?;
    let b = t.as_bytes();
    let ok = b.len() == 24 && b[4] == b'-' && b[10] == b'T' && b[19] == b'.' && b[23] == b'Z';
    if ok { Ok(()) } else { Err(format!("time: not YYYY-MM-DDThh:mm:ss.sssZ: {t}")) }
}

fn number_or_null(v: &Value, k: &str) -> Result<(), String> {
    if v[k].is_number() || v[k].is_null() { Ok(()) } else { Err(format!("{k}: not a number or null: {}", v[k])) }
}

/// The `activity` schema of docs/mqtt.md.
fn check_activity(v: &Value, box_id: &str) -> Result<(), String> {
    let mut want = vec![
        "bls",
        "box_id",
        "ci95_mps",
        "fault",
        "fault_code",
        "feeding",
        "mean_mps",
        "n_fish",
        "seq",
        "smoothed_mps",
        "status",
        "status_bits",
        "time",
    ];
    want.sort_unstable();
    if keys(v) != want {
        return Err(format!("keys {:?}, want {want:?}", keys(v)));
    }
    check_time(v)?;
    if v["box_id"] != box_id {
        return Err(format!("box_id {}", v["box_id"]));
    }
    for k in ["mean_mps", "smoothed_mps", "ci95_mps", "bls"] {
        number_or_null(v, k)?;
    }
    v["seq"].as_u64().filter(|s| *s >= 1).ok_or("seq: not a whole number >= 1")?;
    v["n_fish"].as_u64().ok_or("n_fish: not a whole number")?;
    let bits = v["status_bits"].as_u64().filter(|b| *b < 1 << 10).ok_or("status_bits: not 0..1024")?;
    let mut names: Vec<&str> = STATUS_NAMES.to_vec();
    names.sort_unstable();
    if keys(&v["status"]) != names {
        return Err(format!("status keys {:?}", keys(&v["status"])));
    }
    for (i, n) in STATUS_NAMES.iter().enumerate() {
        if v["status"][n].as_bool() != Some(bits & (1 << i) != 0) {
            return Err(format!("status.{n} disagrees with status_bits {bits}"));
        }
    }
    let code = v["fault_code"].as_u64().ok_or("fault_code: not a whole number")? as usize;
    if FAULTS.get(code).copied() != v["fault"].as_str() {
        return Err(format!("fault {} does not name code {code}", v["fault"]));
    }
    v["feeding"].as_bool().ok_or("feeding: not a bool")?;
    Ok(())
}

/// The `event` schema of docs/mqtt.md.
fn check_event(v: &Value, box_id: &str) -> Result<(), String> {
    check_time(v)?;
    if v["box_id"] != box_id {
        return Err(format!("box_id {}", v["box_id"]));
    }
    let mut want = match v["event"].as_str() {
        Some("feeding_on" | "feeding_off") => {
            number_or_null(v, "smoothed_mps")?;
            let on = v["feeding"].as_bool().ok_or("feeding: not a bool")?;
            if on != (v["event"] == "feeding_on") {
                return Err("feeding disagrees with the event".into());
            }
            vec!["box_id", "event", "feeding", "smoothed_mps", "time"]
        }
        Some("fault_raised" | "fault_cleared") => {
            let code = v["fault_code"].as_u64().ok_or("fault_code")? as usize;
            if code == 0 || FAULTS.get(code).copied() != v["fault"].as_str() {
                return Err(format!("fault {} / code {code}", v["fault"]));
            }
            vec!["box_id", "event", "fault", "fault_code", "time"]
        }
        Some("scale_source") => {
            for k in ["from", "to"] {
                if !matches!(v[k].as_str(), Some("references" | "fish")) {
                    return Err(format!("{k}: {}", v[k]));
                }
            }
            vec!["box_id", "event", "from", "time", "to"]
        }
        _ => return Err(format!("event: unknown {}", v["event"])),
    };
    want.sort_unstable();
    if keys(v) != want { Err(format!("keys {:?}, want {want:?}", keys(v))) } else { Ok(()) }
}

/// The `config` schema of docs/mqtt.md.
fn check_config(v: &Value, box_id: &str) -> Result<(), String> {
    if keys(v) != ["box_id", "build", "config", "depth_form", "detector_form", "version"] {
        return Err(format!("keys {:?}", keys(v)));
    }
    if v["box_id"] != box_id || !v["version"].is_string() {
        return Err("box_id or version".into());
    }
    // The bundled int8 pair the default configuration names, run by ONNX Runtime.
    if v["build"] != fme::infer::backend::BUILD || v["detector_form"] != "int8-qdq" || v["depth_form"] != "int8-qdq" {
        return Err("build, detector_form or depth_form".into());
    }
    let c: Config = serde_json::from_value(v["config"].clone()).map_err(|e| format!("config: {e}"))?;
    if !c.output.mqtt.enabled {
        return Err("config: output.mqtt.enabled must be true in the effective config".into());
    }
    Ok(())
}

/// Checks every message of box `box_id` under `prefix` against the schema; returns the activity
/// sequence numbers in arrival order.
fn check_all(msgs: &[Msg], prefix: &str, box_id: &str) -> Vec<u64> {
    let base = format!("{prefix}/{box_id}/");
    let mut seqs = Vec::new();
    for m in msgs {
        let leaf = m.topic.strip_prefix(&base).unwrap_or_else(|| panic!("unexpected topic {}", m.topic));
        if leaf == "status" {
            assert!(m.payload == "online" || m.payload == "offline", "status payload {:?}", m.payload);
            continue;
        }
        let v: Value =
            serde_json::from_str(&m.payload).unwrap_or_else(|e| panic!("{}: not JSON ({e}): {}", m.topic, m.payload));
        let r = match leaf {
            "activity" => {
                seqs.push(v["seq"].as_u64().unwrap_or(0));
                check_activity(&v, box_id)
            }
            "event" => check_event(&v, box_id),
            "config" => check_config(&v, box_id),
            other => Err(format!("unknown topic leaf {other}")),
        };
        if let Err(e) = r {
            panic!("{}: {e}\n{}", m.topic, m.payload);
        }
    }
    seqs
}

fn mqtt_sets(port: u16, prefix: &str, box_id: &str) -> Vec<String> {
    vec![
        "output.mqtt.enabled=true".into(),
        format!("output.mqtt.broker=\"127.0.0.1:{port}\""),
        format!("output.mqtt.prefix=\"{prefix}\""),
        format!("output.mqtt.box_id=\"{box_id}\""),
    ]
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fme_run_publishes_documented_json_retained_online_and_last_will() {
    let broker = Broker::start("");
    let sub = Sub::start(broker.port, "sub-schema", "t1/#", true);
    tokio::time::sleep(Duration::from_millis(300)).await; // subscribed before the box starts
    let secret = "s3cret-Pw-not-for-logs";
    let pw = broker.dir.path().join("mqtt.pass");
    std::fs::write(&pw, format!("{secret}\n")).expect("write password file");
    let mut sets = mqtt_sets(broker.port, "t1", "box1");
    sets.extend([
        "output.modbus.listen=\"127.0.0.1:0\"".to_string(),
        "output.rate_hz=4.0".into(),
        "service.systemd_notify=false".into(),
        // Feeding turns on at the first value: a feeding_on event.
        "feeding.on_above_mps=0.0".into(),
        "feeding.off_below_mps=0.0".into(),
        "feeding.min_off_s=0.0".into(),
        "output.mqtt.username=\"box1\"".into(),
        format!("output.mqtt.password_file=\"{}\"", pw.display()),
    ]);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fme"));
    cmd.env_remove("NOTIFY_SOCKET").env_remove("WATCHDOG_USEC").env("RUST_LOG", "info");
    cmd.args(["run", "--config", "config/fme.toml", "--source", "tests/data/swarm20"]);
    for s in &sets {
        cmd.arg("--set").arg(s);
    }
    let err_path = broker.dir.path().join("fme.stderr");
    cmd.stdout(Stdio::null()).stderr(std::fs::File::create(&err_path).expect("stderr file"));
    let mut child = cmd.spawn().expect("spawn fme run");
    let enough = wait_for(Duration::from_secs(30), || {
        sub.on("t1/box1/activity").len() >= 8 && !sub.on("t1/box1/event").is_empty()
    })
    .await;
    let stderr = || std::fs::read_to_string(&err_path).unwrap_or_default();
    if !enough {
        let _ = child.kill();
        panic!("no 8 activity messages and an event within 30 s: {:?}\n{}", sub.all(), stderr());
    }
    // A subscriber that comes later gets the retained status and config.
    let late = Sub::start(broker.port, "sub-late", "t1/+/status", true);
    assert!(
        wait_for(Duration::from_secs(5), || late.all().iter().any(|m| m.retain && m.payload == "online")).await,
        "retained online: {:?}",
        late.all()
    );
    let _ = child.kill(); // SIGKILL: no goodbye, the broker publishes the Last Will
    let _ = child.wait();
    assert!(
        wait_for(Duration::from_secs(5), || sub.on("t1/box1/status").last().is_some_and(|m| m.payload == "offline"))
            .await,
        "Last Will offline after SIGKILL: {:?}",
        sub.on("t1/box1/status")
    );
    let after = Sub::start(broker.port, "sub-after", "t1/+/status", true);
    assert!(
        wait_for(Duration::from_secs(5), || after.all().iter().any(|m| m.retain && m.payload == "offline")).await,
        "the Last Will is retained: {:?}",
        after.all()
    );

    let msgs = sub.all();
    let seqs = check_all(&msgs, "t1", "box1");
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1), "no gap while connected: {seqs:?}");
    assert_eq!(sub.on("t1/box1/status").first().map(|m| m.payload.as_str()), Some("online"));
    let configs = sub.on("t1/box1/config");
    assert_eq!(configs.len(), 1, "one config per connect");
    let v: Value = serde_json::from_str(&configs[0].payload).expect("config JSON");
    assert_eq!(v["config"]["output"]["mqtt"]["password_file"], pw.display().to_string(), "the file, not the password");
    let events = sub.on("t1/box1/event");
    assert!(events.iter().any(|m| m.payload.contains("\"feeding_on\"")), "{events:?}");
    for m in &msgs {
        assert!(!m.payload.contains(secret), "the password must never be published: {}", m.topic);
    }
    let err = stderr();
    assert!(err.contains("mqtt: connected to"), "{err}");
    assert!(!err.contains(secret), "the password must never be logged");
}

fn daemon_config(seq: &Path, port: u16, prefix: &str, box_id: &str) -> Config {
    let mut c = support::test_config(seq);
    c.output.rate_hz = 5.0;
    let m = &mut c.output.mqtt;
    m.enabled = true;
    m.broker = format!("127.0.0.1:{port}");
    m.prefix = prefix.into();
    m.box_id = box_id.into();
    m.reconnect_min_ms = 300;
    m.reconnect_max_ms = 1000;
    m.keepalive_s = 5;
    c
}

async fn start_daemon(cfg: Config, seq: &Path) -> Daemon {
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(seq, true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start")
}

async fn read_regs(ctx: &mut tokio_modbus::client::Context) -> Vec<u16> {
    tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(0, 24))
        .await
        .expect("modbus read timed out")
        .expect("transport")
        .expect("exception")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn broker_outage_queue_delivered_rest_dropped_heartbeat_runs_then_offline() {
    // Persistence keeps the subscriber's session (and what the broker queued for it) over the restart.
    let mut broker = Broker::start("persistence true\npersistence_location {dir}/\n");
    let sub = Sub::start(broker.port, "sub-outage", "t2/#", false);
    let seq = tempfile::tempdir().expect("tempdir");
    support::write_sequence(seq.path(), 60, 160, 96, 30);
    let mut cfg = daemon_config(seq.path(), broker.port, "t2", "box2");
    cfg.output.mqtt.queue_messages = 20;
    let daemon = start_daemon(cfg, seq.path()).await;
    let shared = daemon.shared().clone();
    let mut ctx = tcp::connect_slave(daemon.modbus_addr().expect("modbus"), Slave(1)).await.expect("connect");
    assert!(
        wait_for(Duration::from_secs(10), || shared.health().mqtt.published >= 5).await,
        "published before the outage: {:?}",
        shared.health().mqtt
    );

    broker.stop();
    let mut heartbeats = Vec::new();
    for _ in 0..20 {
        tokio::time::sleep(Duration::from_millis(500)).await;
        heartbeats.push(read_regs(&mut ctx).await[12]);
    }
    let during = shared.health().mqtt;
    assert!(heartbeats.windows(2).all(|w| w[1] != w[0]), "the heartbeat never stalls: {heartbeats:?}");
    assert_ne!(during.link, MqttLink::Connected);
    assert_eq!(during.queued, 20, "the queue is full: {during:?}");
    assert!(during.dropped >= 10, "10 s at 5 Hz into a queue of 20: the oldest are dropped: {during:?}");

    broker.restart();
    assert!(
        wait_for(Duration::from_secs(10), || {
            let m = shared.health().mqtt;
            // Every message of the full queue (20) waited for the broker: all are delivered.
            m.link == MqttLink::Connected && m.reconnects >= 1 && m.queued == 0 && m.delivered_after_reconnect >= 20
        })
        .await,
        "reconnect and deliver: {:?}\n{}",
        shared.health().mqtt,
        broker.log()
    );
    let after = shared.health().mqtt;
    assert!(
        after.delivered_after_reconnect <= 20 + 16,
        "the 20 queued and at most the 16 unacknowledged in flight: {after:?}"
    );
    let text = fme::console::mqtt_text(&after, fme::history::now_unix_ms());
    assert!(text.contains("link connected") && text.contains(&format!("dropped {}", after.dropped)), "{text}");

    // The subscriber sees the delivered messages; what it misses was dropped (and counted).
    let last_seq = |s: &Sub| check_all(&s.all(), "t2", "box2").into_iter().max().unwrap_or(0);
    let target = last_seq(&sub) + 5;
    assert!(wait_for(Duration::from_secs(10), || last_seq(&sub) >= target).await, "messages flow again");
    let mut seqs = check_all(&sub.all(), "t2", "box2");
    seqs.sort_unstable();
    seqs.dedup();
    let missing = seqs.last().copied().unwrap_or(0) - seqs.len() as u64;
    let dropped = shared.health().mqtt.dropped;
    eprintln!("outage: {after:?}; subscriber missed {missing} seqs, dropped {dropped}; heartbeats {heartbeats:?}");
    // `dropped` also counts events (rare here: a fault or feeding change), so allow a few.
    assert!(missing >= 10 && missing <= dropped && dropped <= missing + 3, "missed {missing} seqs, dropped {dropped}");

    // Clean stop: "offline" from the box itself (retained), before it disconnects.
    daemon.shutdown().await;
    assert!(
        wait_for(Duration::from_secs(5), || sub.on("t2/box2/status").last().is_some_and(|m| m.payload == "offline"))
            .await,
        "{:?}",
        sub.on("t2/box2/status")
    );
    assert!(shared.last_logs(50).iter().any(|l| l.contains("status offline published")), "{:?}", shared.last_logs(50));
}

fn write_password_file(dir: &Path, user: &str, password: &str) -> PathBuf {
    let p = dir.join("passwd");
    let out = Command::new(mosquitto_program("mosquitto_passwd"))
        .args(["-c", "-b"])
        .arg(&p)
        .args([user, password])
        .output()
        .expect("run mosquitto_passwd");
    assert!(out.status.success(), "mosquitto_passwd: {}", String::from_utf8_lossy(&out.stderr));
    p
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn wrong_password_sets_bit_9_logs_once_backs_off_and_recovers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let users = write_password_file(dir.path(), "box3", "right-pw-3");
    // A client that gives a user name is checked against the file (allow_anonymous only lets in
    // clients that give none).
    let broker = Broker::start(&format!("password_file {}\n", users.display()));
    let seq = tempfile::tempdir().expect("tempdir");
    support::write_sequence(seq.path(), 40, 160, 96, 30);
    let mut cfg = daemon_config(seq.path(), broker.port, "t3", "box3");
    let pw = dir.path().join("box3.pass");
    std::fs::write(&pw, "wrong-pw-3\n").expect("write");
    cfg.output.mqtt.username = "box3".into();
    cfg.output.mqtt.password_file = pw.clone();
    cfg.output.mqtt.reconnect_min_ms = 500;
    cfg.output.mqtt.reconnect_max_ms = 1000;
    let daemon = start_daemon(cfg, seq.path()).await;
    let shared = daemon.shared().clone();
    let mut ctx = tcp::connect_slave(daemon.modbus_addr().expect("modbus"), Slave(1)).await.expect("connect");
    tokio::time::sleep(Duration::from_secs(4)).await;
    let m = shared.health().mqtt;
    assert_eq!(m.link, MqttLink::AuthFailed, "{m:?}");
    assert!((2..=8).contains(&m.connect_attempts), "backoff, no busy loop: {m:?}");
    let regs = read_regs(&mut ctx).await;
    assert_ne!(regs[10] & StatusBits::TELEMETRY_FAULT.bits(), 0, "status bit 9 set");
    assert_ne!(regs[10] & StatusBits::RUNNING.bits(), 0, "the daemon keeps running");
    let logs = shared.last_logs(200);
    let refused: Vec<_> = logs.iter().filter(|l| l.contains("refused the login")).collect();
    assert_eq!(refused.len(), 1, "one line, not one per attempt: {logs:?}");
    assert!(logs.iter().all(|l| !l.contains("wrong-pw-3")), "the password is never logged");
    assert!(fme::console::mqtt_text(&m, 0).contains("link auth_failed"));

    // The technician fixes the password file: the next attempt logs in, bit 9 clears.
    std::fs::write(&pw, "right-pw-3\n").expect("write");
    assert!(
        wait_for(Duration::from_secs(5), || shared.health().mqtt.link == MqttLink::Connected).await,
        "{:?}",
        shared.health().mqtt
    );
    tokio::time::sleep(Duration::from_millis(500)).await;
    assert_eq!(read_regs(&mut ctx).await[10] & StatusBits::TELEMETRY_FAULT.bits(), 0, "bit 9 clears");
    daemon.shutdown().await;
}
