//! The Calibrate page and `/api/calibration` (docs/web.md): the calibration in use, and a solve of
//! clicked references with the solver of `fme calibrate` ([`fme_core::calib`]); with `apply` the
//! file at `camera.calibration` is written atomically and reloaded into the running pipeline
//! ([`crate::calibration::live`]), as SIGHUP does. Solving and applying need the token.

use super::WebState;
use super::api::refused;
use super::auth::check;
use super::calibrate_json::{Checked, SolveRequest, camera_json, named_in, residual_rows};
use crate::calibration::file::{CalibrateInfo, CalibrationFile};
use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use fme_core::calib::{self, CalibError};
use serde_json::{Value, json};
use std::sync::Arc;
use std::time::Duration;
use tracing::Level;

const PAGE: &str = include_str!("assets/calibrate.html");
const SCRIPT: &str = include_str!("assets/calibrate.js");
/// How long an apply waits for the pipeline to take the new calibration (it does between frames).
const TAKE_WAIT: Duration = Duration::from_secs(3);
/// How long `/api/frame.jpg` waits for the next frame before it answers with the latest one.
const FRAME_WAIT: Duration = Duration::from_millis(500);

/// `GET /calibrate`: the frozen frame, the clicked references, solve and apply.
pub async fn page() -> Response {
    super::pages::typed(PAGE, "text/html; charset=utf-8")
}

/// `GET /assets/calibrate.js`.
pub async fn script() -> Response {
    super::pages::typed(SCRIPT, "text/javascript; charset=utf-8")
}

/// `GET /api/frame.jpg`: the next frame as the camera gives it, without overlays (the picture the
/// references are clicked on; `/api/latest.jpg` draws over them). `503` before the first frame.
pub async fn frame_jpg(State(s): State<Arc<WebState>>) -> Response {
    let Some(p) = s.shared.preview.next(FRAME_WAIT).await else {
        return (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response();
    };
    let made = tokio::task::spawn_blocking(move || {
        let mut rgb = Vec::new();
        let (w, h) = p.frame.to_rgb_into(&mut rgb)?;
        let img = image::RgbImage::from_raw(w, h, rgb).ok_or_else(|| "frame size mismatch".to_string())?;
        crate::sequence::encode_jpeg(&img, 92).map_err(|e| e.to_string())
    })
    .await;
    match made {
        Ok(Ok(bytes)) => {
            let mut r = bytes.into_response();
            r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("image/jpeg"));
            r.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
            r
        }
        Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot encode the frame: {e}\n")).into_response(),
        Err(_) => StatusCode::INTERNAL_SERVER_ERROR.into_response(),
    }
}

