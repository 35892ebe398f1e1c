//! The in-process pipeline: one validated frame in, ranked landing sites in world coordinates out.
//!
//! Synchronous and free of tonic types: the service calls [`run_pipeline`] (a frame judged alone)
//! or [`run_fused`] (a fused stream's frame, with the stream's map; its steps in `fused.rs`) on
//! its worker pool, and tests and benchmarks call them directly to compare with what the service
//! answers.

use std::sync::Arc;
use std::time::{Duration, Instant};

use landing_fusion::{Correction, FusionMap, NotRegistered};
use landing_geometry::{CloudKind, Disk, KeepClear, KeepOut, Params, Triangulation};
use landing_perception::ObstacleRays;
use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};

use crate::Error;
pub use crate::frame::{
    CameraImage, Cloud, Frame, FrameOptions, ImagePixels, Intrinsics, SegmentationMode,
};
use crate::segmentation::{self, Judged, PointView, Segmenter};
use landing_geometry::geodetic::{Geodetic, enu_to_geodetic};

mod evidence;
mod fused;
pub use evidence::{Evidence, NotCatalogued, SEEN_CELL_M, rectangles};
pub use fused::run_fused;

/// Time spent in each step; `None` for steps that did not run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageTimings {
    pub queue: Option<Duration>,
    pub decode: Option<Duration>,
    pub segmentation: Option<Duration>,
    pub classification: Option<Duration>,
    pub fusion: Option<Duration>,
    pub triangulation: Option<Duration>,
    pub triangle_filter: Option<Duration>,
    pub plane_extraction: Option<Duration>,
    pub polygon_extraction: Option<Duration>,
    pub polylabel: Option<Duration>,
    pub total: Option<Duration>,
}

/// Every step's name, as [`StageTimings::named`] gives them, in pipeline order.
pub use landing_proto::STAGES;

impl StageTimings {
    /// The steps that ran, by their names in [`STAGES`], in pipeline order (`queue` first,
    /// `total` last).
    pub fn named(&self) -> impl Iterator<Item = (&'static str, Duration)> {
        let durations = [
            self.queue,
            self.decode,
            self.segmentation,
            self.classification,
            self.fusion,
            self.triangulation,
            self.triangle_filter,
            self.plane_extraction,
            self.polygon_extraction,
            self.polylabel,
            self.total,
        ];
        STAGES
            .into_iter()
            .zip(durations)
            .filter_map(|(name, d)| d.map(|d| (name, d)))
    }
}

/// One landing site in world coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    pub rank: u32,
    /// Shell, counter-clockwise seen from above, at the plane height.
    pub shell: Vec<[f64; 3]>,
    /// Holes, clockwise.
    pub holes: Vec<Vec<[f64; 3]>>,
    pub plane_height_m: f64,
    pub center: [f64; 3],
    pub center_geodetic: Option<Geodetic>,
    pub safe_radius_m: f64,
    pub area_m2: f64,
    pub normal: [f64; 3],
    pub point_count: usize,
    pub triangle_count: usize,
}

/// The result of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameOutput {
    pub drone_id: String,
    pub sequence: u64,
    pub timestamp: Option<prost_types::Timestamp>,
    pub sites: Vec<Site>,
    /// The mode actually used (never `Auto`).
    pub segmentation_mode: SegmentationMode,
    pub point_count: usize,
    pub triangle_count: usize,
    pub timings: StageTimings,
    /// What a fused stream's answer came from; `None` for a frame judged alone.
    pub fusion: Option<FusionSummary>,
    /// What a fused stream's answer tells the fleet's catalog, or why nothing; `None` for a frame
    /// judged alone.
    pub catalog: Option<Result<Evidence, NotCatalogued>>,
}

/// The map a fused answer came from (`landing.v1.FusionSummary`).
#[derive(Debug, Clone, PartialEq)]
pub struct FusionSummary {
    pub frames: u32,
    pub points: usize,
    pub cells: usize,
    /// Why the map started over at this frame.
    pub reset: Option<String>,
    pub keep_out_frames: usize,
    /// How the scan was laid onto the map, or why it was fused as it came.
    pub registration: Result<Correction, NotRegistered>,
}

/// A stream's fusion map: cells of the scans and the obstacle rays of recent frames' masks.
pub type StreamMap = FusionMap<ObstacleRays>;

/// What the pipeline needs besides the frame: the default parameters and the segmentation model.
#[derive(Clone, Default)]
pub struct Pipeline {
    /// Parameters used for unset options (the paper's values by default).
    pub defaults: Params,
    /// The segmentation model, when one is loaded.
    pub segmenter: Option<Arc<Segmenter>>,
    /// Whether fused answers carry the evidence the landing-site catalog takes (the server has a
    /// catalog: `catalog.enabled`); without one the work is skipped.
    pub catalogue: bool,
}

