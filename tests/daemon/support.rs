//! Helpers shared by the daemon, Modbus and console tests of this test binary (and by
//! `daemon_alloc` and `daemon_watchdog`, which need binaries of their own).
#![allow(dead_code)]

use fme::config::{Config, ModbusMode};
use fme::pipeline::{ActivitySample, Frame, FrameOutcome, Pipeline, PipelineError, QualityFlags, StageHealth};
use fme::units::{MetresPerSecond, Seconds};
use std::path::Path;

/// Writes a small MOTChallenge-style recording: dark water with bright "fish" squares moving at
/// different speeds, `frames` JPEG frames of `w`x`h` at `fps`.
pub fn write_sequence(dir: &Path, frames: usize, w: u32, h: u32, fps: u32) {
    let img_dir = dir.join("img1");
    std::fs::create_dir_all(&img_dir).expect("create img1");
    std::fs::write(
        dir.join("seqinfo.ini"),
        format!(
            "[Sequence]\nname=test\nimDir=img1\nframeRate={fps}\nseqLength={frames}\nimWidth={w}\nimHeight={h}\nimExt=.jpg\n"
        ),
    )
    .expect("write seqinfo.ini");
    for f in 0..frames {
        let mut img = image::GrayImage::from_pixel(w, h, image::Luma([30]));
        for fish in 0..4u32 {
            // Speed varies over time so the activity value changes.
            let speed = 1 + fish + (f as u32 / 10) % 4;
            let x = (fish * 37 + f as u32 * speed) % (w - 12);
            let y = 8 + fish * (h - 20) / 4;
            for dy in 0..8 {
                for dx in 0..12 {
                    img.put_pixel(x + dx, y + dy, image::Luma([220]));
                }
            }
        }
        img.save(img_dir.join(format!("{:06}.jpg", f + 1))).expect("write frame");
    }
}

/// The pipeline of the daemon-edge tests (Modbus, serial, console, watchdog): the frame-difference
/// test double, so these tests exercise the edges quickly without models. The real pipeline has its
/// own end-to-end tests (`pipeline_e2e.rs`).
pub fn edge_pipeline(cfg: &Config) -> Box<dyn Pipeline> {
    Box::new(FrameDiffPipeline::new(cfg.motion.smoothing_s.0, cfg.motion.body_length_m.0))
}

/// A config for tests: the given sequence, Modbus TCP server on an ephemeral local port, fast output.
pub fn test_config(seq: &Path) -> Config {
    let mut c = Config::default();
    c.source.path = seq.to_path_buf();
    c.output.modbus.mode = ModbusMode::TcpServer;
    c.output.modbus.listen = "127.0.0.1:0".into();
    c.output.rate_hz = 10.0;
    c.motion.smoothing_s = fme::units::Seconds(1.0);
    c.service.systemd_notify = false;
    c.service.stop_grace_ms = 300;
    c
}

/// Test double for the daemon's edges: the "activity" is the mean absolute
/// grey-level change between consecutive frames on a coarse grid, scaled by `scale_mps` per unit of
/// mean change per second. It exercises every edge of the daemon with values that move with the
/// scene; it is **not** a fish-speed estimate and always flags `unfitted`.
#[derive(Debug)]
pub struct FrameDiffPipeline {
    prev: Vec<u8>,
    cur: Vec<u8>,
    prev_t: Option<Seconds>,
    smoothed: Option<f64>,
    smoothing_s: f64,
    scale_mps: f64,
    body_length_m: f64,
    grid: usize,
    ok: bool,
}

impl FrameDiffPipeline {
    /// Grid cells per side used for the grey-level comparison.
    pub const GRID: usize = 32;

    /// A test double with EWMA time constant `smoothing_s` and body length `body_length_m`.
    pub fn new(smoothing_s: f64, body_length_m: f64) -> Self {
        Self {
            prev: vec![0; Self::GRID * Self::GRID],
            cur: vec![0; Self::GRID * Self::GRID],
            prev_t: None,
            smoothed: None,
            smoothing_s,
            scale_mps: 0.02,
            body_length_m,
            grid: Self::GRID,
            ok: false,
        }
    }

