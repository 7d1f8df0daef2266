//! Fleet telemetry over MQTT (`[output.mqtt]`, docs/mqtt.md): every output update as an `activity`
//! JSON message, `event`s (feeding on/off, faults raised/cleared, scale source changes), a retained
//! `status` ("online"; "offline" as the Last Will and on a clean stop) and a retained `config`, all
//! under `<prefix>/<box_id>/`.
//!
//! ```text
//! Publisher::publish -> MqttSender::send (events detected here; short lock, never waits)
//!     -> Queue (bounded: full = oldest dropped and counted) -> fme-mqtt thread (own tokio runtime)
//!         -> rumqttc (QoS 1: a message leaves the books only on the broker's PUBACK)
//! ```
//! Each connection attempt gets a fresh client whose event loop is polled without pause by a task
//! of its own ([`Driver`]); the connection state, the connect timeout and the backoff live outside
//! it. rumqttc's `poll` is not cancel-safe while connecting: a poll dropped before the CONNACK (a
//! `select!` against a timer) starts the TCP connection over, so over a slow link (CONNACK later
//! than the timer) the box would never connect and would open a connection per tick.
//! The pipeline and Modbus never wait on the broker: the sender only pushes into the bounded queue.
//! While the broker is away the queue holds the newest `queue_messages` messages; after a reconnect
//! they are delivered (counted as delivered-after-reconnect) and messages sent but not acknowledged
//! when the link dropped are sent again (QoS 1 is at least once). A refused login or a failed TLS
//! handshake sets status bit 9 and is retried with backoff, logged at most once a minute.
//!
//! The JSON builders, the event detector, the queue policy and the topic names are pure and
//! tested without a broker; `tests/mqtt.rs` runs the whole thing against a real Mosquitto.

use crate::backoff::Backoff;
use crate::config::{Config, MqttConfig};
use crate::history::{Row, format_time, now_unix_ms};
use crate::output::registers::status;
use crate::status::{MqttLink, Shared};
use fme_core::pipeline::ScaleSource;
use rumqttc::{AsyncClient, ConnectionError, Event, EventLoop, LastWill, MqttOptions, Outgoing, Packet, QoS};
use std::collections::VecDeque;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tracing::Level;

/// Names of the status bits of input register 10 as they appear in the `activity` JSON
/// (`status` object), in bit order: the one table ([`status::NAMES`]) the metrics and the console
/// use too.
pub const STATUS_BIT_NAMES: [(&str, u16); 11] = status::NAMES;

/// Payload of the retained `status` topic while connected.
pub const ONLINE: &str = "online";
/// Payload of the retained `status` topic after a clean stop, and the Last Will.
pub const OFFLINE: &str = "offline";
/// Messages handed to the client and not yet acknowledged, at most.
const MAX_IN_FLIGHT: usize = 16;
/// A "the broker refused us" or "cannot reach the broker" line is logged at most this often
/// (a new kind of error is logged at once).
const LOG_EVERY: Duration = Duration::from_secs(60);
/// After a stop request, time left to deliver the queue before saying "offline".
const STOP_FLUSH: Duration = Duration::from_millis(400);

/// Name of a fault code (register 11) in the JSON ([`crate::status::fault_name`]).
pub fn fault_name(code: u16) -> &'static str {
    crate::status::fault_name(code)
}

/// The host name: `/proc/sys/kernel/hostname`, else `gethostname(2)`, else `"fme"`.
pub fn host_name() -> String {
    if let Ok(s) = std::fs::read_to_string("/proc/sys/kernel/hostname") {
        let s = s.trim();
        if !s.is_empty() {
            return s.to_string();
        }
    }
    let mut buf = [0u8; 256];
    // SAFETY: the buffer is valid for its length; gethostname writes at most that many bytes.
    let rc = unsafe { libc::gethostname(buf.as_mut_ptr().cast(), buf.len()) };
    if rc == 0 {
        let end = buf.iter().position(|&b| b == 0).unwrap_or(buf.len());
        if let Ok(s) = std::str::from_utf8(&buf[..end])
            && !s.is_empty()
        {
            return s.to_string();
        }
    }
    "fme".into()
}

/// The box id in use: `output.mqtt.box_id`, or the host name when empty (characters that cannot be
/// in a topic level are replaced by `_`).
pub fn box_id(cfg: &MqttConfig) -> String {
    let id = if cfg.box_id.is_empty() { host_name() } else { cfg.box_id.clone() };
    id.chars()
        .map(|c| if c == '/' || c == '+' || c == '#' || c.is_whitespace() || c.is_control() { '_' } else { c })
        .collect()
}

/// The four topics of one box.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topics {
    /// `<prefix>/<box_id>/activity`: one JSON object per output update.
    pub activity: String,
    /// `<prefix>/<box_id>/status`: retained `online` / `offline`.
    pub status: String,
    /// `<prefix>/<box_id>/event`: one JSON object per event.
    pub event: String,
    /// `<prefix>/<box_id>/config`: retained JSON of the effective config.
    pub config: String,
}

impl Topics {
    /// Topics under `<prefix>/<box_id>/`.
    pub fn new(prefix: &str, box_id: &str) -> Self {
        let t = |leaf: &str| format!("{prefix}/{box_id}/{leaf}");
        Self { activity: t("activity"), status: t("status"), event: t("event"), config: t("config") }
    }
}

