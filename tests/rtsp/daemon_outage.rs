//! `fme run` on an RTSP camera (GStreamer's server) whose server is killed for 10 s and started
//! again on the same port: the daemon reconnects by itself, and the down time is a camera fault in
//! the Modbus registers, the history file and MQTT, while the heartbeat keeps counting and the
//! process (same pid) runs through.

use crate::broker::{Broker, Sub};
use crate::servers::GstServer;
use crate::support::{Running, free_port, wait_until};
use fme::history::{self, HistoryRow};
use fme::output::registers::{FaultCode, StatusBits};
use serde_json::Value;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use tokio_modbus::prelude::*;

const CAMERA: u16 = FaultCode::Camera as u16;

/// The 24 input registers, or `None` while the daemon does not answer.
async fn registers(ctx: &mut tokio_modbus::client::Context) -> Option<Vec<u16>> {
    match tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(0, 24)).await {
        Ok(Ok(Ok(r))) => Some(r),
        _ => None,
    }
}

fn camera_ok(r: &[u16]) -> bool {
    r[10] & StatusBits::CAMERA_OK.bits() != 0
}

/// `fme run` on `url` with its registers on `modbus`, history in `hist`, MQTT to `broker`.
fn fme_run(url: &str, modbus: u16, hist: &std::path::Path, broker: u16, stderr: std::fs::File) -> Running {
    let sets = [
        "service.systemd_notify=false".to_string(),
        "output.rate_hz=4.0".into(),
        format!("history.dir={:?}", hist.to_string_lossy()),
        "history.fsync_s=0.0".into(),
        // A lost camera is found within a second and tried again at most a second apart.
        "source.timeout_ms=1000".into(),
        "source.reconnect_min_ms=200".into(),
        "source.reconnect_max_ms=1000".into(),
        "output.mqtt.enabled=true".into(),
        format!("output.mqtt.broker=\"127.0.0.1:{broker}\""),
        "output.mqtt.prefix=\"cage\"".into(),
        "output.mqtt.box_id=\"c7\"".into(),
    ];
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_fme"));
    cmd.env_remove("NOTIFY_SOCKET").env_remove("WATCHDOG_USEC").env_remove("STATE_DIRECTORY").env("RUST_LOG", "info");
    cmd.args(["run", "--source", url, "--modbus-listen", &format!("127.0.0.1:{modbus}")]);
    for s in &sets {
        cmd.arg("--set").arg(s);
    }
    Running(cmd.stdout(Stdio::null()).stderr(stderr).spawn().expect("spawn fme run"))
}

