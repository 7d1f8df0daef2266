//! The connection's byte stream (a socket, or TLS over it) as hyper sees it: the bytes the server already read (the first
//! request head, [`super::request`]) replayed first, then the socket; a write that makes no
//! progress for [`super::WRITE_TIMEOUT`] (a peer that does not read) and a read that waits longer
//! than the idle limit (a kept-alive connection nobody uses) end the connection.

use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::Sleep;

/// A socket with bytes read ahead and stall limits.
pub(super) struct Stream<S> {
    ahead: Vec<u8>,
    pos: usize,
    inner: S,
    write_limit: Duration,
    read_limit: Duration,
    write_stall: Option<Pin<Box<Sleep>>>,
    read_stall: Option<Pin<Box<Sleep>>>,
}

impl<S> Stream<S> {
    /// `ahead` is served before anything read from `inner`.
    pub(super) fn new(ahead: Vec<u8>, inner: S, write_limit: Duration, read_limit: Duration) -> Self {
        Self { ahead, pos: 0, inner, write_limit, read_limit, write_stall: None, read_stall: None }
    }
}

/// `Pending` until `stall` (started at the first `Pending`) passes; then a time-out error.
fn stalled(stall: &mut Option<Pin<Box<Sleep>>>, limit: Duration, cx: &mut Context<'_>) -> io::Result<()> {
    let sleep = stall.get_or_insert_with(|| Box::pin(tokio::time::sleep(limit)));
    match sleep.as_mut().poll(cx) {
        Poll::Ready(()) => Err(io::Error::new(io::ErrorKind::TimedOut, "peer stalled")),
        Poll::Pending => Ok(()),
    }
}

use std::future::Future as _;

impl<S: AsyncRead + Unpin> AsyncRead for Stream<S> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let me = &mut *self;
        if me.pos < me.ahead.len() {
            let n = (me.ahead.len() - me.pos).min(buf.remaining());
            buf.put_slice(&me.ahead[me.pos..me.pos + n]);
            me.pos += n;
            if me.pos == me.ahead.len() {
                me.ahead = Vec::new();
                me.pos = 0;
            }
            return Poll::Ready(Ok(()));
        }
        match Pin::new(&mut me.inner).poll_read(cx, buf) {
            Poll::Pending => match stalled(&mut me.read_stall, me.read_limit, cx) {
                Ok(()) => Poll::Pending,
                Err(e) => Poll::Ready(Err(e)),
            },
            ready => {
                me.read_stall = None;
                ready
            }
        }
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Stream<S> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        let me = &mut *self;
        match Pin::new(&mut me.inner).poll_write(cx, buf) {
            Poll::Pending => match stalled(&mut me.write_stall, me.write_limit, cx) {
                Ok(()) => Poll::Pending,
                Err(e) => Poll::Ready(Err(e)),
            },
            ready => {
                me.write_stall = None;
                ready
            }
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}
