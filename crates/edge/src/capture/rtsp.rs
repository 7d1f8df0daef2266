//! An IP camera's RTSP stream as a frame source: `retina` (pure-Rust RTSP client) for the session,
//! OpenH264 (built from source) for the H.264 decoding, frames handed on as planar I420 so only the
//! frames the networks run on are converted to RGB. Frame time is the RTP clock ([`StreamClock`]).
//! Errors go back to the capture loop, which raises the camera status bit and calls
//! [`FrameSource::reopen`] with backoff, exactly as for a V4L2 camera.

use super::clock::StreamClock;
use super::credentials::read_login;
use super::{CaptureError, Frame, FrameSource, PixelFormat};
use crate::config::{RtspTransport, SourceConfig};
use fme_core::pipeline::i420_len;
use fme_core::units::Seconds;
use futures::StreamExt as _;
use openh264::formats::YUVSource as _;
use retina::client::{Credentials, Demuxed, PlayOptions, Session, SessionOptions, SetupOptions, Transport};
use retina::codec::{CodecItem, FrameFormat};
use std::path::PathBuf;
use std::pin::Pin;
use std::time::{Duration, Instant};

/// Longest wait, beyond `source.timeout_ms`, for a session's first key frame.
const KEY_FRAME_WAIT: Duration = Duration::from_secs(10);

/// An RTSP camera (`source.kind = "rtsp"`).
pub struct RtspSource {
    cfg: SourceConfig,
    /// `None` only while dropping.
    rt: Option<tokio::runtime::Runtime>,
    session: Option<Pin<Box<Demuxed>>>,
    decoder: Option<openh264::decoder::Decoder>,
    clock: StreamClock,
    seq: u64,
    /// Frames lost on the way: RTP packet loss, undecodable or out-of-order frames.
    lost: u64,
    size: Option<(u32, u32)>,
    /// Whether this session has decoded a picture yet (the first waits for a key frame).
    pictured: bool,
}

impl std::fmt::Debug for RtspSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RtspSource").field("url", &self.cfg.url).field("open", &self.session.is_some()).finish()
    }
}

impl RtspSource {
    /// A source for `cfg.url`; nothing is opened until [`FrameSource::reopen`]. Fails only when no
    /// runtime thread can be started.
    pub fn new(cfg: SourceConfig) -> Result<Self, CaptureError> {
        // One worker: retina sends TEARDOWN from a spawned task when a session is dropped.
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("fme-rtsp")
            .enable_all()
            .build()
            .map_err(|e| CaptureError::Open { path: PathBuf::from(&cfg.url), message: format!("runtime: {e}") })?;
        Ok(Self {
            cfg,
            rt: Some(rt),
            session: None,
            decoder: None,
            clock: StreamClock::default(),
            seq: 0,
            lost: 0,
            size: None,
            pictured: false,
        })
    }

    fn path(&self) -> PathBuf {
        PathBuf::from(&self.cfg.url)
    }

    fn open_err(&self, message: impl Into<String>) -> CaptureError {
        CaptureError::Open { path: self.path(), message: message.into() }
    }

    /// Drops the session inside the runtime (its TEARDOWN task needs one).
    fn close(&mut self) {
        if let Some(rt) = &self.rt {
            let _g = rt.enter();
            self.session = None;
        }
    }

    /// Runs `f` to completion on the source's runtime, with a timeout. The capture thread is no
    /// runtime's; a caller inside one (`fme run` opens the source in its async main) blocks on a
    /// scoped thread instead, as a runtime cannot block inside another.
    fn block_on<F>(rt: &Option<tokio::runtime::Runtime>, timeout: Duration, f: F) -> Option<F::Output>
    where
        F: std::future::Future + Send,
        F::Output: Send,
    {
        let rt = rt.as_ref()?;
        let run = || rt.block_on(async { tokio::time::timeout(timeout, f).await.ok() });
        if tokio::runtime::Handle::try_current().is_err() {
            return run();
        }
        std::thread::scope(|s| s.spawn(run).join()).unwrap_or_else(|p| std::panic::resume_unwind(p))
    }

