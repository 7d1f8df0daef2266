//! The Calibrate page in a real browser (headless Chromium, as tests/web_browser.rs) against
//! `fme run` on the bundled synthetic recording, whose meta.json holds the true camera and the
//! reference cubes: the daemon starts with an old calibration (the camera 0.3 m and 2 degrees
//! off); the test freezes a frame, clicks each reference at its true pixel plus 1 px, types its
//! measured position and the intrinsics, applies without the token (refused: the old camera stays)
//! and with it: the daemon's calibration then matches the truth within 3 cm and 0.5 degrees.
//! Screenshots of the page at 390 and 1280 px go to `target/web-screenshots/calibrate-*.png`.

#[path = "common/browser.rs"]
mod browser;
#[path = "daemon/support.rs"]
mod support;

use fantoccini::actions::{InputSource, MOUSE_BUTTON_LEFT, MouseActions, PointerAction};
use fantoccini::{Client, Locator};
use fme::geometry::{Camera, Pose};
use serde_json::{Value, json};
use std::io::{Read as _, Write as _};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use support::{Running, free_port, get_json};

const META: &str = "tests/data/swarm20/meta.json";
const TOKEN: &str = "calibrate-test-token";

/// The camera `/api/calibration` reports, and how many calibrations the daemon has taken.
fn daemon_camera(port: u16) -> Option<(Camera, u64)> {
    let c = get_json(port, "/api/calibration")?;
    let m = &c["camera"];
    let row = |i: usize| -> Option<[f64; 3]> {
        let r = m["rotation"].get(i)?;
        Some([r[0].as_f64()?, r[1].as_f64()?, r[2].as_f64()?])
    };
    let t = [m["translation"][0].as_f64()?, m["translation"][1].as_f64()?, m["translation"][2].as_f64()?];
    let pose = Pose::from_rows([row(0)?, row(1)?, row(2)?], t).ok()?;
    let f = |k: &str| m[k].as_f64();
    let intrinsics =
        fme::geometry::Intrinsics { fx: f("fx")?, fy: f("fy")?, cx: f("cx")?, cy: f("cy")?, distortion: [0.0; 5] };
    Some((Camera { intrinsics, pose }, c["applied"].as_u64()?))
}

/// (centre distance m, rotation angle degrees) between two cameras.
fn apart(a: &Camera, b: &Camera) -> (f64, f64) {
    let d = a.pose.camera_center().distance(&b.pose.camera_center()).get();
    (d, fme::calib::rotation_angle_deg(&a.pose.rotation, &b.pose.rotation))
}

/// The true calibration with the camera moved 0.3 m along x and turned 2 degrees about z.
fn old_calibration(truth: &Value) -> Value {
    let mut old = truth.clone();
    let w2c = &truth["camera"]["world_to_camera"];
    let r: Vec<Vec<f64>> =
        (0..3).map(|i| (0..3).map(|j| w2c["rotation"][i][j].as_f64().expect("r")).collect()).collect();
    let (c, s) = (2f64.to_radians().cos(), 2f64.to_radians().sin());
    // R' = R Rz(-a): the world turned under the camera; t' = t - 0.3 R' x.
    let rz = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]];
    let rr: Vec<Vec<f64>> =
        (0..3).map(|i| (0..3).map(|j| (0..3).map(|k| r[i][k] * rz[k][j]).sum()).collect()).collect();
    let t: Vec<f64> = (0..3).map(|i| w2c["translation"][i].as_f64().expect("t") - 0.3 * rr[i][0]).collect();
    old["camera"]["world_to_camera"] = json!({ "rotation": rr, "translation": t });
    old
}

/// `fme run` on the bundled recording with the page and a token; `calib`: `camera.calibration`
/// (`None`: the recording's own meta.json, so the page has no file to write).
fn start_fme(dir: &Path, web: u16, calib: Option<&Path>) -> Running {
    let token = dir.join("token");
    std::fs::write(&token, format!("{TOKEN}\n")).expect("token file");
    let log = std::fs::File::create(dir.join("fme.log")).expect("log file");
    let child = Command::new(env!("CARGO_BIN_EXE_fme"))
        .env_remove("NOTIFY_SOCKET")
        .env_remove("WATCHDOG_USEC")
        .env("STATE_DIRECTORY", dir)
        .args(["run", "--source", "tests/data/swarm20", "--modbus-listen", &format!("127.0.0.1:{}", free_port())])
        .args(["--set", &format!("web.listen=\"127.0.0.1:{web}\"")])
        .args(["--set", &format!("web.token_file=\"{}\"", token.display())])
        .args(
            calib
                .map(|c| vec!["--set".to_string(), format!("camera.calibration=\"{}\"", c.display())])
                .unwrap_or_default(),
        )
        .args(["--set", "record.enabled=false"])
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()
        .expect("spawn fme run");
    Running(child)
}

async fn js(c: &Client, code: &str) -> Value {
    c.execute(code, vec![]).await.unwrap_or_else(|e| panic!("{code}: {e}"))
}

