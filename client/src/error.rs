//! The one error type of the SDK.

use std::time::Duration;

/// Everything that can go wrong in the SDK. Messages name the field or value at fault.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClientError {
    /// A configuration value is unusable (bad URL, unreadable certificate, ...).
    #[error("invalid client configuration `{field}` = {value:?}: {reason}")]
    InvalidConfig {
        field: &'static str,
        value: String,
        reason: String,
    },
    /// Reading a file (a certificate, a key) failed.
    #[error("cannot read `{path}`: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// The server could not be reached or the connection broke before an answer.
    #[error("cannot connect to {endpoint}: {reason}")]
    Unreachable { endpoint: String, reason: String },
    /// The server answered the call with an error status.
    #[error("server answered {}: {}", .0.code, .0.message)]
    Status(Box<crate::FrameError>),
    /// Retries ran out; the last status is attached.
    #[error("gave up after {attempts} attempts over {elapsed:?}; last answer {}: {}", .last.code, .last.message)]
    RetriesExhausted {
        attempts: u32,
        elapsed: Duration,
        last: Box<crate::FrameError>,
    },
    /// A builder was given inconsistent input.
    #[error("invalid frame input `{field}`: {reason}")]
    InvalidInput { field: &'static str, reason: String },
    /// A stream ended (or broke) while frames were still unanswered.
    #[error("stream ended with {} frame(s) unanswered (first: {:?}){}", .unanswered.len(), .unanswered.first(), .status.as_ref().map(|s| format!("; server status {}: {}", s.code, s.message)).unwrap_or_default())]
    StreamBroken {
        unanswered: Vec<u64>,
        status: Option<Box<crate::FrameError>>,
    },
    /// The server broke the stream contract (an answer for a frame not sent, ...).
    #[error("protocol violation: {0}")]
    Protocol(String),
    /// A sequence number was reused while its frame was still unanswered.
    #[error("frame sequence {0} is already in flight on this stream")]
    DuplicateSequence(u64),
    /// The request half of a stream is closed.
    #[error("the stream is closed; frame {0} was not sent")]
    StreamClosed(u64),
    /// An encoded image's header could not be read.
    #[error("image `{what}`: {reason}")]
    Image { what: &'static str, reason: String },
}

impl ClientError {
    pub(crate) fn io(path: impl AsRef<std::path::Path>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.as_ref().display().to_string(),
            source,
        }
    }

    /// The gRPC code behind this error, when the server answered one.
    pub fn code(&self) -> Option<tonic::Code> {
        match self {
            Self::Status(e) => Some(e.code),
            Self::RetriesExhausted { last, .. } => Some(last.code),
            Self::StreamBroken {
                status: Some(s), ..
            } => Some(s.code),
            _ => None,
        }
    }

    /// True when the server could not be reached at all (connection refused, TLS failure,
    /// transport error), as opposed to the server answering with an error.
    pub fn is_unreachable(&self) -> bool {
        match self {
            Self::Unreachable { .. } => true,
            Self::Status(e) => e.code == tonic::Code::Unavailable,
            Self::RetriesExhausted { last, .. } => last.code == tonic::Code::Unavailable,
            _ => false,
        }
    }
}
