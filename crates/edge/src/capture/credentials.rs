//! `source.credentials_file`: `user:password` on the first line. Errors name the file only, never
//! what is in it.

use std::path::Path;

/// A camera login.
#[derive(Clone, PartialEq, Eq)]
pub struct Login {
    /// User name.
    pub user: String,
    /// Password.
    pub password: String,
}

impl std::fmt::Debug for Login {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Login").field("user", &self.user).field("password", &"***").finish()
    }
}

/// Reads the login from `path`; `None` for an empty path (no login).
pub fn read_login(path: &Path) -> Result<Option<Login>, String> {
    if path.as_os_str().is_empty() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).map_err(|e| format!("source.credentials_file {}: {e}", path.display()))?;
    let line = text.lines().next().unwrap_or_default().trim_end_matches('\r');
    match line.split_once(':') {
        Some((user, password)) if !user.is_empty() => {
            Ok(Some(Login { user: user.to_string(), password: password.to_string() }))
        }
        _ => Err(format!("source.credentials_file {}: the first line must be user:password", path.display())),
    }
}

/// `user:password` as an HTTP Basic `Authorization` value (base64, RFC 4648).
pub fn basic_auth(login: &Login) -> String {
    const ABC: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let raw = format!("{}:{}", login.user, login.password);
    let mut out = String::from("Basic ");
    for chunk in raw.as_bytes().chunks(3) {
        let b = [chunk[0], chunk.get(1).copied().unwrap_or(0), chunk.get(2).copied().unwrap_or(0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(char::from(ABC[(n >> (18 - 6 * k)) as usize & 63]));
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn login_file_and_basic_auth() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("cam");
        std::fs::write(&p, "admin:se:cret\nignored\n").expect("write");
        let login = read_login(&p).expect("read").expect("some");
        assert_eq!((login.user.as_str(), login.password.as_str()), ("admin", "se:cret"));
        assert!(!format!("{login:?}").contains("se:cret"));
        assert_eq!(read_login(Path::new("")), Ok(None));
        std::fs::write(&p, "justpassword\n").expect("write");
        let e = read_login(&p).expect_err("no colon");
        assert!(e.contains("user:password") && !e.contains("justpassword"), "{e}");
        assert!(read_login(&dir.path().join("none")).expect_err("missing").contains("credentials_file"));
        // RFC 7617's example.
        let l = Login { user: "Aladdin".into(), password: "open sesame".into() };
        assert_eq!(basic_auth(&l), "Basic QWxhZGRpbjpvcGVuIHNlc2FtZQ==");
        let l = Login { user: "a".into(), password: "bc".into() };
        assert_eq!(basic_auth(&l), "Basic YTpiYw==");
    }
}