/// An event of the `event` topic.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EventKind {
    /// Feeding recommended became on.
    FeedingOn,
    /// Feeding recommended became off.
    FeedingOff,
    /// A fault code (register 11) appeared.
    FaultRaised(u16),
    /// A fault code went away.
    FaultCleared(u16),
    /// "Detections look unlike fish" (status bit 10) was raised (`true`) or cleared (`false`).
    UnlikeFish(bool),
    /// The source of the metric scale changed (`depth.scale`: fish <-> references).
    ScaleSource {
        /// Before.
        from: ScaleSource,
        /// Now.
        to: ScaleSource,
    },
}

impl EventKind {
    /// The `event` field of the JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::FeedingOn => "feeding_on",
            Self::FeedingOff => "feeding_off",
            Self::FaultRaised(_) => "fault_raised",
            Self::FaultCleared(_) => "fault_cleared",
            Self::UnlikeFish(true) => "unlike_fish_raised",
            Self::UnlikeFish(false) => "unlike_fish_cleared",
            Self::ScaleSource { .. } => "scale_source",
        }
    }
}

/// Finds the events between successive updates (pure). The first update only sets the baseline,
/// except that a fault present then is raised; the final "stopped" update makes no events (the
/// `status` topic says "offline").
#[derive(Debug, Clone, Default)]
pub struct EventTracker {
    last: Option<(bool, u16, ScaleSource)>,
    unlike_fish: bool,
}

impl EventTracker {
    /// The events of `row` (with the scale source in use) against the previous update.
    pub fn update(&mut self, row: &Row, scale: ScaleSource) -> heapless::Vec<EventKind, 6> {
        let mut out = heapless::Vec::new();
        if row.fault == crate::status::FaultCode::Stopped as u16 {
            return out;
        }
        // Only faults raise and clear ([`crate::status::is_fault_code`], as the history counts them).
        let code = if crate::status::is_fault_code(row.fault) { row.fault } else { 0 };
        let (feeding, fault) = match self.last {
            Some((f, c, s)) => {
                if scale != s && scale != ScaleSource::None && s != ScaleSource::None {
                    let _ = out.push(EventKind::ScaleSource { from: s, to: scale });
                }
                (f, c)
            }
            None => (false, 0),
        };
        if code != fault {
            if fault != 0 {
                let _ = out.push(EventKind::FaultCleared(fault));
            }
            if code != 0 {
                let _ = out.push(EventKind::FaultRaised(code));
            }
        }
        let unlike = row.status & status::UNLIKE_FISH != 0;
        if unlike != self.unlike_fish {
            let _ = out.push(EventKind::UnlikeFish(unlike));
            self.unlike_fish = unlike;
        }
        if row.feeding != feeding {
            let _ = out.push(if row.feeding { EventKind::FeedingOn } else { EventKind::FeedingOff });
        }
        // A scale source of "none" (no fit yet) is not a change worth an event: keep the last real one.
        let kept = match (self.last, scale) {
            (Some((_, _, s)), ScaleSource::None) => s,
            _ => scale,
        };
        self.last = Some((row.feeding, code, kept));
        out
    }
}

/// One message waiting to go out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Item {
    /// An `activity` message: the update and its sequence number since start.
    Activity {
        /// 1 for the first update after start, +1 per update.
        seq: u64,
        /// The update.
        row: Row,
    },
    /// An `event` message at the time of update `row`.
    Event {
        /// The update that made the event.
        row: Row,
        /// The event.
        kind: EventKind,
    },
}

fn push_num(out: &mut String, key: &str, v: f64, decimals: usize) {
    if v.is_finite() {
        let _ = write!(out, "\"{key}\":{v:.decimals$},");
    } else {
        let _ = write!(out, "\"{key}\":null,");
    }
}

fn push_str(out: &mut String, key: &str, v: &str) {
    let _ = write!(out, "\"{key}\":");
    json_string(v, out);
    out.push(',');
}

/// Appends `s` as a JSON string literal.
pub fn json_string(s: &str, out: &mut String) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

/// Appends the `activity` JSON of update `row` (schema in docs/mqtt.md).
pub fn activity_json(box_id: &str, seq: u64, row: &Row, out: &mut String) {
    out.push('{');
    out.push_str("\"time\":\"");
    format_time(row.unix_ms, out);
    out.push_str("\",");
    push_str(out, "box_id", box_id);
    let _ = write!(out, "\"seq\":{seq},");
    push_num(out, "mean_mps", row.activity_mps, 4);
    push_num(out, "smoothed_mps", row.smoothed_mps, 4);
    push_num(out, "ci95_mps", row.ci95_mps, 4);
    let _ = write!(out, "\"n_fish\":{},", row.n_fish);
    push_num(out, "bls", row.bls, 3);
    out.push_str("\"status\":{");
    for (i, (name, bit)) in STATUS_BIT_NAMES.iter().enumerate() {
        let _ = write!(out, "{}\"{name}\":{}", if i > 0 { "," } else { "" }, row.status & bit != 0);
    }
    let _ = write!(out, "}},\"status_bits\":{},", row.status);
    push_str(out, "fault", fault_name(row.fault));
    let _ = write!(out, "\"fault_code\":{},\"feeding\":{}}}", row.fault, row.feeding);
}

