//! Builders that turn raw buffers into `landing.v1` frames, and the reverse (unpacking a packed
//! cloud) for tools that draw or compare frames.

use landing_proto::cloud;
use landing_proto::v1::{
    CameraCalibration, CameraImage, CompressedImage, Frame, GeodeticPoint, PointCloud, Pose,
    Quaternion, RawImage, Vector3, camera_image,
};

use crate::ClientError;

/// Builds a packed [`PointCloud`] from points and optional per-point classes and intensities.
///
/// The layout is `x, y, z` (FLOAT32 at 0, 4, 8), then `intensity` (FLOAT32) if given, then
/// `class` (UINT8) if given, little-endian.
#[derive(Debug, Clone, Default)]
pub struct PointCloudBuilder<'a> {
    points: &'a [[f32; 3]],
    classes: Option<&'a [u8]>,
    intensities: Option<&'a [f32]>,
    pose: Option<Pose>,
    frame_id: String,
    timestamp: Option<prost_types::Timestamp>,
}

impl<'a> PointCloudBuilder<'a> {
    /// Starts a cloud of `points` (in the LiDAR frame, or in the world when no pose is set).
    pub fn new(points: &'a [[f32; 3]]) -> Self {
        Self {
            points,
            ..Default::default()
        }
    }

    /// Per-point classes (values of `SemanticClass`, 0 = unknown); one per point.
    pub fn classes(mut self, classes: &'a [u8]) -> Self {
        self.classes = Some(classes);
        self
    }

    /// Per-point intensities; one per point.
    pub fn intensities(mut self, intensities: &'a [f32]) -> Self {
        self.intensities = Some(intensities);
        self
    }

    /// `T_world_lidar`. Without it the points are taken as world coordinates.
    pub fn pose(mut self, pose: Pose) -> Self {
        self.pose = Some(pose);
        self
    }

    /// Name of the sensor frame.
    pub fn frame_id(mut self, frame_id: impl Into<String>) -> Self {
        self.frame_id = frame_id.into();
        self
    }

    /// Time of the scan.
    pub fn timestamp(mut self, timestamp: prost_types::Timestamp) -> Self {
        self.timestamp = Some(timestamp);
        self
    }

    /// Packs the cloud. Fails when classes or intensities do not have one entry per point.
    pub fn build(self) -> Result<PointCloud, ClientError> {
        let n = self.points.len();
        if let Some(c) = self.classes
            && c.len() != n
        {
            return Err(ClientError::InvalidInput {
                field: "classes",
                reason: format!("{} classes for {n} points", c.len()),
            });
        }
        if let Some(i) = self.intensities
            && i.len() != n
        {
            return Err(ClientError::InvalidInput {
                field: "intensities",
                reason: format!("{} intensities for {n} points", i.len()),
            });
        }
        Ok(PointCloud {
            timestamp: self.timestamp,
            frame_id: self.frame_id,
            pose: self.pose,
            ..cloud::pack(self.points, self.intensities, self.classes)
        })
    }
}

/// A point cloud unpacked from its wire form.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct UnpackedCloud {
    /// Points in the cloud's own frame (apply [`UnpackedCloud::to_world`] for world coordinates).
    pub points: Vec<[f32; 3]>,
    /// Per-point classes, when the cloud has a `class` field.
    pub classes: Option<Vec<u8>>,
    /// Per-point intensities, when the cloud has an `intensity` field.
    pub intensities: Option<Vec<f32>>,
}

impl UnpackedCloud {
    /// The points moved to the world by `pose` (`T_world_lidar`; `None` = identity).
    pub fn to_world(&self, pose: Option<&Pose>) -> Vec<[f64; 3]> {
        let t = pose.map(RigidTransform::from_pose).unwrap_or_default();
        self.points
            .iter()
            .map(|p| t.apply([p[0] as f64, p[1] as f64, p[2] as f64]))
            .collect()
    }
}

/// Unpacks a packed cloud (FLOAT32 or FLOAT64 xyz, optional FLOAT32 intensity and UINT8 class).
pub fn unpack_point_cloud(cloud: &PointCloud) -> Result<UnpackedCloud, ClientError> {
    let cloud::Unpacked {
        points,
        classes,
        intensities,
    } = cloud::unpack(cloud).map_err(|e| ClientError::InvalidInput {
        field: e.field,
        reason: e.reason,
    })?;
    Ok(UnpackedCloud {
        points,
        classes,
        intensities,
    })
}

