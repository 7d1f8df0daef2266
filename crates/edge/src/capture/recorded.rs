//! Recorded MOTChallenge sequences (`img1/*.jpg`, `seqinfo.ini`) as a frame source: paced at the
//! sequence's frame rate and looping (like a camera that never stops), or as fast as possible.

use super::{CaptureError, Frame, FrameSource, PixelFormat};
use crate::sequence::{SeqInfo, frame_file_name};
use fme_core::units::Seconds;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// A recorded sequence played as a camera.
#[derive(Debug)]
pub struct RecordedSource {
    dir: PathBuf,
    files: Vec<PathBuf>,
    fps: f64,
    width: u32,
    height: u32,
    realtime: bool,
    looping: bool,
    /// Frames delivered so far (never reset; gives the monotonic timestamp).
    delivered: u64,
    start: Option<Instant>,
}

impl RecordedSource {
    /// Opens a sequence directory. `realtime` paces frames at `frameRate`; `looping` restarts at the end.
    /// `seqinfo.ini` is read by the sequence reader's parser ([`SeqInfo`]); the sequence is its first
    /// `seqLength` frames, `imDir/000001imExt` on (more images in the folder are not part of it).
    pub fn open(dir: &Path, realtime: bool, looping: bool) -> Result<Self, CaptureError> {
        let open_err = |message: String| CaptureError::Open { path: dir.to_path_buf(), message };
        if !dir.is_dir() {
            return Err(CaptureError::NotFound { path: dir.to_path_buf() });
        }
        let ini_path = dir.join("seqinfo.ini");
        let info = SeqInfo::read(&ini_path).map_err(|e| open_err(e.to_string()))?;
        let ext = info.im_ext.to_ascii_lowercase();
        if ext != ".jpg" && ext != ".jpeg" {
            return Err(open_err(format!(
                "{}: only JPEG frames are supported, imExt is {}",
                ini_path.display(),
                info.im_ext
            )));
        }
        let img_dir = dir.join(&info.im_dir);
        let files: Vec<PathBuf> =
            (1..=info.seq_length).map(|k| img_dir.join(frame_file_name(k, &info.im_ext))).collect();
        let Some(first) = files.first() else {
            return Err(open_err(format!("{}: seqLength is 0, no frames", ini_path.display())));
        };
        if !first.is_file() {
            return Err(open_err(format!("{}: frame 1 is missing", first.display())));
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            files,
            fps: info.frame_rate,
            width: info.im_width,
            height: info.im_height,
            realtime,
            looping,
            delivered: 0,
            start: None,
        })
    }

    /// Frames in one pass of the sequence.
    pub fn len(&self) -> usize {
        self.files.len()
    }

    /// Whether the sequence has no frames (never true for an opened source).
    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// The sequence's frame rate, frames/s.
    pub fn fps(&self) -> f64 {
        self.fps
    }
}

impl FrameSource for RecordedSource {
    fn next_frame(&mut self, buf: Vec<u8>) -> Result<Frame, CaptureError> {
        let n = self.files.len() as u64;
        if !self.looping && self.delivered >= n {
            return Err(CaptureError::End);
        }
        let idx = (self.delivered % n) as usize;
        let timestamp = Seconds(self.delivered as f64 / self.fps);
        if self.realtime {
            let start = *self.start.get_or_insert_with(Instant::now);
            // Checked: a frame time no `Instant` can hold is simply due now (never a panic).
            let due = timestamp.to_duration().ok().and_then(|d| start.checked_add(d));
            let now = Instant::now();
            if let Some(wait) = due.and_then(|due| due.checked_duration_since(now)) {
                std::thread::sleep(wait);
            }
        }
        let path = &self.files[idx];
        let mut data = buf;
        data.clear();
        if let Err(e) = std::fs::File::open(path).and_then(|mut f| std::io::Read::read_to_end(&mut f, &mut data)) {
            self.delivered += 1; // skip the unreadable frame instead of retrying it forever
            return Err(CaptureError::Read { path: path.clone(), message: e.to_string() });
        }
        let frame = Frame {
            seq: self.delivered,
            timestamp,
            arrived: Instant::now(),
            width: self.width,
            height: self.height,
            format: PixelFormat::Jpeg,
            data,
        };
        self.delivered += 1;
        Ok(frame)
    }

    fn reopen(&mut self) -> Result<(), CaptureError> {
        // Nothing to reopen; a missing file shows up again as a Read error on the next frame.
        if self.dir.is_dir() { Ok(()) } else { Err(CaptureError::NotFound { path: self.dir.clone() }) }
    }

    fn paced(&self) -> bool {
        self.realtime
    }

