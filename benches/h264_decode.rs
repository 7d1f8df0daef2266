//! H.264 decoding cost of the RTSP source: OpenH264 (built into fme, one thread) decodes an Annex B
//! file NAL unit by NAL unit and each picture is copied out as I420, as `RtspSource` does; prints
//! the CPU time per frame, to set beside `ffmpeg -benchmark -threads 1` on the same file
//! (docs/benchmarks.md#h264-decoding). Usage: `cargo bench --bench h264_decode -- FILE.h264`.

use openh264::formats::YUVSource as _;

/// CPU time (user + system) of this process, s.
fn cpu_s() -> f64 {
    // SAFETY: getrusage writes into the struct it is given.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut u) };
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    tv(u.ru_utime) + tv(u.ru_stime)
}

fn main() {
    let Some(path) = std::env::args().skip(1).find(|a| !a.starts_with("--")) else {
        eprintln!("usage: cargo bench --bench h264_decode -- FILE.h264");
        return;
    };
    let data = std::fs::read(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let mut dec = openh264::decoder::Decoder::new().expect("OpenH264 decoder");
    let mut buf = Vec::new();
    let (t0, c0) = (std::time::Instant::now(), cpu_s());
    let mut frames = 0u32;
    for nal in openh264::nal_units(&data) {
        if let Ok(Some(yuv)) = dec.decode(nal) {
            let (w, h) = yuv.dimensions();
            let (ys, us, vs) = yuv.strides();
            buf.clear();
            (0..h).for_each(|r| buf.extend_from_slice(&yuv.y()[r * ys..][..w]));
            (0..h.div_ceil(2)).for_each(|r| buf.extend_from_slice(&yuv.u()[r * us..][..w.div_ceil(2)]));
            (0..h.div_ceil(2)).for_each(|r| buf.extend_from_slice(&yuv.v()[r * vs..][..w.div_ceil(2)]));
            frames += 1;
        }
    }
    let (wall, cpu) = (t0.elapsed().as_secs_f64(), cpu_s() - c0);
    let n = f64::from(frames.max(1));
    println!("{path}: {frames} frames, {:.3} ms CPU per frame, {:.3} ms wall per frame", cpu * 1e3 / n, wall * 1e3 / n);
}
