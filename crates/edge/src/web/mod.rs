//! The box's one HTTP server (docs/web.md): the web pages ([`pages`]), the JSON API behind them
//! ([`api`]) and the Prometheus endpoint (`GET /metrics`, [`crate::output::metrics`]), on axum over
//! hyper's HTTP/1.1, with the limits as tower layers ([`routes`]) and the connection limits of a
//! hostile LAN at accept ([`listener`]).
//!
//! Two listeners share the server: `[web] listen` serves everything; `[output.metrics] listen`
//! serves `/metrics` alone (with that section's allow list and limits), so a Prometheus server
//! allowed there sees no page and no action. Reading is open to `allow`; every action needs the
//! token of `[web] token_file` ([`auth`]).
//!
//! Nothing on these paths panics on outside input; should a connection task panic anyway, it ends
//! alone.

mod admission;
pub mod api;
pub mod auth;
pub mod calibrate;
pub mod calibrate_json;
pub mod config;
mod conn;
mod io;
pub mod listener;
pub mod pages;
pub mod preview;
mod request;
pub mod routes;
pub mod tls;

pub use listener::{HttpLimits, PRIORITY_SCRAPES, PRIORITY_WINDOW};
pub use request::request_line_ok;

use crate::config::Config;
use crate::output::bank::RegisterBank;
use crate::status::Shared;
use conn::ConnCtx;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tracing::Level;

/// Largest first request head (request line and headers), bytes; a longer one is answered 431.
pub const MAX_HEAD: usize = 8 * 1024;
/// An answer not written within this (a peer that does not read) ends the connection.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(5);
/// Largest request body (the actions take none; a label travels in the query), bytes.
pub const MAX_BODY: usize = 4 * 1024;

/// Which listener a connection came in on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// `[web] listen`: pages, API, actions and `/metrics`.
    Web,
    /// `[output.metrics] listen`: `/metrics` only; its responses and refusals are counted.
    Metrics,
}

impl Kind {
    /// The name in log lines.
    pub fn name(self) -> &'static str {
        match self {
            Self::Web => "web",
            Self::Metrics => "metrics",
        }
    }
}

/// What the routes read: the box's shared state, the published update and the few settings the
/// pages show.
#[derive(Debug)]
pub struct WebState {
    /// Health, logs, requests to the pipeline (snapshot, record save), the latest frame.
    pub shared: Arc<Shared>,
    /// The published update (the registers' values).
    pub bank: Arc<RegisterBank>,
    /// `output.stale_after_s` (the metrics' staleness rule).
    pub stale_after: Duration,
    /// The action token (`[web] token_file`); `None`: actions are refused.
    pub token: Option<String>,
    /// `feeding.on_above_mps` and `feeding.off_below_mps`, drawn on the history.
    pub feeding: (f64, f64),
    /// `source.path` (the camera named on the picture).
    pub source: PathBuf,
    /// `[web]`'s request limits.
    pub limits: routes::RouteLimits,
}

impl WebState {
    /// The state of a server for `cfg`; an unreadable token file leaves the actions refused (said
    /// in the log, the token never).
    pub fn new(cfg: &Config, stale_after: Duration, shared: &Arc<Shared>, bank: &Arc<RegisterBank>) -> Self {
        let token = match cfg.web.token() {
            Ok(t) => t,
            Err(e) => {
                shared.log(Level::ERROR, format!("web: {e}; the actions (snapshot, record save) are refused"));
                None
            }
        };
        Self {
            shared: shared.clone(),
            bank: bank.clone(),
            stale_after,
            token,
            feeding: (cfg.feeding.on_above_mps, cfg.feeding.off_below_mps),
            source: PathBuf::from(&cfg.source.path),
            limits: routes::RouteLimits::from_config(&cfg.web),
        }
    }
}

/// The running server: its bound addresses and its task (both listeners).
#[derive(Debug)]
pub struct WebServer {
    /// The bound `[web] listen` address (useful with port 0).
    pub web_addr: Option<SocketAddr>,
    /// The bound `[output.metrics] listen` address.
    pub metrics_addr: Option<SocketAddr>,
    task: tokio::task::JoinHandle<()>,
}

impl WebServer {
    /// Stops accepting and ends the open connections.
    pub async fn stop(self) {
        self.task.abort();
        let _ = tokio::time::timeout(Duration::from_millis(200), self.task).await;
    }

    /// The daemon's handle on it (aborted at shutdown).
    pub fn into_subsystem(self) -> crate::service::subsystem::Subsystem {
        crate::service::subsystem::Subsystem::Task(self.task)
    }
}

/// Starts the server on the listeners `cfg` turns on (inside a tokio runtime); `None` when neither
/// is on or none can be bound. A bind failure is logged (journal and console `log`) and shown by
/// the console's `status`; it never stops the daemon.
pub async fn spawn(
    cfg: &Config,
    stale_after: Duration,
    shared: &Arc<Shared>,
    bank: &Arc<RegisterBank>,
) -> Option<WebServer> {
    spawn_with(cfg, Arc::new(WebState::new(cfg, stale_after, shared, bank))).await
}

