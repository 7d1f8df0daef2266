//! The one ONNX Runtime environment of the process and the lookup of its shared library (feature
//! `ort`), model path resolution, and the session options shared by both backends.
//!
//! Library lookup order (first that loads wins):
//! 1. `ORT_DYLIB_PATH` (if set, it must work: a wrong explicit path is an error, not a fallback);
//! 2. `libonnxruntime.so` beside the executable;
//! 3. the install prefix's `lib/fme/libonnxruntime.so` (`make install`: `/usr/local/lib/fme/` for
//!    `/usr/local/bin/fme`), so the installed executable run by hand finds the library the unit names;
//! 4. the repository's `.ort/lib/libonnxruntime.so` (put there by `scripts/setup.sh`), with the
//!    absolute path baked in at compile time so `target/release/fme` finds it with no variable set;
//! 5. the system's dynamic-loader search path.

#[cfg(feature = "ort")]
pub use self::onnxruntime::*;
use std::path::{Path, PathBuf};

#[cfg(feature = "ort")]
mod onnxruntime {
    use std::ffi::OsString;
    use std::fmt::Write as _;
    use std::path::{Path, PathBuf};
    use std::sync::{Mutex, OnceLock};

    use ort::environment::Environment;

    use crate::infer::InferError;

    /// File name of the ONNX Runtime shared library on Linux.
    pub const LIBRARY_NAME: &str = "libonnxruntime.so";

    /// The repository's copy of ONNX Runtime, installed by `scripts/setup.sh`.
    pub const REPO_LIBRARY: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../.ort/lib/libonnxruntime.so");

    static ENV: OnceLock<Environment> = OnceLock::new();
    static INIT: Mutex<()> = Mutex::new(());

    /// Where the library is looked for, in order, given the value of `ORT_DYLIB_PATH` and the directory
    /// of the running executable. A pure function so the order is testable.
    pub fn library_candidates(env_path: Option<OsString>, exe_dir: Option<&Path>) -> Vec<(PathBuf, &'static str)> {
        let mut out = Vec::with_capacity(5);
        if let Some(p) = env_path.filter(|p| !p.is_empty()) {
            out.push((PathBuf::from(p), "ORT_DYLIB_PATH"));
            // An explicit path is the user's choice: no silent fallback.
            return out;
        }
        if let Some(dir) = exe_dir {
            out.push((dir.join(LIBRARY_NAME), "beside the executable"));
            if let Some(prefix) = dir.parent() {
                out.push((prefix.join("lib/fme").join(LIBRARY_NAME), "install prefix lib/fme"));
            }
        }
        out.push((PathBuf::from(REPO_LIBRARY), "repository .ort/lib"));
        out.push((PathBuf::from(LIBRARY_NAME), "system library path"));
        out
    }

