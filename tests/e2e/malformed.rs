//! The malformed-input table: one bad value in every field of the frame, its images and the
//! options. Each is INVALID_ARGUMENT naming the field's path, unary; and a stream that carries
//! the frame cases in a row, between good frames, answers every good frame with sites.

use landing_client::v1::{
    self, CameraImage, CompressedImage, Frame, PipelineOptions, RawImage, SegmentationMode,
    camera_image::Image,
};
use landing_client::{ClientError, FrameOutcome};

use crate::support::{TestServer, mode, scene, stream_all};

/// One bad input: what it breaks, and the field path the error must name.
struct Case {
    field: &'static str,
    /// Makes the good frame and options bad.
    spoil: fn(&mut Frame, &mut PipelineOptions),
}

fn cloud(f: &mut Frame) -> &mut v1::PointCloud {
    f.point_cloud.as_mut().expect("a cloud")
}

fn image(f: &mut Frame) -> &mut CameraImage {
    f.image.as_mut().expect("an image")
}

fn class_image(f: &mut Frame) -> &mut CameraImage {
    f.class_image.as_mut().expect("a class image")
}

fn calibration(c: &mut CameraImage) -> &mut v1::CameraCalibration {
    c.calibration.as_mut().expect("a calibration")
}

fn compressed(c: &mut CameraImage) -> &mut CompressedImage {
    match c.image.as_mut() {
        Some(Image::Compressed(x)) => x,
        other => panic!("expected a compressed image, got {other:?}"),
    }
}

/// `c` as a raw image of its calibration's size: "rgb8" grey, or "mono8" rooftop.
fn raw<'a>(c: &'a mut CameraImage, encoding: &str) -> &'a mut RawImage {
    let k = c.calibration.expect("a calibration");
    let channels = if encoding == "mono8" { 1 } else { 3 };
    let value = if encoding == "mono8" { 4 } else { 128 };
    c.image = Some(Image::Raw(RawImage {
        width: k.width,
        height: k.height,
        encoding: encoding.into(),
        step: k.width * channels,
        data: vec![value; (k.width * k.height * channels) as usize].into(),
    }));
    match c.image.as_mut() {
        Some(Image::Raw(r)) => r,
        _ => unreachable!("just set"),
    }
}

/// Frame bytes are shared and immutable: a spoiled byte is a changed copy.
fn set_byte(data: &mut landing_client::Bytes, at: usize, value: u8) {
    let mut changed = data.to_vec();
    changed[at] = value;
    *data = changed.into();
}

/// The `i`-th point's coordinate `axis` of the cloud (FLOAT32 fields, as the simulator packs).
fn set_coordinate(f: &mut Frame, i: usize, axis: usize, v: f32) {
    let c = cloud(f);
    let offset = c
        .fields
        .iter()
        .find(|x| x.name == ["x", "y", "z"][axis])
        .expect("the coordinate field")
        .offset as usize;
    let at = i * c.point_stride as usize + offset;
    let mut data = c.data.to_vec();
    data[at..at + 4].copy_from_slice(&v.to_le_bytes());
    c.data = data.into();
}

