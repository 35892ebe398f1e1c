//! Conversions between `landing.v1` messages and the pipeline's domain types.
//!
//! Proto → domain conversions validate every field and report each bad one by its path in the
//! request (`frame.point_cloud.data`, `options.min_normal_dot`, ...), collected into one
//! [`Error::InvalidArgument`]. Domain → proto conversions cannot fail.

use landing_geometry::Params;
use landing_proto::v1;
use nalgebra::Isometry3;

use crate::config::FusionConfig;
use crate::pipeline::{
    CameraImage, Cloud, Frame, FrameOptions, FrameOutput, ImagePixels, Intrinsics,
    SegmentationMode, Site, StageTimings, StreamMap, pose,
};
use crate::{Error, FieldViolation};
use landing_geometry::geodetic::Geodetic;

/// Largest coordinate magnitude accepted, metres: beyond this a value is corrupt, not a city.
pub const MAX_COORDINATE_M: f64 = 1.0e7;
/// Largest image side accepted, pixels.
pub const MAX_IMAGE_SIDE: u32 = 8192;
/// Highest class number ([`landing_geometry::SemanticClass::Vegetation`]).
const MAX_CLASS: u8 = 14;

/// Validates and converts the frame and options of a unary request.
pub fn request_parts(
    request: &v1::DetectLandingSitesRequest,
    defaults: &Params,
) -> Result<(Frame, FrameOptions), Error> {
    parts(request.frame.as_ref(), request.options.as_ref(), defaults)
}

/// Validates and converts the frame and options of one stream message.
pub fn stream_parts(
    request: &v1::StreamLandingSitesRequest,
    defaults: &Params,
) -> Result<(Frame, FrameOptions), Error> {
    parts(request.frame.as_ref(), request.options.as_ref(), defaults)
}

fn parts(
    frame: Option<&v1::Frame>,
    options: Option<&v1::PipelineOptions>,
    defaults: &Params,
) -> Result<(Frame, FrameOptions), Error> {
    let mut violations = Vec::new();
    let frame = match frame {
        None => {
            violations.push(FieldViolation::new("frame", "required"));
            None
        }
        Some(f) => match Frame::try_from(f) {
            Ok(f) => Some(f),
            Err(Error::InvalidArgument(v)) => {
                violations.extend(v);
                None
            }
            Err(other) => return Err(other),
        },
    };
    let options = match options_from(options, defaults) {
        Ok(o) => Some(o),
        Err(Error::InvalidArgument(v)) => {
            violations.extend(v);
            None
        }
        Err(other) => return Err(other),
    };
    match (frame, options) {
        (Some(f), Some(o)) if violations.is_empty() => Ok((f, o)),
        _ => Err(Error::InvalidArgument(violations)),
    }
}

/// Collects violations with a path prefix.
struct Checker {
    prefix: &'static str,
    violations: Vec<FieldViolation>,
}

impl Checker {
    fn new(prefix: &'static str) -> Self {
        Self {
            prefix,
            violations: Vec::new(),
        }
    }

    fn bad(&mut self, field: impl AsRef<str>, description: impl Into<String>) {
        let field = field.as_ref();
        let path = if field.is_empty() {
            self.prefix.to_owned()
        } else {
            format!("{}.{field}", self.prefix)
        };
        self.violations.push(FieldViolation::new(path, description));
    }

    fn finish<T>(self, value: Option<T>) -> Result<T, Error> {
        match value {
            Some(v) if self.violations.is_empty() => Ok(v),
            _ => Err(Error::InvalidArgument(self.violations)),
        }
    }
}

impl TryFrom<&v1::Frame> for Frame {
    type Error = Error;

    /// Checks `drone_id`, `timestamp`, `point_cloud` (layout, length, values, pose), `image` and
    /// `class_image` (pose, calibration, pixels) and `geodetic_origin`.
    fn try_from(f: &v1::Frame) -> Result<Self, Error> {
        let mut c = Checker::new("frame");
        if f.drone_id.len() > 256 {
            c.bad(
                "drone_id",
                format!("{} bytes long; at most 256", f.drone_id.len()),
            );
        }
        if let Some(t) = &f.timestamp {
            check_timestamp(&mut c, "timestamp", t);
        }
        let cloud = match &f.point_cloud {
            None => {
                c.bad("point_cloud", "required");
                None
            }
            Some(pc) => cloud(&mut c, pc),
        };
        let image = match &f.image {
            None => Some(None),
            Some(img) => camera_image(&mut c, "image", img, ImageKind::Colour).map(Some),
        };
        let class_image = match &f.class_image {
            None => Some(None),
            Some(img) => camera_image(&mut c, "class_image", img, ImageKind::Classes).map(Some),
        };
        let geodetic_origin = match &f.geodetic_origin {
            None => Some(None),
            Some(g) => geodetic(&mut c, g).map(Some),
        };
        let frame = match (cloud, image, class_image, geodetic_origin) {
            (Some(cloud), Some(image), Some(class_image), Some(geodetic_origin)) => Some(Frame {
                drone_id: f.drone_id.clone(),
                sequence: f.sequence,
                timestamp: f.timestamp,
                cloud,
                image,
                class_image,
                geodetic_origin,
            }),
            _ => None,
        };
        c.finish(frame)
    }
}

