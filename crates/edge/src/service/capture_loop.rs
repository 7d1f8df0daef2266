//! The capture thread: frames from the source into the bounded queue, the camera's health, and
//! reconnects with backoff; a panicking source is restarted, never the process.

use crate::capture::{Backoff, CaptureError, FrameQueue, FrameSource};
use crate::status::Shared;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tracing::Level;

/// Sleeps `d` in small steps, returning early (true) when a stop is requested.
pub(super) fn sleep_unless_stopping(shared: &Shared, d: Duration) -> bool {
    let end = Instant::now() + d;
    while Instant::now() < end {
        if shared.stopping() {
            return true;
        }
        std::thread::sleep((end - Instant::now()).min(Duration::from_millis(50)));
    }
    shared.stopping()
}

/// The message of a caught panic.
pub(super) fn panic_text(p: &(dyn std::any::Any + Send)) -> String {
    let msg = p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned());
    format!("panicked: {}", msg.unwrap_or_else(|| "(no message)".into()))
}

/// Runs the capture loop, restarting it (after the reconnect backoff) if a source panics.
pub(super) fn capture_thread(
    mut source: Box<dyn FrameSource>,
    queue: Arc<FrameQueue>,
    shared: Arc<Shared>,
    backoff: Backoff,
    size: SizeLimit,
) {
    loop {
        let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            capture_loop(&mut source, &queue, &shared, backoff, size);
        }));
        match run {
            Ok(()) => return,
            Err(p) => {
                shared.with_health(|h| {
                    h.camera_ok = false;
                    h.capture_errors += 1;
                });
                shared.log(Level::ERROR, format!("capture {}; restarting capture", panic_text(&*p)));
                let mut b = backoff;
                if sleep_unless_stopping(&shared, b.next_delay()) {
                    queue.close();
                    return;
                }
                if let Err(e) = source.reopen() {
                    shared.log(Level::WARN, format!("camera reconnect failed: {e}"));
                }
            }
        }
    }
}

/// `source.max_pixels` and the configured size ([`crate::capture::Frame::check_size`]).
#[derive(Debug, Clone, Copy)]
pub(super) struct SizeLimit {
    pub max_pixels: u64,
    pub configured: (u32, u32),
}

fn capture_loop(
    source: &mut Box<dyn FrameSource>,
    queue: &FrameQueue,
    shared: &Shared,
    mut backoff: Backoff,
    size: SizeLimit,
) {
    let mut window_start = Instant::now();
    let mut window_frames = 0u32;
    let mut oversized = 0u64;
    let paced = source.paced();
    while !shared.stopping() {
        match source.next_frame(queue.take_buffer()) {
            Ok(frame) => {
                backoff.reset();
                // Checked from the header before anything decodes it: a bad frame, not a decode.
                if let Err(e) = frame.check_size(size.max_pixels, size.configured) {
                    oversized += 1;
                    shared.with_health(|h| h.capture_errors += 1);
                    if oversized == 1 || oversized.is_multiple_of(100) {
                        shared.log(Level::WARN, format!("bad frame #{oversized} dropped: {e}"));
                    }
                    queue.recycle(frame.data);
                    continue;
                }
                let now = frame.arrived;
                if paced {
                    if let Some(old) = queue.push(frame) {
                        queue.recycle(old.data);
                    }
                } else {
                    let mut f = frame;
                    while let Err(back) = queue.push_wait(f, Duration::from_millis(100)) {
                        if shared.stopping() || queue.is_closed() {
                            break;
                        }
                        f = back;
                    }
                }
                let dropped = queue.stats().dropped + source.source_dropped();
                window_frames += 1;
                let elapsed = now.saturating_duration_since(window_start).as_secs_f64();
                shared.with_health(|h| {
                    // A camera back after an outage restarts the stall clock: the frames not
                    // processed while it was away are no pipeline stall.
                    if !h.camera_ok {
                        h.last_processed_at = Some(now);
                    }
                    h.camera_ok = true;
                    h.frames_captured += 1;
                    h.frames_dropped = dropped;
                    if elapsed >= 1.0 {
                        h.camera_fps = f64::from(window_frames) / elapsed;
                    }
                });
                if elapsed >= 1.0 {
                    window_start = now;
                    window_frames = 0;
                }
            }
            Err(CaptureError::End) => {
                shared.log(Level::INFO, format!("{}: end of recording", source.describe()));
                break;
            }
            Err(e) => {
                shared.with_health(|h| {
                    h.camera_ok = false;
                    h.camera_fps = 0.0;
                    h.capture_errors += 1;
                });
                shared.log(Level::WARN, format!("camera: {e}"));
                loop {
                    let d = backoff.next_delay();
                    if sleep_unless_stopping(shared, d) {
                        break;
                    }
                    match source.reopen() {
                        Ok(()) => {
                            shared.with_health(|h| {
                                h.reconnects += 1;
                                h.source = source.describe();
                            });
                            shared.log(Level::INFO, format!("camera back: {}", source.describe()));
                            window_start = Instant::now();
                            window_frames = 0;
                            break;
                        }
                        Err(e) => shared.log(Level::WARN, format!("camera reconnect failed: {e}")),
                    }
                }
            }
        }
    }
    queue.close();
}