    async fn connect(cfg: &SourceConfig) -> Result<Demuxed, String> {
        let url = url::Url::parse(&cfg.url).map_err(|e| format!("source.url: {e}"))?;
        let login = read_login(&cfg.credentials_file)?;
        let user = login.as_ref().map(|l| l.user.clone());
        let err = |e: retina::Error| login_error(&e, user.as_deref());
        let creds = login.map(|l| Credentials { username: l.user, password: l.password });
        let opts = SessionOptions::default().creds(creds).user_agent("fme".into());
        let mut session = Session::describe(url, opts).await.map_err(err)?;
        let stream = pick_h264(session.streams())?;
        let transport = match cfg.transport {
            RtspTransport::Tcp => Transport::Tcp(Default::default()),
            RtspTransport::Udp => Transport::Udp(Default::default()),
        };
        let setup = SetupOptions::default().transport(transport).frame_format(FrameFormat::SIMPLE);
        session.setup(stream, setup).await.map_err(err)?;
        let playing = session.play(PlayOptions::default()).await.map_err(err)?;
        playing.demuxed().map_err(err)
    }

    /// Decodes one access unit; `Some` when it completed a picture, written into `buf` as I420.
    fn decode(&mut self, au: &[u8], buf: &mut Vec<u8>) -> Result<Option<(u32, u32)>, String> {
        let Some(dec) = self.decoder.as_mut() else { return Err("no decoder".into()) };
        let Some(yuv) = dec.decode(au).map_err(|e| format!("H.264 decoding: {e}"))? else {
            return Ok(None);
        };
        let (w, h) = yuv.dimensions();
        let (ys, us, vs) = yuv.strides();
        let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
        buf.clear();
        buf.reserve(i420_len(w, h));
        for r in 0..h {
            buf.extend_from_slice(&yuv.y()[r * ys..][..w]);
        }
        for (plane, stride) in [(yuv.u(), us), (yuv.v(), vs)] {
            for r in 0..ch {
                buf.extend_from_slice(&plane[r * stride..][..cw]);
            }
        }
        Ok(Some((w as u32, h as u32)))
    }
}

/// The first H.264 video stream; any other video codec is an error naming it and what to set.
fn pick_h264(streams: &[retina::client::Stream]) -> Result<usize, String> {
    let video = || streams.iter().enumerate().filter(|(_, s)| s.media() == "video");
    if let Some((i, _)) = video().find(|(_, s)| s.encoding_name().eq_ignore_ascii_case("h264")) {
        return Ok(i);
    }
    match video().next() {
        Some((_, s)) => Err(format!(
            "the camera sends {} video; fme decodes H.264 only: set the stream's video encoding to H.264 \
             in the camera's settings (often Video > Encoding, for the sub-stream)",
            s.encoding_name().to_ascii_uppercase()
        )),
        None => Err("the camera's stream has no video".into()),
    }
}

/// [`rtsp_error`], with a refused login named by its user (never its password): a camera with
/// several accounts is fixed by knowing which one was tried.
fn login_error(e: &retina::Error, user: Option<&str>) -> String {
    if e.status_code() != Some(401) {
        return rtsp_error(e);
    }
    let first = e.to_string().lines().next().unwrap_or_default().to_string();
    match user {
        Some(u) => format!(
            "the camera refused the login of user {u:?} (401 Unauthorized): check the user and password in \
             source.credentials_file ({first})"
        ),
        None => format!(
            "the camera asks for a login (401 Unauthorized) and none is set: put user:password in a file \
             named by source.credentials_file ({first})"
        ),
    }
}

/// One line for a retina error, with what to check for the statuses a wrong config gives.
fn rtsp_error(e: &retina::Error) -> String {
    let first = e.to_string().lines().next().unwrap_or_default().to_string();
    match e.status_code() {
        Some(401) => format!("wrong user or password (401 Unauthorized): check source.credentials_file ({first})"),
        Some(403) => format!("access refused (403 Forbidden): check the camera's user rights ({first})"),
        Some(404) => format!("no stream at this path (404 Not Found): check source.url's path ({first})"),
        _ => first,
    }
}

