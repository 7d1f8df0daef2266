//! End to end: recorded sequence -> daemon -> in-process Modbus TCP client.

use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::config::WordOrder;
use fme::output::registers::{FaultCode, StatusBits, decode_f32, join_u32};
use fme::service::{Daemon, RunOptions};
use std::time::Duration;
use tokio_modbus::prelude::*;

async fn read_block(ctx: &mut tokio_modbus::client::Context) -> Vec<u16> {
    tokio::time::timeout(Duration::from_secs(2), ctx.read_input_registers(0, 24))
        .await
        .expect("read timed out")
        .expect("transport")
        .expect("exception")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn recorded_sequence_to_modbus_client() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 40, 160, 96, 30);
    let cfg = support::test_config(dir.path());
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let addr = daemon.modbus_addr().expect("tcp server address");
    let mut ctx = tcp::connect_slave(addr, Slave(1)).await.expect("connect");

    let mut heartbeats = Vec::new();
    let mut means = Vec::new();
    let mut last = Vec::new();
    for _ in 0..15 {
        tokio::time::sleep(Duration::from_millis(120)).await;
        let r = read_block(&mut ctx).await;
        heartbeats.push(r[12]);
        let m = decode_f32([r[0], r[1]], WordOrder::HighFirst);
        if m.is_finite() {
            means.push(m);
        }
        last = r;
    }
    assert!(heartbeats.windows(2).all(|w| w[1] >= w[0]), "heartbeat must not go back: {heartbeats:?}");
    assert!(heartbeats.last() > heartbeats.first(), "heartbeat must increment: {heartbeats:?}");
    assert!(means.len() >= 10, "values must be available: {means:?}");
    assert!(means.iter().all(|m| (0.0..10.0).contains(m)), "plausible values: {means:?}");
    assert!(means.windows(2).any(|w| w[0] != w[1]), "values must change: {means:?}");
    assert_eq!(
        last[10] & ((StatusBits::RUNNING | StatusBits::CAMERA_OK).bits()),
        (StatusBits::RUNNING | StatusBits::CAMERA_OK).bits()
    );
    assert_ne!(last[10] & StatusBits::PLC_LINK_OK.bits(), 0, "we are polling: link bit set");
    assert_eq!(last[11], FaultCode::None as u16);
    assert!(join_u32([last[13], last[14]], WordOrder::HighFirst) < 60);
    assert!((150..=450).contains(&last[15]), "camera fps x10 near 300: {}", last[15]);
    let holding = ctx.read_holding_registers(0, 24).await.expect("transport").expect("exception");
    assert_eq!(holding[18..20], last[18..20], "holding registers mirror input registers");

    // Shutdown: the "stopped" block is served before the server goes away.
    let stopper = tokio::spawn(daemon.shutdown());
    let mut saw_stopped = false;
    for _ in 0..20 {
        tokio::time::sleep(Duration::from_millis(20)).await;
        if let Ok(Ok(Ok(r))) = tokio::time::timeout(Duration::from_millis(200), ctx.read_input_registers(0, 24)).await
            && r[10] & StatusBits::RUNNING.bits() == 0
        {
            assert_eq!(r[11], FaultCode::Stopped as u16);
            assert_eq!(r[17], 0, "no feeding recommendation when stopped");
            saw_stopped = true;
            break;
        }
    }
    assert!(saw_stopped, "the PLC must be able to read status stopped");
    let t0 = std::time::Instant::now();
    tokio::time::timeout(Duration::from_secs(2), stopper).await.expect("shutdown within 2 s").expect("join");
    assert!(t0.elapsed() < Duration::from_secs(2));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn finite_recording_as_fast_as_possible_finishes() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 25, 96, 64, 30);
    let mut cfg = support::test_config(dir.path());
    cfg.output.modbus.mode = fme::config::ModbusMode::Off;
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), false, false).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let mut daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let normal =
        tokio::time::timeout(Duration::from_secs(20), daemon.finished()).await.expect("finishes at end of recording");
    assert!(normal, "normal end, not a dead pipeline thread");
    let h = daemon.shared().health();
    assert_eq!(h.frames_captured, 25);
    assert_eq!(h.frames_processed, 25, "an unpaced replay is back-pressured: every frame processed");
    assert_eq!(h.frames_dropped, 0);
    assert!(h.updates >= 2, "output at 10 Hz on the frame clock over 0.8 s of video: {}", h.updates);
    daemon.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn serial_line_output_over_pty() {
    use std::io::Read;
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 20, 64, 48, 30);
    let (mut logger, line_end) = serialport::TTYPort::pair().expect("pty pair");
    serialport::SerialPort::set_timeout(&mut logger, Duration::from_millis(100)).expect("timeout");
    let mut cfg = support::test_config(dir.path());
    cfg.output.modbus.mode = fme::config::ModbusMode::Off;
    cfg.output.serial.enabled = true;
    cfg.output.serial.device = serialport::SerialPort::name(&line_end).expect("pty name");
    let src: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let daemon = Daemon::start(cfg.clone(), String::new(), src, support::edge_pipeline(&cfg), RunOptions::default())
        .await
        .expect("start");
    let text = tokio::task::spawn_blocking(move || {
        let mut acc = String::new();
        let mut buf = [0u8; 1024];
        let end = std::time::Instant::now() + Duration::from_secs(3);
        while std::time::Instant::now() < end && acc.matches("\r\n").count() < 6 {
            if let Ok(n) = logger.read(&mut buf) {
                acc.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        }
        acc
    })
    .await
    .expect("join");
    daemon.shutdown().await;
    drop(line_end);
    let lines: Vec<&str> = text.split("\r\n").filter(|l| l.starts_with('$')).collect();
    assert!(lines.len() >= 5, "one line per update: {text:?}");
    let mut last_hb = None;
    for l in &lines {
        let f = fme::output::serial_line::parse_line(l).unwrap_or_else(|| panic!("bad checksum or format: {l:?}"));
        assert_eq!(f[0], "FME");
        assert_eq!(f.len(), 11);
        let hb: u32 = f[1].parse().expect("heartbeat");
        if let Some(p) = last_hb {
            assert!(hb > p, "heartbeat increases: {lines:?}");
        }
        last_hb = Some(hb);
    }
}