impl std::fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipeline")
            .field("defaults", &self.defaults)
            .field("segmenter", &self.segmenter.as_ref().map(|s| s.describe()))
            .finish()
    }
}

impl Pipeline {
    /// A pipeline without a model, using `defaults` for unset options.
    pub fn geometry_only(defaults: Params) -> Self {
        Self {
            defaults,
            segmenter: None,
            catalogue: false,
        }
    }

    /// Resolves `Auto` for this frame, and checks that the chosen mode has what it needs.
    pub fn resolve_mode(
        &self,
        frame: &Frame,
        requested: SegmentationMode,
    ) -> Result<SegmentationMode, Error> {
        match requested {
            SegmentationMode::Unspecified => Ok(if frame.class_image.is_some() {
                SegmentationMode::ClassImage
            } else if frame.image.is_some() && self.segmenter.is_some() {
                SegmentationMode::Model
            } else if frame.cloud.classes.is_some() {
                SegmentationMode::PointClasses
            } else {
                SegmentationMode::None
            }),
            SegmentationMode::Model => {
                if frame.image.is_none() {
                    return Err(Error::invalid(
                        "frame.image",
                        "segmentation mode MODEL needs an image, and the frame has none",
                    ));
                }
                if self.segmenter.is_none() {
                    return Err(Error::ModelUnavailable(
                        "this server has no segmentation model loaded".into(),
                    ));
                }
                Ok(SegmentationMode::Model)
            }
            SegmentationMode::ClassImage => {
                if frame.class_image.is_none() {
                    return Err(Error::invalid(
                        "frame.class_image",
                        "segmentation mode CLASS_IMAGE needs a class image, and the frame has none",
                    ));
                }
                Ok(SegmentationMode::ClassImage)
            }
            SegmentationMode::PointClasses => {
                if frame.cloud.classes.is_none() {
                    return Err(Error::invalid(
                        "frame.point_cloud.fields",
                        "segmentation mode POINT_CLASSES needs a \"class\" field, and the cloud has none",
                    ));
                }
                Ok(SegmentationMode::PointClasses)
            }
            SegmentationMode::None => Ok(SegmentationMode::None),
        }
    }
}

/// Runs the whole pipeline on one frame: classes (per the mode), world transform, geometry,
/// and world/geodetic results. Blocking and CPU-bound: call it from a worker thread.
///
/// Everything between the request and the answer runs in frame-local coordinates (the world
/// moved so that the cloud's bounding-box centre is the origin): the geometry's single-precision
/// points keep their millimetres wherever the world origin is, up to the API's 1e7 m.
pub fn run_pipeline(
    frame: &Frame,
    options: &FrameOptions,
    pipeline: &Pipeline,
) -> Result<FrameOutput, Error> {
    let start = Instant::now();
    let world = to_world(&frame.cloud);
    let origin = landing_fusion::centre(&world, frame.cloud.pose.translation.vector.into());
    let segmented = segment(
        decode(frame, options, pipeline)?,
        options,
        pipeline,
        Judged::Alone,
    )?;
    let c = classify(
        frame,
        segmented,
        &to_local(origin),
        relative_to(&world, origin),
        options,
    )?;
    let keep_out: Vec<&ObstacleRays> = c.obstacles.iter().collect();
    let coarse = c
        .view
        .as_ref()
        .map_or_else(Vec::new, |v| seen_coarsely(v, &c.points));
    let located = Located {
        points: &c.points,
        classes: c.classes.as_deref(),
        kind: CloudKind::Scan,
        keep_out: &keep_out,
        unresolved: &coarse,
        origin,
        params: &options.params,
        triangulated: None,
    };
    locate(frame, located, c.mode, c.timings, start)
}

/// A frame judged alone keeps its safe circles off the places its camera saw no finer than this,
/// metres per class pixel (the longer side of the patch of level ground a pixel covers): an
/// obstacle the scan lines missed is there only in the image, and an air vent (0.4-1 m across)
/// spans under three pixels this coarse, too few for the model to call it. A 320-pixel mask of a
/// 70° camera covers 0.3 m at 69 m straight down and at about 53 m looking 50° down: the
/// highest frames of an approach (EVALUATION.md, "Today: single frames"; 0.2 m cost 0.09 of
/// mean IoU there, 0.4 m removed nothing). A fused stream keeps the same kind of rule with its
/// own bound (`fusion.max_pixel_footprint_m`), over the finest view any of its frames had.
pub const SINGLE_FRAME_MAX_PIXEL_FOOTPRINT_M: f64 = 0.3;

