//! One connection: the first request head read and checked by the server ([`super::request`]:
//! 408 for a slowloris head, 431 for an oversized one, 400 for garbage, each answered and closed
//! without reaching hyper), then hyper's HTTP/1.1 serving the router. Kept alive on the web
//! listener (a browser polls), one request per connection on the metrics listener.

use super::admission::Slot;
use super::io::Stream;
use super::request::{Head, read_head, request_line_ok, response};
use super::{Kind, MAX_HEAD, WRITE_TIMEOUT, WebState};
use hyper_util::rt::{TokioIo, TokioTimer};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _};
use tower::ServiceExt as _;

/// A kept-alive connection with no request for this long is closed.
const IDLE_LIMIT: Duration = Duration::from_secs(30);

/// What every connection of one listener shares.
#[derive(Debug)]
pub(super) struct ConnCtx {
    /// Which listener.
    pub kind: Kind,
    /// The box's state the routes read.
    pub state: Arc<WebState>,
    /// The routes (with their limits as layers).
    pub router: axum::Router,
    /// Time to send a complete request head (and, with TLS, as long again for the handshake).
    pub header_timeout: Duration,
    /// `[web] tls_cert`/`tls_key`: TLS on this listener.
    pub tls: Option<Arc<rustls::ServerConfig>>,
}

impl ConnCtx {
    fn note(&self, code: u16) {
        if self.kind == Kind::Metrics {
            self.state.shared.metrics.note_response(code);
        }
    }
}

/// Serves one admitted connection (after the TLS handshake when the listener has TLS); `slot`
/// gives its place back when it ends.
pub(super) async fn serve_connection(stream: tokio::net::TcpStream, ctx: Arc<ConnCtx>, slot: Slot) {
    let Some(server) = ctx.tls.clone() else {
        return serve_stream(stream, ctx, slot).await;
    };
    match super::tls::handshake(&server, stream, ctx.header_timeout).await {
        super::tls::Start::Tls(s) => serve_stream(*s, ctx, slot).await,
        super::tls::Start::Plain(s) => {
            slot.head_done();
            refuse(s, 400, "this port speaks HTTPS: use https://\n").await;
        }
        super::tls::Start::Gone => {}
    }
}

/// Serves one connection's byte stream: the first head checked here, then hyper.
async fn serve_stream<S>(mut stream: S, ctx: Arc<ConnCtx>, slot: Slot)
where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let mut buf = Box::new([0u8; MAX_HEAD]);
    let mut len = 0;
    let head = tokio::time::timeout(ctx.header_timeout, read_head(&mut stream, &mut buf, &mut len)).await;
    slot.head_done();
    let code = match head {
        Ok(Head::Complete(end)) if request_line_ok(&buf[..end]) => 0,
        Ok(Head::Complete(_)) => 400,
        Ok(Head::TooLarge) => 431,
        Ok(Head::Closed) => {
            if ctx.kind == Kind::Metrics {
                ctx.state.shared.metrics.aborted.fetch_add(1, Ordering::Relaxed);
            }
            return;
        }
        Err(_) => 408,
    };
    if code != 0 {
        ctx.note(code);
        let body = match code {
            408 => "request timeout\n",
            431 => "request head too large\n",
            _ => "bad request\n",
        };
        refuse(stream, code, body).await;
        return;
    }
    let slot = Arc::new(slot);
    let (c, s) = (ctx.clone(), slot.clone());
    let svc = hyper::service::service_fn(move |req: hyper::Request<hyper::body::Incoming>| {
        let (ctx, slot) = (c.clone(), s.clone());
        async move {
            let resp = ctx.router.clone().oneshot(req).await;
            if let Ok(r) = &resp {
                ctx.note(r.status().as_u16());
                if r.status().is_success() {
                    slot.answered();
                }
            }
            resp
        }
    });
    let io = TokioIo::new(Stream::new(buf[..len].to_vec(), stream, WRITE_TIMEOUT, IDLE_LIMIT));
    let mut http = hyper::server::conn::http1::Builder::new();
    http.keep_alive(ctx.kind == Kind::Web)
        .title_case_headers(true)
        .timer(TokioTimer::new())
        .header_read_timeout(ctx.header_timeout)
        .max_buf_size(MAX_HEAD);
    if let Err(e) = http.serve_connection(io, svc).await
        && e.is_parse()
    {
        ctx.note(if e.is_parse_too_large() { 431 } else { 400 });
    }
}

/// Writes the error answer `code` and closes, reading a little of what the peer still sends so
/// that closing does not reset the connection before the peer has read the answer.
async fn refuse<S: AsyncRead + AsyncWrite + Unpin>(mut stream: S, code: u16, body: &str) {
    let written = tokio::time::timeout(WRITE_TIMEOUT, async {
        stream.write_all(&response(code, body)).await?;
        stream.shutdown().await
    })
    .await;
    if !matches!(written, Ok(Ok(()))) {
        return;
    }
    let mut sink = [0u8; 1024];
    let _ = tokio::time::timeout(Duration::from_millis(200), async {
        let mut left = 64 * 1024usize;
        while left > 0 {
            match stream.read(&mut sink).await {
                Ok(0) | Err(_) => break,
                Ok(n) => left = left.saturating_sub(n),
            }
        }
    })
    .await;
}
