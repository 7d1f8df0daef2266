//! The JSON API behind the pages (docs/web.md): `/api/status` (the published update the registers
//! carry, and the box's health), `/api/activity` (history rows), `/api/latest.jpg` (the latest
//! frame with the overlays of `snap`), and the actions `POST /api/snapshot` and
//! `POST /api/record`, which need the token ([`super::auth`]).

use super::WebState;
use super::auth::{Refusal, check};
use crate::history::{self, HistoryRow};
use axum::Json;
use axum::extract::{Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::sync::Arc;
use std::time::Duration;

/// The longest span `/api/activity` answers, ms (8 days: the 7-day view and a day's margin).
pub const MAX_SPAN_MS: i64 = 8 * 86_400_000;
/// How long `/api/latest.jpg` waits for the next frame before it answers with the latest one.
const FRAME_WAIT: Duration = Duration::from_millis(500);

/// `GET /api/status`: the values of the registers at this moment (one published update) and the
/// health behind them.
pub async fn status(State(s): State<Arc<WebState>>) -> Response {
    let mut r = Json(status_json(&s)).into_response();
    no_store(&mut r);
    r
}

/// The body of `/api/status` (NaN values are `null`).
pub fn status_json(s: &WebState) -> Value {
    let u = s.bank.update();
    let h = s.shared.health();
    let bits: serde_json::Map<String, Value> =
        u.status.named().map(|(n, on)| (n.to_string(), Value::Bool(on))).collect();
    json!({
        "time_unix_ms": u.unix_ms,
        "activity_mps": u.mean_mps,
        "activity_bls": u.mean_bls,
        "smoothed_mps": u.smoothed_mps,
        "ci95_mps": u.ci95_half_mps,
        "fish": u.fish,
        "heartbeat": u.heartbeat,
        "status_word": u.status.bits(),
        "status": u.status.words(),
        "status_bits": bits,
        "fault_code": u.fault as u16,
        "fault": u.fault.name(),
        "is_fault": u.fault.is_fault(),
        "feeding": u.feeding,
        "scale": u.scale.name(),
        "value_age_s": if u.value_age_s.is_finite() { Some(u.value_age_s) } else { None },
        "uptime_s": u.uptime_s,
        "feeding_thresholds_mps": { "on_above": s.feeding.0, "off_below": s.feeding.1 },
        "health": health_json(s, &u, &h),
    })
}

/// The health part of `/api/status`: rates, drops, latency, outputs, disk, version.
fn health_json(s: &WebState, u: &crate::output::Update, h: &crate::status::Health) -> Value {
    let q = |p: f64| h.latency.quantile_ms(p);
    let c = s.bank.counters();
    json!({
        "camera_fps": u.camera_fps,
        "detector_hz": u.detector_hz,
        "depth_hz": u.depth_hz,
        "frames_captured": h.frames_captured,
        "frames_processed": h.frames_processed,
        "frames_dropped": h.frames_dropped,
        "capture_errors": h.capture_errors,
        "reconnects": h.reconnects,
        "pipeline_errors": h.pipeline_errors,
        "updates": h.updates,
        "latency_p50_ms": q(0.5),
        "latency_p99_ms": q(0.99),
        "source": h.source,
        "modbus": s.shared.modbus.get().map_or("off", String::as_str),
        "modbus_clients": c.tcp_open,
        "modbus_requests": c.requests,
        "modbus_polled_last_10s": s.bank.served_within(Duration::from_secs(10)),
        "mqtt": h.mqtt.link.name(),
        "history": s.shared.history.describe(),
        "metrics": s.shared.metrics.describe(),
        "web": s.shared.web.get().map_or("off", String::as_str),
        "record": {
            "active": h.record.active,
            "ring_mb": h.record.ring_bytes as f64 / 1e6,
            "frames_dropped": h.record.frames_dropped,
            "write_errors": h.record.write_errors,
            "disk_fault": h.record.disk_fault,
            "saved": h.record.saved,
            "snapshots": h.record.snapshots,
            "last": h.record.last,
        },
        "version": env!("CARGO_PKG_VERSION"),
        "backend": fme_core::infer::backend::BUILD,
        "networks": {
            "detector": network_json(h.networks.detector.as_ref()),
            "depth": network_json(h.networks.depth.as_ref()),
        },
    })
}

/// One network the pipeline runs (`null` where the stage runs none): file, numeric form, runtime,
/// as the start-up `networks:` line and `fme_build_info` name them.
fn network_json(n: Option<&fme_core::pipeline::Network>) -> Value {
    n.map_or(
        Value::Null,
        |n| json!({ "file": n.path.display().to_string(), "form": n.form.name(), "backend": n.backend.name() }),
    )
}

/// The query of `/api/activity`: `from` and `to` as Unix ms or `YYYY-MM-DDTHH:MM:SS(.mmm)Z`
/// (default: the last hour), `format=csv` for the day files' CSV.
#[derive(Debug, Default, Deserialize)]
pub struct ActivityQuery {
    /// Start (included).
    pub from: Option<String>,
    /// End (excluded; default now).
    pub to: Option<String>,
    /// `json` (default) or `csv`.
    pub format: Option<String>,
    /// JSON only: at most this many points, each the mean of an equal slice of the span (a week
    /// of rows at 1 Hz is 604,800; a chart needs a few hundred).
    pub points: Option<usize>,
}

/// A time of the query: Unix ms or the history's UTC time format.
pub fn parse_when(s: &str) -> Option<i64> {
    s.trim().parse::<i64>().ok().or_else(|| history::parse_time(s.trim()))
}

fn bad_request(msg: String) -> Response {
    (StatusCode::BAD_REQUEST, Json(json!({ "error": msg }))).into_response()
}

/// `GET /api/activity?from=&to=`: the history rows in that span, as JSON or CSV.
pub async fn activity(State(s): State<Arc<WebState>>, Query(q): Query<ActivityQuery>) -> Response {
    let now = history::now_unix_ms();
    let to = match q.to.as_deref().map(parse_when) {
        None => now,
        Some(Some(t)) => t,
        Some(None) => return bad_request("to: Unix ms or YYYY-MM-DDTHH:MM:SSZ".into()),
    };
    let from = match q.from.as_deref().map(parse_when) {
        None => to - 3_600_000,
        Some(Some(t)) => t,
        Some(None) => return bad_request("from: Unix ms or YYYY-MM-DDTHH:MM:SSZ".into()),
    };
    if from >= to || to - from > MAX_SPAN_MS {
        return bad_request(format!("from must be before to, at most {} days apart", MAX_SPAN_MS / 86_400_000));
    }
    let csv = match q.format.as_deref() {
        None | Some("json") => false,
        Some("csv") => true,
        Some(other) => return bad_request(format!("format: json or csv, got {other:?}")),
    };
    let Some(dir) = s.shared.history.dir().map(std::path::Path::to_path_buf) else {
        return (
            StatusCode::NOT_FOUND,
            Json(json!({ "error": "no history: history.enabled = false, or no state directory" })),
        )
            .into_response();
    };
    let read = tokio::task::spawn_blocking(move || history::read_range(&dir, from, to)).await;
    let (rows, torn) = match read {
        Ok(Ok(r)) => r,
        Ok(Err(e)) => {
            return (StatusCode::INTERNAL_SERVER_ERROR, Json(json!({ "error": e.to_string() }))).into_response();
        }
        Err(_) => return StatusCode::INTERNAL_SERVER_ERROR.into_response(),
    };
    let rows = match q.points {
        Some(n) if !csv && n > 0 && rows.len() > n => thin(&rows, n, from, to),
        _ => rows,
    };
    let mut r = if csv {
        csv_body(&rows).into_response()
    } else {
        Json(activity_json(&s, &rows, torn, from, to)).into_response()
    };
    if csv {
        r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("text/csv; charset=utf-8"));
        let name = format!("attachment; filename=\"fme-activity-{from}-{to}.csv\"");
        if let Ok(v) = HeaderValue::from_str(&name) {
            r.headers_mut().insert(header::CONTENT_DISPOSITION, v);
        }
    }
    no_store(&mut r);
    r
}

