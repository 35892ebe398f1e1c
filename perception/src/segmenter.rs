//! The ONNX Runtime segmentation session.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use image::RgbImage;
use ort::environment::Environment;
use ort::logging::LogLevel;
use ort::session::builder::{GraphOptimizationLevel, SessionBuilder};
use ort::session::{HasSelectedOutputs, OutputSelector, RunOptions, Session};
use ort::value::{TensorElementType, TensorRef};
use sha2::{Digest, Sha256};

use crate::{ClassMask, NUM_CLASSES, PerceptionError, decode::preprocess};

/// The model path the service uses when none is configured (relative to the working directory).
pub const DEFAULT_MODEL_PATH: &str = "models/rooftop-segmentation.onnx";

/// The input size used when neither the config nor the model's metadata gives one.
pub const DEFAULT_INPUT_SIZE: (u32, u32) = (256, 192);

/// The environment variable naming the ONNX Runtime library; it wins over the default location.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

/// Where ONNX Runtime runs the model; `"cpu"` or `"cuda"` in a config file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[non_exhaustive]
pub enum ExecutionProvider {
    /// The CPU (always available).
    #[default]
    Cpu,
    /// NVIDIA CUDA. Falls back to the CPU, with a logged warning, when the CUDA provider cannot be
    /// registered (no GPU, no CUDA libraries, or this crate built without its `cuda` feature).
    Cuda,
}

impl ExecutionProvider {
    /// `"cpu"` or `"cuda"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Cpu => "cpu",
            Self::Cuda => "cuda",
        }
    }
}

impl std::fmt::Display for ExecutionProvider {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// The least severe of ONNX Runtime's own log messages that reach the `tracing` logs (target
/// `ort`). ONNX Runtime writes about 200 INFO lines while it loads a model, so the default is
/// [`OrtLogLevel::Warning`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default)]
#[non_exhaustive]
pub enum OrtLogLevel {
    /// Everything, graph transformations included.
    Verbose,
    /// Session and provider set-up as well.
    Info,
    /// Only what may need attention (the default).
    #[default]
    Warning,
    /// Only failures.
    Error,
    /// Only failures that end the runtime.
    Fatal,
}

impl OrtLogLevel {
    /// Every level, most verbose first.
    pub const ALL: [Self; 5] = [
        Self::Verbose,
        Self::Info,
        Self::Warning,
        Self::Error,
        Self::Fatal,
    ];

    /// `"verbose"`, `"info"`, `"warning"`, `"error"` or `"fatal"`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Verbose => "verbose",
            Self::Info => "info",
            Self::Warning => "warning",
            Self::Error => "error",
            Self::Fatal => "fatal",
        }
    }
}

impl std::fmt::Display for OrtLogLevel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for OrtLogLevel {
    type Err = PerceptionError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.trim().to_ascii_lowercase();
        let name = if lower == "warn" { "warning" } else { &lower };
        Self::ALL
            .into_iter()
            .find(|l| l.as_str() == name)
            .ok_or_else(|| PerceptionError::InvalidConfig {
                field: "ort_log_level",
                value: format!("{s:?}"),
                reason: "expected \"verbose\", \"info\", \"warning\", \"error\" or \"fatal\"",
            })
    }
}

/// Written as [`OrtLogLevel::as_str`] says; read as [`str::parse`] does ("warn" and any case
/// too), so a config file names a level as a log line would.
impl serde::Serialize for OrtLogLevel {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> serde::Deserialize<'de> for OrtLogLevel {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = <String as serde::Deserialize>::deserialize(deserializer)?;
        name.parse().map_err(serde::de::Error::custom)
    }
}

impl From<LogLevel> for OrtLogLevel {
    fn from(level: LogLevel) -> Self {
        match level {
            LogLevel::Verbose => Self::Verbose,
            LogLevel::Info => Self::Info,
            LogLevel::Warning => Self::Warning,
            LogLevel::Error => Self::Error,
            LogLevel::Fatal => Self::Fatal,
        }
    }
}

impl From<OrtLogLevel> for LogLevel {
    fn from(level: OrtLogLevel) -> Self {
        match level {
            OrtLogLevel::Verbose => Self::Verbose,
            OrtLogLevel::Info => Self::Info,
            OrtLogLevel::Warning => Self::Warning,
            OrtLogLevel::Error => Self::Error,
            OrtLogLevel::Fatal => Self::Fatal,
        }
    }
}