fn check_timestamp(c: &mut Checker, field: &str, t: &prost_types::Timestamp) {
    if !(0..1_000_000_000).contains(&t.nanos) {
        c.bad(
            format!("{field}.nanos"),
            format!("{} is outside 0..1e9", t.nanos),
        );
    }
}

fn pose_of(c: &mut Checker, field: &str, p: &v1::Pose) -> Option<Isometry3<f64>> {
    let position = p.position.as_ref().map_or([0.0; 3], |v| [v.x, v.y, v.z]);
    if let Some((axis, v)) = ["x", "y", "z"]
        .iter()
        .zip(position)
        .find(|(_, v)| !v.is_finite() || v.abs() > MAX_COORDINATE_M)
    {
        c.bad(
            format!("{field}.position.{axis}"),
            format!("{v} is not a finite coordinate within 1e7 m"),
        );
        return None;
    }
    let q = p
        .orientation
        .as_ref()
        .map_or([0.0, 0.0, 0.0, 1.0], |q| [q.x, q.y, q.z, q.w]);
    match pose(position, q) {
        Some(pose) => Some(pose),
        None => {
            c.bad(
                format!("{field}.orientation"),
                format!("quaternion {q:?} has zero or non-finite norm"),
            );
            None
        }
    }
}

#[derive(Clone, Copy)]
enum Coord {
    F32(usize),
    F64(usize),
}

impl Coord {
    #[inline]
    fn read(self, point: &[u8]) -> f64 {
        match self {
            Coord::F32(o) => f64::from(f32::from_le_bytes([
                point[o],
                point[o + 1],
                point[o + 2],
                point[o + 3],
            ])),
            Coord::F64(o) => {
                let mut b = [0u8; 8];
                b.copy_from_slice(&point[o..o + 8]);
                f64::from_le_bytes(b)
            }
        }
    }
}

fn cloud(c: &mut Checker, pc: &v1::PointCloud) -> Option<Cloud> {
    let before = c.violations.len();
    if let Some(t) = &pc.timestamp {
        check_timestamp(c, "point_cloud.timestamp", t);
    }
    let pose = match &pc.pose {
        None => Some(Isometry3::identity()),
        Some(p) => pose_of(c, "point_cloud.pose", p),
    };
    let layout = cloud_layout(c, pc);
    if c.violations.len() > before {
        return None;
    }
    read_points(c, &pc.data, &layout?, pose?)
}

/// Where a packed point keeps its coordinates and its class.
struct CloudLayout {
    stride: usize,
    xyz: [Coord; 3],
    class_offset: Option<usize>,
}

/// Checks `point_cloud.point_stride`, `.fields` and the length of `.data`; `None` (with the
/// violations recorded) unless x, y and z can be read.
fn cloud_layout(c: &mut Checker, pc: &v1::PointCloud) -> Option<CloudLayout> {
    let stride = pc.point_stride as usize;
    if stride == 0 {
        c.bad("point_cloud.point_stride", "must be > 0");
    }
    let mut xyz: [Option<Coord>; 3] = [None; 3];
    let mut class_offset = None;
    let mut seen = std::collections::HashSet::new();
    for (i, field) in pc.fields.iter().enumerate() {
        let path = format!("point_cloud.fields[{i}]");
        if !seen.insert(field.name.as_str()) {
            c.bad(
                format!("{path}.name"),
                format!("field {:?} appears twice", field.name),
            );
            continue;
        }
        let Some((ty, offset)) = packed_field(c, &path, field, stride) else {
            continue;
        };
        match field.name.as_str() {
            "x" | "y" | "z" => {
                let axis = usize::from(field.name.as_bytes()[0] - b'x');
                xyz[axis] = coordinate(c, &path, &field.name, ty, offset);
            }
            "class" => {
                if ty == v1::NumericType::Uint8 {
                    class_offset = Some(offset);
                } else {
                    c.bad(
                        format!("{path}.type"),
                        format!("\"class\" must be UINT8, not {}", ty.as_str_name()),
                    );
                }
            }
            "intensity" if ty != v1::NumericType::Float32 => {
                c.bad(
                    format!("{path}.type"),
                    format!("\"intensity\" must be FLOAT32, not {}", ty.as_str_name()),
                );
            }
            // Other fields are carried along and ignored.
            _ => {}
        }
    }
    for (axis, coord) in ["x", "y", "z"].iter().zip(xyz) {
        if coord.is_none() && !pc.fields.iter().any(|f| f.name == *axis) {
            c.bad("point_cloud.fields", format!("no {axis:?} field"));
        }
    }
    if stride > 0 && !pc.data.len().is_multiple_of(stride) {
        c.bad(
            "point_cloud.data",
            format!(
                "{} bytes is not a multiple of point_stride {stride}",
                pc.data.len()
            ),
        );
    }
    let [Some(x), Some(y), Some(z)] = xyz else {
        return None;
    };
    Some(CloudLayout {
        stride,
        xyz: [x, y, z],
        class_offset,
    })
}

