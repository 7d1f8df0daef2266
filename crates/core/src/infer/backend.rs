//! The inference backend seam: "run this graph on this input tensor, hand me the output tensor".
//! The detector and the depth network keep one implementation of their pre- and post-processing
//! and reach the runtime only through [`Model`].
//!
//! Backends are chosen at build time with cargo features:
//! - `ort` (the default): ONNX Runtime, dlopened from `libonnxruntime.so` (see [`super::runtime`]);
//! - `tract`: tract, a pure-Rust ONNX runtime, so the executable needs no shared library (the
//!   static binary of `make static`). It runs each network on one thread.
//!
//! With both features, ONNX Runtime runs the pipeline ([`Backend::DEFAULT`]) and tract is there for
//! the parity test and the backend benchmark, which pick a backend explicitly.

use std::borrow::Cow;
use std::path::Path;

use super::runtime::SessionOptions;
use super::{InferError, ModelForm};

#[cfg(not(any(feature = "ort", feature = "tract")))]
compile_error!("fme needs an inference backend: enable the cargo feature `ort` (the default) or `tract`");

/// One inference runtime compiled into this build.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Backend {
    /// ONNX Runtime (feature `ort`).
    #[cfg(feature = "ort")]
    Ort,
    /// tract, pure Rust (feature `tract`).
    #[cfg(feature = "tract")]
    Tract,
}

impl Backend {
    /// The backend the pipeline uses: ONNX Runtime when it is compiled in, else tract.
    #[cfg(feature = "ort")]
    pub const DEFAULT: Backend = Backend::Ort;
    /// The backend the pipeline uses: ONNX Runtime when it is compiled in, else tract.
    #[cfg(all(feature = "tract", not(feature = "ort")))]
    pub const DEFAULT: Backend = Backend::Tract;

    /// Every backend of this build, the default first.
    pub const ALL: &'static [Backend] = &[
        #[cfg(feature = "ort")]
        Backend::Ort,
        #[cfg(feature = "tract")]
        Backend::Tract,
    ];

    /// Short name, as `fme --version` shows it.
    pub fn name(self) -> &'static str {
        match self {
            #[cfg(feature = "ort")]
            Backend::Ort => "onnxruntime",
            #[cfg(feature = "tract")]
            Backend::Tract => "tract",
        }
    }

    /// Makes the backend ready to open models (ONNX Runtime: finds and loads the shared library
    /// once per process). Errors name what is missing.
    pub fn prepare(self) -> Result<(), InferError> {
        match self {
            #[cfg(feature = "ort")]
            Backend::Ort => super::runtime::environment().map(|_| ()),
            #[cfg(feature = "tract")]
            Backend::Tract => Ok(()),
        }
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

macro_rules! build_line {
    ($backend:literal, $forms:literal, $models:literal) => {
        /// The backend, the numeric form of its default models and whether they are inside the
        /// executable, e.g. `backend tract, default models fp32, embedded` (`fme --version`, the
        /// console `version`, the start-up line).
        pub const BUILD: &str = concat!("backend ", $backend, ", default models ", $forms, $models);
        /// `fme --version`: the package version and [`BUILD`].
        pub const VERSION: &str =
            concat!(env!("CARGO_PKG_VERSION"), " (backend ", $backend, ", default models ", $forms, $models, ")");
    };
}
// The forms of `config::DEFAULT_DETECTOR_MODEL` and `DEFAULT_DEPTH_MODEL` (a test checks them).
#[cfg(all(feature = "ort", feature = "embed-models"))]
build_line!("onnxruntime", "int8-qdq", ", embedded");
#[cfg(all(feature = "ort", not(feature = "embed-models")))]
build_line!("onnxruntime", "int8-qdq", "");
#[cfg(all(not(feature = "ort"), feature = "embed-models"))]
build_line!("tract", "fp32", ", embedded");
#[cfg(all(not(feature = "ort"), not(feature = "embed-models")))]
build_line!("tract", "fp32", "");

/// A float32 tensor outlet of a model: its name and shape (`-1` for a dynamic dimension), or why
/// it is not a float32 tensor.
#[derive(Debug, Clone, PartialEq)]
pub struct Outlet {
    /// Name in the graph.
    pub name: String,
    /// The shape when the outlet is a float32 tensor of known rank, else what it is instead.
    pub shape: Result<Vec<i64>, String>,
}

impl Outlet {
    /// The shape, or an [`InferError::Shape`] naming `what` when the outlet is not a float32 tensor.
    pub fn float_shape(&self, path: &Path, what: &str) -> Result<Vec<i64>, InferError> {
        self.shape.clone().map_err(|actual| InferError::Shape {
            path: path.to_path_buf(),
            what: what.to_string(),
            expected: "float32 tensor".into(),
            actual,
        })
    }
}

/// Reads a model file. A default model path of the bundled models that is not a file resolves to
/// the copy inside the executable (feature `embed-models`, see [`super::embedded`]).
pub fn model_bytes(path: &Path) -> Result<Cow<'static, [u8]>, InferError> {
    let model_err = |reason: String| InferError::ModelFile { path: path.to_path_buf(), reason };
    if !path.is_file()
        && let Some(bytes) = super::embedded::lookup(path)
    {
        tracing::info!(model = %path.display(), "no such file: using the copy embedded in the executable");
        return Ok(Cow::Borrowed(bytes));
    }
    // Read first: the runtimes' own messages for a missing file are less clear.
    let bytes = std::fs::read(path).map_err(|e| model_err(format!("cannot read: {e}")))?;
    if bytes.is_empty() {
        return Err(model_err("file is empty".into()));
    }
    Ok(Cow::Owned(bytes))
}

