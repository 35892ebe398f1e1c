//! Camera perception for rooftop landing: decode a camera image, segment it into the paper's
//! semantic classes with a MobileNetV2 + FCN4s model run by ONNX Runtime, and give every LiDAR
//! point the class of the pixel it projects to.
//!
//! Main types:
//! - [`Segmenter`] (built from a [`SegmenterConfig`]): an ONNX Runtime session, CPU by default,
//!   CUDA when configured (with a logged fallback to the CPU). `Send + Sync`.
//! - [`ClassMask`]: one `SemanticClass` id per pixel (`0` unknown … `14` vegetation, the numbers
//!   of `landing_geometry::SemanticClass` and of the proto enum).
//! - [`CameraModel`] and [`classify_points`]: world points → camera frame → pixel → class.
//! - [`ObstacleRays`]: the mask's obstacle pixels as keep-out disks on a candidate landing plane,
//!   for the obstacles that the LiDAR's scan lines missed.
//!
//! ONNX Runtime is loaded at run time from `ORT_DYLIB_PATH` or `.ort/libonnxruntime.so`, which
//! `scripts/setup-ort.sh` installs from the PyPI `onnxruntime==1.31.1` wheel. This crate knows
//! nothing of gRPC.
//!
//! ```
//! use landing_perception::{CameraModel, ClassMask, classify_points};
//! use nalgebra::Isometry3;
//!
//! // A camera at the origin looking along world +z; left half of the image is sky (1), right
//! // half building rooftop (4).
//! let camera = CameraModel {
//!     pose: Isometry3::identity(),
//!     fx: 100.0, fy: 100.0, cx: 32.0, cy: 24.0, width: 64, height: 48,
//! };
//! let mask = ClassMask::new(2, 1, vec![1, 4])?;
//! let classes = classify_points(
//!     &[[-0.1, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.0, -1.0]],
//!     &camera,
//!     &mask,
//! );
//! assert_eq!(classes, vec![1, 4, 0]); // the last point is behind the camera
//! # Ok::<(), landing_perception::PerceptionError>(())
//! ```

#![forbid(unsafe_code)]

pub mod camera;
pub mod decode;
pub mod error;
pub mod keep_out;
pub mod mask;
pub mod segmenter;

pub use camera::{CameraModel, classify_points};
pub use decode::{
    ImageData, NORMALIZE_MEAN, NORMALIZE_STD, decode_class_mask, decode_image, preprocess,
};
pub use error::PerceptionError;
pub use image::RgbImage;
pub use keep_out::ObstacleRays;
pub use mask::{ClassMask, Confusion, IouReport, iou};
pub use segmenter::{
    DEFAULT_MODEL_PATH, ExecutionProvider, ModelInfo, OrtLogLevel, Segmenter, SegmenterConfig,
    resolve_ort_library, workspace_root,
};

/// Number of class ids a mask may hold, `Unknown` (0) included: the model's output channels.
pub const NUM_CLASSES: usize = 15;
