//! Per-frame outcomes and the decoding of `google.rpc.Status` error details.

use std::time::Duration;

use landing_proto::google::rpc;
use landing_proto::v1::{FrameResult, StreamLandingSitesResponse, stream_landing_sites_response};
use prost::Message;

const BAD_REQUEST_TYPE: &str = "type.googleapis.com/google.rpc.BadRequest";
const RETRY_INFO_TYPE: &str = "type.googleapis.com/google.rpc.RetryInfo";

/// What happened to one frame.
// Results are the common case: boxing them would cost an allocation per frame for nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq)]
pub enum FrameOutcome {
    /// The frame was processed; the sites are in the result, best first.
    Result(FrameResult),
    /// The frame was refused or failed; the stream (if any) goes on.
    Error(FrameError),
    /// The frame was dropped unprocessed because a newer one arrived (`OVERFLOW_POLICY_LATEST`).
    Skipped {
        /// The sequence of the newer frame that replaced this one.
        superseded_by: u64,
    },
}

impl FrameOutcome {
    /// The result, if the frame was processed.
    pub fn result(&self) -> Option<&FrameResult> {
        match self {
            Self::Result(r) => Some(r),
            _ => None,
        }
    }

    /// The error, if the frame failed.
    pub fn error(&self) -> Option<&FrameError> {
        match self {
            Self::Error(e) => Some(e),
            _ => None,
        }
    }

    /// A short lowercase label for tables and summaries: `ok`, `skipped`, or the error code
    /// (`invalid_argument`, `resource_exhausted`, ...).
    pub fn label(&self) -> String {
        match self {
            Self::Result(_) => "ok".to_owned(),
            Self::Skipped { .. } => "skipped".to_owned(),
            Self::Error(e) => code_label(e.code),
        }
    }
}

/// The snake_case name of a gRPC code, e.g. `resource_exhausted`.
pub fn code_label(code: tonic::Code) -> String {
    let name = format!("{code:?}");
    let mut out = String::with_capacity(name.len() + 4);
    for (i, ch) in name.chars().enumerate() {
        if ch.is_ascii_uppercase() && i > 0 {
            out.push('_');
        }
        out.push(ch.to_ascii_lowercase());
    }
    out
}

/// One answer of a stream: the frame it answers and what happened to it.
#[derive(Debug, Clone, PartialEq)]
pub struct StreamItem {
    /// The `sequence` of the frame this answers.
    pub sequence: u64,
    /// What happened to the frame.
    pub outcome: FrameOutcome,
    /// Time from handing the frame to the transport to receiving this answer.
    pub latency: Duration,
}

/// A failed frame or call: the gRPC code, the message, and the decoded error details.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameError {
    /// The gRPC status code.
    pub code: tonic::Code,
    /// The server's message.
    pub message: String,
    /// `google.rpc.BadRequest` field violations: which field was wrong, and why.
    pub field_violations: Vec<FieldViolation>,
    /// `google.rpc.RetryInfo`: how long the server asks the client to wait before retrying.
    pub retry_delay: Option<Duration>,
}

/// One `google.rpc.BadRequest.FieldViolation`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FieldViolation {
    /// Path of the bad field, e.g. `frame.point_cloud.point_stride`.
    pub field: String,
    /// Why it is bad.
    pub description: String,
}

impl FrameError {
    /// Decodes a `google.rpc.Status` (as carried in a stream response).
    pub fn from_rpc_status(status: &rpc::Status) -> Self {
        let mut error = Self {
            code: tonic::Code::from_i32(status.code),
            message: status.message.clone(),
            field_violations: Vec::new(),
            retry_delay: None,
        };
        for any in &status.details {
            error.absorb_detail(&any.type_url, &any.value);
        }
        error
    }

    /// Decodes a call's `tonic::Status`, including its binary `grpc-status-details-bin` details.
    pub fn from_status(status: &tonic::Status) -> Self {
        let mut error = Self {
            code: status.code(),
            message: status.message().to_owned(),
            field_violations: Vec::new(),
            retry_delay: None,
        };
        if !status.details().is_empty()
            && let Ok(decoded) = rpc::Status::decode(status.details())
        {
            for any in &decoded.details {
                error.absorb_detail(&any.type_url, &any.value);
            }
        }
        error
    }

    /// The field paths of the violations, for quick checks.
    pub fn fields(&self) -> Vec<&str> {
        self.field_violations
            .iter()
            .map(|v| v.field.as_str())
            .collect()
    }