    fn sample_grid(&self, frame: &Frame, out: &mut [u8]) -> Result<(), PipelineError> {
        let img = frame.to_luma().map_err(|message| PipelineError::Decode { seq: frame.seq, message })?;
        let (w, h) = (img.width() as usize, img.height() as usize);
        if w == 0 || h == 0 {
            return Err(PipelineError::Decode { seq: frame.seq, message: "empty image".into() });
        }
        for gy in 0..self.grid {
            for gx in 0..self.grid {
                let x = (gx * w + w / 2) / self.grid;
                let y = (gy * h + h / 2) / self.grid;
                out[gy * self.grid + gx] = img.get_pixel(x.min(w - 1) as u32, y.min(h - 1) as u32).0[0];
            }
        }
        Ok(())
    }
}

impl Pipeline for FrameDiffPipeline {
    fn process(&mut self, frame: &Frame) -> Result<FrameOutcome<'_>, PipelineError> {
        let sample = self.sample(frame)?;
        Ok(FrameOutcome::sample_only(sample, self.health()))
    }

    fn health(&self) -> StageHealth {
        // No depth stage here, so nothing to fail: depth_ok follows frame decoding like detector_ok.
        StageHealth { detector_ok: self.ok, depth_ok: self.ok, ..StageHealth::default() }
    }
}

impl FrameDiffPipeline {
    fn sample(&mut self, frame: &Frame) -> Result<Option<ActivitySample>, PipelineError> {
        let mut cur = std::mem::take(&mut self.cur);
        let r = self.sample_grid(frame, &mut cur);
        self.cur = cur;
        if let Err(e) = r {
            self.ok = false;
            return Err(e);
        }
        self.ok = true;
        let t = frame.timestamp;
        let prev_t = self.prev_t.replace(t);
        std::mem::swap(&mut self.prev, &mut self.cur); // prev = this frame, cur = the previous one
        let Some(pt) = prev_t else { return Ok(None) };
        let dt = (t - pt).get();
        if dt.is_nan() || dt <= 0.0 {
            return Ok(None); // loop restart or duplicate timestamp: no speed across it
        }
        let n = self.cur.len() as f64;
        let diffs = self.cur.iter().zip(&self.prev).map(|(a, b)| (f64::from(*a) - f64::from(*b)).abs() / 255.0);
        let (sum, sum2) = diffs.fold((0.0, 0.0), |(s, s2), d| (s + d, s2 + d * d));
        let mean = sum / n;
        let var = (sum2 / n - mean * mean).max(0.0);
        let v = self.scale_mps * mean / dt;
        let ci = self.scale_mps * 1.96 * (var / n).sqrt() / dt;
        let alpha = (dt / self.smoothing_s).clamp(0.0, 1.0);
        let s = match self.smoothed {
            Some(s) => s + alpha * (v - s),
            None => v,
        };
        self.smoothed = Some(s);
        Ok(Some(ActivitySample {
            timestamp: t,
            mean: MetresPerSecond(v),
            mean_body_lengths: v / self.body_length_m,
            smoothed: MetresPerSecond(s),
            ci95_half: MetresPerSecond(ci),
            fish: 0,
            latency: Seconds(0.0),
            flags: QualityFlags { too_few_fish: true, unfitted: true, stale: false, unlike_fish: false },
            scale: fme::pipeline::ScaleSource::None,
        }))
    }
}

#[test]
fn written_sequence_opens() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_sequence(dir.path(), 3, 64, 48, 30);
    let s = fme::capture::RecordedSource::open(dir.path(), false, false).expect("open");
    assert_eq!(s.len(), 3);
    assert_eq!(s.fps(), 30.0);
}

/// A free local port (bound, then released) for a server the test starts.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").and_then(|l| l.local_addr()).map(|a| a.port()).expect("free port")
}

/// A child process killed when the test ends, however it ends.
pub struct Running(pub std::process::Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Waits until `f` holds, polling every 20 ms; fails the test naming `what` after `secs` seconds.
pub async fn wait_until(what: &str, secs: u64, mut f: impl FnMut() -> bool) {
    let end = tokio::time::Instant::now() + std::time::Duration::from_secs(secs);
    while !f() {
        assert!(tokio::time::Instant::now() < end, "timed out waiting for {what}");
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}

/// `GET path` on 127.0.0.1:`port` as JSON; `None` unless the answer is a 200 with a JSON body.
pub fn get_json(port: u16, path: &str) -> Option<serde_json::Value> {
    use std::io::{Read as _, Write as _};
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(std::time::Duration::from_secs(5))).ok()?;
    s.write_all(format!("GET {path} HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n").as_bytes()).ok()?;
    let mut raw = String::new();
    s.read_to_string(&mut raw).ok()?;
    serde_json::from_str(raw.strip_prefix("HTTP/1.1 200")?.split_once("\r\n\r\n")?.1).ok()
}