/// A loaded model with one float32 input and float32 outputs.
pub struct Model {
    inner: Inner,
    inputs: Vec<Outlet>,
    outputs: Vec<Outlet>,
    form: ModelForm,
}

/// What a backend's `open` gives: the runtime's handle and the model's inputs and outputs.
type Opened = (Inner, Vec<Outlet>, Vec<Outlet>);

enum Inner {
    #[cfg(feature = "ort")]
    Ort(ort::session::Session),
    #[cfg(feature = "tract")]
    Tract(tract::Graph),
}

impl std::fmt::Debug for Model {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Model")
            .field("backend", &self.backend())
            .field("inputs", &self.inputs)
            .field("outputs", &self.outputs)
            .field("form", &self.form)
            .finish()
    }
}

impl Model {
    /// Opens `path` (or its embedded copy) with `backend`. A missing file, a corrupt model or a
    /// model the runtime rejects is an [`InferError::ModelFile`] naming the file.
    pub fn open(path: &Path, opts: SessionOptions, backend: Backend) -> Result<Self, InferError> {
        let bytes = model_bytes(path)?;
        let (inner, inputs, outputs) = match backend {
            #[cfg(feature = "ort")]
            Backend::Ort => ort_backend::open(path, &bytes, opts)?,
            #[cfg(feature = "tract")]
            Backend::Tract => tract::open(path, &bytes, opts)?,
        };
        Ok(Model { inner, inputs, outputs, form: ModelForm::of_onnx(&bytes) })
    }

    /// The file's numeric form (float32, int8 QDQ or QOperator).
    pub fn form(&self) -> ModelForm {
        self.form
    }

    /// The backend running this model.
    pub fn backend(&self) -> Backend {
        match self.inner {
            #[cfg(feature = "ort")]
            Inner::Ort(_) => Backend::Ort,
            #[cfg(feature = "tract")]
            Inner::Tract(_) => Backend::Tract,
        }
    }

    /// The model's inputs.
    pub fn inputs(&self) -> &[Outlet] {
        &self.inputs
    }

    /// The model's outputs.
    pub fn outputs(&self) -> &[Outlet] {
        &self.outputs
    }