const CASES: &[Case] = &[
    // The cloud.
    Case {
        field: "frame.point_cloud",
        spoil: |f, _| f.point_cloud = None,
    },
    Case {
        field: "frame.point_cloud.point_stride",
        spoil: |f, _| cloud(f).point_stride = 0,
    },
    Case {
        field: "frame.point_cloud.fields[0].offset",
        spoil: |f, _| cloud(f).point_stride = 2,
    },
    Case {
        field: "frame.point_cloud.data",
        spoil: |f, _| {
            let data = &mut cloud(f).data;
            data.truncate(data.len() - 1);
        },
    },
    Case {
        field: "frame.point_cloud.fields",
        spoil: |f, _| cloud(f).fields.clear(),
    },
    Case {
        field: "frame.point_cloud.fields[0].type",
        spoil: |f, _| cloud(f).fields[0].r#type = v1::NumericType::Uint8 as i32,
    },
    Case {
        field: "frame.point_cloud.fields[0].offset",
        spoil: |f, _| cloud(f).fields[0].offset = 1 << 20,
    },
    Case {
        field: "frame.point_cloud.fields[5].name",
        spoil: |f, _| {
            let x = cloud(f).fields[0].clone();
            cloud(f).fields.push(x);
        },
    },
    Case {
        field: "frame.point_cloud.data",
        spoil: |f, _| set_coordinate(f, 3, 0, f32::NAN),
    },
    Case {
        field: "frame.point_cloud.data",
        spoil: |f, _| set_coordinate(f, 5, 1, f32::INFINITY),
    },
    Case {
        field: "frame.point_cloud.data",
        spoil: |f, _| set_coordinate(f, 7, 2, 2.0e7),
    },
    Case {
        field: "frame.point_cloud.data",
        spoil: |f, _| {
            let c = cloud(f);
            let o = c
                .fields
                .iter()
                .find(|x| x.name == "class")
                .expect("class")
                .offset as usize;
            set_byte(&mut c.data, o, 99);
        },
    },
    Case {
        field: "frame.point_cloud.pose.position.x",
        spoil: |f, _| pose_position(f, |p| p.x = f64::NAN),
    },
    Case {
        field: "frame.point_cloud.pose.position.z",
        spoil: |f, _| pose_position(f, |p| p.z = 1.1e7),
    },
    Case {
        field: "frame.point_cloud.pose.orientation",
        spoil: |f, _| {
            cloud(f).pose.as_mut().expect("pose").orientation = Some(v1::Quaternion::default())
        },
    },
    Case {
        field: "frame.point_cloud.timestamp.nanos",
        spoil: |f, _| cloud(f).timestamp = timestamp(1, -1),
    },
    Case {
        field: "frame.timestamp.nanos",
        spoil: |f, _| f.timestamp = timestamp(1, 2_000_000_000),
    },
    // The camera image.
    Case {
        field: "frame.image.pose",
        spoil: |f, _| image(f).pose = None,
    },
    Case {
        field: "frame.image.pose.orientation",
        spoil: |f, _| {
            image(f).pose.as_mut().expect("pose").orientation = Some(v1::Quaternion {
                x: f64::NAN,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            })
        },
    },
    Case {
        field: "frame.image.calibration",
        spoil: |f, _| image(f).calibration = None,
    },
    Case {
        field: "frame.image.calibration.width",
        spoil: |f, _| calibration(image(f)).width = 0,
    },
    Case {
        field: "frame.image.calibration.fx",
        spoil: |f, _| calibration(image(f)).fx = 0.0,
    },
    Case {
        field: "frame.image.calibration.fy",
        spoil: |f, _| calibration(image(f)).fy = f64::NAN,
    },
    Case {
        field: "frame.image.calibration.cy",
        spoil: |f, _| calibration(image(f)).cy = f64::INFINITY,
    },
    Case {
        field: "frame.image.timestamp.nanos",
        spoil: |f, _| image(f).timestamp = timestamp(0, -5),
    },
    Case {
        field: "frame.image.image",
        spoil: |f, _| image(f).image = None,
    },
    Case {
        field: "frame.image.compressed.format",
        spoil: |f, _| compressed(image(f)).format = "gif".into(),
    },
    Case {
        field: "frame.image.compressed.data",
        spoil: |f, _| compressed(image(f)).data.clear(),
    },
    Case {
        field: "frame.image.compressed.data",
        spoil: |f, _| compressed(image(f)).data.truncate(64),
    },
    Case {
        field: "frame.image.raw.encoding",
        spoil: |f, _| raw(image(f), "rgb8").encoding = "bgr16".into(),
    },
    Case {
        field: "frame.image.raw.width",
        spoil: |f, _| raw(image(f), "rgb8").width += 1,
    },
    Case {
        field: "frame.image.raw.height",
        spoil: |f, _| raw(image(f), "rgb8").height = 0,
    },
    Case {
        field: "frame.image.raw.step",
        spoil: |f, _| raw(image(f), "rgb8").step -= 1,
    },
    Case {
        field: "frame.image.raw.data",
        spoil: |f, _| {
            let data = &mut raw(image(f), "rgb8").data;
            data.truncate(data.len() - 1);
        },
    },
    // The class image.
    Case {
        field: "frame.class_image.pose",
        spoil: |f, _| class_image(f).pose = None,
    },
    Case {
        field: "frame.class_image.calibration.fx",
        spoil: |f, _| calibration(class_image(f)).fx = -1.0,
    },
    Case {
        field: "frame.class_image.compressed.format",
        spoil: |f, _| compressed(class_image(f)).format = "jpeg".into(),
    },
    Case {
        field: "frame.class_image.compressed.data",
        spoil: |f, _| compressed(class_image(f)).data = b"\x89PNG\r\n\x1a\nnot really"[..].into(),
    },
    Case {
        field: "frame.class_image.raw.encoding",
        spoil: |f, _| {
            raw(class_image(f), "rgb8");
        },
    },
    Case {
        field: "frame.class_image.raw.data",
        spoil: |f, _| set_byte(&mut raw(class_image(f), "mono8").data, 11, 99),
    },
    Case {
        field: "frame.class_image.raw.step",
        spoil: |f, _| raw(class_image(f), "mono8").step = 1,
    },
    // The geodetic origin.
    Case {
        field: "frame.geodetic_origin.latitude_deg",
        spoil: |f, _| geodetic(f).latitude_deg = 91.0,
    },
    Case {
        field: "frame.geodetic_origin.longitude_deg",
        spoil: |f, _| geodetic(f).longitude_deg = f64::NAN,
    },
    Case {
        field: "frame.geodetic_origin.altitude_m",
        spoil: |f, _| geodetic(f).altitude_m = 1.0e6,
    },
    // The options.
    Case {
        field: "options.max_triangle_edge_m",
        spoil: |_, o| o.max_triangle_edge_m = Some(0.0),
    },
    Case {
        field: "options.min_normal_dot",
        spoil: |_, o| o.min_normal_dot = Some(1.0),
    },
    Case {
        field: "options.max_triangle_height_m",
        spoil: |_, o| o.max_triangle_height_m = Some(-1.0),
    },
    Case {
        field: "options.polylabel_precision_m",
        spoil: |_, o| o.polylabel_precision_m = Some(0.0),
    },
    Case {
        field: "options.min_safe_radius_m",
        spoil: |_, o| o.min_safe_radius_m = Some(f64::NAN),
    },
    Case {
        field: "options.min_area_m2",
        spoil: |_, o| o.min_area_m2 = Some(-1.0),
    },
    Case {
        field: "options.min_hole_area_m2",
        spoil: |_, o| o.min_hole_area_m2 = Some(1.0e9),
    },
    Case {
        field: "options.min_region_triangles",
        spoil: |_, o| o.min_region_triangles = Some(20_000_000),
    },
    Case {
        field: "options.max_sites",
        spoil: |_, o| o.max_sites = Some(5000),
    },
    Case {
        field: "options.landable_classes[0]",
        spoil: |_, o| o.landable_classes = vec![0],
    },
    Case {
        field: "options.landable_classes[1]",
        spoil: |_, o| o.landable_classes = vec![4, 99],
    },
    Case {
        field: "options.segmentation_mode",
        spoil: |_, o| o.segmentation_mode = 17,
    },
    // A mode the frame lacks the input for.
    Case {
        field: "frame.class_image",
        spoil: |f, o| {
            f.class_image = None;
            o.segmentation_mode = SegmentationMode::ClassImage as i32;
        },
    },
    Case {
        field: "frame.image",
        spoil: |f, o| {
            f.image = None;
            o.segmentation_mode = SegmentationMode::Model as i32;
        },
    },
];

