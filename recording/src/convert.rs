//! A frame's sensor data as Foxglove messages, and back: the scan as a `foxglove.PointCloud` in
//! its sensor frame, the camera as `foxglove.CompressedImage` (or `RawImage`) with a
//! `foxglove.CameraCalibration`, the sensor poses as one `foxglove.FrameTransforms` from
//! [`WORLD_FRAME`]. Both directions are exact: every number is copied, none is recomputed.

use foxglove::messages as fox;
use landing_proto::v1;

use crate::Error;

/// The root frame of every recording and live view: the service's local ENU world, metres.
pub const WORLD_FRAME: &str = "world";
/// Frame id given to a scan that names none.
pub const DEFAULT_LIDAR_FRAME: &str = "lidar";
/// Frame id given to a camera image that names none.
pub const DEFAULT_CAMERA_FRAME: &str = "camera";

/// The Foxglove messages of one frame. Every value of the [`v1::Frame`] is in exactly one of
/// them, and [`frame_from_foxglove`] puts the frame back together.
#[derive(Debug, Clone, PartialEq)]
pub struct FoxgloveFrame {
    /// Identity, time, geodetic origin and the drone's own class image.
    pub header: v1::FrameHeader,
    /// The scan, in its sensor frame.
    pub cloud: Option<fox::PointCloud>,
    /// The camera image.
    pub image: Option<Image>,
    /// The camera's intrinsics.
    pub calibration: Option<fox::CameraCalibration>,
    /// `world → lidar` and `world → camera`, for the sensors that have a pose.
    pub transforms: fox::FrameTransforms,
}

/// A camera image as Foxglove carries it.
#[derive(Debug, Clone, PartialEq)]
pub enum Image {
    /// PNG or JPEG bytes.
    Compressed(fox::CompressedImage),
    /// Unencoded pixels.
    Raw(fox::RawImage),
}

/// Splits `frame` into its Foxglove messages. Fails only when two sensors would claim the same
/// frame id with different poses, or a sensor with a pose calls itself [`WORLD_FRAME`]: a viewer
/// could not place them.
pub fn frame_to_foxglove(frame: &v1::Frame) -> Result<FoxgloveFrame, Error> {
    let mut transforms = fox::FrameTransforms::default();
    let cloud = frame.point_cloud.as_ref().map(|pc| {
        let frame_id = frame_id_or(&pc.frame_id, DEFAULT_LIDAR_FRAME);
        if let Some(pose) = &pc.pose {
            transforms
                .transforms
                .push(transform(pc.timestamp.as_ref(), &frame_id, pose));
        }
        fox::PointCloud {
            timestamp: pc.timestamp.as_ref().map(to_fox_time),
            frame_id,
            pose: None,
            point_stride: pc.point_stride,
            fields: pc
                .fields
                .iter()
                .map(|f| fox::PackedElementField {
                    name: f.name.clone(),
                    offset: f.offset,
                    r#type: f.r#type,
                })
                .collect(),
            data: pc.data.clone(),
        }
    });
    let (image, calibration) = match &frame.image {
        Some(img) => {
            let (image, calibration) = camera_to_foxglove(img);
            if let Some(pose) = &img.pose {
                transforms.transforms.push(transform(
                    img.timestamp.as_ref(),
                    &frame_id_or(&img.frame_id, DEFAULT_CAMERA_FRAME),
                    pose,
                ));
            }
            (image, calibration)
        }
        None => (None, None),
    };
    check_frame_ids(&transforms)?;
    Ok(FoxgloveFrame {
        header: v1::FrameHeader {
            drone_id: frame.drone_id.clone(),
            sequence: frame.sequence,
            timestamp: frame.timestamp,
            geodetic_origin: frame.geodetic_origin,
            class_image: frame.class_image.clone(),
        },
        cloud,
        image,
        calibration,
        transforms,
    })
}

/// A camera image's pixels and intrinsics as Foxglove messages (the pose goes to the transforms).
pub fn camera_to_foxglove(
    img: &v1::CameraImage,
) -> (Option<Image>, Option<fox::CameraCalibration>) {
    let timestamp = img.timestamp.as_ref().map(to_fox_time);
    let frame_id = frame_id_or(&img.frame_id, DEFAULT_CAMERA_FRAME);
    let image = img.image.as_ref().map(|pixels| match pixels {
        v1::camera_image::Image::Compressed(c) => Image::Compressed(fox::CompressedImage {
            timestamp,
            frame_id: frame_id.clone(),
            data: c.data.clone(),
            format: c.format.clone(),
        }),
        v1::camera_image::Image::Raw(r) => Image::Raw(fox::RawImage {
            timestamp,
            frame_id: frame_id.clone(),
            width: r.width,
            height: r.height,
            encoding: r.encoding.clone(),
            step: r.step,
            data: r.data.clone(),
        }),
    });
    let calibration = img.calibration.map(|c| fox::CameraCalibration {
        timestamp,
        frame_id,
        width: c.width,
        height: c.height,
        distortion_model: String::new(),
        d: Vec::new(),
        k: vec![c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0],
        r: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: vec![
            c.fx, 0.0, c.cx, 0.0, 0.0, c.fy, c.cy, 0.0, 0.0, 0.0, 1.0, 0.0,
        ],
    });
    (image, calibration)
}

