//! An HTTP camera serving `multipart/x-mixed-replace` JPEGs (MJPEG over HTTP) as a frame source:
//! one plain-HTTP GET on a blocking socket (the capture thread is a thread of its own), each part
//! a JPEG frame handed on encoded, as a V4L2 MJPEG camera's. Frame time is the arrival time, or the
//! part's `X-Timestamp` header (seconds) where the camera sends one.

use super::clock::StreamClock;
use super::credentials::{basic_auth, read_login};
use super::{CaptureError, Frame, FrameSource, PixelFormat};
use crate::config::SourceConfig;
use fme_core::units::Seconds;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// A part larger than this is not a camera frame: the stream is dropped and reopened.
const MAX_PART_BYTES: usize = 32 << 20;

/// An MJPEG-over-HTTP camera (`source.kind = "mjpeg"`).
#[derive(Debug)]
pub struct MjpegSource {
    cfg: SourceConfig,
    conn: Option<BufReader<TcpStream>>,
    /// The part delimiter line, `--boundary`.
    delimiter: Vec<u8>,
    /// Whether the next part's delimiter line was already read (end of a part without a length).
    at_part: bool,
    epoch: Instant,
    clock: StreamClock,
    seq: u64,
    lost: u64,
    line: Vec<u8>,
}

impl MjpegSource {
    /// A source for `cfg.url`; nothing is opened until [`FrameSource::reopen`].
    pub fn new(cfg: SourceConfig) -> Self {
        Self {
            cfg,
            conn: None,
            delimiter: Vec::new(),
            at_part: false,
            epoch: Instant::now(),
            clock: StreamClock::default(),
            seq: 0,
            lost: 0,
            line: Vec::new(),
        }
    }

    fn path(&self) -> PathBuf {
        PathBuf::from(&self.cfg.url)
    }

    fn read_err(&mut self, message: impl Into<String>) -> CaptureError {
        self.conn = None;
        CaptureError::Read { path: self.path(), message: message.into() }
    }

    fn connect(&self) -> Result<(BufReader<TcpStream>, Vec<u8>), String> {
        let rest = self.cfg.url.strip_prefix("http://").ok_or("source.url must start with http://")?;
        let (authority, path) = rest.split_once('/').map_or((rest, "/".to_string()), |(a, p)| (a, format!("/{p}")));
        let hostport = if authority.contains(':') && !authority.ends_with(']') {
            authority.to_string()
        } else {
            format!("{authority}:80")
        };
        let timeout = Duration::from_millis(self.cfg.timeout_ms);
        let addr = hostport.to_socket_addrs().map_err(|e| format!("{hostport}: {e}"))?.next();
        let addr = addr.ok_or_else(|| format!("{hostport}: no address"))?;
        let stream = TcpStream::connect_timeout(&addr, timeout).map_err(|e| format!("connect {addr}: {e}"))?;
        stream.set_read_timeout(Some(timeout)).map_err(|e| e.to_string())?;
        stream.set_write_timeout(Some(timeout)).map_err(|e| e.to_string())?;
        let mut req = format!("GET {path} HTTP/1.1\r\nHost: {authority}\r\nUser-Agent: fme\r\nAccept: */*\r\n");
        if let Some(login) = read_login(&self.cfg.credentials_file)? {
            req.push_str(&format!("Authorization: {}\r\n", basic_auth(&login)));
        }
        req.push_str("\r\n");
        let mut conn = BufReader::new(stream);
        conn.get_mut().write_all(req.as_bytes()).map_err(|e| format!("sending the request: {e}"))?;
        let head = read_head(&mut conn)?;
        let status = head.first().and_then(|l| l.split_whitespace().nth(1)).unwrap_or_default().to_string();
        match status.as_str() {
            "200" => {}
            "401" => return Err("wrong user or password (HTTP 401): check source.credentials_file".into()),
            "404" => return Err("no stream at this path (HTTP 404): check source.url's path".into()),
            _ => return Err(format!("HTTP answer {:?}", head.first().map(String::as_str).unwrap_or(""))),
        }
        let ctype = header(&head, "content-type").unwrap_or_default();
        if !ctype.to_ascii_lowercase().starts_with("multipart/") {
            return Err(format!("Content-Type is {ctype:?}, not multipart/x-mixed-replace (an MJPEG stream)"));
        }
        let boundary = ctype
            .split(';')
            .filter_map(|p| p.trim().strip_prefix("boundary="))
            .next()
            .map(|b| b.trim_matches('"'))
            .filter(|b| !b.is_empty())
            .ok_or_else(|| format!("Content-Type {ctype:?} names no boundary"))?;
        let delimiter = if boundary.starts_with("--") { boundary.to_string() } else { format!("--{boundary}") };
        Ok((conn, delimiter.into_bytes()))
    }

    /// One raw line (with its line end) into `self.line`.
    fn read_line(&mut self) -> Result<(), CaptureError> {
        self.line.clear();
        let Some(conn) = self.conn.as_mut() else { return Err(self.read_err("stream not open")) };
        let limit = (MAX_PART_BYTES + 2) as u64;
        match conn.by_ref().take(limit).read_until(b'\n', &mut self.line) {
            Ok(0) => Err(self.read_err("the camera closed the connection")),
            Ok(_) => Ok(()),
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {
                self.conn = None;
                Err(CaptureError::Timeout { path: self.path(), timeout_ms: self.cfg.timeout_ms })
            }
            Err(e) => Err(self.read_err(e.to_string())),
        }
    }

