//! The file formats of the service, in one place: MCAP recordings and PLY scans.
//!
//! Everyone who reads or writes a file goes through this crate: the simulator records flights
//! with [`Writer`], the server's offline `detect` and the `landing` command line read them with
//! [`read`], `landing replay --out` writes answers with [`Writer::write_result`], and PLY scans go
//! through [`ply`]. It knows the wire types (`landing_proto`) and nothing of the simulator, the
//! pipeline or gRPC.
//!
//! A recording speaks Foxglove's own schemas wherever one exists, so that it opens in Foxglove
//! (and any MCAP tool) with a 3-D scene and camera view, and keeps each value in one place. Per
//! frame, all at the frame's log time:
//!
//! | topic | schema | content |
//! |---|---|---|
//! | [`FRAME_TOPIC`] `/frame` | `landing.v1.FrameHeader` | drone id, sequence, time, geodetic origin |
//! | [`LIDAR_TOPIC`] `/lidar/points` | `foxglove.PointCloud` | the scan in its sensor frame: x, y, z, intensity, class |
//! | [`CAMERA_TOPIC`] `/camera/image` | `foxglove.CompressedImage` | the camera image (raw pixels: [`CAMERA_RAW_TOPIC`], `foxglove.RawImage`) |
//! | [`CALIBRATION_TOPIC`] `/camera/calibration` | `foxglove.CameraCalibration` | pinhole intrinsics |
//! | [`TF_TOPIC`] `/tf` | `foxglove.FrameTransforms` | `world → lidar`, `world → camera` (the poses the frame carries) |
//! | [`LABELS_TOPIC`] `/camera/labels` | `foxglove.CompressedImage` | true classes: 8-bit grayscale PNG, pixel value = class id |
//! | [`TRUTH_TOPIC`] `/ground_truth` | `landing.v1.GroundTruth` | roofs in view, obstacles, true best landing point per roof |
//! | [`TRUTH_SCENE_TOPIC`] `/ground_truth/scene` | `foxglove.SceneUpdate` | the truth drawn: roof outlines, obstacle boxes by class, best circle |
//! | [`RESULT_TOPIC`] `/landing/results` | `landing.v1.StreamLandingSitesResponse` | the service's answer to a frame |
//! | [`SITES_TOPIC`] `/landing/sites` | `foxglove.SceneUpdate` | the answer drawn: polygons with holes, safe circles, centres, labels |
//! | [`ANNOTATIONS_TOPIC`] `/camera/annotations` | `foxglove.ImageAnnotations` | the answer over the camera image (as `landing render`) |
//!
//! The `landing.v1` messages are the source of truth for what Foxglove has no schema for; the two
//! scenes and the annotations are drawings of them ([`scene`]), written by the same call and
//! never read back. The reader puts each [`v1::Frame`] back together from the header, cloud,
//! image, calibration and transforms of one log time ([`convert`]), exactly. Older recordings,
//! and tools that write whole `landing.v1.Frame` messages on any topic, replay too.
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
//! assert_eq!(frames[0].frame, frame);
//! assert_eq!(frames[0].truth.as_ref().map(|t| t.sequence), Some(3));
//! assert!(frames[0].labels.is_none());
//! # Ok::<(), landing_recording::Error>(())
//! ```

#![forbid(unsafe_code)]

pub mod convert;
pub mod ply;
mod read;
pub mod scene;
mod write;

pub use convert::{FoxgloveFrame, WORLD_FRAME, frame_from_foxglove, frame_to_foxglove};
pub use foxglove::messages as foxglove_messages;
pub use read::{MAX_RECORD_BYTES, RecordedFrame, read, read_bytes};
pub use write::{Writer, log_time_ns};

/// Topic of the frame headers (`landing.v1.FrameHeader`): a frame's values that no Foxglove
/// schema holds. Older recordings hold whole `landing.v1.Frame` messages here.
pub const FRAME_TOPIC: &str = "/frame";
/// Topic of the scans (`foxglove.PointCloud`).
pub const LIDAR_TOPIC: &str = "/lidar/points";
/// Topic of encoded camera images (`foxglove.CompressedImage`).
pub const CAMERA_TOPIC: &str = "/camera/image";
/// Topic of raw camera images (`foxglove.RawImage`).
pub const CAMERA_RAW_TOPIC: &str = "/camera/image_raw";
/// Topic of the camera intrinsics (`foxglove.CameraCalibration`).
pub const CALIBRATION_TOPIC: &str = "/camera/calibration";
/// Topic of the sensor poses (`foxglove.FrameTransforms`, from [`WORLD_FRAME`]).
pub const TF_TOPIC: &str = "/tf";
/// Topic of the true label images (`foxglove.CompressedImage`, PNG; older recordings:
/// `landing.v1.CameraImage`).
pub const LABELS_TOPIC: &str = "/camera/labels";
/// Topic of raw true label images (`foxglove.RawImage`, `mono8`).
pub const LABELS_RAW_TOPIC: &str = "/camera/labels_raw";
/// Topic of the ground truth (`landing.v1.GroundTruth`).
pub const TRUTH_TOPIC: &str = "/ground_truth";
/// Topic of the ground truth drawn (`foxglove.SceneUpdate`).
pub const TRUTH_SCENE_TOPIC: &str = "/ground_truth/scene";
/// Topic of the service's answers (`landing.v1.StreamLandingSitesResponse`).
pub const RESULT_TOPIC: &str = "/landing/results";
/// Topic of the answers drawn in 3-D (`foxglove.SceneUpdate`).
pub const SITES_TOPIC: &str = "/landing/sites";
/// Topic of the answers drawn over the camera image (`foxglove.ImageAnnotations`).
pub const ANNOTATIONS_TOPIC: &str = "/camera/annotations";

/// Schema name of [`FRAME_TOPIC`].
pub const FRAME_HEADER_SCHEMA: &str = "landing.v1.FrameHeader";
/// Schema name of whole frames (older recordings, other tools).
pub const FRAME_SCHEMA: &str = "landing.v1.Frame";
/// Schema name of [`TRUTH_TOPIC`].
pub const TRUTH_SCHEMA: &str = "landing.v1.GroundTruth";
/// Schema name of label images in older recordings.
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
    /// The recording holds no frame: no header on [`FRAME_TOPIC`], no `foxglove.PointCloud` on
    /// [`LIDAR_TOPIC`] and no `landing.v1.Frame`.
    #[error(
        "no frames: no `{FRAME_HEADER_SCHEMA}` on `{FRAME_TOPIC}`, no `foxglove.PointCloud` on `{LIDAR_TOPIC}`, no `{FRAME_SCHEMA}`"
    )]
    NoFrames,
    /// A frame's sensors cannot be placed in a viewer's frame tree.
    #[error("frame ids: {0}")]
    FrameId(String),
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
