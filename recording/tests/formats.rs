//! Recordings as other tools write them, the simulator's committed sample, and answers written
//! back: what every reader of the workspace relies on.

use std::collections::BTreeMap;
use std::path::Path;

use landing_proto::v1::{self, Frame, StreamLandingSitesResponse};
use landing_recording::{
    Error, FRAME_SCHEMA, LIDAR_TOPIC, RESULT_TOPIC, SITES_TOPIC, Writer, read, read_bytes,
};
use prost::Message;

/// Writes frames the way another recorder would: its own topic name, and an unrelated JSON
/// channel in between.
fn foreign_recording(frames: &[Frame]) -> Vec<u8> {
    let mut w = mcap::Writer::new(std::io::Cursor::new(Vec::new())).unwrap();
    let s = w
        .add_schema(FRAME_SCHEMA, "protobuf", landing_proto::FILE_DESCRIPTOR_SET)
        .unwrap();
    let c = w
        .add_channel(s, "/drone/frame", "protobuf", &BTreeMap::new())
        .unwrap();
    let other = w
        .add_channel(0, "/truth", "json", &BTreeMap::new())
        .unwrap();
    for (i, f) in frames.iter().enumerate() {
        let h = |channel_id| mcap::records::MessageHeader {
            channel_id,
            sequence: i as u32,
            log_time: i as u64 * 100_000_000,
            publish_time: 0,
        };
        w.write_to_known_channel(&h(c), &f.encode_to_vec()).unwrap();
        w.write_to_known_channel(&h(other), b"{}").unwrap();
    }
    w.finish().unwrap();
    w.into_inner().into_inner()
}

#[test]
fn reads_only_frame_messages_in_order() {
    let frames: Vec<Frame> = (0..3)
        .map(|i| Frame {
            sequence: i,
            drone_id: "d".into(),
            ..Default::default()
        })
        .collect();
    let read = read_bytes(&foreign_recording(&frames)).unwrap();
    assert_eq!(read.len(), 3);
    assert_eq!(read[2].frame, frames[2]);
    assert_eq!(read[1].log_time_ns, 100_000_000);
    assert_eq!(read[0].topic, "/drone/frame");
    assert!(read.iter().all(|r| r.truth.is_none() && r.labels.is_none()));
}

#[test]
fn the_simulators_truth_and_labels_come_with_their_frames() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
    let read = read(&path).unwrap();
    assert!(read.len() >= 10, "{} frames", read.len());
    for r in &read {
        let truth = r
            .truth
            .as_ref()
            .expect("every simulated frame has ground truth");
        assert_eq!(truth.sequence, r.frame.sequence);
        let labels = r.labels.as_ref().expect("every simulated frame has labels");
        let image = r.frame.image.as_ref().unwrap();
        // Same camera, same moment: the labels are the image's.
        assert_eq!(labels.calibration, image.calibration);
        assert_eq!(labels.pose, image.pose);
        assert_eq!(labels.timestamp, r.frame.timestamp);
    }
    let sequences: Vec<u64> = read.iter().map(|r| r.frame.sequence).collect();
    assert!(sequences.windows(2).all(|w| w[0] < w[1]), "{sequences:?}");
}

/// Every frame of the sample, written again in today's format and read back, is the same frame
/// with the same truth and labels: the Foxglove channels lose nothing.
#[test]
fn frames_survive_the_foxglove_channels_exactly() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
    let original = read(&path).unwrap();
    let mut w = Writer::new(std::io::Cursor::new(Vec::new()), "test").unwrap();
    for r in &original {
        w.write_frame(r.log_time_ns, &r.frame).unwrap();
        w.write_truth(r.log_time_ns, r.truth.as_ref().unwrap())
            .unwrap();
        w.write_labels(r.log_time_ns, r.frame.sequence, r.labels.as_ref().unwrap())
            .unwrap();
    }
    let again = read_bytes(&w.finish().unwrap().into_inner()).unwrap();
    assert_eq!(again.len(), original.len());
    for (a, b) in again.iter().zip(&original) {
        assert_eq!(a.topic, LIDAR_TOPIC);
        assert_eq!(
            (&a.frame, &a.truth, &a.labels),
            (&b.frame, &b.truth, &b.labels)
        );
    }
}