/// A stage that panics on some frames (e.g. a decoder bug on a corrupt frame).
struct PanicsSometimes(u32);

impl fme::pipeline::Pipeline for PanicsSometimes {
    fn process(
        &mut self,
        frame: &fme::capture::Frame,
    ) -> Result<fme::pipeline::FrameOutcome<'_>, fme::pipeline::PipelineError> {
        self.0 += 1;
        if self.0.is_multiple_of(3) {
            panic!("corrupt frame {}", frame.seq);
        }
        Ok(fme::pipeline::FrameOutcome::sample_only(None, self.health()))
    }
    fn health(&self) -> fme::pipeline::StageHealth {
        fme::pipeline::StageHealth::default()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn panicking_stage_is_counted_not_fatal() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 30, 64, 48, 30);
    let mut cfg = support::test_config(dir.path());
    cfg.output.modbus.mode = fme::config::ModbusMode::Off;
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), false, false).expect("open"));
    let mut daemon = Daemon::start(cfg, String::new(), source, Box::new(PanicsSometimes(0)), RunOptions::default())
        .await
        .expect("start");
    let normal = tokio::time::timeout(Duration::from_secs(20), daemon.finished()).await.expect("finishes");
    assert!(normal, "the pipeline thread survived the panics");
    let h = daemon.shared().health();
    assert_eq!(h.frames_processed, 30);
    assert_eq!(h.pipeline_errors, 10);
    assert!(daemon.shared().last_logs(50).iter().any(|l| l.contains("panicked: corrupt frame")));
    daemon.shutdown().await;
}
