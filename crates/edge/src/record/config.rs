//! `[record]`: the black box's ring, snapshots, alarms and freezes, and their check.

use crate::config::KeyError;
use serde::{Deserialize, Serialize};

/// `[record]`: the black box (docs/recording.md). Active only with a state directory.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct RecordConfig {
    /// Keep a rolling on-disk ring of the frames the pipeline processed, with their detections,
    /// tracks and activity samples.
    pub enabled: bool,
    /// Seconds of frames kept in the ring (frame time), s.
    pub ring_s: f64,
    /// Largest size of the ring on disk, MB (10^6 bytes); the oldest frames go first.
    pub max_disk_mb: u64,
    /// Free space the ring leaves on its file system for the history, snapshots and recordings, MB
    /// (at most a quarter of the file system, so a small disk still keeps a ring).
    pub reserve_mb: u64,
    /// Write a snapshot (frame with overlays + metric depth map) every this many seconds (0 = off), s.
    pub snapshot_every_s: f64,
    /// Snapshots kept (older ones are deleted).
    pub keep_snapshots: usize,
    /// Frozen recordings kept (older ones are deleted; 0 = keep all).
    pub keep_recordings: usize,
    /// Freeze the ring when the smoothed activity falls below this, m/s (0 = off).
    pub alarm_low_mps: f64,
    /// Freeze the ring when the smoothed activity rises above this, m/s (0 = off).
    pub alarm_high_mps: f64,
    /// Freeze the ring on a fault: camera lost or stalled, detector or depth failure, pipeline error.
    pub freeze_on_fault: bool,
    /// At least this long between two automatic freezes (alarms, faults), s.
    pub freeze_min_gap_s: f64,
    /// Frames held between the pipeline and the recorder's writer thread; when full, frames are
    /// dropped from the recording and counted (console `counters`); the pipeline never waits.
    pub queue_frames: usize,
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            ring_s: 60.0,
            max_disk_mb: 500,
            reserve_mb: 64,
            snapshot_every_s: 0.0,
            keep_snapshots: 20,
            keep_recordings: 20,
            alarm_low_mps: 0.0,
            alarm_high_mps: 0.0,
            freeze_on_fault: true,
            freeze_min_gap_s: 600.0,
            queue_frames: 32,
        }
    }
}

impl RecordConfig {
    /// The alarms must not overlap (the ranges check each alone; 0 = off).
    pub fn validate(&self) -> Result<(), KeyError> {
        if self.alarm_high_mps > 0.0 && self.alarm_high_mps <= self.alarm_low_mps {
            return Err(KeyError::new("record.alarm_high_mps", "must be > record.alarm_low_mps"));
        }
        Ok(())
    }
}
