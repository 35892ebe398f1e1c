//! The segmentation model of the server: decodes a frame's camera image, segments it on one of
//! its own ONNX Runtime sessions, and gives each point the class of the pixel it projects to.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use landing_perception::{
    CameraModel, ClassMask, ExecutionProvider, ImageData, ObstacleRays, PerceptionError, RgbImage,
    SegmenterConfig, classify_points, decode_image,
};

use crate::Error;
use crate::config::SegmentationConfig;
use crate::pipeline::{CameraImage, ImagePixels};

/// Classes of every point of a frame, from the model, with the time of each step.
#[derive(Debug, Clone)]
pub struct Classified {
    pub classes: Vec<u8>,
    /// The pixels of every class outside `landable`: obstacles the points may have missed.
    pub obstacles: ObstacleRays,
    pub segmentation: Duration,
    pub classification: Duration,
}

/// A loaded segmentation model with `sessions` ONNX Runtime sessions used in turn, so that
/// several frames can be segmented at once.
#[derive(Debug)]
pub struct Segmenter {
    sessions: Vec<landing_perception::Segmenter>,
    next: AtomicUsize,
    /// The input sizes of every frame, finest first (the masks are fused).
    sizes: Vec<(u32, u32)>,
}

impl Segmenter {
    /// Loads the model and its sessions as `[segmentation]` says.
    pub fn load(config: &SegmentationConfig) -> Result<Self, Error> {
        let provider: ExecutionProvider =
            config
                .execution_provider
                .parse()
                .map_err(|e: PerceptionError| {
                    Error::config("segmentation.execution_provider", e.to_string())
                })?;
        let perception = SegmenterConfig {
            model_path: config.model_path.clone(),
            execution_provider: provider,
            intra_threads: config.intra_threads as usize,
            ort_library: (!config.ort_library.as_os_str().is_empty())
                .then(|| config.ort_library.clone()),
            input_size: None,
        };
        let sizes = config.parsed_input_sizes()?;
        let sessions = (0..config.sessions.max(1))
            .map(|_| landing_perception::Segmenter::new(&perception))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| Error::config("segmentation.model_path", e.to_string()))?;
        if provider == ExecutionProvider::Cuda
            && sessions
                .first()
                .is_some_and(|s| s.info().execution_provider != ExecutionProvider::Cuda)
        {
            tracing::warn!(
                "segmentation.execution_provider = \"cuda\" is unavailable; running on the CPU"
            );
        }
        // No sizes: the model's own.
        let sizes = if sizes.is_empty() {
            let i = sessions[0].info();
            vec![(i.input_width, i.input_height)]
        } else {
            sizes
        };
        Ok(Self {
            sessions,
            next: AtomicUsize::new(0),
            sizes,
        })
    }

    fn info(&self) -> &landing_perception::ModelInfo {
        self.sessions[0].info()
    }

    /// A short description for logs.
    pub fn describe(&self) -> String {
        let i = self.info();
        let sizes: Vec<String> = self.sizes.iter().map(|(w, h)| format!("{w}x{h}")).collect();
        format!(
            "{} (at {}, {}, {} session(s), sha256 {})",
            i.name,
            sizes.join(" + "),
            i.execution_provider,
            self.sessions.len(),
            i.sha256
        )
    }

    /// The model as `GetServiceInfo` reports it.
    pub fn model_info(&self) -> landing_proto::v1::ModelInfo {
        let i = self.info();
        let (input_width, input_height) = self.sizes[0];
        landing_proto::v1::ModelInfo {
            name: i.name.clone(),
            sha256: i.sha256.clone(),
            input_width,
            input_height,
            execution_provider: i.execution_provider.to_string(),
        }
    }

    /// Segments the decoded `image` at every input size and fuses the masks (a pixel is landable
    /// only where every size says so), gives each world point the class of its pixel, and
    /// collects the rays of the pixels whose class is not in `landable`.
    pub fn classify(
        &self,
        camera: &CameraImage,
        image: &RgbImage,
        world_points: &[[f32; 3]],
        landable: &[u8],
    ) -> Result<Classified, Error> {
        let t0 = Instant::now();
        let session =
            &self.sessions[self.next.fetch_add(1, Ordering::Relaxed) % self.sessions.len()];
        let masks = self
            .sizes
            .iter()
            .map(|&(w, h)| session.segment_at(image, w, h))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| perception_error(&e))?;
        // Unknown (0) is no obstacle: the points there get no class and the pixels no disk.
        let is_obstacle = |c: u8| c != 0 && !landable.contains(&c);
        let mask = ClassMask::fuse_keeping_obstacles(&masks, is_obstacle)
            .ok_or_else(|| Error::Internal("no segmentation input size".into()))?;
        let t1 = Instant::now();
        let k = camera.intrinsics;
        let model = CameraModel {
            pose: camera.pose,
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
        };
        let classes = classify_points(world_points, &model, &mask);
        let obstacles = ObstacleRays::new(&model, &mask, world_points, is_obstacle);
        Ok(Classified {
            classes,
            obstacles,
            segmentation: t1 - t0,
            classification: t1.elapsed(),
        })
    }
}

/// Decodes the frame's image and checks it against the calibration's size.
pub fn decode(camera: &CameraImage) -> Result<RgbImage, Error> {
    let (data, field) = match &camera.pixels {
        ImagePixels::Encoded { format, data } => (
            ImageData::compressed(format, data)
                .map_err(|e| Error::invalid("frame.image.compressed.format", e.to_string()))?,
            "frame.image.compressed.data",
        ),
        ImagePixels::Rgb8 {
            width,
            height,
            step,
            data,
        } => (
            ImageData::Rgb8 {
                width: *width,
                height: *height,
                step: *step,
                data,
            },
            "frame.image.raw.data",
        ),
    };
    let image = decode_image(data).map_err(|e| Error::invalid(field, e.to_string()))?;
    let k = camera.intrinsics;
    if (image.width(), image.height()) != (k.width, k.height) {
        return Err(Error::invalid(
            field,
            format!(
                "the image is {}x{} but frame.image.calibration says {}x{}",
                image.width(),
                image.height(),
                k.width,
                k.height
            ),
        ));
    }
    Ok(image)
}

/// Perception errors at run time: bad input is the caller's, the rest is the model's.
fn perception_error(e: &PerceptionError) -> Error {
    match e {
        PerceptionError::Decode { .. } => Error::invalid("frame.image", e.to_string()),
        PerceptionError::InvalidInput { field, .. } => {
            Error::invalid(format!("frame.image.{field}"), e.to_string())
        }
        _ => Error::Segmentation(e.to_string()),
    }
}