/// A pose from a position and a unit quaternion `[x, y, z, w]`.
pub fn pose(position: [f64; 3], orientation_xyzw: [f64; 4]) -> Pose {
    let [x, y, z, w] = orientation_xyzw;
    Pose {
        position: Some(Vector3 {
            x: position[0],
            y: position[1],
            z: position[2],
        }),
        orientation: Some(Quaternion { x, y, z, w }),
    }
}

/// The identity pose.
pub fn identity_pose() -> Pose {
    pose([0.0; 3], [0.0, 0.0, 0.0, 1.0])
}

/// Pinhole intrinsics.
pub fn intrinsics(
    width: u32,
    height: u32,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
) -> CameraCalibration {
    CameraCalibration {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
    }
}

/// Pinhole intrinsics of an ideal camera with square pixels, the principal point at the image
/// centre, and the given horizontal field of view.
pub fn intrinsics_from_fov(width: u32, height: u32, horizontal_fov_deg: f64) -> CameraCalibration {
    let f = width as f64 / 2.0 / (horizontal_fov_deg.to_radians() / 2.0).tan();
    intrinsics(width, height, f, f, width as f64 / 2.0, height as f64 / 2.0)
}

/// The pixels of a camera image, before they are tied to a pose and intrinsics.
#[derive(Debug, Clone)]
pub enum ImageData {
    /// An encoded PNG file.
    Png(Vec<u8>),
    /// An encoded JPEG file.
    Jpeg(Vec<u8>),
    /// Raw 8-bit RGB, row-major, tightly packed (`width * 3` bytes per row).
    Rgb8 {
        width: u32,
        height: u32,
        data: Vec<u8>,
    },
    /// Raw 8-bit single channel, row-major, tightly packed: a class image (one
    /// `SemanticClass` number per pixel) for [`FrameBuilder::class_image`].
    Mono8 {
        width: u32,
        height: u32,
        data: Vec<u8>,
    },
}

/// Ties pixels to the camera's pose and intrinsics. The image size is checked against the
/// intrinsics (encoded images are probed from their headers, not decoded).
pub fn camera_image(
    pixels: ImageData,
    pose: Pose,
    calibration: CameraCalibration,
) -> Result<CameraImage, ClientError> {
    let (size, image) = match pixels {
        ImageData::Png(data) => (
            png_size(&data)?,
            camera_image::Image::Compressed(CompressedImage {
                data: data.into(),
                format: "png".into(),
            }),
        ),
        ImageData::Jpeg(data) => (
            jpeg_size(&data)?,
            camera_image::Image::Compressed(CompressedImage {
                data: data.into(),
                format: "jpeg".into(),
            }),
        ),
        ImageData::Rgb8 {
            width,
            height,
            data,
        } => raw(width, height, "rgb8", 3, data)?,
        ImageData::Mono8 {
            width,
            height,
            data,
        } => raw(width, height, "mono8", 1, data)?,
    };
    if size != (calibration.width, calibration.height) {
        return Err(ClientError::InvalidInput {
            field: "calibration",
            reason: format!(
                "intrinsics are for {}x{} but the image is {}x{}",
                calibration.width, calibration.height, size.0, size.1
            ),
        });
    }
    Ok(CameraImage {
        timestamp: None,
        frame_id: "camera".into(),
        pose: Some(pose),
        calibration: Some(calibration),
        image: Some(image),
    })
}

/// Raw pixels, tightly packed, checked against their size.
fn raw(
    width: u32,
    height: u32,
    encoding: &str,
    channels: u32,
    data: Vec<u8>,
) -> Result<((u32, u32), camera_image::Image), ClientError> {
    let expected = width as usize * height as usize * channels as usize;
    if data.len() != expected {
        return Err(ClientError::InvalidInput {
            field: "image.data",
            reason: format!(
                "{} bytes for a {width}x{height} {encoding} image (expected {expected})",
                data.len()
            ),
        });
    }
    Ok((
        (width, height),
        camera_image::Image::Raw(RawImage {
            width,
            height,
            encoding: encoding.into(),
            step: width * channels,
            data: data.into(),
        }),
    ))
}

/// Width and height from a PNG's IHDR chunk, which the format puts first.
fn png_size(data: &[u8]) -> Result<(u32, u32), ClientError> {
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    let bad = |reason: &str| ClientError::Image {
        what: "png",
        reason: reason.to_string(),
    };
    if !data.starts_with(SIGNATURE) {
        return Err(bad("no PNG signature"));
    }
    if data.len() < 24 || &data[12..16] != b"IHDR" {
        return Err(bad("no IHDR chunk after the signature"));
    }
    let be = |at: usize| u32::from_be_bytes([data[at], data[at + 1], data[at + 2], data[at + 3]]);
    match (be(16), be(20)) {
        (0, _) | (_, 0) => Err(bad("IHDR gives a zero width or height")),
        size => Ok(size),
    }
}

