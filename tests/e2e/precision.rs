//! Results do not depend on where the world origin is: a frame moved by any offset the API
//! accepts (its cloud, camera and class camera together) gives the same sites in the same
//! order, moved by the offset, with centres, plane heights and radii within a millimetre, in
//! every segmentation mode and in a fused stream.

use landing_client::v1::{self, SegmentationMode};
use landing_client::{FrameOutcome, StreamConfig};
use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

use crate::support::{SCENE_FRAMES, TestServer, in_process, mode, scene, stream_with};

/// Offsets stay this far inside the API's 1e7 m bound, so that the scene (a few hundred metres
/// across) stays inside it too.
const REACH_M: f64 = 1.0e7 - 1.0e4;

/// A millimetre.
const TOLERANCE_M: f64 = 1e-3;

/// `frame` with every pose it carries moved by `d`.
fn moved(frame: &v1::Frame, d: [f64; 3]) -> v1::Frame {
    let mut f = frame.clone();
    let poses = [
        f.point_cloud.as_mut().and_then(|c| c.pose.as_mut()),
        f.image.as_mut().and_then(|i| i.pose.as_mut()),
        f.class_image.as_mut().and_then(|i| i.pose.as_mut()),
    ];
    for pose in poses.into_iter().flatten() {
        let p = pose.position.get_or_insert_with(Default::default);
        p.x += d[0];
        p.y += d[1];
        p.z += d[2];
    }
    f
}

fn xyz(v: Option<&v1::Vector3>) -> [f64; 3] {
    v.map_or([f64::NAN; 3], |v| [v.x, v.y, v.z])
}

/// Why `there` (the answer to the frame moved by `d`) differs from `here`, if it does.
fn difference(here: &v1::FrameResult, there: &v1::FrameResult, d: [f64; 3]) -> Option<String> {
    if here.sites.len() != there.sites.len() {
        return Some(format!(
            "{} sites here, {} there",
            here.sites.len(),
            there.sites.len()
        ));
    }
    for (a, b) in here.sites.iter().zip(&there.sites) {
        let (ca, cb) = (xyz(a.center.as_ref()), xyz(b.center.as_ref()));
        let off = (0..3)
            .map(|i| (ca[i] + d[i] - cb[i]).abs())
            .fold(0.0, f64::max);
        let height =
            |s: &v1::LandingSite| s.polygon.as_ref().map_or(f64::NAN, |p| p.plane_height_m);
        let dz = (height(a) + d[2] - height(b)).abs();
        let dr = (a.safe_radius_m - b.safe_radius_m).abs();
        if a.rank != b.rank || !(off < TOLERANCE_M && dz < TOLERANCE_M && dr < TOLERANCE_M) {
            return Some(format!(
                "site {}: centre off by {off:.2e} m, plane by {dz:.2e} m, radius by {dr:.2e} m \
                 (rank {} vs {})",
                a.rank, a.rank, b.rank
            ));
        }
    }
    None
}

