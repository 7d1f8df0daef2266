//! The web page over TLS (`[web] tls_cert`/`tls_key`, docs/web.md): a self-signed certificate made
//! here (rcgen), a rustls client fetching `/api/status` over HTTPS, plain HTTP to the TLS port
//! answered "use https://" without harming the server, and unusable files named in the error.

#[path = "common/web_lan.rs"]
mod web_lan;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tokio_rustls::TlsConnector;
use tokio_rustls::rustls;
use web_lan::{connect_from, exchange, get, start};

/// A self-signed certificate for `localhost` and its key, written as PEM into `dir`; the
/// certificate (DER) for the client's trust store.
fn self_signed(dir: &Path) -> (PathBuf, PathBuf, rustls::pki_types::CertificateDer<'static>) {
    let key = rcgen::KeyPair::generate().expect("key pair");
    let params = rcgen::CertificateParams::new(vec!["localhost".to_string()]).expect("params");
    let cert = params.self_signed(&key).expect("self-signed certificate");
    let (cert_path, key_path) = (dir.join("web.crt"), dir.join("web.key"));
    std::fs::write(&cert_path, cert.pem()).expect("write certificate");
    std::fs::write(&key_path, key.serialize_pem()).expect("write key");
    (cert_path, key_path, cert.der().clone())
}

/// A client trusting only `cert`.
fn connector(cert: rustls::pki_types::CertificateDer<'static>) -> TlsConnector {
    let mut roots = rustls::RootCertStore::empty();
    roots.add(cert).expect("trust the test certificate");
    let provider = Arc::new(rustls::crypto::ring::default_provider());
    let cfg = rustls::ClientConfig::builder_with_provider(provider)
        .with_safe_default_protocol_versions()
        .expect("protocol versions")
        .with_root_certificates(roots)
        .with_no_client_auth();
    TlsConnector::from(Arc::new(cfg))
}

/// `GET path` over TLS: (code, body); the handshake must succeed.
async fn get_tls(tls: &TlsConnector, addr: SocketAddr, path: &str) -> (u16, Vec<u8>) {
    let tcp = connect_from("127.0.0.1", addr).await.expect("connect");
    let name = rustls::pki_types::ServerName::try_from("localhost").expect("name");
    let mut s = tls.connect(name, tcp).await.expect("TLS handshake with the box");
    let (code, _, body) = exchange(&mut s, &get(path)).await;
    (code, body)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn status_over_tls_and_plain_http_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (cert, key, der) = self_signed(dir.path());
    let f = start(|c| (c.web.tls_cert, c.web.tls_key) = (cert.clone(), key.clone())).await.expect("serves");
    let tls = connector(der);
    let (code, body) = get_tls(&tls, f.addr, "/api/status").await;
    assert_eq!(code, 200, "{}", String::from_utf8_lossy(&body));
    let status: serde_json::Value = serde_json::from_slice(&body).expect("JSON status");
    assert!(status.get("health").is_some(), "{status}");
    // Plain HTTP to the TLS port: a plain-text refusal, nothing served.
    let mut plain = connect_from("127.0.0.1", f.addr).await.expect("connect");
    let (code, head, body) = exchange(&mut plain, &get("/api/status")).await;
    assert_eq!(code, 400, "{head}");
    assert!(String::from_utf8_lossy(&body).contains("https://"), "{head}");
    // A TLS-looking first byte with garbage after it: closed, no answer.
    let mut junk = connect_from("127.0.0.1", f.addr).await.expect("connect");
    let (code, _, _) = exchange(&mut junk, b"\x16\x03\x01garbage that is no ClientHello\r\n\r\n").await;
    assert_eq!(code, 0, "a failed handshake is closed");
    // The server is unharmed: TLS still answers, several times on one port.
    for _ in 0..3 {
        assert_eq!(get_tls(&tls, f.addr, "/api/status").await.0, 200);
    }
    assert!(f.shared.last_logs(64).join("\n").contains("https://"), "the log gives the https address");
    f.server.stop().await;
}

#[tokio::test]
async fn unusable_tls_files_are_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let (cert, key, _) = self_signed(dir.path());
    let other = tempfile::tempdir().expect("tempdir");
    let (_, other_key, _) = self_signed(other.path());
    let missing = dir.path().join("missing.pem");
    let not_pem = dir.path().join("not.pem");
    std::fs::write(&not_pem, "not a certificate\n").expect("write");
    for (c, k, key_named, file) in [
        (&missing, &key, "web.tls_cert", &missing),
        (&cert, &missing, "web.tls_key", &missing),
        (&not_pem, &key, "web.tls_cert", &not_pem),
        (&cert, &not_pem, "web.tls_key", &not_pem),
        (&key, &cert, "web.tls_cert", &key),
        (&cert, &other_key, "web.tls_key", &other_key),
    ] {
        let mut cfg = fme::config::Config::default();
        (cfg.web.tls_cert, cfg.web.tls_key) = (c.clone(), k.clone());
        let (k_err, msg) = fme::web::tls::server_config(&cfg.web).expect_err("refused");
        assert_eq!(k_err, key_named, "{msg}");
        assert!(msg.contains(&file.display().to_string()), "{msg} names {}", file.display());
        // The daemon: the page stays off (never plain HTTP instead), said in the log.
        let f = start(|w| (w.web.tls_cert, w.web.tls_key) = (c.clone(), k.clone())).await;
        assert!(f.is_none(), "no page with unusable TLS files");
    }
    let mut half = fme::config::Config::default();
    half.web.tls_cert = cert;
    let e = half.validate().expect_err("a certificate without a key");
    assert!(e.to_string().contains("web.tls_key"), "{e}");
}
