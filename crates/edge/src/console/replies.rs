//! The console's replies that are views of the shared state: one function per command, each
//! writing the reply's body (the `OK` / `ERR` line is the session's).

use crate::output::bank::RegisterBank;
use crate::output::registers::{self, BLOCK_LEN};
use crate::status::{FaultCode, Shared};
use std::fmt::Write as _;

/// A reply's outcome: `OK`, or `ERR` with the reason.
pub(super) type Reply = Result<(), String>;

/// `v` as the registers carry it (float32), `decimals` decimals, `-` when unavailable.
fn float_text(v: f64, decimals: usize) -> String {
    let v = v as f32;
    if v.is_finite() { format!("{v:.decimals$}") } else { "-".into() }
}

/// One-line activity summary (console `activity`, `stream`, the live view). Every value and flag
/// comes from one published update, so a value and the flags beside it are of the same update
/// (the PLC's view); a fault ([`crate::status::FaultCode::is_fault`]) is named at the end.
pub fn activity_line(_shared: &Shared, bank: &RegisterBank) -> String {
    let u = bank.update();
    let fish = u.fish.min(u32::from(u16::MAX));
    let mean = u.mean_mps as f32;
    let mut line = if mean.is_finite() {
        format!(
            "activity {mean:.3} m/s ({} BL/s) smoothed {} m/s ±{} fish {fish} hb {} {}",
            float_text(u.mean_bls, 2),
            float_text(u.smoothed_mps, 3),
            float_text(u.ci95_half_mps, 3),
            u.heartbeat,
            u.status.words()
        )
    } else {
        format!("activity n/a fish {fish} hb {} {}", u.heartbeat, u.status.words())
    };
    if u.fault.is_fault() {
        let _ = write!(line, " fault {}", u.fault.name());
    }
    line
}

/// The console `mqtt` text: link state, broker, queue, counters, last publish (age at `now_ms`).
pub fn mqtt_text(m: &crate::status::MqttHealth, now_ms: i64) -> String {
    if m.link == crate::status::MqttLink::Disabled {
        return "mqtt disabled (output.mqtt.enabled = false)".into();
    }
    let last = match m.last_publish_unix_ms {
        Some(t) => {
            let mut s = String::new();
            crate::history::format_time(t, &mut s);
            format!("{s} ({:.1} s ago)", (now_ms - t).max(0) as f64 / 1000.0)
        }
        None => "never".into(),
    };
    format!(
        "link {}\nbroker {}\nqueued {}\npublished {}\ndelivered-after-reconnect {}\ndropped {}\nreconnects {}\nconnect-attempts {}\nauth-failures {}\nlast-publish {}\nlast-error {}",
        m.link.name(),
        m.broker,
        m.queued,
        m.published,
        m.delivered_after_reconnect,
        m.dropped,
        m.reconnects,
        m.connect_attempts,
        m.auth_failures,
        last,
        if m.last_error.is_empty() { "-" } else { &m.last_error },
    )
}

/// The `record` reply: the black box's ring, drops, errors and last file.
pub(super) fn record(shared: &Shared, body: &mut String) -> Reply {
    let r = shared.health().record;
    let _ = write!(
        body,
        "ring {}
ring-frames {}
ring-mb {:.1}
frames-written {}
frames-dropped {}
write-errors {}
disk {}
saved {}
snapshots {}
last {}",
        if r.active { "on" } else { "off" },
        r.ring_frames,
        r.ring_bytes as f64 / 1e6,
        r.frames_written,
        r.frames_dropped,
        r.write_errors,
        if r.disk_fault { "FAULT (recording paused)" } else { "ok" },
        r.saved,
        r.snapshots,
        if r.last.is_empty() { "-" } else { &r.last }
    );
    Ok(())
}