/// Per point: whether `view` saw it coarser than [`SINGLE_FRAME_MAX_PIXEL_FOOTPRINT_M`] (points
/// out of view are left unflagged: no pixel gave them a class).
fn seen_coarsely(view: &PointView, points: &[[f32; 3]]) -> Vec<bool> {
    points
        .iter()
        .map(|p| {
            let p = Point3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
            view.footprint_on_level_ground(&p)
                .is_some_and(|f| f > SINGLE_FRAME_MAX_PIXEL_FOOTPRINT_M)
        })
        .collect()
}

/// The move from world coordinates to those relative to `origin`.
fn to_local(origin: [f64; 3]) -> Isometry3<f64> {
    Isometry3::translation(-origin[0], -origin[1], -origin[2])
}

/// `points` relative to `origin`, in the single precision the geometry takes.
fn relative_to(points: &[[f64; 3]], origin: [f64; 3]) -> Vec<[f32; 3]> {
    points
        .iter()
        .map(|p| std::array::from_fn(|i| (p[i] - origin[i]) as f32))
        .collect()
}

/// A frame's points with their classes, before geometry.
struct Classified {
    /// The cloud in frame-local coordinates.
    points: Vec<[f32; 3]>,
    classes: Option<Vec<u8>>,
    /// The class mask's obstacle pixels, when a mask classified the points.
    obstacles: Option<ObstacleRays>,
    /// The view that classified the points, when a mask did.
    view: Option<PointView>,
    mode: SegmentationMode,
    timings: StageTimings,
}

/// A frame's images decoded and its mode resolved: what can be wrong with its input is known.
struct Decoded {
    mode: SegmentationMode,
    image: Option<landing_perception::RgbImage>,
    class_mask: Option<landing_perception::ClassMask>,
    /// Time spent decoding, when there was an image.
    time: Option<Duration>,
}

/// Resolves the frame's mode and decodes its images.
fn decode(frame: &Frame, options: &FrameOptions, pipeline: &Pipeline) -> Result<Decoded, Error> {
    let mode = pipeline.resolve_mode(frame, options.segmentation_mode)?;
    // Every image is decoded, so that a bad one is reported whatever the mode.
    let decode_start = Instant::now();
    let image = frame.image.as_ref().map(segmentation::decode).transpose()?;
    let class_mask = frame
        .class_image
        .as_ref()
        .map(segmentation::decode_classes)
        .transpose()?;
    let time = (image.is_some() || class_mask.is_some()).then(|| decode_start.elapsed());
    Ok(Decoded {
        mode,
        image,
        class_mask,
        time,
    })
}

/// A [`decode`]d frame with its image segmented when the mode says so ([`segment`]).
struct Segmented {
    mode: SegmentationMode,
    masks: Option<segmentation::Masks>,
    class_mask: Option<landing_perception::ClassMask>,
    judged: Judged,
    timings: StageTimings,
}

/// Segments the [`decode`]d frame's image, in model mode, as the frame is `judged`
/// ([`Judged`]). Needs no pose, so a fused stream registers its scan meanwhile.
fn segment(
    decoded: Decoded,
    options: &FrameOptions,
    pipeline: &Pipeline,
    judged: Judged,
) -> Result<Segmented, Error> {
    let Decoded {
        mode,
        image,
        class_mask,
        time,
    } = decoded;
    let mut timings = StageTimings {
        decode: time,
        ..StageTimings::default()
    };
    let masks = match (mode, &image, &pipeline.segmenter) {
        (SegmentationMode::Model, Some(image), Some(segmenter)) => {
            let masks = segmenter.segment(image, judged, &options.params.landable_classes)?;
            timings.segmentation = Some(masks.time);
            Some(masks)
        }
        // resolve_mode checked both; classify reports their absence rather than panic.
        _ => None,
    };
    Ok(Segmented {
        mode,
        masks,
        class_mask,
        judged,
        timings,
    })
}

