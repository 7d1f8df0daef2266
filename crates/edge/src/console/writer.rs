//! The console's output side, which never blocks: replies, echo and streamed lines go into a
//! bounded buffer that is written to the device without waiting (`O_NONBLOCK`, no `tcdrain`). When
//! the peer does not read (a stalled socat relay, a frozen terminal) the buffer fills, further
//! output is dropped and counted, and the console keeps reading input; once the peer reads again it
//! is told how much was lost.

use std::collections::VecDeque;
use std::io;
use std::os::fd::RawFd;
use std::sync::atomic::{AtomicU64, Ordering};

/// Console output held for a slow peer, bytes (about 16 `help` replies).
pub const OUTPUT_CAP: usize = 16 * 1024;

static DROPPED: AtomicU64 = AtomicU64::new(0);

/// Console output bytes dropped since start because the peer did not read (console `counters`).
pub fn output_dropped() -> u64 {
    DROPPED.load(Ordering::Relaxed)
}

/// Bounded output buffer: whole pieces are queued or dropped, never split.
#[derive(Debug)]
pub struct OutputBuffer {
    buf: VecDeque<u8>,
    cap: usize,
    /// Bytes dropped in the current stall (reported when the buffer drains).
    dropped_now: u64,
}

impl OutputBuffer {
    /// An empty buffer holding at most `cap` bytes.
    pub fn new(cap: usize) -> Self {
        Self { buf: VecDeque::with_capacity(cap.min(OUTPUT_CAP)), cap, dropped_now: 0 }
    }

    /// Queues `bytes`, or drops (and counts) them all when they do not fit. Returns whether they
    /// were queued.
    pub fn push(&mut self, bytes: &[u8]) -> bool {
        if self.buf.len() + bytes.len() > self.cap {
            self.dropped_now += bytes.len() as u64;
            DROPPED.fetch_add(bytes.len() as u64, Ordering::Relaxed);
            return false;
        }
        self.buf.extend(bytes);
        true
    }

    /// Bytes queued.
    pub fn len(&self) -> usize {
        self.buf.len()
    }

    /// Whether nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    /// Bytes dropped in the current stall (0 once reported).
    pub fn dropped_now(&self) -> u64 {
        self.dropped_now
    }

    /// Writes as much as `sink` takes without waiting: stops at `WouldBlock` or a zero-length
    /// write; other errors are returned. After a stall, once everything queued is out, a note of
    /// what was dropped follows.
    pub fn write_to(&mut self, mut sink: impl FnMut(&[u8]) -> io::Result<usize>) -> io::Result<()> {
        loop {
            if self.buf.is_empty() && self.dropped_now > 0 {
                let note = format!(
                    "\r\n[console: {} bytes of output dropped: the terminal was not reading]\r\n",
                    std::mem::take(&mut self.dropped_now)
                );
                self.buf.extend(note.as_bytes());
            }
            let (front, _) = self.buf.as_slices();
            if front.is_empty() {
                return Ok(());
            }
            match sink(front) {
                Ok(0) => return Ok(()),
                Ok(n) => {
                    self.buf.drain(..n.min(front.len()));
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return Ok(()),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }
}

/// Puts `fd` in non-blocking mode, so that writes return `WouldBlock` instead of waiting for the
/// peer (reads keep their poll timeout in `serialport`).
pub fn set_nonblocking(fd: RawFd) -> io::Result<()> {
    // SAFETY: fcntl on a descriptor the caller owns (an open serial port); no memory is passed.
    let flags = unsafe { libc::fcntl(fd, libc::F_GETFL) };
    if flags < 0 {
        return Err(io::Error::last_os_error());
    }
    // SAFETY: as above.
    if unsafe { libc::fcntl(fd, libc::F_SETFL, flags | libc::O_NONBLOCK) } < 0 {
        return Err(io::Error::last_os_error());
    }
    Ok(())
}

/// One `write(2)` on a non-blocking `fd`: never waits.
pub fn write_nonblocking(fd: RawFd, bytes: &[u8]) -> io::Result<usize> {
    // SAFETY: `bytes` is a valid slice for its length; `fd` is an open descriptor the caller owns.
    let n = unsafe { libc::write(fd, bytes.as_ptr().cast(), bytes.len()) };
    if n < 0 { Err(io::Error::last_os_error()) } else { Ok(n as usize) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_peer_that_does_not_read_loses_output_not_the_console() {
        let mut b = OutputBuffer::new(10);
        assert!(b.push(b"hello "));
        assert!(!b.push(b"world!"), "does not fit: dropped whole");
        assert!(b.push(b"ok"));
        let before = output_dropped();
        let mut stalled = |_: &[u8]| -> io::Result<usize> { Err(io::ErrorKind::WouldBlock.into()) };
        assert!(b.write_to(&mut stalled).is_ok(), "a stalled peer is not an error");
        assert_eq!(b.len(), 8);
        assert!(!b.push(b"more"));
        assert!(output_dropped() >= before + 4);
        let mut got = Vec::new();
        let mut slow = |x: &[u8]| -> io::Result<usize> {
            let n = x.len().min(3);
            got.extend_from_slice(&x[..n]);
            Ok(n)
        };
        assert!(b.write_to(&mut slow).is_ok());
        let text = String::from_utf8_lossy(&got).to_string();
        assert!(text.starts_with("hello ok\r\n[console: 10 bytes of output dropped"), "{text:?}");
        assert!(b.is_empty() && b.dropped_now() == 0);
        let mut broken = |_: &[u8]| -> io::Result<usize> { Err(io::ErrorKind::BrokenPipe.into()) };
        assert!(b.push(b"x") && b.write_to(&mut broken).is_err());
    }
}
