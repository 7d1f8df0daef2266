//! The pages (Live, History, Health) and their one stylesheet and script, all inside the binary:
//! farms have no internet, so no CDN and no build step. Plain HTML, CSS and a little vanilla
//! JavaScript that reads the JSON API ([`super::api`]); they work at phone width.

use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};

const LIVE: &str = include_str!("assets/live.html");
const HISTORY: &str = include_str!("assets/history.html");
const HEALTH: &str = include_str!("assets/health.html");
const STYLE: &str = include_str!("assets/style.css");
const SCRIPT: &str = include_str!("assets/app.js");

pub(super) fn typed(body: &'static str, ctype: &'static str) -> Response {
    let mut r = body.into_response();
    r.headers_mut().insert(header::CONTENT_TYPE, HeaderValue::from_static(ctype));
    r.headers_mut().insert(header::CACHE_CONTROL, HeaderValue::from_static("no-cache"));
    r.headers_mut().insert("x-content-type-options", HeaderValue::from_static("nosniff"));
    r
}

/// `GET /`: the live picture and numbers.
pub async fn live() -> Response {
    typed(LIVE, "text/html; charset=utf-8")
}

/// `GET /history`: activity, smoothed and fish count over the last hour, day or 7 days.
pub async fn history() -> Response {
    typed(HISTORY, "text/html; charset=utf-8")
}

/// `GET /health`: rates, drops, latency, outputs, disk, version.
pub async fn health() -> Response {
    typed(HEALTH, "text/html; charset=utf-8")
}

/// `GET /assets/style.css`.
pub async fn style() -> Response {
    typed(STYLE, "text/css; charset=utf-8")
}

/// `GET /assets/app.js`.
pub async fn script() -> Response {
    typed(SCRIPT, "text/javascript; charset=utf-8")
}