/// Classifies the [`segment`]ed frame's points per the mode. `points` is the cloud in the
/// coordinates the frame's poses give once moved by `by` (frame-local ones from the callers);
/// the frame itself is not copied.
fn classify(
    frame: &Frame,
    segmented: Segmented,
    by: &Isometry3<f64>,
    points: Vec<[f32; 3]>,
    options: &FrameOptions,
) -> Result<Classified, Error> {
    let Segmented {
        mode,
        masks,
        class_mask,
        judged,
        mut timings,
    } = segmented;
    let landable = &options.params.landable_classes;
    let from_mask = match mode {
        SegmentationMode::Model => {
            // resolve_mode checked both; keep the error rather than panic.
            let (Some(masks), Some(camera)) = (masks, &frame.image) else {
                return Err(Error::Internal("model mode without image or model".into()));
            };
            Some(masks.classify(camera, by * camera.pose, &points, landable))
        }
        SegmentationMode::ClassImage => {
            let (Some(mask), Some(camera)) = (class_mask, &frame.class_image) else {
                return Err(Error::Internal(
                    "class image mode without a class image".into(),
                ));
            };
            Some(segmentation::classify_with_mask(
                camera,
                by * camera.pose,
                &mask,
                &points,
                landable,
                judged,
            ))
        }
        SegmentationMode::PointClasses | SegmentationMode::None | SegmentationMode::Unspecified => {
            None
        }
    };
    let (classes, obstacles, view) = match from_mask {
        Some(out) => {
            timings.classification = Some(out.classification);
            (Some(out.classes), Some(out.obstacles), Some(out.view))
        }
        None if mode == SegmentationMode::PointClasses => (frame.cloud.classes.clone(), None, None),
        None => (None, None, None),
    };
    Ok(Classified {
        points,
        classes,
        obstacles,
        view,
        mode,
        timings,
    })
}

/// What the geometry runs on: frame-local points, their classes, what kind of cloud they are, the
/// obstacle rays whose footprints safe circles keep clear of (in the same coordinates), and the
/// world position of their origin.
struct Located<'a> {
    points: &'a [[f32; 3]],
    classes: Option<&'a [u8]>,
    /// A frame's scan, or a fused stream's map.
    kind: CloudKind,
    keep_out: &'a [&'a ObstacleRays],
    /// Per point (empty for none): on landable ground no camera has seen finely enough yet
    /// (`landing_fusion::Fused::unresolved`), or, for a frame judged alone, seen by its camera
    /// only coarsely ([`SINGLE_FRAME_MAX_PIXEL_FOOTPRINT_M`]). Safe circles keep off every triangle with such a
    /// vertex: the points are a sample of the unresolved ground, and early in an approach a
    /// 16-beam scan's lines lie up to ~2.4 m apart on the roof, so the ground between them is as
    /// unresolved as they are. The polygons still hold those triangles (the votes call them
    /// roof).
    unresolved: &'a [bool],
    origin: [f64; 3],
    /// The request's parameters.
    params: &'a Params,
    /// The points' triangulation and its time, when it was made beforehand.
    triangulated: Option<(Triangulation, Duration)>,
}

/// The geometry on classified frame-local points, and the world/geodetic results.
fn locate(
    frame: &Frame,
    input: Located<'_>,
    mode: SegmentationMode,
    mut timings: StageTimings,
    start: Instant,
) -> Result<FrameOutput, Error> {
    let origin = input.origin;
    let point_count = input.points.len();
    let (detection, triangulation) = detect(input)?;
    let t = detection.timings;
    timings.triangulation = Some(triangulation.unwrap_or(t.triangulation));
    timings.triangle_filter = Some(t.triangle_filter);
    timings.plane_extraction = Some(t.plane_extraction);
    timings.polygon_extraction = Some(t.polygon_extraction);
    timings.polylabel = Some(t.polylabel);
    let sites = detection
        .sites
        .iter()
        .map(|s| in_world(s, origin, frame.geodetic_origin))
        .collect();
    timings.total = Some(start.elapsed());
    Ok(FrameOutput {
        drone_id: frame.drone_id.clone(),
        sequence: frame.sequence,
        timestamp: frame.timestamp,
        sites,
        segmentation_mode: mode,
        point_count,
        triangle_count: detection.triangle_count,
        timings,
        fusion: None,
        catalog: None,
    })
}

/// Several frames' obstacle rays, oldest first, as the geometry's keep-out disks: on each
/// plane, [`ObstacleRays::newest_view_on_plane`] (where a newer camera sees, its view decides).
struct NewestViews<'a>(&'a [&'a ObstacleRays]);

impl KeepOut for NewestViews<'_> {
    fn disks_on_plane(&self, point: [f64; 3], normal: [f64; 3], bounds: [f64; 4]) -> Vec<Disk> {
        self.wanted_disks_on_plane(point, normal, bounds, &|_| true)
    }

    fn wanted_disks_on_plane(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
        wanted: &dyn Fn(&[f64; 4]) -> bool,
    ) -> Vec<Disk> {
        ObstacleRays::newest_view_on_plane(self.0, point, normal, bounds, wanted)
            .into_iter()
            .map(|(center, radius)| Disk { center, radius })
            .collect()
    }
}

