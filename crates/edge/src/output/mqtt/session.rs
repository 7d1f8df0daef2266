//! The MQTT thread: connection attempts with backoff, one session per connection, and the
//! bookkeeping of the link in the health.

use super::payload::{activity_json, event_json};
use super::queue::{Item, Queued};
use super::tls::options;
use super::{Inner, LOG_EVERY, MAX_IN_FLIGHT, OFFLINE, ONLINE, STOP_FLUSH, Settings};
use crate::backoff::Backoff;
use crate::history::now_unix_ms;
use crate::status::{MqttLink, Shared};
use rumqttc::{AsyncClient, ConnectionError, Event, EventLoop, Outgoing, Packet, QoS};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use tracing::Level;

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

pub(super) async fn run(s: Settings, inner: Arc<Inner>, shared: Arc<Shared>) {
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
        let closing_now = closing(inner, shared, stop_seen);
        if closing_now && flush_deadline.is_none() {
            flush_deadline = Some(tokio::time::Instant::now() + STOP_FLUSH);
        }
        // Hand queued messages to the client, a few at a time.
        if !offline_sent {
            hand_over(s, inner, &client, &mut in_flight, &mut payload);
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

/// Hands queued messages to the client while fewer than [`MAX_IN_FLIGHT`] wait for their
/// acknowledgement; one the client cannot take goes back in front of the queue.
fn hand_over(
    s: &Settings,
    inner: &Inner,
    client: &AsyncClient,
    in_flight: &mut VecDeque<InFlight>,
    payload: &mut String,
) {
    while in_flight.len() < MAX_IN_FLIGHT {
        let Some(q) = inner.queue().pop() else { break };
        payload.clear();
        let topic = match q.item {
            Item::Activity { seq, update } => {
                activity_json(&s.box_id, seq, &update, payload);
                &s.topics.activity
            }
            Item::Event { update, kind } => {
                event_json(&s.box_id, &update, kind, payload);
                &s.topics.event
            }
        };
        if client.try_publish(topic.as_str(), s.qos, false, payload.as_bytes().to_vec()).is_err() {
            inner.queue().requeue_front(std::iter::once(q.item));
            break;
        }
        in_flight.push_back(InFlight { pkid: None, msg: Some(q) });
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