/// The frames and modes the property runs on: the scene's first and last frames, each in every
/// mode the server has (the model's only when it is installed), with the true labels as the
/// class image.
fn cases(server: &TestServer) -> Vec<(v1::Frame, SegmentationMode)> {
    let scene = scene(71);
    let mut modes = vec![
        SegmentationMode::None,
        SegmentationMode::PointClasses,
        SegmentationMode::ClassImage,
    ];
    if server.config.segmentation.enabled {
        modes.push(SegmentationMode::Model);
    }
    let mut out = Vec::new();
    for recorded in [&scene.frames[0], &scene.frames[SCENE_FRAMES as usize - 1]] {
        let mut frame = recorded.frame.clone();
        frame.class_image.clone_from(&recorded.labels);
        out.extend(modes.iter().map(|&m| (frame.clone(), m)));
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn moving_the_world_origin_moves_the_sites_and_nothing_else() {
    let server = TestServer::start().await;
    let cases = cases(&server);
    let answer = |frame: &v1::Frame, m: SegmentationMode| {
        in_process(server.reference(), frame, &mode(m)).expect("the frame is answered")
    };
    let here: Vec<v1::FrameResult> = cases.iter().map(|(f, m)| answer(f, *m)).collect();
    assert!(
        here.iter().all(|r| !r.sites.is_empty()),
        "every case has sites to compare"
    );
    let check = |d: [f64; 3]| -> Result<(), TestCaseError> {
        for ((frame, m), here) in cases.iter().zip(&here) {
            let there = answer(&moved(frame, d), *m);
            if let Some(why) = difference(here, &there, d) {
                return Err(TestCaseError::fail(format!(
                    "{m:?}, frame {}: {why}",
                    frame.sequence
                )));
            }
        }
        Ok(())
    };
    // The offsets that broke single precision (UTM-like, and a few tens of kilometres), and the
    // corners of the accepted range.
    for d in [
        [5.0e5, 4.5e6, 0.0],
        [3.0e4, 4.0e4, 0.0],
        [REACH_M, -REACH_M, 0.0],
        [-REACH_M, REACH_M, REACH_M],
    ] {
        check(d).unwrap_or_else(|e| panic!("offset {d:?}: {e}"));
    }
    let mut runner = TestRunner::new(Config {
        cases: 12,
        ..Config::default()
    });
    let offsets = (-REACH_M..REACH_M, -REACH_M..REACH_M, -REACH_M..REACH_M);
    runner
        .run(&offsets, |(x, y, z)| check([x, y, z]))
        .unwrap_or_else(|e| panic!("{e}"));
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fused_stream_far_from_the_world_origin_answers_as_near_it() {
    let server = TestServer::start().await;
    let recorded = &scene(73).frames;
    let frames: Vec<v1::Frame> = recorded
        .iter()
        .map(|r| {
            let mut f = r.frame.clone();
            f.class_image.clone_from(&r.labels);
            f
        })
        .collect();
    let config = StreamConfig {
        max_in_flight: 4,
        ..StreamConfig::fused().with_options(mode(SegmentationMode::ClassImage))
    };
    let answers = |frames: Vec<v1::Frame>| {
        let (server, config) = (&server, config.clone());
        async move {
            stream_with(server, frames, config, None)
                .await
                .into_iter()
                .map(|item| match item.outcome {
                    FrameOutcome::Result(r) => r,
                    other => panic!("frame {}: {other:?}", item.sequence),
                })
                .collect::<Vec<_>>()
        }
    };
    let here = answers(frames.clone()).await;
    let d = [5.0e5, 4.5e6, 0.0];
    let there = answers(frames.iter().map(|f| moved(f, d)).collect()).await;
    assert_eq!(here.len(), frames.len());
    assert!(here.iter().any(|r| !r.sites.is_empty()));
    for (i, (a, b)) in here.iter().zip(&there).enumerate() {
        assert_eq!(
            a.fusion.as_ref().map(|f| f.frames),
            b.fusion.as_ref().map(|f| f.frames)
        );
        if let Some(why) = difference(a, b, d) {
            panic!("frame {i}: {why}");
        }
    }
    server.stop().await;
}

/// `frame`'s cloud moved to the world frame and by `d`, sent as FLOAT64 points with no pose
/// (the API's "already in world coordinates"), with its classes.
fn in_world_coordinates(frame: &v1::Frame, d: [f64; 3]) -> v1::Frame {
    let cloud = frame.point_cloud.as_ref().expect("a cloud");
    let unpacked = landing_client::unpack_point_cloud(cloud).expect("unpack the cloud");
    let classes = unpacked.classes.clone().expect("the cloud has classes");
    let mut data = Vec::new();
    for (p, class) in unpacked.to_world(cloud.pose.as_ref()).iter().zip(classes) {
        for i in 0..3 {
            data.extend_from_slice(&(p[i] + d[i]).to_le_bytes());
        }
        data.push(class);
    }
    let field = |name: &str, offset, ty: v1::NumericType| v1::PackedElementField {
        name: name.into(),
        offset,
        r#type: ty as i32,
    };
    let mut f = frame.clone();
    f.point_cloud = Some(v1::PointCloud {
        point_stride: 25,
        fields: vec![
            field("x", 0, v1::NumericType::Float64),
            field("y", 8, v1::NumericType::Float64),
            field("z", 16, v1::NumericType::Float64),
            field("class", 24, v1::NumericType::Uint8),
        ],
        data: data.into(),
        ..Default::default()
    });
    f
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_cloud_sent_in_world_coordinates_keeps_its_millimetres_far_from_the_origin() {
    let server = TestServer::start().await;
    let frame = scene(71).frames[0].frame.clone();
    let m = mode(SegmentationMode::PointClasses);
    let here = in_process(server.reference(), &frame, &m).expect("answered");
    assert!(!here.sites.is_empty());
    for d in [[0.0; 3], [5.0e5, 4.5e6, 0.0], [-REACH_M, REACH_M, 0.0]] {
        let there =
            in_process(server.reference(), &in_world_coordinates(&frame, d), &m).expect("answered");
        if let Some(why) = difference(&here, &there, d) {
            panic!("offset {d:?}: {why}");
        }
    }
    server.stop().await;
}
