//! The routes of each listener and the request limits, as tower layers around them: a request
//! timeout (408), a body size limit (413) and a limit on requests handled at once over every
//! connection (more wait their turn, within the timeout).

use super::{MAX_BODY, WebState, api, calibrate, pages};
use crate::output::metrics::{CONTENT_TYPE, Scrape, render};
use axum::Router;
use axum::extract::State;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use std::sync::Arc;
use std::time::Duration;
use tower::limit::GlobalConcurrencyLimitLayer;
use tower_http::limit::RequestBodyLimitLayer;
use tower_http::timeout::TimeoutLayer;

/// The request limits of `[web]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RouteLimits {
    /// Requests handled at once (`max_requests`).
    pub max_requests: usize,
    /// Time to answer a request (`request_timeout_ms`).
    pub timeout: Duration,
}

impl RouteLimits {
    /// The limits `[web]` configures.
    pub fn from_config(cfg: &super::config::WebConfig) -> Self {
        Self {
            max_requests: (cfg.max_requests as usize).max(1),
            timeout: Duration::from_millis(cfg.request_timeout_ms),
        }
    }
}

/// Everything, for `[web] listen`.
pub fn web(state: Arc<WebState>) -> Router {
    let limits = state.limits;
    Router::new()
        .route("/", get(pages::live))
        .route("/history", get(pages::history))
        .route("/health", get(pages::health))
        .route("/calibrate", get(calibrate::page))
        .route("/assets/calibrate.js", get(calibrate::script))
        .route("/api/calibration", get(calibrate::get).post(calibrate::post))
        .route("/api/frame.jpg", get(calibrate::frame_jpg))
        .route("/assets/style.css", get(pages::style))
        .route("/assets/app.js", get(pages::script))
        .route("/metrics", get(metrics).fallback(metrics_method))
        .route("/api/status", get(api::status))
        .route("/api/activity", get(api::activity))
        .route("/api/latest.jpg", get(api::latest_jpg))
        .route("/api/snapshot", post(api::snapshot))
        .route("/api/record", post(api::record))
        .fallback(not_found)
        .with_state(state)
        .layer(RequestBodyLimitLayer::new(MAX_BODY))
        .layer(GlobalConcurrencyLimitLayer::new(limits.max_requests))
        .layer(TimeoutLayer::with_status_code(StatusCode::REQUEST_TIMEOUT, limits.timeout))
}

/// `/metrics` alone, for `[output.metrics] listen`.
pub fn metrics_only(state: Arc<WebState>) -> Router {
    let limits = state.limits;
    Router::new()
        .route("/metrics", get(metrics).fallback(metrics_method))
        .fallback(not_found_metrics)
        .with_state(state)
        .layer(RequestBodyLimitLayer::new(MAX_BODY))
        .layer(GlobalConcurrencyLimitLayer::new(limits.max_requests))
        .layer(TimeoutLayer::with_status_code(StatusCode::REQUEST_TIMEOUT, limits.timeout))
}

/// `GET /metrics` (and HEAD: the same head, no body): the exposition of a copy of the state.
async fn metrics(State(s): State<Arc<WebState>>) -> Response {
    let scrape = Scrape::take(&s.shared, &s.bank, s.stale_after);
    let body = render(&scrape);
    let mut r = body.into_response();
    let h = r.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(CONTENT_TYPE));
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

async fn metrics_method() -> Response {
    let mut r = (StatusCode::METHOD_NOT_ALLOWED, "method not allowed: use GET or HEAD\n").into_response();
    r.headers_mut().insert(header::ALLOW, HeaderValue::from_static("GET, HEAD"));
    r
}

async fn not_found() -> Response {
    (StatusCode::NOT_FOUND, "not found: the pages are /, /history, /health and /calibrate (docs/web.md)\n")
        .into_response()
}

async fn not_found_metrics() -> Response {
    (StatusCode::NOT_FOUND, "not found: the metrics are at /metrics\n").into_response()
}