/// [`spawn`] with a given state (tests: a fake one).
pub async fn spawn_with(cfg: &Config, state: Arc<WebState>) -> Option<WebServer> {
    let (tls, web) = match web_tls(cfg, &state) {
        Ok(tls) => {
            let scheme = if tls.is_some() { "https" } else { "http" };
            (tls, bind(Kind::Web, &cfg.web.listen, &cfg.web.allow, &state, scheme).await)
        }
        Err(()) => (None, None),
    };
    let metrics = bind(Kind::Metrics, &cfg.output.metrics.listen, &cfg.output.metrics.allow, &state, "http").await;
    let (web_addr, metrics_addr) = (web.as_ref().map(|w| w.1), metrics.as_ref().map(|m| m.1));
    if web.is_none() && metrics.is_none() {
        return None;
    }
    let header = |ms: u64| Duration::from_millis(ms);
    let web_part = web.map(|(l, _)| {
        let ctx = ConnCtx {
            kind: Kind::Web,
            state: state.clone(),
            router: routes::web(state.clone()),
            header_timeout: header(cfg.web.header_timeout_ms),
            tls,
        };
        listener::serve(l, HttpLimits::web(&cfg.web), Arc::new(ctx))
    });
    let metrics_part = metrics.map(|(l, _)| {
        let ctx = ConnCtx {
            kind: Kind::Metrics,
            state: state.clone(),
            router: routes::metrics_only(state.clone()),
            header_timeout: header(cfg.output.metrics.header_timeout_ms),
            tls: None,
        };
        listener::serve(l, HttpLimits::metrics(&cfg.output.metrics), Arc::new(ctx))
    });
    let task = tokio::spawn(async move {
        let web = async move {
            if let Some(w) = web_part {
                w.await;
            }
        };
        let metrics = async move {
            if let Some(m) = metrics_part {
                m.await;
            }
        };
        tokio::join!(web, metrics);
    });
    Some(WebServer { web_addr, metrics_addr, task })
}

/// The web listener's TLS (`None`: plain HTTP); `Err` when the web page is on and its TLS files
/// cannot be used: logged naming the file, and the page stays off rather than falling back to
/// plain HTTP.
fn web_tls(cfg: &Config, state: &WebState) -> Result<Option<Arc<rustls::ServerConfig>>, ()> {
    if cfg.web.listen.is_empty() {
        return Ok(None);
    }
    tls::server_config(&cfg.web).map_err(|(key, msg)| {
        state.shared.log(Level::ERROR, format!("web: {key}: {msg}; the web page is off, everything else runs"));
        let _ = state.shared.web.set(format!("failed: {key}: {msg}"));
    })
}

/// Binds one listener and says so (or why not); `None` when `listen` is empty or cannot be bound.
async fn bind(
    kind: Kind,
    listen: &str,
    allow: &[String],
    state: &WebState,
    scheme: &str,
) -> Option<(tokio::net::TcpListener, SocketAddr)> {
    if listen.is_empty() {
        return None;
    }
    let shared = &state.shared;
    let key = match kind {
        Kind::Web => "web",
        Kind::Metrics => "output.metrics",
    };
    let bound = match tokio::net::TcpListener::bind(listen).await {
        Ok(l) => l.local_addr().map(|a| (l, a)),
        Err(e) => Err(e),
    };
    let (listener, addr) = match bound {
        Ok(x) => x,
        Err(e) => {
            let hint = crate::output::listen_hint::listen_hint(&e, &format!("{key}.listen"));
            let msg = format!("cannot listen on {listen} ({key}.listen): {e}{hint}");
            let what = if kind == Kind::Web { "the web page" } else { "the Prometheus endpoint" };
            shared.log(Level::ERROR, format!("{}: {msg}; {what} is off, everything else runs", kind.name()));
            match kind {
                Kind::Metrics => shared.metrics.set_state(format!("failed: {msg}")),
                Kind::Web => {
                    let _ = shared.web.set(format!("failed: {msg}"));
                }
            }
            return None;
        }
    };
    let open = crate::config::allow::open_to_all(&addr.to_string(), allow);
    let reach = if open {
        format!(", OPEN TO EVERY ADDRESS ({key}.allow is empty)")
    } else if allow.is_empty() {
        " (this box only)".to_string()
    } else {
        format!(", allow {}", allow.join(", "))
    };
    match kind {
        Kind::Metrics => {
            shared.metrics.set_state(format!("on {addr} (GET /metrics){reach}"));
            shared.log(Level::INFO, format!("metrics: Prometheus endpoint on http://{addr}/metrics"));
        }
        Kind::Web => {
            let _ = shared.web.set(format!("on {scheme}://{addr}/{reach}"));
            shared.log(Level::INFO, format!("web: pages on {scheme}://{addr}/{reach}"));
        }
    }
    if open {
        let msg = format!(
            "{}: {addr} is open to every address ({key}.allow is empty); list who may connect there",
            kind.name()
        );
        shared.log(Level::WARN, msg);
    }
    Some((listener, addr))
}

#[cfg(test)]
mod tests;
