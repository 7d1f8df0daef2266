//! The calibration in use while `fme run` runs, and a reload (SIGHUP, the web page's "apply"):
//! the file is read and checked as at start ([`Config::calibration`]); a good one is handed to the
//! pipeline thread, which sets it up as at start between two frames
//! ([`fme_core::pipeline::Pipeline::set_calibration`]); a bad one is refused with a log line naming
//! the file and the problem, and the calibration in use keeps running.

use crate::config::Config;
use crate::status::Shared;
use fme_core::pipeline::Calibration;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock, PoisonError};
use tracing::Level;

/// The calibration slot in [`Shared`]: the one in use and the one waiting for the pipeline.
#[derive(Debug, Default)]
pub struct LiveCalibration {
    /// The configuration a reload reads the file with (set once at start).
    config: OnceLock<Config>,
    in_use: Mutex<Option<Calibration>>,
    pending: Mutex<Option<Option<Calibration>>>,
    has_pending: AtomicBool,
    /// Calibrations the pipeline took since start (a page waits for its apply to be taken).
    taken: AtomicU64,
}

impl LiveCalibration {
    /// At start: the configuration and the calibration the pipeline was built with.
    pub fn start(&self, cfg: &Config, in_use: Option<Calibration>) {
        let _ = self.config.set(cfg.clone());
        *self.in_use.lock().unwrap_or_else(PoisonError::into_inner) = in_use;
    }

    /// The calibration in use (`None`: uncalibrated, or not running).
    pub fn in_use(&self) -> Option<Calibration> {
        self.in_use.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// Where an applied calibration is written: `camera.calibration` (`None`: not set, or not running).
    pub fn configured_path(&self) -> Option<PathBuf> {
        let p = &self.config.get()?.camera.calibration;
        (!p.as_os_str().is_empty()).then(|| p.clone())
    }

    /// How many calibrations the pipeline took since start.
    pub fn taken(&self) -> u64 {
        self.taken.load(Ordering::Acquire)
    }

    /// The calibration waiting for the pipeline, if any (one atomic load when none: every frame asks).
    pub fn take_pending(&self) -> Option<Option<Calibration>> {
        if !self.has_pending.swap(false, Ordering::AcqRel) {
            return None;
        }
        self.pending.lock().unwrap_or_else(PoisonError::into_inner).take()
    }

    /// The pipeline took `c`.
    pub fn took(&self, c: Option<Calibration>) {
        *self.in_use.lock().unwrap_or_else(PoisonError::into_inner) = c;
        self.taken.fetch_add(1, Ordering::AcqRel);
    }

    fn offer(&self, c: Option<Calibration>) {
        *self.pending.lock().unwrap_or_else(PoisonError::into_inner) = Some(c);
        self.has_pending.store(true, Ordering::Release);
    }
}

/// Reads the calibration file again (`why`: what asked, for the log) and hands a good one to the
/// pipeline. `Ok`: what was handed over; `Err`: why nothing was (the calibration in use is kept).
/// Either is logged (journal and console `log`).
pub fn reload(shared: &Shared, why: &str) -> Result<String, String> {
    let Some(cfg) = shared.calibration.config.get() else {
        return Err(format!("{why}: the daemon is not running: nothing to reload"));
    };
    match cfg.calibration() {
        Ok(Some(c)) => {
            let msg = format!(
                "{why}: calibration {} reads OK ({} reference objects): handed to the pipeline",
                c.path.display(),
                c.references.len()
            );
            shared.log(Level::INFO, msg.clone());
            shared.calibration.offer(Some(c));
            Ok(msg)
        }
        Ok(None) => {
            let msg = format!("{why}: no calibration configured (camera.calibration): nothing to apply");
            shared.log(Level::WARN, msg.clone());
            Err(msg)
        }
        Err(e) => {
            let msg = format!("{why}: calibration refused: {e}; the calibration in use is kept");
            shared.log(Level::ERROR, msg.clone());
            Err(msg)
        }
    }
}

/// On the pipeline thread, between frames: sets up a calibration waiting in `shared` (if any) and
/// says so; a pipeline that refuses it (or panics) keeps the one in use.
pub fn apply_pending(shared: &Shared, pipeline: &mut dyn fme_core::pipeline::Pipeline) {
    let Some(next) = shared.calibration.take_pending() else { return };
    let name = next.as_ref().map_or_else(|| "none".to_string(), |c| c.path.display().to_string());
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| pipeline.set_calibration(next.as_ref())))
        .unwrap_or_else(|_| Err("the pipeline panicked setting it up".into()));
    match r {
        Ok(()) => {
            let n = next.as_ref().map_or(0, |c| c.references.len());
            shared.log(Level::INFO, format!("calibration {name} applied ({n} reference objects)"));
            shared.calibration.took(next);
        }
        Err(e) => shared.log(
            Level::ERROR,
            format!("calibration {name} refused by the pipeline: {e}; the calibration in use is kept"),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pending_calibration_is_taken_once() {
        let slot = LiveCalibration::default();
        assert!(slot.take_pending().is_none());
        slot.offer(None);
        assert_eq!(slot.take_pending(), Some(None));
        assert!(slot.take_pending().is_none());
        slot.took(None);
        assert_eq!(slot.taken(), 1);
    }

    /// A pipeline that cannot take a calibration (the trait's default).
    struct Fixed;

    impl fme_core::pipeline::Pipeline for Fixed {
        fn process(
            &mut self,
            _frame: &fme_core::pipeline::Frame,
        ) -> Result<fme_core::pipeline::FrameOutcome<'_>, fme_core::pipeline::PipelineError> {
            Err(fme_core::pipeline::PipelineError::Stage { stage: "test", message: "none".into() })
        }
        fn health(&self) -> fme_core::pipeline::StageHealth {
            fme_core::pipeline::StageHealth::default()
        }
    }

    #[test]
    fn a_refused_calibration_is_logged_and_the_one_in_use_kept() {
        let shared = Shared::new(String::new(), 50);
        let path = std::path::Path::new(fme_core::REPO_DIR).join("tests/data/swarm20/meta.json");
        let c = crate::calibration::load(&path).expect("the bundled calibration");
        shared.calibration.offer(Some(c));
        apply_pending(&shared, &mut Fixed);
        assert!(shared.calibration.in_use().is_none(), "the pipeline refused it");
        assert_eq!(shared.calibration.taken(), 0);
        let log = shared.last_logs(10).join("\n");
        assert!(log.contains("refused by the pipeline") && log.contains("meta.json"), "{log}");
    }
}
