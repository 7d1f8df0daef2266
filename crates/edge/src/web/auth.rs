//! The actions' token: `Authorization: Bearer TOKEN` equal to `[web] token_file`'s, compared in
//! constant time (the time taken says nothing about how much of a guess was right). The token is
//! never logged, shown or echoed.

use axum::http::HeaderMap;

/// Whether `a` equals `b`, in a time that depends only on their lengths.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = u8::from(a.len() != b.len());
    for i in 0..a.len().max(b.len()) {
        diff |= a.get(i).copied().unwrap_or(0) ^ b.get(i).copied().unwrap_or(0xff);
    }
    diff == 0
}

/// Why an action is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// No token configured: no action is possible (403).
    NoToken,
    /// No token or a wrong one sent (401).
    Unauthorized,
}

/// Whether `headers` carry the configured `token`.
pub fn check(headers: &HeaderMap, token: Option<&str>) -> Result<(), Refusal> {
    let Some(token) = token else { return Err(Refusal::NoToken) };
    let sent = headers
        .get(axum::http::header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(str::trim)
        .unwrap_or("");
    if constant_time_eq(sent.as_bytes(), token.as_bytes()) { Ok(()) } else { Err(Refusal::Unauthorized) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equal_only_when_every_byte_and_the_length_match() {
        assert!(constant_time_eq(b"secret-token", b"secret-token"));
        assert!(!constant_time_eq(b"secret-token", b"secret-tokeN"));
        assert!(!constant_time_eq(b"secret-token", b"secret-toke"));
        assert!(!constant_time_eq(b"", b"x"));
        assert!(constant_time_eq(b"", b""));
    }

    #[test]
    fn bearer_header_is_checked() {
        let mut h = HeaderMap::new();
        assert_eq!(check(&h, Some("abcdefgh")), Err(Refusal::Unauthorized));
        assert_eq!(check(&h, None), Err(Refusal::NoToken));
        h.insert("authorization", "Bearer abcdefgh".parse().expect("header"));
        assert_eq!(check(&h, Some("abcdefgh")), Ok(()));
        assert_eq!(check(&h, Some("abcdefgi")), Err(Refusal::Unauthorized));
    }
}