/// Width and height from a JPEG's start-of-frame segment, walking the segments before it.
fn jpeg_size(data: &[u8]) -> Result<(u32, u32), ClientError> {
    let bad = |reason: String| ClientError::Image {
        what: "jpeg",
        reason,
    };
    if !data.starts_with(&[0xFF, 0xD8]) {
        return Err(bad("no JPEG start-of-image marker".into()));
    }
    let mut at = 2;
    // Each step moves past one segment, so the walk ends within `data.len()` steps.
    while at + 4 <= data.len() {
        if data[at] != 0xFF {
            return Err(bad(format!("no segment marker at byte {at}")));
        }
        let marker = data[at + 1];
        match marker {
            // Fill bytes before a marker.
            0xFF => at += 1,
            // Markers without a length.
            0x01 | 0xD0..=0xD7 => at += 2,
            0xD9 | 0xDA => break,
            _ => {
                let len = usize::from(u16::from_be_bytes([data[at + 2], data[at + 3]]));
                // SOF0..SOF15, except DHT (C4), JPG (C8) and DAC (CC).
                let is_sof = matches!(marker, 0xC0..=0xCF) && !matches!(marker, 0xC4 | 0xC8 | 0xCC);
                if is_sof {
                    if len < 7 || at + 9 > data.len() {
                        break;
                    }
                    let h = u16::from_be_bytes([data[at + 5], data[at + 6]]);
                    let w = u16::from_be_bytes([data[at + 7], data[at + 8]]);
                    if w == 0 || h == 0 {
                        return Err(bad("start of frame gives a zero width or height".into()));
                    }
                    return Ok((u32::from(w), u32::from(h)));
                }
                if len < 2 {
                    return Err(bad(format!("segment length {len} at byte {at}")));
                }
                at += 2 + len;
            }
        }
    }
    Err(bad("no start-of-frame segment before the image data".into()))
}

/// Builds a [`Frame`] around a cloud.
#[derive(Debug, Clone, Default)]
pub struct FrameBuilder {
    frame: Frame,
}

impl FrameBuilder {
    /// A frame with this sequence number and LiDAR scan.
    pub fn new(sequence: u64, point_cloud: PointCloud) -> Self {
        Self {
            frame: Frame {
                sequence,
                point_cloud: Some(point_cloud),
                ..Default::default()
            },
        }
    }

    /// The drone that took the frame.
    pub fn drone_id(mut self, drone_id: impl Into<String>) -> Self {
        self.frame.drone_id = drone_id.into();
        self
    }

    /// The camera image used to classify the points.
    pub fn image(mut self, image: CameraImage) -> Self {
        self.frame.image = Some(image);
        self
    }

    /// Per-pixel classes of a camera (for example the drone's own segmentation: an 8-bit
    /// grayscale PNG or [`ImageData::Mono8`], pixel value = `SemanticClass` number), used instead
    /// of the server's model (`SEGMENTATION_MODE_CLASS_IMAGE`, which `UNSPECIFIED` picks when a
    /// frame has one).
    pub fn class_image(mut self, classes: CameraImage) -> Self {
        self.frame.class_image = Some(classes);
        self
    }

    /// Capture time.
    pub fn timestamp(mut self, timestamp: prost_types::Timestamp) -> Self {
        self.frame.timestamp = Some(timestamp);
        self
    }

    /// WGS-84 position of the world origin, so sites also carry latitude/longitude.
    pub fn geodetic_origin(
        mut self,
        latitude_deg: f64,
        longitude_deg: f64,
        altitude_m: f64,
    ) -> Self {
        self.frame.geodetic_origin = Some(GeodeticPoint {
            latitude_deg,
            longitude_deg,
            altitude_m,
        });
        self
    }

    /// The finished frame.
    pub fn build(self) -> Frame {
        self.frame
    }
}

/// A rigid transform (rotation as a unit quaternion, then translation).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidTransform {
    /// Unit quaternion `[x, y, z, w]`.
    pub rotation: [f64; 4],
    /// Translation.
    pub translation: [f64; 3],
}

impl Default for RigidTransform {
    fn default() -> Self {
        Self {
            rotation: [0.0, 0.0, 0.0, 1.0],
            translation: [0.0; 3],
        }
    }
}