    /// Fixes the input shape the model will be run with (tract plans and optimises the graph for
    /// it here, so a graph it cannot run fails at start-up, and learns the outputs' shapes; ONNX
    /// Runtime needs nothing). Call it before reading [`Self::outputs`].
    pub fn set_input_shape(&mut self, path: &Path, shape: [usize; 4]) -> Result<(), InferError> {
        match &mut self.inner {
            #[cfg(feature = "ort")]
            Inner::Ort(_) => {
                let _ = (path, shape);
                Ok(())
            }
            #[cfg(feature = "tract")]
            Inner::Tract(g) => {
                let model_err = |reason: String| InferError::ModelFile { path: path.to_path_buf(), reason };
                g.plan(shape).map_err(model_err)?;
                // An ONNX file need not declare its outputs' shapes: take them from the analysed graph.
                let planned = g.outputs().map_err(model_err)?;
                for (o, shape) in self.outputs.iter_mut().zip(planned) {
                    o.shape = shape;
                }
                Ok(())
            }
        }
    }

    /// Runs the model on `input` (shape `shape`, row-major) and hands the first output's shape and
    /// data to `read`. Runtime failures are [`InferError::Run`] naming `path`.
    pub fn run<R>(
        &mut self,
        path: &Path,
        shape: [usize; 4],
        input: &[f32],
        read: impl FnOnce(&[i64], &[f32]) -> Result<R, InferError>,
    ) -> Result<R, InferError> {
        let run_err = |reason: String| InferError::Run { path: path.to_path_buf(), reason };
        match &mut self.inner {
            #[cfg(feature = "ort")]
            Inner::Ort(session) => {
                let tensor =
                    ort::value::TensorRef::from_array_view((shape, input)).map_err(|e| run_err(e.to_string()))?;
                let outputs = session.run(ort::inputs![tensor]).map_err(|e| run_err(e.to_string()))?;
                let (oshape, data) = outputs[0].try_extract_tensor::<f32>().map_err(|e| run_err(e.to_string()))?;
                read(oshape, data)
            }
            #[cfg(feature = "tract")]
            Inner::Tract(g) => {
                let out = g.run(shape, input).map_err(run_err)?;
                let dims: Vec<i64> = out.shape().iter().map(|&d| d as i64).collect();
                let view = out.try_as_plain_ram().map_err(|e| run_err(format!("output: {e:#}")))?;
                let data = view.as_slice::<f32>().map_err(|e| run_err(format!("output is not float32: {e:#}")))?;
                read(&dims, data)
            }
        }
    }
}

#[cfg(feature = "ort")]
mod ort_backend {
    use std::path::Path;

    use ort::session::Session;
    use ort::session::builder::GraphOptimizationLevel;
    use ort::value::ValueType;

    use super::{Inner, Opened, Outlet};
    use crate::infer::InferError;
    use crate::infer::runtime::{SessionOptions, environment};

    pub(super) fn open(path: &Path, bytes: &[u8], opts: SessionOptions) -> Result<Opened, InferError> {
        let model_err = |reason: String| InferError::ModelFile { path: path.to_path_buf(), reason };
        let env = environment()?;
        let mut builder = Session::builder(env)
            .map_err(|e| model_err(e.to_string()))?
            .with_optimization_level(GraphOptimizationLevel::All)
            .map_err(|e| model_err(e.to_string()))?;
        if opts.intra_threads > 0 {
            builder = builder.with_intra_threads(opts.intra_threads).map_err(|e| model_err(e.to_string()))?;
        }
        builder = builder.with_intra_op_spinning(opts.spin).map_err(|e| model_err(e.to_string()))?;
        let session =
            builder.commit_from_memory(bytes).map_err(|e| model_err(format!("not a loadable ONNX model: {e}")))?;
        let outlet = |name: &str, ty: &ValueType| Outlet { name: name.to_string(), shape: float_shape(ty) };
        let inputs = session.inputs().iter().map(|o| outlet(o.name(), o.dtype())).collect();
        let outputs = session.outputs().iter().map(|o| outlet(o.name(), o.dtype())).collect();
        Ok((Inner::Ort(session), inputs, outputs))
    }

    fn float_shape(ty: &ValueType) -> Result<Vec<i64>, String> {
        match ty {
            ValueType::Tensor { ty, shape, .. } if *ty == ort::value::TensorElementType::Float32 => {
                Ok(shape.iter().copied().collect())
            }
            other => Err(format!("{other:?}")),
        }
    }
}