#[test]
fn a_file_without_frames_and_a_file_that_is_not_mcap_are_errors() {
    let err = read_bytes(&foreign_recording(&[])).unwrap_err();
    assert!(matches!(err, Error::NoFrames), "{err}");
    assert!(err.to_string().contains("no frames"), "{err}");
    assert!(matches!(
        read_bytes(b"not an mcap file"),
        Err(Error::Mcap(_))
    ));
    let err = read(Path::new("/nonexistent/rec.mcap")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/rec.mcap"), "{err}");
}

#[test]
fn a_message_that_is_not_its_schema_names_topic_and_sequence() {
    let mut w = mcap::Writer::new(std::io::Cursor::new(Vec::new())).unwrap();
    let s = w
        .add_schema(FRAME_SCHEMA, "protobuf", landing_proto::FILE_DESCRIPTOR_SET)
        .unwrap();
    let c = w
        .add_channel(s, "/f", "protobuf", &BTreeMap::new())
        .unwrap();
    let header = mcap::records::MessageHeader {
        channel_id: c,
        sequence: 9,
        log_time: 1,
        publish_time: 1,
    };
    w.write_to_known_channel(&header, &[0xFF, 0xFF, 0xFF])
        .unwrap();
    w.finish().unwrap();
    let err = read_bytes(&w.into_inner().into_inner()).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("message 9 on `/f`") && text.contains(FRAME_SCHEMA),
        "{text}"
    );
}

#[test]
fn written_results_read_back() {
    let mut w = Writer::new(std::io::Cursor::new(Vec::new()), "test").unwrap();
    let response = StreamLandingSitesResponse {
        sequence: 4,
        outcome: Some(v1::stream_landing_sites_response::Outcome::Result(
            v1::FrameResult {
                sequence: 4,
                ..Default::default()
            },
        )),
    };
    w.write_result(42, &response, None).unwrap();
    w.write_result(43, &response, None).unwrap();
    let bytes = w.finish().unwrap().into_inner();
    let all: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .collect();
    // Each answer is drawn too (no camera: no annotations).
    assert_eq!(
        all.iter()
            .filter(|m| m.channel.topic == SITES_TOPIC)
            .count(),
        2
    );
    let msgs: Vec<_> = all
        .into_iter()
        .filter(|m| m.channel.topic == RESULT_TOPIC)
        .collect();
    assert_eq!(msgs.len(), 2);
    assert_eq!((msgs[0].log_time, msgs[1].log_time), (42, 43));
    assert_eq!((msgs[0].sequence, msgs[1].sequence), (1, 2));
    assert_eq!(msgs[0].channel.topic, RESULT_TOPIC);
    assert_eq!(
        StreamLandingSitesResponse::decode(&msgs[0].data[..]).unwrap(),
        response
    );
    // A file of answers alone holds no frame to replay.
    assert!(matches!(read_bytes(&bytes), Err(Error::NoFrames)));
}

/// Found by the `recording` fuzz target: a record length that mcap 0.26 adds to without a check
/// (it panicked with "attempt to add with overflow"). Reading it is an error, not a panic.
#[test]
fn a_record_length_near_the_integer_limit_is_an_error_not_a_panic() {
    let bytes = include_bytes!("data/fuzz-mcap-record-length-overflow.mcap");
    let err = landing_recording::read_bytes(bytes).unwrap_err();
    assert!(err.to_string().contains("MCAP"), "{err}");
}

/// Found by the `recording` fuzz target: zstd chunks whose records declare lengths near 2^64,
/// which mcap 0.26 tried to reserve (an allocation failure aborts the process; a test that
/// reached it would abort the test binary). They are errors.
#[test]
fn records_declaring_impossible_lengths_are_errors_not_aborts() {
    for bytes in [
        &include_bytes!("data/fuzz-mcap-huge-chunk.mcap")[..],
        &include_bytes!("data/fuzz-mcap-huge-chunk-record.mcap")[..],
    ] {
        let err = landing_recording::read_bytes(bytes).unwrap_err();
        assert!(err.to_string().contains("MCAP"), "{err}");
    }
}

/// Found by the `ply` fuzz target: a binary file whose header claims up to 2^31 rows of an
/// element with no properties, which the reader counted through one by one (minutes). Rows of
/// no bytes are now skipped, so the file is answered at once.
#[test]
fn rows_of_no_properties_are_not_counted_one_by_one() {
    let bytes = include_bytes!("data/fuzz-ply-empty-rows.ply");
    let answer = landing_recording::ply::parse(bytes);
    let points = answer.map(|c| c.points.len()).map_err(|e| e.to_string());
    assert_eq!(points, Ok(0), "{points:?}");
}

