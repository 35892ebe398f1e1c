//! The segmentation model of the server: decodes a frame's camera image, segments it on one of
//! its own ONNX Runtime sessions, and gives each point the class of the pixel it projects to.
//! A frame's class image (the drone's own segmentation) takes the same path from the mask on.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use landing_geometry::SemanticClass;
use landing_perception::{
    CameraModel, ClassMask, ExecutionProvider, ImageData, ObstacleRays, PerceptionError, RgbImage,
    SegmenterConfig, classify_points, decode_class_mask, decode_image,
};
use nalgebra::{Isometry3, Point3};

use crate::Error;
use crate::config::SegmentationConfig;
use crate::frame::{CameraImage, ImagePixels};

/// Classes of every point of a frame, from a class mask, with the time it took.
#[derive(Debug, Clone)]
pub struct Classified {
    pub classes: Vec<u8>,
    /// The pixels of every class outside `landable`: obstacles the points may have missed.
    pub obstacles: ObstacleRays,
    /// The view the classes came from.
    pub view: PointView,
    pub classification: Duration,
}

/// The camera and the size of the mask that gave the points their classes: how coarsely each
/// point was seen.
#[derive(Debug, Clone)]
pub struct PointView {
    camera: CameraModel,
    mask_width: u32,
    mask_height: u32,
}

impl PointView {
    /// For a point (in the coordinates of the classified points), the longer side of the patch
    /// of level ground one class pixel covers there, metres; `None` outside the view
    /// ([`CameraModel::footprint_on_level_ground`]).
    pub fn footprint_on_level_ground(&self, point: &Point3<f64>) -> Option<f64> {
        self.camera
            .footprint_on_level_ground(point, self.mask_width, self.mask_height)
    }
}

/// A loaded segmentation model with `sessions` ONNX Runtime sessions used in turn, so that
/// several frames, and a frame's input sizes, can be segmented at once.
#[derive(Debug)]
pub struct Segmenter {
    sessions: Vec<landing_perception::Segmenter>,
    next: AtomicUsize,
    /// The input sizes of a frame judged alone, finest first (the masks are fused); a fused
    /// stream's frames run the first alone.
    sizes: Vec<(u32, u32)>,
}