/// The `status` reply: running state, the last update's status bits, fault and feeding, and where
/// each output stands.
pub(super) fn status(shared: &Shared, bank: &RegisterBank, body: &mut String) -> Reply {
    let u = bank.update();
    let h = shared.health();
    let _ = write!(
        body,
        "state {}\nstatus 0x{:04x} {}\nfault {} ({}{})\nsource {}\nuptime {} s\nfeeding-recommended {}\ndetections {}\nhistory {}\nmodbus {}\nmetrics {}\nweb {}",
        if shared.stopping() { "stopping" } else { "running" },
        u.status.bits(),
        u.status.words(),
        u.fault as u16,
        u.fault.name(),
        if u.fault != FaultCode::None && !u.fault.is_fault() { ", not a fault" } else { "" },
        h.source,
        h.started.elapsed().as_secs(),
        u8::from(u.feeding),
        h.stage.familiarity.describe(),
        shared.history.describe(),
        shared.modbus.get().map_or("off", String::as_str),
        shared.metrics.describe(),
        shared.web.get().map_or("off", String::as_str)
    );
    Ok(())
}

/// The `version` reply: fme, register map and inference backend.
pub(super) fn version(body: &mut String) -> Reply {
    let (maj, min) = registers::version();
    let _ = write!(
        body,
        "fme {} (register map {maj}.{min}, {BLOCK_LEN} registers; {})",
        env!("CARGO_PKG_VERSION"),
        fme_core::infer::backend::BUILD
    );
    Ok(())
}

/// The `calib` reply: the metric depth fit in use.
pub(super) fn calib(shared: &Shared, body: &mut String) -> Reply {
    let c = shared.health().fit_state;
    if c.fitted {
        let _ = write!(
            body,
            "scale {:.6}\nshift {:.6}\nresidual {:.3} m\nreferences-visible {}\nscale-from {}",
            c.scale,
            c.shift,
            c.residual_m,
            c.references_visible,
            c.source.name()
        );
        if c.source == fme_core::pipeline::ScaleSource::Fish {
            let _ = write!(body, " ({} fish)", c.fish_rulers);
        }
        if c.ruler_length_m > 0.0 {
            let how = if c.ruler_length_learned { "measured on the references" } else { "configured" };
            let _ = write!(body, "\nfish-length {:.3} m ({how})", c.ruler_length_m);
        }
    } else {
        let _ = write!(body, "not calibrated (references-visible {})", c.references_visible);
    }
    Ok(())
}

/// The `regs` reply: one block, decoded by the register map the encoder follows.
pub(super) fn regs(shared: &Shared, bank: &RegisterBank, body: &mut String) -> Reply {
    // One block, decoded by the register map the encoder follows.
    let r = bank.block();
    let order = shared.word_order();
    body.push_str("reg    name                 raw            value\n");
    for reg in &registers::MAP {
        let (addr, raw) = if reg.len() == 2 {
            (format!("{}-{}", reg.addr, reg.addr + 1), format!("0x{:04x} 0x{:04x}", r[reg.addr], r[reg.addr + 1]))
        } else {
            (reg.addr.to_string(), format!("0x{:04x}", r[reg.addr]))
        };
        let _ = writeln!(body, "{addr:<5}  {:<20} {raw:<14} {}", reg.name, reg.decode(&r, order));
    }
    let w = bank.writable();
    let _ = write!(body, "hr100-103 (plc writable): {} {} {} {}", w[0], w[1], w[2], w[3]);
    Ok(())
}

