//! What to do about a listen address that cannot be bound: appended to the bind error, so a replay
//! run as a normal user, or next to the running service, says how to get on without the port.

use std::io::ErrorKind;

/// A hint for `error` binding `key` (`output.modbus.listen`, `output.metrics.listen`); empty when
/// there is nothing more to say.
pub fn listen_hint(error: &std::io::Error, key: &str) -> String {
    let off = if key == "output.modbus.listen" {
        "--modbus-listen 127.0.0.1:0 (any free port) or --set output.modbus.mode=off"
    } else {
        "--set output.metrics.listen=127.0.0.1:0 (any free port) or --set output.metrics.listen='\"\"' (off)"
    };
    match error.kind() {
        ErrorKind::PermissionDenied => format!(
            " (ports below 1024 need root or CAP_NET_BIND_SERVICE, which systemd/fme.service grants; \
             to run without the port, e.g. a replay: {off})"
        ),
        ErrorKind::AddrInUse => {
            format!(" (another program, perhaps the fme service, already listens there; {off})")
        }
        _ => String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hints_name_the_way_out() {
        let denied = std::io::Error::from(ErrorKind::PermissionDenied);
        assert!(listen_hint(&denied, "output.modbus.listen").contains("output.modbus.mode=off"));
        assert!(listen_hint(&denied, "output.modbus.listen").contains("CAP_NET_BIND_SERVICE"));
        let used = std::io::Error::from(ErrorKind::AddrInUse);
        assert!(listen_hint(&used, "output.metrics.listen").contains("output.metrics.listen=127.0.0.1:0"));
        assert_eq!(listen_hint(&std::io::Error::from(ErrorKind::Other), "output.modbus.listen"), "");
    }
}
