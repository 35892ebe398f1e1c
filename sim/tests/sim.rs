//! End-to-end checks of the simulator: reproducibility, camera/LiDAR/pose consistency, ground
//! truth, and the committed samples.

use std::path::PathBuf;

use landing_geometry::Polygon;
use landing_geometry::polylabel::signed_distance;
use landing_proto::v1;
use landing_sim::flight::FlightConfig;
use landing_sim::recording::{RecordConfig, encode_recording, pose_from_proto, simulate};
use nalgebra::Point3;

fn config(seed: u64, frames: u32) -> RecordConfig {
    RecordConfig {
        seed,
        flight: FlightConfig {
            frames,
            ..Default::default()
        },
        width: 160,
        height: 120,
        ..Default::default()
    }
}

fn record(cfg: &RecordConfig) -> Vec<u8> {
    let (world, frames) = simulate(cfg).expect("simulate");
    encode_recording(&world, &frames, cfg).expect("encode")
}

fn samples() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../samples")
}

#[test]
fn same_seed_gives_identical_bytes_and_other_seeds_differ() {
    let a = record(&config(3, 4));
    let b = record(&config(3, 4));
    assert!(a == b, "two recordings of seed 3 differ");
    let c = record(&config(4, 4));
    assert!(a != c, "seeds 3 and 4 gave the same recording");
}

fn decode_png_l8(img: &v1::CameraImage) -> (u32, u32, Vec<u8>) {
    let Some(v1::camera_image::Image::Compressed(c)) = &img.image else {
        panic!("no compressed image")
    };
    let dynimg =
        image::load_from_memory_with_format(&c.data, image::ImageFormat::Png).expect("png");
    let l = dynimg.to_luma8();
    (l.width(), l.height(), l.into_raw())
}

/// Counts (agreeing, checked) points: each LiDAR point is moved to the world with the recorded
/// T_world_lidar, into the camera with the recorded T_world_camera, projected with the recorded
/// intrinsics, and compared with the label image where the 3×3 neighbourhood has one label.
fn projection_agreement(frames: &[landing_recording::RecordedFrame]) -> (usize, usize) {
    let (mut agree, mut checked) = (0usize, 0usize);
    for rf in frames {
        let pc = rf.frame.point_cloud.as_ref().expect("cloud");
        let img = rf.frame.image.as_ref().expect("image");
        let cal = img.calibration.as_ref().expect("calibration");
        let t_wl = pose_from_proto(pc.pose.as_ref());
        let t_wc = pose_from_proto(img.pose.as_ref());
        let t_cw = t_wc.inverse();
        let (w, h, labels) = decode_png_l8(rf.labels.as_ref().expect("labels"));
        assert_eq!((w, h), (cal.width, cal.height));
        let stride = pc.point_stride as usize;
        for chunk in pc.data.chunks_exact(stride) {
            let f =
                |o: usize| f32::from_le_bytes([chunk[o], chunk[o + 1], chunk[o + 2], chunk[o + 3]]);
            let p = Point3::new(f64::from(f(0)), f64::from(f(4)), f64::from(f(8)));
            let class = chunk[16];
            let c = t_cw * (t_wl * p);
            if c.z <= 0.0 {
                continue;
            }
            let u = (cal.fx * c.x / c.z + cal.cx).floor();
            let v = (cal.fy * c.y / c.z + cal.cy).floor();
            if u < 1.0 || v < 1.0 || u >= f64::from(w) - 1.0 || v >= f64::from(h) - 1.0 {
                continue;
            }
            let (u, v) = (u as usize, v as usize);
            let at = |x: usize, y: usize| labels[y * w as usize + x];
            let l = at(u, v);
            let uniform = (v - 1..=v + 1).all(|y| (u - 1..=u + 1).all(|x| at(x, y) == l));
            if !uniform {
                continue;
            }
            checked += 1;
            if l == class {
                agree += 1;
            }
        }
    }
    (agree, checked)
}

#[test]
fn lidar_points_project_onto_their_own_class_in_the_label_image() {
    for seed in [1u64, 2, 5] {
        let cfg = RecordConfig {
            width: 320,
            height: 240,
            ..config(seed, 8)
        };
        let frames = landing_recording::read_bytes(&record(&cfg)).expect("read back");
        assert_eq!(frames.len(), 8);
        let (agree, checked) = projection_agreement(&frames);
        assert!(
            checked > 8 * 800,
            "seed {seed}: only {checked} points away from label edges"
        );
        let ratio = agree as f64 / checked as f64;
        eprintln!(
            "seed {seed}: {agree}/{checked} = {ratio:.4} of points agree with the label image"
        );
        assert!(
            ratio >= 0.99,
            "seed {seed}: {agree}/{checked} = {ratio:.4} agree"
        );
    }
}

fn to_polygon(p: &v1::Polygon) -> Polygon {
    let ring = |r: &v1::LinearRing| r.points.iter().map(|q| [q.x, q.y]).collect::<Vec<_>>();
    #[allow(clippy::needless_update)]
    Polygon {
        shell: p.shell.as_ref().map(ring).unwrap_or_default(),
        holes: p.holes.iter().map(ring).collect(),
        ..Default::default()
    }
}

