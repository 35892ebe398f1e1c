//! The crate's one error type.

use std::path::PathBuf;

/// Everything that can go wrong in perception. Messages name the field or file and the bad value.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PerceptionError {
    /// The ONNX Runtime shared library is not where we looked.
    #[error(
        "ONNX Runtime library not found at {path} (from {source_of_path}); run `scripts/setup-ort.sh` \
         in the workspace root to install it (onnxruntime==1.31.1 from PyPI into .ort/libonnxruntime.so), \
         or set ORT_DYLIB_PATH to an existing libonnxruntime.so"
    )]
    RuntimeLibraryMissing {
        /// Where we looked.
        path: PathBuf,
        /// Which setting gave that path (config field, environment variable or default).
        source_of_path: &'static str,
    },
    /// The ONNX Runtime library exists but could not be loaded (wrong version, wrong architecture).
    #[error("failed to load the ONNX Runtime library {path}: {message}")]
    RuntimeLibraryLoad {
        /// The library file.
        path: PathBuf,
        /// What the loader said.
        message: String,
    },
    /// The model file does not exist or cannot be read.
    #[error("cannot read model_path {path}: {message}")]
    ModelRead {
        /// The configured model path.
        path: PathBuf,
        /// The I/O error.
        message: String,
    },
    /// The model does not have the expected inputs and outputs.
    #[error("model {path} is not a segmentation model this crate can run: {message}")]
    ModelShape {
        /// The configured model path.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A configuration value is out of range.
    #[error("invalid config field `{field}` = {value}: {reason}")]
    InvalidConfig {
        /// The field name, e.g. `intra_threads`.
        field: &'static str,
        /// The bad value, as text.
        value: String,
        /// Why it is rejected.
        reason: &'static str,
    },
    /// An image could not be decoded.
    #[error("cannot decode {format} image: {message}")]
    Decode {
        /// The declared format (`png`, `jpeg`, `rgb8`).
        format: String,
        /// What the decoder said.
        message: String,
    },
    /// An image, mask or camera has a bad size or layout.
    #[error("invalid `{field}` = {value}: {reason}")]
    InvalidInput {
        /// The field name, e.g. `raw.step`.
        field: &'static str,
        /// The bad value, as text.
        value: String,
        /// Why it is rejected.
        reason: String,
    },
    /// ONNX Runtime failed while building a session or running the model.
    #[error("ONNX Runtime error while {stage}: {message}")]
    Runtime {
        /// What we were doing, e.g. "running the model".
        stage: &'static str,
        /// What ONNX Runtime said.
        message: String,
    },
}

impl PerceptionError {
    pub(crate) fn runtime(stage: &'static str, err: impl std::fmt::Display) -> Self {
        Self::Runtime {
            stage,
            message: err.to_string(),
        }
    }

    pub(crate) fn invalid_input(
        field: &'static str,
        value: impl std::fmt::Display,
        reason: impl Into<String>,
    ) -> Self {
        Self::InvalidInput {
            field,
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}
