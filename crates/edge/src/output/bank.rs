//! The shared register bank: the latest published update and its block (published by the service,
//! the block read by every Modbus role, the update by the console and the metrics) and the holding
//! registers the PLC may write.

use super::registers::{BLOCK_LEN, HR_WRITABLE_LEN, HR_WRITABLE_START};
use super::update::Update;
use crate::config::WordOrder;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use tokio::sync::watch;

/// Shared registers. Publishing never blocks on a reader (a `watch` channel keeps only the latest).
#[derive(Debug)]
pub struct RegisterBank {
    block: watch::Sender<[u16; BLOCK_LEN]>,
    update: Mutex<Update>,
    writable: Mutex<[u16; HR_WRITABLE_LEN]>,
    epoch: Instant,
    /// ms since `epoch` + 1 of the last served request (0 = never).
    last_request_ms: AtomicU64,
    requests: AtomicU64,
    exceptions: AtomicU64,
    client_link_ok: AtomicBool,
    client_writes: AtomicU64,
    client_failures: AtomicU64,
    tcp_open: AtomicU64,
    tcp_idle_closed: AtomicU64,
    tcp_evicted: AtomicU64,
    tcp_accept_errors: AtomicU64,
    tcp_refused: AtomicU64,
    tcp_bad_frames: AtomicU64,
    task_panics: AtomicU64,
}

impl Default for RegisterBank {
    fn default() -> Self {
        Self::new()
    }
}

/// Counters of the Modbus side, for the console and tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ModbusCounters {
    /// Requests served (server roles).
    pub requests: u64,
    /// Exception responses sent (server roles).
    pub exceptions: u64,
    /// Successful block writes (client roles).
    pub client_writes: u64,
    /// Failed connects or writes (client roles).
    pub client_failures: u64,
    /// TCP server: connections open now.
    pub tcp_open: u64,
    /// TCP server: connections closed after the idle timeout.
    pub tcp_idle_closed: u64,
    /// TCP server: connections closed to make room for a newer one (limit reached).
    pub tcp_evicted: u64,
    /// TCP server: failed accepts (each retried after a pause).
    pub tcp_accept_errors: u64,
    /// TCP server: connections closed at accept because the peer is not in `output.modbus.allow`,
    /// or because every connection that could make room for it has priority.
    pub tcp_refused: u64,
    /// TCP server: connections closed on a frame that cannot be framed (bad MBAP header).
    pub tcp_bad_frames: u64,
    /// Server roles: connection or server tasks that panicked (each logged at most once per 10 s).
    pub task_panics: u64,
}

impl RegisterBank {
    /// An all-zero bank.
    pub fn new() -> Self {
        Self {
            block: watch::Sender::new([0; BLOCK_LEN]),
            update: Mutex::new(Update::default()),
            writable: Mutex::new([0; HR_WRITABLE_LEN]),
            epoch: Instant::now(),
            last_request_ms: AtomicU64::new(0),
            requests: AtomicU64::new(0),
            exceptions: AtomicU64::new(0),
            client_link_ok: AtomicBool::new(false),
            client_writes: AtomicU64::new(0),
            client_failures: AtomicU64::new(0),
            tcp_open: AtomicU64::new(0),
            tcp_idle_closed: AtomicU64::new(0),
            tcp_evicted: AtomicU64::new(0),
            tcp_accept_errors: AtomicU64::new(0),
            tcp_refused: AtomicU64::new(0),
            tcp_bad_frames: AtomicU64::new(0),
            task_panics: AtomicU64::new(0),
        }
    }

    /// Publishes a new block (never blocks).
    pub fn publish(&self, block: [u16; BLOCK_LEN]) {
        self.block.send_replace(block);
    }

    /// Publishes update `u`: keeps it for the console and the metrics, then its block encoded in
    /// word order `order` (never blocks).
    pub fn publish_update(&self, u: &Update, order: WordOrder) {
        *self.update.lock().unwrap_or_else(|p| p.into_inner()) = *u;
        self.publish(super::registers::encode(u, order));
    }

