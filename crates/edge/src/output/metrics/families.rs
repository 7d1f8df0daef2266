//! Every exported metric family (`docs/metrics.md` lists them), one function per group. Base units
//! (s, m/s); counters end in `_total`. Adding a family is one call in its group.

use super::{Exposition, LATENCY_BOUNDS_S, Scrape};
use crate::output::registers;
use crate::status::{MetricsStatus, MqttLink};

fn b(v: bool) -> f64 {
    if v { 1.0 } else { 0.0 }
}

/// Every exported metric family, in exposition order.
pub fn families(s: &Scrape, e: &mut Exposition) {
    build_and_activity(s, e);
    plc_view(s, e);
    camera_and_pipeline(s, e);
    modbus(s, e);
    history_and_recorder(s, e);
    mqtt(s, e);
    endpoint(s, e);
}

/// Build, uptime and the activity index.
fn build_and_activity(s: &Scrape, e: &mut Exposition) {
    let h = &s.health;
    let (maj, min) = registers::version();
    let map = format!("{maj}.{min}");
    let nets = &h.networks;
    let form = |n: &Option<fme_core::pipeline::Network>| n.as_ref().map_or("none", |n| n.form.name());
    let backend = nets.detector.as_ref().or(nets.depth.as_ref()).map_or("none", |n| n.backend.name());
    e.info(
        "fme_build_info",
        "fme version, register-map version, inference backend and the networks' numeric forms (value 1).",
        &[
            ("version", env!("CARGO_PKG_VERSION")),
            ("register_map", &map),
            ("backend", backend),
            ("detector", form(&nets.detector)),
            ("depth", form(&nets.depth)),
        ],
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
}

/// What the PLC reads: status bits, fault code, feeding (of the last published update).
fn plc_view(s: &Scrape, e: &mut Exposition) {
    // What the PLC reads in registers 10, 11 and 17.
    let u = &s.update;
    let word = u.status.bits();
    e.gauge("fme_status_word", "Status bits as register 10 holds them (docs/plc-integration.md).", f64::from(word));
    let bits: Vec<(&str, f64)> = u.status.named().map(|(name, on)| (name, b(on))).collect();
    e.gauge_by("fme_status_bit", "Each status bit of register 10 by name (0/1).", "name", &bits);
    e.gauge(
        "fme_fault_code",
        "Fault code of register 11: 0 none, 1 camera, 2 detector, 3 depth, 4 pipeline stalled, 5 PLC link, 6 stopped, 7 unlike fish.",
        f64::from(u.fault as u16),
    );
    e.gauge(
        "fme_fault_active",
        "Register 11 holds a fault (0/1): codes 1-5 and 7; 0 none and 6 stopped are not (as history, console and MQTT count them).",
        b(u.fault.is_fault()),
    );
    e.gauge("fme_feeding_recommended", "Feeding recommended (register 17, 0/1).", b(u.feeding));
}

/// Camera and pipeline counters, calibration, latency.
fn camera_and_pipeline(s: &Scrape, e: &mut Exposition) {
    let h = &s.health;
    let nan = f64::NAN;
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
}

/// The Modbus roles.
fn modbus(s: &Scrape, e: &mut Exposition) {
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
}

/// History and the black-box recorder.
fn history_and_recorder(s: &Scrape, e: &mut Exposition) {
    let h = &s.health;
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
}

/// MQTT telemetry.
fn mqtt(s: &Scrape, e: &mut Exposition) {
    let h = &s.health;
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
}

/// This endpoint's own counters.
fn endpoint(s: &Scrape, e: &mut Exposition) {
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
