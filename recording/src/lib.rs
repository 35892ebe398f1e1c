//! The file formats of the service, in one place: MCAP recordings and PLY scans.
//!
//! Everyone who reads or writes a file goes through this crate: the simulator records flights
//! with [`Writer`], the server's offline `detect` and the `landing` command line read them with
//! [`read`], `landing replay --out` writes answers with [`Writer::write_result`], and PLY scans go
//! through [`ply`]. It knows the wire types (`landing_proto`) and nothing of the simulator, the
//! pipeline or gRPC.
//!
//! A recording has these protobuf channels (schemas embedded from
//! `landing_proto::FILE_DESCRIPTOR_SET`, named by the fully-qualified message name):
//!
//! | topic | schema | content |
//! |---|---|---|
//! | [`FRAME_TOPIC`] `/frame` | `landing.v1.Frame` | the LiDAR scan and camera image of one frame |
//! | [`TRUTH_TOPIC`] `/ground_truth` | `landing.v1.GroundTruth` | roofs in view, obstacles, true best landing point per roof |
//! | [`LABELS_TOPIC`] `/camera/labels` | `landing.v1.CameraImage` | 8-bit grayscale PNG, pixel value = class id |
//! | [`RESULT_TOPIC`] `/landing/results` | `landing.v1.StreamLandingSitesResponse` | the service's answer to a frame |
//!
//! The messages of one frame share its log time, which is how the reader pairs them; frames are
//! read from any channel whose schema is `landing.v1.Frame`, so recordings made by other tools
//! with other topic names replay too.
//!
//! ```
//! use landing_proto::v1;
//! use landing_recording::{Writer, read_bytes};
//!
//! let mut w = Writer::new(std::io::Cursor::new(Vec::new()), "doc-test")?;
//! let frame = v1::Frame { sequence: 3, drone_id: "d".into(), ..Default::default() };
//! w.write_frame(1_000, &frame)?;
//! w.write_truth(1_000, &v1::GroundTruth { sequence: 3, ..Default::default() })?;
//! let bytes = w.finish()?.into_inner();
//!
//! let frames = read_bytes(&bytes)?;
//! assert_eq!(frames.len(), 1);
//! assert_eq!(frames[0].frame.sequence, 3);
//! assert_eq!(frames[0].truth.as_ref().map(|t| t.sequence), Some(3));
//! assert!(frames[0].labels.is_none());
//! # Ok::<(), landing_recording::Error>(())
//! ```

#![forbid(unsafe_code)]

pub mod ply;
mod read;
mod write;

pub use read::{RecordedFrame, read, read_bytes};
pub use write::{Writer, log_time_ns};

/// Topic of the frames (`landing.v1.Frame`).
pub const FRAME_TOPIC: &str = "/frame";
/// Topic of the ground truth (`landing.v1.GroundTruth`).
pub const TRUTH_TOPIC: &str = "/ground_truth";
/// Topic of the true label images (`landing.v1.CameraImage`).
pub const LABELS_TOPIC: &str = "/camera/labels";
/// Topic of the service's answers (`landing.v1.StreamLandingSitesResponse`).
pub const RESULT_TOPIC: &str = "/landing/results";

/// Schema name of [`FRAME_TOPIC`].
pub const FRAME_SCHEMA: &str = "landing.v1.Frame";
/// Schema name of [`TRUTH_TOPIC`].
pub const TRUTH_SCHEMA: &str = "landing.v1.GroundTruth";
/// Schema name of [`LABELS_TOPIC`].
pub const LABELS_SCHEMA: &str = "landing.v1.CameraImage";
/// Schema name of [`RESULT_TOPIC`].
pub const RESULT_SCHEMA: &str = "landing.v1.StreamLandingSitesResponse";

/// Why a recording could not be read or written. PLY files have their own error,
/// [`ply::PlyError`], which names the header line or the row and property at fault.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be read or written.
    #[error("cannot access `{path}`: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// The MCAP container is malformed, or the writer failed.
    #[error("MCAP: {0}")]
    Mcap(String),
    /// A message on `topic` is not the protobuf message its schema names.
    #[error("message {sequence} on `{topic}` is not a {schema}: {reason}")]
    Decode {
        topic: String,
        sequence: u32,
        schema: &'static str,
        reason: String,
    },
    /// The recording holds no `landing.v1.Frame` message.
    #[error("no `{FRAME_SCHEMA}` messages (protobuf) found")]
    NoFrames,
}

impl Error {
    fn io(path: &std::path::Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.display().to_string(),
            source,
        }
    }
}

impl From<mcap::McapError> for Error {
    fn from(e: mcap::McapError) -> Self {
        Self::Mcap(e.to_string())
    }
}