/// A field's type and offset, when the type is a known one and the field fits in a point.
fn packed_field(
    c: &mut Checker,
    path: &str,
    field: &v1::PackedElementField,
    stride: usize,
) -> Option<(v1::NumericType, usize)> {
    let Ok(ty) = v1::NumericType::try_from(field.r#type) else {
        c.bad(
            format!("{path}.type"),
            format!("{} is not a NumericType", field.r#type),
        );
        return None;
    };
    let Some(size) = landing_proto::cloud::numeric_size(ty) else {
        c.bad(
            format!("{path}.type"),
            "must be set (NUMERIC_TYPE_UNSPECIFIED)",
        );
        return None;
    };
    let offset = field.offset as usize;
    if stride > 0 && offset + size > stride {
        c.bad(
            format!("{path}.offset"),
            format!(
                "field {:?} at offset {offset} with {size} bytes overruns point_stride {stride}",
                field.name
            ),
        );
        return None;
    }
    Some((ty, offset))
}

/// How to read the coordinate field `name`: float32 or float64.
fn coordinate(
    c: &mut Checker,
    path: &str,
    name: &str,
    ty: v1::NumericType,
    offset: usize,
) -> Option<Coord> {
    match ty {
        v1::NumericType::Float32 => Some(Coord::F32(offset)),
        v1::NumericType::Float64 => Some(Coord::F64(offset)),
        other => {
            c.bad(
                format!("{path}.type"),
                format!(
                    "{name:?} must be FLOAT32 or FLOAT64, not {}",
                    other.as_str_name()
                ),
            );
            None
        }
    }
}

/// The points and (when the layout has them) the classes of `data`, at `pose`; `None` at the
/// first point with a coordinate that is not finite and within [`MAX_COORDINATE_M`], or a class
/// that is not a `SemanticClass`.
fn read_points(
    c: &mut Checker,
    data: &[u8],
    layout: &CloudLayout,
    pose: Isometry3<f64>,
) -> Option<Cloud> {
    let n = data.len() / layout.stride;
    let mut points = Vec::with_capacity(n);
    let mut classes = layout.class_offset.map(|_| Vec::with_capacity(n));
    let [x, y, z] = layout.xyz;
    for (i, p) in data.chunks_exact(layout.stride).enumerate() {
        let v = [x.read(p), y.read(p), z.read(p)];
        if let Some((axis, bad)) = ["x", "y", "z"]
            .iter()
            .zip(v)
            .find(|(_, v)| !v.is_finite() || v.abs() > MAX_COORDINATE_M)
        {
            c.bad(
                "point_cloud.data",
                format!("point {i} has {axis} = {bad}, not a finite coordinate within 1e7 m"),
            );
            return None;
        }
        points.push(v);
        if let (Some(o), Some(classes)) = (layout.class_offset, classes.as_mut()) {
            let class = p[o];
            if class > MAX_CLASS {
                c.bad(
                    "point_cloud.data",
                    format!("point {i} has class {class}, not a SemanticClass (0..=14)"),
                );
                return None;
            }
            classes.push(class);
        }
    }
    Some(Cloud {
        points,
        classes,
        pose,
    })
}

/// What a camera image of a frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ImageKind {
    /// `Frame.image`: colour for the model (PNG, JPEG or raw "rgb8").
    Colour,
    /// `Frame.class_image`: one class id per pixel (PNG or raw "mono8"; JPEG would change ids).
    Classes,
}

/// Checks `frame.<field>` (`image` or `class_image`): pose, calibration and the pixels' layout.
/// The pixels themselves are decoded by the pipeline, which names the same fields.
fn camera_image(
    c: &mut Checker,
    field: &str,
    img: &v1::CameraImage,
    kind: ImageKind,
) -> Option<CameraImage> {
    let before = c.violations.len();
    if let Some(t) = &img.timestamp {
        check_timestamp(c, &format!("{field}.timestamp"), t);
    }
    let pose = match &img.pose {
        None => {
            c.bad(format!("{field}.pose"), "required (T_world_camera)");
            None
        }
        Some(p) => pose_of(c, &format!("{field}.pose"), p),
    };
    let intrinsics = match &img.calibration {
        None => {
            c.bad(format!("{field}.calibration"), "required");
            None
        }
        Some(k) => Some(intrinsics(c, field, k)),
    };
    let pixels = match &img.image {
        None => {
            c.bad(
                format!("{field}.image"),
                "required: compressed or raw pixels",
            );
            None
        }
        Some(v1::camera_image::Image::Compressed(ci)) => compressed_pixels(c, field, ci, kind),
        Some(v1::camera_image::Image::Raw(raw)) => {
            Some(raw_pixels(c, field, raw, kind, intrinsics.as_ref()))
        }
    };
    if c.violations.len() > before {
        return None;
    }
    Some(CameraImage {
        pixels: pixels?,
        pose: pose?,
        intrinsics: intrinsics?,
    })
}

/// `frame.<field>.calibration`, its violations recorded.
fn intrinsics(c: &mut Checker, field: &str, k: &v1::CameraCalibration) -> Intrinsics {
    for (name, v) in [("width", k.width), ("height", k.height)] {
        if v == 0 || v > MAX_IMAGE_SIDE {
            c.bad(
                format!("{field}.calibration.{name}"),
                format!("{v} is outside 1..={MAX_IMAGE_SIDE}"),
            );
        }
    }
    for (name, v) in [("fx", k.fx), ("fy", k.fy)] {
        if !(v.is_finite() && v > 0.0) {
            c.bad(
                format!("{field}.calibration.{name}"),
                format!("{v} must be a positive focal length in pixels"),
            );
        }
    }
    for (name, v) in [("cx", k.cx), ("cy", k.cy)] {
        if !v.is_finite() {
            c.bad(
                format!("{field}.calibration.{name}"),
                format!("{v} is not finite"),
            );
        }
    }
    Intrinsics {
        width: k.width,
        height: k.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
    }
}

