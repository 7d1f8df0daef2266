//! The on-disk ring of the black box: one JPEG per processed frame in `ring/`, the oldest deleted
//! so that the ring spans at most `record.ring_s` of frame time and `record.max_disk_mb` of disk,
//! and leaves `record.reserve_mb` free on its file system for the history, snapshots and
//! recordings. The per-frame rows (detections, tracks, sample) are small and kept in memory beside it.

use super::Overlays;
use fme_core::pipeline::ActivitySample;
use std::collections::VecDeque;
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// How a ring frame reaches the disk: a seam, so that a test can put a stalled or failing disk
/// under the recorder. [`write_file`] is the real one.
pub type WriteFile = fn(&Path, &[u8]) -> std::io::Result<()>;

/// Creates `path` with `bytes` (the ring's [`WriteFile`]).
pub fn write_file(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    std::fs::File::create(path).and_then(|mut f| f.write_all(bytes))
}

/// Free and total bytes of the file system holding `dir`, and its block size (statvfs).
// The statvfs fields are 32-bit on some 32-bit boards: the casts are not useless there.
#[allow(clippy::unnecessary_cast)]
pub fn fs_space(dir: &Path) -> std::io::Result<FsSpace> {
    use std::os::unix::ffi::OsStrExt as _;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).map_err(std::io::Error::other)?;
    // SAFETY: a NUL-terminated path and a zeroed out-struct that statvfs fills.
    let mut st: libc::statvfs = unsafe { std::mem::zeroed() };
    if unsafe { libc::statvfs(c.as_ptr(), &mut st) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    let unit = st.f_frsize.max(1) as u64;
    Ok(FsSpace {
        free: (st.f_bavail as u64).saturating_mul(unit),
        total: (st.f_blocks as u64).saturating_mul(unit),
        block: (st.f_bsize as u64).clamp(512, 1 << 20),
    })
}

/// What [`fs_space`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FsSpace {
    /// Bytes an unprivileged writer may still use.
    pub free: u64,
    /// Size of the file system, bytes.
    pub total: u64,
    /// Block size: a file takes its length rounded up to this.
    pub block: u64,
}

/// One frame of the ring.
#[derive(Debug, Clone)]
pub struct RingEntry {
    /// Source sequence number.
    pub seq: u64,
    /// Frame timestamp, s.
    pub t: f64,
    /// Image size, px.
    pub size: (u32, u32),
    /// Bytes of the JPEG file.
    pub bytes: u64,
    /// What the pipeline produced on it.
    pub overlays: Overlays,
    /// The activity sample computed on it.
    pub sample: Option<ActivitySample>,
}

/// The ring: frames on disk, their rows in memory.
#[derive(Debug)]
pub struct Ring {
    dir: PathBuf,
    entries: VecDeque<RingEntry>,
    bytes: u64,
    /// Bytes the frames take on disk (each rounded up to the block size).
    disk: u64,
    max_bytes: u64,
    reserve: u64,
    /// The file system's block size, as last seen.
    block: u64,
    span_s: f64,
    write: WriteFile,
}

fn on_disk(len: u64, block: u64) -> u64 {
    len.div_ceil(block.max(1)) * block.max(1)
}

fn disk_full(e: &std::io::Error) -> bool {
    matches!(e.raw_os_error(), Some(libc::ENOSPC | libc::EDQUOT))
}

impl Ring {
    /// Opens (creates) `dir` and empties it of an earlier run's frames (their rows are gone).
    pub fn open(dir: &Path, span_s: f64, max_bytes: u64) -> std::io::Result<Self> {
        std::fs::create_dir_all(dir)?;
        for e in std::fs::read_dir(dir)?.flatten() {
            if e.path().extension().is_some_and(|x| x == "jpg") {
                let _ = std::fs::remove_file(e.path());
            }
        }
        Ok(Self {
            dir: dir.to_path_buf(),
            entries: VecDeque::new(),
            bytes: 0,
            disk: 0,
            max_bytes,
            reserve: 0,
            block: 4096,
            span_s,
            write: write_file,
        })
    }

    /// Leaves `reserve` bytes free on the ring's file system (at most a quarter of it).
    pub fn with_reserve(mut self, reserve: u64) -> Self {
        self.reserve = reserve;
        self
    }

    /// Writes the frames with `write` instead of [`write_file`].
    pub fn with_writer(mut self, write: WriteFile) -> Self {
        self.write = write;
        self
    }

    /// The file of frame `seq`.
    pub fn path(&self, seq: u64) -> PathBuf {
        self.dir.join(format!("{seq:012}.jpg"))
    }

    /// Bytes the ring may take now: `record.max_disk_mb`, and no more than leaves the reserve free
    /// (what the ring holds counts as free: it can delete it), with the block size.
    fn budget(&mut self) -> u64 {
        match fs_space(&self.dir) {
            Ok(s) => {
                self.block = s.block;
                let reserve = self.reserve.min(s.total / 4);
                (self.disk + s.free).saturating_sub(reserve).min(self.max_bytes)
            }
            Err(_) => self.max_bytes,
        }
    }