#[test]
fn best_landing_point_is_inside_the_free_roof_at_its_radius() {
    let frames = landing_recording::read_bytes(&record(&config(7, 6))).expect("read back");
    for rf in &frames {
        let gt = rf.truth.as_ref().expect("truth");
        assert!(!gt.roofs.is_empty());
        assert_eq!(gt.roofs[0].building, gt.target_building);
        for roof in &gt.roofs {
            let poly = to_polygon(roof.landable_region.as_ref().expect("region"));
            if poly.shell.len() < 3 {
                continue;
            }
            let c = roof.best_landing_point.as_ref().expect("point");
            let d = signed_distance(&poly, [c.x, c.y]);
            assert!(d > 0.0, "best point outside the free roof (d = {d})");
            assert!(
                (d - roof.best_safe_radius_m).abs() < 1e-6,
                "{d} vs {}",
                roof.best_safe_radius_m
            );
            // No obstacle footprint contains the point.
            for o in &roof.obstacles {
                let fp: Vec<[f64; 2]> = o
                    .footprint
                    .as_ref()
                    .expect("fp")
                    .points
                    .iter()
                    .map(|q| [q.x, q.y])
                    .collect();
                #[allow(clippy::needless_update)]
                let op = Polygon {
                    shell: fp,
                    holes: vec![],
                    ..Default::default()
                };
                assert!(
                    signed_distance(&op, [c.x, c.y]) < 0.0,
                    "best point inside a {}",
                    o.asset
                );
            }
            assert!((c.z - roof.height_m).abs() < 1e-9);
        }
    }
}

#[test]
fn committed_sample_recording_replays() {
    let path = samples().join("rooftops.mcap");
    let frames = landing_recording::read(&path).expect("samples/rooftops.mcap");
    assert!((10..=20).contains(&frames.len()), "{} frames", frames.len());
    assert!(std::fs::metadata(&path).expect("size").len() <= 5_000_000);
    for rf in &frames {
        assert!(rf.truth.is_some() && rf.labels.is_some());
    }
    let (agree, checked) = projection_agreement(&frames);
    assert!(agree as f64 >= 0.99 * checked as f64, "{agree}/{checked}");
}

#[test]
fn committed_sample_ply_has_world_points_with_classes() {
    let bytes = std::fs::read(samples().join("roof.ply")).expect("samples/roof.ply");
    assert!(bytes.len() < 1_000_000);
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .expect("header")
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).expect("ascii header");
    assert!(header.contains("format binary_little_endian 1.0"));
    assert!(header.contains("property uchar class"));
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .expect("vertex count")
        .parse()
        .expect("number");
    assert_eq!(bytes.len() - end, n * 13);
    let rooftop = bytes[end..].chunks_exact(13).filter(|p| p[12] == 4).count();
    assert!(rooftop > n / 3, "{rooftop} of {n} points on rooftops");
    let obstacles = bytes[end..].chunks_exact(13).filter(|p| p[12] >= 5).count();
    assert!(obstacles > 10, "{obstacles} obstacle points");
}

#[test]
fn realistic_pose_noise_moves_only_the_carried_poses_of_one_rigid_body() {
    use landing_sim::noise::PoseNoise;
    let base = RecordConfig {
        flight: FlightConfig {
            frames: 11,
            ..Default::default()
        },
        ..config(9100, 11)
    };
    let noisy = RecordConfig {
        pose_noise: PoseNoise::REALISTIC,
        ..base.clone()
    };
    let clean = landing_recording::read_bytes(&record(&base)).expect("read back");
    let moved = landing_recording::read_bytes(&record(&noisy)).expect("read back");
    assert_eq!(clean.len(), moved.len());
    for (c, m) in clean.iter().zip(&moved) {
        let (ct, mt) = (c.truth.as_ref().unwrap(), m.truth.as_ref().unwrap());
        // The ground truth is the same, true poses included, and so are the scan and pixels.
        assert_eq!(ct, mt);
        let (cc, mc) = (
            c.frame.point_cloud.as_ref().unwrap(),
            m.frame.point_cloud.as_ref().unwrap(),
        );
        assert_eq!(cc.data, mc.data);
        let (ci, mi) = (
            c.frame.image.as_ref().unwrap(),
            m.frame.image.as_ref().unwrap(),
        );
        assert_eq!(ci.image, mi.image);
        // Without noise the frame carries the true poses.
        assert_eq!(ci.pose, ct.camera_pose);
        assert_eq!(cc.pose, ct.lidar_pose);

        let true_cam = pose_from_proto(ct.camera_pose.as_ref());
        let true_lidar = pose_from_proto(ct.lidar_pose.as_ref());
        let cam = pose_from_proto(mi.pose.as_ref());
        let lidar = pose_from_proto(mc.pose.as_ref());
        let off = (cam.translation.vector - true_cam.translation.vector).norm();
        assert!(off > 1e-5 && off < 0.25, "camera position off by {off} m");
        let turned = cam.rotation.angle_to(&true_cam.rotation).to_degrees();
        assert!(turned > 1e-5 && turned < 1.0, "camera turned by {turned}°");
        // One body: the carried camera-to-LiDAR transform is the true one.
        let (want, got) = (true_cam.inverse() * true_lidar, cam.inverse() * lidar);
        assert!((want.translation.vector - got.translation.vector).norm() < 1e-9);
        assert!(want.rotation.angle_to(&got.rotation) < 1e-9);
        // The label image is registered with the camera image and carries its pose.
        assert_eq!(m.labels.as_ref().unwrap().pose, mi.pose);
    }
}