/// `frame.<field>.compressed`: a format `kind` allows and some bytes.
fn compressed_pixels(
    c: &mut Checker,
    field: &str,
    ci: &v1::CompressedImage,
    kind: ImageKind,
) -> Option<ImagePixels> {
    let format = match (ci.format.to_ascii_lowercase().as_str(), kind) {
        ("png", _) => Some("png"),
        ("jpeg" | "jpg", ImageKind::Colour) => Some("jpeg"),
        (_, ImageKind::Colour) => {
            c.bad(
                format!("{field}.compressed.format"),
                format!("{:?} is neither \"png\" nor \"jpeg\"", ci.format),
            );
            None
        }
        (_, ImageKind::Classes) => {
            c.bad(
                format!("{field}.compressed.format"),
                format!(
                    "{:?} is not \"png\" (a class image must be lossless)",
                    ci.format
                ),
            );
            None
        }
    };
    if ci.data.is_empty() {
        c.bad(format!("{field}.compressed.data"), "is empty");
    }
    format.map(|f| ImagePixels::Encoded {
        format: f.to_owned(),
        data: ci.data.to_vec(),
    })
}

/// `frame.<field>.raw`: the encoding `kind` needs, the calibration's size, and enough bytes for
/// its rows (violations recorded; the pixels are returned as given).
fn raw_pixels(
    c: &mut Checker,
    field: &str,
    raw: &v1::RawImage,
    kind: ImageKind,
    intrinsics: Option<&Intrinsics>,
) -> ImagePixels {
    let (encoding, channels) = match kind {
        ImageKind::Colour => ("rgb8", 3),
        ImageKind::Classes => ("mono8", 1),
    };
    if raw.encoding != encoding {
        c.bad(
            format!("{field}.raw.encoding"),
            format!("{:?} is not \"{encoding}\"", raw.encoding),
        );
    }
    if let Some(k) = intrinsics {
        check_raw_size(c, field, raw, k);
    }
    check_raw_rows(c, field, raw, encoding, channels);
    let (width, height, step, data) = (raw.width, raw.height, raw.step, raw.data.to_vec());
    match kind {
        ImageKind::Colour => ImagePixels::Rgb8 {
            width,
            height,
            step,
            data,
        },
        ImageKind::Classes => ImagePixels::Mono8 {
            width,
            height,
            step,
            data,
        },
    }
}

/// A raw image is as large as its calibration says.
fn check_raw_size(c: &mut Checker, field: &str, raw: &v1::RawImage, k: &Intrinsics) {
    if raw.width != k.width {
        c.bad(
            format!("{field}.raw.width"),
            format!("{} does not match calibration.width {}", raw.width, k.width),
        );
    }
    if raw.height != k.height {
        c.bad(
            format!("{field}.raw.height"),
            format!(
                "{} does not match calibration.height {}",
                raw.height, k.height
            ),
        );
    }
}

/// A raw image's step holds a row, and its data every row.
fn check_raw_rows(c: &mut Checker, field: &str, raw: &v1::RawImage, encoding: &str, channels: u64) {
    let row = u64::from(raw.width) * channels;
    if u64::from(raw.step) < row {
        c.bad(
            format!("{field}.raw.step"),
            format!("{} is less than width * {channels} = {row}", raw.step),
        );
    } else if raw.height > 0 {
        let needed = u64::from(raw.step) * u64::from(raw.height - 1) + row;
        if (raw.data.len() as u64) < needed {
            c.bad(
                format!("{field}.raw.data"),
                format!(
                    "{} bytes; {}x{} {encoding} with step {} needs {needed}",
                    raw.data.len(),
                    raw.width,
                    raw.height,
                    raw.step
                ),
            );
        }
    }
}

fn geodetic(c: &mut Checker, g: &v1::GeodeticPoint) -> Option<Geodetic> {
    let before = c.violations.len();
    if !(g.latitude_deg.is_finite() && (-90.0..=90.0).contains(&g.latitude_deg)) {
        c.bad(
            "geodetic_origin.latitude_deg",
            format!("{} is outside -90..=90", g.latitude_deg),
        );
    }
    if !(g.longitude_deg.is_finite() && (-180.0..=180.0).contains(&g.longitude_deg)) {
        c.bad(
            "geodetic_origin.longitude_deg",
            format!("{} is outside -180..=180", g.longitude_deg),
        );
    }
    if !(g.altitude_m.is_finite() && g.altitude_m.abs() <= 100_000.0) {
        c.bad(
            "geodetic_origin.altitude_m",
            format!("{} is outside -1e5..=1e5 m", g.altitude_m),
        );
    }
    (c.violations.len() == before).then_some(Geodetic {
        latitude_deg: g.latitude_deg,
        longitude_deg: g.longitude_deg,
        altitude_m: g.altitude_m,
    })
}