/// Any frame a drone may send, with its parts present or not, poses anywhere the API allows and
/// raw or encoded pixels, is read back from the Foxglove channels exactly as it was written.
mod round_trip {
    use super::*;
    use proptest::prelude::*;

    fn pose() -> impl Strategy<Value = Option<v1::Pose>> {
        proptest::option::of(
            (
                proptest::array::uniform3(-1e7f64..1e7),
                proptest::array::uniform4(-1.0f64..1.0),
            )
                .prop_map(|([x, y, z], [qx, qy, qz, qw])| v1::Pose {
                    position: Some(v1::Vector3 { x, y, z }),
                    orientation: Some(v1::Quaternion {
                        x: qx,
                        y: qy,
                        z: qz,
                        w: qw,
                    }),
                }),
        )
    }

    fn time() -> impl Strategy<Value = Option<prost_types::Timestamp>> {
        proptest::option::of(
            (0i64..4_000_000_000, 0i32..1_000_000_000)
                .prop_map(|(seconds, nanos)| prost_types::Timestamp { seconds, nanos }),
        )
    }

    fn cloud() -> impl Strategy<Value = v1::PointCloud> {
        (
            time(),
            "[a-z]{1,8}",
            pose(),
            proptest::collection::vec(any::<u8>(), 0..64),
        )
            .prop_map(|(timestamp, frame_id, pose, data)| v1::PointCloud {
                timestamp,
                frame_id: format!("lidar-{frame_id}"),
                pose,
                point_stride: 16,
                fields: vec![v1::PackedElementField {
                    name: "x".into(),
                    offset: 0,
                    r#type: v1::NumericType::Float32 as i32,
                }],
                data: data.into(),
            })
    }

    fn camera() -> impl Strategy<Value = v1::CameraImage> {
        (
            time(),
            pose(),
            proptest::option::of((1u32..5000, 1u32..5000, 1.0f64..1e4, 0.0f64..5000.0)),
            any::<bool>(),
            proptest::collection::vec(any::<u8>(), 0..32),
        )
            .prop_map(|(timestamp, pose, k, raw, data)| v1::CameraImage {
                timestamp,
                frame_id: "camera".into(),
                pose,
                calibration: k.map(|(width, height, f, c)| v1::CameraCalibration {
                    width,
                    height,
                    fx: f,
                    fy: f * 1.01,
                    cx: c,
                    cy: c * 0.75,
                }),
                image: Some(if raw {
                    v1::camera_image::Image::Raw(v1::RawImage {
                        width: 2,
                        height: 1,
                        encoding: "rgb8".into(),
                        step: 6,
                        data: data.into(),
                    })
                } else {
                    v1::camera_image::Image::Compressed(v1::CompressedImage {
                        data: data.into(),
                        format: "png".into(),
                    })
                }),
            })
    }

    fn frame() -> impl Strategy<Value = Frame> {
        (
            "[a-z0-9-]{0,12}",
            any::<u64>(),
            time(),
            proptest::option::of(cloud()),
            proptest::option::of(camera()),
            proptest::option::of((-90.0f64..90.0, -180.0f64..180.0, -100.0f64..9000.0)),
        )
            .prop_map(
                |(drone_id, sequence, timestamp, point_cloud, image, geo)| Frame {
                    drone_id,
                    sequence,
                    timestamp,
                    point_cloud,
                    image,
                    geodetic_origin: geo.map(|(latitude_deg, longitude_deg, altitude_m)| {
                        v1::GeodeticPoint {
                            latitude_deg,
                            longitude_deg,
                            altitude_m,
                        }
                    }),
                    class_image: None,
                },
            )
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 128,
            rng_seed: proptest::test_runner::RngSeed::Fixed(18),
            ..Default::default()
        })]
        #[test]
        fn frames_read_back_as_written(frames in proptest::collection::vec(frame(), 1..4)) {
            let mut w = Writer::new(std::io::Cursor::new(Vec::new()), "proptest").unwrap();
            for (i, f) in frames.iter().enumerate() {
                w.write_frame(1_000 + i as u64, f).unwrap();
            }
            let read = read_bytes(&w.finish().unwrap().into_inner()).unwrap();
            let read: Vec<Frame> = read.into_iter().map(|r| r.frame).collect();
            prop_assert_eq!(read, frames);
        }
    }
}