/// Appends the `event` JSON of `kind` at the time of `row` (schema in docs/mqtt.md).
pub fn event_json(box_id: &str, row: &Row, kind: EventKind, out: &mut String) {
    out.push('{');
    out.push_str("\"time\":\"");
    format_time(row.unix_ms, out);
    out.push_str("\",");
    push_str(out, "box_id", box_id);
    push_str(out, "event", kind.name());
    match kind {
        EventKind::FeedingOn | EventKind::FeedingOff => {
            let _ = write!(out, "\"feeding\":{},", row.feeding);
            push_num(out, "smoothed_mps", row.smoothed_mps, 4);
        }
        EventKind::FaultRaised(c) | EventKind::FaultCleared(c) => {
            push_str(out, "fault", fault_name(c));
            let _ = write!(out, "\"fault_code\":{c},");
        }
        EventKind::UnlikeFish(raised) => {
            let _ = write!(out, "\"unlike_fish\":{raised},\"n_fish\":{},", row.n_fish);
            push_num(out, "mean_mps", row.activity_mps, 4);
        }
        EventKind::ScaleSource { from, to } => {
            push_str(out, "from", from.name());
            push_str(out, "to", to.name());
        }
    }
    out.pop(); // the last ','
    out.push('}');
}

/// The retained `config` JSON: box id, fme version and the effective configuration (it holds no
/// secret: the password is only named by its file, `output.mqtt.password_file`).
pub fn config_json(box_id: &str, cfg: &Config) -> String {
    let mut out = String::from("{");
    push_str(&mut out, "box_id", box_id);
    push_str(&mut out, "version", env!("CARGO_PKG_VERSION"));
    match serde_json::to_string(cfg) {
        Ok(c) => {
            let _ = write!(out, "\"config\":{c}}}");
        }
        Err(e) => {
            // A value JSON cannot hold (a non-finite float): the TOML text instead.
            let _ = write!(out, "\"config_error\":");
            json_string(&e.to_string(), &mut out);
            out.push_str(",\"config_toml\":");
            json_string(&cfg.to_toml(), &mut out);
            out.push('}');
        }
    }
    out
}

/// A queued message and whether it waited while the link was down.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Queued {
    /// The message.
    pub item: Item,
    /// It was queued (or put back) while the broker was unreachable.
    pub waited: bool,
}

/// The bounded queue between the publisher and the MQTT thread: when full, the oldest message is
/// dropped and counted (pure; allocation-free after construction).
#[derive(Debug)]
pub struct Queue {
    items: VecDeque<Queued>,
    cap: usize,
    /// Messages dropped because the queue was full.
    pub dropped: u64,
}

impl Queue {
    /// A queue of at most `cap` messages (at least 1).
    pub fn new(cap: usize) -> Self {
        let cap = cap.max(1);
        Self { items: VecDeque::with_capacity(cap), cap, dropped: 0 }
    }
    /// Appends `q`, dropping (and counting) the oldest message when full.
    pub fn push(&mut self, q: Queued) {
        if self.items.len() >= self.cap {
            self.items.pop_front();
            self.dropped += 1;
        }
        self.items.push_back(q);
    }
    /// Puts messages that were sent but not acknowledged back in front, oldest first, marked as
    /// waited; those that do not fit (the oldest) are dropped and counted.
    pub fn requeue_front(&mut self, unacked: impl DoubleEndedIterator<Item = Item>) {
        for item in unacked.rev() {
            if self.items.len() < self.cap {
                self.items.push_front(Queued { item, waited: true });
            } else {
                self.dropped += 1;
            }
        }
    }
    /// Marks every waiting message as having waited for the broker (the link just dropped).
    pub fn mark_waited(&mut self) {
        for q in &mut self.items {
            q.waited = true;
        }
    }
    /// Takes the oldest message.
    pub fn pop(&mut self) -> Option<Queued> {
        self.items.pop_front()
    }
    /// Messages waiting.
    pub fn len(&self) -> usize {
        self.items.len()
    }
    /// No message waiting.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
}

#[derive(Debug)]
struct Inner {
    queue: Mutex<Queue>,
    notify: tokio::sync::Notify,
    /// The broker is connected now (messages queued meanwhile did not wait).
    link_up: AtomicBool,
    /// The sender was dropped: deliver what is queued, say "offline", disconnect.
    closed: AtomicBool,
}

