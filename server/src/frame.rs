//! The validated frame: what [`crate::convert`] makes of a request and the pipeline consumes.
//!
//! Plain data with no behaviour, so that every step (conversion, segmentation, the pipeline)
//! depends on it and none on another for its types.

use landing_geometry::Params;
use nalgebra::Isometry3;

use landing_geometry::geodetic::Geodetic;

/// Where the point classes of a frame come from: the API's enum, the one definition.
/// `Unspecified` is "auto": the frame's class image if it has one, else the model if the frame
/// has an image and the server a model, else the cloud's classes if it has them, else none
/// (`Pipeline::resolve_mode` decides it).
pub use landing_proto::v1::SegmentationMode;

/// A validated LiDAR scan: points in the LiDAR frame and the pose `T_world_lidar`.
#[derive(Debug, Clone, PartialEq)]
pub struct Cloud {
    /// In double precision: a cloud sent already in world coordinates (identity pose, FLOAT64
    /// fields) keeps its millimetres at 1e7 m.
    pub points: Vec<[f64; 3]>,
    /// One [`landing_geometry::SemanticClass`] number per point, when the cloud has a class field.
    pub classes: Option<Vec<u8>>,
    pub pose: Isometry3<f64>,
}

/// The pixels of a validated camera image (decoded only when needed).
#[derive(Debug, Clone, PartialEq)]
pub enum ImagePixels {
    /// PNG or JPEG bytes; `format` is "png" or "jpeg".
    Encoded { format: String, data: Vec<u8> },
    /// Packed RGB8 rows.
    Rgb8 {
        width: u32,
        height: u32,
        step: u32,
        data: Vec<u8>,
    },
    /// Packed 8-bit rows of class ids (a class image).
    Mono8 {
        width: u32,
        height: u32,
        step: u32,
        data: Vec<u8>,
    },
}

/// Pinhole intrinsics: `u = fx * x / z + cx`, `v = fy * y / z + cy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

/// A validated camera or class image: pixels, `T_world_camera` (optical convention) and
/// intrinsics.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraImage {
    pub pixels: ImagePixels,
    pub pose: Isometry3<f64>,
    pub intrinsics: Intrinsics,
}

/// A validated frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    pub drone_id: String,
    pub sequence: u64,
    pub timestamp: Option<prost_types::Timestamp>,
    pub cloud: Cloud,
    pub image: Option<CameraImage>,
    /// Per-pixel class ids of a camera (`Frame.class_image`).
    pub class_image: Option<CameraImage>,
    pub geodetic_origin: Option<Geodetic>,
}

/// Validated per-frame options: geometry parameters and segmentation mode.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameOptions {
    pub params: Params,
    pub segmentation_mode: SegmentationMode,
}