/// Puts a frame back together from its Foxglove messages: the inverse of [`frame_to_foxglove`].
/// A sensor whose frame has no transform from [`WORLD_FRAME`] keeps no pose (its data is taken to
/// be in world coordinates, as `landing.v1` reads an unset pose).
pub fn frame_from_foxglove(parts: &FoxgloveFrame) -> Result<v1::Frame, String> {
    let h = &parts.header;
    let point_cloud = parts.cloud.as_ref().map(|pc| v1::PointCloud {
        timestamp: pc.timestamp.map(from_fox_time),
        frame_id: pc.frame_id.clone(),
        pose: pose_of(&parts.transforms, &pc.frame_id),
        point_stride: pc.point_stride,
        fields: pc
            .fields
            .iter()
            .map(|f| v1::PackedElementField {
                name: f.name.clone(),
                offset: f.offset,
                r#type: f.r#type,
            })
            .collect(),
        data: pc.data.clone(),
    });
    let image = match &parts.image {
        Some(image) => Some(camera_from_foxglove(
            image,
            parts.calibration.as_ref(),
            &parts.transforms,
        )?),
        None => None,
    };
    Ok(v1::Frame {
        drone_id: h.drone_id.clone(),
        sequence: h.sequence,
        timestamp: h.timestamp,
        point_cloud,
        image,
        geodetic_origin: h.geodetic_origin,
        class_image: h.class_image.clone(),
    })
}

/// A `landing.v1` camera image from a Foxglove image, the calibration logged with it and the
/// frame's transforms.
pub fn camera_from_foxglove(
    image: &Image,
    calibration: Option<&fox::CameraCalibration>,
    transforms: &fox::FrameTransforms,
) -> Result<v1::CameraImage, String> {
    let (timestamp, frame_id, pixels) = match image {
        Image::Compressed(c) => (
            c.timestamp,
            &c.frame_id,
            v1::camera_image::Image::Compressed(v1::CompressedImage {
                data: c.data.clone(),
                format: c.format.clone(),
            }),
        ),
        Image::Raw(r) => (
            r.timestamp,
            &r.frame_id,
            v1::camera_image::Image::Raw(v1::RawImage {
                width: r.width,
                height: r.height,
                encoding: r.encoding.clone(),
                step: r.step,
                data: r.data.clone(),
            }),
        ),
    };
    let calibration = match calibration {
        Some(c) if c.k.len() == 9 => Some(v1::CameraCalibration {
            width: c.width,
            height: c.height,
            fx: c.k[0],
            fy: c.k[4],
            cx: c.k[2],
            cy: c.k[5],
        }),
        Some(c) => {
            return Err(format!(
                "camera calibration `k` has {} numbers, not 9",
                c.k.len()
            ));
        }
        None => None,
    };
    Ok(v1::CameraImage {
        timestamp: timestamp.map(from_fox_time),
        frame_id: frame_id.clone(),
        pose: pose_of(transforms, frame_id),
        calibration,
        image: Some(pixels),
    })
}

/// `landing.v1` time as Foxglove time. Foxglove counts unsigned seconds, so a time before 1970
/// becomes 1970.
pub fn to_fox_time(t: &prost_types::Timestamp) -> fox::Timestamp {
    fox::Timestamp::new(
        u32::try_from(t.seconds.max(0)).unwrap_or(u32::MAX),
        u32::try_from(t.nanos).unwrap_or(0),
    )
}

/// Foxglove time as `landing.v1` time.
pub fn from_fox_time(t: fox::Timestamp) -> prost_types::Timestamp {
    prost_types::Timestamp {
        seconds: i64::from(t.sec()),
        nanos: i32::try_from(t.nsec()).unwrap_or(0),
    }
}

fn frame_id_or(frame_id: &str, default: &str) -> String {
    if frame_id.is_empty() {
        default.to_string()
    } else {
        frame_id.to_string()
    }
}

fn transform(
    timestamp: Option<&prost_types::Timestamp>,
    child: &str,
    pose: &v1::Pose,
) -> fox::FrameTransform {
    let p = pose.position.unwrap_or_default();
    let q = pose.orientation.unwrap_or_default();
    fox::FrameTransform {
        timestamp: timestamp.map(to_fox_time),
        parent_frame_id: WORLD_FRAME.to_string(),
        child_frame_id: child.to_string(),
        translation: Some(fox::Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        }),
        rotation: Some(fox::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        }),
    }
}

