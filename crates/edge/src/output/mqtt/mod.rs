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
//! of its own (`session::Driver`); the connection state, the connect timeout and the backoff live outside
//! it. rumqttc's `poll` is not cancel-safe while connecting: a poll dropped before the CONNACK (a
//! `select!` against a timer) starts the TCP connection over, so over a slow link (CONNACK later
//! than the timer) the box would never connect and would open a connection per tick.
//! The pipeline and Modbus never wait on the broker: the sender only pushes into the bounded queue.
//! While the broker is away the queue holds the newest `queue_messages` messages; after a reconnect
//! they are delivered (counted as delivered-after-reconnect) and messages sent but not acknowledged
//! when the link dropped are sent again (QoS 1 is at least once). A refused login or a failed TLS
//! handshake sets status bit 9 and is retried with backoff, logged at most once a minute.
//!
//! The JSON builders (`payload`), the event detector (`events`), the queue policy (`queue`) and the
//! topic names are pure and tested without a broker; the connection is `session` (options and TLS:
//! `tls`); `tests/mqtt.rs` runs the whole thing against a real Mosquitto.

mod events;
mod payload;
mod queue;
mod session;
mod tls;

use session::run;

pub use events::{EventKind, EventTracker};
pub use payload::{activity_json, config_json, event_json, json_string};
pub use queue::{Item, Queue, Queued};
pub(crate) use tls::{read_pem_certs, read_pem_key};

use crate::config::{Config, MqttConfig};
use crate::output::Update;
use crate::status::{MqttLink, Shared};
use rumqttc::QoS;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tracing::Level;

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
    /// Queues update `update` and the events it makes.
    pub fn send(&mut self, update: Update) {
        self.seq += 1;
        let events = self.events.update(&update);
        let waited = !self.inner.link_up.load(Ordering::Relaxed);
        {
            let mut q = self.inner.queue();
            q.push(Queued { item: Item::Activity { seq: self.seq, update }, waited });
            for kind in events {
                q.push(Queued { item: Item::Event { update, kind }, waited });
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

#[cfg(test)]
mod tests;