/// The fault events (`fault_raised` / `fault_cleared`, fault name) in arrival order.
fn fault_events(sub: &Sub) -> Vec<(String, String)> {
    sub.on("cage/c7/event")
        .iter()
        .filter_map(|m| serde_json::from_str::<Value>(&m.payload).ok())
        .filter_map(|v| Some((v["event"].as_str()?.to_string(), v["fault"].as_str()?.to_string())))
        .filter(|(e, _)| e.starts_with("fault_"))
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fme_run_rides_out_a_10_s_server_outage_as_a_camera_fault_everywhere() {
    let broker = Broker::start("");
    let sub = Sub::start(broker.port, "sub-outage", "cage/#", true);
    let server = GstServer::start(0);
    let (port, modbus) = (server.port, free_port());
    let dir = tempfile::tempdir().expect("tempdir");
    let (hist, err_path) = (dir.path().join("history"), dir.path().join("fme.stderr"));
    let stderr = std::fs::File::create(&err_path).expect("stderr file");
    let mut daemon = fme_run(&server.url("/h264"), modbus, &hist, broker.port, stderr);
    let log = || std::fs::read_to_string(&err_path).unwrap_or_default();
    let pid = daemon.0.id();
    // Start-up loads the models: wait for the registers, then for the camera.
    let t0 = Instant::now();
    let mut ctx = loop {
        if let Ok(c) = tcp::connect_slave(([127, 0, 0, 1], modbus).into(), Slave(1)).await {
            break c;
        }
        assert!(daemon.0.try_wait().ok().flatten().is_none() && t0.elapsed().as_secs() < 60, "{}", log());
        tokio::time::sleep(Duration::from_millis(100)).await;
    };
    let mut streaming = false;
    while !streaming {
        assert!(t0.elapsed().as_secs() < 60, "no frames over RTSP within 60 s: {}", log());
        tokio::time::sleep(Duration::from_millis(100)).await;
        streaming = registers(&mut ctx).await.is_some_and(|r| camera_ok(&r) && r[11] == 0);
    }
    let up_ms = history::now_unix_ms();
    tokio::time::sleep(Duration::from_secs(1)).await;

    // The server goes away for 10 s.
    let killed_ms = history::now_unix_ms();
    drop(server);
    let killed = Instant::now();
    let mut faulted_ms = None;
    let mut heartbeats = Vec::new();
    while killed.elapsed() < Duration::from_secs(10) {
        tokio::time::sleep(Duration::from_millis(250)).await;
        let r = registers(&mut ctx).await.expect("the registers answer while the camera is down");
        heartbeats.push(r[12]);
        if r[11] == CAMERA && !camera_ok(&r) {
            faulted_ms.get_or_insert(history::now_unix_ms());
        } else {
            assert!(faulted_ms.is_none(), "the fault stays while the server is down: {r:?}");
        }
    }
    let faulted_ms = faulted_ms.expect("camera fault (register 11 = 1, bit 1 clear) while the server is down");
    assert!(faulted_ms - killed_ms < 3000, "fault {} ms after the server went", faulted_ms - killed_ms);
    // Updates follow the frames; without frames they go on at the daemon's own pace (2 Hz): the
    // heartbeat never stops for a second and never jumps.
    let steps: Vec<u16> = heartbeats.windows(2).map(|w| w[1].wrapping_sub(w[0])).collect();
    let counting = steps.iter().all(|s| *s <= 3) && steps.windows(4).all(|w| w.iter().any(|s| *s > 0));
    assert!(counting && steps.iter().map(|s| u32::from(*s)).sum::<u32>() >= 10, "heartbeat: {heartbeats:?}");
    assert!(daemon.0.try_wait().ok().flatten().is_none(), "fme run still runs: {}", log());

    // Back on the same port: the daemon reconnects by itself.
    let restarted_ms = history::now_unix_ms();
    let _server = GstServer::start(port);
    let mut back = false;
    while !back {
        assert!(history::now_unix_ms() - restarted_ms < 15_000, "no frames 15 s after the restart: {}", log());
        tokio::time::sleep(Duration::from_millis(100)).await;
        back = registers(&mut ctx).await.is_some_and(|r| camera_ok(&r) && r[11] == 0);
    }
    let back_ms = history::now_unix_ms();
    wait_until("the fault events over MQTT", 5, || fault_events(&sub).len() >= 2).await;
    tokio::time::sleep(Duration::from_secs(1)).await;
    assert!(daemon.0.try_wait().ok().flatten().is_none() && daemon.0.id() == pid, "the same process runs");
    // SAFETY: kill(2) on our own child's pid.
    unsafe { libc::kill(pid as i32, libc::SIGTERM) };
    let status = daemon.0.wait().expect("wait");
    let log = log();
    assert_eq!(status.code(), Some(0), "a clean stop: {log}");
    assert!(log.contains("camera back: rtsp camera"), "{log}");

    // MQTT: the camera fault raised, then cleared; activity messages of the down time say so.
    let events = fault_events(&sub);
    let camera = |e: &str| (e.to_string(), "camera".to_string());
    assert_eq!(events, vec![camera("fault_raised"), camera("fault_cleared")], "{:?}", sub.on("cage/c7/event"));
    let codes: Vec<u64> = sub
        .on("cage/c7/activity")
        .iter()
        .filter_map(|m| serde_json::from_str::<Value>(&m.payload).ok()?["fault_code"].as_u64())
        .collect();
    assert!(codes.contains(&0) && codes.contains(&1), "activity fault codes: {codes:?}");

    // History: the rows of the down time carry fault 1 and bit 1 clear; before and after, no fault.
    let mut rows: Vec<HistoryRow> = Vec::new();
    for e in std::fs::read_dir(&hist).expect("history dir").flatten() {
        rows.extend(history::read_day_file(&e.path()).unwrap_or_else(|err| panic!("{err}")).rows);
    }
    let camera_bit = StatusBits::CAMERA_OK.bits();
    let down: Vec<&HistoryRow> = rows.iter().filter(|r| (faulted_ms..=restarted_ms).contains(&r.unix_ms)).collect();
    assert!(down.len() >= 12, "{} rows in the 10 s down", down.len());
    assert!(down.iter().all(|r| r.fault == CAMERA && r.status & camera_bit == 0), "down rows: {down:?}");
    let up = |r: &&HistoryRow| (up_ms..killed_ms).contains(&r.unix_ms) || (r.unix_ms > back_ms && r.fault != 6);
    let up_rows: Vec<&HistoryRow> = rows.iter().filter(up).collect();
    assert!(up_rows.iter().filter(|r| r.unix_ms > back_ms).count() >= 2, "rows after the reconnect");
    assert!(up_rows.iter().all(|r| r.fault == 0 && r.status & camera_bit != 0), "rows with the camera: {up_rows:?}");
}