    /// The latest published update (all default before the first).
    pub fn update(&self) -> Update {
        *self.update.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The latest block.
    pub fn block(&self) -> [u16; BLOCK_LEN] {
        *self.block.borrow()
    }

    /// A receiver that wakes on each publish (client roles, serial line).
    pub fn subscribe(&self) -> watch::Receiver<[u16; BLOCK_LEN]> {
        self.block.subscribe()
    }

    /// Writable holding registers (HR 100..).
    pub fn writable(&self) -> [u16; HR_WRITABLE_LEN] {
        *self.writable.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Writes into the writable holding registers; `false` when the range is outside them.
    pub fn write_holding(&self, addr: u16, words: &[u16]) -> bool {
        let Some(start) = addr.checked_sub(HR_WRITABLE_START).map(usize::from) else { return false };
        let Some(end) = start.checked_add(words.len()) else { return false };
        if words.is_empty() || end > HR_WRITABLE_LEN {
            return false;
        }
        self.writable.lock().unwrap_or_else(|p| p.into_inner())[start..end].copy_from_slice(words);
        true
    }

    pub(crate) fn note_request(&self, exception: bool) {
        let ms = self.epoch.elapsed().as_millis() as u64 + 1;
        self.last_request_ms.store(ms, Ordering::Relaxed);
        self.requests.fetch_add(1, Ordering::Relaxed);
        if exception {
            self.exceptions.fetch_add(1, Ordering::Relaxed);
        }
    }

    pub(crate) fn note_client(&self, ok: bool) {
        self.client_link_ok.store(ok, Ordering::Relaxed);
        if ok {
            self.client_writes.fetch_add(1, Ordering::Relaxed);
        } else {
            self.client_failures.fetch_add(1, Ordering::Relaxed);
        }
    }

    pub(crate) fn set_tcp_open(&self, n: usize) {
        self.tcp_open.store(n as u64, Ordering::Relaxed);
    }

    pub(crate) fn note_tcp_idle_closed(&self) {
        self.tcp_idle_closed.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn note_tcp_evicted(&self) {
        self.tcp_evicted.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn note_tcp_accept_error(&self) {
        self.tcp_accept_errors.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn note_tcp_refused(&self) {
        self.tcp_refused.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn note_tcp_bad_frame(&self) {
        self.tcp_bad_frames.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn note_task_panic(&self) {
        self.task_panics.fetch_add(1, Ordering::Relaxed);
    }

    /// Server roles: whether a request was served within `window`.
    pub fn served_within(&self, window: Duration) -> bool {
        let last = self.last_request_ms.load(Ordering::Relaxed);
        last != 0 && self.epoch.elapsed().as_millis() as u64 + 1 - last <= window.as_millis() as u64
    }

    /// Client roles: whether the last write succeeded.
    pub fn client_link_ok(&self) -> bool {
        self.client_link_ok.load(Ordering::Relaxed)
    }

    /// Counters.
    pub fn counters(&self) -> ModbusCounters {
        ModbusCounters {
            requests: self.requests.load(Ordering::Relaxed),
            exceptions: self.exceptions.load(Ordering::Relaxed),
            client_writes: self.client_writes.load(Ordering::Relaxed),
            client_failures: self.client_failures.load(Ordering::Relaxed),
            tcp_open: self.tcp_open.load(Ordering::Relaxed),
            tcp_idle_closed: self.tcp_idle_closed.load(Ordering::Relaxed),
            tcp_evicted: self.tcp_evicted.load(Ordering::Relaxed),
            tcp_accept_errors: self.tcp_accept_errors.load(Ordering::Relaxed),
            tcp_refused: self.tcp_refused.load(Ordering::Relaxed),
            tcp_bad_frames: self.tcp_bad_frames.load(Ordering::Relaxed),
            task_panics: self.task_panics.load(Ordering::Relaxed),
        }
    }
}
