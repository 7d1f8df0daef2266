//! Optional TLS on the `[web] listen` listener: rustls with the ring provider (the MQTT client's:
//! pure Rust, builds static), the PEM files read by the MQTT code's readers. The handshake runs
//! inside the head timeout's budget, so a peer that stalls it is a slowloris like any other; a
//! plain-HTTP request to the TLS port is answered in plain text (400, "use https://") and closed.

use super::config::WebConfig;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpStream;
use tokio_rustls::TlsAcceptor;
use tokio_rustls::server::TlsStream;

/// The first byte of a TLS record carrying a handshake (a ClientHello).
const TLS_HANDSHAKE: u8 = 0x16;

/// The server configuration of `[web] tls_cert`/`tls_key`; `Ok(None)` when TLS is off. The error is (dotted
/// key, message naming the file), never the key's content.
pub fn server_config(cfg: &WebConfig) -> Result<Option<Arc<rustls::ServerConfig>>, (String, String)> {
    if cfg.tls_cert.as_os_str().is_empty() && cfg.tls_key.as_os_str().is_empty() {
        return Ok(None);
    }
    fn keyed(key: &'static str) -> impl Fn(String) -> (String, String) {
        move |m| (key.to_string(), m)
    }
    let certs = crate::output::mqtt::read_pem_certs(&cfg.tls_cert).map_err(keyed("web.tls_cert"))?;
    let key = crate::output::mqtt::read_pem_key(&cfg.tls_key).map_err(keyed("web.tls_key"))?;
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let mut server = rustls::ServerConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .map_err(|e| ("web.tls_cert".to_string(), format!("TLS: {e}")))?
        .with_no_client_auth()
        .with_single_cert(certs, key)
        .map_err(|e| {
            let files = format!("{} and {}", cfg.tls_cert.display(), cfg.tls_key.display());
            ("web.tls_key".to_string(), format!("{files}: not a usable certificate and key: {e}"))
        })?;
    server.alpn_protocols = vec![b"http/1.1".to_vec()];
    Ok(Some(Arc::new(server)))
}

/// How a connection to the TLS port began.
pub(super) enum Start {
    /// A completed handshake.
    Tls(Box<TlsStream<TcpStream>>),
    /// Not TLS: the peer's first byte is not a handshake record (plain HTTP, garbage).
    Plain(TcpStream),
    /// Closed, failed or stalled (longer than the limit): nothing to answer.
    Gone,
}

/// The handshake on `stream` within `limit`.
pub(super) async fn handshake(server: &Arc<rustls::ServerConfig>, stream: TcpStream, limit: Duration) -> Start {
    let done = tokio::time::timeout(limit, async {
        let mut first = [0u8; 1];
        match stream.peek(&mut first).await {
            Ok(1) if first[0] == TLS_HANDSHAKE => {}
            Ok(1) => return Start::Plain(stream),
            _ => return Start::Gone,
        }
        match TlsAcceptor::from(server.clone()).accept(stream).await {
            Ok(s) => Start::Tls(Box::new(s)),
            Err(e) => {
                tracing::debug!("web: TLS handshake failed: {e}");
                Start::Gone
            }
        }
    })
    .await;
    done.unwrap_or(Start::Gone)
}