/// Validates the request's options and fills unset fields from `defaults`.
pub fn options_from(
    options: Option<&v1::PipelineOptions>,
    defaults: &Params,
) -> Result<FrameOptions, Error> {
    let Some(o) = options else {
        return Ok(FrameOptions {
            params: defaults.clone(),
            segmentation_mode: SegmentationMode::Unspecified,
        });
    };
    let mut c = Checker::new("options");
    let mut p = defaults.clone();
    set_real_options(&mut c, o, &mut p);
    set_count_options(&mut c, o, &mut p);
    if !o.landable_classes.is_empty() {
        p.landable_classes = landable_classes(&mut c, &o.landable_classes);
    }
    let segmentation_mode = segmentation_mode(&mut c, o.segmentation_mode);
    c.finish(segmentation_mode.map(|segmentation_mode| FrameOptions {
        params: p,
        segmentation_mode,
    }))
}

/// Whether a real-valued option is in its range.
type InRange = fn(f64) -> bool;

/// The real-valued options, each checked against its range (finite, and as shown in the error)
/// and set where the request sets it.
fn set_real_options(c: &mut Checker, o: &v1::PipelineOptions, p: &mut Params) {
    let reals: [(&str, Option<f64>, InRange, &str, &mut f64); 7] = [
        (
            "max_triangle_edge_m",
            o.max_triangle_edge_m,
            |v| v > 0.0 && v <= 1000.0,
            "(0, 1000]",
            &mut p.max_triangle_edge_m,
        ),
        (
            "min_normal_dot",
            o.min_normal_dot,
            |v| (0.0..1.0).contains(&v),
            "[0, 1)",
            &mut p.min_normal_dot,
        ),
        (
            "max_triangle_height_m",
            o.max_triangle_height_m,
            |v| (0.0..=100.0).contains(&v),
            "[0, 100]",
            &mut p.max_triangle_height_m,
        ),
        (
            "polylabel_precision_m",
            o.polylabel_precision_m,
            |v| (0.001..=100.0).contains(&v),
            "[0.001, 100]",
            &mut p.polylabel_precision_m,
        ),
        (
            "min_safe_radius_m",
            o.min_safe_radius_m,
            |v| (0.0..=1e4).contains(&v),
            "[0, 1e4]",
            &mut p.min_safe_radius_m,
        ),
        (
            "min_area_m2",
            o.min_area_m2,
            |v| (0.0..=1e8).contains(&v),
            "[0, 1e8]",
            &mut p.min_area_m2,
        ),
        (
            "min_hole_area_m2",
            o.min_hole_area_m2,
            |v| (0.0..=1e8).contains(&v),
            "[0, 1e8]",
            &mut p.min_hole_area_m2,
        ),
    ];
    for (name, value, ok, range, slot) in reals {
        match value {
            Some(v) if v.is_finite() && ok(v) => *slot = v,
            Some(v) => c.bad(name, format!("{v} is outside {range}")),
            None => {}
        }
    }
}

/// `min_region_triangles` and `max_sites` (0: the server's default).
fn set_count_options(c: &mut Checker, o: &v1::PipelineOptions, p: &mut Params) {
    if let Some(n) = o.min_region_triangles {
        if n > 10_000_000 {
            c.bad("min_region_triangles", format!("{n} is above 1e7"));
        } else {
            p.min_region_triangles = n as usize;
        }
    }
    match o.max_sites {
        None | Some(0) => {}
        Some(n) if n <= 1000 => p.max_sites = n as usize,
        Some(n) => c.bad("max_sites", format!("{n} is above 1000")),
    }
}

/// The landable classes as class ids; each unknown or unspecified one is a violation.
fn landable_classes(c: &mut Checker, asked: &[i32]) -> Vec<u8> {
    let mut classes = Vec::with_capacity(asked.len());
    for (i, &v) in asked.iter().enumerate() {
        match v1::SemanticClass::try_from(v) {
            Ok(v1::SemanticClass::Unspecified) => c.bad(
                format!("landable_classes[{i}]"),
                "SEMANTIC_CLASS_UNSPECIFIED is not a landable class",
            ),
            Ok(class) => classes.push(class as u8),
            Err(_) => c.bad(
                format!("landable_classes[{i}]"),
                format!("{v} is not a SemanticClass"),
            ),
        }
    }
    classes
}

fn segmentation_mode(c: &mut Checker, mode: i32) -> Option<SegmentationMode> {
    match v1::SegmentationMode::try_from(mode) {
        Ok(m) => Some(m),
        Err(_) => {
            c.bad(
                "segmentation_mode",
                format!("{mode} is not a SegmentationMode"),
            );
            None
        }
    }
}

/// The map a fusing stream asks for: `defaults` (the server's `[fusion]`) where a field is unset;
/// never more cells than the defaults allow. Errors name the field (`fusion.cell_size_m`).
pub fn fusion_map(
    asked: &v1::FusionOptions,
    defaults: &landing_fusion::FusionParams,
) -> Result<StreamMap, Error> {
    let mut p = FusionConfig::from(defaults);
    if let Some(v) = asked.max_cells {
        if v > p.max_cells {
            return Err(Error::invalid(
                "fusion.max_cells",
                format!("{v} is above this server's limit of {}", p.max_cells),
            ));
        }
        p.max_cells = v;
    }
    p.cell_size_m = asked.cell_size_m.unwrap_or(p.cell_size_m);
    p.horizon_s = asked.horizon_s.unwrap_or(p.horizon_s);
    p.keep_out_frames = asked.keep_out_frames.unwrap_or(p.keep_out_frames);
    p.max_jump_m = asked.max_jump_m.unwrap_or(p.max_jump_m);
    p.register_scans = asked.register_scans.unwrap_or(p.register_scans);
    p.max_pixel_footprint_m = asked
        .max_pixel_footprint_m
        .unwrap_or(p.max_pixel_footprint_m);
    StreamMap::new(p.params())
        .map_err(|e| Error::invalid(format!("fusion.{}", e.field()), e.to_string()))
}

