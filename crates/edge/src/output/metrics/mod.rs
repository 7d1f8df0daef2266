//! The Prometheus endpoint (`[output.metrics]`, `docs/metrics.md`): a small HTTP/1.1 server that
//! answers `GET /metrics` with the text exposition format 0.0.4.
//!
//! Each scrape ([`Scrape`]) renders a copy of the [`Shared`] health, the last published update and
//! the [`RegisterBank`] counters; the pipeline never waits on it (a scrape holds the health lock
//! only to copy it). The list
//! of metric families is [`families`] (one function per group): a new family is one call there (and
//! one row in `docs/metrics.md`); the text format is `exposition`.
//!
//! The HTTP server, its connection limits and its defences against a hostile LAN are in
//! [`crate::web`].
//!
//! Text format: <https://prometheus.io/docs/instrumenting/exposition_formats/> (0.0.4): `# HELP` and
//! `# TYPE` once per family before its samples, label values escaped (`\\`, `\"`, `\n`), HELP text
//! escaped (`\\`, `\n`), floats as Go writes them (`NaN`, `+Inf`, `-Inf`), histograms as cumulative
//! `_bucket{le="..."}` samples ending with `le="+Inf"` equal to `_count`, then `_sum` and `_count`.

/// The content type of the exposition.
pub const CONTENT_TYPE: &str = "text/plain; version=0.0.4; charset=utf-8";

/// Upper bounds of the frame-to-register latency histogram's buckets, s (`+Inf` follows). Whole
/// milliseconds (the health histogram's resolution, so each bound counts the samples below it),
/// each at most 1.2 x the one before from 5 ms to 1 s: a p99 that `histogram_quantile` interpolates
/// in a bucket is then within 20 % of the console's `latency-p99` for any p99 from 5 ms to 1 s.
pub const LATENCY_BOUNDS_S: [f64; 37] = [
    0.005, 0.006, 0.007, 0.008, 0.009, 0.010, 0.012, 0.014, 0.016, 0.019, 0.022, 0.026, 0.030, 0.035, 0.040, 0.045,
    0.050, 0.060, 0.070, 0.080, 0.090, 0.100, 0.120, 0.140, 0.160, 0.190, 0.225, 0.270, 0.320, 0.380, 0.450, 0.500,
    0.600, 0.700, 0.800, 0.900, 1.0,
];

mod exposition;
mod families;

pub use exposition::{Exposition, valid_label_name, valid_metric_name};
pub use families::families;

use super::Update;
use super::bank::RegisterBank;
use crate::status::{Health, MetricsStatus, Shared};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Everything one scrape exports, copied at once (the health lock is held only for the copy).
#[derive(Debug, Clone)]
pub struct Scrape {
    /// The health snapshot.
    pub health: Health,
    /// When it was taken.
    pub now: Instant,
    /// The last published update (status bits, fault code, feeding).
    pub update: Update,
    /// Modbus counters.
    pub modbus: super::bank::ModbusCounters,
    /// History rows written, dropped, failed.
    pub history: [u64; 3],
    /// The history is paused after a write error.
    pub history_paused: bool,
    /// Responses by code ([`MetricsStatus::CODES`]), refused and aborted connections of this endpoint.
    pub http: ([u64; 6], u64, u64),
    /// `output.stale_after_s`: an older activity value is exported as NaN (as registers 0-7).
    pub stale_after: Duration,
}

impl Scrape {
    /// Copies what a scrape exports from the shared state and the bank.
    pub fn take(shared: &Shared, bank: &RegisterBank, stale_after: Duration) -> Self {
        let h = &shared.history;
        let m: &MetricsStatus = &shared.metrics;
        Self {
            health: shared.health(),
            now: Instant::now(),
            update: bank.update(),
            modbus: bank.counters(),
            history: [
                h.written.load(Ordering::Relaxed),
                h.dropped.load(Ordering::Relaxed),
                h.failed.load(Ordering::Relaxed),
            ],
            history_paused: h.paused.load(Ordering::Relaxed),
            http: (
                std::array::from_fn(|i| m.responses[i].load(Ordering::Relaxed)),
                m.refused.load(Ordering::Relaxed),
                m.aborted.load(Ordering::Relaxed),
            ),
            stale_after,
        }
    }
}

/// The exposition of `s`.
pub fn render(s: &Scrape) -> String {
    let mut e = Exposition::new();
    families::families(s, &mut e);
    e.finish()
}

#[cfg(test)]
mod tests;
