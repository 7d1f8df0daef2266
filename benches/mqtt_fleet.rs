//! A farm's fleet through one broker (docs/mqtt.md, docs/benchmarks.md): one process simulates
//! `MQTT_BENCH_BOXES` boxes (default 50), each publishing its `activity` JSON (the daemon's own
//! builder, [`fme::output::mqtt::activity_json`]) at 1 Hz with QoS 1 for `MQTT_BENCH_S` seconds
//! (default 60) through one local Mosquitto started here on a free loopback port; one subscriber
//! receives everything. Prints messages/s received, messages lost, the broker's CPU (utime + stime
//! of /proc/PID/stat over the run) and the end-to-end latency (publish call -> subscriber) p50/p99.
//!
//! `make bench-mqtt` (needs Debian's mosquitto: `make setup`). A benchmark, not a test.

use fme::output::{StatusBits, Update};
use rumqttc::{AsyncClient, Event, MqttOptions, Packet, QoS};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

#[path = "support/broker.rs"]
mod broker;

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// utime + stime of a process, s.
fn cpu_s(pid: u32) -> f64 {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else { return f64::NAN };
    // Fields after the command name (which may hold spaces) start at field 3.
    let Some(rest) = stat.rfind(')').map(|i| &stat[i + 2..]) else { return f64::NAN };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN);
    // SAFETY: sysconf has no preconditions.
    let hz = unsafe { libc::sysconf(libc::_SC_CLK_TCK) } as f64;
    (ticks(11) + ticks(12)) / hz // utime, stime (fields 14, 15)
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((q * sorted.len() as f64).ceil() as usize).clamp(1, sorted.len()) - 1]
}

/// Send instants per box and sequence number.
type Sent = Arc<Mutex<Vec<Vec<Option<Instant>>>>>;

fn main() {
    let boxes = env_or("MQTT_BENCH_BOXES", 50) as usize;
    let secs = env_or("MQTT_BENCH_S", 60);
    let broker = broker::Broker::start("mqtt_fleet");
    let port = broker.port;
    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().expect("runtime");
    let sent: Sent = Arc::new(Mutex::new(vec![vec![None; secs as usize + 1]; boxes]));
    let latencies = Arc::new(Mutex::new(Vec::<f64>::with_capacity(boxes * secs as usize)));
    let received = rt.block_on(async {
        // The subscriber.
        let mut o = MqttOptions::new("fleet-sub", "127.0.0.1", port);
        o.set_keep_alive(Duration::from_secs(30));
        let (sub, mut el) = AsyncClient::new(o, 64);
        sub.subscribe("bench/+/activity", QoS::AtLeastOnce).await.expect("subscribe");
        loop {
            if let Event::Incoming(Packet::SubAck(_)) = el.poll().await.expect("subscriber connect") {
                break;
            }
        }
        let (s2, l2) = (sent.clone(), latencies.clone());
        let received = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let r2 = received.clone();
        tokio::spawn(async move {
            while let Ok(ev) = el.poll().await {
                if let Event::Incoming(Packet::Publish(p)) = ev {
                    let now = Instant::now();
                    let Ok(v) = serde_json::from_slice::<serde_json::Value>(&p.payload) else { continue };
                    let b =
                        v["box_id"].as_str().and_then(|s| s.strip_prefix("box")).and_then(|s| s.parse::<usize>().ok());
                    let seq = v["seq"].as_u64().map(|s| s as usize);
                    if let (Some(b), Some(seq)) = (b, seq)
                        && let Some(Some(t)) = s2.lock().expect("lock").get(b).and_then(|v| v.get(seq)).copied()
                    {
                        l2.lock().expect("lock").push(now.duration_since(t).as_secs_f64() * 1000.0);
                    }
                    r2.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
            }
        });
        received
    });
    let cpu0 = cpu_s(broker.child.id());
    let t0 = Instant::now();
    let published = rt.block_on(async {
        let mut tasks = Vec::new();
        for b in 0..boxes {
            let sent = sent.clone();
            tasks.push(tokio::spawn(async move {
                let id = format!("box{b:02}");
                let mut o = MqttOptions::new(id.clone(), "127.0.0.1", port);
                o.set_keep_alive(Duration::from_secs(30));
                let (client, mut el) = AsyncClient::new(o, 16);
                let pump = tokio::spawn(async move { while el.poll().await.is_ok() {} });
                // Spread the boxes over the second, as real boxes started at different times are.
                tokio::time::sleep(Duration::from_millis((b as u64 * 1000) / boxes as u64)).await;
                let mut tick = tokio::time::interval(Duration::from_secs(1));
                let mut json = String::with_capacity(512);
                let mut n = 0u64;
                for seq in 1..=secs {
                    tick.tick().await;
                    let row = Update {
                        unix_ms: fme::history::now_unix_ms(),
                        mean_mps: 0.1 + 0.001 * seq as f64,
                        smoothed_mps: 0.1,
                        ci95_half_mps: 0.01,
                        fish: 20,
                        mean_bls: 0.4,
                        status: StatusBits::from_word(0b1111),
                        scale: fme::pipeline::ScaleSource::References,
                        ..Update::default()
                    };
                    json.clear();
                    fme::output::mqtt::activity_json(&id, seq, &row, &mut json);
                    sent.lock().expect("lock")[b][seq as usize] = Some(Instant::now());
                    if client
                        .publish(format!("bench/{id}/activity"), QoS::AtLeastOnce, false, json.clone())
                        .await
                        .is_ok()
                    {
                        n += 1;
                    }
                }
                tokio::time::sleep(Duration::from_secs(2)).await;
                let _ = client.disconnect().await;
                tokio::time::sleep(Duration::from_millis(200)).await;
                pump.abort();
                n
            }));
        }
        let mut total = 0;
        for t in tasks {
            total += t.await.unwrap_or(0);
        }
        total
    });
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu_s(broker.child.id()) - cpu0;
    let got = received.load(std::sync::atomic::Ordering::Relaxed);
    drop(broker);
    let mut lat = latencies.lock().expect("lock").clone();
    lat.sort_by(f64::total_cmp);
    println!("mqtt_fleet: {boxes} boxes x 1 Hz x {secs} s, QoS 1, one local mosquitto, one subscriber");
    println!("  published {published}, received {got}, lost {}", published.saturating_sub(got));
    println!(
        "  {:.1} messages/s received (received / {secs} s; the run took {wall:.1} s with the 1 s start spread and 2 s drain)",
        got as f64 / secs as f64
    );
    println!("  broker CPU {:.2} s = {:.2} % of one core", cpu, 100.0 * cpu / wall);
    println!(
        "  end-to-end latency p50 {:.2} ms p99 {:.2} ms max {:.2} ms ({} samples)",
        quantile(&lat, 0.5),
        quantile(&lat, 0.99),
        lat.last().copied().unwrap_or(f64::NAN),
        lat.len()
    );
}
