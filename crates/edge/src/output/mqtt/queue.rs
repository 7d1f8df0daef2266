//! The bounded queue between the publisher and the MQTT thread (pure).

use super::events::EventKind;
use crate::output::Update;
use std::collections::VecDeque;

/// One message waiting to go out.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Item {
    /// An `activity` message: the update and its sequence number since start.
    Activity {
        /// 1 for the first update after start, +1 per update.
        seq: u64,
        /// The update.
        update: Update,
    },
    /// An `event` message at the time of update `update`.
    Event {
        /// The update that made the event.
        update: Update,
        /// The event.
        kind: EventKind,
    },
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