    /// Writes one frame (`jpeg`: its bytes) and trims the ring. Time going backwards (a camera
    /// restart) starts the ring afresh. A full disk drops the oldest frames and tries once more,
    /// so the ring shrinks instead of stopping. A failed write leaves no partial file.
    pub fn push(&mut self, mut entry: RingEntry, jpeg: &[u8]) -> std::io::Result<()> {
        if self.entries.back().is_some_and(|b| entry.t <= b.t || entry.seq <= b.seq) {
            self.clear();
        }
        let path = self.path(entry.seq);
        let budget = self.budget();
        let size = on_disk(jpeg.len() as u64, self.block);
        // Room first: the new frame must fit beside the frames kept.
        while !self.entries.is_empty() && self.disk + size > budget {
            self.pop_front();
        }
        let mut written = (self.write)(&path, jpeg);
        if let Err(e) = &written
            && disk_full(e)
            && !self.entries.is_empty()
        {
            // Someone else took the space (history, a recording pinning frames): shed a quarter.
            let _ = std::fs::remove_file(&path);
            let keep = self.entries.len() * 3 / 4;
            while self.entries.len() > keep {
                self.pop_front();
            }
            written = (self.write)(&path, jpeg);
        }
        if let Err(e) = written {
            let _ = std::fs::remove_file(&path);
            return Err(e);
        }
        entry.bytes = jpeg.len() as u64;
        self.bytes += entry.bytes;
        self.disk += size;
        self.entries.push_back(entry);
        self.trim();
        Ok(())
    }

    fn trim(&mut self) {
        let newest = self.entries.back().map_or(f64::NAN, |e| e.t);
        while let Some(front) = self.entries.front() {
            let too_old = newest - front.t > self.span_s;
            if !(too_old || self.bytes > self.max_bytes) || self.entries.len() == 1 {
                break;
            }
            self.pop_front();
        }
    }

    fn pop_front(&mut self) {
        if let Some(e) = self.entries.pop_front() {
            self.bytes -= e.bytes;
            let size = if self.entries.is_empty() { self.disk } else { on_disk(e.bytes, self.block).min(self.disk) };
            self.disk -= size;
            let _ = std::fs::remove_file(self.path(e.seq));
        }
    }
    /// Deletes every frame.
    pub fn clear(&mut self) {
        while !self.entries.is_empty() {
            self.pop_front();
        }
    }

    /// The frames, oldest first.
    pub fn entries(&self) -> &VecDeque<RingEntry> {
        &self.entries
    }

    /// Bytes on disk.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(seq: u64, t: f64) -> RingEntry {
        RingEntry { seq, t, size: (4, 4), bytes: 0, overlays: Overlays::default(), sample: None }
    }

    fn files(dir: &Path) -> usize {
        std::fs::read_dir(dir).map(|d| d.count()).unwrap_or(0)
    }

    #[test]
    fn bounded_by_time() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut r = Ring::open(dir.path(), 1.0, 1 << 30).expect("open");
        for i in 0..100u64 {
            r.push(entry(i, i as f64 / 30.0), &[0u8; 100]).expect("push");
        }
        // 1 s at 30 frames/s: the newest frame and the 30 before it.
        assert_eq!(r.entries().len(), 31);
        assert_eq!(files(dir.path()), 31);
        assert_eq!(r.entries().front().map(|e| e.seq), Some(69));
        assert_eq!(r.bytes(), 3100);
    }

    #[test]
    fn bounded_by_size() {
        let dir = tempfile::tempdir().expect("tempdir");
        // The budget counts whole file-system blocks: frames of one 4 KiB block each.
        let mut r = Ring::open(dir.path(), 1e9, 40_960).expect("open");
        for i in 0..100u64 {
            r.push(entry(i, i as f64), &vec![7u8; 4096]).expect("push");
        }
        assert_eq!(r.entries().len(), 10);
        assert!(r.bytes() <= 40_960);
        let on_disk: u64 = std::fs::read_dir(dir.path())
            .expect("dir")
            .flatten()
            .map(|e| e.metadata().map(|m| m.len()).unwrap_or(0))
            .sum();
        assert_eq!(on_disk, r.bytes());
        assert_eq!(r.entries().front().map(|e| e.seq), Some(90));
    }

    #[test]
    fn restart_and_old_files_cleared() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("000000000001.jpg"), b"old").expect("write");
        let mut r = Ring::open(dir.path(), 10.0, 1 << 20).expect("open");
        assert_eq!(files(dir.path()), 0);
        r.push(entry(5, 5.0), b"a").expect("push");
        r.push(entry(6, 1.0), b"b").expect("push");
        assert_eq!(r.entries().len(), 1);
        assert_eq!(files(dir.path()), 1);
    }
}