/// How to build a [`Segmenter`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SegmenterConfig {
    /// The ONNX model: float32 NCHW input, uint8 class-id output (see `models/MODEL_CARD.md`).
    pub model_path: PathBuf,
    /// CPU (default) or CUDA.
    pub execution_provider: ExecutionProvider,
    /// Threads ONNX Runtime uses inside one inference (1..=64); more than one spin between
    /// operators. Default 1: a server gets its parallelism from several frames at once, and
    /// sessions whose threads together outnumber the cores run slower than one thread each.
    pub intra_threads: usize,
    /// The ONNX Runtime library. `None`: `ORT_DYLIB_PATH`, else `.ort/libonnxruntime.so` in the
    /// working directory or the workspace root (filled by `scripts/setup-ort.sh`).
    pub ort_library: Option<PathBuf>,
    /// Model input `(width, height)`, each in 32..=4096 (the graph takes any size; multiples
    /// of 32 waste nothing). `None`: the model's metadata
    /// (`input_width`/`input_height`), else [`DEFAULT_INPUT_SIZE`].
    pub input_size: Option<(u32, u32)>,
    /// The least severe ONNX Runtime log message passed on. The runtime is loaded once per
    /// process and its level is process-wide: the last segmenter built sets it.
    pub ort_log_level: OrtLogLevel,
}

impl Default for SegmenterConfig {
    fn default() -> Self {
        Self {
            model_path: PathBuf::from(DEFAULT_MODEL_PATH),
            execution_provider: ExecutionProvider::Cpu,
            intra_threads: 1,
            ort_library: None,
            input_size: None,
            ort_log_level: OrtLogLevel::default(),
        }
    }
}

impl SegmenterConfig {
    /// Checks the values that can be checked without loading anything.
    pub fn validate(&self) -> Result<(), PerceptionError> {
        if !(1..=64).contains(&self.intra_threads) {
            return Err(PerceptionError::InvalidConfig {
                field: "intra_threads",
                value: self.intra_threads.to_string(),
                reason: "must be in 1..=64",
            });
        }
        if let Some((w, h)) = self.input_size
            && (!(32..=4096).contains(&w) || !(32..=4096).contains(&h))
        {
            return Err(PerceptionError::InvalidConfig {
                field: "input_size",
                value: format!("{w}x{h}"),
                reason: "width and height must be in 32..=4096",
            });
        }
        if self.model_path.as_os_str().is_empty() {
            return Err(PerceptionError::InvalidConfig {
                field: "model_path",
                value: "\"\"".to_owned(),
                reason: "must name an .onnx file",
            });
        }
        Ok(())
    }
}

/// What a [`Segmenter`] runs, for logs and the service's info call.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModelInfo {
    /// The model's name (its `name` metadata, else the file stem).
    pub name: String,
    /// Lower-case hex SHA-256 of the model file.
    pub sha256: String,
    /// Where the model was loaded from.
    pub path: PathBuf,
    /// Model input width, pixels.
    pub input_width: u32,
    /// Model input height, pixels.
    pub input_height: u32,
    /// The provider actually in use (CPU when CUDA was asked for but is unavailable).
    pub execution_provider: ExecutionProvider,
    /// Intra-op threads.
    pub intra_threads: usize,
    /// The ONNX Runtime library in use.
    pub ort_library: PathBuf,
}

/// A loaded segmentation model. `Send + Sync`: share it in an `Arc`; calls to [`Segmenter::segment`]
/// run one at a time per `Segmenter` (build several for parallel inference).
pub struct Segmenter {
    session: Mutex<Loaded>,
    info: ModelInfo,
}

/// The session and the options of a run for the class ids alone (ONNX Runtime then skips any
/// other output a graph may have).
struct Loaded {
    session: Session,
    classes_only: RunOptions<HasSelectedOutputs>,
}

impl std::fmt::Debug for Segmenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Segmenter")
            .field("info", &self.info)
            .finish()
    }
}

impl Segmenter {
    /// Loads ONNX Runtime (once per process) and the model, and checks the model's signature.
    pub fn new(config: &SegmenterConfig) -> Result<Self, PerceptionError> {
        config.validate()?;
        let (library, env) = environment(config.ort_library.as_deref(), config.ort_log_level)?;
        let bytes = std::fs::read(&config.model_path).map_err(|e| PerceptionError::ModelRead {
            path: config.model_path.clone(),
            message: e.to_string(),
        })?;
        let sha256 = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>();

        let (session, provider) = build_session(config, &env, &bytes)?;
        check_signature(&session, &config.model_path)?;

        let metadata = session.metadata().ok();
        let custom = |key: &str| metadata.as_ref().and_then(|m| m.custom(key));
        let name = custom("name").unwrap_or_else(|| {
            config
                .model_path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
        let metadata_size = custom("input_width")
            .zip(custom("input_height"))
            .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)));
        let (input_width, input_height) = config
            .input_size
            .or(metadata_size)
            .unwrap_or(DEFAULT_INPUT_SIZE);
        drop(metadata);

