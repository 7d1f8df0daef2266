//! What kind of network a model file holds, read from its operators: float32, int8 in ONNX Runtime's
//! QDQ form (QuantizeLinear/DequantizeLinear pairs around float operators, which ONNX Runtime fuses
//! into int8 kernels) or int8 in QOperator form (QLinearConv and friends). Start-up lines, the MQTT
//! status and the build-info metric name it, so a slow box is told apart from a slow model.

/// The numeric form of a model file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelForm {
    /// Float32 throughout.
    Fp32,
    /// int8 as QuantizeLinear/DequantizeLinear pairs around float operators.
    Int8Qdq,
    /// int8 operators (QLinearConv, ConvInteger, QLinearMatMul, MatMulInteger).
    Int8QOperator,
}

impl ModelForm {
    /// The form of the ONNX file `bytes`. Operator types are plain strings in the protobuf, so a scan
    /// finds them without parsing the graph; a float32 graph names none of these operators.
    pub fn of_onnx(bytes: &[u8]) -> Self {
        let has = |op: &[u8]| bytes.windows(op.len()).any(|w| w == op);
        if [&b"QLinearConv"[..], b"ConvInteger", b"QLinearMatMul", b"MatMulInteger"].iter().any(|op| has(op)) {
            ModelForm::Int8QOperator
        } else if has(b"DequantizeLinear") {
            ModelForm::Int8Qdq
        } else {
            ModelForm::Fp32
        }
    }

    /// The form of the model file `path` (resolved as the pipeline resolves it, an embedded copy
    /// included).
    pub fn of_file(path: &std::path::Path) -> Result<Self, super::InferError> {
        let bytes = super::backend::model_bytes(&super::runtime::resolve_model(path))?;
        Ok(Self::of_onnx(&bytes))
    }

    /// Short name: `fp32`, `int8-qdq`, `int8-qop`.
    pub fn name(self) -> &'static str {
        match self {
            ModelForm::Fp32 => "fp32",
            ModelForm::Int8Qdq => "int8-qdq",
            ModelForm::Int8QOperator => "int8-qop",
        }
    }
}

impl std::fmt::Display for ModelForm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bundled(name: &str) -> Vec<u8> {
        let p = std::path::Path::new(crate::REPO_DIR).join("models").join(name);
        std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    }

    #[test]
    fn the_bundled_files_are_told_apart() {
        assert_eq!(ModelForm::of_onnx(&bundled("fish_det_int8.onnx")), ModelForm::Int8Qdq);
        assert_eq!(ModelForm::of_onnx(&bundled("fish_depth_int8.onnx")), ModelForm::Int8Qdq);
        assert_eq!(ModelForm::of_onnx(&bundled("fish_det_fp32.onnx")), ModelForm::Fp32);
        assert_eq!(ModelForm::of_onnx(&bundled("fish_depth_fp32.onnx")), ModelForm::Fp32);
    }

    #[test]
    fn qoperator_ops_win_over_a_stray_dequantize() {
        assert_eq!(ModelForm::of_onnx(b"..QLinearConv..DequantizeLinear.."), ModelForm::Int8QOperator);
        assert_eq!(ModelForm::of_onnx(b"..Conv..Relu.."), ModelForm::Fp32);
        assert_eq!(ModelForm::Int8Qdq.to_string(), "int8-qdq");
    }
}
