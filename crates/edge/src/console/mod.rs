//! The serial field-diagnostics console (line based, case-insensitive; it changes nothing, only
//! `snap` and `record save` ask the service, through [`crate::status::Requests`], to write files).
//!
//! Works with picocom/screen at 115200 baud. Every reply ends with a line `OK` or `ERR <reason>`, so
//! scripts can parse it. Garbage, over-long lines and binary noise get an `ERR` line and never stop
//! the daemon. Output never blocks the console ([`writer`]): a terminal that stops reading loses
//! output (counted: `console-output-dropped`), never its input. Commands: `help`, `status`, `version`, `activity`, `tracks`, `calib`, `regs`,
//! `counters`, `log [n]`, `history [hours]`, `stream on|off`, `config`, `snap`, `record`,
//! `record save [label]` (docs/recording.md).

pub mod writer;

use crate::output::bank::RegisterBank;
use crate::output::registers::{self, BLOCK_LEN};
use crate::status::{FaultCode, Shared};
use std::fmt::Write as _;
use std::time::Duration;

/// Longest accepted command line, characters.
pub const MAX_LINE: usize = 80;

/// One event from the [`LineReader`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LineEvent {
    /// A complete printable line (trimmed).
    Line(String),
    /// The line exceeded [`MAX_LINE`]; the rest of it is discarded.
    TooLong,
    /// The line contained non-printable bytes.
    Binary,
}

/// Assembles lines from raw serial bytes (CR, LF or CRLF terminated) with a bounded buffer.
#[derive(Debug, Default)]
pub struct LineReader {
    buf: String,
    overflow: bool,
    binary: bool,
    last_cr: bool,
}

impl LineReader {
    /// Feeds bytes; calls `on_event` for each finished line.
    pub fn feed(&mut self, bytes: &[u8], mut on_event: impl FnMut(LineEvent)) {
        for &b in bytes {
            let was_cr = std::mem::replace(&mut self.last_cr, b == b'\r');
            match b {
                b'\n' if was_cr => {} // CRLF: the CR already ended the line
                b'\r' | b'\n' => {
                    let ev = if self.overflow {
                        None // already reported when it overflowed
                    } else if self.binary {
                        Some(LineEvent::Binary)
                    } else {
                        let l = self.buf.trim();
                        (!l.is_empty()).then(|| LineEvent::Line(l.to_string()))
                    };
                    self.buf.clear();
                    self.overflow = false;
                    self.binary = false;
                    if let Some(ev) = ev {
                        on_event(ev);
                    }
                }
                0x08 | 0x7f => {
                    self.buf.pop(); // backspace/delete from a terminal
                }
                _ if self.overflow => {}
                _ => {
                    if !(b == b'\t' || (0x20..0x7f).contains(&b)) {
                        self.binary = true;
                    } else {
                        self.buf.push(b as char);
                    }
                    if self.buf.len() > MAX_LINE {
                        self.overflow = true;
                        self.buf.clear();
                        on_event(LineEvent::TooLong);
                    }
                }
            }
        }
    }
}

/// A console session: line assembly, echo and the `stream` flag.
#[derive(Debug, Default)]
pub struct Session {
    reader: LineReader,
    /// Whether `stream on` is active.
    pub stream: bool,
    /// Echo typed characters (terminals like picocom do not echo locally).
    pub echo: bool,
    echo_cr: bool,
}

/// Track rows the pipeline lists for `tracks` at each update, at most.
pub const TRACK_ROWS: usize = 64;

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