    /// Loads ONNX Runtime from the first candidate that works (see the module doc) and creates the
    /// process-wide environment once. Later calls return the same environment.
    pub fn environment() -> Result<&'static Environment, InferError> {
        if let Some(env) = ENV.get() {
            return Ok(env);
        }
        let exe_dir = std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf));
        init_with(library_candidates(std::env::var_os("ORT_DYLIB_PATH"), exe_dir.as_deref()))
    }

    /// Like [`environment`], but with an explicit library path (e.g. from the configuration).
    pub fn environment_from(library: &Path) -> Result<&'static Environment, InferError> {
        if let Some(env) = ENV.get() {
            return Ok(env);
        }
        init_with(vec![(library.to_path_buf(), "configured path")])
    }

    fn init_with(candidates: Vec<(PathBuf, &'static str)>) -> Result<&'static Environment, InferError> {
        let _guard = INIT.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(env) = ENV.get() {
            return Ok(env);
        }
        let mut tried = String::new();
        let mut loaded = None;
        for (path, origin) in &candidates {
            // Absolute paths that do not exist are skipped without calling into ort (its loader would
            // only say "cannot open"); bare names go to the dynamic loader's search path.
            if path.is_absolute() && !path.exists() {
                let _ = write!(tried, "{} ({origin}): no such file; ", path.display());
                continue;
            }
            match ort::init_from(path) {
                Ok(builder) => {
                    loaded = Some((builder, path.clone()));
                    break;
                }
                Err(e) => {
                    let _ = write!(tried, "{} ({origin}): {e}; ", path.display());
                }
            }
        }
        let Some((builder, path)) = loaded else {
            return Err(InferError::Library { tried: tried.trim_end_matches("; ").to_string() });
        };
        let env = builder
            .with_name("fme")
            .with_telemetry(false)
            .build()
            .map_err(|e| InferError::Environment(e.to_string()))?;
        tracing::info!(library = %path.display(), "ONNX Runtime loaded");
        Ok(ENV.get_or_init(|| env))
    }
}

/// Finds a model file: as given, else (relative paths) beside the repository or install prefix of
/// the running executable (`target/release/fme` -> the repository; `bin/fme` -> `share/fme/`).
/// An empty path stays empty (never a directory that happens to exist), and only files are found.
pub fn resolve_model(path: &Path) -> PathBuf {
    if path.as_os_str().is_empty() || path.is_absolute() || path.exists() {
        return path.to_path_buf();
    }
    let exe_dir = std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf));
    if let Some(dir) = exe_dir {
        for base in [dir.join("../.."), dir.join("../share/fme")] {
            let p = base.join(path);
            if p.is_file() {
                return p;
            }
        }
    }
    path.to_path_buf()
}

/// Session options shared by the detector and the depth network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SessionOptions {
    /// Intra-op threads (ONNX Runtime's include the calling thread; tract's matrix products get a
    /// pool of this many). 0: ONNX Runtime chooses, tract takes one per core.
    pub intra_threads: usize,
    /// Let idle worker threads spin (lower latency, but burns CPU the tracker could use).
    pub spin: bool,
}

impl Default for SessionOptions {
    fn default() -> Self {
        Self { intra_threads: 2, spin: false }
    }
}

/// Formats a shape as `[1, 3, 640, 640]` with `?` for dynamic dimensions.
pub fn fmt_shape(dims: &[i64]) -> String {
    let parts: Vec<String> = dims.iter().map(|d| if *d < 0 { "?".to_string() } else { d.to_string() }).collect();
    format!("[{}]", parts.join(", "))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(feature = "ort")]
    #[test]
    fn explicit_env_path_is_the_only_candidate() {
        let c = library_candidates(Some("/opt/ort/libonnxruntime.so".into()), Some(Path::new("/usr/bin")));
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].0, PathBuf::from("/opt/ort/libonnxruntime.so"));
    }

    #[cfg(feature = "ort")]
    #[test]
    fn default_order_is_exe_dir_install_prefix_repo_system() {
        let c = library_candidates(None, Some(Path::new("/srv/fme/bin")));
        let paths: Vec<_> = c.iter().map(|(p, _)| p.clone()).collect();
        assert_eq!(
            paths,
            vec![
                PathBuf::from("/srv/fme/bin/libonnxruntime.so"),
                // Where `make install` puts it: the installed fme run by hand (no unit, no
                // ORT_DYLIB_PATH) on a box without the build's checkout.
                PathBuf::from("/srv/fme/lib/fme/libonnxruntime.so"),
                PathBuf::from(REPO_LIBRARY),
                PathBuf::from("libonnxruntime.so")
            ]
        );
        assert!(Path::new(REPO_LIBRARY).is_absolute());
        // An empty variable counts as unset.
        assert_eq!(library_candidates(Some("".into()), None).len(), 2);
    }

    #[test]
    fn shapes_format_dynamic_dims() {
        assert_eq!(fmt_shape(&[1, 3, -1, 640]), "[1, 3, ?, 640]");
    }
}
