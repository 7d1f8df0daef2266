//! The web page in a real browser: headless Chromium (Debian's `chromium` and `chromium-driver`,
//! installed by `make setup`) driven over WebDriver against `fme run` on the bundled recording.
//! The live page shows the activity the Modbus register holds (within one update), an action
//! without the token is refused, the history page draws the run's rows, and screenshots of each
//! page at phone (390 px) and desktop (1280 px) width are written under `target/web-screenshots/`
//! (docs/web.md has what each must show).

#[path = "common/browser.rs"]
mod browser;
#[path = "daemon/support.rs"]
mod support;

use browser::start_browser;
use fantoccini::Client;
use serde_json::json;
use std::collections::HashMap;
use std::io::{Read as _, Write as _};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use support::{Running, free_port};

/// Input registers 0-23 over Modbus TCP, or `None`.
fn registers(port: u16) -> Option<[u16; 24]> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(2))).ok()?;
    s.write_all(&[0, 1, 0, 0, 0, 6, 1, 4, 0, 0, 0, 24]).ok()?;
    let mut ans = [0u8; 9 + 48];
    s.read_exact(&mut ans).ok()?;
    (ans[7] == 4).then(|| std::array::from_fn(|i| u16::from_be_bytes([ans[9 + 2 * i], ans[10 + 2 * i]])))
}

/// (heartbeat, activity m/s) of the registers.
fn plc_view(port: u16) -> Option<(u16, f32)> {
    let r = registers(port)?;
    let order = fme::config::Config::default().output.modbus.word_order;
    Some((r[12], fme::output::registers::decode_f32([r[0], r[1]], order)))
}

fn http_ok(port: u16, path: &str) -> Option<String> {
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    s.write_all(format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").as_bytes()).ok()?;
    let mut raw = String::new();
    s.read_to_string(&mut raw).ok()?;
    raw.starts_with("HTTP/1.1 200").then(|| raw.split_once("\r\n\r\n").map(|(_, b)| b.to_string()))?
}

fn start_fme(dir: &Path, web: u16, modbus: u16) -> Running {
    let token = dir.join("token");
    std::fs::write(&token, "browser-test-token\n").expect("token file");
    let log = std::fs::File::create(dir.join("fme.log")).expect("log file");
    let child = Command::new(env!("CARGO_BIN_EXE_fme"))
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env("STATE_DIRECTORY", dir)
        .args(["run", "--source", "tests/data/swarm20", "--modbus-listen", &format!("127.0.0.1:{modbus}")])
        .args(["--set", &format!("web.listen=\"127.0.0.1:{web}\"")])
        .args(["--set", &format!("web.token_file=\"{}\"", token.display())])
        .args(["--set", "record.enabled=false", "--set", "output.rate_hz=1"])
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("spawn fme run");
    Running(child)
}

/// The live page's (heartbeat, activity value, shown text), once it has shown an update.
async fn page_view(c: &Client) -> Option<(u16, f64, String)> {
    let js = "const a = document.getElementById('activity'); return [a.dataset.heartbeat || '', a.dataset.value || '', a.textContent];";
    let v = c.execute(js, vec![]).await.ok()?;
    let hb = v[0].as_str()?.parse().ok()?;
    let value = v[1].as_str()?.parse().ok()?;
    Some((hb, value, v[2].as_str()?.to_string()))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_live_page_shows_the_registers_and_refuses_an_action_without_the_token() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (web, modbus) = (free_port(), free_port());
    let _fme = start_fme(dir.path(), web, modbus);
    let log = || std::fs::read_to_string(dir.path().join("fme.log")).unwrap_or_default();
    let deadline = Instant::now() + Duration::from_secs(60);
    while !http_ok(web, "/api/status").is_some_and(|b| b.contains("\"fish\":") && !b.contains("\"fish\":0")) {
        assert!(Instant::now() < deadline, "no fish on /api/status within 60 s:\n{}", log());
        std::thread::sleep(Duration::from_millis(200));
    }
    let (_driver, c) = start_browser(dir.path()).await;
    c.goto(&format!("http://127.0.0.1:{web}/")).await.expect("open the live page");

    // What the PLC read at each heartbeat, polled while the page updates itself.
    let mut plc: HashMap<u16, f32> = HashMap::new();
    let mut matched = 0;
    let deadline = Instant::now() + Duration::from_secs(30);
    while matched < 3 {
        assert!(Instant::now() < deadline, "the page never matched the registers; PLC saw {plc:?}\n{}", log());
        if let Some((hb, v)) = plc_view(modbus) {
            plc.insert(hb, v);
        }
        let (Some((page_hb, value, text)), Some((now_hb, _))) = (page_view(&c).await, plc_view(modbus)) else {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        };
        assert!(now_hb.wrapping_sub(page_hb) <= 2, "the page is more than one update behind: {page_hb} vs {now_hb}");
        if let Some(reg) = plc.get(&page_hb) {
            assert_eq!(value as f32, *reg, "heartbeat {page_hb}: page {value} vs register {reg}");
            assert_eq!(text, format!("{:.3}", f64::from(*reg)), "shown text");
            matched += 1;
        }
        tokio::time::sleep(Duration::from_millis(300)).await;
    }

    // An action without the token, from the page itself: refused.
    let js = "return fetch('/api/snapshot', {method: 'POST'}).then(r => r.status);";
    assert_eq!(c.execute(js, vec![]).await.expect("fetch"), json!(401));

    // The history page draws this run's rows (a line of at least two points).
    c.goto(&format!("http://127.0.0.1:{web}/history")).await.expect("open the history page");
    let js = "const p = document.querySelector('#activity-chart path'); return p ? p.getAttribute('d') : '';";
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let d = c.execute(js, vec![]).await.expect("read the chart");
        if d.as_str().is_some_and(|d| d.contains('L')) {
            break;
        }
        assert!(Instant::now() < deadline, "no activity line on the history page: {d}");
        tokio::time::sleep(Duration::from_millis(300)).await;
    }

    screenshots(&c, web).await;
    c.close().await.expect("close the browser");
}

/// Each page at phone and desktop width, once its data is shown.
async fn screenshots(c: &Client, web: u16) {
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/web-screenshots");
    std::fs::create_dir_all(&out).expect("screenshot folder");
    for (w, h) in [(390, 844), (1280, 900)] {
        c.set_window_size(w, h).await.expect("window size");
        for (name, path) in [("live", "/"), ("history", "/history"), ("health", "/health")] {
            c.goto(&format!("http://127.0.0.1:{web}{path}")).await.expect("open page");
            tokio::time::sleep(Duration::from_millis(2500)).await;
            let png = c.screenshot().await.expect("screenshot");
            std::fs::write(out.join(format!("{name}-{w}.png")), png).expect("write screenshot");
        }
    }
}
