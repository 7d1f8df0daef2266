//! The serial field-diagnostics console (line based, case-insensitive; it changes nothing, only
//! `snap` and `record save` ask the service, through [`crate::status::Requests`], to write files).
//!
//! Works with picocom/screen at 115200 baud. Every reply ends with a line `OK` or `ERR <reason>`, so
//! scripts can parse it. Garbage, over-long lines and binary noise get an `ERR` line and never stop
//! the daemon. Output never blocks the console ([`writer`]): a terminal that stops reading loses
//! output (counted: `console-output-dropped`), never its input. Commands: `help`, `status`, `version`, `activity`, `tracks`, `calib`, `regs`,
//! `counters`, `log [n]`, `history [hours]`, `stream on|off`, `config`, `snap`, `record`,
//! `record save [label]` (docs/recording.md).

pub mod config;
mod replies;
pub mod tracks;
pub mod writer;

pub use replies::{activity_line, mqtt_text};

use crate::output::bank::RegisterBank;
use crate::status::Shared;
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
            ("record", Some("save"), _) if words.next().is_some() => Err("usage: record save [label]".into()),
            ("record", Some("save"), label) => replies::record_save(shared, label, &mut body),
            (_, _, Some(_)) => Err(format!("too many arguments for `{cmd}`")),
            ("snap", None, _) => replies::snap(shared, &mut body),
            ("record", None, _) => replies::record(shared, &mut body),
            ("help" | "?", None, _) => {
                body.push_str(HELP);
                Ok(())
            }
            ("status", None, _) => replies::status(shared, bank, &mut body),
            ("version", None, _) => replies::version(&mut body),
            ("activity", None, _) => {
                body.push_str(&activity_line(shared, bank));
                Ok(())
            }
            ("tracks", None, _) => {
                // The count is of the rows shown: both are of the same update (the pipeline
                // writes the list at the output rate; its per-frame count may be newer).
                let mut text = String::new();
                tracks::describe_fish(&mut text, &shared.health().fish, TRACK_ROWS);
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
            ("calib", None, _) => replies::calib(shared, &mut body),
            ("regs", None, _) => replies::regs(shared, bank, &mut body),
            ("counters", None, _) => replies::counters(shared, bank, &mut body),
            ("log", n, _) => replies::log(shared, n, &mut body),
            ("history", n, _) => replies::history(shared, n, &mut body),
            ("stream", Some("on"), _) => {
                self.stream = true;
                Ok(())
            }
            ("stream", Some("off"), _) => {
                self.stream = false;
                Ok(())
            }
            ("stream", _, _) => Err("usage: stream on|off".into()),
            ("mqtt", None, _) => replies::mqtt(shared, &mut body),
            ("config", None, _) => replies::config(shared, &mut body),
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
mod tests;
