//! The Prometheus endpoint (`[output.metrics]`, `docs/metrics.md`): a small HTTP/1.1 server that
//! answers `GET /metrics` with the text exposition format 0.0.4.
//!
//! Each scrape renders a snapshot of [`Shared`] health and the [`RegisterBank`] counters; the
//! pipeline never waits on it (a scrape holds the health lock only to copy the snapshot). The list
//! of metric families is one function, [`families`]: a new family is one call there (and one row in
//! `docs/metrics.md`).
//!
//! The HTTP server, its connection limits and its defences against a hostile LAN are in
//! [`super::metrics_http`].
//!
//! Text format: <https://prometheus.io/docs/instrumenting/exposition_formats/> (0.0.4): `# HELP` and
//! `# TYPE` once per family before its samples, label values escaped (`\\`, `\"`, `\n`), HELP text
//! escaped (`\\`, `\n`), floats as Go writes them (`NaN`, `+Inf`, `-Inf`), histograms as cumulative
//! `_bucket{le="..."}` samples ending with `le="+Inf"` equal to `_count`, then `_sum` and `_count`.

use super::bank::RegisterBank;
use super::registers::{self, BLOCK_LEN, status};
use crate::status::{Health, MetricsStatus, MqttLink, Shared};
use std::fmt::Write as _;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

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

/// The status bits of register 10 by name, exported as `fme_status_bit{name}`: the names of the MQTT
/// `activity` JSON (one table, [`status::NAMES`]).
pub const STATUS_BITS: [(&str, u16); 11] = status::NAMES;

// ---------------------------------------------------------------------------------------------
// The text format.

/// Kind of a metric family (`# TYPE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Counter,
    Gauge,
    Histogram,
}

/// A Prometheus text-format (0.0.4) document under construction: one family per call, each with its
/// `# HELP` and `# TYPE` lines. Names are checked in debug builds (and by the tests over the whole
/// output); a value is written as Go's `strconv.FormatFloat` would parse it back.
#[derive(Debug, Default)]
pub struct Exposition {
    out: String,
    #[cfg(debug_assertions)]
    names: Vec<String>,
}

/// Whether `s` is a valid metric name (`[a-zA-Z_:][a-zA-Z0-9_:]*`).
pub fn valid_metric_name(s: &str) -> bool {
    let mut c = s.chars();
    c.next().is_some_and(|f| f.is_ascii_alphabetic() || f == '_' || f == ':')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_' || x == ':')
}

/// Whether `s` is a valid label name (`[a-zA-Z_][a-zA-Z0-9_]*`, not starting with `__`).
pub fn valid_label_name(s: &str) -> bool {
    let mut c = s.chars();
    !s.starts_with("__")
        && c.next().is_some_and(|f| f.is_ascii_alphabetic() || f == '_')
        && c.all(|x| x.is_ascii_alphanumeric() || x == '_')
}

/// Appends `v` as the text format writes a sample value.
fn push_value(out: &mut String, v: f64) {
    if v.is_nan() {
        out.push_str("NaN");
    } else if v.is_infinite() {
        out.push_str(if v > 0.0 { "+Inf" } else { "-Inf" });
    } else {
        let _ = write!(out, "{v}");
    }
}

/// Appends a label value with `\`, `"` and newline escaped.
fn push_label_value(out: &mut String, v: &str) {
    for c in v.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
}

/// Appends HELP text with `\` and newline escaped.
fn push_help(out: &mut String, v: &str) {
    for c in v.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
}

impl Exposition {
    /// An empty document.
    pub fn new() -> Self {
        Self { out: String::with_capacity(16 * 1024), ..Self::default() }
    }

    fn header(&mut self, name: &str, kind: Kind, help: &str) {
        debug_assert!(valid_metric_name(name), "bad metric name {name:?}");
        debug_assert!(kind != Kind::Counter || name.ends_with("_total"), "counter {name} must end in _total");
        #[cfg(debug_assertions)]
        {
            debug_assert!(!self.names.iter().any(|n| n == name), "family {name} written twice");
            self.names.push(name.to_string());
        }
        let kind = match kind {
            Kind::Counter => "counter",
            Kind::Gauge => "gauge",
            Kind::Histogram => "histogram",
        };
        let _ = write!(self.out, "# HELP {name} ");
        push_help(&mut self.out, help);
        let _ = write!(self.out, "\n# TYPE {name} {kind}\n");
    }