impl FrameSource for RtspSource {
    fn next_frame(&mut self, mut buf: Vec<u8>) -> Result<Frame, CaptureError> {
        let timeout = Duration::from_millis(self.cfg.timeout_ms);
        // Packets that never make a picture (an undecodable stream) stall the camera like silence;
        // a session's first picture may wait for the camera's next key frame (GOPs of several s).
        let wait = if self.pictured { timeout } else { timeout + KEY_FRAME_WAIT };
        let deadline = Instant::now() + wait;
        loop {
            if Instant::now() > deadline {
                self.close();
                let message = format!("no H.264 picture decoded within {} ms", wait.as_millis());
                return Err(CaptureError::Read { path: self.path(), message });
            }
            let Some(session) = self.session.as_mut() else {
                return Err(CaptureError::Read { path: self.path(), message: "stream not open".into() });
            };
            let item = match Self::block_on(&self.rt, timeout, session.next()) {
                Some(Some(Ok(item))) => item,
                Some(Some(Err(e))) => {
                    self.close();
                    return Err(CaptureError::Read { path: self.path(), message: rtsp_error(&e) });
                }
                Some(None) => {
                    self.close();
                    return Err(CaptureError::Read {
                        path: self.path(),
                        message: "the camera ended the stream".into(),
                    });
                }
                None => {
                    self.close();
                    return Err(CaptureError::Timeout { path: self.path(), timeout_ms: self.cfg.timeout_ms });
                }
            };
            let CodecItem::VideoFrame(vf) = item else { continue };
            self.lost += u64::from(vf.loss());
            let stream_s = vf.timestamp().elapsed_secs();
            let arrived = Instant::now();
            let size = match self.decode(vf.data(), &mut buf) {
                Ok(Some(size)) => size,
                Ok(None) => continue,
                Err(e) => {
                    self.lost += 1;
                    if self.lost == 1 || self.lost.is_multiple_of(100) {
                        tracing::warn!(camera = %self.cfg.url, "frame lost ({} so far): {e}", self.lost);
                    }
                    continue;
                }
            };
            let Some(t) = self.clock.time(stream_s, arrived) else {
                self.lost += 1;
                continue;
            };
            self.size = Some(size);
            self.pictured = true;
            let frame = Frame {
                seq: self.seq,
                timestamp: Seconds(t),
                arrived,
                width: size.0,
                height: size.1,
                format: PixelFormat::I420,
                data: buf,
            };
            self.seq += 1;
            return Ok(frame);
        }
    }

    fn reopen(&mut self) -> Result<(), CaptureError> {
        self.close();
        self.clock.restart();
        let timeout = Duration::from_millis(self.cfg.timeout_ms);
        let demuxed = match Self::block_on(&self.rt, timeout, Self::connect(&self.cfg)) {
            Some(Ok(d)) => d,
            Some(Err(m)) => return Err(self.open_err(m)),
            None => {
                return Err(self.open_err(format!(
                    "no answer to DESCRIBE/SETUP/PLAY within {} ms (source.timeout_ms)",
                    self.cfg.timeout_ms
                )));
            }
        };
        // A fresh decoder per session: the new stream starts at its own key frame.
        self.decoder =
            Some(openh264::decoder::Decoder::new().map_err(|e| self.open_err(format!("H.264 decoder: {e}")))?);
        self.session = Some(Box::pin(demuxed));
        self.pictured = false;
        Ok(())
    }

    fn source_dropped(&self) -> u64 {
        self.lost
    }

    fn describe(&self) -> String {
        let transport = match self.cfg.transport {
            RtspTransport::Tcp => "tcp",
            RtspTransport::Udp => "udp",
        };
        match (&self.session, self.size) {
            (Some(_), Some((w, h))) => format!("rtsp camera {} ({transport}, H.264 {w}x{h})", self.cfg.url),
            (Some(_), None) => format!("rtsp camera {} ({transport}, H.264)", self.cfg.url),
            (None, _) => format!("rtsp camera {} (closed)", self.cfg.url),
        }
    }
}

impl Drop for RtspSource {
    fn drop(&mut self) {
        self.close();
        // A runtime cannot be dropped (it blocks) inside another one's context.
        if let Some(rt) = self.rt.take()
            && tokio::runtime::Handle::try_current().is_ok()
        {
            rt.shutdown_background();
        }
    }
}
