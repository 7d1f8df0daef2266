//! Bounded frame queue between capture and pipeline: when full, the oldest frame is dropped and
//! counted, so capture never waits on inference (a stale frame is worth less than a fresh one).
//! It also keeps a small pool of frame buffers: the pipeline hands each buffer back after use and
//! capture reuses it, so steady-state capture allocates nothing per frame.

use super::Frame;
use std::collections::VecDeque;
use std::sync::{Condvar, Mutex};
use std::time::Duration;

/// Counters of a [`FrameQueue`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct QueueStats {
    /// Frames pushed.
    pub pushed: u64,
    /// Frames dropped because the queue was full.
    pub dropped: u64,
}

#[derive(Debug)]
struct Inner {
    frames: VecDeque<Frame>,
    stats: QueueStats,
    closed: bool,
}

/// A bounded multi-producer queue that drops the oldest frame when full.
#[derive(Debug)]
pub struct FrameQueue {
    capacity: usize,
    inner: Mutex<Inner>,
    ready: Condvar,
    space: Condvar,
    pool: Mutex<Vec<Vec<u8>>>,
}

impl FrameQueue {
    /// A queue holding at most `capacity` frames (at least 1). The storage is allocated once.
    pub fn new(capacity: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            capacity,
            inner: Mutex::new(Inner {
                frames: VecDeque::with_capacity(capacity),
                stats: QueueStats::default(),
                closed: false,
            }),
            ready: Condvar::new(),
            space: Condvar::new(),
            pool: Mutex::new(Vec::with_capacity(capacity + 2)),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while holding the lock cannot leave the deque inconsistent; keep going.
        self.inner.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Pushes a frame without ever blocking; returns the dropped (oldest) frame if the queue was full,
    /// so the caller can recycle its buffer.
    pub fn push(&self, frame: Frame) -> Option<Frame> {
        let mut g = self.lock();
        g.stats.pushed += 1;
        let dropped = if g.frames.len() >= self.capacity {
            g.stats.dropped += 1;
            g.frames.pop_front()
        } else {
            None
        };
        g.frames.push_back(frame);
        drop(g);
        self.ready.notify_one();
        dropped
    }

    /// Pushes a frame, waiting while the queue is full (back-pressure for unpaced sources such as a
    /// recording replayed as fast as possible: every frame is processed, none dropped). Gives up and
    /// returns the frame after `timeout` or when the queue is closed.
    pub fn push_wait(&self, frame: Frame, timeout: Duration) -> Result<(), Frame> {
        let g = self.lock();
        let (mut g, _) = self
            .space
            .wait_timeout_while(g, timeout, |i| i.frames.len() >= self.capacity && !i.closed)
            .unwrap_or_else(|p| p.into_inner());
        if g.closed || g.frames.len() >= self.capacity {
            return Err(frame);
        }
        g.stats.pushed += 1;
        g.frames.push_back(frame);
        drop(g);
        self.ready.notify_one();
        Ok(())
    }

    /// Pops the oldest frame, waiting up to `timeout`. `None` on timeout or when closed and empty.
    pub fn pop(&self, timeout: Duration) -> Option<Frame> {
        let g = self.lock();
        let (mut g, _) = self
            .ready
            .wait_timeout_while(g, timeout, |i| i.frames.is_empty() && !i.closed)
            .unwrap_or_else(|p| p.into_inner());
        let f = g.frames.pop_front();
        drop(g);
        if f.is_some() {
            self.space.notify_one();
        }
        f
    }

    /// A cleared buffer for the next frame: a recycled one when available, else a new empty one.
    pub fn take_buffer(&self) -> Vec<u8> {
        let mut b = self.pool.lock().unwrap_or_else(|p| p.into_inner()).pop().unwrap_or_default();
        b.clear();
        b
    }

    /// Returns a frame buffer for reuse (dropped when the pool is full).
    pub fn recycle(&self, buf: Vec<u8>) {
        let mut pool = self.pool.lock().unwrap_or_else(|p| p.into_inner());
        if pool.len() < self.capacity + 2 && buf.capacity() > 0 {
            pool.push(buf);
        }
    }

    /// Closes the queue: waiting `pop`s return.
    pub fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_all();
        self.space.notify_all();
    }

    /// Whether [`close`](Self::close) was called.
    pub fn is_closed(&self) -> bool {
        self.lock().closed
    }

    /// Counters.
    pub fn stats(&self) -> QueueStats {
        self.lock().stats
    }

    /// Frames waiting.
    pub fn len(&self) -> usize {
        self.lock().frames.len()
    }

    /// Whether no frame is waiting.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::PixelFormat;
    use fme_core::units::Seconds;

    fn frame(seq: u64) -> Frame {
        Frame {
            seq,
            timestamp: Seconds(seq as f64),
            arrived: std::time::Instant::now(),
            width: 1,
            height: 1,
            format: PixelFormat::Gray8,
            data: vec![0],
        }
    }

    #[test]
    fn drops_oldest_and_counts() {
        let q = FrameQueue::new(2);
        assert!(q.push(frame(1)).is_none());
        assert!(q.push(frame(2)).is_none());
        assert_eq!(q.push(frame(3)).map(|f| f.seq), Some(1));
        assert_eq!(q.stats(), QueueStats { pushed: 3, dropped: 1 });
        let seqs: Vec<_> = std::iter::from_fn(|| q.pop(Duration::from_millis(1))).map(|f| f.seq).collect();
        assert_eq!(seqs, vec![2, 3]);
    }

    #[test]
    fn buffers_are_recycled() {
        let q = FrameQueue::new(1);
        let mut b = q.take_buffer();
        b.extend_from_slice(&[1, 2, 3]);
        let ptr = b.as_ptr();
        q.recycle(b);
        let b2 = q.take_buffer();
        assert!(b2.is_empty() && b2.capacity() >= 3);
        assert_eq!(b2.as_ptr(), ptr, "same allocation reused");
    }

    #[test]
    fn push_wait_blocks_until_space() {
        let q = std::sync::Arc::new(FrameQueue::new(1));
        assert!(q.push_wait(frame(1), Duration::from_millis(1)).is_ok());
        assert_eq!(q.push_wait(frame(2), Duration::from_millis(5)).map_err(|f| f.seq), Err(2));
        let q2 = q.clone();
        let h = std::thread::spawn(move || q2.push_wait(frame(3), Duration::from_secs(10)).is_ok());
        std::thread::sleep(Duration::from_millis(20));
        assert_eq!(q.pop(Duration::from_millis(1)).map(|f| f.seq), Some(1));
        assert_eq!(h.join().ok(), Some(true));
        assert_eq!(q.pop(Duration::from_millis(100)).map(|f| f.seq), Some(3));
        assert_eq!(q.stats().dropped, 0);
    }

    #[test]
    fn pop_times_out_and_close_wakes() {
        let q = std::sync::Arc::new(FrameQueue::new(1));
        assert!(q.pop(Duration::from_millis(5)).is_none());
        let q2 = q.clone();
        let h = std::thread::spawn(move || q2.pop(Duration::from_secs(10)).is_none());
        std::thread::sleep(Duration::from_millis(20));
        q.close();
        assert_eq!(h.join().ok(), Some(true));
    }
}