    fn describe(&self) -> String {
        format!(
            "recording {} ({} frames, {}x{} @ {} fps, {}{})",
            self.dir.display(),
            self.files.len(),
            self.width,
            self.height,
            self.fps,
            if self.realtime { "real time" } else { "as fast as possible" },
            if self.looping { ", looping" } else { "" }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_frame_rate_no_timer_holds_is_refused_at_open() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir_all(dir.path().join("img1")).expect("mkdir");
        image::GrayImage::from_pixel(4, 4, image::Luma([9])).save(dir.path().join("img1/000001.jpg")).expect("save");
        for rate in ["1e-300", "0", "-1", "inf", "NaN", "1e300"] {
            std::fs::write(
                dir.path().join("seqinfo.ini"),
                format!("[Sequence]\nframeRate={rate}\nseqLength=1\nimWidth=4\nimHeight=4\n"),
            )
            .expect("ini");
            let e = RecordedSource::open(dir.path(), true, true).err().map(|e| e.to_string()).unwrap_or_default();
            assert!(e.contains("frameRate") && e.contains("0.001..=10000"), "{rate}: {e:?}");
        }
        // The slowest accepted rate paces without a panic (the first frame is due at once).
        std::fs::write(
            dir.path().join("seqinfo.ini"),
            "[Sequence]\nframeRate=0.001\nseqLength=1\nimWidth=4\nimHeight=4\n",
        )
        .expect("ini");
        let mut s = RecordedSource::open(dir.path(), true, true).expect("open");
        assert!(s.next_frame(Vec::new()).is_ok());
    }

    #[test]
    fn unreadable_frame_is_skipped_and_timestamps_stay_monotonic() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir_all(dir.path().join("img1")).expect("mkdir");
        let ini = "[Sequence]\nframeRate=10\nseqLength=3\nimWidth=4\nimHeight=4\nimExt=.jpg\n";
        std::fs::write(dir.path().join("seqinfo.ini"), ini).expect("ini");
        let img = image::GrayImage::from_pixel(4, 4, image::Luma([9]));
        img.save(dir.path().join("img1/000001.jpg")).expect("save");
        img.save(dir.path().join("img1/000003.jpg")).expect("save");
        // A directory named like a frame cannot be read as a file.
        std::fs::create_dir(dir.path().join("img1/000002.jpg")).expect("mkdir");
        let mut s = RecordedSource::open(dir.path(), false, true).expect("open");
        assert_eq!((s.len(), s.fps()), (3, 10.0));
        let a = s.next_frame(Vec::new()).expect("frame 1");
        assert!(matches!(s.next_frame(Vec::new()), Err(CaptureError::Read { .. })));
        let c = s.next_frame(Vec::new()).expect("frame 3");
        let d = s.next_frame(Vec::new()).expect("loops to frame 1");
        assert_eq!((a.seq, c.seq, d.seq), (0, 2, 3));
        assert!(a.timestamp.get() < c.timestamp.get() && c.timestamp.get() < d.timestamp.get());
        assert_eq!((d.width, d.height), (4, 4));
        let mut once = RecordedSource::open(dir.path(), false, false).expect("open");
        for _ in 0..3 {
            let _ = once.next_frame(Vec::new());
        }
        assert!(matches!(once.next_frame(Vec::new()), Err(CaptureError::End)));
        assert!(matches!(
            RecordedSource::open(&dir.path().join("nope"), false, false),
            Err(CaptureError::NotFound { .. })
        ));
    }

    #[test]
    fn plays_only_the_first_seq_length_frames() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::create_dir_all(dir.path().join("img1")).expect("mkdir");
        let img = image::GrayImage::from_pixel(4, 4, image::Luma([9]));
        for k in 1..=5 {
            img.save(dir.path().join(format!("img1/{k:06}.jpg"))).expect("save");
        }
        let ini = "[Sequence]\nframeRate=10\nseqLength=3\nimWidth=4\nimHeight=4\nimExt=.jpg\n";
        std::fs::write(dir.path().join("seqinfo.ini"), ini).expect("ini");
        let mut s = RecordedSource::open(dir.path(), false, false).expect("open");
        assert_eq!(s.len(), 3);
        for _ in 0..3 {
            s.next_frame(Vec::new()).expect("frame");
        }
        assert!(matches!(s.next_frame(Vec::new()), Err(CaptureError::End)));
        // A seqinfo.ini without its required keys is refused, naming the file and the key.
        std::fs::write(dir.path().join("seqinfo.ini"), "[Sequence]\nframeRate=10\n").expect("ini");
        let e = RecordedSource::open(dir.path(), false, false).expect_err("no seqLength").to_string();
        assert!(e.contains("seqinfo.ini") && e.contains("seqLength"), "{e}");
    }
}