/// At most `n` rows: the rows of each of `n` equal slices of `from..to` averaged (finite values
/// only; NaN where a slice has none), at the mean time of the slice's rows; feeding when any was.
pub fn thin(rows: &[HistoryRow], n: usize, from: i64, to: i64) -> Vec<HistoryRow> {
    let width = ((to - from) as f64 / n as f64).max(1.0);
    let mut out: Vec<HistoryRow> = Vec::with_capacity(n);
    let mut i = 0;
    while i < rows.len() {
        let slot = ((rows[i].unix_ms - from) as f64 / width).floor();
        let j = i + rows[i..].iter().take_while(|r| ((r.unix_ms - from) as f64 / width).floor() == slot).count();
        let part = &rows[i..j];
        let mean = |f: fn(&HistoryRow) -> f64| {
            let v: Vec<f64> = part.iter().map(f).filter(|x| x.is_finite()).collect();
            if v.is_empty() { f64::NAN } else { v.iter().sum::<f64>() / v.len() as f64 }
        };
        let mut r = part[part.len() - 1];
        r.unix_ms = part.iter().map(|r| r.unix_ms).sum::<i64>() / part.len() as i64;
        r.activity_mps = mean(|r| r.activity_mps);
        r.smoothed_mps = mean(|r| r.smoothed_mps);
        r.ci95_mps = mean(|r| r.ci95_mps);
        r.bls = mean(|r| r.bls);
        r.n_fish = (part.iter().map(|r| f64::from(r.n_fish)).sum::<f64>() / part.len() as f64).round() as u32;
        r.feeding = part.iter().any(|r| r.feeding);
        out.push(r);
        i = j.max(i + 1);
    }
    out
}