impl Inner {
    fn queue(&self) -> std::sync::MutexGuard<'_, Queue> {
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The publisher's end: turns each output update into an `activity` message and its events and
/// queues them. Never waits on the network (a short lock of the queue). Dropping it tells the MQTT
/// thread to finish.
#[derive(Debug)]
pub struct MqttSender {
    inner: Arc<Inner>,
    events: EventTracker,
    seq: u64,
}

impl MqttSender {
    /// Queues update `row` and the events it makes.
    pub fn send(&mut self, row: Row) {
        self.seq += 1;
        let events = self.events.update(&row, row.scale);
        let waited = !self.inner.link_up.load(Ordering::Relaxed);
        {
            let mut q = self.inner.queue();
            q.push(Queued { item: Item::Activity { seq: self.seq, row }, waited });
            for kind in events {
                q.push(Queued { item: Item::Event { row, kind }, waited });
            }
        }
        self.inner.notify.notify_one();
    }
}

impl Drop for MqttSender {
    fn drop(&mut self) {
        self.inner.closed.store(true, Ordering::SeqCst);
        self.inner.notify.notify_one();
    }
}

/// What the MQTT thread needs from the config, resolved once.
#[derive(Debug, Clone)]
struct Settings {
    host: String,
    port: u16,
    broker: String,
    box_id: String,
    topics: Topics,
    qos: QoS,
    keepalive: Duration,
    connect_timeout_s: u64,
    min_backoff: Duration,
    max_backoff: Duration,
    username: String,
    password_file: std::path::PathBuf,
    tls: bool,
    ca_file: std::path::PathBuf,
    cert_file: std::path::PathBuf,
    key_file: std::path::PathBuf,
    config_json: String,
}

/// Starts the MQTT thread for `cfg.output.mqtt` (call only when enabled). Returns the sender to give
/// to the publisher and the thread.
pub fn spawn(cfg: &Config, shared: Arc<Shared>) -> std::io::Result<(MqttSender, std::thread::JoinHandle<()>)> {
    let m = &cfg.output.mqtt;
    let (host, port) = match m.broker.rsplit_once(':') {
        Some((h, p)) => (h.trim_start_matches('[').trim_end_matches(']').to_string(), p.parse().unwrap_or(1883)),
        None => (m.broker.clone(), 1883),
    };
    let id = box_id(m);
    let settings = Settings {
        host,
        port,
        broker: m.broker.clone(),
        topics: Topics::new(&m.prefix, &id),
        qos: if m.qos == 0 { QoS::AtMostOnce } else { QoS::AtLeastOnce },
        keepalive: Duration::from_secs(m.keepalive_s),
        connect_timeout_s: m.connect_timeout_s.max(1),
        min_backoff: Duration::from_millis(m.reconnect_min_ms),
        max_backoff: Duration::from_millis(m.reconnect_max_ms),
        username: m.username.clone(),
        password_file: m.password_file.clone(),
        tls: m.tls,
        ca_file: m.ca_file.clone(),
        cert_file: m.cert_file.clone(),
        key_file: m.key_file.clone(),
        config_json: config_json(&id, cfg),
        box_id: id,
    };
    let inner = Arc::new(Inner {
        queue: Mutex::new(Queue::new(m.queue_messages)),
        notify: tokio::sync::Notify::new(),
        link_up: AtomicBool::new(false),
        closed: AtomicBool::new(false),
    });
    shared.with_health(|h| {
        h.mqtt.link = MqttLink::Connecting;
        h.mqtt.broker = settings.broker.clone();
    });
    shared.log(Level::INFO, format!("mqtt: publishing to {} under {}/{}/", settings.broker, m.prefix, settings.box_id));
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build()?;
    let thread_inner = inner.clone();
    let thread = std::thread::Builder::new()
        .name("fme-mqtt".into())
        .spawn(move || runtime.block_on(run(settings, thread_inner, shared)))?;
    Ok((MqttSender { inner, events: EventTracker::default(), seq: 0 }, thread))
}

/// Why a connection attempt or a session ended.
#[derive(Debug)]
enum Failure {
    /// The broker refused the login, or the TLS setup/handshake failed: status bit 9.
    Refused(String),
    /// Unreachable, reset, timed out: just retry.
    Network(String),
}

fn classify(e: &ConnectionError) -> Failure {
    use rumqttc::ConnectReturnCode as C;
    match e {
        ConnectionError::ConnectionRefused(C::BadUserNamePassword) => {
            Failure::Refused("broker refused the login: bad user name or password".into())
        }
        ConnectionError::ConnectionRefused(C::NotAuthorized) => {
            Failure::Refused("broker refused the login: not authorized".into())
        }
        ConnectionError::ConnectionRefused(c) => Failure::Refused(format!("broker refused the connection: {c:?}")),
        ConnectionError::Tls(t) => Failure::Refused(format!("TLS: {t}")),
        ConnectionError::Io(io) if io.kind() == std::io::ErrorKind::InvalidData => {
            Failure::Refused(format!("TLS: {io}"))
        }
        other => {
            // TLS 1.3 rejects a missing or bad client certificate with an alert after the
            // handshake, so it arrives as a read error of the first MQTT packet.
            let text = other.to_string();
            let lower = text.to_ascii_lowercase();
            if lower.contains("fatal alert") || lower.contains("certificate") {
                Failure::Refused(format!("TLS: {text}"))
            } else {
                Failure::Network(text)
            }
        }
    }
}

/// The PEM certificates in `path` (at least one); the error names the file.
pub(crate) fn read_pem_certs(path: &Path) -> Result<Vec<rustls::pki_types::CertificateDer<'static>>, String> {
    let f = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let certs: Vec<_> = rustls_pemfile::certs(&mut std::io::BufReader::new(f))
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if certs.is_empty() {
        return Err(format!("{}: no PEM certificate in it", path.display()));
    }
    Ok(certs)
}

/// The PEM private key in `path`; the error names the file.
pub(crate) fn read_pem_key(path: &Path) -> Result<rustls::pki_types::PrivateKeyDer<'static>, String> {
    let f = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    rustls_pemfile::private_key(&mut std::io::BufReader::new(f))
        .map_err(|e| format!("{}: {e}", path.display()))?
        .ok_or_else(|| format!("{}: no PEM private key in it", path.display()))
}

/// The rustls client configuration of `s` (ring provider).
fn tls_config(s: &Settings) -> Result<rustls::ClientConfig, String> {
    let mut roots = rustls::RootCertStore::empty();
    if s.ca_file.as_os_str().is_empty() {
        for c in rustls_native_certs::load_native_certs().certs {
            let _ = roots.add(c);
        }
        if roots.is_empty() {
            return Err("no system CA certificates found; set output.mqtt.ca_file".into());
        }
    } else {
        for c in read_pem_certs(&s.ca_file)? {
            roots.add(c).map_err(|e| format!("output.mqtt.ca_file {}: {e}", s.ca_file.display()))?;
        }
    }
    let builder = rustls::ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_root_certificates(roots);
    if s.cert_file.as_os_str().is_empty() {
        return Ok(builder.with_no_client_auth());
    }
    let certs = read_pem_certs(&s.cert_file)?;
    let key = read_pem_key(&s.key_file)?;
    builder.with_client_auth_cert(certs, key).map_err(|e| format!("output.mqtt.cert_file/key_file: {e}"))
}