const HELP: &str = "commands (case-insensitive; only snap and record save write, to the state directory):
  help            this list
  status          running state, status bits, fault, source, uptime
  version         fme version, register-map version and inference backend
  activity        the last published update (one register block)
  tracks          tracks of the last update: count and rows
  calib           metric depth fit: scale/shift, residual, visible references
  regs            input registers 0-23: name, raw, decoded value (holding registers mirror them)
  counters        frames, drops, errors, reconnects, modbus, latency
  log [n]         last n log lines (default 10)
  history [hours] hourly activity summary of the last hours (default 24, max 168)
  stream on|off   print one activity line per update
  config          the configuration file in use
  snap            snapshot of the next frame (overlays + depth map) into snapshots/
  record          black box state: ring size, drops, errors, last file
  record save [l] freeze the black box into recordings/<UTC>-<l>/
  mqtt            MQTT link state, queued, published, dropped, last publish (docs/mqtt.md)";

impl Session {
    /// The partly typed line as echoed so far (to redraw it after a streamed line), if any.
    pub fn partial_echo(&self) -> Option<&str> {
        (self.echo && !self.reader.overflow && !self.reader.binary && !self.reader.buf.is_empty())
            .then_some(self.reader.buf.as_str())
    }

    /// Feeds received bytes; appends echo and replies to `out`, in order.
    pub fn feed(&mut self, bytes: &[u8], shared: &Shared, bank: &RegisterBank, out: &mut String) {
        for &b in bytes {
            if self.echo {
                let was_cr = std::mem::replace(&mut self.echo_cr, b == b'\r');
                match b {
                    b'\n' if was_cr => {}
                    b'\r' | b'\n' => out.push_str("\r\n"),
                    0x08 | 0x7f => out.push_str("\x08 \x08"),
                    // A flood is not echoed past the line limit; binary noise is not echoed at all.
                    b'\t' | 0x20..=0x7e if !self.reader.overflow && self.reader.buf.len() < MAX_LINE => {
                        out.push(b as char)
                    }
                    _ => {}
                }
            }
            let mut event = None;
            self.reader.feed(std::slice::from_ref(&b), |e| event = Some(e));
            let Some(e) = event else { continue };
            match e {
                LineEvent::Line(l) => self.command(&l, shared, bank, out),
                LineEvent::TooLong => {
                    // The echoed characters are on the line: the error goes on its own.
                    if self.echo {
                        out.push_str("\r\n");
                    }
                    let _ = write!(out, "ERR line too long (max {MAX_LINE} characters)\r\n");
                }
                LineEvent::Binary => out.push_str("ERR binary input ignored\r\n"),
            }
        }
    }

