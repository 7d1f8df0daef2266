//! `[web]`: the web page's address, allow list, action token and limits, and their check.

use crate::config::{KeyError, allow::AllowList, ensure, is_host_port};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// `[web]`: the box's web pages and JSON API (`docs/web.md`), on the same server as `/metrics`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(default, deny_unknown_fields)]
pub struct WebConfig {
    /// Address to serve on, HOST:PORT (e.g. `"0.0.0.0:8080"`); empty = off (default).
    pub listen: String,
    /// Addresses or CIDR ranges allowed to connect (`["192.168.1.0/24"]`); empty = everyone.
    pub allow: Vec<String>,
    /// File holding the token the actions need (`Authorization: Bearer TOKEN`); empty = the actions
    /// (snapshot, record save) are refused. The token is never logged nor shown.
    pub token_file: PathBuf,
    /// Connections served at once; more are refused at accept.
    pub max_connections: u32,
    /// Connections served at once from one IP address (a browser opens up to 6).
    pub max_connections_per_peer: u32,
    /// Requests handled at once, over every connection; more wait their turn (within the timeout).
    pub max_requests: u32,
    /// A request head not complete within this long is answered 408 and the connection closed, ms.
    pub header_timeout_ms: u64,
    /// A request not answered within this long (waiting for its turn included) is answered 408, ms.
    pub request_timeout_ms: u64,
    /// TLS: the server's certificate chain (PEM); empty = plain HTTP. Needs `tls_key`.
    pub tls_cert: PathBuf,
    /// TLS: the certificate's private key (PEM); never shown, only the file is named.
    pub tls_key: PathBuf,
}

impl Default for WebConfig {
    fn default() -> Self {
        Self {
            listen: String::new(),
            allow: Vec::new(),
            token_file: PathBuf::new(),
            max_connections: 32,
            max_connections_per_peer: 8,
            max_requests: 16,
            header_timeout_ms: 2000,
            request_timeout_ms: 10_000,
            tls_cert: PathBuf::new(),
            tls_key: PathBuf::new(),
        }
    }
}

impl WebConfig {
    /// The address (when on) and the allow list must parse; the TLS files come as a pair.
    pub fn validate(&self) -> Result<(), KeyError> {
        ensure(
            self.listen.is_empty() || is_host_port(&self.listen),
            "web.listen",
            format!("must be HOST:PORT (e.g. \"0.0.0.0:8080\") or empty (off), got {:?}", self.listen),
        )?;
        let (no_cert, no_key) = (self.tls_cert.as_os_str().is_empty(), self.tls_key.as_os_str().is_empty());
        ensure(
            no_cert == no_key,
            if no_key { "web.tls_key" } else { "web.tls_cert" },
            "TLS needs both web.tls_cert and web.tls_key (PEM files), or neither (plain HTTP)",
        )?;
        AllowList::parse(&self.allow).map(drop).map_err(|e| KeyError::new("web.allow", e))
    }

    /// The action token of `token_file` (trimmed); `Ok(None)` when no file is set. The error names
    /// the key and the file, never the content.
    pub fn token(&self) -> Result<Option<String>, String> {
        if self.token_file.as_os_str().is_empty() {
            return Ok(None);
        }
        let text = std::fs::read_to_string(&self.token_file)
            .map_err(|e| format!("web.token_file {}: {e}", self.token_file.display()))?;
        let token = text.trim();
        if token.len() < 8 {
            return Err(format!(
                "web.token_file {}: the token must be at least 8 characters",
                self.token_file.display()
            ));
        }
        Ok(Some(token.to_string()))
    }
}