/// The `counters` reply: frames, drops, errors, Modbus, history, recorder, latency.
pub(super) fn counters(shared: &Shared, bank: &RegisterBank, body: &mut String) -> Reply {
    let h = shared.health();
    let m = bank.counters();
    let q = |x: Option<f64>| x.map_or("n/a".to_string(), |v| format!("{v:.0} ms"));
    let _ = write!(
        body,
        "frames-captured {}\nframes-processed {}\nframes-dropped {}\ncamera-fps {:.1}\ncapture-errors {}\nreconnects {}\npipeline-errors {}\nupdates {}\nmodbus-requests {}\nmodbus-exceptions {}\nmodbus-tcp-open {}\nmodbus-tcp-idle-closed {}\nmodbus-tcp-evicted {}\nmodbus-tcp-accept-errors {}\nmodbus-tcp-refused {}\nmodbus-tcp-bad-frames {}\nmodbus-task-panics {}\nplc-writes {}\nplc-failures {}\nconsole-output-dropped {}\nhistory-rows {}\nhistory-dropped {}\nhistory-failed {}\nrecord-written {}\nrecord-dropped {}\nrecord-write-errors {}\nlatency-p50 {}\nlatency-p99 {}",
        h.frames_captured,
        h.frames_processed,
        h.frames_dropped,
        h.camera_fps,
        h.capture_errors,
        h.reconnects,
        h.pipeline_errors,
        h.updates,
        m.requests,
        m.exceptions,
        m.tcp_open,
        m.tcp_idle_closed,
        m.tcp_evicted,
        m.tcp_accept_errors,
        m.tcp_refused,
        m.tcp_bad_frames,
        m.task_panics,
        m.client_writes,
        m.client_failures,
        super::writer::output_dropped(),
        shared.history.written.load(std::sync::atomic::Ordering::Relaxed),
        shared.history.dropped.load(std::sync::atomic::Ordering::Relaxed),
        shared.history.failed.load(std::sync::atomic::Ordering::Relaxed),
        h.record.frames_written,
        h.record.frames_dropped,
        h.record.write_errors,
        q(h.latency.quantile_ms(0.5)),
        q(h.latency.quantile_ms(0.99)),
    );
    Ok(())
}

/// `record save [label]`: asks the service to freeze the black box.
pub(super) fn record_save(shared: &Shared, label: Option<&str>, body: &mut String) -> Reply {
    if !shared.health().record.active {
        return Err("no black box: record.enabled = false, or no state directory".into());
    }
    shared.requests.request_save(label.unwrap_or("manual"));
    body.push_str("saving: see `record` or `log` for the folder");
    Ok(())
}

/// `snap`: asks the service for a snapshot of the next frame.
pub(super) fn snap(shared: &Shared, body: &mut String) -> Reply {
    shared.requests.request_snapshot();
    body.push_str("snapshot of the next frame requested: see `record` or `log` for the file");
    Ok(())
}

/// `log [n]`: the last `n` log lines (default 10).
pub(super) fn log(shared: &Shared, n: Option<&str>, body: &mut String) -> Reply {
    match n.map(str::parse::<usize>) {
        None => {
            body.push_str(&shared.last_logs(10).join("\n"));
            Ok(())
        }
        Some(Ok(n)) if (1..=10_000).contains(&n) => {
            body.push_str(&shared.last_logs(n).join("\n"));
            Ok(())
        }
        Some(_) => Err("usage: log [n] with n from 1 to 10000".into()),
    }
}

/// `history [hours]`: the hourly summary of the last hours (default 24).
pub(super) fn history(shared: &Shared, n: Option<&str>, body: &mut String) -> Reply {
    match (n.map_or(Ok(24), str::parse::<usize>), shared.history.dir()) {
        (Ok(h), Some(dir)) if (1..=168).contains(&h) => {
            crate::history::hourly_report(dir, crate::history::now_unix_ms(), h)
                .map(|t| body.push_str(&t))
                .map_err(|e| e.to_string())
        }
        (Ok(h), None) if (1..=168).contains(&h) => {
            Err("history is off (set history.dir or run under systemd with StateDirectory=)".into())
        }
        _ => Err("usage: history [hours] with hours from 1 to 168".into()),
    }
}

/// `mqtt`: the telemetry link.
pub(super) fn mqtt(shared: &Shared, body: &mut String) -> Reply {
    body.push_str(&mqtt_text(&shared.health().mqtt, crate::history::now_unix_ms()));
    Ok(())
}

/// `config`: the configuration file in use.
pub(super) fn config(shared: &Shared, body: &mut String) -> Reply {
    body.push_str(shared.config_text.trim_end());
    if body.is_empty() {
        body.push_str("(built-in defaults)");
    }
    Ok(())
}
