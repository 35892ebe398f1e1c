//! The one place where errors become gRPC statuses: [`code_of`] matches every [`Error`] variant
//! (no `_` arm, so a new variant forces a decision), [`to_status`] builds the `tonic::Status` of a
//! unary call and [`to_rpc_status`] the `google.rpc.Status` of a per-frame stream error, both
//! with `google.rpc.BadRequest` / `RetryInfo` details.

use prost::Message as _;
use tonic::Code;
use tonic_types::{ErrorDetails, StatusExt as _};

use landing_proto::google::rpc;

use crate::Error;

/// Type URL of `google.rpc.BadRequest` in a `google.protobuf.Any`.
pub const BAD_REQUEST_TYPE_URL: &str = "type.googleapis.com/google.rpc.BadRequest";
/// Type URL of `google.rpc.RetryInfo` in a `google.protobuf.Any`.
pub const RETRY_INFO_TYPE_URL: &str = "type.googleapis.com/google.rpc.RetryInfo";

/// The gRPC code of an error.
pub fn code_of(error: &Error) -> Code {
    match error {
        Error::InvalidArgument(_) => Code::InvalidArgument,
        Error::ModelUnavailable(_) => Code::FailedPrecondition,
        Error::Segmentation(_) => Code::Internal,
        Error::Geometry(g) => geometry_code(g),
        Error::Overloaded { .. } => Code::ResourceExhausted,
        // gRPC's code for a message over the receiver's limit; no RetryInfo, since a retry of
        // the same message is refused the same way.
        Error::RequestTooLarge { .. } => Code::ResourceExhausted,
        Error::DeadlineExceeded => Code::DeadlineExceeded,
        Error::Cancelled => Code::Cancelled,
        Error::ShuttingDown => Code::Unavailable,
        // Off, unreachable or unreadable: the caller may retry later, or ask another replica.
        Error::CatalogUnavailable(_) => Code::Unavailable,
        Error::Unauthenticated => Code::Unauthenticated,
        Error::Internal(_) => Code::Internal,
        // Configuration, file and PLY errors come from the command line, never from a request;
        // if one ever reaches a caller it describes the server's state, not the request.
        Error::Config { .. } | Error::Io { .. } => Code::Internal,
        Error::Ply { .. } => Code::InvalidArgument,
    }
}

/// Geometry errors are about the caller's points or parameters.
fn geometry_code(error: &landing_geometry::GeometryError) -> Code {
    use landing_geometry::GeometryError as G;
    match error {
        G::InvalidParameter { .. } | G::InvalidPoint { .. } | G::ClassCountMismatch { .. } => {
            Code::InvalidArgument
        }
        // GeometryError is #[non_exhaustive] in another crate, so a catch-all is required here;
        // unknown geometry failures are reported as internal errors.
        _ => Code::Internal,
    }
}

/// `(field, description)` pairs for the BadRequest details of an error, if it has any.
fn violations(error: &Error) -> Vec<(String, String)> {
    match error {
        Error::InvalidArgument(v) => v
            .iter()
            .map(|v| (v.field.clone(), v.description.clone()))
            .collect(),
        Error::Geometry(landing_geometry::GeometryError::InvalidParameter {
            field,
            value,
            reason,
        }) => {
            vec![(format!("options.{field}"), format!("{value}: {reason}"))]
        }
        Error::Geometry(landing_geometry::GeometryError::InvalidPoint { index, value }) => {
            vec![(
                "frame.point_cloud.data".into(),
                format!("point {index} has coordinate {value}"),
            )]
        }
        _ => Vec::new(),
    }
}

fn retry_after(error: &Error) -> Option<std::time::Duration> {
    match error {
        Error::Overloaded { retry_after, .. } => Some(*retry_after),
        _ => None,
    }
}

/// The status of a unary call failing with `error`.
pub fn to_status(error: &Error) -> tonic::Status {
    let mut details = ErrorDetails::new();
    for (field, description) in violations(error) {
        details.add_bad_request_violation(field, description);
    }
    if let Some(delay) = retry_after(error) {
        details.set_retry_info(Some(delay));
    }
    tonic::Status::with_error_details(code_of(error), error.to_string(), details)
}