#[cfg(feature = "tract")]
mod tract {
    use std::path::Path;

    use tract_onnx::prelude::*;
    use tract_onnx::tract_core::plan::SimpleState;
    use tract_onnx::tract_hir::infer::Factoid;

    use tract_linalg::multithread::{Executor, multithread_tract_scope};

    use super::{Inner, Opened, Outlet};
    use crate::infer::InferError;
    use crate::infer::runtime::SessionOptions;

    type Plan = Arc<TypedRunnableModel>;

    /// The parsed graph, its plan for one input shape once [`Graph::plan`] ran, and the threads its
    /// matrix products run on.
    pub(super) struct Graph {
        model: Option<InferenceModel>,
        plan: Option<Planned>,
        executor: Executor,
    }

    /// A plan for one input shape and the run state kept across runs (tract builds the per-node
    /// states again for every run of a bare plan).
    struct Planned {
        shape: TVec<usize>,
        plan: Plan,
        state: TypedSimpleState,
    }

    /// The threads of `opts` as a tract executor: one thread runs on the caller's; more get a pool
    /// of their own per model, as ONNX Runtime's sessions do (0: one per core).
    fn executor(opts: SessionOptions) -> Result<Executor, String> {
        let n = match opts.intra_threads {
            0 => std::thread::available_parallelism().map_or(1, usize::from),
            n => n,
        };
        if n <= 1 {
            return Ok(Executor::SingleThread);
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .thread_name(|i| format!("fme-tract-{i}"))
            .build()
            .map(|pool| Executor::MultiThread(Arc::new(pool)))
            .map_err(|e| format!("cannot start {n} inference threads: {e}"))
    }

    pub(super) fn open(path: &Path, bytes: &[u8], opts: SessionOptions) -> Result<Opened, InferError> {
        let model_err = |reason: String| InferError::ModelFile { path: path.to_path_buf(), reason };
        let executor = executor(opts).map_err(model_err)?;
        let model = tract_onnx::onnx()
            .model_for_read(&mut &bytes[..])
            .map_err(|e| model_err(format!("not a loadable ONNX model: {e:#}")))?;
        let name = |o: &OutletId| model.node(o.node).name.clone();
        let outlet = |o: &OutletId| -> Result<Outlet, InferError> {
            let fact = model.outlet_fact(*o).map_err(|e| model_err(format!("{e:#}")))?;
            Ok(Outlet { name: name(o), shape: float_shape(fact) })
        };
        let inputs = model.inputs.iter().map(outlet).collect::<Result<Vec<_>, _>>()?;
        let outputs = model.outputs.iter().map(outlet).collect::<Result<Vec<_>, _>>()?;
        let graph = Graph { model: Some(model), plan: None, executor };
        Ok((Inner::Tract(graph), inputs, outputs))
    }

    fn float_shape(fact: &InferenceFact) -> Result<Vec<i64>, String> {
        match fact.datum_type.concretize() {
            Some(DatumType::F32) => {}
            Some(other) => return Err(format!("{other:?} tensor")),
            None => return Err("tensor of unknown element type".into()),
        }
        if fact.shape.is_open() {
            return Err("float32 tensor of unknown rank".into());
        }
        Ok(fact.shape.dims().map(|d| d.concretize().and_then(|d| d.to_i64().ok()).unwrap_or(-1)).collect())
    }

    fn typed_shape(fact: &TypedFact) -> Result<Vec<i64>, String> {
        if fact.datum_type != DatumType::F32 {
            return Err(format!("{:?} tensor", fact.datum_type));
        }
        Ok(fact.shape.iter().map(|d| d.to_i64().unwrap_or(-1)).collect())
    }

    impl Graph {
        /// Plans and optimises the graph for `shape`; once planned, another shape is an error.
        pub(super) fn plan(&mut self, shape: [usize; 4]) -> Result<(), String> {
            if let Some(planned) = &self.plan {
                return if planned.shape[..] == shape[..] {
                    Ok(())
                } else {
                    Err(format!("planned for input {:?}, asked for {shape:?}", planned.shape))
                };
            }
            let Some(model) = self.model.take() else {
                return Err("graph lost after a failed plan".into());
            };
            let plan = model
                .with_input_fact(0, f32::fact(shape).into())
                .and_then(|m| m.into_optimized())
                .and_then(|m| m.into_runnable())
                .map_err(|e| format!("tract cannot run this graph: {e:#}"))?;
            let state = SimpleState::new(&plan).map_err(|e| format!("tract cannot run this graph: {e:#}"))?;
            self.plan = Some(Planned { shape: shape.into(), plan, state });
            Ok(())
        }

        /// The planned graph's output shapes.
        pub(super) fn outputs(&self) -> Result<Vec<Result<Vec<i64>, String>>, String> {
            let Some(planned) = &self.plan else {
                return Err("the graph is not planned".into());
            };
            let model = planned.plan.model();
            (0..model.outputs.len())
                .map(|ix| model.output_fact(ix).map(typed_shape).map_err(|e| format!("{e:#}")))
                .collect()
        }

        /// Runs the planned graph on `input`; returns the first output.
        pub(super) fn run(&mut self, shape: [usize; 4], input: &[f32]) -> Result<TValue, String> {
            self.plan(shape)?;
            let Some(planned) = &mut self.plan else {
                return Err("no plan".into());
            };
            let tensor = Tensor::from_shape(&shape, input).map_err(|e| format!("input tensor: {e:#}"))?;
            let state = &mut planned.state;
            let mut out = multithread_tract_scope(self.executor.clone(), || state.run(tvec!(tensor.into())))
                .map_err(|e| format!("{e:#}"))?;
            if out.is_empty() {
                return Err("the graph has no output".into());
            }
            Ok(out.swap_remove(0))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn version_names_the_backend_and_the_models() {
        assert!(VERSION.starts_with(env!("CARGO_PKG_VERSION")), "{VERSION}");
        assert!(VERSION.contains(BUILD) && BUILD.contains(Backend::DEFAULT.name()), "{VERSION}");
        assert_eq!(BUILD.ends_with(", embedded"), !super::super::embedded::MODELS.is_empty(), "{BUILD}");
        for model in [crate::infer::config::DEFAULT_DETECTOR_MODEL, crate::infer::config::DEFAULT_DEPTH_MODEL] {
            let bytes = std::fs::read(Path::new(crate::REPO_DIR).join(model)).expect("bundled model");
            let form = ModelForm::of_onnx(&bytes);
            assert!(BUILD.contains(&format!("default models {form}")), "{BUILD} but {model} is {form}");
        }
        assert_eq!(Backend::ALL.first(), Some(&Backend::DEFAULT));
    }

    #[test]
    fn a_missing_model_file_is_named() {
        let e = model_bytes(Path::new("/nonexistent/fme/det.onnx")).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/fme/det.onnx") && e.contains("cannot read"), "{e}");
        let dir = tempfile::tempdir().expect("tempdir");
        let empty = dir.path().join("empty.onnx");
        std::fs::write(&empty, b"").expect("write");
        let e = model_bytes(&empty).unwrap_err().to_string();
        assert!(e.contains("empty.onnx") && e.contains("empty"), "{e}");
    }

    #[test]
    fn a_file_that_is_not_onnx_is_refused_by_every_backend() {
        let dir = tempfile::tempdir().expect("tempdir");
        let junk = dir.path().join("junk.onnx");
        std::fs::write(&junk, b"this is not a protobuf").expect("write");
        for &b in Backend::ALL {
            match Model::open(&junk, SessionOptions::default(), b) {
                Err(InferError::ModelFile { path, reason }) => {
                    assert_eq!(path, junk);
                    assert!(reason.contains("not a loadable ONNX model"), "{b}: {reason}");
                }
                Err(InferError::Library { .. }) => {} // ONNX Runtime not installed: named elsewhere.
                other => panic!("{b}: {other:?}"),
            }
        }
    }
}