/// The rows as the day files hold them (their header first).
fn csv_body(rows: &[HistoryRow]) -> String {
    let mut out = String::with_capacity(64 * (rows.len() + 1));
    let _ = writeln!(out, "{}", history::HEADER);
    for r in rows {
        history::format_row(r, &mut out);
    }
    out
}

fn activity_json(s: &WebState, rows: &[HistoryRow], torn: usize, from: i64, to: i64) -> Value {
    let rows: Vec<Value> = rows
        .iter()
        .map(|r| {
            json!({
                "t": r.unix_ms, "activity_mps": r.activity_mps, "smoothed_mps": r.smoothed_mps,
                "ci95_mps": r.ci95_mps, "fish": r.n_fish, "bls": r.bls, "status": r.status,
                "fault": r.fault, "feeding": r.feeding, "scale": r.scale.name(),
            })
        })
        .collect();
    json!({
        "from": from, "to": to, "torn": torn, "rows": rows,
        "feeding_thresholds_mps": { "on_above": s.feeding.0, "off_below": s.feeding.1 },
    })
}

/// `GET /api/latest.jpg`: the next frame (or the latest) with the overlays of `snap`.
pub async fn latest_jpg(State(s): State<Arc<WebState>>) -> Response {
    let Some(p) = s.shared.preview.next(FRAME_WAIT).await else {
        return (StatusCode::SERVICE_UNAVAILABLE, "no frame yet\n").into_response();
    };
    let source = s.source.clone();
    let made = tokio::task::spawn_blocking(move || {
        p.jpeg
            .get_or_init(|| {
                let caption = crate::record::snapshot::Caption::now(&source, p.sample.as_ref());
                let img = crate::record::snapshot::overlay(&p.frame, &p.overlays, &caption)?;
                crate::sequence::encode_jpeg(&img, 80).map_err(|e| e.to_string())
            })
            .clone()
    })
    .await;
    match made {
        Ok(Ok(bytes)) => {
            let mut r = bytes.into_response();
            r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static("image/jpeg"));
            no_store(&mut r);
            r
        }
        Ok(Err(e)) => (StatusCode::INTERNAL_SERVER_ERROR, format!("cannot draw the frame: {e}\n")).into_response(),
        Err(_) => StatusCode::INTERNAL_SERVER_ERROR.into_response(),
    }
}

pub(super) fn refused(why: Refusal) -> Response {
    match why {
        Refusal::NoToken => {
            (StatusCode::FORBIDDEN, Json(json!({ "error": "actions are off: set web.token_file (docs/web.md)" })))
                .into_response()
        }
        Refusal::Unauthorized => {
            let mut r = (
                StatusCode::UNAUTHORIZED,
                Json(json!({ "error": "a valid token is needed: Authorization: Bearer TOKEN" })),
            )
                .into_response();
            r.headers_mut().insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
            r
        }
    }
}

/// `POST /api/snapshot`: what the console's `snap` does.
pub async fn snapshot(State(s): State<Arc<WebState>>, headers: HeaderMap) -> Response {
    if let Err(why) = check(&headers, s.token.as_deref()) {
        return refused(why);
    }
    s.shared.requests.request_snapshot();
    s.shared.log(tracing::Level::INFO, "web: snapshot of the next frame requested");
    (
        StatusCode::ACCEPTED,
        Json(json!({ "ok": "snapshot of the next frame requested: see the Health page for the file" })),
    )
        .into_response()
}

/// The query of `/api/record`.
#[derive(Debug, Default, Deserialize)]
pub struct RecordQuery {
    /// The recording's label (default `manual`).
    pub label: Option<String>,
}

/// `POST /api/record?label=L`: what the console's `record save L` does.
pub async fn record(State(s): State<Arc<WebState>>, headers: HeaderMap, Query(q): Query<RecordQuery>) -> Response {
    if let Err(why) = check(&headers, s.token.as_deref()) {
        return refused(why);
    }
    if !s.shared.health().record.active {
        return (
            StatusCode::CONFLICT,
            Json(json!({ "error": "no black box: record.enabled = false, or no state directory" })),
        )
            .into_response();
    }
    let label = q.label.as_deref().map(str::trim).filter(|l| !l.is_empty()).unwrap_or("manual");
    let label: String = label.chars().take(40).collect();
    s.shared.requests.request_save(&label);
    s.shared.log(tracing::Level::INFO, format!("web: record save {label:?} requested"));
    (StatusCode::ACCEPTED, Json(json!({ "ok": "saving: see the Health page for the folder" }))).into_response()
}

fn no_store(r: &mut Response) {
    r.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
}
