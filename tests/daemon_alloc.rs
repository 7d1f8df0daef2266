//! Steady-state capture allocates nothing per frame: a recorded source reading into recycled
//! buffers, through the drop-oldest queue, back to the pool (counting global allocator).

#[path = "daemon_support.rs"]
mod support;

use fme::capture::{FrameQueue, FrameSource, RecordedSource};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    // Only the measuring thread counts (the test harness runs other tests in parallel threads).
    static MEASURING: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

fn count() {
    if MEASURING.with(|m| m.get()) {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        // SAFETY: same contract as the caller's.
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as the caller's.
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn capture_path_is_allocation_free_in_steady_state() {
    let dir = tempfile::tempdir().expect("tempdir");
    support::write_sequence(dir.path(), 12, 160, 96, 30);
    let mut src = RecordedSource::open(dir.path(), false, true).expect("open");
    let q = FrameQueue::new(2);
    let mut cycle = |n: usize| {
        for i in 0..n {
            let f = src.next_frame(q.take_buffer()).expect("frame");
            if let Some(old) = q.push(f) {
                q.recycle(old.data);
            }
            if i % 2 == 0
                && let Some(f) = q.pop(Duration::from_millis(1))
            {
                q.recycle(f.data);
            }
        }
    };
    cycle(48); // warm-up: buffers grow to the largest frame, the pool fills
    let before = ALLOCS.load(Ordering::Relaxed);
    MEASURING.with(|m| m.set(true));
    cycle(240);
    MEASURING.with(|m| m.set(false));
    let after = ALLOCS.load(Ordering::Relaxed);
    assert_eq!(after - before, 0, "allocations in 240 steady-state frames");
}
