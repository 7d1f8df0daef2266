//! Who may connect: the per-address limit ([`PeerLimit`]), the total limit, and the steady scrapers
//! that a stalling connection makes room for (see [`super::listener`]).

use super::listener::{HttpLimits, PRIORITY_SCRAPES, PRIORITY_WINDOW};
use crate::output::peer_limit::PeerLimit;
use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use tokio::task::AbortHandle;
use tokio::time::Instant;

/// Addresses whose scrapes are remembered (the least recently answered is forgotten first).
const SCRAPERS_KEPT: usize = 64;

/// One open connection.
#[derive(Debug)]
struct Conn {
    id: u64,
    ip: IpAddr,
    opened: Instant,
    /// Its request head is complete (or too large): it is being answered and closes soon.
    head_done: bool,
    /// Set once its task is spawned.
    abort: Option<AbortHandle>,
}

/// An address's answered scrapes.
#[derive(Debug, Clone, Copy)]
struct Scraper {
    answered: u32,
    last: Instant,
}

/// The open connections and the addresses that scraped.
#[derive(Debug, Default)]
pub(super) struct Table {
    next_id: u64,
    conns: Vec<Conn>,
    scrapers: HashMap<IpAddr, Scraper>,
}

impl Table {
    fn steady(&self, ip: IpAddr, now: Instant) -> bool {
        self.scrapers
            .get(&ip)
            .is_some_and(|s| s.answered >= PRIORITY_SCRAPES && now.duration_since(s.last) <= PRIORITY_WINDOW)
    }

    fn note_scrape(&mut self, ip: IpAddr, now: Instant) {
        if !self.scrapers.contains_key(&ip)
            && self.scrapers.len() >= SCRAPERS_KEPT
            && let Some(oldest) = self.scrapers.iter().min_by_key(|(_, s)| s.last).map(|(ip, _)| *ip)
        {
            self.scrapers.remove(&oldest);
        }
        let s = self.scrapers.entry(ip).or_insert(Scraper { answered: 0, last: now });
        s.answered = s.answered.saturating_add(1);
        s.last = now;
    }
}

pub(super) type Conns = Arc<Mutex<Table>>;

fn lock(t: &Conns) -> std::sync::MutexGuard<'_, Table> {
    t.lock().unwrap_or_else(|p| p.into_inner())
}

/// One connection's place in the [`Table`], given back when its task ends (also by a panic or an
/// abort).
#[derive(Debug)]
pub(super) struct Slot {
    table: Conns,
    pub(super) id: u64,
    ip: IpAddr,
}

impl Slot {
    pub(super) fn head_done(&self) {
        if let Some(c) = lock(&self.table).conns.iter_mut().find(|c| c.id == self.id) {
            c.head_done = true;
        }
    }

    pub(super) fn answered(&self) {
        lock(&self.table).note_scrape(self.ip, Instant::now());
    }
}

impl Drop for Slot {
    fn drop(&mut self) {
        let mut t = lock(&self.table);
        if let Some(i) = t.conns.iter().position(|c| c.id == self.id) {
            t.conns.swap_remove(i);
        }
    }
}

/// The outcome of [`admit`]: the new connection's slot and the address of a connection closed
/// for it, or why it is refused.
pub(super) type Admission = Result<(Slot, Option<IpAddr>), &'static str>;

/// Admits a connection from `ip` within `limits` (see the module docs).
pub(super) fn admit(table: &Conns, limits: &HttpLimits, ip: IpAddr, now: Instant) -> Admission {
    let mut t = lock(table);
    if PeerLimit::new(limits.max_per_peer, limits.max_connections).reached(ip, t.conns.iter().map(|c| c.ip)) {
        return Err("per-address limit reached");
    }
    let mut closed = None;
    if t.conns.len() >= limits.max_connections {
        if !t.steady(ip, now) {
            return Err("connection limit reached");
        }
        let victim = (0..t.conns.len())
            .filter(|&i| !t.conns[i].head_done && !t.steady(t.conns[i].ip, now))
            .min_by_key(|&i| t.conns[i].opened);
        let Some(i) = victim else {
            return Err("connection limit reached, every connection is a steady scraper's or being answered");
        };
        let c = t.conns.swap_remove(i);
        if let Some(a) = c.abort {
            a.abort();
        }
        closed = Some(c.ip);
    }
    let id = t.next_id;
    t.next_id += 1;
    t.conns.push(Conn { id, ip, opened: now, head_done: false, abort: None });
    Ok((Slot { table: table.clone(), id, ip }, closed))
}

/// Gives connection `id` the handle that closes it when a steady scraper needs its place.
pub(super) fn set_abort(table: &Conns, id: u64, abort: AbortHandle) {
    if let Some(c) = lock(table).conns.iter_mut().find(|c| c.id == id) {
        c.abort = Some(abort);
    }
}