/// Runs the geometry on `input`: the detection, and the time of the triangulation when it was
/// made beforehand.
fn detect(input: Located<'_>) -> Result<(landing_geometry::Detection, Option<Duration>), Error> {
    let Located {
        points,
        classes,
        kind,
        keep_out,
        unresolved,
        origin: _,
        params,
        triangulated,
    } = input;
    let (given, triangulation) = triangulated.unzip();
    let disks = NewestViews(keep_out);
    let mut cloud = landing_geometry::Cloud::new(points, classes).with_kind(kind);
    // With a class mask, safe circles also keep clear of the obstacle pixels: the camera sees
    // what fell between the LiDAR's scan lines. (A fused map always has a triangulation given.)
    if !(keep_out.is_empty() && unresolved.is_empty() && given.is_none()) {
        cloud = cloud.with_keep_clear(KeepClear {
            disks: Some(&disks),
            points: (!unresolved.is_empty()).then_some(unresolved),
        });
    }
    if let Some(tri) = &given {
        cloud = cloud.with_triangulation(tri);
    }
    Ok((landing_geometry::detect(&cloud, params)?, triangulation))
}

/// A site found in frame-local coordinates relative to `origin`, in world coordinates.
fn in_world(
    s: &landing_geometry::LandingSite,
    origin: [f64; 3],
    geodetic_origin: Option<Geodetic>,
) -> Site {
    let [x0, y0, z0] = origin;
    let z = s.plane_height_m + z0;
    let ring = |r: &[[f64; 2]]| {
        r.iter()
            .map(|p| [p[0] + x0, p[1] + y0, z])
            .collect::<Vec<_>>()
    };
    let center = std::array::from_fn(|i| s.center[i] + origin[i]);
    Site {
        rank: s.rank,
        shell: ring(&s.polygon.shell),
        holes: s.polygon.holes.iter().map(|h| ring(h)).collect(),
        plane_height_m: z,
        center,
        center_geodetic: geodetic_origin.map(|o| enu_to_geodetic(o, center)),
        safe_radius_m: s.safe_radius_m,
        area_m2: s.area_m2,
        normal: s.normal,
        point_count: s.point_count,
        triangle_count: s.triangle_count,
    }
}

/// The cloud's points in the world frame, in double precision.
pub fn to_world(cloud: &Cloud) -> Vec<[f64; 3]> {
    cloud
        .points
        .iter()
        .map(|&p| (cloud.pose * Point3::from(p)).into())
        .collect()
}

