//! The field console over a pseudo-terminal pair, inside a running daemon: commands answer, fuzzed
//! input (binary noise, over-long lines, garbage) gets error lines and never kills the daemon.

use crate::support;

use fme::capture::{FrameSource, RecordedSource};
use fme::service::{Daemon, RunOptions};
use serialport::SerialPort;
use std::io::{Read as _, Write as _};
use std::time::{Duration, Instant};

/// Reads until the reply to one command is complete (a line `OK` or `ERR ...`) or 5 s pass.
pub(crate) fn reply(port: &mut dyn SerialPort, acc: &mut String) -> String {
    let end = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 512];
    loop {
        if let Some(i) = acc
            .find("OK\r\n")
            .or_else(|| acc.find("ERR "))
            .map(|i| acc[i..].find("\r\n").map_or(acc.len(), |j| i + j + 2))
        {
            let out = acc[..i].to_string();
            acc.drain(..i);
            return out;
        }
        assert!(Instant::now() < end, "no complete reply; got so far: {acc:?}");
        match port.read(&mut buf) {
            Ok(n) => acc.push_str(&String::from_utf8_lossy(&buf[..n])),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => panic!("read: {e}"),
        }
    }
}

/// Waits up to 5 s for the greeting the console sends when it opens the device, then clears `acc`.
pub(crate) fn greeting(port: &mut dyn SerialPort, acc: &mut String) {
    let end = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 256];
    while !acc.contains("console ready") {
        assert!(Instant::now() < end, "no greeting: {acc:?}");
        if let Ok(n) = port.read(&mut buf) {
            acc.push_str(&String::from_utf8_lossy(&buf[..n]));
        }
    }
    acc.clear();
}

/// Sends a command; returns the reply without the echoed command line.
pub(crate) fn ask(port: &mut dyn SerialPort, acc: &mut String, cmd: &str) -> String {
    port.write_all(cmd.as_bytes()).expect("write");
    port.write_all(b"\r\n").expect("write");
    let r = reply(port, acc);
    let echo = format!("{cmd}\r\n");
    // Streamed lines may come before the echo; everything else follows it.
    assert!(r.contains(&echo), "typed characters are echoed: {r:?}");
    r.replacen(&echo, "", 1)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn console_commands_and_fuzz() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 30, 96, 64, 30);
    let (mut master, slave) = serialport::TTYPort::pair().expect("pty pair");
    master.set_timeout(Duration::from_millis(100)).expect("timeout");
    let mut cfg = support::test_config(dir.path());
    cfg.console.enabled = true;
    cfg.console.device = slave.name().expect("pty name");
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, "[source]\nrealtime = true\n".into(), source, pipeline, RunOptions::default())
        .await
        .expect("start");
    let shared = daemon.shared().clone();

    let result = tokio::task::spawn_blocking(move || {
        let port: &mut dyn SerialPort = &mut master;
        let mut acc = String::new();
        greeting(port, &mut acc);
        std::thread::sleep(Duration::from_millis(400)); // let a few samples through
        let v = ask(port, &mut acc, "VERSION");
        assert!(v.contains(env!("CARGO_PKG_VERSION")) && v.ends_with("OK\r\n"), "{v:?}");
        let s = ask(port, &mut acc, "status");
        assert!(s.contains("state running") && s.contains("camera_ok"), "{s:?}");
        let a = ask(port, &mut acc, "Activity");
        assert!(a.starts_with("activity ") && a.contains(" m/s"), "{a:?}");
        let r = ask(port, &mut acc, "regs");
        assert!(r.contains("heartbeat") && r.contains("hr100-103"), "{r:?}");
        let c = ask(port, &mut acc, "counters");
        assert!(c.contains("frames-processed") && c.contains("latency-p99"), "{c:?}");
        let l = ask(port, &mut acc, "log 3");
        let logged = l.lines().filter(|x| !x.trim().is_empty() && x.trim() != "OK").count();
        assert!((1..=3).contains(&logged), "at most the 3 newest log lines, and the start-up ones exist: {l:?}");
        assert!(ask(port, &mut acc, "calib").contains("not calibrated"));
        assert!(ask(port, &mut acc, "tracks").starts_with("tracks "));
        assert!(ask(port, &mut acc, "config").contains("realtime = true"));
        assert!(ask(port, &mut acc, "help").contains("stream on|off"));
        assert!(ask(port, &mut acc, "reboot").starts_with("ERR unknown command"));
        let st = ask(port, &mut acc, "stream on");
        assert!(st.ends_with("OK\r\n"));
        std::thread::sleep(Duration::from_millis(500));
        let streamed = ask(port, &mut acc, "stream off");
        assert!(streamed.matches("activity ").count() >= 2, "stream prints updates: {streamed:?}");

        // Fuzz: 64 KiB of pseudo-random bytes (xorshift), including CR/LF, NUL, 0xFF, huge lines.
        let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
        let mut junk = Vec::with_capacity(65_536);
        for i in 0..65_536 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            junk.push(if i % 4000 == 3999 { b'\n' } else { (x >> 24) as u8 });
        }
        let mut drain = [0u8; 8192];
        let mut drain_all = |port: &mut dyn SerialPort, acc: &mut String| {
            // Read until the console has been quiet for one port timeout (100 ms).
            while let Ok(n) = port.read(&mut drain) {
                if n == 0 {
                    break;
                }
                acc.push_str(&String::from_utf8_lossy(&drain[..n]));
            }
        };
        for chunk in junk.chunks(2048) {
            port.write_all(chunk).expect("write junk");
            drain_all(port, &mut acc); // keep the pty buffers from filling
        }
        for _ in 0..5 {
            port.write_all(&[b'x'; 1000]).expect("long line");
            drain_all(port, &mut acc);
        }
        port.write_all(b"\r\n\r\n").expect("write");
        drain_all(port, &mut acc);
        assert!(acc.contains("ERR"), "fuzz must get error lines");
        acc.clear();
        let v = ask(port, &mut acc, "version");
        assert!(
            v.contains(env!("CARGO_PKG_VERSION")) && v.contains(fme::infer::backend::BUILD),
            "console still answers after fuzz, naming the backend: {v:?}"
        );
    })
    .await;
    drop(slave);
    let h = shared.health();
    assert!(h.frames_processed > 0);
    daemon.shutdown().await;
    if let Err(e) = result {
        std::panic::resume_unwind(e.into_panic());
    }
}