/// The server's fusion defaults as the proto reports them (`ServiceInfo.default_fusion`).
pub fn default_fusion(p: &landing_fusion::FusionParams) -> v1::FusionOptions {
    let p = FusionConfig::from(p);
    v1::FusionOptions {
        cell_size_m: Some(p.cell_size_m),
        horizon_s: Some(p.horizon_s),
        max_cells: Some(p.max_cells),
        keep_out_frames: Some(p.keep_out_frames),
        max_jump_m: Some(p.max_jump_m),
        register_scans: Some(p.register_scans),
        max_pixel_footprint_m: Some(p.max_pixel_footprint_m),
    }
}

/// The defaults as the `PipelineOptions` message that `GetServiceInfo` reports.
pub fn default_options(p: &Params) -> v1::PipelineOptions {
    v1::PipelineOptions {
        max_triangle_edge_m: Some(p.max_triangle_edge_m),
        min_normal_dot: Some(p.min_normal_dot),
        max_triangle_height_m: Some(p.max_triangle_height_m),
        landable_classes: p.landable_classes.iter().map(|&c| i32::from(c)).collect(),
        polylabel_precision_m: Some(p.polylabel_precision_m),
        min_region_triangles: Some(u32::try_from(p.min_region_triangles).unwrap_or(u32::MAX)),
        min_safe_radius_m: Some(p.min_safe_radius_m),
        min_area_m2: Some(p.min_area_m2),
        min_hole_area_m2: Some(p.min_hole_area_m2),
        max_sites: Some(u32::try_from(p.max_sites).unwrap_or(u32::MAX)),
        segmentation_mode: v1::SegmentationMode::Unspecified as i32,
    }
}

fn vec3(v: [f64; 3]) -> v1::Vector3 {
    v1::Vector3 {
        x: v[0],
        y: v[1],
        z: v[2],
    }
}

fn ring(points: &[[f64; 3]]) -> v1::LinearRing {
    v1::LinearRing {
        points: points.iter().map(|&p| vec3(p)).collect(),
    }
}

fn duration(d: Option<std::time::Duration>) -> Option<prost_types::Duration> {
    d.and_then(|d| prost_types::Duration::try_from(d).ok())
}

fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl From<&StageTimings> for v1::StageTimings {
    fn from(t: &StageTimings) -> Self {
        Self {
            queue: duration(t.queue),
            decode: duration(t.decode),
            segmentation: duration(t.segmentation),
            classification: duration(t.classification),
            fusion: duration(t.fusion),
            triangulation: duration(t.triangulation),
            triangle_filter: duration(t.triangle_filter),
            plane_extraction: duration(t.plane_extraction),
            polygon_extraction: duration(t.polygon_extraction),
            polylabel: duration(t.polylabel),
            total: duration(t.total),
        }
    }
}

impl From<&Site> for v1::LandingSite {
    fn from(s: &Site) -> Self {
        Self {
            rank: s.rank,
            polygon: Some(v1::Polygon {
                shell: Some(ring(&s.shell)),
                holes: s.holes.iter().map(|h| ring(h)).collect(),
                plane_height_m: s.plane_height_m,
            }),
            center: Some(vec3(s.center)),
            center_geodetic: s.center_geodetic.map(|g| v1::GeodeticPoint {
                latitude_deg: g.latitude_deg,
                longitude_deg: g.longitude_deg,
                altitude_m: g.altitude_m,
            }),
            safe_radius_m: s.safe_radius_m,
            area_m2: s.area_m2,
            normal: Some(vec3(s.normal)),
            point_count: count(s.point_count),
            triangle_count: count(s.triangle_count),
        }
    }
}

impl From<&FrameOutput> for v1::FrameResult {
    fn from(o: &FrameOutput) -> Self {
        Self {
            drone_id: o.drone_id.clone(),
            sequence: o.sequence,
            frame_timestamp: o.timestamp,
            sites: o.sites.iter().map(v1::LandingSite::from).collect(),
            segmentation_mode: o.segmentation_mode as i32,
            point_count: count(o.point_count),
            triangle_count: count(o.triangle_count),
            timings: Some(v1::StageTimings::from(&o.timings)),
            fusion: o.fusion.as_ref().map(|f| v1::FusionSummary {
                frames: f.frames,
                points: count(f.points),
                cells: count(f.cells),
                reset_reason: f.reset.clone().unwrap_or_default(),
                keep_out_frames: count(f.keep_out_frames),
                registration: f.registration.as_ref().ok().map(|c| v1::Registration {
                    translation_m: c.translation_m(),
                    rotation_deg: c.rotation_deg(),
                    matched_points: count(c.matched),
                    rms_before_m: c.rms_before_m,
                    rms_after_m: c.rms_after_m,
                }),
                registration_skipped: f
                    .registration
                    .as_ref()
                    .err()
                    .map(ToString::to_string)
                    .unwrap_or_default(),
            }),
        }
    }
}