        let info = ModelInfo {
            name,
            sha256,
            path: config.model_path.clone(),
            input_width,
            input_height,
            execution_provider: provider,
            intra_threads: config.intra_threads,
            ort_library: library,
        };
        tracing::info!(
            model = %info.name,
            sha256 = %info.sha256,
            provider = %info.execution_provider,
            threads = info.intra_threads,
            input = %format!("{}x{}", info.input_width, info.input_height),
            "segmentation model loaded"
        );
        let classes = session.outputs()[0].name().to_owned();
        let classes_only = RunOptions::new()
            .map_err(|e| PerceptionError::runtime("creating the run options", e))?
            .with_outputs(OutputSelector::no_default().with(classes));
        Ok(Self {
            session: Mutex::new(Loaded {
                session,
                classes_only,
            }),
            info,
        })
    }

    /// What is loaded and where it runs.
    pub fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// Segments one image: resize and normalise to the model input, run the model, and return the
    /// class mask at model resolution (`info().input_width × input_height`).
    pub fn segment(&self, image: &RgbImage) -> Result<ClassMask, PerceptionError> {
        self.segment_at(image, self.info.input_width, self.info.input_height)
    }

    /// Like [`Segmenter::segment`] with the image resized to `width × height` for the model
    /// (the graph takes any size; the mask comes out at that size).
    pub fn segment_at(
        &self,
        image: &RgbImage,
        width: u32,
        height: u32,
    ) -> Result<ClassMask, PerceptionError> {
        check_not_empty(image)?;
        self.run(&preprocess(image, width, height), width, height)
    }

    /// Runs the model on an already preprocessed NCHW float32 tensor of `3 * height * width`
    /// values (see [`crate::preprocess`]). Exposed for benchmarks that time the stages apart.
    pub fn run(
        &self,
        input: &[f32],
        width: u32,
        height: u32,
    ) -> Result<ClassMask, PerceptionError> {
        let expected = 3 * width as usize * height as usize;
        if input.len() != expected || width == 0 || height == 0 {
            return Err(PerceptionError::invalid_input(
                "input",
                format!("{} values", input.len()),
                format!("a 3x{height}x{width} tensor has {expected}"),
            ));
        }
        let tensor =
            TensorRef::from_array_view(([1usize, 3, height as usize, width as usize], input))
                .map_err(|e| PerceptionError::runtime("creating the input tensor", e))?;
        // A poisoned lock only means another inference panicked; the session itself is intact.
        let mut loaded = self
            .session
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Loaded {
            session,
            classes_only,
        } = &mut *loaded;
        let outputs = session
            .run_with_options(ort::inputs![tensor], classes_only)
            .map_err(|e| PerceptionError::runtime("running the model", e))?;
        let (shape, data) = outputs[0]
            .try_extract_tensor::<u8>()
            .map_err(|e| PerceptionError::runtime("reading the model output", e))?;
        let dims: &[i64] = shape;
        let (out_h, out_w) = match dims {
            [1, h, w] | [1, 1, h, w] => (*h, *w),
            _ => {
                return Err(PerceptionError::ModelShape {
                    path: self.info.path.clone(),
                    message: format!("output shape {dims:?}, expected [1, H, W]"),
                });
            }
        };
        let (out_w, out_h) = (
            u32::try_from(out_w).unwrap_or(0),
            u32::try_from(out_h).unwrap_or(0),
        );
        ClassMask::new(out_w, out_h, data.to_vec()).map_err(|e| PerceptionError::ModelShape {
            path: self.info.path.clone(),
            message: format!("output is not a class mask: {e}"),
        })
    }
}