/// The `google.rpc.Status` of a stream frame failing with `error`.
pub fn to_rpc_status(error: &Error) -> rpc::Status {
    let mut details = Vec::new();
    let v = violations(error);
    if !v.is_empty() {
        let bad = rpc::BadRequest {
            field_violations: v
                .into_iter()
                .map(|(field, description)| rpc::bad_request::FieldViolation { field, description })
                .collect(),
        };
        details.push(prost_types::Any {
            type_url: BAD_REQUEST_TYPE_URL.into(),
            value: bad.encode_to_vec(),
        });
    }
    if let Some(delay) = retry_after(error) {
        let info = rpc::RetryInfo {
            retry_delay: prost_types::Duration::try_from(delay).ok(),
        };
        details.push(prost_types::Any {
            type_url: RETRY_INFO_TYPE_URL.into(),
            value: info.encode_to_vec(),
        });
    }
    rpc::Status {
        code: code_of(error) as i32,
        message: error.to_string(),
        details,
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::FieldViolation;
    use crate::error::Capacity;

    #[test]
    fn every_variant_has_its_code() {
        let cases = [
            (Error::invalid("frame", "required"), Code::InvalidArgument),
            (
                Error::ModelUnavailable("none".into()),
                Code::FailedPrecondition,
            ),
            (Error::Segmentation("ort".into()), Code::Internal),
            (
                Error::Geometry(landing_geometry::GeometryError::ClassCountMismatch {
                    points: 1,
                    classes: 2,
                }),
                Code::InvalidArgument,
            ),
            (
                Error::Overloaded {
                    capacity: Capacity::Frames(1),
                    retry_after: Duration::from_millis(5),
                },
                Code::ResourceExhausted,
            ),
            (
                Error::RequestTooLarge {
                    bytes: 2 << 20,
                    limit: 1 << 20,
                },
                Code::ResourceExhausted,
            ),
            (Error::DeadlineExceeded, Code::DeadlineExceeded),
            (Error::Cancelled, Code::Cancelled),
            (Error::ShuttingDown, Code::Unavailable),
            (
                Error::CatalogUnavailable("not connected".into()),
                Code::Unavailable,
            ),
            (Error::Unauthenticated, Code::Unauthenticated),
            (Error::Internal("bug".into()), Code::Internal),
            (Error::config("server.listen", "bad"), Code::Internal),
            (
                Error::Io {
                    path: "p".into(),
                    reason: "r".into(),
                },
                Code::Internal,
            ),
            (
                Error::Ply {
                    path: "p".into(),
                    reason: "r".into(),
                },
                Code::InvalidArgument,
            ),
        ];
        for (error, code) in cases {
            assert_eq!(code_of(&error), code, "{error}");
            assert_eq!(to_status(&error).code(), code);
            assert_eq!(to_rpc_status(&error).code, code as i32);
        }
    }

    #[test]
    fn bad_request_details_name_every_field() {
        let error = Error::InvalidArgument(vec![
            FieldViolation::new("frame.point_cloud.data", "NaN"),
            FieldViolation::new("options.min_normal_dot", "1.5"),
        ]);
        let status = to_status(&error);
        let details = status.get_error_details();
        let fields: Vec<_> = details
            .bad_request()
            .unwrap()
            .field_violations
            .iter()
            .map(|v| v.field.clone())
            .collect();
        assert_eq!(
            fields,
            vec!["frame.point_cloud.data", "options.min_normal_dot"]
        );

        let rpc = to_rpc_status(&error);
        assert_eq!(rpc.details.len(), 1);
        assert_eq!(rpc.details[0].type_url, BAD_REQUEST_TYPE_URL);
        let decoded = rpc::BadRequest::decode(rpc.details[0].value.as_slice()).unwrap();
        assert_eq!(decoded.field_violations[1].field, "options.min_normal_dot");
    }

    #[test]
    fn catalog_errors_name_the_field_or_the_catalog() {
        let bad = Error::from(landing_catalog::Error::invalid(
            "center.latitude_deg",
            "91 is not a latitude",
        ));
        let status = to_status(&bad);
        assert_eq!(status.code(), Code::InvalidArgument);
        let details = status.get_error_details();
        let violations = &details.bad_request().unwrap().field_violations;
        assert_eq!(violations[0].field, "center.latitude_deg");
        let down = Error::from(landing_catalog::Error::Corrupt {
            backend: "sqlite",
            what: "a newer schema".into(),
        });
        let status = to_status(&down);
        assert_eq!(status.code(), Code::Unavailable);
        assert!(status.message().contains("catalog"), "{}", status.message());
    }

    #[test]
    fn overload_carries_retry_info() {
        let error = Error::Overloaded {
            capacity: Capacity::Bytes(4 << 20),
            retry_after: Duration::from_millis(250),
        };
        let status = to_status(&error);
        let retry = status.get_error_details().retry_info().unwrap().retry_delay;
        assert_eq!(retry, Some(Duration::from_millis(250)));
        let rpc = to_rpc_status(&error);
        assert_eq!(rpc.details[0].type_url, RETRY_INFO_TYPE_URL);
        let info = rpc::RetryInfo::decode(rpc.details[0].value.as_slice()).unwrap();
        assert_eq!(
            info.retry_delay,
            Some(prost_types::Duration {
                seconds: 0,
                nanos: 250_000_000
            })
        );
    }
}