/// What the technician sees comes from one update: the live view's values and flags from one
/// published block (not a newer frame's count beside the block's flags), the `tracks` count from the
/// rows it lists, `history` on a new box says there is none, `regs` decodes each register.
#[test]
fn each_view_shows_one_update_and_regs_are_decoded() {
    use fme::output::{StatusBits, Update};
    let (mut master, slave) = serialport::TTYPort::pair().expect("pty pair");
    master.set_timeout(Duration::from_millis(100)).expect("timeout");
    let shared = std::sync::Arc::new(fme::status::Shared::new(String::new(), 50));
    let bank = std::sync::Arc::new(fme::output::bank::RegisterBank::new());
    // The published update: 5 fish, too few of them, heartbeat 7.
    let published = Update {
        mean_mps: 0.2,
        mean_bls: 0.8,
        smoothed_mps: 0.19,
        ci95_half_mps: 0.02,
        fish: 5,
        status: StatusBits::RUNNING | StatusBits::CAMERA_OK | StatusBits::TOO_FEW_FISH,
        heartbeat: 7,
        ..Update::default()
    };
    bank.publish_update(&published, fme::config::WordOrder::HighFirst);
    // A newer frame the block does not hold yet (18 fish, no flag), and the track list of the last
    // update (3 rows) beside a per-frame count of 23.
    shared.with_health(|h| {
        h.last_sample = Some(fme::pipeline::ActivitySample {
            timestamp: fme::units::Seconds(9.0),
            mean: fme::units::MetresPerSecond(0.31),
            mean_body_lengths: 1.2,
            smoothed: fme::units::MetresPerSecond(0.3),
            ci95_half: fme::units::MetresPerSecond(0.01),
            fish: 18,
            latency: fme::units::Seconds(0.0),
            flags: fme::pipeline::QualityFlags::default(),
            scale: fme::pipeline::ScaleSource::References,
        });
        h.last_sample_at = Some(Instant::now());
        h.stage.tracks = 23;
        h.fish = (1..=3)
            .map(|id| fme::motion::Fish {
                id,
                last_seen: fme::units::Seconds(8.9),
                bbox: fme::geometry::PixelBox::from_center(fme::geometry::Pixel::new(10.0, 10.0), 5.0, 3.0),
                depth_measured: None,
                depth: None,
                position: None,
                speed: None,
                length: None,
            })
            .collect();
    });
    let hist = tempfile::tempdir().expect("tempdir");
    shared.history.set_dir(hist.path());
    let name = slave.name().expect("pty name");
    let (sh, bk) = (shared.clone(), bank.clone());
    let console = std::thread::spawn(move || fme::console::run_on_device(&name, 115_200, true, &sh, &bk));

    let port: &mut dyn SerialPort = &mut master;
    let mut acc = String::new();
    greeting(port, &mut acc);
    let a = ask(port, &mut acc, "activity");
    assert!(a.contains("fish 5 ") && a.contains("too_few_fish") && a.contains("activity 0.200 m/s"), "{a:?}");
    assert!(!a.contains("fish 18") && !a.contains(" fault "), "{a:?}");
    let t = ask(port, &mut acc, "tracks");
    let lines: Vec<&str> = t.lines().filter(|l| !l.is_empty() && *l != "OK").collect();
    assert_eq!(lines[0], "tracks 3", "{t:?}");
    assert_eq!(lines.len(), 4, "the count and its rows: {t:?}");
    let h = ask(port, &mut acc, "history");
    assert!(h.starts_with("no history yet"), "{h:?}");
    assert_eq!(h.lines().count(), 2, "one line and OK, no hours of zeros: {h:?}");
    let r = ask(port, &mut acc, "regs");
    let row =
        |name: &str| r.lines().find(|l| l.split_whitespace().nth(1) == Some(name)).unwrap_or_default().to_string();
    assert!(row("activity_mean").contains("0x3e4c 0xcccd") && row("activity_mean").ends_with("0.2000 m/s"), "{r}");
    assert!(row("fish").contains("0x0005") && row("fish").ends_with(" 5"), "{r}");
    assert!(row("status").ends_with("running camera_ok too_few_fish"), "{r}");
    assert!(row("fault").ends_with("none") && row("heartbeat").ends_with(" 7"), "{r}");
    assert!(row("value_age").ends_with("0.0 s"), "{r}");
    shared.request_stop();
    console.join().expect("the console thread ends");
    drop(slave);
}