    fn absorb_detail(&mut self, type_url: &str, value: &[u8]) {
        match type_url {
            BAD_REQUEST_TYPE => {
                if let Ok(bad) = rpc::BadRequest::decode(value) {
                    self.field_violations
                        .extend(bad.field_violations.into_iter().map(|v| FieldViolation {
                            field: v.field,
                            description: v.description,
                        }));
                }
            }
            RETRY_INFO_TYPE => {
                if let Ok(info) = rpc::RetryInfo::decode(value) {
                    self.retry_delay = info.retry_delay.and_then(duration_from_proto);
                }
            }
            // Other details (ErrorInfo, DebugInfo, ...) carry nothing the SDK acts on.
            _ => {}
        }
    }
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", code_label(self.code), self.message)?;
        // The service's message already names its fields; others' may not.
        for v in self
            .field_violations
            .iter()
            .filter(|v| !self.message.contains(v.field.as_str()))
        {
            write!(f, "; {}: {}", v.field, v.description)?;
        }
        if let Some(d) = self.retry_delay {
            write!(f, "; retry after {d:?}")?;
        }
        Ok(())
    }
}

pub use landing_proto::duration_from_proto;

/// Turns one stream response into its sequence and outcome.
pub(crate) fn outcome_of(response: StreamLandingSitesResponse) -> (u64, FrameOutcome) {
    use stream_landing_sites_response::Outcome;
    let outcome = match response.outcome {
        Some(Outcome::Result(r)) => FrameOutcome::Result(r),
        Some(Outcome::Error(s)) => FrameOutcome::Error(FrameError::from_rpc_status(&s)),
        Some(Outcome::Skipped(s)) => FrameOutcome::Skipped {
            superseded_by: s.superseded_by_sequence,
        },
        None => FrameOutcome::Error(FrameError {
            code: tonic::Code::Internal,
            message: "the server's response carried no outcome".to_owned(),
            field_violations: Vec::new(),
            retry_delay: None,
        }),
    };
    (response.sequence, outcome)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn any<M: Message>(type_url: &str, m: &M) -> prost_types::Any {
        prost_types::Any {
            type_url: type_url.to_owned(),
            value: m.encode_to_vec(),
        }
    }

    fn bad_request_status() -> rpc::Status {
        rpc::Status {
            code: tonic::Code::InvalidArgument as i32,
            message: "bad frame".into(),
            details: vec![
                any(
                    BAD_REQUEST_TYPE,
                    &rpc::BadRequest {
                        field_violations: vec![rpc::bad_request::FieldViolation {
                            field: "frame.point_cloud.point_stride".into(),
                            description: "must be > 0".into(),
                        }],
                    },
                ),
                any(
                    RETRY_INFO_TYPE,
                    &rpc::RetryInfo {
                        retry_delay: Some(prost_types::Duration {
                            seconds: 1,
                            nanos: 500_000_000,
                        }),
                    },
                ),
                any(
                    "type.googleapis.com/google.rpc.DebugInfo",
                    &rpc::RetryInfo::default(),
                ),
            ],
        }
    }

    #[test]
    fn decodes_bad_request_and_retry_info_from_rpc_status() {
        let e = FrameError::from_rpc_status(&bad_request_status());
        assert_eq!(e.code, tonic::Code::InvalidArgument);
        assert_eq!(e.fields(), vec!["frame.point_cloud.point_stride"]);
        assert_eq!(e.retry_delay, Some(Duration::from_millis(1500)));
        assert!(
            e.to_string()
                .contains("invalid_argument: bad frame; frame.point_cloud.point_stride")
        );
        // A message that already names the field is not repeated.
        let named = FrameError {
            message: "`frame.point_cloud.point_stride`: must be > 0".into(),
            ..e
        };
        assert_eq!(
            named.to_string(),
            "invalid_argument: `frame.point_cloud.point_stride`: must be > 0; retry after 1.5s"
        );
    }

    #[test]
    fn decodes_details_from_tonic_status() {
        let details = bad_request_status().encode_to_vec();
        let status =
            tonic::Status::with_details(tonic::Code::InvalidArgument, "bad frame", details.into());
        let e = FrameError::from_status(&status);
        assert_eq!(e.fields(), vec!["frame.point_cloud.point_stride"]);
        assert_eq!(e.retry_delay, Some(Duration::from_millis(1500)));
    }

    #[test]
    fn garbage_details_are_ignored_not_fatal() {
        let status =
            tonic::Status::with_details(tonic::Code::Internal, "x", vec![0xff, 0x01].into());
        let e = FrameError::from_status(&status);
        assert_eq!(e.code, tonic::Code::Internal);
        assert!(e.field_violations.is_empty());
    }

    #[test]
    fn code_labels_are_snake_case() {
        assert_eq!(
            code_label(tonic::Code::ResourceExhausted),
            "resource_exhausted"
        );
        assert_eq!(code_label(tonic::Code::Ok), "ok");
        assert_eq!(code_label(tonic::Code::InvalidArgument), "invalid_argument");
    }

    #[test]
    fn stream_response_without_outcome_is_an_internal_error() {
        let (seq, outcome) = outcome_of(StreamLandingSitesResponse {
            sequence: 7,
            outcome: None,
        });
        assert_eq!(seq, 7);
        assert_eq!(outcome.error().map(|e| e.code), Some(tonic::Code::Internal));
    }

    #[test]
    fn negative_durations_are_rejected() {
        assert_eq!(
            duration_from_proto(prost_types::Duration {
                seconds: -1,
                nanos: 0
            }),
            None
        );
    }
}