fn timestamp(seconds: i64, nanos: i32) -> Option<prost_types::Timestamp> {
    Some(prost_types::Timestamp { seconds, nanos })
}

fn pose_position(f: &mut Frame, change: fn(&mut v1::Vector3)) {
    let pose = cloud(f).pose.get_or_insert_with(Default::default);
    change(pose.position.get_or_insert_with(Default::default));
}

fn geodetic(f: &mut Frame) -> &mut v1::GeodeticPoint {
    f.geodetic_origin.get_or_insert(v1::GeodeticPoint {
        latitude_deg: 40.7,
        longitude_deg: -74.0,
        altitude_m: 10.0,
    })
}

/// A good frame: scene 91's first, with its true labels as the class image.
fn good_frame() -> Frame {
    let recorded = &scene(91).frames[0];
    let mut f = recorded.frame.clone();
    f.class_image.clone_from(&recorded.labels);
    f
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_malformed_field_is_invalid_argument_naming_its_path() {
    assert!(CASES.len() >= 40, "{} cases", CASES.len());
    let server = TestServer::start().await;
    let client = server.client().await;
    let good = good_frame();
    client
        .detect_with(good.clone(), None)
        .await
        .expect("the good frame is answered");
    let mut wrong = Vec::new();
    for (i, case) in CASES.iter().enumerate() {
        let (mut frame, mut options) = (good.clone(), mode(SegmentationMode::Unspecified));
        (case.spoil)(&mut frame, &mut options);
        match client.detect_with(frame, Some(options)).await {
            Err(ClientError::Status(e))
                if e.code == tonic::Code::InvalidArgument && e.fields().contains(&case.field) => {}
            Err(ClientError::Status(e)) => wrong.push(format!(
                "case {i} ({}): {:?} naming {:?}: {e}",
                case.field,
                e.code,
                e.fields()
            )),
            other => wrong.push(format!(
                "case {i} ({}): {:?}",
                case.field,
                other.map(|r| r.sites.len())
            )),
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_of_malformed_frames_in_a_row_answers_the_good_frames_around_them() {
    let server = TestServer::start().await;
    let good = good_frame();
    let options = mode(SegmentationMode::Unspecified);
    // Every case that spoils only the frame (a stream's options come once), in a row, with a
    // good frame before and after the run and one in the middle.
    let bad: Vec<&Case> = CASES
        .iter()
        .filter(|c| {
            let (mut f, mut o) = (good.clone(), options.clone());
            (c.spoil)(&mut f, &mut o);
            o == options
        })
        .collect();
    assert!(bad.len() >= 30, "{} frame cases", bad.len());
    let middle = bad.len() / 2;
    let mut frames = vec![good.clone()];
    let mut expected = vec![None];
    for (i, case) in bad.iter().enumerate() {
        if i == middle {
            frames.push(good.clone());
            expected.push(None);
        }
        let mut f = good.clone();
        (case.spoil)(&mut f, &mut options.clone());
        frames.push(f);
        expected.push(Some(case.field));
    }
    frames.push(good.clone());
    expected.push(None);
    for (k, f) in frames.iter_mut().enumerate() {
        f.sequence = k as u64;
    }
    let items = stream_all(&server, frames.clone(), options).await;
    assert_eq!(items.len(), frames.len(), "one answer per frame");
    for (k, (item, want)) in items.iter().zip(&expected).enumerate() {
        assert_eq!(item.sequence, k as u64, "answers in order");
        match (&item.outcome, want) {
            (FrameOutcome::Result(r), None) => assert!(!r.sites.is_empty(), "frame {k}"),
            (FrameOutcome::Error(e), Some(field)) => {
                assert_eq!(e.code, tonic::Code::InvalidArgument, "frame {k}: {e}");
                assert!(e.fields().contains(field), "frame {k}: {field} in {e}");
            }
            (got, want) => panic!("frame {k}: {got:?}, expected {want:?}"),
        }
    }
    server.stop().await;
}
