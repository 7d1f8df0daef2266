//! Headless Chromium over WebDriver for the browser tests (tests/web_browser.rs,
//! tests/web_calibrate.rs): Debian's `chromium` and `chromium-driver`, installed by `make setup`.
//! Include with `#[path = "common/browser.rs"] mod browser;` beside `support`.
#![allow(dead_code)]

use crate::support::{Running, free_port};
use fantoccini::{Client, ClientBuilder};
use serde_json::{Value, json};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The program `name` on the PATH (or in /usr/bin, /usr/lib/chromium), or a failure saying how to get it.
pub fn program(name: &str) -> PathBuf {
    let dirs = std::env::var("PATH").unwrap_or_default();
    std::env::split_paths(&dirs)
        .chain([PathBuf::from("/usr/bin"), PathBuf::from("/usr/lib/chromium")])
        .map(|d| d.join(name))
        .find(|p| p.is_file())
        .unwrap_or_else(|| panic!("{name} not found: `make setup` installs Debian's chromium and chromium-driver"))
}

/// chromedriver and a headless Chromium session with its profile under `dir`.
pub async fn start_browser(dir: &Path) -> (Running, Client) {
    let chromium = program("chromium");
    let port = free_port();
    let driver = Command::new(program("chromedriver"))
        .arg(format!("--port={port}"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn chromedriver");
    let driver = Running(driver);
    let profile = dir.join("chromium-profile");
    let args = [
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        "--disable-dev-shm-usage",
        "--hide-scrollbars",
    ];
    let mut args: Vec<String> = args.iter().map(|a| a.to_string()).collect();
    args.push(format!("--user-data-dir={}", profile.display()));
    let caps = json!({ "goog:chromeOptions": { "binary": chromium, "args": args } });
    let Value::Object(caps) = caps else { unreachable!("an object") };
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let connector = hyper_util::client::legacy::connect::HttpConnector::new();
        match ClientBuilder::new(connector)
            .capabilities(caps.clone())
            .connect(&format!("http://127.0.0.1:{port}"))
            .await
        {
            Ok(c) => return (driver, c),
            Err(e) => assert!(Instant::now() < deadline, "chromedriver on port {port}: {e}"),
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}