/// A point cloud of packed little-endian float32 x, y, z (stride 12) from flat coordinates.
pub fn packed_xyz(xyz: &[f32]) -> v1::PointCloud {
    packed_cloud(xyz, None)
}

/// A packed cloud of float32 x, y, z and, when given, a uint8 "class" per point (stride 13; a
/// missing class is 0): [`landing_proto::cloud::pack`] from flat coordinates.
pub fn packed_cloud(xyz: &[f32], classes: Option<&[u8]>) -> v1::PointCloud {
    let points: Vec<[f32; 3]> = xyz.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    landing_proto::cloud::pack(&points, None, classes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(
        frame: v1::Frame,
        options: Option<v1::PipelineOptions>,
    ) -> v1::DetectLandingSitesRequest {
        v1::DetectLandingSitesRequest {
            frame: Some(frame),
            options,
        }
    }

    fn good_frame() -> v1::Frame {
        v1::Frame {
            drone_id: "d".into(),
            sequence: 1,
            point_cloud: Some(packed_cloud(&[0.0, 0.0, 1.0, 1.0, 0.0, 1.0], Some(&[4, 4]))),
            ..Default::default()
        }
    }

    fn fields_of(e: Error) -> Vec<String> {
        match e {
            Error::InvalidArgument(v) => v.into_iter().map(|v| v.field).collect(),
            other => panic!("expected InvalidArgument, got {other}"),
        }
    }

    fn bad_fields(frame: v1::Frame, options: Option<v1::PipelineOptions>) -> Vec<String> {
        fields_of(request_parts(&request(frame, options), &Params::default()).unwrap_err())
    }

    #[test]
    fn good_frame_converts() {
        let (f, o) = request_parts(&request(good_frame(), None), &Params::default()).unwrap();
        assert_eq!(f.cloud.points, vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]]);
        assert_eq!(f.cloud.classes, Some(vec![4, 4]));
        assert_eq!(o.params, Params::default());
        assert_eq!(o.segmentation_mode, SegmentationMode::Unspecified);
    }

    #[test]
    fn float64_coordinates_and_extra_fields() {
        let mut data = Vec::new();
        for p in [[1.5f64, 2.5, 3.5], [4.0, 5.0, 6.0]] {
            for v in p {
                data.extend_from_slice(&v.to_le_bytes());
            }
            data.extend_from_slice(&0.5f32.to_le_bytes());
            data.extend_from_slice(&[9, 9, 9, 9]);
        }
        let field = |name: &str, offset, ty: v1::NumericType| v1::PackedElementField {
            name: name.into(),
            offset,
            r#type: ty as i32,
        };
        let frame = v1::Frame {
            point_cloud: Some(v1::PointCloud {
                point_stride: 32,
                fields: vec![
                    field("x", 0, v1::NumericType::Float64),
                    field("y", 8, v1::NumericType::Float64),
                    field("z", 16, v1::NumericType::Float64),
                    field("intensity", 24, v1::NumericType::Float32),
                    field("ring", 28, v1::NumericType::Uint32),
                ],
                data: data.into(),
                ..Default::default()
            }),
            ..Default::default()
        };
        let f = Frame::try_from(&frame).unwrap();
        assert_eq!(f.cloud.points, vec![[1.5, 2.5, 3.5], [4.0, 5.0, 6.0]]);
        assert_eq!(f.cloud.classes, None);
    }

    #[test]
    fn missing_frame_and_cloud_are_named() {
        let e = request_parts(
            &v1::DetectLandingSitesRequest::default(),
            &Params::default(),
        )
        .unwrap_err();
        assert_eq!(fields_of(e), vec!["frame"]);
        assert_eq!(
            bad_fields(v1::Frame::default(), None),
            vec!["frame.point_cloud"]
        );
    }

    #[test]
    fn nan_point_names_data_and_index() {
        let mut f = good_frame();
        f.point_cloud = Some(packed_xyz(&[0.0, 0.0, 0.0, 1.0, f32::NAN, 0.0]));
        let e = request_parts(&request(f, None), &Params::default()).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("frame.point_cloud.data")
                && msg.contains("point 1")
                && msg.contains("NaN"),
            "{msg}"
        );
    }

    #[test]
    fn buffer_length_not_multiple_of_stride() {
        let mut f = good_frame();
        let mut pc = packed_xyz(&[0.0; 6]);
        let mut data = pc.data.to_vec();
        data.push(0);
        pc.data = data.into();
        f.point_cloud = Some(pc);
        assert_eq!(bad_fields(f, None), vec!["frame.point_cloud.data"]);
    }

    #[test]
    fn layout_errors_each_name_their_field() {
        let mut f = good_frame();
        let pc = f.point_cloud.as_mut().unwrap();
        pc.point_stride = 0;
        assert!(bad_fields(f.clone(), None).contains(&"frame.point_cloud.point_stride".to_owned()));

        let mut f = good_frame();
        let pc = f.point_cloud.as_mut().unwrap();
        pc.fields[1].r#type = v1::NumericType::Uint8 as i32;
        pc.fields[2].offset = 12;
        pc.fields[3].r#type = 99;
        let fields = bad_fields(f, None);
        assert!(
            fields.contains(&"frame.point_cloud.fields[1].type".to_owned()),
            "{fields:?}"
        );
        assert!(
            fields.contains(&"frame.point_cloud.fields[2].offset".to_owned()),
            "{fields:?}"
        );
        assert!(
            fields.contains(&"frame.point_cloud.fields[3].type".to_owned()),
            "{fields:?}"
        );

        let mut f = good_frame();
        f.point_cloud.as_mut().unwrap().fields.remove(2);
        assert_eq!(bad_fields(f, None), vec!["frame.point_cloud.fields"]);

        let mut f = good_frame();
        f.point_cloud = Some(packed_cloud(&[0.0; 3], Some(&[200])));
        let e = request_parts(&request(f, None), &Params::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("class 200"), "{e}");
    }

    #[test]
    fn zero_quaternion_is_named() {
        let mut f = good_frame();
        f.point_cloud.as_mut().unwrap().pose = Some(v1::Pose {
            position: Some(v1::Vector3 {
                x: 1.0,
                y: 0.0,
                z: 0.0,
            }),
            orientation: Some(v1::Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 0.0,
            }),
        });
        assert_eq!(
            bad_fields(f, None),
            vec!["frame.point_cloud.pose.orientation"]
        );
    }

    fn image(
        calibration: v1::CameraCalibration,
        image: v1::camera_image::Image,
    ) -> v1::CameraImage {
        v1::CameraImage {
            pose: Some(v1::Pose {
                position: None,
                orientation: Some(v1::Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    w: 1.0,
                }),
            }),
            calibration: Some(calibration),
            image: Some(image),
            ..Default::default()
        }
    }

    #[test]
    fn image_errors_each_name_their_field() {
        let k = v1::CameraCalibration {
            width: 4,
            height: 2,
            fx: -1.0,
            fy: 0.0,
            cx: 2.0,
            cy: f64::NAN,
        };
        let raw = v1::RawImage {
            width: 3,
            height: 2,
            encoding: "bgr8".into(),
            step: 12,
            data: vec![0; 10].into(),
        };
        let mut f = good_frame();
        f.image = Some(image(k, v1::camera_image::Image::Raw(raw)));
        let fields = bad_fields(f, None);
        for expected in [
            "frame.image.calibration.fx",
            "frame.image.calibration.fy",
            "frame.image.calibration.cy",
            "frame.image.raw.encoding",
            "frame.image.raw.width",
            "frame.image.raw.data",
        ] {
            assert!(
                fields.contains(&expected.to_owned()),
                "{expected} missing from {fields:?}"
            );
        }
        let k = v1::CameraCalibration {
            width: 4,
            height: 2,
            fx: 1.0,
            fy: 1.0,
            cx: 2.0,
            cy: 1.0,
        };
        let mut f = good_frame();
        let compressed = v1::CompressedImage {
            data: Default::default(),
            format: "gif".into(),
        };
        f.image = Some(image(k, v1::camera_image::Image::Compressed(compressed)));
        f.image.as_mut().unwrap().pose = None;
        let fields = bad_fields(f, None);
        assert_eq!(
            fields,
            vec![
                "frame.image.pose",
                "frame.image.compressed.format",
                "frame.image.compressed.data"
            ]
        );
    }

    #[test]
    fn option_ranges_are_named() {
        let o = v1::PipelineOptions {
            max_triangle_edge_m: Some(0.0),
            min_normal_dot: Some(1.5),
            max_triangle_height_m: Some(f64::NAN),
            polylabel_precision_m: Some(-1.0),
            landable_classes: vec![4, 0, 99],
            max_sites: Some(5000),
            segmentation_mode: 17,
            ..Default::default()
        };
        let fields = bad_fields(good_frame(), Some(o));
        assert_eq!(
            fields,
            vec![
                "options.max_triangle_edge_m",
                "options.min_normal_dot",
                "options.max_triangle_height_m",
                "options.polylabel_precision_m",
                "options.max_sites",
                "options.landable_classes[1]",
                "options.landable_classes[2]",
                "options.segmentation_mode",
            ]
        );
    }

    #[test]
    fn options_override_defaults() {
        let o = v1::PipelineOptions {
            max_triangle_edge_m: Some(2.0),
            landable_classes: vec![4, 2],
            max_sites: Some(0),
            segmentation_mode: v1::SegmentationMode::None as i32,
            ..Default::default()
        };
        let got = options_from(Some(&o), &Params::default()).unwrap();
        assert_eq!(got.params.max_triangle_edge_m, 2.0);
        assert_eq!(got.params.landable_classes, vec![4, 2]);
        assert_eq!(got.params.max_sites, Params::default().max_sites);
        assert_eq!(got.segmentation_mode, SegmentationMode::None);
        // The defaults reported by GetServiceInfo convert back to the defaults.
        let round = options_from(
            Some(&default_options(&Params::default())),
            &Params::default(),
        )
        .unwrap();
        assert_eq!(round.params, Params::default());
    }

    #[test]
    fn geodetic_origin_is_checked() {
        let mut f = good_frame();
        f.geodetic_origin = Some(v1::GeodeticPoint {
            latitude_deg: 91.0,
            longitude_deg: 0.0,
            altitude_m: 0.0,
        });
        assert_eq!(
            bad_fields(f, None),
            vec!["frame.geodetic_origin.latitude_deg"]
        );
    }
}