/// A terminal that stops reading (a stalled socat relay, a frozen screen) must not stall the
/// console: it keeps reading input, drops and counts the output, and answers again once the
/// terminal reads.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stalled_reader_never_blocks_the_console() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 30, 96, 64, 30);
    let (mut master, slave) = serialport::TTYPort::pair().expect("pty pair");
    master.set_timeout(Duration::from_millis(100)).expect("timeout");
    let mut cfg = support::test_config(dir.path());
    cfg.console.enabled = true;
    cfg.console.device = slave.name().expect("pty name");
    let source: Box<dyn FrameSource> = Box::new(RecordedSource::open(dir.path(), true, true).expect("open"));
    let pipeline = support::edge_pipeline(&cfg);
    let daemon = Daemon::start(cfg, String::new(), source, pipeline, RunOptions::default()).await.expect("start");
    let shared = daemon.shared().clone();

    let result = tokio::task::spawn_blocking(move || {
        let mut acc = String::new();
        let end = Instant::now() + Duration::from_secs(5);
        let mut buf = [0u8; 4096];
        while !acc.contains("console ready") {
            assert!(Instant::now() < end, "no greeting: {acc:?}");
            if let Ok(n) = master.read(&mut buf) {
                acc.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        }
        acc.clear();
        let dropped_before = fme::console::writer::output_dropped();
        // Stall: ~140 KB of replies asked for and ~64 KB of input typed, nothing read back. The
        // writes only complete if the console keeps reading its input; a blocked console would
        // leave them hanging (checked with a deadline on another thread).
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut ok = true;
            for _ in 0..200 {
                ok &= master.write_all(b"help\r\n").is_ok();
            }
            let junk = [b"x".repeat(60), b"\r\n".to_vec()].concat();
            for _ in 0..1000 {
                ok &= master.write_all(&junk).is_ok();
            }
            let _ = tx.send((ok, master));
        });
        let (ok, mut master) = rx.recv_timeout(Duration::from_secs(30)).expect("the console stopped reading its input");
        assert!(ok, "every write reached the console");
        let dropped = fme::console::writer::output_dropped() - dropped_before;
        assert!(dropped > 50_000, "output the terminal did not read is dropped and counted: {dropped}");
        // The terminal reads again: the console catches up, says what was lost and answers.
        let end = Instant::now() + Duration::from_secs(10);
        while !acc.contains("bytes of output dropped: the terminal was not reading]") {
            assert!(Instant::now() < end, "no note of the dropped output: {:?}", &acc[acc.len().saturating_sub(300)..]);
            if let Ok(n) = master.read(&mut buf) {
                acc.push_str(&String::from_utf8_lossy(&buf[..n]));
            }
        }
        // Let the console finish the input still queued, then talk to it.
        let mut quiet_since = Instant::now();
        while quiet_since.elapsed() < Duration::from_millis(500) {
            assert!(Instant::now() < end, "the console never went quiet");
            if let Ok(n) = master.read(&mut buf)
                && n > 0
            {
                quiet_since = Instant::now();
            }
        }
        acc.clear();
        let port: &mut dyn SerialPort = &mut master;
        let v = ask(port, &mut acc, "version");
        assert!(v.contains(env!("CARGO_PKG_VERSION")), "answers after the stall: {v:?}");
        let c = ask(port, &mut acc, "counters");
        assert!(c.contains("console-output-dropped "), "{c:?}");
    })
    .await;
    drop(slave);
    assert!(shared.last_logs(50).iter().any(|l| l.contains("terminal is not reading")), "the stall is logged");
    daemon.shutdown().await;
    if let Err(e) = result {
        std::panic::resume_unwind(e.into_panic());
    }
}