/// The pose of `frame_id` in the world, from the transform whose child it is.
fn pose_of(transforms: &fox::FrameTransforms, frame_id: &str) -> Option<v1::Pose> {
    let t = transforms
        .transforms
        .iter()
        .find(|t| t.parent_frame_id == WORLD_FRAME && t.child_frame_id == frame_id)?;
    let p = t.translation.unwrap_or_default();
    let q = t.rotation.unwrap_or_default();
    Some(v1::Pose {
        position: Some(v1::Vector3 {
            x: p.x,
            y: p.y,
            z: p.z,
        }),
        orientation: Some(v1::Quaternion {
            x: q.x,
            y: q.y,
            z: q.z,
            w: q.w,
        }),
    })
}

fn check_frame_ids(transforms: &fox::FrameTransforms) -> Result<(), Error> {
    let t = &transforms.transforms;
    if let Some(w) = t.iter().find(|t| t.child_frame_id == WORLD_FRAME) {
        return Err(Error::FrameId(format!(
            "a sensor with a pose is named `{}`, the recording's root frame",
            w.child_frame_id
        )));
    }
    if let [a, b] = &t[..]
        && a.child_frame_id == b.child_frame_id
        && (a.translation != b.translation || a.rotation != b.rotation)
    {
        return Err(Error::FrameId(format!(
            "the LiDAR and the camera are both `{}` but have different poses",
            a.child_frame_id
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, qz: f64) -> v1::Pose {
        let n = (1.0 + qz * qz).sqrt();
        v1::Pose {
            position: Some(v1::Vector3 {
                x,
                y: -2.5,
                z: 40.0,
            }),
            orientation: Some(v1::Quaternion {
                x: 0.0,
                y: 0.0,
                z: qz / n,
                w: 1.0 / n,
            }),
        }
    }

    fn frame() -> v1::Frame {
        let ts = prost_types::Timestamp {
            seconds: 1_700_000_000,
            nanos: 123_456_789,
        };
        v1::Frame {
            drone_id: "d-7".into(),
            sequence: 42,
            timestamp: Some(ts),
            point_cloud: Some(v1::PointCloud {
                timestamp: Some(ts),
                frame_id: "lidar".into(),
                pose: Some(pose(1e6 + 0.125, 0.3)),
                ..landing_proto::cloud::pack(
                    &[[0.5, -1.0, 2.0], [3.0, 4.0, 5.0]],
                    None,
                    Some(&[4, 13]),
                )
            }),
            image: Some(v1::CameraImage {
                timestamp: Some(ts),
                frame_id: "camera".into(),
                pose: Some(pose(3.0, -0.7)),
                calibration: Some(v1::CameraCalibration {
                    width: 320,
                    height: 240,
                    fx: 277.1,
                    fy: 277.2,
                    cx: 160.5,
                    cy: 119.5,
                }),
                image: Some(v1::camera_image::Image::Raw(v1::RawImage {
                    width: 2,
                    height: 1,
                    encoding: "rgb8".into(),
                    step: 6,
                    data: vec![1, 2, 3, 4, 5, 6].into(),
                })),
            }),
            geodetic_origin: Some(v1::GeodeticPoint {
                latitude_deg: 40.7,
                longitude_deg: -74.0,
                altitude_m: 10.0,
            }),
            class_image: None,
        }
    }

    #[test]
    fn a_frame_survives_the_trip_through_foxglove_exactly() {
        let f = frame();
        let parts = frame_to_foxglove(&f).unwrap();
        assert_eq!(parts.transforms.transforms.len(), 2);
        assert_eq!(parts.cloud.as_ref().unwrap().pose, None);
        assert_eq!(frame_from_foxglove(&parts).unwrap(), f);
    }

    #[test]
    fn a_cloud_without_pose_stays_in_world_coordinates() {
        let mut f = frame();
        f.point_cloud.as_mut().unwrap().pose = None;
        f.image = None;
        let parts = frame_to_foxglove(&f).unwrap();
        assert!(parts.transforms.transforms.is_empty());
        assert_eq!(frame_from_foxglove(&parts).unwrap(), f);
    }

    #[test]
    fn sensors_that_a_viewer_could_not_place_are_refused() {
        let mut f = frame();
        f.image.as_mut().unwrap().frame_id = "lidar".into();
        assert!(matches!(frame_to_foxglove(&f), Err(Error::FrameId(_))));
        let mut f = frame();
        f.point_cloud.as_mut().unwrap().frame_id = WORLD_FRAME.into();
        assert!(matches!(frame_to_foxglove(&f), Err(Error::FrameId(_))));
    }

    #[test]
    fn a_calibration_with_a_short_matrix_is_an_error() {
        let mut parts = frame_to_foxglove(&frame()).unwrap();
        parts.calibration.as_mut().unwrap().k.pop();
        assert!(frame_from_foxglove(&parts).unwrap_err().contains("`k`"));
    }
}