impl RigidTransform {
    /// From a proto pose; a missing or zero quaternion is taken as identity.
    pub fn from_pose(pose: &Pose) -> Self {
        let t = pose
            .position
            .as_ref()
            .map(|p| [p.x, p.y, p.z])
            .unwrap_or([0.0; 3]);
        let q = pose
            .orientation
            .as_ref()
            .map(|q| [q.x, q.y, q.z, q.w])
            .unwrap_or([0.0, 0.0, 0.0, 1.0]);
        let n = q.iter().map(|c| c * c).sum::<f64>().sqrt();
        let rotation = if n > 0.0 && n.is_finite() {
            [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
        } else {
            [0.0, 0.0, 0.0, 1.0]
        };
        Self {
            rotation,
            translation: t,
        }
    }

    /// Rotates a vector (no translation).
    pub fn rotate(&self, v: [f64; 3]) -> [f64; 3] {
        let [qx, qy, qz, qw] = self.rotation;
        // v' = v + 2w(q×v) + 2 q×(q×v)
        let c1 = cross([qx, qy, qz], v);
        let c2 = cross([qx, qy, qz], c1);
        [
            v[0] + 2.0 * (qw * c1[0] + c2[0]),
            v[1] + 2.0 * (qw * c1[1] + c2[1]),
            v[2] + 2.0 * (qw * c1[2] + c2[2]),
        ]
    }

    /// Maps a point from the child frame to the parent frame.
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let r = self.rotate(p);
        [
            r[0] + self.translation[0],
            r[1] + self.translation[1],
            r[2] + self.translation[2],
        ]
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Self {
        let [x, y, z, w] = self.rotation;
        let inv = Self {
            rotation: [-x, -y, -z, w],
            translation: [0.0; 3],
        };
        let t = inv.rotate(self.translation);
        Self {
            rotation: inv.rotation,
            translation: [-t[0], -t[1], -t[2]],
        }
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use landing_proto::v1::{NumericType, PackedElementField};
    use proptest::prelude::*;

    #[test]
    fn packs_xyz_intensity_class_little_endian() {
        let pts = [[1.0f32, 2.0, 3.0], [-1.5, 0.0, 7.25]];
        let cloud = PointCloudBuilder::new(&pts)
            .intensities(&[0.5, 0.25])
            .classes(&[4, 13])
            .build()
            .unwrap();
        assert_eq!(cloud.point_stride, 17);
        assert_eq!(cloud.data.len(), 34);
        assert_eq!(&cloud.data[0..4], &1.0f32.to_le_bytes());
        assert_eq!(&cloud.data[12..16], &0.5f32.to_le_bytes());
        assert_eq!(cloud.data[16], 4);
        assert_eq!(cloud.data[33], 13);
        let names: Vec<_> = cloud.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["x", "y", "z", "intensity", "class"]);
    }

    #[test]
    fn rejects_class_count_mismatch_naming_the_field() {
        let pts = [[0.0f32; 3]; 3];
        let err = PointCloudBuilder::new(&pts)
            .classes(&[1, 2])
            .build()
            .unwrap_err();
        assert!(err.to_string().contains("`classes`"), "{err}");
        assert!(err.to_string().contains("2 classes for 3 points"), "{err}");
    }

    #[test]
    fn unpacks_float64_clouds() {
        let mut data = Vec::new();
        for v in [1.0f64, 2.0, 3.0] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        let field = |name: &str, offset| PackedElementField {
            name: name.into(),
            offset,
            r#type: NumericType::Float64 as i32,
        };
        let cloud = PointCloud {
            point_stride: 24,
            fields: vec![field("x", 0), field("y", 8), field("z", 16)],
            data: data.into(),
            ..Default::default()
        };
        let u = unpack_point_cloud(&cloud).unwrap();
        assert_eq!(u.points, vec![[1.0, 2.0, 3.0]]);
        assert_eq!(u.classes, None);
    }

    #[test]
    fn unpack_errors_name_the_field() {
        let mut cloud = PointCloudBuilder::new(&[[0.0; 3]]).build().unwrap();
        cloud.point_stride = 5;
        let err = unpack_point_cloud(&cloud).unwrap_err();
        assert!(err.to_string().contains("point_cloud.data"), "{err}");
    }

    #[test]
    fn raw_image_size_must_match_data_and_intrinsics() {
        let calib = intrinsics_from_fov(4, 2, 90.0);
        assert!((calib.fx - 2.0).abs() < 1e-9);
        let ok = camera_image(
            ImageData::Rgb8 {
                width: 4,
                height: 2,
                data: vec![0; 24],
            },
            identity_pose(),
            calib,
        );
        assert!(ok.is_ok());
        let short = camera_image(
            ImageData::Rgb8 {
                width: 4,
                height: 2,
                data: vec![0; 23],
            },
            identity_pose(),
            calib,
        );
        assert!(short.unwrap_err().to_string().contains("image.data"));
        let other = camera_image(
            ImageData::Rgb8 {
                width: 2,
                height: 4,
                data: vec![0; 24],
            },
            identity_pose(),
            calib,
        );
        assert!(
            other
                .unwrap_err()
                .to_string()
                .contains("intrinsics are for 4x2")
        );
    }

    #[test]
    fn png_size_is_probed_from_the_header() {
        let img = image::RgbImage::new(5, 3);
        let mut png = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        let calib = intrinsics(5, 3, 10.0, 10.0, 2.5, 1.5);
        let cam = camera_image(ImageData::Png(png.clone()), identity_pose(), calib).unwrap();
        assert!(
            matches!(cam.image, Some(camera_image::Image::Compressed(ref c)) if c.format == "png")
        );
        let wrong = intrinsics(6, 3, 10.0, 10.0, 2.5, 1.5);
        assert!(camera_image(ImageData::Png(png), identity_pose(), wrong).is_err());
        assert!(camera_image(ImageData::Jpeg(vec![1, 2, 3]), identity_pose(), calib).is_err());
    }

    fn encoded(width: u32, height: u32, format: image::ImageFormat) -> Vec<u8> {
        let img = image::RgbImage::from_fn(width, height, |x, y| image::Rgb([x as u8, y as u8, 7]));
        let mut bytes = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut bytes), format)
            .unwrap();
        bytes
    }

    #[test]
    fn sizes_are_read_from_real_encoders_headers() {
        for (w, h) in [(1, 1), (5, 3), (320, 240), (641, 17)] {
            assert_eq!(
                png_size(&encoded(w, h, image::ImageFormat::Png)).unwrap(),
                (w, h)
            );
            assert_eq!(
                jpeg_size(&encoded(w, h, image::ImageFormat::Jpeg)).unwrap(),
                (w, h)
            );
        }
        let e = jpeg_size(&encoded(4, 4, image::ImageFormat::Png)).unwrap_err();
        assert!(e.to_string().contains("jpeg"), "{e}");
        let e = png_size(b"\x89PNG\r\n\x1a\n").unwrap_err();
        assert!(e.to_string().contains("IHDR"), "{e}");
    }

    proptest! {
        /// A cut or corrupted header is an error or a size, never a panic or a hang.
        #[test]
        fn damaged_headers_never_panic(cut in 0usize..700, flip in 0usize..700, byte: u8) {
            for format in [image::ImageFormat::Png, image::ImageFormat::Jpeg] {
                let mut data = encoded(9, 4, format);
                if flip < data.len() {
                    data[flip] = byte;
                }
                data.truncate(cut);
                let _ = png_size(&data);
                let _ = jpeg_size(&data);
            }
        }
    }

    #[test]
    fn quarter_turn_about_z_maps_x_to_y() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let t = RigidTransform::from_pose(&pose([1.0, 0.0, 0.0], [0.0, 0.0, h, h]));
        let p = t.apply([1.0, 0.0, 0.0]);
        assert!((p[0] - 1.0).abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12 && p[2].abs() < 1e-12);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, rng_seed: proptest::test_runner::RngSeed::Fixed(7), ..ProptestConfig::default() })]

        #[test]
        fn pack_then_unpack_is_identity(
            pts in prop::collection::vec(prop::array::uniform3(-1.0e4f32..1.0e4), 0..50),
            with_classes in any::<bool>(),
        ) {
            let classes: Vec<u8> = (0..pts.len()).map(|i| (i % 15) as u8).collect();
            let intens: Vec<f32> = (0..pts.len()).map(|i| i as f32 * 0.5).collect();
            let mut b = PointCloudBuilder::new(&pts).intensities(&intens);
            if with_classes {
                b = b.classes(&classes);
            }
            let u = unpack_point_cloud(&b.build().unwrap()).unwrap();
            prop_assert_eq!(&u.points, &pts);
            prop_assert_eq!(u.intensities.as_deref(), Some(&intens[..]));
            prop_assert_eq!(u.classes.is_some(), with_classes);
        }

        #[test]
        fn transform_then_inverse_is_identity(
            q in prop::array::uniform4(-1.0f64..1.0),
            t in prop::array::uniform3(-100.0f64..100.0),
            p in prop::array::uniform3(-100.0f64..100.0),
        ) {
            prop_assume!(q.iter().map(|c| c * c).sum::<f64>() > 0.01);
            let tf = RigidTransform::from_pose(&pose(t, q));
            let back = tf.inverse().apply(tf.apply(p));
            for k in 0..3 {
                prop_assert!((back[k] - p[k]).abs() < 1e-9);
            }
        }
    }
}