impl Segmenter {
    /// Loads the model and its sessions as `[segmentation]` says.
    pub fn load(config: &SegmentationConfig) -> Result<Self, Error> {
        let provider = config.execution_provider;
        let perception = SegmenterConfig {
            model_path: config.model_path.clone(),
            execution_provider: provider,
            intra_threads: config.intra_threads as usize,
            ort_library: (!config.ort_library.as_os_str().is_empty())
                .then(|| config.ort_library.clone()),
            input_size: None,
            ort_log_level: config.ort_log_level,
        };
        let sizes = config.input_sizes_finest_first();
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
        let threads = config.sessions.max(1) * config.intra_threads;
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        if config.intra_threads > 1 && threads as usize > cores {
            tracing::warn!(
                sessions = config.sessions,
                intra_threads = config.intra_threads,
                cores,
                "segmentation.sessions × segmentation.intra_threads outnumber the cores: the \
                 sessions' spinning threads will slow each other down"
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
        let streams = if self.sizes.len() > 1 {
            format!(", streams at {}", sizes[0])
        } else {
            String::new()
        };
        format!(
            "{} (at {}{streams}, {}, {} session(s), sha256 {})",
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

    /// Segments the decoded `image` at the input sizes `judged` names (every one, or a fused
    /// stream's first alone) and fuses the masks (a pixel is landable only where every size
    /// says so); [`Masks::classify`] then gives the points their classes. Needs no pose: a
    /// fused stream registers its scan meanwhile.
    pub fn segment(
        &self,
        image: &RgbImage,
        judged: Judged,
        landable: &[u8],
    ) -> Result<Masks, Error> {
        let t0 = Instant::now();
        let sizes = match judged {
            Judged::Alone => &self.sizes[..],
            Judged::InStream => &self.sizes[..1],
        };
        // The sizes take the next sessions in turn, and with more than one session every size
        // but the first runs on a thread of its own beside it (sizes sharing a session take
        // turns on it): a frame judged alone waits for its slowest size, not for their sum.
        let first = self.next.fetch_add(sizes.len(), Ordering::Relaxed);
        let run = |i: usize| {
            let (w, h) = sizes[i];
            self.sessions[(first + i) % self.sessions.len()].segment_at(image, w, h)
        };
        let masks: Vec<Result<ClassMask, PerceptionError>> = if self.sessions.len() > 1 {
            std::thread::scope(|threads| {
                let others: Vec<_> = (1..sizes.len())
                    .map(|i| threads.spawn(move || run(i)))
                    .collect();
                let mut masks = vec![run(0)];
                for other in others {
                    let mask = other.join().map_err(|_| {
                        Error::Internal("segmenting at a second input size panicked".into())
                    })?;
                    masks.push(mask);
                }
                Ok::<_, Error>(masks)
            })?
        } else {
            (0..sizes.len()).map(run).collect()
        };
        let mut masks = masks
            .into_iter()
            .collect::<Result<Vec<_>, PerceptionError>>()
            .map_err(|e| model_error(&e))?;
        let fused = ClassMask::fuse_keeping_obstacles(&masks, obstacle_test(landable))
            .ok_or_else(|| Error::Internal("no segmentation input size".into()))?;
        Ok(Masks {
            finest: masks.swap_remove(0),
            fused,
            judged,
            time: t0.elapsed(),
        })
    }
}

/// An image's class masks ([`Segmenter::segment`]).
#[derive(Debug)]
pub struct Masks {
    /// At the finest input size.
    finest: ClassMask,
    /// Every size's, fused.
    fused: ClassMask,
    judged: Judged,
    /// Time spent segmenting.
    pub time: Duration,
}

impl Masks {
    /// Gives the points their classes from the mask the image was `judged` for, then as
    /// [`classify_with_mask`] does; the obstacle rays always come from the fused mask.
    pub fn classify(
        &self,
        camera: &CameraImage,
        pose: Isometry3<f64>,
        world_points: &[[f32; 3]],
        landable: &[u8],
    ) -> Classified {
        let for_points = match self.judged {
            Judged::Alone => &self.fused,
            Judged::InStream => &self.finest,
        };
        classify_with_masks(
            camera,
            pose,
            for_points,
            &self.fused,
            world_points,
            landable,
            self.judged,
        )
    }
}

/// How a frame is judged: alone, or as one of a fused stream's frames. It decides which of the
/// frame's masks gives its points their classes (the polygons; the obstacle rays, which safe
/// circles keep clear of, always come from the fused mask), and whether a structure the scan
/// hit casts keep-out footprints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Judged {
    /// Alone, where one frame's miss would be an unsafe site. The points take the masks of
    /// every input size fused (a point is landable only where every size says so), and every
    /// obstacle block casts its footprint.
    Alone,
    /// In a fused stream, where a cell's class is the votes of every frame that saw it, an
    /// obstacle vote outweighing several landable ones, and the keep-out footprints of several
    /// frames are kept. The points take the first (finest) input size's mask alone, the one
    /// with the highest rooftop recall: the guard's lost recall buys no safety the votes and
    /// the footprints do not already give (EVALUATION.md, "Fused points from the finest
    /// mask"). That size is the only one run, and casts the footprints too (EVALUATION.md, "One
    /// input size in streams"). A wall the scan hit casts nothing ([`ObstacleRays::new`]): its
    /// sweep kept a band of free roof clear in front of every far parapet. A small obstacle the model calls
    /// wall beside a real one loses its footprint in that frame, not in the stream's other
    /// kept frames (EVALUATION.md, "Walls the scan hit").
    InStream,
}

/// Whether a class is an obstacle for landing: any class outside `landable` but unknown (0),
/// whose points get no class and whose pixels no keep-out disk.
fn obstacle_test(landable: &[u8]) -> impl Fn(u8) -> bool + '_ {
    move |c| c != 0 && !landable.contains(&c)
}

/// Whether a class is a structure too large for a scan to miss: a building's wall, which on a
/// roof is a parapet's face or a taller neighbour's side ([`ObstacleRays::new`]).
fn is_structure(class: u8) -> bool {
    class == SemanticClass::BuildingWall as u8
}

/// Gives each world point the class of the pixel of `mask` (stretched over `camera`'s image) it
/// projects to, and collects the rays of the obstacle pixels (classes outside `landable`).
/// `pose` is the camera's in the coordinates of `world_points` (`camera.pose` moved with them).
/// `judged` decides which structures cast footprints ([`Judged`]).
pub fn classify_with_mask(
    camera: &CameraImage,
    pose: Isometry3<f64>,
    mask: &ClassMask,
    world_points: &[[f32; 3]],
    landable: &[u8],
    judged: Judged,
) -> Classified {
    classify_with_masks(camera, pose, mask, mask, world_points, landable, judged)
}

/// [`classify_with_mask`] with the points' classes from `point_mask` and the obstacle rays from
/// `obstacle_mask` (both stretched over `camera`'s image).
fn classify_with_masks(
    camera: &CameraImage,
    pose: Isometry3<f64>,
    point_mask: &ClassMask,
    obstacle_mask: &ClassMask,
    world_points: &[[f32; 3]],
    landable: &[u8],
    judged: Judged,
) -> Classified {
    let t = Instant::now();
    let k = camera.intrinsics;
    let model = CameraModel {
        pose,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        width: k.width,
        height: k.height,
    };
    let classes = classify_points(world_points, &model, point_mask);
    let obstacles = ObstacleRays::new(
        &model,
        obstacle_mask,
        world_points,
        obstacle_test(landable),
        |c| judged == Judged::InStream && is_structure(c),
    );
    Classified {
        classes,
        obstacles,
        view: PointView {
            camera: model,
            mask_width: point_mask.width(),
            mask_height: point_mask.height(),
        },
        classification: t.elapsed(),
    }
}

/// Decodes the frame's image and checks it against the calibration's size.
pub fn decode(camera: &CameraImage) -> Result<RgbImage, Error> {
    const IMAGE: &str = "frame.image";
    let image = image_data(camera)
        .and_then(decode_image)
        .map_err(|e| input_error(IMAGE, camera, &e))?;
    check_size(IMAGE, camera, image.width(), image.height())?;
    Ok(image)
}

/// Decodes the frame's class image and checks it against its calibration's size.
pub fn decode_classes(camera: &CameraImage) -> Result<ClassMask, Error> {
    const IMAGE: &str = "frame.class_image";
    let mask = image_data(camera)
        .and_then(decode_class_mask)
        .map_err(|e| input_error(IMAGE, camera, &e))?;
    check_size(IMAGE, camera, mask.width(), mask.height())?;
    Ok(mask)
}

/// The pixels as perception takes them.
fn image_data(camera: &CameraImage) -> Result<ImageData<'_>, PerceptionError> {
    Ok(match &camera.pixels {
        ImagePixels::Encoded { format, data } => ImageData::compressed(format, data)?,
        &ImagePixels::Rgb8 {
            width,
            height,
            step,
            ref data,
        } => ImageData::Rgb8 {
            width,
            height,
            step,
            data,
        },
        &ImagePixels::Mono8 {
            width,
            height,
            step,
            ref data,
        } => ImageData::Mono8 {
            width,
            height,
            step,
            data,
        },
    })
}

/// The field holding the pixels of `image`: `<image>.compressed.data` or `<image>.raw.data`.
fn data_field(image: &str, camera: &CameraImage) -> String {
    match camera.pixels {
        ImagePixels::Encoded { .. } => format!("{image}.compressed.data"),
        _ => format!("{image}.raw.data"),
    }
}

fn check_size(image: &str, camera: &CameraImage, width: u32, height: u32) -> Result<(), Error> {
    let k = camera.intrinsics;
    if (width, height) == (k.width, k.height) {
        return Ok(());
    }
    Err(Error::invalid(
        data_field(image, camera),
        format!(
            "the image is {width}x{height} but {image}.calibration says {}x{}",
            k.width, k.height
        ),
    ))
}

/// A decoding error of `image`, named by the field it is about.
fn input_error(image: &str, camera: &CameraImage, e: &PerceptionError) -> Error {
    match e {
        PerceptionError::InvalidInput { field, .. } => {
            Error::invalid(format!("{image}.{field}"), e.to_string())
        }
        _ => Error::invalid(data_field(image, camera), e.to_string()),
    }
}

/// Model errors at run time: the image was decoded, so they are the model's.
fn model_error(e: &PerceptionError) -> Error {
    match e {
        PerceptionError::InvalidInput { field, .. } => {
            Error::invalid(format!("frame.image.{field}"), e.to_string())
        }
        _ => Error::Segmentation(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::Intrinsics;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A nadir camera 20 m above the origin (optical z down), 100 × 80 pixels, f = 100.
    fn nadir_class_camera() -> CameraImage {
        CameraImage {
            pixels: ImagePixels::Encoded {
                format: "png".into(),
                data: vec![],
            },
            pose: Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 20.0),
                UnitQuaternion::from_axis_angle(&nalgebra::Vector3::x_axis(), std::f64::consts::PI),
            ),
            intrinsics: Intrinsics {
                width: 100,
                height: 80,
                fx: 100.0,
                fy: 100.0,
                cx: 50.0,
                cy: 40.0,
            },
        }
    }

    #[test]
    fn a_wall_the_scan_hit_casts_footprints_only_for_a_frame_judged_alone() {
        let camera = nadir_class_camera();
        // Rooftop, with a wall one block wide at mask columns 70..72, rows 30..50.
        let mut data = vec![SemanticClass::BuildingRooftop as u8; 100 * 80];
        for y in 30..50 {
            for x in 70..72 {
                data[y * 100 + x] = SemanticClass::BuildingWall as u8;
            }
        }
        let mask = ClassMask::new(100, 80, data).unwrap();
        // A LiDAR point on the wall, 1 m above a roof at z = 5, at the wall's image (71, 40)
        // (the camera looks down the world's -z, its image x along world x).
        let on_wall = [[2.94f32, 0.0, 6.0]];
        let landable = [SemanticClass::BuildingRooftop as u8];
        let blocks = |judged| {
            classify_with_mask(&camera, camera.pose, &mask, &on_wall, &landable, judged)
                .obstacles
                .len()
        };
        assert_eq!(blocks(Judged::Alone), 10);
        // In a stream, the blocks around the point cast nothing; the first block, out of its
        // 3 × 3 mask cells, still does.
        assert_eq!(blocks(Judged::InStream), 1);
    }

    /// With a session per input size the sizes run at once, on threads of their own; the masks
    /// are those of one session running them in turn, and concurrent frames share the sessions.
    #[test]
    fn a_frame_segmented_on_two_sessions_at_once_gets_the_masks_of_one() {
        let root = landing_perception::workspace_root();
        let png = std::fs::read(root.join("perception/tests/data/images/000001.png")).unwrap();
        let image = decode_image(ImageData::Png(&png)).unwrap();
        let landable = [SemanticClass::BuildingRooftop as u8];
        let load = |sessions| {
            Segmenter::load(&SegmentationConfig {
                model_path: root.join("models/rooftop-segmentation.onnx"),
                sessions,
                ..SegmentationConfig::default()
            })
            .unwrap()
        };
        let (one, two) = (load(1), load(2));
        for judged in [Judged::Alone, Judged::InStream] {
            let want = one.segment(&image, judged, &landable).unwrap();
            let got: Vec<Masks> = std::thread::scope(|threads| {
                let frames: Vec<_> = (0..3)
                    .map(|_| threads.spawn(|| two.segment(&image, judged, &landable).unwrap()))
                    .collect();
                frames.into_iter().map(|f| f.join().unwrap()).collect()
            });
            for masks in got {
                assert_eq!(masks.finest, want.finest, "{judged:?}");
                assert_eq!(masks.fused, want.fused, "{judged:?}");
            }
        }
        // The two sizes disagree somewhere, so the fused mask is not the finest one alone.
        let alone = one.segment(&image, Judged::Alone, &landable).unwrap();
        assert_ne!(alone.fused, alone.finest);
    }
}
