//! Client options of a connection: login, Last Will, keep-alive and the TLS setup (rustls, ring).

use super::{OFFLINE, Settings};
use rumqttc::{LastWill, MqttOptions, QoS};
use std::path::Path;
use std::sync::Arc;

/// The PEM certificates in `path` (at least one); the error names the file.
pub(crate) fn read_pem_certs(path: &Path) -> Result<Vec<rustls::pki_types::CertificateDer<'static>>, String> {
    let f = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let certs: Vec<_> = rustls_pemfile::certs(&mut std::io::BufReader::new(f))
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if certs.is_empty() {
        return Err(format!("{}: no PEM certificate in it", path.display()));
    }
    Ok(certs)
}

/// The PEM private key in `path`; the error names the file.
pub(crate) fn read_pem_key(path: &Path) -> Result<rustls::pki_types::PrivateKeyDer<'static>, String> {
    let f = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    rustls_pemfile::private_key(&mut std::io::BufReader::new(f))
        .map_err(|e| format!("{}: {e}", path.display()))?
        .ok_or_else(|| format!("{}: no PEM private key in it", path.display()))
}

/// The rustls client configuration of `s` (ring provider).
fn tls_config(s: &Settings) -> Result<rustls::ClientConfig, String> {
    let mut roots = rustls::RootCertStore::empty();
    if s.ca_file.as_os_str().is_empty() {
        for c in rustls_native_certs::load_native_certs().certs {
            let _ = roots.add(c);
        }
        if roots.is_empty() {
            return Err("no system CA certificates found; set output.mqtt.ca_file".into());
        }
    } else {
        for c in read_pem_certs(&s.ca_file)? {
            roots.add(c).map_err(|e| format!("output.mqtt.ca_file {}: {e}", s.ca_file.display()))?;
        }
    }
    let builder = rustls::ClientConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
        .with_safe_default_protocol_versions()
        .map_err(|e| format!("TLS: {e}"))?
        .with_root_certificates(roots);
    if s.cert_file.as_os_str().is_empty() {
        return Ok(builder.with_no_client_auth());
    }
    let certs = read_pem_certs(&s.cert_file)?;
    let key = read_pem_key(&s.key_file)?;
    builder.with_client_auth_cert(certs, key).map_err(|e| format!("output.mqtt.cert_file/key_file: {e}"))
}

/// The client options of `s`: Last Will, keep-alive, login (the password read now), TLS.
pub(super) fn options(s: &Settings) -> Result<MqttOptions, String> {
    let mut o = MqttOptions::new(s.box_id.clone(), s.host.clone(), s.port);
    o.set_keep_alive(s.keepalive);
    o.set_clean_session(true);
    o.set_max_packet_size(1 << 20, 1 << 20);
    o.set_last_will(LastWill::new(s.topics.status.clone(), OFFLINE, QoS::AtLeastOnce, true));
    if !s.username.is_empty() {
        let password = if s.password_file.as_os_str().is_empty() {
            String::new()
        } else {
            // Only the file is named in errors, never its content.
            let text = std::fs::read_to_string(&s.password_file)
                .map_err(|e| format!("output.mqtt.password_file {}: {e}", s.password_file.display()))?;
            text.lines().next().unwrap_or("").to_string()
        };
        o.set_credentials(s.username.clone(), password);
    }
    if s.tls {
        o.set_transport(rumqttc::Transport::tls_with_config(rumqttc::TlsConfiguration::Rustls(Arc::new(tls_config(
            s,
        )?))));
    }
    Ok(o)
}
