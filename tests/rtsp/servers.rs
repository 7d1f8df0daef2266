//! The servers of tests/rtsp.rs, all on loopback: GStreamer's RTSP server (started and killed
//! here), a TCP listener that never answers or refuses every login, and an MJPEG HTTP camera.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

/// Debian's Python, where `python3-gi` installs (a pyenv `python3` earlier on PATH lacks it).
const PYTHON: &str = "/usr/bin/python3";

/// tests/rtsp_server.py: the bundled recording as H.264 on `/h264` (and H.265 on `/h265`), and
/// `/stall`, which answers but sends no picture.
pub struct GstServer {
    child: Child,
    pub port: u16,
    pub has_h265: bool,
}

impl GstServer {
    /// Starts the server on `port` (0: a free one) and waits until it listens.
    pub fn start(port: u16) -> Self {
        Self::start_with(port, &[])
    }

    /// [`GstServer::start`] with more options of tests/rtsp_server.py (`--auth digest --login u:p`).
    pub fn start_with(port: u16, options: &[&str]) -> Self {
        let probe = "import gi; gi.require_version('GstRtspServer', '1.0'); \
                     from gi.repository import Gst, GstRtspServer; Gst.init(None); \
                     assert Gst.ElementFactory.find('x264enc'); \
                     print('h265' if Gst.ElementFactory.find('x265enc') else 'h264')";
        let out = Command::new(PYTHON).args(["-c", probe]).stderr(Stdio::null()).output();
        let Some(out) = out.ok().filter(|o| o.status.success()) else {
            panic!(
                "GStreamer's RTSP server is not installed ({PYTHON} with python3-gi, gir1.2-gst-rtsp-server-1.0, \
                 x264enc from gstreamer1.0-plugins-ugly): run `make setup`, which installs it"
            );
        };
        let has_h265 = String::from_utf8_lossy(&out.stdout).contains("h265");
        let mut child = Command::new(PYTHON)
            .args(["tests/rtsp_server.py", "tests/data/swarm20/img1", "30", &port.to_string()])
            .args(options)
            .stdout(Stdio::piped())
            .spawn()
            .expect("start tests/rtsp_server.py");
        let stdout = child.stdout.take().expect("stdout");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(stdout).read_line(&mut line);
            let _ = tx.send(line);
        });
        let line = rx.recv_timeout(Duration::from_secs(20)).unwrap_or_default();
        let Some(port) = line.trim().strip_prefix("port ").and_then(|p| p.parse().ok()) else {
            let _ = child.kill();
            panic!("tests/rtsp_server.py did not start: {line:?}");
        };
        Self { child, port, has_h265 }
    }

    pub fn url(&self, path: &str) -> String {
        format!("rtsp://127.0.0.1:{}{path}", self.port)
    }
}

impl Drop for GstServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Reads one request head (up to the blank line); `None` when the peer closed.
fn read_head(r: &mut BufReader<TcpStream>) -> Option<Vec<String>> {
    let mut lines = Vec::new();
    loop {
        let mut l = String::new();
        if r.read_line(&mut l).ok()? == 0 {
            return None;
        }
        let l = l.trim_end().to_string();
        if l.is_empty() {
            return Some(lines);
        }
        lines.push(l);
    }
}

/// A TCP listener that holds every connection open and never answers (`refuse_login`: answers
/// every RTSP request with 401, as a camera does to a wrong password). Counts the connections.
pub struct SilentListener {
    port: u16,
    count: Arc<AtomicUsize>,
}

impl SilentListener {
    pub fn start(refuse_login: bool) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("addr").port();
        let count = Arc::new(AtomicUsize::new(0));
        let c = count.clone();
        std::thread::spawn(move || {
            for conn in listener.incoming().flatten() {
                c.fetch_add(1, Ordering::SeqCst);
                std::thread::spawn(move || {
                    let mut r = BufReader::new(conn);
                    while let Some(head) = read_head(&mut r) {
                        if !refuse_login {
                            continue; // swallow, never answer
                        }
                        let cseq = head.iter().find_map(|l| l.strip_prefix("CSeq:")).unwrap_or(" 1").trim().to_string();
                        let answer = format!(
                            "RTSP/1.0 401 Unauthorized\r\nCSeq: {cseq}\r\nWWW-Authenticate: Basic realm=\"cam\"\r\n\r\n"
                        );
                        if r.get_mut().write_all(answer.as_bytes()).is_err() {
                            return;
                        }
                    }
                });
            }
        });
        Self { port, count }
    }

    pub fn url(&self) -> String {
        format!("rtsp://127.0.0.1:{}/stream", self.port)
    }

    pub fn connections(&self) -> usize {
        self.count.load(Ordering::SeqCst)
    }
}

/// An MJPEG HTTP camera: each GET gets `frames` as `multipart/x-mixed-replace` parts (the last
/// one without Content-Length), with X-Timestamp 100.0, 100.1, ..., then the connection closes.
/// With `login`, a request without its Basic authorization gets 401.
pub struct MjpegCamera {
    port: u16,
}

impl MjpegCamera {
    pub fn start(frames: Vec<Vec<u8>>, login: Option<&str>) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let port = listener.local_addr().expect("addr").port();
        let want = login.and_then(|l| l.split_once(':')).map(|(user, password)| {
            let login = fme::capture::Login { user: user.into(), password: password.into() };
            format!("Authorization: {}", fme::capture::basic_auth(&login))
        });
        std::thread::spawn(move || {
            for conn in listener.incoming().flatten() {
                let mut r = BufReader::new(conn);
                let Some(head) = read_head(&mut r) else { continue };
                let mut w = r.into_inner();
                if want.as_ref().is_some_and(|a| !head.iter().any(|l| l == a)) {
                    let _ = w.write_all(b"HTTP/1.0 401 Unauthorized\r\nWWW-Authenticate: Basic realm=\"cam\"\r\n\r\n");
                    continue;
                }
                let _ = serve_parts(&mut w, &frames);
            }
        });
        Self { port }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://127.0.0.1:{}{path}", self.port)
    }
}

fn serve_parts(w: &mut TcpStream, frames: &[Vec<u8>]) -> std::io::Result<()> {
    w.write_all(b"HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=\"frame\"\r\n\r\n")?;
    for (k, jpeg) in frames.iter().enumerate() {
        let length = if k + 1 < frames.len() { format!("Content-Length: {}\r\n", jpeg.len()) } else { String::new() };
        let head = format!(
            "--frame\r\nContent-Type: image/jpeg\r\n{length}X-Timestamp: {:.1}\r\n\r\n",
            100.0 + 0.1 * k as f64
        );
        w.write_all(head.as_bytes())?;
        w.write_all(jpeg)?;
        w.write_all(b"\r\n")?;
    }
    w.write_all(b"--frame\r\n")?;
    w.flush()?;
    // Drain what the client may still send, then close.
    let _ = w.set_read_timeout(Some(Duration::from_millis(50)));
    let _ = w.read(&mut [0u8; 64]);
    Ok(())
}