/// Clicks the frozen frame at image pixel (u, v).
async fn click_at(c: &Client, u: f64, v: f64) {
    let r = js(c, "window.scrollTo(0, 0); const b = document.getElementById('marks').getBoundingClientRect(); const i = document.getElementById('still'); return [b.left, b.top, b.width / i.naturalWidth];").await;
    let (left, top, scale) = (r[0].as_f64().expect("left"), r[1].as_f64().expect("top"), r[2].as_f64().expect("scale"));
    let (x, y) = (left + u * scale, top + v * scale);
    let mouse = MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo { duration: None, x, y })
        .then(PointerAction::Down { button: MOUSE_BUTTON_LEFT })
        .then(PointerAction::Up { button: MOUSE_BUTTON_LEFT });
    c.perform_actions(mouse).await.expect("click");
    c.release_actions().await.expect("release");
}

async fn type_into(c: &Client, css: &str, text: &str) {
    let e = c.find(Locator::Css(css)).await.unwrap_or_else(|e| panic!("{css}: {e}"));
    e.clear().await.expect("clear");
    e.send_keys(text).await.expect("type");
}

/// Clicks a button and waits for the page's answer (`#said` with an HTTP status).
async fn press_and_wait(c: &Client, id: &str) -> (u16, String) {
    js(c, "delete document.getElementById('said').dataset.status;").await;
    c.find(Locator::Id(id)).await.expect("button").click().await.expect("click");
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let v =
            js(c, "const s = document.getElementById('said'); return [s.dataset.status || '', s.textContent];").await;
        if let Some(code) = v[0].as_str().and_then(|s| s.parse().ok()) {
            return (code, v[1].as_str().unwrap_or_default().to_string());
        }
        assert!(Instant::now() < deadline, "no answer on the page after {id}: {v}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn clicking_the_references_calibrates_the_running_daemon() {
    let dir = tempfile::tempdir().expect("tempdir");
    let truth_json: Value = serde_json::from_str(&std::fs::read_to_string(META).expect("meta.json")).expect("json");
    let truth = fme::calibration::load(Path::new(META)).expect("the true calibration");
    let calib = dir.path().join("calib.json");
    std::fs::write(&calib, old_calibration(&truth_json).to_string()).expect("old calibration");
    let web = free_port();
    let _fme = start_fme(dir.path(), web, Some(&calib));
    let log = || std::fs::read_to_string(dir.path().join("fme.log")).unwrap_or_default();
    let deadline = Instant::now() + Duration::from_secs(60);
    let (old, taken0) = loop {
        if let Some(x) = daemon_camera(web) {
            break x;
        }
        assert!(Instant::now() < deadline, "no /api/calibration within 60 s:\n{}", log());
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    let (d, a) = apart(&old, &truth.camera);
    assert!(d > 0.25 && a > 1.5, "the old calibration is off: {d} m, {a} degrees");

    let (_driver, c) = browser::start_browser(dir.path()).await;
    c.set_window_size(1280, 900).await.expect("window size");
    c.goto(&format!("http://127.0.0.1:{web}/calibrate")).await.expect("open the calibrate page");
    c.find(Locator::Id("freeze")).await.expect("freeze").click().await.expect("freeze");
    let deadline = Instant::now() + Duration::from_secs(15);
    while js(&c, "return document.getElementById('still').dataset.frozen || '';").await == json!("") {
        if Instant::now() >= deadline {
            let said = js(&c, "return document.getElementById('said').textContent;").await;
            panic!("no frozen frame (the page says {said}):\n{}", log());
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }

    // Each reference at its true pixel plus 1 px (each in its own direction), then its position.
    for (i, face) in truth.references.iter().enumerate() {
        let p = truth.camera.world_to_pixel(face).expect("in front of the camera");
        let angle = i as f64 * 2.4;
        click_at(&c, p.u + angle.cos(), p.v + angle.sin()).await;
        let row = format!("#refs .ref:nth-child({})", i + 1);
        for (k, v) in ["x", "y", "z"].iter().zip([face.0.x, face.0.y, face.0.z]) {
            type_into(&c, &format!("{row} input.{k}"), &format!("{v:.4}")).await;
        }
    }
    let k = &truth.camera.intrinsics;
    for (id, v) in [("fx", k.fx), ("fy", k.fy), ("cx", k.cx), ("cy", k.cy)] {
        js(&c, "document.getElementById('kbox').open = true;").await;
        type_into(&c, &format!("#{id}"), &format!("{v:.3}")).await;
    }

    // Without the token: refused, and the daemon keeps its calibration.
    type_into(&c, "#token", " ").await;
    let (code, said) = press_and_wait(&c, "apply").await;
    assert_eq!(code, 401, "apply without the token: {said}");
    assert_eq!(daemon_camera(web).map(|x| x.1), Some(taken0), "a refused apply changed the calibration");

    type_into(&c, "#token", TOKEN).await;
    let (code, said) = press_and_wait(&c, "solve").await;
    assert_eq!(code, 200, "solve: {said}");
    let (code, said) = press_and_wait(&c, "apply").await;
    assert_eq!(code, 200, "apply: {said}\n{}", log());
    let (now, taken) = daemon_camera(web).expect("the calibration in use");
    assert!(taken > taken0, "the pipeline has not taken the applied calibration: {said}");
    let (d, a) = apart(&now, &truth.camera);
    assert!(d <= 0.03 && a <= 0.5, "the applied calibration is {d:.3} m and {a:.2} degrees from the truth");
    eprintln!("applied: {d:.4} m and {a:.3} degrees from the truth");
    assert!(fme::calibration::load(&calib).is_ok(), "the written file loads");

    screenshots(&c).await;
    c.close().await.expect("close the browser");
}

/// The page with its marks and errors at desktop and phone width.
async fn screenshots(c: &Client) {
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/web-screenshots");
    std::fs::create_dir_all(&out).expect("screenshot folder");
    for (w, h) in [(1280, 1000), (390, 844)] {
        c.set_window_size(w, h).await.expect("window size");
        js(c, "window.scrollTo(0, 0);").await;
        tokio::time::sleep(Duration::from_millis(500)).await;
        let png = c.screenshot().await.expect("screenshot");
        std::fs::write(out.join(format!("calibrate-{w}.png")), png).expect("write screenshot");
    }
}

/// `POST /api/calibration` with `token` (or none): the status and the JSON answer.
fn post(port: u16, token: Option<&str>, body: &Value) -> (u16, Value) {
    let body = body.to_string();
    let auth = token.map(|t| format!("Authorization: Bearer {t}\r\n")).unwrap_or_default();
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(20))).expect("timeout");
    let head = format!(
        "POST /api/calibration HTTP/1.1\r\nHost: x\r\nConnection: close\r\n{auth}Content-Type: application/json\r\nContent-Length: {}\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).and_then(|()| s.write_all(body.as_bytes())).expect("send");
    let mut raw = String::new();
    s.read_to_string(&mut raw).expect("answer");
    let code = raw.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0);
    let json = raw.split_once("\r\n\r\n").and_then(|(_, b)| serde_json::from_str(b).ok()).unwrap_or(Value::Null);
    (code, json)
}

/// The API alone: the token is needed, a reference measured 0.3 m off is named with every
/// reference's error, and an apply with no `camera.calibration` to write is refused (409).
#[test]
fn the_api_names_a_bad_reference_and_needs_the_token() {
    let dir = tempfile::tempdir().expect("tempdir");
    let truth = fme::calibration::load(Path::new(META)).expect("the true calibration");
    let web = free_port();
    let _fme = start_fme(dir.path(), web, None);
    let deadline = Instant::now() + Duration::from_secs(60);
    while get_json(web, "/api/calibration").is_none() {
        let log = std::fs::read_to_string(dir.path().join("fme.log")).unwrap_or_default();
        assert!(Instant::now() < deadline, "no /api/calibration within 60 s:\n{log}");
        std::thread::sleep(Duration::from_millis(100));
    }
    let refs: Vec<Value> = truth
        .references
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let p = truth.camera.world_to_pixel(w).expect("in view");
            // The fourth one measured 0.3 m off along x.
            let x = if i == 3 { w.0.x + 0.3 } else { w.0.x };
            json!({ "name": format!("cube{}", i + 1), "x": x, "y": w.0.y, "z": w.0.z, "u": p.u, "v": p.v })
        })
        .collect();
    let k = &truth.camera.intrinsics;
    let body = json!({ "width": 640, "height": 384, "references": refs,
                       "intrinsics": { "fx": k.fx, "fy": k.fy, "cx": k.cx, "cy": k.cy } });
    assert_eq!(post(web, None, &body).0, 401);
    assert_eq!(post(web, Some("wrong-token-0"), &body).0, 401);
    let (code, a) = post(web, Some(TOKEN), &body);
    assert_eq!(code, 422, "{a}");
    assert_eq!(a["bad_reference"], json!("cube4"), "{a}");
    assert!(a["error"].as_str().is_some_and(|e| e.contains("cube4")), "{a}");
    assert_eq!(a["references"].as_array().map(Vec::len), Some(10), "every reference's error: {a}");
    let mut good = body.clone();
    good["references"][3]["x"] = json!(truth.references[3].0.x);
    let (code, a) = post(web, Some(TOKEN), &good);
    assert_eq!(code, 200, "{a}");
    assert!(a["rms_px"].as_f64().is_some_and(|r| r < 0.01), "{a}");
    good["apply"] = json!(true);
    let (code, a) = post(web, Some(TOKEN), &good);
    assert_eq!(code, 409, "{a}");
    assert!(a["error"].as_str().is_some_and(|e| e.contains("camera.calibration")), "{a}");
    let (code, a) = post(web, Some(TOKEN), &json!({ "width": 640, "height": 384, "references": [], "x": 1 }));
    assert_eq!(code, 400, "{a}");
}
