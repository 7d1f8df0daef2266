//! Helpers shared by the daemon, Modbus and console tests (included with `#[path]`); as its own
//! test target it only checks that a written sequence opens.
#![allow(dead_code)]

use fme::config::{Config, ModbusMode};
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
pub fn edge_pipeline(cfg: &Config) -> Box<dyn fme::service::pipeline::Pipeline> {
    Box::new(fme::service::pipeline::FrameDiffPipeline::new(cfg.motion.smoothing_s, cfg.motion.body_length_m))
}

/// A config for tests: the given sequence, Modbus TCP server on an ephemeral local port, fast output.
pub fn test_config(seq: &Path) -> Config {
    let mut c = Config::default();
    c.source.path = seq.to_path_buf();
    c.output.modbus.mode = ModbusMode::TcpServer;
    c.output.modbus.listen = "127.0.0.1:0".into();
    c.output.rate_hz = 10.0;
    c.motion.smoothing_s = 1.0;
    c.service.systemd_notify = false;
    c.service.stop_grace_ms = 300;
    c
}

#[test]
fn written_sequence_opens() {
    let dir = tempfile::tempdir().expect("tempdir");
    write_sequence(dir.path(), 3, 64, 48, 30);
    let s = fme::capture::RecordedSource::open(dir.path(), false, false).expect("open");
    assert_eq!(s.len(), 3);
    assert_eq!(s.fps(), 30.0);
}