    /// Executes one command line.
    pub fn command(&mut self, line: &str, shared: &Shared, bank: &RegisterBank, out: &mut String) {
        let lower = line.to_ascii_lowercase();
        let mut words = lower.split_whitespace();
        let cmd = words.next().unwrap_or("");
        let arg = words.next();
        let extra = words.next();
        let mut body = String::new();
        let result: Result<(), String> = match (cmd, arg, extra) {
            ("record", Some("save"), label) => {
                if words.next().is_some() {
                    Err("usage: record save [label]".into())
                } else if shared.health().record.active {
                    shared.requests.request_save(label.unwrap_or("manual"));
                    body.push_str("saving: see `record` or `log` for the folder");
                    Ok(())
                } else {
                    Err("no black box: record.enabled = false, or no state directory".into())
                }
            }
            (_, _, Some(_)) => Err(format!("too many arguments for `{cmd}`")),
            ("snap", None, _) => {
                shared.requests.request_snapshot();
                body.push_str("snapshot of the next frame requested: see `record` or `log` for the file");
                Ok(())
            }
            ("record", None, _) => {
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
            ("help" | "?", None, _) => {
                body.push_str(HELP);
                Ok(())
            }
            ("status", None, _) => {
                let u = bank.update();
                let h = shared.health();
                let _ = write!(
                    body,
                    "state {}\nstatus 0x{:04x} {}\nfault {} ({}{})\nsource {}\nuptime {} s\nfeeding-recommended {}\ndetections {}\nhistory {}\nmodbus {}\nmetrics {}",
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
                    shared.metrics.describe()
                );
                Ok(())
            }
            ("version", None, _) => {
                let (maj, min) = registers::version();
                let _ = write!(
                    body,
                    "fme {} (register map {maj}.{min}, {BLOCK_LEN} registers; {})",
                    env!("CARGO_PKG_VERSION"),
                    fme_core::infer::backend::BUILD
                );
                Ok(())
            }
            ("activity", None, _) => {
                body.push_str(&activity_line(shared, bank));
                Ok(())
            }
            ("tracks", None, _) => {
                // The count is of the rows shown: both are of the same update (the pipeline
                // writes the list at the output rate; its per-frame count may be newer).
                let text = shared.health().tracks_text;
                let rows: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
                let _ = write!(body, "tracks {}", rows.len());
                if rows.len() >= TRACK_ROWS {
                    let _ = write!(body, " (the first {TRACK_ROWS} listed)");
                }
                for l in rows {
                    body.push('\n');
                    body.push_str(l);
                }
                Ok(())
            }
            ("calib", None, _) => {
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
            ("regs", None, _) => {
                // One block, decoded by the register map the encoder follows.
                let r = bank.block();
                let order = shared.word_order();
                body.push_str("reg    name                 raw            value\n");
                for reg in &registers::MAP {
                    let (addr, raw) = if reg.len() == 2 {
                        (
                            format!("{}-{}", reg.addr, reg.addr + 1),
                            format!("0x{:04x} 0x{:04x}", r[reg.addr], r[reg.addr + 1]),
                        )
                    } else {
                        (reg.addr.to_string(), format!("0x{:04x}", r[reg.addr]))
                    };
                    let _ = writeln!(body, "{addr:<5}  {:<20} {raw:<14} {}", reg.name, reg.decode(&r, order));
                }
                let w = bank.writable();
                let _ = write!(body, "hr100-103 (plc writable): {} {} {} {}", w[0], w[1], w[2], w[3]);
                Ok(())
            }
            ("counters", None, _) => {
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
                    writer::output_dropped(),
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
            ("log", n, _) => match n.map(str::parse::<usize>) {
                None => {
                    body.push_str(&shared.last_logs(10).join("\n"));
                    Ok(())
                }
                Some(Ok(n)) if (1..=10_000).contains(&n) => {
                    body.push_str(&shared.last_logs(n).join("\n"));
                    Ok(())
                }
                Some(_) => Err("usage: log [n] with n from 1 to 10000".into()),
            },
            ("history", n, _) => match (n.map_or(Ok(24), str::parse::<usize>), shared.history.dir()) {
                (Ok(h), Some(dir)) if (1..=168).contains(&h) => {
                    crate::history::hourly_report(dir, crate::history::now_unix_ms(), h)
                        .map(|t| body.push_str(&t))
                        .map_err(|e| e.to_string())
                }
                (Ok(h), None) if (1..=168).contains(&h) => {
                    Err("history is off (set history.dir or run under systemd with StateDirectory=)".into())
                }
                _ => Err("usage: history [hours] with hours from 1 to 168".into()),
            },
            ("stream", Some("on"), _) => {
                self.stream = true;
                Ok(())
            }
            ("stream", Some("off"), _) => {
                self.stream = false;
                Ok(())
            }
            ("stream", _, _) => Err("usage: stream on|off".into()),
            ("mqtt", None, _) => {
                body.push_str(&mqtt_text(&shared.health().mqtt, crate::history::now_unix_ms()));
                Ok(())
            }
            ("config", None, _) => {
                body.push_str(shared.config_text.trim_end());
                if body.is_empty() {
                    body.push_str("(built-in defaults)");
                }
                Ok(())
            }
            (
                "help" | "?" | "status" | "version" | "activity" | "tracks" | "calib" | "regs" | "counters" | "config"
                | "mqtt",
                Some(_),
                _,
            ) => Err(format!("`{cmd}` takes no argument")),
            _ => {
                // Echo at most 20 printable characters of what was typed.
                let shown: String = line.chars().take(20).collect();
                Err(format!("unknown command `{shown}` (try help)"))
            }
        };
        for l in body.lines() {
            out.push_str(l);
            out.push_str("\r\n");
        }
        match result {
            Ok(()) => out.push_str("OK\r\n"),
            Err(e) => {
                let _ = write!(out, "ERR {e}\r\n");
            }
        }
    }
}

/// Serves the console on an open port until a stop is requested. I/O errors end the session (the
/// caller reopens the device). Writes never wait ([`writer`]): input is read every 100 ms at the
/// latest whatever the peer does with the output.
pub fn serve(port: &mut serialport::TTYPort, shared: &Shared, bank: &RegisterBank, echo: bool) -> std::io::Result<()> {
    use std::io::Read as _;
    use std::os::fd::AsRawFd as _;
    let fd = port.as_raw_fd();
    writer::set_nonblocking(fd)?;
    let mut output = writer::OutputBuffer::new(writer::OUTPUT_CAP);
    let mut session = Session { echo, ..Session::default() };
    let mut buf = [0u8; 256];
    let mut out = String::with_capacity(1024);
    let mut last_hb = bank.update().heartbeat;
    let mut stalled = false;
    output.push(b"fme console ready (type help)\r\n");
    while !shared.stopping() {
        match port.read(&mut buf) {
            Ok(0) => {}
            Ok(n) => session.feed(&buf[..n], shared, bank, &mut out),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut || e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
        let hb = bank.update().heartbeat;
        if session.stream && hb != last_hb {
            // Do not split what the technician is typing: new line, the update, then redraw the input.
            let partial = session.partial_echo().map(str::to_owned);
            if partial.is_some() {
                out.push_str("\r\n");
            }
            out.push_str(&activity_line(shared, bank));
            out.push_str("\r\n");
            if let Some(p) = partial {
                out.push_str(&p);
            }
        }
        last_hb = hb;
        if !out.is_empty() {
            output.push(out.as_bytes());
            out.clear();
        }
        output.write_to(|b| writer::write_nonblocking(fd, b))?;
        match (output.dropped_now() > 0, stalled) {
            (true, false) => {
                stalled = true;
                shared.log(
                    tracing::Level::WARN,
                    "console: the terminal is not reading; its output is dropped (counted) until it does".to_string(),
                );
            }
            (false, true) => stalled = false,
            _ => {}
        }
    }
    Ok(())
}

/// Opens `device` and serves the console, reopening with backoff after errors, until a stop.
pub fn run_on_device(device: &str, baud: u32, echo: bool, shared: &Shared, bank: &RegisterBank) {
    let mut backoff = crate::backoff::Backoff::new(Duration::from_millis(500), Duration::from_secs(30));
    while !shared.stopping() {
        match serialport::new(device, baud).timeout(Duration::from_millis(100)).open_native() {
            Ok(mut port) => {
                backoff.reset();
                shared.log(tracing::Level::INFO, format!("console on {device} at {baud} baud"));
                if let Err(e) = serve(&mut port, shared, bank, echo) {
                    shared.log(tracing::Level::WARN, format!("console {device}: {e}"));
                }
            }
            Err(e) => shared.log(tracing::Level::WARN, format!("console {device}: {e}")),
        }
        let d = backoff.next_delay();
        let end = std::time::Instant::now() + d;
        while std::time::Instant::now() < end && !shared.stopping() {
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shared() -> (Shared, RegisterBank) {
        (Shared::new("[source]\npath = \"x\"\n".into(), 50), RegisterBank::new())
    }

    fn run(input: &[u8]) -> String {
        let s = shared();
        let mut sess = Session::default();
        let mut out = String::new();
        sess.feed(input, &s.0, &s.1, &mut out);
        out
    }

    #[test]
    fn mqtt_shows_link_queue_drops_and_last_publish() {
        let out = run(b"mqtt\r\nmqtt now\r\n");
        assert!(out.contains("mqtt disabled (output.mqtt.enabled = false)\r\nOK"), "{out}");
        assert!(out.contains("ERR `mqtt` takes no argument"), "{out}");
        let m = crate::status::MqttHealth {
            link: crate::status::MqttLink::Connected,
            broker: "broker.farm:1883".into(),
            queued: 3,
            dropped: 7,
            last_publish_unix_ms: Some(4_102_444_800_000),
            ..Default::default()
        };
        let t = mqtt_text(&m, 4_102_444_802_500);
        for want in ["link connected", "queued 3", "dropped 7", "last-publish 2100-01-01T00:00:00.000Z (2.5 s ago)"] {
            assert!(t.contains(want), "{want}: {t}");
        }
        assert!(run(b"help\r\n").contains("mqtt "), "in help");
    }

    #[test]
    fn commands_case_insensitive() {
        let out = run(b"HeLp\r\nVERSION\n");
        assert!(out.contains("stream on|off"));
        assert!(out.contains(concat!("fme ", env!("CARGO_PKG_VERSION"))));
        assert_eq!(out.matches("OK\r\n").count(), 2);
    }

    #[test]
    fn errors_for_garbage() {
        assert!(run(b"frobnicate\n").starts_with("ERR unknown command `frobnicate`"));
        assert!(run(b"status now\n").starts_with("ERR `status` takes no argument"));
        assert!(run(b"stream maybe\n").starts_with("ERR usage: stream on|off"));
        assert!(run(b"log -3\n").starts_with("ERR usage: log"));
        assert_eq!(run(b"\x00\x01\xff\n"), "ERR binary input ignored\r\n");
        let long = vec![b'a'; 500];
        let out = run(&[long.as_slice(), b"\nversion\n"].concat());
        assert!(out.starts_with("ERR line too long"), "{out}");
        assert_eq!(out.matches("ERR").count(), 1);
        assert!(out.ends_with("OK\r\n"));
        assert_eq!(run(b"\r\n\r\n   \n"), "");
    }

    #[test]
    fn snap_and_record_save_go_through_the_mailbox() {
        let s = shared();
        let mut sess = Session::default();
        let mut out = String::new();
        sess.feed(
            b"record save storm
",
            &s.0,
            &s.1,
            &mut out,
        );
        assert!(out.starts_with("ERR no black box"), "{out}");
        assert_eq!(s.0.requests.take_save(), None);
        s.0.with_health(|h| h.record.active = true);
        out.clear();
        sess.feed(
            b"SNAP
record save Storm
record save
record save a b
record
",
            &s.0,
            &s.1,
            &mut out,
        );
        assert!(s.0.requests.take_snapshot());
        assert_eq!(s.0.requests.take_save().as_deref(), Some("manual"), "the latest request wins");
        assert!(out.contains("ERR usage: record save [label]"), "{out}");
        assert!(out.contains("ring on") && out.contains("disk ok"), "{out}");
        sess.feed(
            b"record save storm
",
            &s.0,
            &s.1,
            &mut out,
        );
        assert_eq!(s.0.requests.take_save().as_deref(), Some("storm"));
    }

    #[test]
    fn stream_and_config() {
        let s = shared();
        let mut sess = Session::default();
        let mut out = String::new();
        sess.feed(b"stream on\n", &s.0, &s.1, &mut out);
        assert!(sess.stream);
        sess.feed(b"Stream OFF\nconfig\n", &s.0, &s.1, &mut out);
        assert!(!sess.stream);
        assert!(out.contains("path = \"x\""));
    }

    #[test]
    fn echo_in_order_with_replies() {
        let s = shared();
        let mut sess = Session { echo: true, ..Session::default() };
        let mut out = String::new();
        sess.feed(b"vex\x7frsion\r\nhelp\x00\r\n", &s.0, &s.1, &mut out);
        assert!(out.starts_with("vex\x08 \x08rsion\r\nfme "), "{out:?}");
        assert!(out.contains("OK\r\nhelp\r\nERR binary input ignored\r\n"), "{out:?}");
    }

    #[test]
    fn partial_input_is_available_for_redraw() {
        let s = shared();
        let mut sess = Session { echo: true, ..Session::default() };
        let mut out = String::new();
        sess.feed(b"stat", &s.0, &s.1, &mut out);
        assert_eq!(sess.partial_echo(), Some("stat"));
        sess.feed(b"us\r", &s.0, &s.1, &mut out);
        assert_eq!(sess.partial_echo(), None);
        sess.feed(b"\x01", &s.0, &s.1, &mut out);
        assert_eq!(sess.partial_echo(), None, "binary input is not redrawn");
    }

    #[test]
    fn an_over_long_line_gets_its_error_on_its_own_line_with_echo() {
        let s = shared();
        let mut sess = Session { echo: true, ..Session::default() };
        let mut out = String::new();
        sess.feed(&[b'a'; 100], &s.0, &s.1, &mut out);
        sess.feed(b"\r\nversion\r\n", &s.0, &s.1, &mut out);
        let lines: Vec<&str> = out.split("\r\n").collect();
        assert_eq!(lines[0], "a".repeat(MAX_LINE), "the echo stops at the limit");
        assert!(lines[1].starts_with("ERR line too long"), "{out:?}");
        assert!(out.ends_with("OK\r\n"));
        let mut quiet = Session::default();
        let mut out = String::new();
        quiet.feed(&[b'a'; 100], &s.0, &s.1, &mut out);
        assert!(out.starts_with("ERR line too long"), "no echo, no extra line: {out:?}");
    }

    #[test]
    fn history_hourly_summary_from_the_files() {
        let s = shared();
        assert!(run(b"history\n").starts_with("ERR history is off"), "no directory: off");
        let dir = tempfile::tempdir().expect("tempdir");
        let now = crate::history::now_unix_ms();
        let mut w = crate::history::DayWriter::new(dir.path(), 30, 0.0);
        // One row a second for the last 10 minutes: 0.1 m/s, feeding for all of them.
        for i in 0..600 {
            let r = crate::history::HistoryRow {
                unix_ms: now - (600 - i) * 1000,
                activity_mps: 0.1,
                smoothed_mps: 0.1,
                ci95_mps: 0.01,
                n_fish: 5,
                bls: 0.3,
                status: 1,
                fault: 0,
                feeding: true,
                scale: fme_core::pipeline::ScaleSource::References,
                unlike_fish: false,
            };
            w.write(&r).expect("write");
        }
        s.0.history.set_dir(dir.path());
        let mut sess = Session::default();
        let mut out = String::new();
        sess.command("history 2", &s.0, &s.1, &mut out);
        let lines: Vec<&str> = out.split("\r\n").filter(|l| !l.is_empty()).collect();
        assert!((3..=4).contains(&lines.len()), "header, the one or two hours with rows, OK: {out}");
        assert!(lines[0].starts_with("hour (UTC)"), "{out}");
        assert_eq!(lines[lines.len() - 1], "OK");
        let rows: u32 = lines[1..lines.len() - 1]
            .iter()
            .map(|l| l.split_whitespace().nth(2).and_then(|n| n.parse::<u32>().ok()).unwrap_or(0))
            .sum();
        assert_eq!(rows, 600, "{out}");
        assert!(lines[lines.len() - 2].contains(" 0.100 "), "{out}");
        let mut out = String::new();
        sess.command("history 0", &s.0, &s.1, &mut out);
        assert!(out.starts_with("ERR usage: history"), "{out}");
        let mut out = String::new();
        sess.command("status", &s.0, &s.1, &mut out);
        assert!(out.contains(&format!("history on {}", dir.path().display())), "{out}");
    }

    #[test]
    fn backspace_and_crlf() {
        assert!(run(b"versiom\x08n\r\n").contains("fme "));
    }
}