    fn sample(&mut self, name: &str, suffix: &str, labels: &[(&str, &str)], value: f64) {
        self.out.push_str(name);
        self.out.push_str(suffix);
        if !labels.is_empty() {
            self.out.push('{');
            for (i, (k, v)) in labels.iter().enumerate() {
                debug_assert!(valid_label_name(k), "bad label name {k:?}");
                if i > 0 {
                    self.out.push(',');
                }
                self.out.push_str(k);
                self.out.push_str("=\"");
                push_label_value(&mut self.out, v);
                self.out.push('"');
            }
            self.out.push('}');
        }
        self.out.push(' ');
        push_value(&mut self.out, value);
        self.out.push('\n');
    }

    /// A gauge without labels.
    pub fn gauge(&mut self, name: &str, help: &str, v: f64) {
        self.header(name, Kind::Gauge, help);
        self.sample(name, "", &[], v);
    }

    /// A gauge with one label: one sample per `(label value, value)`.
    pub fn gauge_by(&mut self, name: &str, help: &str, label: &str, items: &[(&str, f64)]) {
        self.header(name, Kind::Gauge, help);
        for (l, v) in items {
            self.sample(name, "", &[(label, l)], *v);
        }
    }

    /// An info gauge: one sample of value 1 carrying `labels`.
    pub fn info(&mut self, name: &str, help: &str, labels: &[(&str, &str)]) {
        self.header(name, Kind::Gauge, help);
        self.sample(name, "", labels, 1.0);
    }

    /// A counter without labels (`name` ends in `_total`).
    pub fn counter(&mut self, name: &str, help: &str, v: u64) {
        self.header(name, Kind::Counter, help);
        self.sample(name, "", &[], v as f64);
    }

    /// A counter with one label: one sample per `(label value, value)`.
    pub fn counter_by(&mut self, name: &str, help: &str, label: &str, items: &[(&str, u64)]) {
        self.header(name, Kind::Counter, help);
        for (l, v) in items {
            self.sample(name, "", &[(label, l)], *v as f64);
        }
    }

    /// A histogram: `buckets` are `(upper bound, samples <= bound)` in increasing bound order,
    /// cumulative; a `+Inf` bucket equal to `count` is added unless the last bound is `+Inf` (then
    /// its count must be `count`). Counts are made non-decreasing and capped at `count`, so the
    /// output is a valid histogram whatever the input.
    pub fn histogram(&mut self, name: &str, help: &str, buckets: &[(f64, u64)], count: u64, sum: f64) {
        self.header(name, Kind::Histogram, help);
        let mut prev = 0u64;
        let mut le = String::with_capacity(16);
        for &(bound, n) in buckets.iter().filter(|(b, _)| b.is_finite()) {
            let n = n.clamp(prev, count);
            prev = n;
            le.clear();
            push_value(&mut le, bound);
            self.sample(name, "_bucket", &[("le", &le)], n as f64);
        }
        self.sample(name, "_bucket", &[("le", "+Inf")], count as f64);
        self.sample(name, "_sum", &[], sum);
        self.sample(name, "_count", &[], count as f64);
    }

    /// The document.
    pub fn finish(self) -> String {
        self.out
    }
}

// ---------------------------------------------------------------------------------------------
// What is exported.

/// Everything one scrape exports, copied at once (the health lock is held only for the copy).
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// The health snapshot.
    pub health: Health,
    /// When it was taken.
    pub now: Instant,
    /// The register block the PLC reads (status word, fault code, feeding).
    pub block: [u16; BLOCK_LEN],
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

