//! The one error type of this crate. `status.rs` maps every variant to a gRPC status.

use std::time::Duration;

use landing_geometry::GeometryError;

/// A field of a request that failed validation, named by its path in the request
/// (`frame.point_cloud.data`, `options.min_normal_dot`, ...).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldViolation {
    /// Path of the field, dot-separated, with `[i]` for repeated fields.
    pub field: String,
    /// Why the value is wrong, with the value.
    pub description: String,
}

impl FieldViolation {
    /// A violation of `field`.
    pub fn new(field: impl Into<String>, description: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            description: description.into(),
        }
    }
}

/// Everything that can go wrong in the server, the offline command and their inputs.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A request field is invalid (one or more violations, each naming its field).
    #[error("invalid request: {}", describe(.0))]
    InvalidArgument(Vec<FieldViolation>),
    /// The frame asked for model segmentation but the server has no model loaded.
    #[error("segmentation mode MODEL was requested but {0}")]
    ModelUnavailable(String),
    /// Segmentation failed inside the model runtime.
    #[error("segmentation failed: {0}")]
    Segmentation(String),
    /// The geometry pipeline rejected its input or parameters.
    #[error("geometry: {0}")]
    Geometry(GeometryError),
    /// Admission control: the server is at capacity; retry after the given delay.
    #[error("server at capacity ({capacity}); retry in {retry_after:?}")]
    Overloaded {
        capacity: Capacity,
        retry_after: Duration,
    },
    /// A request message is larger than `server.max_request_bytes`; resending it cannot succeed.
    #[error("request of {bytes} bytes exceeds server.max_request_bytes = {limit}")]
    RequestTooLarge { bytes: u64, limit: u64 },
    /// The caller's deadline passed before the frame's result was ready.
    #[error("the caller's deadline passed before the frame's result was ready")]
    DeadlineExceeded,
    /// The caller went away.
    #[error("the call was cancelled")]
    Cancelled,
    /// The server is draining for shutdown and takes no new frames.
    #[error("the server is shutting down")]
    ShuttingDown,
    /// The landing-site catalog cannot answer: it is off (`catalog.enabled = false`), its
    /// database cannot be reached, or it holds data this build cannot read.
    #[error("the landing-site catalog is unavailable: {0}")]
    CatalogUnavailable(String),
    /// No or wrong bearer token.
    #[error("missing or invalid bearer token")]
    Unauthenticated,
    /// A bug or a crashed worker; never the caller's fault.
    #[error("internal error: {0}")]
    Internal(String),
    /// A configuration key has a bad value or is unknown.
    #[error("config key `{key}`: {reason}")]
    Config { key: String, reason: String },
    /// A file could not be read.
    #[error("cannot read `{path}`: {reason}")]
    Io { path: String, reason: String },
    /// A PLY file could not be parsed (the reason names the header line, or the element, row and
    /// property, that is wrong).
    #[error("`{path}`: {reason}")]
    Ply { path: String, reason: String },
}

impl Error {
    /// One invalid field.
    pub fn invalid(field: impl Into<String>, description: impl Into<String>) -> Self {
        Self::InvalidArgument(vec![FieldViolation::new(field, description)])
    }

    /// A bad configuration key.
    pub fn config(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Config {
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// A [`landing_recording::ply::PlyError`] for the file at `path`: [`Error::Io`] when the file could
    /// not be read, [`Error::Ply`] when its contents are not a usable PLY.
    pub fn from_ply(path: &std::path::Path, error: landing_recording::ply::PlyError) -> Self {
        let path = path.display().to_string();
        match error {
            landing_recording::ply::PlyError::Io { source, .. } => Self::Io {
                path,
                reason: source.to_string(),
            },
            other => Self::Ply {
                path,
                reason: other.to_string(),
            },
        }
    }
}

impl From<landing_catalog::Error> for Error {
    /// A bad search field stays the caller's (named as the request names it); every storage
    /// failure makes the catalog unavailable.
    fn from(e: landing_catalog::Error) -> Self {
        match e {
            landing_catalog::Error::InvalidArgument { field, reason } => {
                Self::invalid(field, reason)
            }
            landing_catalog::Error::Storage { .. } | landing_catalog::Error::Corrupt { .. } => {
                Self::CatalogUnavailable(e.to_string())
            }
            // The catalog's error is #[non_exhaustive] in another crate: a failure it adds later
            // is a storage one until it is told apart here.
            _ => Self::CatalogUnavailable(e.to_string()),
        }
    }
}

impl From<GeometryError> for Error {
    fn from(e: GeometryError) -> Self {
        Self::Geometry(e)
    }
}

fn describe(violations: &[FieldViolation]) -> String {
    violations
        .iter()
        .map(|v| format!("`{}`: {}", v.field, v.description))
        .collect::<Vec<_>>()
        .join("; ")
}

/// The admission limit a refused frame met.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Capacity {
    /// `pipeline.queue_capacity`: frames admitted and not finished.
    Frames(usize),
    /// `pipeline.max_queued_bytes`: the memory those frames hold.
    Bytes(u64),
}

impl std::fmt::Display for Capacity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Frames(n) => write!(f, "{n} frames in flight, pipeline.queue_capacity"),
            Self::Bytes(b) => write!(f, "{b} bytes of queued frames, pipeline.max_queued_bytes"),
        }
    }
}
