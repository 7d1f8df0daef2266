//! The pipeline thread: frames from the queue through the pipeline, each frame's outcome to the
//! black box, the `--series` writer and the health; an output update on the frame clock at
//! `output.rate_hz`. A bad frame or a panicking stage is counted and logged, never fatal.

use super::capture_loop::panic_text;
use super::publish::{Publish, Publisher, publish_and_send};
use crate::capture::FrameQueue;
use crate::record::{Overlays, Recorder};
use crate::sequence::SeriesRow;
use crate::status::Shared;
use fme_core::motion::Fish;
use fme_core::pipeline::{ActivitySample, DepthFitState, Frame, Pipeline, PipelineError};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tracing::Level;

/// What the pipeline thread owns.
pub(super) struct PipelineCtx {
    pub pipeline: Box<dyn Pipeline>,
    pub queue: Arc<FrameQueue>,
    pub shared: Arc<Shared>,
    pub publisher: Arc<Mutex<Publisher>>,
    pub serial_tx: Option<SyncSender<String>>,
    pub output_period_s: f64,
    pub max_frames: Option<u64>,
    pub series: Option<SyncSender<SeriesRow>>,
    pub watchdog: Option<Duration>,
    pub finished: tokio::sync::watch::Sender<bool>,
    pub recorder: Option<Recorder>,
}

/// The loop's state between frames; its buffers are allocated once.
struct LoopState {
    next_out: Option<f64>,
    last_ping: Option<Instant>,
    processed: u64,
    errors: u64,
    series_dropped: u64,
    /// Copies of the last outcome: its fish (console `tracks`) and overlays (the recorder).
    fish: Vec<Fish>,
    overlays: Overlays,
    fit_state: DepthFitState,
}

/// Runs until stopped, the queue ends or `max_frames`; then finishes the series and the recorder.
pub(super) fn pipeline_loop(mut c: PipelineCtx) {
    let mut st = LoopState {
        next_out: None,
        last_ping: None,
        processed: 0,
        errors: 0,
        series_dropped: 0,
        fish: Vec::with_capacity(fme_core::motion::MAX_FISH),
        overlays: Overlays::default(),
        fit_state: DepthFitState::default(),
    };
    while !c.shared.stopping() {
        st.ping_watchdog(c.watchdog);
        crate::calibration::live::apply_pending(&c.shared, &mut *c.pipeline);
        let Some(frame) = c.queue.pop(Duration::from_millis(100)) else {
            if let Some(r) = c.recorder.as_mut() {
                r.watch(None, st.errors);
            }
            if c.queue.is_closed() && c.queue.is_empty() {
                break;
            }
            continue;
        };
        st.frame(&mut c, &frame);
        c.queue.recycle(frame.data);
        if c.max_frames.is_some_and(|m| st.processed >= m) {
            c.shared.log(Level::INFO, format!("processed {} frames: stopping as asked", st.processed));
            break;
        }
    }
    drop(c.series.take()); // the writer thread drains what is queued and finishes the file
    if let Some(r) = c.recorder.as_mut() {
        r.close();
    }
    let _ = c.finished.send(true);
}

impl LoopState {
    /// Pings the systemd watchdog every half period: a stuck `process` stops the pings.
    fn ping_watchdog(&mut self, watchdog: Option<Duration>) {
        if let Some(wd) = watchdog
            && self.last_ping.is_none_or(|t| t.elapsed() >= wd / 2)
        {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            self.last_ping = Some(Instant::now());
        }
    }

