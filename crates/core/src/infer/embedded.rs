//! The bundled models inside the executable (feature `embed-models`). A configured model path that
//! is not a file and names one of the bundled models (as the default configuration does, e.g.
//! `models/fish_det_int8.onnx`) resolves to the embedded copy, so the static binary of
//! `make static` runs from an empty directory. A file at that path always wins.

use std::path::{Component, Path};

/// One bundled model: its path relative to the repository (as in the default configuration) and
/// its bytes.
#[derive(Debug, Clone, Copy)]
pub struct EmbeddedModel {
    /// Path as configured, e.g. `models/fish_det_int8.onnx`.
    pub path: &'static str,
    /// The ONNX file.
    pub bytes: &'static [u8],
}

#[cfg(feature = "embed-models")]
macro_rules! bundled {
    ($($name:literal),* $(,)?) => {
        &[$(EmbeddedModel {
            path: concat!("models/", $name),
            bytes: include_bytes!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/", $name)),
        }),*]
    };
}

/// The models inside this executable (none without the feature `embed-models`): the int8 files of
/// the default configuration, and the fp32 files (ONNX Runtime runs int8 faster, tract runs fp32
/// faster; see docs/benchmarks.md).
#[cfg(feature = "embed-models")]
pub const MODELS: &[EmbeddedModel] =
    bundled!("fish_det_int8.onnx", "fish_depth_int8.onnx", "fish_det_fp32.onnx", "fish_depth_fp32.onnx");
/// The models inside this executable (none without the feature `embed-models`).
#[cfg(not(feature = "embed-models"))]
pub const MODELS: &[EmbeddedModel] = &[];

/// The embedded copy of the model `path` names: `path` must be one of [`MODELS`]' paths, relative,
/// optionally with `./` components (`./models/fish_det_int8.onnx`).
pub fn lookup(path: &Path) -> Option<&'static [u8]> {
    if path.is_absolute() {
        return None;
    }
    let parts: Vec<&std::ffi::OsStr> = path
        .components()
        .filter(|c| !matches!(c, Component::CurDir))
        .map(|c| match c {
            Component::Normal(s) => Some(s),
            _ => None,
        })
        .collect::<Option<Vec<_>>>()?;
    MODELS.iter().find(|m| Path::new(m.path).iter().eq(parts.iter().copied())).map(|m| m.bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(feature = "embed-models")]
    #[test]
    fn default_model_paths_resolve_to_the_bundled_bytes() {
        let (det, depth) = (crate::infer::DetectorConfig::default().model, crate::infer::DepthConfig::default().model);
        for p in [&det, &depth] {
            let bytes = lookup(p).unwrap_or_else(|| panic!("{} is not embedded", p.display()));
            let file = Path::new(crate::REPO_DIR).join(p);
            assert_eq!(std::fs::read(&file).ok().as_deref(), Some(bytes), "{}", file.display());
        }
        assert!(lookup(Path::new("./models/fish_det_fp32.onnx")).is_some());
    }

    #[test]
    fn other_paths_do_not_resolve() {
        for p in ["/models/fish_det_int8.onnx", "models/other.onnx", "../models/fish_det_int8.onnx", ""] {
            assert!(lookup(Path::new(p)).is_none(), "{p}");
        }
        #[cfg(not(feature = "embed-models"))]
        assert!(lookup(Path::new("models/fish_det_int8.onnx")).is_none());
    }
}
