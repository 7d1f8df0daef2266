//! Where the box writes its files (recordings, snapshots, history): one resolution every writer uses.

use crate::config::Config;
use std::path::PathBuf;

/// The state directory: `$STATE_DIRECTORY` when systemd set it (`StateDirectory=fme` in the unit;
/// the first entry if it lists several, separated by `:`), else `service.state_dir`, else `None`
/// (nothing is written to disk). The directory is not created here: writers create what they need
/// below it and report failures themselves.
pub fn state_dir(cfg: &Config) -> Option<PathBuf> {
    from(std::env::var_os("STATE_DIRECTORY"), cfg)
}

fn from(env: Option<std::ffi::OsString>, cfg: &Config) -> Option<PathBuf> {
    if let Some(first) = env.as_ref().and_then(|v| v.to_str()).and_then(|v| v.split(':').next())
        && !first.is_empty()
    {
        return Some(PathBuf::from(first));
    }
    let configured = &cfg.service.state_dir;
    (!configured.as_os_str().is_empty()).then(|| configured.clone())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn environment_then_config_then_none() {
        let mut cfg = Config::default();
        assert_eq!(from(None, &cfg), None);
        cfg.service.state_dir = PathBuf::from("/tmp/x");
        assert_eq!(from(None, &cfg), Some(PathBuf::from("/tmp/x")));
        assert_eq!(from(Some("/var/lib/fme:/var/lib/other".into()), &cfg), Some(PathBuf::from("/var/lib/fme")));
        assert_eq!(from(Some("".into()), &cfg), Some(PathBuf::from("/tmp/x")));
    }
}