    /// One frame: process it, hand what it produced on, update the health, publish when due.
    fn frame(&mut self, c: &mut PipelineCtx, frame: &Frame) {
        // The fish are copied out only on frames that may carry an update (the console reads them).
        let may_publish = self.is_due(frame.timestamp.get(), c.output_period_s);
        // A web page waiting for the picture: this frame's overlays are kept for it.
        let preview = c.shared.preview.wanted();
        let result = self.process(c, frame, may_publish, preview);
        let now = Instant::now();
        self.processed += 1;
        let ts = frame.timestamp.get();
        let stage = c.pipeline.health();
        let sample = match result {
            Ok(s) => {
                self.send_series(c, frame, s);
                s
            }
            Err(e) => {
                self.errors += 1;
                // First error and then every 100th: a flood of bad frames must not flood the journal.
                if self.errors == 1 || self.errors.is_multiple_of(100) {
                    c.shared.log(Level::WARN, format!("pipeline error #{}: {e}", self.errors));
                }
                None
            }
        };
        if preview {
            self.offer_preview(c, frame, sample);
        }
        if let Some(r) = c.recorder.as_mut() {
            // Never waits: a full queue drops the frame from the recording (counted).
            r.after_frame(frame, &self.overlays, &*c.pipeline, sample);
            r.watch(sample.as_ref(), self.errors);
        }
        let due = sample.is_some() && self.update_due(ts, c.output_period_s);
        c.shared.with_health(|h| {
            h.frames_processed = self.processed;
            h.pipeline_errors = self.errors;
            h.last_processed_at = Some(now);
            h.stage = stage;
            h.fit_state = self.fit_state;
            if let Some(s) = sample {
                h.last_sample = Some(s);
                h.last_sample_at = Some(now);
            }
            if due {
                h.fish.clear();
                h.fish.extend(self.fish.iter().take(crate::console::TRACK_ROWS).copied());
            }
        });
        if due {
            publish_and_send(&c.publisher, &c.shared, c.serial_tx.as_ref(), Publish::Update);
            let ms = frame.arrived.elapsed().as_secs_f64() * 1000.0;
            c.shared.with_health(|h| h.latency.record(ms));
        }
    }

    /// Runs the pipeline on `frame` and copies out what the loop keeps of its outcome (the outcome
    /// borrows the pipeline). A panic in a stage on one bad frame is an error, not the end.
    fn process(
        &mut self,
        c: &mut PipelineCtx,
        frame: &Frame,
        keep_fish: bool,
        preview: bool,
    ) -> Result<Option<ActivitySample>, PipelineError> {
        let (fish, overlays, record) = (&mut self.fish, &mut self.overlays, c.recorder.is_some() || preview);
        let result = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            c.pipeline.process(frame).map(|o| {
                if keep_fish {
                    fish.clear();
                    fish.extend_from_slice(o.fish);
                }
                if record {
                    overlays.copy_from(&o);
                }
                (o.sample, o.fit)
            })
        })) {
            Ok(r) => r,
            Err(p) => Err(PipelineError::Stage { stage: "pipeline", message: panic_text(&*p) }),
        };
        match result {
            Ok((sample, fit)) => {
                self.fit_state = fit;
                Ok(sample)
            }
            Err(e) => {
                self.overlays.clear();
                Err(e)
            }
        }
    }

    /// Hands a copy of `frame` and what `snap` draws on it to the web page waiting for it.
    fn offer_preview(&self, c: &PipelineCtx, frame: &Frame, sample: Option<ActivitySample>) {
        c.shared.preview.offer(|| {
            let mut overlays = self.overlays.clone();
            c.pipeline.reference_residuals(&mut overlays.references);
            crate::web::preview::PreviewFrame {
                frame: frame.clone(),
                overlays,
                sample,
                jpeg: std::sync::OnceLock::new(),
            }
        });
    }

    /// `--series`: the writer thread has the disk; the pipeline never waits on it.
    fn send_series(&mut self, c: &mut PipelineCtx, frame: &Frame, sample: Option<ActivitySample>) {
        let (Some(tx), Some(sample)) = (&c.series, sample) else { return };
        match tx.try_send(SeriesRow { frame: frame.seq + 1, sample }) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.series_dropped += 1;
                if self.series_dropped == 1 || self.series_dropped.is_multiple_of(1000) {
                    c.shared.log(Level::WARN, format!("--series: {} rows dropped (disk slow)", self.series_dropped));
                }
            }
            Err(TrySendError::Disconnected(_)) => c.series = None,
        }
    }

    /// Whether frame time `ts` reaches the next update slot (or jumped back before it).
    fn is_due(&self, ts: f64, period: f64) -> bool {
        let next = self.next_out.unwrap_or(ts);
        ts + 1e-9 >= next || ts < next - 2.0 * period
    }

    /// Whether an output update is due at frame time `ts`, and if so, the next slot on the frame
    /// clock, resynchronised after gaps or a clock jump.
    fn update_due(&mut self, ts: f64, period: f64) -> bool {
        if !self.is_due(ts, period) {
            return false;
        }
        let next = self.next_out.get_or_insert(ts);
        *next = if ts - *next > period || ts < *next - 2.0 * period { ts + period } else { *next + period };
        true
    }
}