fn answer(code: StatusCode, body: Value) -> Response {
    let mut r = (code, Json(body)).into_response();
    r.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// `GET /api/calibration`: the calibration in use (camera, pose, the references with their
/// reprojection under it and, when the file says, the error of the solve that made it), where an
/// apply writes, and the depth fit on the references now.
pub async fn get(State(s): State<Arc<WebState>>) -> Response {
    let live = &s.shared.calibration;
    let c = live.in_use();
    let info = match &c {
        Some(c) => made_by(&c.path).await,
        None => None,
    };
    let refs: Vec<Value> = c.as_ref().map_or_else(Vec::new, |c| {
        c.references
            .iter()
            .enumerate()
            .map(|(i, w)| {
                let name = info.as_ref().and_then(|f| f.names.get(i).cloned()).unwrap_or_else(|| format!("{}", i + 1));
                let solve = info.as_ref().and_then(|f| f.error_px.get(i).copied()).filter(|e| e.is_finite());
                json!({
                    "name": name,
                    "x": w.0.x, "y": w.0.y, "z": w.0.z,
                    "projected": c.camera.world_to_pixel(w).ok().map(|p| [p.u, p.v]),
                    "error_px": solve,
                })
            })
            .collect()
    });
    let f = s.shared.health().fit_state;
    answer(
        StatusCode::OK,
        json!({
            "calibrated": c.is_some(),
            "file": c.as_ref().map(|c| c.path.display().to_string()),
            "apply_writes": live.configured_path().map(|p| p.display().to_string()),
            "applied": live.taken(),
            "camera": c.as_ref().map(|c| camera_json(&c.camera)),
            "rms_px": info.as_ref().map(|f| f.rms_px).filter(|v| v.is_finite()),
            "references": refs,
            "fit": {
                "fitted": f.fitted,
                "scale_from": f.source.name(),
                "residual_m": f.residual_m.is_finite().then_some(f.residual_m),
                "references_visible": f.references_visible,
            },
        }),
    )
}

/// The `calibrate` block of a calibration file, if it has one (files beside a recording do not).
async fn made_by(path: &std::path::Path) -> Option<CalibrateInfo> {
    #[derive(serde::Deserialize)]
    struct WithInfo {
        calibrate: CalibrateInfo,
    }
    let path = path.to_path_buf();
    let text = tokio::task::spawn_blocking(move || std::fs::read_to_string(path)).await.ok()?.ok()?;
    serde_json::from_str::<WithInfo>(&text).ok().map(|w| w.calibrate)
}

/// `POST /api/calibration` (token): solves the clicked references as `fme calibrate` does and
/// answers each one's error, naming a bad one; with `"apply": true` a good solve is written to
/// `camera.calibration` and reloaded into the pipeline.
pub async fn post(State(s): State<Arc<WebState>>, headers: HeaderMap, body: Bytes) -> Response {
    if let Err(why) = check(&headers, s.token.as_deref()) {
        return refused(why);
    }
    let req: SolveRequest = match serde_json::from_slice(&body) {
        Ok(r) => r,
        Err(e) => return answer(StatusCode::BAD_REQUEST, json!({ "ok": false, "error": format!("the body: {e}") })),
    };
    let checked = match req.check() {
        Ok(c) => c,
        Err(e) => return answer(StatusCode::BAD_REQUEST, json!({ "ok": false, "error": e })),
    };
    let (apply, ref_size) = (req.apply, req.ref_size_m);
    // The solve takes tens of milliseconds of CPU: off the server's threads.
    let solved = tokio::task::spawn_blocking(move || solve(checked)).await;
    let Ok((checked, result)) = solved else {
        return answer(StatusCode::INTERNAL_SERVER_ERROR, json!({ "ok": false, "error": "the solver failed" }));
    };
    let sol = match result {
        Ok(sol) => sol,
        Err((e, rows)) => {
            let bad = match &e {
                CalibError::Outlier { label, .. } => named_in(&checked.refs, label),
                CalibError::OverLimit { worst, .. } => named_in(&checked.refs, worst),
                _ => None,
            };
            let body = json!({ "ok": false, "error": e.to_string(), "bad_reference": bad, "references": rows });
            return answer(StatusCode::UNPROCESSABLE_ENTITY, body);
        }
    };
    let mut body = json!({
        "ok": true,
        "rms_px": sol.rms_px,
        "references": residual_rows(&checked.refs, &sol.residuals),
        "camera": camera_json(&sol.camera),
        "estimated_intrinsics": sol.estimated_intrinsics,
        "start": sol.start,
        "applied": false,
    });
    if !apply {
        return answer(StatusCode::OK, body);
    }
    let file =
        CalibrationFile::new(&checked.refs, &sol, &checked.opts, ref_size, ("web page".into(), "web page".into()));
    match apply_file(&s, file).await {
        Ok(said) => {
            body["applied"] = json!(true);
            body["said"] = json!(said);
            answer(StatusCode::OK, body)
        }
        Err((code, e)) => {
            body["ok"] = json!(false);
            body["error"] = json!(e);
            answer(code, body)
        }
    }
}

type Solved = Result<calib::Solution, (CalibError, Vec<Value>)>;

/// The solve of `fme calibrate`; when it is refused, each reference's error under the unchecked
/// solve (if there is one) goes with the reason, for the page's overlay.
fn solve(c: Checked) -> (Checked, Solved) {
    let r = calib::calibrate(&c.refs, c.intrinsics.as_ref(), &c.opts).map_err(|e| {
        let rows = match calib::check_geometry(&c.refs, &c.opts) {
            Ok(()) => calib::solve_once(&c.refs, c.intrinsics.as_ref(), &c.opts)
                .map(|s| residual_rows(&c.refs, &s.residuals))
                .unwrap_or_default(),
            Err(_) => Vec::new(),
        };
        (e, rows)
    });
    (c, r)
}

/// Writes the file where `camera.calibration` points, atomically, and reloads it; waits (a little)
/// for the pipeline to take it. Errors: the status code and what went wrong.
async fn apply_file(s: &WebState, file: CalibrationFile) -> Result<String, (StatusCode, String)> {
    let Some(path) = s.shared.calibration.configured_path() else {
        let e = "camera.calibration is not set: the page has no file to write; set it in the configuration \
                 (docs/calibration.md)";
        return Err((StatusCode::CONFLICT, e.to_string()));
    };
    let (p, refs) = (path.clone(), file.reference_objects.len());
    let written = tokio::task::spawn_blocking(move || file.write_atomic(&p)).await;
    if let Err(e) = written.unwrap_or_else(|e| Err(e.to_string())) {
        s.shared.log(Level::ERROR, format!("web: calibration not written: {e}"));
        return Err((StatusCode::INTERNAL_SERVER_ERROR, e));
    }
    s.shared.log(Level::INFO, format!("web: calibration written to {} ({refs} references)", path.display()));
    let before = s.shared.calibration.taken();
    let said =
        crate::calibration::live::reload(&s.shared, "web: apply").map_err(|e| (StatusCode::UNPROCESSABLE_ENTITY, e))?;
    let deadline = tokio::time::Instant::now() + TAKE_WAIT;
    while s.shared.calibration.taken() == before {
        if tokio::time::Instant::now() >= deadline {
            return Ok(format!("{said}; the pipeline has not taken it yet (it does between frames)"));
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    Ok(format!("calibration {} written and applied ({refs} reference objects)", path.display()))
}
