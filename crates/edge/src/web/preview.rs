//! The latest frame for `/api/latest.jpg`: the page asks ([`Preview::next`]), the pipeline thread
//! hands over a copy of the next frame with its overlays ([`Preview::offer`]: one flag read per
//! frame while nobody asks), and the web task draws and encodes it once per frame, off the
//! pipeline's thread. A box nobody watches pays nothing.

use crate::record::Overlays;
use fme_core::pipeline::{ActivitySample, Frame};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::Duration;

/// One frame handed over, with what `snap` draws on it.
#[derive(Debug)]
pub struct PreviewFrame {
    /// The frame.
    pub frame: Frame,
    /// Its detections, fish and references (with their residuals).
    pub overlays: Overlays,
    /// Its activity sample.
    pub sample: Option<ActivitySample>,
    /// The drawn JPEG, made by the first request that needs it.
    pub jpeg: OnceLock<Result<Vec<u8>, String>>,
}

/// The hand-over slot (in [`crate::status::Shared`]).
#[derive(Default)]
pub struct Preview {
    wanted: AtomicBool,
    latest: Mutex<Option<Arc<PreviewFrame>>>,
    notify: tokio::sync::Notify,
}

impl std::fmt::Debug for Preview {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Preview").field("wanted", &self.wanted.load(Ordering::Relaxed)).finish_non_exhaustive()
    }
}

impl Preview {
    /// Whether a page waits for a frame (the pipeline then keeps the frame's overlays).
    pub fn wanted(&self) -> bool {
        self.wanted.load(Ordering::Relaxed)
    }

    /// Called by the pipeline thread after each frame: when a page waits, `make` copies the frame.
    pub fn offer(&self, make: impl FnOnce() -> PreviewFrame) {
        if self.wanted.swap(false, Ordering::AcqRel) {
            *self.latest.lock().unwrap_or_else(|p| p.into_inner()) = Some(Arc::new(make()));
            self.notify.notify_waiters();
        }
    }

    /// The last frame handed over, if any.
    pub fn latest(&self) -> Option<Arc<PreviewFrame>> {
        self.latest.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// Asks for the next frame and waits for it at most `wait`; then the latest one (an older frame
    /// when the pipeline has none: camera down, end of a recording).
    pub async fn next(&self, wait: Duration) -> Option<Arc<PreviewFrame>> {
        let notified = self.notify.notified();
        self.wanted.store(true, Ordering::Release);
        let _ = tokio::time::timeout(wait, notified).await;
        self.latest()
    }
}