/// A pose from a position and a quaternion (x, y, z, w) that is normalised here; `None` when the
/// quaternion has (near) zero norm or a non-finite component.
pub fn pose(position: [f64; 3], quaternion: [f64; 4]) -> Option<Isometry3<f64>> {
    let [x, y, z, w] = quaternion;
    let q = nalgebra::Quaternion::new(w, x, y, z);
    let norm = q.norm();
    if !norm.is_finite() || norm < 1e-9 || position.iter().any(|c| !c.is_finite()) {
        return None;
    }
    Some(Isometry3::from_parts(
        Vector3::new(position[0], position[1], position[2]).into(),
        UnitQuaternion::from_quaternion(q),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 120 × 120 class image (`data`, row-major) from a camera at the origin looking straight
    /// down, focal length `f` pixels.
    fn looking_down(f: f64, data: Vec<u8>) -> CameraImage {
        let side = 120u32;
        let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        CameraImage {
            pixels: ImagePixels::Mono8 {
                width: side,
                height: side,
                step: side,
                data,
            },
            pose: Isometry3::from_parts(Vector3::zeros().into(), down),
            intrinsics: Intrinsics {
                width: side,
                height: side,
                fx: f,
                fy: f,
                cx: 60.0,
                cy: 60.0,
            },
        }
    }

    fn frame(points: Vec<[f64; 3]>, classes: Option<Vec<u8>>) -> Frame {
        Frame {
            drone_id: "d1".into(),
            sequence: 7,
            timestamp: None,
            cloud: Cloud {
                points,
                classes,
                pose: Isometry3::identity(),
            },
            image: None,
            class_image: None,
            geodetic_origin: None,
        }
    }

    #[test]
    fn pose_normalises_and_rejects_zero_quaternion() {
        let p = pose([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 2.0]).unwrap();
        assert_eq!(p, Isometry3::translation(1.0, 2.0, 3.0));
        assert!(pose([0.0; 3], [0.0; 4]).is_none());
        assert!(pose([f64::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]).is_none());
    }

    #[test]
    fn to_world_rotates_and_translates() {
        // 90 degrees about z: x -> y.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let cloud = Cloud {
            points: vec![[1.0, 0.0, 0.0]],
            classes: None,
            pose: pose([10.0, 0.0, 5.0], [0.0, 0.0, h, h]).unwrap(),
        };
        let w = to_world(&cloud)[0];
        assert!(
            (w[0] - 10.0).abs() < 1e-12 && (w[1] - 1.0).abs() < 1e-12 && (w[2] - 5.0).abs() < 1e-12,
            "{w:?}"
        );
    }

    #[test]
    fn auto_mode_resolves_by_what_the_frame_has() {
        let p = Pipeline::default();
        let with_classes = frame(vec![], Some(vec![]));
        assert_eq!(
            p.resolve_mode(&with_classes, SegmentationMode::Unspecified),
            Ok(SegmentationMode::PointClasses)
        );
        let bare = frame(vec![], None);
        assert_eq!(
            p.resolve_mode(&bare, SegmentationMode::Unspecified),
            Ok(SegmentationMode::None)
        );
        let e = p
            .resolve_mode(&bare, SegmentationMode::PointClasses)
            .unwrap_err();
        assert!(e.to_string().contains("frame.point_cloud.fields"), "{e}");
        let e = p.resolve_mode(&bare, SegmentationMode::Model).unwrap_err();
        assert!(e.to_string().contains("frame.image"), "{e}");
        let e = p
            .resolve_mode(&bare, SegmentationMode::ClassImage)
            .unwrap_err();
        assert!(e.to_string().contains("frame.class_image"), "{e}");
        // A class image comes first, even over the cloud's own classes.
        let mut with_class_image = with_classes;
        with_class_image.class_image = Some(CameraImage {
            pixels: ImagePixels::Mono8 {
                width: 1,
                height: 1,
                step: 1,
                data: vec![4],
            },
            pose: Isometry3::identity(),
            intrinsics: Intrinsics {
                width: 1,
                height: 1,
                fx: 1.0,
                fy: 1.0,
                cx: 0.5,
                cy: 0.5,
            },
        });
        assert_eq!(
            p.resolve_mode(&with_class_image, SegmentationMode::Unspecified),
            Ok(SegmentationMode::ClassImage)
        );
    }

    #[test]
    fn pipeline_echoes_identity_and_mode() {
        let out = run_pipeline(
            &frame(vec![[0.0, 0.0, 0.0]; 3], None),
            &FrameOptions::default(),
            &Pipeline::default(),
        )
        .unwrap();
        assert_eq!((out.drone_id.as_str(), out.sequence), ("d1", 7));
        assert_eq!(out.segmentation_mode, SegmentationMode::None);
        assert!(out.timings.total.is_some());
    }

    #[test]
    fn a_frame_judged_alone_keeps_its_circles_off_what_its_camera_saw_coarsely() {
        // A 12 m roof of points 0.3 m apart, 20 m below a camera looking straight down, all
        // rooftop in its class image: with a focal length of 100 pixels each pixel covers 0.2 m
        // of the roof, with 40 pixels 0.5 m, coarser than a frame judged alone lands on.
        let mut points = Vec::new();
        for y in 0..40 {
            for x in 0..40 {
                let at = |i: i32| 0.3 * f64::from(i) - 6.0 + 0.001 * f64::from((i * 7) % 5);
                points.push([at(x), at(y), -20.0]);
            }
        }
        let seen = |f: f64| Frame {
            class_image: Some(looking_down(
                f,
                vec![landing_geometry::SemanticClass::BuildingRooftop as u8; 120 * 120],
            )),
            ..frame(points.clone(), None)
        };
        let options = FrameOptions {
            segmentation_mode: SegmentationMode::ClassImage,
            ..FrameOptions::default()
        };
        let pipeline = Pipeline::default();
        let fine = run_pipeline(&seen(100.0), &options, &pipeline).unwrap();
        assert_eq!(fine.sites.len(), 1);
        assert!(
            fine.sites[0].safe_radius_m > 5.0,
            "{}",
            fine.sites[0].safe_radius_m
        );
        let coarse = run_pipeline(&seen(40.0), &options, &pipeline).unwrap();
        assert!(coarse.sites.is_empty(), "{:?}", coarse.sites);
    }

    #[test]
    fn a_fused_answer_closes_the_pinholes_a_frame_judged_alone_keeps() {
        // A 12 m roof of points 0.3 m apart (one a map cell), 20 m below the LiDAR, and 25 pairs
        // of neighbours 0.12 m apart in height: the two triangles on each pair's edge tilt past
        // min_normal_dot, a hole with no point of its own.
        let mut points = Vec::new();
        for y in 0..40 {
            for x in 0..40 {
                let jitter = 0.003 * f64::from((x * 7 + y * 3) % 5);
                let dz = match (x % 8, y % 8) {
                    (3, 3) => 0.06,
                    (4, 3) => -0.06,
                    _ => 0.0,
                };
                let at = |i: i32| 0.3 * f64::from(i) - 6.0;
                points.push([at(x) + jitter, at(y) - jitter, -20.0 + dz]);
            }
        }
        let classes = vec![landing_geometry::SemanticClass::BuildingRooftop as u8; points.len()];
        let f = frame(points, Some(classes));
        let (options, pipeline) = (FrameOptions::default(), Pipeline::default());
        let holes = |out: &FrameOutput| out.sites.iter().map(|s| s.holes.len()).sum::<usize>();
        assert_eq!(holes(&run_pipeline(&f, &options, &pipeline).unwrap()), 25);
        // No camera resolves the cells here: the resolution rule off.
        let params = landing_fusion::FusionParams {
            max_pixel_footprint_m: 0.0,
            ..crate::Config::default().fusion.params()
        };
        let mut map = StreamMap::new(params).unwrap();
        let fused = run_fused(&f, &options, &pipeline, &mut map, false).unwrap();
        assert_eq!(fused.sites.len(), 1);
        assert_eq!(holes(&fused), 0);
    }

    #[test]
    fn a_fused_frame_with_a_bad_image_is_refused_before_the_map_changes() {
        let points: Vec<[f64; 3]> = (0..400)
            .map(|i| [0.3 * f64::from(i % 20), 0.3 * f64::from(i / 20), -20.0])
            .collect();
        let classes = vec![landing_geometry::SemanticClass::BuildingRooftop as u8; points.len()];
        let good = frame(points.clone(), Some(classes.clone()));
        let (options, pipeline) = (FrameOptions::default(), Pipeline::default());
        let mut map = StreamMap::new(crate::Config::default().fusion.params()).unwrap();
        run_fused(&good, &options, &pipeline, &mut map, false).unwrap();
        let (frames, cells) = (map.frames(), map.cells());
        // The next frame's points are new ground, and its class image is not a PNG.
        let moved: Vec<[f64; 3]> = points.iter().map(|p| [p[0] + 10.0, p[1], p[2]]).collect();
        let mut bad = frame(moved, Some(classes));
        bad.class_image = Some(CameraImage {
            pixels: ImagePixels::Encoded {
                format: "png".into(),
                data: vec![1, 2, 3],
            },
            pose: Isometry3::identity(),
            intrinsics: Intrinsics {
                width: 4,
                height: 4,
                fx: 1.0,
                fy: 1.0,
                cx: 2.0,
                cy: 2.0,
            },
        });
        let e = run_fused(&bad, &options, &pipeline, &mut map, false).unwrap_err();
        assert!(e.to_string().contains("frame.class_image"), "{e}");
        assert_eq!((map.frames(), map.cells()), (frames, cells));
    }

    #[test]
    fn a_fused_answer_keeps_clear_of_footprints_only_where_the_map_has_a_gap() {
        // A 12 m roof of points 0.2 m apart (one a map cell), 20 m below a camera looking
        // straight down whose pixels span 0.2 m there, and which sees an AC unit of 1.2 x 1.2 m
        // in the middle (a true label image): the best circles sit in a corner and touch it.
        let unit = |x: f64, y: f64| x.abs() <= 0.6 && y.abs() <= 0.6;
        let (side, f) = (120u32, 100.0);
        let mut data = vec![landing_geometry::SemanticClass::BuildingRooftop as u8; 120 * 120];
        for v in 0..side {
            for u in 0..side {
                // The pixel's centre on the roof (the camera's x right, y down, looking down).
                let x = (f64::from(u) + 0.5 - 60.0) / f * 20.0;
                let y = -(f64::from(v) + 0.5 - 60.0) / f * 20.0;
                if unit(x, y) {
                    data[(v * side + u) as usize] = landing_geometry::SemanticClass::AcUnit as u8;
                }
            }
        }
        let labels = looking_down(f, data);
        let roof = |missed: bool| {
            let mut points = Vec::new();
            for y in 0..60 {
                for x in 0..60 {
                    let at = |i: i32| 0.2 * f64::from(i) - 5.9 + 0.001 * f64::from((i * 7) % 5);
                    let (px, py) = (at(x), at(y));
                    if !(missed && unit(px, py)) {
                        points.push([px, py, -20.0]);
                    }
                }
            }
            Frame {
                class_image: Some(labels.clone()),
                ..frame(points, None)
            }
        };
        // A fine polylabel search, so that the circles show a tenth of a metre.
        let options = FrameOptions {
            segmentation_mode: SegmentationMode::ClassImage,
            params: Params {
                polylabel_precision_m: 0.01,
                ..Params::default()
            },
        };
        let pipeline = Pipeline::default();
        let fused = |f: &Frame| {
            let params = landing_fusion::FusionParams {
                max_pixel_footprint_m: 0.0,
                ..crate::Config::default().fusion.params()
            };
            let mut map = StreamMap::new(params).unwrap();
            run_fused(f, &options, &pipeline, &mut map, false).unwrap()
        };
        // How deep a circle reaches into the unit's footprint.
        let depth = |s: &Site| {
            let (dx, dy) = (s.center[0].abs() - 0.6, s.center[1].abs() - 0.6);
            let outside = dx.max(0.0).hypot(dy.max(0.0)) + dx.max(dy).min(0.0);
            (s.safe_radius_m - outside).max(0.0)
        };
        // The scan hit the unit (its points are labelled so and make a hole): judged alone, the
        // circle keeps clear of the camera's footprints around the hole too; fused, the map's
        // dense roof points show the ground there, and only the hole bounds it.
        let hit = roof(false);
        let alone = run_pipeline(&hit, &options, &pipeline).unwrap();
        let together = fused(&hit);
        let (a, b) = (&alone.sites[0], &together.sites[0]);
        let (ra, rb) = (a.safe_radius_m, b.safe_radius_m);
        assert!(rb > ra + 0.05, "judged alone {ra} m, fused {rb} m");
        // (The hole's corners are cut by the triangles past the unit's corners: by millimetres.)
        assert!(depth(b) < 0.01, "{} m into the unit", depth(b));
        // The scan missed it (no point on or under it): the footprints over the gap still count.
        let missed = fused(&roof(true));
        let c = &missed.sites[0];
        assert!(
            depth(c) <= 0.3 / 3f64.sqrt(),
            "{} m into the unit",
            depth(c)
        );
    }

    #[test]
    fn a_fused_answer_ends_its_polygons_halfway_to_the_first_obstacle_point() {
        // A 12 m roof of points 0.2 m apart (no two in one map cell), 20 m below the LiDAR, with
        // an AC unit's points over 1 m² in the middle: the hole around it ends at the last roof
        // points judged alone, halfway to the unit's points fused.
        let mut points = Vec::new();
        let mut classes = Vec::new();
        for y in 0..60 {
            for x in 0..60 {
                let at = |i: i32| 0.2 * f64::from(i) - 6.0 + 0.001 * f64::from((i * 7) % 5);
                points.push([at(x), at(y), -20.0]);
                let unit = (28..=33).contains(&x) && (28..=33).contains(&y);
                classes.push(if unit {
                    landing_geometry::SemanticClass::AcUnit as u8
                } else {
                    landing_geometry::SemanticClass::BuildingRooftop as u8
                });
            }
        }
        let f = frame(points, Some(classes));
        let (options, pipeline) = (FrameOptions::default(), Pipeline::default());
        let hole_area = |out: &FrameOutput| {
            assert_eq!(out.sites.len(), 1);
            assert_eq!(out.sites[0].holes.len(), 1);
            let hole: Vec<[f64; 2]> = out.sites[0].holes[0].iter().map(|p| [p[0], p[1]]).collect();
            landing_geometry::validation::ring_signed_area(&hole).abs()
        };
        let alone = run_pipeline(&f, &options, &pipeline).unwrap();
        let params = landing_fusion::FusionParams {
            max_pixel_footprint_m: 0.0,
            ..crate::Config::default().fusion.params()
        };
        let mut map = StreamMap::new(params).unwrap();
        let fused = run_fused(&f, &options, &pipeline, &mut map, false).unwrap();
        // The unit's points span 1.0 m, the last roof points around it 1.4 m (a square less the
        // corners the triangles cut). Fused, the hole runs through the midpoints of the edges
        // from the roof points to the unit's: through 1.2 m where a triangle has two roof
        // corners, saw-toothed out to the unit's points where it has one.
        let (a, b) = (hole_area(&alone), hole_area(&fused));
        assert!(a > 1.8 && a <= 1.4 * 1.4, "judged alone: {a} m²");
        assert!(b >= 1.2 * 1.2 && b < a - 0.3, "fused: {b} m²");
    }
}