/// Finds the ONNX Runtime library: the config field, `ORT_DYLIB_PATH`, `.ort/libonnxruntime.so` in
/// the working directory, `.ort/libonnxruntime.so` in the workspace root, in that order. A missing
/// file is an error that says how to install it.
pub fn resolve_ort_library(configured: Option<&Path>) -> Result<PathBuf, PerceptionError> {
    let (path, source_of_path) = if let Some(p) = configured {
        (p.to_path_buf(), "config field ort_library")
    } else if let Some(p) = std::env::var_os(ORT_DYLIB_ENV).filter(|v| !v.is_empty()) {
        (PathBuf::from(p), "environment variable ORT_DYLIB_PATH")
    } else {
        let local = PathBuf::from(".ort/libonnxruntime.so");
        if local.is_file() {
            (local, "default location .ort/ in the working directory")
        } else {
            (
                workspace_root().join(".ort/libonnxruntime.so"),
                "default location .ort/ in the workspace root",
            )
        }
    };
    if path.is_file() {
        Ok(path)
    } else {
        Err(PerceptionError::RuntimeLibraryMissing {
            path,
            source_of_path,
        })
    }
}

/// The workspace root this crate was built in (the parent of the crate's manifest directory).
pub fn workspace_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().unwrap_or(manifest).to_path_buf()
}

/// ONNX Runtime can be loaded once per process; the environment is shared by all sessions.
static ENVIRONMENT: OnceLock<(PathBuf, Environment)> = OnceLock::new();
static ENVIRONMENT_INIT: Mutex<()> = Mutex::new(());

fn environment(
    configured: Option<&Path>,
    level: OrtLogLevel,
) -> Result<(PathBuf, Environment), PerceptionError> {
    ORT_LOG_LEVEL.store(level as u8, Ordering::Relaxed);
    if let Some((loaded, env)) = ENVIRONMENT.get() {
        env.set_log_level(level.into());
        if let Some(asked) = configured
            && asked != loaded
        {
            tracing::warn!(
                asked = %asked.display(),
                loaded = %loaded.display(),
                "ONNX Runtime is already loaded from another file; the configured ort_library is ignored"
            );
        }
        return Ok((loaded.clone(), env.clone()));
    }
    let _guard = ENVIRONMENT_INIT
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some((loaded, env)) = ENVIRONMENT.get() {
        env.set_log_level(level.into());
        return Ok((loaded.clone(), env.clone()));
    }
    let library = resolve_ort_library(configured)?;
    // `init_from` (unlike `init`) reports a bad library as an error instead of panicking.
    let env = ort::init_from(&library)
        .map_err(|e| PerceptionError::RuntimeLibraryLoad {
            path: library.clone(),
            message: e.to_string(),
        })?
        .with_name("landing-perception")
        .with_telemetry(false)
        .with_logger(Arc::new(forward_ort_log))
        .build()
        .map_err(|e| PerceptionError::RuntimeLibraryLoad {
            path: library.clone(),
            message: e.to_string(),
        })?;
    // The environment is created passing on every message, verbose ones included; from here
    // on ONNX Runtime drops those below the level itself.
    env.set_log_level(level.into());
    let _ = ENVIRONMENT.set((library.clone(), env.clone()));
    Ok((library, env))
}

/// The least severe ONNX Runtime message passed on (an [`OrtLogLevel`] as `u8`): process-wide,
/// like the runtime.
static ORT_LOG_LEVEL: AtomicU8 = AtomicU8::new(OrtLogLevel::Warning as u8);

/// ONNX Runtime's logger: passes its messages at or above [`ORT_LOG_LEVEL`] to `tracing` (target
/// `ort::logging`, as ort's own forwarding names it). It filters itself because the runtime
/// logs while its environment is created, before it can be told a level.
fn forward_ort_log(level: LogLevel, _category: &str, id: &str, location: &str, message: &str) {
    let level = OrtLogLevel::from(level);
    if (level as u8) < ORT_LOG_LEVEL.load(Ordering::Relaxed) {
        return;
    }
    const TARGET: &str = "ort::logging";
    match level {
        OrtLogLevel::Verbose => tracing::trace!(target: TARGET, id, location, "{message}"),
        OrtLogLevel::Info => tracing::info!(target: TARGET, id, location, "{message}"),
        OrtLogLevel::Warning => tracing::warn!(target: TARGET, id, location, "{message}"),
        OrtLogLevel::Error => tracing::error!(target: TARGET, id, location, "{message}"),
        OrtLogLevel::Fatal => tracing::error!(target: TARGET, id, location, "(fatal) {message}"),
    }
}