    /// The last line read without its LF or CR LF.
    fn text(&self) -> &[u8] {
        let l = self.line.strip_suffix(b"\n").unwrap_or(&self.line);
        l.strip_suffix(b"\r").unwrap_or(l)
    }

    /// Reads one part into `data`; returns its `X-Timestamp` (seconds) if it has one.
    fn read_part(&mut self, data: &mut Vec<u8>) -> Result<Option<f64>, CaptureError> {
        while !self.at_part {
            self.read_line()?;
            self.at_part = self.text() == self.delimiter.as_slice();
        }
        self.at_part = false;
        let (mut length, mut stamp) = (None, None);
        loop {
            self.read_line()?;
            if self.text().is_empty() {
                break;
            }
            let text = String::from_utf8_lossy(self.text()).to_string();
            if let Some((k, v)) = text.split_once(':') {
                match k.trim().to_ascii_lowercase().as_str() {
                    "content-length" => length = v.trim().parse::<usize>().ok(),
                    "x-timestamp" => stamp = v.trim().parse::<f64>().ok().filter(|s| s.is_finite()),
                    _ => {}
                }
            }
        }
        data.clear();
        match length {
            Some(n) if n > MAX_PART_BYTES => Err(self.read_err(format!("a part of {n} bytes is too large"))),
            Some(n) => {
                data.resize(n, 0);
                let Some(conn) = self.conn.as_mut() else { return Err(self.read_err("stream not open")) };
                if let Err(e) = conn.read_exact(data) {
                    return Err(self.read_err(format!("reading a {n}-byte part: {e}")));
                }
                Ok(stamp)
            }
            // No length: the part runs to the next delimiter line (the CR LF before it is not part of it).
            None => loop {
                self.read_line()?;
                if self.text() == self.delimiter.as_slice() {
                    self.at_part = true;
                    if data.ends_with(b"\r\n") {
                        data.truncate(data.len() - 2);
                    } else if data.ends_with(b"\n") {
                        data.pop();
                    }
                    return Ok(stamp);
                }
                if data.len() + self.line.len() > MAX_PART_BYTES {
                    return Err(self.read_err("a part without Content-Length runs past 32 MiB"));
                }
                data.extend_from_slice(&self.line);
            },
        }
    }
}

/// The status line and header lines of an HTTP answer, up to the blank line.
fn read_head(conn: &mut BufReader<TcpStream>) -> Result<Vec<String>, String> {
    let mut lines = Vec::new();
    loop {
        let mut line = String::new();
        let n = conn.by_ref().take(8192).read_line(&mut line).map_err(|e| format!("reading the answer: {e}"))?;
        let line = line.trim_end().to_string();
        if n == 0 || line.is_empty() {
            return if lines.is_empty() { Err("the camera closed without an HTTP answer".into()) } else { Ok(lines) };
        }
        if lines.len() > 100 {
            return Err("HTTP answer with more than 100 header lines".into());
        }
        lines.push(line);
    }
}

fn header(head: &[String], name: &str) -> Option<String> {
    head.iter().skip(1).find_map(|l| {
        let (k, v) = l.split_once(':')?;
        k.trim().eq_ignore_ascii_case(name).then(|| v.trim().to_string())
    })
}

impl FrameSource for MjpegSource {
    fn next_frame(&mut self, mut data: Vec<u8>) -> Result<Frame, CaptureError> {
        loop {
            let stamp = self.read_part(&mut data)?;
            let arrived = Instant::now();
            let stream_s = stamp.unwrap_or_else(|| arrived.duration_since(self.epoch).as_secs_f64());
            let Some(t) = self.clock.time(stream_s, arrived) else {
                self.lost += 1;
                continue;
            };
            let mut frame = Frame {
                seq: self.seq,
                timestamp: Seconds(t),
                arrived,
                width: self.cfg.width,
                height: self.cfg.height,
                format: PixelFormat::Jpeg,
                data,
            };
            // The size from the header when it reads; a broken JPEG goes on to be counted as a bad frame.
            if let Ok((w, h)) = frame.encoded_dimensions() {
                (frame.width, frame.height) = (w, h);
            }
            self.seq += 1;
            return Ok(frame);
        }
    }

    fn reopen(&mut self) -> Result<(), CaptureError> {
        self.conn = None;
        self.at_part = false;
        self.clock.restart();
        let (conn, delimiter) = self.connect().map_err(|message| CaptureError::Open { path: self.path(), message })?;
        self.conn = Some(conn);
        self.delimiter = delimiter;
        Ok(())
    }

    fn source_dropped(&self) -> u64 {
        self.lost
    }

    fn describe(&self) -> String {
        let state = if self.conn.is_some() { "MJPEG over HTTP" } else { "closed" };
        format!("mjpeg camera {} ({state})", self.cfg.url)
    }
}
