//! What an open web page costs the daemon (`make bench-daemon`; not a test): `fme run` (the release
//! binary, a child process) replays the bundled `tests/data/swarm20` at 30 fps with `[web] listen`
//! on, and its CPU (utime + stime of `/proc/<pid>/stat`, % of one core) is measured over the same
//! wall span:
//! - `none`: no client;
//! - `client`: one client doing what the Live page does, `GET /api/status` and `GET /api/latest.jpg`
//!   once a second;
//! - `browser`: headless Chromium on `/` (the real page and its JavaScript), when `chromium` is
//!   installed (`make setup`); skipped with a message otherwise.
//!
//! The client's and the browser's own CPU are not counted: only the daemon's process. Rounds
//! alternate the modes so that a change in the machine's load hits them alike.
//!
//! Environment: `FME_BENCH_WEB_S` (measured span per run, default 20 s), `FME_BENCH_WEB_ROUNDS`
//! (default 2), `FME_BENCH_WEB_BROWSER=0` (skip the browser). Run without `--bench` (as
//! `cargo test --all-targets` does) it only smoke-runs: one round of 2 s, no browser.

#[path = "../tests/daemon/support.rs"]
mod support;

use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use support::{Running, free_port};

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Mode {
    None,
    Client,
    Browser,
}

fn env_num(key: &str, default: u64) -> u64 {
    std::env::var(key).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// utime + stime of `pid` in seconds (clock ticks of 100 Hz).
fn cpu_seconds(pid: u32) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            let rest = s.rsplit_once(')')?.1;
            let f: Vec<&str> = rest.split_whitespace().collect();
            Some((f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?) / 100.0)
        })
        .expect("the daemon's /proc/<pid>/stat")
}

/// `GET path` on a new connection: the status code (0: no answer) and the body's length.
fn get(port: u16, path: &str) -> (u16, usize) {
    let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) else { return (0, 0) };
    let _ = s.set_read_timeout(Some(Duration::from_secs(3)));
    let req = format!("GET {path} HTTP/1.1\r\nHost: box\r\nConnection: close\r\n\r\n");
    if s.write_all(req.as_bytes()).is_err() {
        return (0, 0);
    }
    let mut buf = Vec::new();
    let _ = s.read_to_end(&mut buf);
    let code = std::str::from_utf8(buf.get(9..12).unwrap_or_default()).ok().and_then(|c| c.parse().ok());
    (code.unwrap_or(0), buf.len())
}

fn start_fme(state: &Path, web: u16, modbus: u16) -> Running {
    let child = Command::new(env!("CARGO_BIN_EXE_fme"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env("STATE_DIRECTORY", state)
        .args(["run", "--source", "tests/data/swarm20", "--modbus-listen", &format!("127.0.0.1:{modbus}")])
        .args(["--set", &format!("web.listen=\"127.0.0.1:{web}\""), "--set", "record.enabled=false"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn fme run");
    Running(child)
}

/// The browser program, if installed.
fn chromium() -> Option<PathBuf> {
    ["/usr/bin/chromium", "/usr/lib/chromium/chromium", "/usr/bin/chromium-browser"]
        .into_iter()
        .map(PathBuf::from)
        .find(|p| p.is_file())
}

/// Headless Chromium showing the Live page at `port` until dropped.
fn start_browser(program: &Path, profile: &Path, port: u16) -> Running {
    let child = Command::new(program)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--no-first-run"])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--window-size=1280,900")
        .arg(format!("http://127.0.0.1:{port}/"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn chromium");
    Running(child)
}

/// One run in `mode`: the daemon's CPU over `span` in % of one core, and the pictures fetched.
fn run(mode: Mode, span: Duration) -> (f64, u32) {
    let state = tempfile::tempdir().expect("tempdir");
    let (web, modbus) = (free_port(), free_port());
    let fme = start_fme(state.path(), web, modbus);
    let warm = Instant::now();
    while get(web, "/api/status").0 != 200 {
        assert!(warm.elapsed() < Duration::from_secs(60), "fme run: no web page within 60 s");
        std::thread::sleep(Duration::from_millis(100));
    }
    std::thread::sleep(Duration::from_secs(3)); // models loaded, the pipeline at its pace
    let mut browser = (mode == Mode::Browser).then(|| {
        let program = chromium().expect("chromium");
        start_browser(&program, &state.path().join("chromium"), web)
    });
    let pid = fme.0.id();
    let (c0, t0) = (cpu_seconds(pid), Instant::now());
    let mut pictures = 0;
    while t0.elapsed() < span {
        let next = t0 + Duration::from_secs(u64::from(pictures) + 1);
        if mode == Mode::Client {
            let (status, _) = get(web, "/api/status");
            let (jpeg, len) = get(web, "/api/latest.jpg");
            assert!(status == 200 && jpeg == 200 && len > 1000, "the page's requests: {status} {jpeg} {len}");
        }
        pictures += 1;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let (c1, wall) = (cpu_seconds(pid), t0.elapsed().as_secs_f64());
    if let Some(b) = browser.as_mut() {
        assert!(matches!(b.0.try_wait(), Ok(None)), "chromium showed the page for the whole span");
    }
    assert_eq!(get(web, "/api/status").0, 200, "the daemon still serves");
    ((c1 - c0) / wall * 100.0, if mode == Mode::Client { pictures } else { 0 })
}

fn main() {
    let bench = std::env::args().any(|a| a == "--bench");
    let span = Duration::from_secs(env_num("FME_BENCH_WEB_S", if bench { 20 } else { 2 }));
    let rounds = env_num("FME_BENCH_WEB_ROUNDS", if bench { 2 } else { 1 });
    let browser = bench && env_num("FME_BENCH_WEB_BROWSER", 1) == 1;
    let mut modes = vec![Mode::None, Mode::Client];
    match (browser, chromium()) {
        (true, Some(_)) => modes.push(Mode::Browser),
        (true, None) => println!("daemon web bench: no chromium (`make setup` installs it): browser mode skipped"),
        (false, _) => {}
    }
    println!(
        "daemon web bench: fme run on tests/data/swarm20 (30 fps), [web] on, CPU of the daemon over {} s per run, \
         {rounds} round(s)",
        span.as_secs()
    );
    let mut sums = vec![0.0; modes.len()];
    for round in 0..rounds {
        for (i, &mode) in modes.iter().enumerate() {
            let (cpu, pictures) = run(mode, span);
            let fetched =
                if mode == Mode::Client { format!(", {pictures} status+picture fetches") } else { String::new() };
            println!("round {round} {mode:?}: daemon CPU {cpu:.1} % of one core{fetched}");
            sums[i] += cpu;
        }
    }
    let mean = |i: usize| sums[i] / rounds as f64;
    println!("mean without a page: {:.1} % of one core", mean(0));
    for (i, mode) in modes.iter().enumerate().skip(1) {
        println!(
            "mean with {mode:?}: {:.1} % of one core ({:+.1} % of one core; target +3)",
            mean(i),
            mean(i) - mean(0)
        );
    }
}
