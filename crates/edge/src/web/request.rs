//! The first request head of a connection, read by the server itself before hyper parses it: a
//! bounded read (431 past [`MAX_HEAD`]) within the head timeout (408), and a strict request line
//! (400 otherwise), so a slow or garbage client is answered and closed without reaching hyper.

use super::MAX_HEAD;
use tokio::io::AsyncReadExt as _;

/// Whether a complete head's request line is `METHOD /target HTTP/1.x` (method in capitals, one
/// space between the parts, valid UTF-8). Never panics.
pub fn request_line_ok(head: &[u8]) -> bool {
    let line_end = head.iter().position(|&c| c == b'\n').unwrap_or(head.len());
    let Ok(line) = std::str::from_utf8(&head[..line_end]) else { return false };
    let mut parts = line.trim_end_matches('\r').split(' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return false;
    };
    !method.is_empty()
        && method.bytes().all(|c| c.is_ascii_uppercase())
        && target.starts_with('/')
        && matches!(version, "HTTP/1.0" | "HTTP/1.1")
}

/// The reason phrase of an error status the server writes itself.
fn reason(code: u16) -> &'static str {
    match code {
        408 => "Request Timeout",
        431 => "Request Header Fields Too Large",
        _ => "Bad Request",
    }
}

/// A complete error response the server writes itself (`Connection: close`).
pub(super) fn response(code: u16, body: &str) -> Vec<u8> {
    format!(
        "HTTP/1.1 {code} {}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\nCache-Control: no-store\r\n\r\n{body}",
        reason(code),
        body.len()
    )
    .into_bytes()
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

/// Reads into `buf` until a head is complete; `len` is the number of bytes read (a body may follow
/// the head in them).
pub(super) async fn read_head<R: tokio::io::AsyncRead + Unpin>(
    r: &mut R,
    buf: &mut [u8; MAX_HEAD],
    len: &mut usize,
) -> Head {
    *len = 0;
    loop {
        if *len == buf.len() {
            return Head::TooLarge;
        }
        match r.read(&mut buf[*len..]).await {
            Ok(0) | Err(_) => return Head::Closed,
            Ok(n) => {
                let from = *len;
                *len += n;
                if let Some(end) = head_end(&buf[..*len], from) {
                    return Head::Complete(end);
                }
            }
        }
    }
}