fn base_builder(
    config: &SegmenterConfig,
    env: &Environment,
) -> Result<SessionBuilder, PerceptionError> {
    let stage = "configuring the session";
    Session::builder(env)
        .map_err(|e| PerceptionError::runtime(stage, e))?
        .with_optimization_level(GraphOptimizationLevel::All)
        .map_err(|e| PerceptionError::runtime(stage, e))?
        .with_intra_threads(config.intra_threads)
        .map_err(|e| PerceptionError::runtime(stage, e))?
        .with_inter_threads(1)
        .map_err(|e| PerceptionError::runtime(stage, e))?
        // A pool's threads spin between the model's operators: without it a second thread
        // sleeps through most of them and gains nothing (320×240 one frame at a time: 8.6 ms
        // on one thread, 8.6 ms on two without spinning, 4.7 ms with it; BENCHMARKS.md). Spinning
        // pools that outnumber the cores steal them from each other (`intra_threads`).
        .with_intra_op_spinning(config.intra_threads > 1)
        .map_err(|e| PerceptionError::runtime(stage, e))?
        .with_inter_op_spinning(false)
        .map_err(|e| PerceptionError::runtime(stage, e))?
        .with_log_level(config.ort_log_level.into())
        .map_err(|e| PerceptionError::runtime(stage, e))
}

fn build_session(
    config: &SegmenterConfig,
    env: &Environment,
    model: &[u8],
) -> Result<(Session, ExecutionProvider), PerceptionError> {
    let commit = |mut builder: SessionBuilder| {
        builder
            .commit_from_memory(model)
            .map_err(|e| PerceptionError::ModelShape {
                path: config.model_path.clone(),
                message: format!("ONNX Runtime cannot load it: {e}"),
            })
    };
    match config.execution_provider {
        ExecutionProvider::Cpu => Ok((commit(base_builder(config, env)?)?, ExecutionProvider::Cpu)),
        ExecutionProvider::Cuda => match cuda_builder(config, env) {
            Ok(builder) => Ok((commit(builder)?, ExecutionProvider::Cuda)),
            Err(reason) => {
                tracing::warn!(
                    %reason,
                    "CUDA execution provider unavailable; falling back to the CPU"
                );
                Ok((commit(base_builder(config, env)?)?, ExecutionProvider::Cpu))
            }
        },
    }
}

#[cfg(feature = "cuda")]
fn cuda_builder(config: &SegmenterConfig, env: &Environment) -> Result<SessionBuilder, String> {
    let builder = base_builder(config, env).map_err(|e| e.to_string())?;
    builder
        .with_execution_providers([ort::ep::CUDA::default().build().error_on_failure()])
        .map_err(|e| e.to_string())
}

#[cfg(not(feature = "cuda"))]
fn cuda_builder(_config: &SegmenterConfig, _env: &Environment) -> Result<SessionBuilder, String> {
    Err("landing-perception was built without its `cuda` feature".to_owned())
}

fn check_not_empty(image: &RgbImage) -> Result<(), PerceptionError> {
    if image.width() == 0 || image.height() == 0 {
        return Err(PerceptionError::invalid_input(
            "image.size",
            format!("{}x{}", image.width(), image.height()),
            "must not be empty",
        ));
    }
    Ok(())
}

/// Checks the model's input and its first output (the class ids).
fn check_signature(session: &Session, path: &Path) -> Result<(), PerceptionError> {
    let bad = |message: String| PerceptionError::ModelShape {
        path: path.to_path_buf(),
        message,
    };
    let inputs = session.inputs();
    let outputs = session.outputs();
    if inputs.len() != 1 || outputs.is_empty() {
        return Err(bad(format!(
            "{} inputs and {} outputs, expected 1 input and at least 1 output",
            inputs.len(),
            outputs.len()
        )));
    }
    let input = inputs[0].dtype();
    if input.tensor_type() != Some(TensorElementType::Float32)
        || input.tensor_shape().map(|s| s.len()) != Some(4)
    {
        return Err(bad(format!(
            "input `{}` is {input:?}, expected a float32 NCHW tensor",
            inputs[0].name()
        )));
    }
    if let Some(channels) = input.tensor_shape().map(|s| s[1])
        && channels != 3
        && channels != -1
    {
        return Err(bad(format!(
            "input has {channels} channels, expected 3 (RGB)"
        )));
    }
    let output = outputs[0].dtype();
    if output.tensor_type() != Some(TensorElementType::Uint8) {
        return Err(bad(format!(
            "output `{}` is {output:?}, expected uint8 class ids (argmax inside the graph; \
             {NUM_CLASSES} classes)",
            outputs[0].name()
        )));
    }
    Ok(())
}
