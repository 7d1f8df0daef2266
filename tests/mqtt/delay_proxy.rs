//! A slow link on loopback: a TCP proxy that delays every byte (and the close) by a fixed time in
//! each direction, like a cage on 4G or satellite (350 ms each way = 700 ms round trip), and counts
//! the connections it accepts. Each direction is a delay line: bytes are stamped when read and
//! written once their time is due, so the link keeps its throughput and only adds latency.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};
use tokio::net::{TcpListener, TcpStream};
use tokio::time::Instant;

/// The proxy: listens on `port` (loopback) and forwards to the upstream port; stops on drop.
pub struct DelayProxy {
    pub port: u16,
    accepts: Arc<AtomicUsize>,
    task: tokio::task::JoinHandle<()>,
}

impl DelayProxy {
    /// A proxy to `127.0.0.1:upstream` adding `one_way` in each direction. While nothing listens
    /// upstream, it accepts and closes each connection after `one_way` (what a box sees when the
    /// broker behind a slow link is down).
    pub async fn start(upstream: u16, one_way: Duration) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind the proxy");
        let port = listener.local_addr().expect("proxy addr").port();
        let accepts = Arc::new(AtomicUsize::new(0));
        let counter = accepts.clone();
        let task = tokio::spawn(async move {
            while let Ok((client, _)) = listener.accept().await {
                counter.fetch_add(1, Ordering::SeqCst);
                tokio::spawn(relay(client, upstream, one_way));
            }
        });
        Self { port, accepts, task }
    }

    /// TCP connections accepted so far.
    pub fn accepts(&self) -> usize {
        self.accepts.load(Ordering::SeqCst)
    }
}

impl Drop for DelayProxy {
    fn drop(&mut self) {
        self.task.abort();
    }
}

async fn relay(client: TcpStream, upstream: u16, one_way: Duration) {
    let _ = client.set_nodelay(true);
    let Ok(server) = TcpStream::connect(("127.0.0.1", upstream)).await else {
        tokio::time::sleep(one_way).await;
        return; // dropping `client` closes it
    };
    let _ = server.set_nodelay(true);
    let (cr, cw) = client.into_split();
    let (sr, sw) = server.into_split();
    tokio::join!(delay_line(cr, sw, one_way), delay_line(sr, cw, one_way));
}

/// Copies `from` to `to`, each chunk (and the end of the stream) `delay` after it was read.
async fn delay_line(mut from: OwnedReadHalf, mut to: OwnedWriteHalf, delay: Duration) {
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel::<(Instant, Option<Vec<u8>>)>();
    let reader = async move {
        let mut buf = vec![0u8; 16 * 1024];
        loop {
            let n = from.read(&mut buf).await.unwrap_or(0);
            let chunk = (n > 0).then(|| buf[..n].to_vec());
            if tx.send((Instant::now() + delay, chunk)).is_err() || n == 0 {
                return;
            }
        }
    };
    let writer = async move {
        while let Some((due, chunk)) = rx.recv().await {
            tokio::time::sleep_until(due).await;
            match chunk {
                Some(c) if to.write_all(&c).await.is_ok() => {}
                _ => {
                    let _ = to.shutdown().await;
                    return;
                }
            }
        }
    };
    tokio::join!(reader, writer);
}
