//! Steady-state capture allocates nothing per frame: a recorded source reading into recycled
//! buffers, through the drop-oldest queue, back to the pool (counting global allocator).

#[path = "daemon/support.rs"]
mod support;

use fme::capture::{FrameQueue, FrameSource, RecordedSource};
use std::time::Duration;

#[path = "common/counting_alloc.rs"]
mod counting_alloc;

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
    let (allocs, ()) = counting_alloc::allocations_in(|| cycle(240));
    assert_eq!(allocs, 0, "allocations in 240 steady-state frames");
}