/// The client options of `s`: Last Will, keep-alive, login (the password read now), TLS.
fn options(s: &Settings) -> Result<MqttOptions, String> {
    let mut o = MqttOptions::new(s.box_id.clone(), s.host.clone(), s.port);
    o.set_keep_alive(s.keepalive);
    o.set_clean_session(true);
    o.set_max_packet_size(1 << 20, 1 << 20);
    o.set_last_will(LastWill::new(s.topics.status.clone(), OFFLINE, QoS::AtLeastOnce, true));
    if !s.username.is_empty() {
        let password = if s.password_file.as_os_str().is_empty() {
            String::new()
        } else {
            // Only the file is named in errors, never its content.
            let text = std::fs::read_to_string(&s.password_file)
                .map_err(|e| format!("output.mqtt.password_file {}: {e}", s.password_file.display()))?;
            text.lines().next().unwrap_or("").to_string()
        };
        o.set_credentials(s.username.clone(), password);
    }
    if s.tls {
        o.set_transport(rumqttc::Transport::tls_with_config(rumqttc::TlsConfiguration::Rustls(Arc::new(tls_config(
            s,
        )?))));
    }
    Ok(o)
}

/// Health and log bookkeeping of the MQTT thread.
struct Books {
    shared: Arc<Shared>,
    last_logged: Option<(String, Instant)>,
    held_back: u64,
}

impl Books {
    /// Logs a link problem: a new message at once, a repeated one at most every [`LOG_EVERY`].
    fn problem(&mut self, msg: &str, retry_in: Duration) {
        let now = Instant::now();
        let due = match &self.last_logged {
            Some((m, t)) => m != msg || now.duration_since(*t) >= LOG_EVERY,
            None => true,
        };
        if due {
            let more = std::mem::take(&mut self.held_back);
            let more = if more > 0 { format!(" ({more} more failures since the last line)") } else { String::new() };
            self.shared.log(Level::WARN, format!("mqtt: {msg}; retrying in {:.1} s{more}", retry_in.as_secs_f64()));
            self.last_logged = Some((msg.to_string(), now));
        } else {
            self.held_back += 1;
        }
    }

    fn sync(&self, inner: &Inner) {
        let (queued, dropped) = {
            let q = inner.queue();
            (q.len() as u64, q.dropped)
        };
        self.shared.with_health(|h| {
            h.mqtt.queued = queued;
            h.mqtt.dropped = dropped;
        });
    }
}

/// Whether the thread should finish: the sender is gone, or a stop was requested a while ago.
fn closing(inner: &Inner, shared: &Shared, stop_seen: &mut Option<Instant>) -> bool {
    if shared.stopping() && stop_seen.is_none() {
        *stop_seen = Some(Instant::now());
    }
    inner.closed.load(Ordering::SeqCst) || stop_seen.is_some_and(|t| t.elapsed() > STOP_FLUSH)
}

/// Sleeps `d` (keeping the queue counters of the health fresh), returning early (true) when the
/// thread should finish.
async fn pause(d: Duration, inner: &Inner, books: &Books, stop_seen: &mut Option<Instant>) -> bool {
    let shared = &*books.shared;
    let end = tokio::time::Instant::now() + d;
    while tokio::time::Instant::now() < end {
        books.sync(inner);
        if closing(inner, shared, stop_seen) || shared.stopping() {
            return true;
        }
        let step = (end - tokio::time::Instant::now()).min(Duration::from_millis(50));
        tokio::select! {
            () = tokio::time::sleep(step) => {}
            () = inner.notify.notified() => {}
        }
    }
    false
}

async fn run(s: Settings, inner: Arc<Inner>, shared: Arc<Shared>) {
    let mut backoff = Backoff::new(s.min_backoff, s.max_backoff);
    let mut books = Books { shared: shared.clone(), last_logged: None, held_back: 0 };
    let mut connected_before = false;
    let mut stop_seen = None;
    loop {
        books.sync(&inner);
        if closing(&inner, &shared, &mut stop_seen) || shared.stopping() {
            return; // not connected: nobody to say "offline" to (the Last Will already says it)
        }
        shared.with_health(|h| h.mqtt.connect_attempts += 1);
        let failure = match connect(&s, &inner, &shared, &mut stop_seen).await {
            Ok(None) => return,
            Ok(Some((client, driver))) => {
                backoff.reset();
                inner.link_up.store(true, Ordering::SeqCst);
                shared.with_health(|h| {
                    h.mqtt.link = MqttLink::Connected;
                    if connected_before {
                        h.mqtt.reconnects += 1;
                    }
                });
                let (queued, dropped) = {
                    let q = inner.queue();
                    (q.len(), q.dropped)
                };
                shared.log(
                    Level::INFO,
                    format!(
                        "mqtt: connected to {} as {}; {queued} queued messages to deliver, {dropped} dropped so far",
                        s.broker, s.box_id
                    ),
                );
                books.last_logged = None;
                connected_before = true;
                let end = session(&s, &inner, &shared, &books, client, driver, &mut stop_seen).await;
                inner.link_up.store(false, Ordering::SeqCst);
                match end {
                    None => {
                        shared.with_health(|h| h.mqtt.link = MqttLink::Disabled);
                        return;
                    }
                    Some(f) => f,
                }
            }
            Err(f) => f,
        };
        let delay = backoff.next_delay();
        let msg = match &failure {
            Failure::Refused(m) => {
                shared.with_health(|h| {
                    h.mqtt.link = MqttLink::AuthFailed;
                    h.mqtt.auth_failures += 1;
                    h.mqtt.last_error = m.clone();
                });
                format!("{m} (status bit 9 set)")
            }
            Failure::Network(m) => {
                shared.with_health(|h| {
                    h.mqtt.link = MqttLink::Connecting;
                    h.mqtt.last_error = m.clone();
                });
                format!("broker {}: {m}", s.broker)
            }
        };
        books.problem(&msg, delay);
        if pause(delay, &inner, &books, &mut stop_seen).await {
            books.sync(&inner);
            return;
        }
    }
}

