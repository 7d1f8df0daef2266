//! `fme config check`: the files a configuration names must exist, be readable and parse, so a
//! check that passes means `fme run` will not stop at start for a missing or broken file (exit 2,
//! which `RestartPreventExitStatus=2` leaves dead). Devices (`/dev/video0`, serial ports) are not
//! checked: they may enumerate after the check.

use super::Config;

/// Checks every file `cfg` names: the calibration (or a recording's own `meta.json`), the two
/// models (ONNX structure), a recorded source, and the MQTT password and TLS files, the web page's token and TLS files. The first
/// problem is the error, as (dotted key, message naming the file).
pub fn check(cfg: &Config) -> Result<(), (String, String)> {
    fn keyed(key: &'static str) -> impl Fn(String) -> (String, String) {
        move |m| (key.to_string(), m)
    }
    if cfg.source.is_ip_camera() {
        // Read, never shown: only the file is named.
        crate::capture::read_login(&cfg.source.credentials_file).map_err(keyed("source.credentials_file"))?;
    }
    if !cfg.source.is_camera() {
        crate::capture::RecordedSource::open(&cfg.source.path, false, false)
            .map_err(|e| keyed("source.path")(e.to_string()))?;
    }
    let calib_key = if cfg.camera.calibration.as_os_str().is_empty() { "source.path" } else { "camera.calibration" };
    cfg.calibration().map_err(keyed(calib_key))?;
    for (key, path) in [("detector.model", &cfg.detector.model), ("depth.model", &cfg.depth.model)] {
        let resolved = fme_core::infer::runtime::resolve_model(path);
        let bytes = fme_core::infer::backend::model_bytes(&resolved).map_err(|e| keyed(key)(e.to_string()))?;
        onnx_structure(&bytes)
            .map_err(|m| (key.to_string(), format!("{}: not an ONNX model: {m}", resolved.display())))?;
    }
    let q = &cfg.output.mqtt;
    if !q.password_file.as_os_str().is_empty() {
        // Read, never shown: only the file is named.
        std::fs::read(&q.password_file)
            .map_err(|e| keyed("output.mqtt.password_file")(format!("{}: {e}", q.password_file.display())))?;
    }
    // Read, never shown: only the file is named.
    cfg.web.token().map_err(keyed("web.token_file"))?;
    crate::web::tls::server_config(&cfg.web)?;
    if !q.ca_file.as_os_str().is_empty() {
        crate::output::mqtt::read_pem_certs(&q.ca_file).map_err(keyed("output.mqtt.ca_file"))?;
    }
    if !q.cert_file.as_os_str().is_empty() {
        crate::output::mqtt::read_pem_certs(&q.cert_file).map_err(keyed("output.mqtt.cert_file"))?;
    }
    if !q.key_file.as_os_str().is_empty() {
        crate::output::mqtt::read_pem_key(&q.key_file).map_err(keyed("output.mqtt.key_file"))?;
    }
    Ok(())
}

/// Checks that `bytes` is a protobuf `ModelProto` (ONNX IR): its top-level fields parse to the
/// end, and it has an `ir_version` (field 1) and a `graph` (field 7). Cheap: the graph itself is
/// skipped, not parsed.
pub fn onnx_structure(bytes: &[u8]) -> Result<(), String> {
    fn varint(b: &[u8], pos: &mut usize) -> Option<u64> {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let byte = *b.get(*pos)?;
            *pos += 1;
            v |= u64::from(byte & 0x7f) << shift;
            if byte & 0x80 == 0 {
                return Some(v);
            }
        }
        None
    }
    let (mut pos, mut ir_version, mut graph) = (0usize, false, false);
    while pos < bytes.len() {
        let at = pos;
        let bad = |what: &str| format!("{what} at byte {at}");
        let tag = varint(bytes, &mut pos).ok_or_else(|| bad("truncated field tag"))?;
        let (field, wire) = (tag >> 3, tag & 7);
        match wire {
            0 => {
                varint(bytes, &mut pos).ok_or_else(|| bad("truncated number"))?;
            }
            1 => pos = pos.checked_add(8).filter(|&p| p <= bytes.len()).ok_or_else(|| bad("truncated field"))?,
            5 => pos = pos.checked_add(4).filter(|&p| p <= bytes.len()).ok_or_else(|| bad("truncated field"))?,
            2 => {
                let len = varint(bytes, &mut pos).ok_or_else(|| bad("truncated length"))?;
                let end = usize::try_from(len).ok().and_then(|l| pos.checked_add(l));
                pos = end.filter(|&p| p <= bytes.len()).ok_or_else(|| bad("field longer than the file"))?;
            }
            _ => return Err(bad(&format!("invalid protobuf wire type {wire}"))),
        }
        if field == 0 {
            return Err(bad("field number 0"));
        }
        ir_version |= field == 1 && wire == 0;
        graph |= field == 7 && wire == 2;
    }
    match (ir_version, graph) {
        (true, true) => Ok(()),
        (false, _) => Err("no ir_version".into()),
        (true, false) => Err("no graph".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn onnx_structure_accepts_models_and_refuses_other_files() {
        // ir_version = 8, graph = {} (empty message), opset_import = {}.
        assert_eq!(onnx_structure(&[0x08, 0x08, 0x3a, 0x00, 0x42, 0x00]), Ok(()));
        assert!(onnx_structure(b"not an onnx model").is_err());
        assert!(onnx_structure(&[0x08, 0x08]).unwrap_err().contains("no graph"));
        assert!(onnx_structure(&[0x08, 0x08, 0x3a, 0x05, 0x00]).unwrap_err().contains("longer than the file"));
        assert!(onnx_structure(b"").is_err());
        let bundled = std::fs::read(std::path::Path::new(fme_core::REPO_DIR).join("models/fish_det_int8.onnx"))
            .expect("the bundled detector");
        assert_eq!(onnx_structure(&bundled), Ok(()));
    }
}
