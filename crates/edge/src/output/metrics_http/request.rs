//! Requests and responses of the endpoint: reading a bounded request head, routing it, and the
//! complete answer (pure apart from reading the head).

use super::super::metrics::CONTENT_TYPE;
use super::MAX_HEAD;
use tokio::io::AsyncReadExt as _;

/// The answer to a request head.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// `GET /metrics` (`head`: `HEAD /metrics`, no body).
    Metrics {
        /// HEAD: headers only.
        head: bool,
    },
    /// An error status (400, 404, 405, 408, 431).
    Error(u16),
}

/// Routes a complete request head (request line first; headers are not needed). Never panics.
pub fn route(head: &[u8]) -> Route {
    let line_end = head.iter().position(|&c| c == b'\n').unwrap_or(head.len());
    let Ok(line) = std::str::from_utf8(&head[..line_end]) else { return Route::Error(400) };
    let mut parts = line.trim_end_matches('\r').split(' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Route::Error(400);
    };
    if method.is_empty() || !method.bytes().all(|c| c.is_ascii_uppercase()) || !target.starts_with('/') {
        return Route::Error(400);
    }
    if !matches!(version, "HTTP/1.0" | "HTTP/1.1") {
        return Route::Error(400);
    }
    let path = target.split_once('?').map_or(target, |(p, _)| p);
    if path != "/metrics" {
        return Route::Error(404);
    }
    match method {
        "GET" => Route::Metrics { head: false },
        "HEAD" => Route::Metrics { head: true },
        _ => Route::Error(405),
    }
}

/// The reason phrase of a status code.
fn reason(code: u16) -> &'static str {
    match code {
        200 => "OK",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        431 => "Request Header Fields Too Large",
        _ => "Bad Request",
    }
}

/// The complete response (head and, unless `head_only`, body).
pub(super) fn response(code: u16, body: &str, head_only: bool) -> Vec<u8> {
    let ctype = if code == 200 { CONTENT_TYPE } else { "text/plain; charset=utf-8" };
    let mut out = format!(
        "HTTP/1.1 {code} {}\r\nContent-Type: {ctype}\r\nContent-Length: {}\r\nConnection: close\r\nCache-Control: no-store\r\n",
        reason(code),
        body.len()
    );
    if code == 405 {
        out.push_str("Allow: GET, HEAD\r\n");
    }
    out.push_str("\r\n");
    let mut out = out.into_bytes();
    if !head_only {
        out.extend_from_slice(body.as_bytes());
    }
    out
}

/// How reading a request head ended.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Head {
    /// Complete: this many bytes (up to and including the blank line).
    Complete(usize),
    /// [`MAX_HEAD`] bytes without the blank line.
    TooLarge,
    /// The peer closed (or reset) first.
    Closed,
}

/// Where the blank line ending a head is in `buf` (searching from `from`): the byte after it.
pub(super) fn head_end(buf: &[u8], from: usize) -> Option<usize> {
    let start = from.saturating_sub(3);
    (start..buf.len()).find_map(|i| {
        if buf[i..].starts_with(b"\r\n\r\n") {
            Some(i + 4)
        } else if buf[i..].starts_with(b"\n\n") {
            Some(i + 2)
        } else {
            None
        }
    })
}

pub(super) async fn read_head<R: tokio::io::AsyncRead + Unpin>(r: &mut R, buf: &mut [u8; MAX_HEAD]) -> Head {
    let mut len = 0;
    loop {
        if len == buf.len() {
            return Head::TooLarge;
        }
        match r.read(&mut buf[len..]).await {
            Ok(0) | Err(_) => return Head::Closed,
            Ok(n) => {
                let from = len;
                len += n;
                if let Some(end) = head_end(&buf[..len], from) {
                    return Head::Complete(end);
                }
            }
        }
    }
}