impl Snapshot {
    /// Copies what a scrape exports from the shared state and the bank.
    pub fn take(shared: &Shared, bank: &RegisterBank, stale_after: Duration) -> Self {
        let h = &shared.history;
        let m: &MetricsStatus = &shared.metrics;
        Self {
            health: shared.health(),
            now: Instant::now(),
            block: bank.block(),
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

fn b(v: bool) -> f64 {
    if v { 1.0 } else { 0.0 }
}

/// Every exported metric family (`docs/metrics.md` lists them). Base units (s, m/s); counters end
/// in `_total`. Adding a family is one call here.
pub fn families(s: &Snapshot, e: &mut Exposition) {
    let h = &s.health;
    let (maj, min) = registers::version();
    let map = format!("{maj}.{min}");
    e.info(
        "fme_build_info",
        "fme version and register-map version (value 1).",
        &[("version", env!("CARGO_PKG_VERSION")), ("register_map", &map)],
    );
    e.gauge(
        "fme_uptime_seconds",
        "Time since the daemon started, s.",
        s.now.saturating_duration_since(h.started).as_secs_f64(),
    );

    // The activity index (paper eq. 5) as the registers publish it: NaN when there is no value or it
    // is older than output.stale_after_s.
    let age = h.last_sample_at.map(|t| s.now.saturating_duration_since(t));
    let sample = h.last_sample.filter(|_| age.is_some_and(|a| a <= s.stale_after));
    let nan = f64::NAN;
    e.gauge(
        "fme_activity_mean_meters_per_second",
        "Swarm mean 3D speed (activity index, paper eq. 5), m/s; NaN when unavailable or stale.",
        sample.map_or(nan, |x| x.mean.get()),
    );
    e.gauge(
        "fme_activity_smoothed_meters_per_second",
        "Smoothed activity index (motion.smoothing_s), m/s; NaN when unavailable or stale.",
        sample.map_or(nan, |x| x.smoothed.get()),
    );
    e.gauge(
        "fme_activity_ci95_half_width_meters_per_second",
        "Half-width of the 95% interval of the activity mean, m/s; NaN when unavailable or stale.",
        sample.map_or(nan, |x| x.ci95_half.get()),
    );
    e.gauge(
        "fme_activity_mean_body_lengths_per_second",
        "Swarm mean speed in body lengths per second; NaN when unavailable or stale.",
        sample.map_or(nan, |x| x.mean_body_lengths),
    );
    e.gauge(
        "fme_activity_age_seconds",
        "Age of the last activity value, s (+Inf before the first).",
        age.map_or(f64::INFINITY, |a| a.as_secs_f64()),
    );
    e.gauge(
        "fme_fish",
        "Fish in the activity mean (0 when unavailable or stale).",
        sample.map_or(0.0, |x| f64::from(x.fish)),
    );
    e.gauge("fme_tracks", "Confirmed tracks.", f64::from(h.stage.tracks));

    // What the PLC reads in registers 10, 11 and 17.
    let word = s.block[10];
    e.gauge("fme_status_word", "Status bits as register 10 holds them (docs/plc-integration.md).", f64::from(word));
    let bits: Vec<(&str, f64)> = STATUS_BITS.iter().map(|&(name, bit)| (name, b(word & bit != 0))).collect();
    e.gauge_by("fme_status_bit", "Each status bit of register 10 by name (0/1).", "name", &bits);
    e.gauge(
        "fme_fault_code",
        "Fault code of register 11: 0 none, 1 camera, 2 detector, 3 depth, 4 pipeline stalled, 5 PLC link, 6 stopped, 7 unlike fish.",
        f64::from(s.block[11]),
    );
    e.gauge(
        "fme_fault_active",
        "Register 11 holds a fault (0/1): codes 1-5 and 7; 0 none and 6 stopped are not (as history, console and MQTT count them).",
        b(crate::status::is_fault_code(s.block[11])),
    );
    e.gauge("fme_feeding_recommended", "Feeding recommended (register 17, 0/1).", f64::from(s.block[17]));

    // Camera and pipeline: rates are counters (the frame rate is rate(fme_frames_captured_total)).
    e.counter("fme_frames_captured_total", "Frames captured.", h.frames_captured);
    e.counter("fme_frames_processed_total", "Frames processed by the pipeline.", h.frames_processed);
    e.counter(
        "fme_frames_dropped_total",
        "Frames dropped: capture queue full, driver sequence gaps.",
        h.frames_dropped,
    );
    e.counter(
        "fme_capture_errors_total",
        "Capture errors (timeouts, read errors, oversized frames).",
        h.capture_errors,
    );
    e.counter("fme_camera_reconnects_total", "Camera reconnects.", h.reconnects);
    e.counter("fme_pipeline_errors_total", "Pipeline errors (bad frames, stage failures).", h.pipeline_errors);
    e.counter("fme_updates_total", "Register updates published.", h.updates);
    e.counter("fme_detector_runs_total", "Detector runs (rate() of it: runs per second).", h.stage.detector_runs);
    e.counter("fme_depth_runs_total", "Depth network runs (rate() of it: runs per second).", h.stage.depth_runs);
    e.gauge(
        "fme_calibration_residual_meters",
        "RMS residual of the metric depth fit on the reference objects (paper eq. 1-2), m; NaN when uncalibrated.",
        if h.fit_state.fitted { h.fit_state.residual_m } else { nan },
    );
    e.gauge(
        "fme_calibration_references_visible",
        "Reference objects visible in the last depth frame.",
        f64::from(h.fit_state.references_visible),
    );
    let l = &h.latency;
    let buckets: Vec<(f64, u64)> =
        LATENCY_BOUNDS_S.iter().map(|&le| (le, l.count_below_ms((le * 1000.0).round() as u32))).collect();
    e.histogram(
        "fme_frame_to_register_latency_seconds",
        "Time from a frame's arrival to the register update it produced, s (1 ms resolution).",
        &buckets,
        l.count(),
        l.sum_ms() / 1000.0,
    );

    // Modbus (docs/plc-integration.md).
    let m = &s.modbus;
    e.counter("fme_modbus_requests_total", "Modbus requests served (server roles).", m.requests);
    e.counter("fme_modbus_exceptions_total", "Modbus exception responses sent (server roles).", m.exceptions);
    e.gauge("fme_modbus_tcp_connections", "Modbus TCP connections open now.", m.tcp_open as f64);
    e.counter_by(
        "fme_modbus_tcp_closed_total",
        "Modbus TCP connections closed by the server: idle timeout, evicted for a newer one, refused (allow), bad MBAP header.",
        "reason",
        &[("idle", m.tcp_idle_closed), ("evicted", m.tcp_evicted), ("refused", m.tcp_refused), ("bad_frame", m.tcp_bad_frames)],
    );
    e.counter("fme_modbus_tcp_accept_errors_total", "Failed accepts of the Modbus TCP server.", m.tcp_accept_errors);
    e.counter("fme_modbus_task_panics_total", "Modbus connection or server tasks that panicked.", m.task_panics);
    e.counter("fme_plc_writes_total", "Successful block writes to the PLC (client roles).", m.client_writes);
    e.counter(
        "fme_plc_write_failures_total",
        "Failed connects or block writes to the PLC (client roles).",
        m.client_failures,
    );

    // History (docs/history.md) and recorder (docs/recording.md).
    e.counter("fme_history_rows_written_total", "History rows written.", s.history[0]);
    e.counter("fme_history_rows_dropped_total", "History rows dropped (writer queue full).", s.history[1]);
    e.counter(
        "fme_history_rows_failed_total",
        "History rows not written (write error, or paused after one).",
        s.history[2],
    );
    e.gauge("fme_history_paused", "History paused after a write error (0/1).", b(s.history_paused));
    let r = &h.record;
    e.gauge("fme_record_active", "The black-box recorder runs (0/1).", b(r.active));
    e.counter("fme_record_frames_written_total", "Frames written to the black-box ring.", r.frames_written);
    e.counter("fme_record_frames_dropped_total", "Frames not recorded (queue full or disk failed).", r.frames_dropped);
    e.counter("fme_record_write_errors_total", "Recorder write errors.", r.write_errors);
    e.gauge("fme_record_disk_fault", "Recording paused after a write error (0/1).", b(r.disk_fault));
    e.gauge("fme_record_ring_bytes", "Bytes in the black-box ring.", r.ring_bytes as f64);
    e.gauge("fme_record_ring_frames", "Frames in the black-box ring.", r.ring_frames as f64);
    e.counter("fme_record_saved_total", "Frozen recordings written.", r.saved);
    e.counter("fme_record_snapshots_total", "Snapshots written.", r.snapshots);

    // MQTT telemetry (docs/mqtt.md).
    let q = &h.mqtt;
    let links = [MqttLink::Disabled, MqttLink::Connecting, MqttLink::Connected, MqttLink::AuthFailed];
    let states: Vec<(&str, f64)> = links.iter().map(|l| (l.name(), b(q.link == *l))).collect();
    e.gauge_by("fme_mqtt_link", "MQTT link state: 1 for the current one.", "state", &states);
    e.gauge("fme_mqtt_queued_messages", "MQTT messages waiting in the queue.", q.queued as f64);
    e.counter(
        "fme_mqtt_published_total",
        "MQTT messages acknowledged by the broker (QoS 1) or written to it (QoS 0).",
        q.published,
    );
    e.counter(
        "fme_mqtt_delivered_after_reconnect_total",
        "MQTT messages delivered after waiting in the queue for the broker.",
        q.delivered_after_reconnect,
    );
    e.counter("fme_mqtt_dropped_total", "MQTT messages dropped: the queue was full (oldest first).", q.dropped);
    e.counter("fme_mqtt_reconnects_total", "MQTT connections made after the first one.", q.reconnects);
    e.counter("fme_mqtt_connect_attempts_total", "MQTT connection attempts.", q.connect_attempts);
    e.counter(
        "fme_mqtt_auth_failures_total",
        "MQTT connection attempts refused for the login or the certificate (status bit 9).",
        q.auth_failures,
    );
    let age = q.last_publish_unix_ms.map_or(f64::NAN, |t| (crate::history::now_unix_ms() - t).max(0) as f64 / 1000.0);
    e.gauge("fme_mqtt_last_publish_age_seconds", "Time since the last acknowledged MQTT message, s (NaN: never).", age);

    // This endpoint.
    let (codes, refused, aborted) = &s.http;
    let names = MetricsStatus::CODES.map(|c| c.to_string());
    let by_code: Vec<(&str, u64)> = names.iter().map(String::as_str).zip(codes.iter().copied()).collect();
    e.counter_by("fme_metrics_http_responses_total", "Responses of this endpoint by status code.", "code", &by_code);
    e.counter(
        "fme_metrics_connections_refused_total",
        "Connections to this endpoint closed at accept (connection limits, output.metrics.allow) or to make room for a steady scraper.",
        *refused,
    );
    e.counter(
        "fme_metrics_connections_aborted_total",
        "Connections to this endpoint that ended before a complete request.",
        *aborted,
    );
}

/// The exposition of `s`.
pub fn render(s: &Snapshot) -> String {
    let mut e = Exposition::new();
    families(s, &mut e);
    e.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use fme_core::pipeline::{ActivitySample, QualityFlags};
    use fme_core::units::{MetresPerSecond, Seconds};

    fn snapshot() -> Snapshot {
        let shared = Shared::new(String::new(), 4);
        let bank = RegisterBank::new();
        shared.with_health(|h| {
            h.frames_captured = 120;
            h.frames_processed = 118;
            h.last_sample = Some(ActivitySample {
                timestamp: Seconds(4.0),
                mean: MetresPerSecond(0.25),
                mean_body_lengths: 1.25,
                smoothed: MetresPerSecond(0.2),
                ci95_half: MetresPerSecond(0.03),
                fish: 17,
                latency: Seconds(0.0),
                flags: QualityFlags::default(),
                scale: fme_core::pipeline::ScaleSource::References,
            });
            h.last_sample_at = Some(Instant::now());
            for ms in [0.5, 3.0, 7.0, 40.0, 2000.0] {
                h.latency.record(ms);
            }
        });
        let inp = registers::RegisterInputs {
            status: status::RUNNING | status::CAMERA_OK | status::STALE,
            fault: registers::FaultCode::Depth,
            feeding: true,
            ..Default::default()
        };
        bank.publish(registers::encode(&inp, crate::config::WordOrder::HighFirst));
        Snapshot::take(&shared, &bank, Duration::from_secs(5))
    }

    /// The samples of `text` as (name with labels, value), checking each line's grammar on the way.
    fn samples(text: &str) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for line in text.lines() {
            if line.starts_with('#') {
                let mut w = line.splitn(4, ' ');
                let (_, kw, name) = (w.next(), w.next(), w.next().unwrap_or(""));
                assert!(matches!(kw, Some("HELP") | Some("TYPE")), "{line}");
                assert!(valid_metric_name(name), "{line}");
                continue;
            }
            let (key, value) = line.rsplit_once(' ').unwrap_or(("", ""));
            let name = key.split('{').next().unwrap_or("");
            assert!(valid_metric_name(name), "{line}");
            assert!(value == "NaN" || value == "+Inf" || value.parse::<f64>().is_ok(), "{line}");
            out.push((key.to_string(), value.to_string()));
        }
        out
    }

    fn value(text: &str, key: &str) -> String {
        samples(text).into_iter().find(|(k, _)| k == key).map(|(_, v)| v).unwrap_or_else(|| panic!("no {key}"))
    }

    #[test]
    fn escapes_label_values_and_help() {
        let mut e = Exposition::new();
        e.info("x_info", "a \\ b\nc \"q\"", &[("path", "C:\\dir \"quoted\"\nnext")]);
        let t = e.finish();
        assert_eq!(
            t,
            "# HELP x_info a \\\\ b\\nc \"q\"\n# TYPE x_info gauge\nx_info{path=\"C:\\\\dir \\\"quoted\\\"\\nnext\"} 1\n"
        );
        let parsed = openmetrics_parser::prometheus::parse_prometheus(&t).expect("parses");
        assert_eq!(parsed.families.len(), 1);
    }

    #[test]
    fn special_values_are_written_as_go_parses_them() {
        let mut e = Exposition::new();
        e.gauge("a", "h", f64::NAN);
        e.gauge("b", "h", f64::INFINITY);
        e.gauge("c", "h", f64::NEG_INFINITY);
        e.gauge("d", "h", 0.1 + 0.2);
        e.counter("e_total", "h", u64::from(u32::MAX) + 1);
        let t = e.finish();
        for (k, v) in
            [("a", "NaN"), ("b", "+Inf"), ("c", "-Inf"), ("d", "0.30000000000000004"), ("e_total", "4294967296")]
        {
            assert_eq!(value(&t, k), v, "{k}");
        }
    }

    #[test]
    fn histogram_is_cumulative_and_ends_with_inf_equal_to_count() {
        let mut e = Exposition::new();
        // A decreasing count and one above the total are repaired, not written.
        e.histogram("lat_seconds", "h", &[(0.1, 2), (0.5, 1), (1.0, 9)], 5, 1.5);
        let t = e.finish();
        let s = samples(&t);
        let buckets: Vec<&str> = s.iter().filter(|(k, _)| k.contains("_bucket")).map(|(_, v)| v.as_str()).collect();
        assert_eq!(buckets, ["2", "2", "5", "5"]);
        assert_eq!(value(&t, "lat_seconds_bucket{le=\"+Inf\"}"), "5");
        assert_eq!(value(&t, "lat_seconds_bucket{le=\"0.1\"}"), "2");
        assert_eq!(value(&t, "lat_seconds_bucket{le=\"1\"}"), "5");
        assert_eq!(value(&t, "lat_seconds_sum"), "1.5");
        assert_eq!(value(&t, "lat_seconds_count"), "5");
        openmetrics_parser::prometheus::parse_prometheus(&t).expect("parses");
    }

    #[test]
    fn the_parser_used_as_oracle_rejects_broken_expositions() {
        let parse = |t: &str| openmetrics_parser::prometheus::parse_prometheus(t).is_ok();
        let ok = "# HELP h_seconds h\n# TYPE h_seconds histogram\nh_seconds_bucket{le=\"1\"} 1\nh_seconds_bucket{le=\"+Inf\"} 2\nh_seconds_sum 3\nh_seconds_count 2\n";
        assert!(parse(ok));
        assert!(!parse(&ok.replace("{le=\"1\"} 1", "{le=\"1\"} 3")), "buckets not cumulative");
        assert!(!parse(&ok.replace("h_seconds_bucket{le=\"+Inf\"} 2\n", "")), "no +Inf bucket");
        assert!(!parse("# TYPE g gauge\ng{name=\"a\\q\"} 1\n"), "bad escape in a label value");
        assert!(!parse("# TYPE g gauge\ng 1 2 3\n"), "garbage after the value");
    }

    #[test]
    fn every_family_once_with_valid_names_and_a_strict_parser_accepts_it() {
        let snap = snapshot();
        let t = render(&snap);
        let mut families = Vec::new();
        for line in t.lines().filter(|l| l.starts_with("# TYPE ")) {
            let name = line.split(' ').nth(2).unwrap_or("").to_string();
            assert!(!families.contains(&name), "{name} twice");
            families.push(name);
        }
        assert!(families.len() >= 50, "{} families", families.len());
        assert!(families.iter().all(|f| f.starts_with("fme_")), "{families:?}");
        let parsed = openmetrics_parser::prometheus::parse_prometheus(&t).unwrap_or_else(|e| panic!("{e:?}\n{t}"));
        assert_eq!(parsed.families.len(), families.len());
        assert_eq!(value(&t, "fme_fish"), "17");
        assert_eq!(value(&t, "fme_activity_mean_meters_per_second"), "0.25");
        assert_eq!(value(&t, "fme_frames_captured_total"), "120");
        assert_eq!(value(&t, "fme_status_bit{name=\"camera_ok\"}"), "1");
        assert_eq!(value(&t, "fme_status_bit{name=\"stale\"}"), "1");
        assert_eq!(value(&t, "fme_status_bit{name=\"detector_ok\"}"), "0");
        assert_eq!(value(&t, "fme_status_word"), "19");
        assert_eq!(value(&t, "fme_fault_code"), "3");
        assert_eq!(value(&t, "fme_feeding_recommended"), "1");
        assert_eq!(value(&t, "fme_activity_age_seconds").parse::<f64>().map(|a| a < 5.0), Ok(true));
        assert_eq!(
            value(&t, &format!("fme_build_info{{version=\"{}\",register_map=\"0.1\"}}", env!("CARGO_PKG_VERSION"))),
            "1"
        );
        // Latencies 0.5, 3, 7, 40, 2000 ms.
        let l = "fme_frame_to_register_latency_seconds";
        for (le, n) in [("0.005", "2"), ("0.01", "3"), ("0.05", "4"), ("1", "4"), ("+Inf", "5")] {
            assert_eq!(value(&t, &format!("{l}_bucket{{le=\"{le}\"}}")), n, "le {le}");
        }
        assert_eq!(value(&t, &format!("{l}_count")), "5");
        assert_eq!(value(&t, &format!("{l}_sum")), "2.0505");
    }

    #[test]
    fn a_stale_value_is_nan_and_no_fish() {
        let mut snap = snapshot();
        snap.health.last_sample_at = snap.now.checked_sub(Duration::from_secs(6));
        let t = render(&snap);
        assert_eq!(value(&t, "fme_activity_mean_meters_per_second"), "NaN");
        assert_eq!(value(&t, "fme_activity_smoothed_meters_per_second"), "NaN");
        assert_eq!(value(&t, "fme_fish"), "0");
        snap.health.last_sample_at = None;
        assert_eq!(value(&render(&snap), "fme_activity_age_seconds"), "+Inf");
    }
}