/// What the event loop of a client said: an event, or the error that ended it.
type Polled = Result<Event, ConnectionError>;

/// The event loop of one client, polled without pause by a task of its own until its first error;
/// its events come through a channel (whose `recv` is cancel-safe, so the MQTT thread may race it
/// against timers). Never polled again after an error: the next attempt is a fresh client, after
/// the backoff. Dropping the driver ends the task and closes the connection.
struct Driver {
    events: tokio::sync::mpsc::Receiver<Polled>,
    task: tokio::task::JoinHandle<()>,
}

impl Driver {
    fn start(mut eventloop: EventLoop) -> Self {
        let (tx, events) = tokio::sync::mpsc::channel(64);
        let task = tokio::spawn(async move {
            loop {
                let polled = eventloop.poll().await;
                let failed = polled.is_err();
                if tx.send(polled).await.is_err() || failed {
                    return;
                }
            }
        });
        Self { events, task }
    }

    /// The next event; an error when the task ended without one.
    async fn next(&mut self) -> Polled {
        self.events.recv().await.unwrap_or(Err(ConnectionError::RequestsDone))
    }
}

impl Drop for Driver {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// One connection attempt (one TCP connection): `Ok(None)` when asked to stop meanwhile.
async fn connect(
    s: &Settings,
    inner: &Inner,
    shared: &Shared,
    stop_seen: &mut Option<Instant>,
) -> Result<Option<(AsyncClient, Driver)>, Failure> {
    let opts = options(s).map_err(Failure::Refused)?;
    let (client, mut eventloop) = AsyncClient::new(opts, 64);
    // rumqttc's timeout covers the TCP connect, the TLS handshake and the CONNACK.
    eventloop.network_options.set_connection_timeout(s.connect_timeout_s);
    let mut driver = Driver::start(eventloop);
    let too_slow =
        || Failure::Network(format!("no CONNACK within {} s (output.mqtt.connect_timeout_s)", s.connect_timeout_s));
    // A backstop only: rumqttc's own timeout ends the attempt first.
    let deadline = tokio::time::Instant::now() + Duration::from_secs(s.connect_timeout_s + 2);
    loop {
        if closing(inner, shared, stop_seen) || shared.stopping() {
            return Ok(None);
        }
        tokio::select! {
            ev = driver.next() => match ev {
                Ok(Event::Incoming(Packet::ConnAck(_))) => return Ok(Some((client, driver))),
                Ok(_) => {}
                Err(ConnectionError::NetworkTimeout) => return Err(too_slow()),
                Err(e) => return Err(classify(&e)),
            },
            () = tokio::time::sleep(Duration::from_millis(100)) => {
                if tokio::time::Instant::now() > deadline {
                    return Err(too_slow());
                }
            }
        }
    }
}

/// A message handed to the client, waiting for its packet id and acknowledgement.
struct InFlight {
    pkid: Option<u16>,
    /// `None`: the "online"/config/"offline" messages (not counted).
    msg: Option<Queued>,
}

/// Runs a connected session until the link drops (`Some(failure)`) or the thread must finish
/// (`None`, after "offline" and a DISCONNECT).
async fn session(
    s: &Settings,
    inner: &Inner,
    shared: &Shared,
    books: &Books,
    client: AsyncClient,
    mut driver: Driver,
    stop_seen: &mut Option<Instant>,
) -> Option<Failure> {
    let mut in_flight: VecDeque<InFlight> = VecDeque::with_capacity(MAX_IN_FLIGHT + 4);
    let mut payload = String::with_capacity(512);
    let retained = [(&s.topics.status, ONLINE.to_string()), (&s.topics.config, s.config_json.clone())];
    for (topic, body) in retained {
        if client.try_publish(topic.as_str(), QoS::AtLeastOnce, true, body.into_bytes()).is_ok() {
            in_flight.push_back(InFlight { pkid: None, msg: None });
        }
    }
    let mut flush_deadline: Option<tokio::time::Instant> = None;
    let mut offline_sent = false;
    loop {
        // Hand queued messages to the client, a few at a time.
        let closing_now = closing(inner, shared, stop_seen);
        if closing_now && flush_deadline.is_none() {
            flush_deadline = Some(tokio::time::Instant::now() + STOP_FLUSH);
        }
        while in_flight.len() < MAX_IN_FLIGHT && !offline_sent {
            let Some(q) = inner.queue().pop() else { break };
            payload.clear();
            let topic = match q.item {
                Item::Activity { seq, row } => {
                    activity_json(&s.box_id, seq, &row, &mut payload);
                    &s.topics.activity
                }
                Item::Event { row, kind } => {
                    event_json(&s.box_id, &row, kind, &mut payload);
                    &s.topics.event
                }
            };
            if client.try_publish(topic.as_str(), s.qos, false, payload.as_bytes().to_vec()).is_err() {
                inner.queue().requeue_front(std::iter::once(q.item));
                break;
            }
            in_flight.push_back(InFlight { pkid: None, msg: Some(q) });
        }
        books.sync(inner);
        if let Some(d) = flush_deadline
            && !offline_sent
        {
            let drained = inner.queue().is_empty() && in_flight.iter().all(|f| f.msg.is_none());
            if drained || tokio::time::Instant::now() > d {
                // Clean stop: say "offline" (retained) before leaving.
                if client.try_publish(s.topics.status.as_str(), QoS::AtLeastOnce, true, OFFLINE).is_ok() {
                    in_flight.push_back(InFlight { pkid: None, msg: None });
                }
                offline_sent = true;
                flush_deadline = Some(tokio::time::Instant::now() + Duration::from_millis(300));
            }
        }
        if offline_sent {
            let acked = in_flight.is_empty();
            if acked || flush_deadline.is_some_and(|d| tokio::time::Instant::now() > d) {
                let _ = client.try_disconnect();
                let end = tokio::time::Instant::now() + Duration::from_millis(200);
                while let Ok(Ok(ev)) = tokio::time::timeout_at(end, driver.next()).await {
                    if matches!(ev, Event::Outgoing(Outgoing::Disconnect)) {
                        break;
                    }
                }
                shared.log(Level::INFO, "mqtt: status offline published; disconnected");
                return None;
            }
        }
        tokio::select! {
            ev = driver.next() => match ev {
                Ok(Event::Outgoing(Outgoing::Publish(pkid))) => {
                    if let Some(f) = in_flight.iter_mut().find(|f| f.pkid.is_none()) {
                        f.pkid = Some(pkid);
                    }
                    if pkid == 0 {
                        // QoS 0: written to the broker is all there is.
                        if let Some(i) = in_flight.iter().position(|f| f.pkid == Some(0)) {
                            complete(shared, &mut in_flight, i);
                        }
                    }
                }
                Ok(Event::Incoming(Packet::PubAck(ack))) => {
                    if let Some(i) = in_flight.iter().position(|f| f.pkid == Some(ack.pkid)) {
                        complete(shared, &mut in_flight, i);
                    }
                }
                Ok(_) => {}
                Err(e) => {
                    // Sent but not acknowledged: send again after the reconnect (QoS 1 is at least once).
                    {
                        let mut q = inner.queue();
                        q.mark_waited();
                        q.requeue_front(in_flight.drain(..).filter_map(|f| f.msg.map(|m| m.item)));
                    }
                    books.sync(inner);
                    return Some(classify(&e));
                }
            },
            () = inner.notify.notified() => {}
            () = tokio::time::sleep(Duration::from_millis(100)) => {}
        }
    }
}

/// Books an acknowledged message.
fn complete(shared: &Shared, in_flight: &mut VecDeque<InFlight>, i: usize) {
    let Some(f) = in_flight.remove(i) else { return };
    if let Some(m) = f.msg {
        let now = now_unix_ms();
        shared.with_health(|h| {
            h.mqtt.published += 1;
            h.mqtt.delivered_after_reconnect += u64::from(m.waited);
            h.mqtt.last_publish_unix_ms = Some(now);
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(fault: u16, feeding: bool) -> Row {
        Row {
            unix_ms: 4_102_444_800_000 + 1234, // 2100-01-01T00:00:01.234Z
            activity_mps: 0.1234,
            smoothed_mps: f64::NAN,
            ci95_mps: 0.01,
            n_fish: 7,
            bls: 0.5,
            status: status::RUNNING | status::TELEMETRY_FAULT,
            fault,
            feeding,
            scale: ScaleSource::References,
            unlike_fish: false,
        }
    }

    #[test]
    fn topics_under_prefix_and_box() {
        let t = Topics::new("fme", "cage7");
        assert_eq!(t.activity, "fme/cage7/activity");
        assert_eq!(t.status, "fme/cage7/status");
        assert_eq!(t.event, "fme/cage7/event");
        assert_eq!(t.config, "fme/cage7/config");
    }

    #[test]
    fn box_id_defaults_to_host_name() {
        let mut c = MqttConfig::default();
        assert_eq!(box_id(&c), host_name());
        assert!(!box_id(&c).is_empty());
        c.box_id = "cage 7/a".into();
        assert_eq!(box_id(&c), "cage_7_a");
    }

    #[test]
    fn activity_json_parses_with_every_field() {
        let mut s = String::new();
        activity_json("cage\"7", 42, &row(1, true), &mut s);
        let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
        assert_eq!(v["time"], "2100-01-01T00:00:01.234Z");
        assert_eq!(v["box_id"], "cage\"7");
        assert_eq!(v["seq"], 42);
        assert_eq!(v["mean_mps"], 0.1234);
        assert!(v["smoothed_mps"].is_null(), "NaN is null: {s}");
        assert_eq!(v["n_fish"], 7);
        assert_eq!(v["status"]["running"], true);
        assert_eq!(v["status"]["telemetry_fault"], true);
        assert_eq!(v["status"]["stale"], false);
        assert_eq!(v["status"].as_object().map(|o| o.len()), Some(11));
        assert_eq!(v["status"]["unlike_fish"], false);
        assert_eq!(v["status_bits"], u64::from(status::RUNNING | status::TELEMETRY_FAULT));
        assert_eq!(v["fault"], "camera");
        assert_eq!(v["fault_code"], 1);
        assert_eq!(v["feeding"], true);
    }

    #[test]
    fn event_json_parses() {
        for kind in [
            EventKind::FeedingOn,
            EventKind::FaultRaised(4),
            EventKind::FaultCleared(4),
            EventKind::ScaleSource { from: ScaleSource::References, to: ScaleSource::Fish },
        ] {
            let mut s = String::new();
            event_json("b", &row(0, true), kind, &mut s);
            let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
            assert_eq!(v["event"], kind.name());
            assert_eq!(v["box_id"], "b");
        }
        let mut s = String::new();
        event_json(
            "b",
            &row(0, false),
            EventKind::ScaleSource { from: ScaleSource::Fish, to: ScaleSource::References },
            &mut s,
        );
        let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
        assert_eq!((v["from"].as_str(), v["to"].as_str()), (Some("fish"), Some("references")));
    }

    #[test]
    fn config_json_has_no_password_only_its_file() {
        let mut c = Config::default();
        c.output.mqtt.username = "box".into();
        c.output.mqtt.password_file = "/etc/fme/mqtt.pass".into();
        let j = config_json("b", &c);
        let v: serde_json::Value = serde_json::from_str(&j).expect(&j);
        assert_eq!(v["config"]["output"]["mqtt"]["password_file"], "/etc/fme/mqtt.pass");
        assert!(v["config"]["output"]["mqtt"].get("password").is_none());
    }

    #[test]
    fn events_on_changes_only() {
        let mut t = EventTracker::default();
        assert!(t.update(&row(0, false), ScaleSource::None).is_empty(), "baseline");
        assert_eq!(t.update(&row(0, true), ScaleSource::References)[..], [EventKind::FeedingOn]);
        assert!(t.update(&row(0, true), ScaleSource::References).is_empty());
        assert_eq!(
            t.update(&row(1, true), ScaleSource::Fish)[..],
            [
                EventKind::ScaleSource { from: ScaleSource::References, to: ScaleSource::Fish },
                EventKind::FaultRaised(1)
            ]
        );
        assert_eq!(
            t.update(&row(4, false), ScaleSource::None)[..],
            [EventKind::FaultCleared(1), EventKind::FaultRaised(4), EventKind::FeedingOff]
        );
        assert!(t.update(&row(6, false), ScaleSource::Fish).is_empty(), "the stop makes no events");
        let mut t = EventTracker::default();
        assert_eq!(t.update(&row(1, false), ScaleSource::None)[..], [EventKind::FaultRaised(1)], "fault at start");
    }

    #[test]
    fn unlike_fish_is_an_event_when_raised_and_when_cleared() {
        let mut t = EventTracker::default();
        let flagged = |fault| Row { status: row(0, false).status | status::UNLIKE_FISH, ..row(fault, false) };
        assert!(t.update(&row(0, false), ScaleSource::References).is_empty());
        assert_eq!(
            t.update(&flagged(7), ScaleSource::References)[..],
            [EventKind::FaultRaised(7), EventKind::UnlikeFish(true)]
        );
        assert!(t.update(&flagged(7), ScaleSource::References).is_empty(), "no event while it stays raised");
        // Under a more severe fault the bit still says it, and its clearing is an event of its own.
        assert_eq!(
            t.update(&flagged(1), ScaleSource::References)[..],
            [EventKind::FaultCleared(7), EventKind::FaultRaised(1)]
        );
        assert_eq!(t.update(&row(1, false), ScaleSource::References)[..], [EventKind::UnlikeFish(false)]);
        let mut s = String::new();
        event_json("b", &flagged(7), EventKind::UnlikeFish(true), &mut s);
        let v: serde_json::Value = serde_json::from_str(&s).expect(&s);
        assert_eq!(v["event"], "unlike_fish_raised");
        assert_eq!(v["unlike_fish"], true);
        assert_eq!(v["n_fish"], 7);
    }

    #[test]
    fn queue_drops_oldest_and_requeues_in_front() {
        let a = |seq| Item::Activity { seq, row: row(0, false) };
        let mut q = Queue::new(3);
        for s in 1..=5 {
            q.push(Queued { item: a(s), waited: false });
        }
        assert_eq!((q.len(), q.dropped), (3, 2));
        let seq = |m: Option<Queued>| match m.map(|m| m.item) {
            Some(Item::Activity { seq, .. }) => Some(seq),
            _ => None,
        };
        assert_eq!(seq(q.pop()), Some(3));
        // Two unacknowledged messages go back in front; one fits (the newer one), one is dropped.
        q.requeue_front([a(1), a(2)].into_iter());
        assert_eq!((q.len(), q.dropped), (3, 3));
        let order: Vec<_> = std::iter::from_fn(|| q.pop()).map(|m| (seq(Some(m)), m.waited)).collect();
        assert_eq!(order, vec![(Some(2), true), (Some(4), false), (Some(5), false)]);
        assert!(q.is_empty());
    }

    #[test]
    fn fault_names_cover_the_codes() {
        for c in 0..=7 {
            assert_ne!(fault_name(c), "unknown");
        }
        assert_eq!(fault_name(99), "unknown");
    }
}
