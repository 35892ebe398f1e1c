//! Simulated flights as MCAP recordings, in the format of [`landing_recording`], which also
//! reads them back.
//!
//! Each frame is three messages at the frame's timestamp: the `landing.v1.Frame` (LiDAR scan in
//! the LiDAR frame, pose = T_world_lidar, fields x, y, z, intensity FLOAT32 and class UINT8,
//! stride 17; PNG camera image, pose = T_world_camera, optical), its `landing.v1.GroundTruth`
//! and its true label image. The same seed gives a byte-identical file.
//!
//! The poses a frame carries are the drone's belief: the true poses, or with
//! [`RecordConfig::pose_noise`] the true poses moved by one rigid error of the drone body
//! ([`crate::noise`]). The scan is always simulated from the true pose, and the ground truth
//! (`GroundTruth.camera_pose`/`lidar_pose`, roofs, obstacles) keeps the true poses.

use std::io::Cursor;
use std::path::Path;

use landing_proto::v1;
use nalgebra::Isometry3;
use rand::SeedableRng;
use rand::rngs::SmallRng;

use crate::SimError;
use crate::camera::{CameraConfig, Intrinsics, Rendered, render};
use crate::dataset::{encode_label_png, encode_rgb_png};
use crate::flight::{FlightConfig, View, approach, lidar_pose};
use crate::geodetic::Geodetic;
use crate::lidar::{LidarConfig, LidarPoint, scan};
use crate::noise::{PoseNoise, body_errors};
use crate::truth::{RoofTruth, TruthConfig, ground_truth};
use crate::world::{World, WorldConfig};

/// Start time of every recording (2026-01-01T00:00:00Z), so that files are reproducible.
pub const START_UNIX_S: i64 = 1_767_225_600;

/// What to record.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordConfig {
    pub seed: u64,
    pub world: WorldConfig,
    pub flight: FlightConfig,
    pub width: u32,
    pub height: u32,
    pub camera: CameraConfig,
    pub lidar: LidarConfig,
    pub truth: TruthConfig,
    /// Roof to approach; `None` picks the one with the most assets.
    pub building: Option<usize>,
    pub drone_id: String,
    /// Error of the poses the frames carry (default: none, the true poses).
    pub pose_noise: PoseNoise,
    /// WGS-84 position of the world origin that every frame carries (default: none).
    pub geodetic_origin: Option<Geodetic>,
    /// Which visit of the roof this flight is (default: the first).
    pub visit: Visit,
}

/// One visit of a roof: the first flies today's approach at [`START_UNIX_S`]; a later one starts
/// `start_offset_s` later and draws its own heading, aim, pose error and sensor noise, as another
/// drone's approach would. The light stays (the world's sun is part of the world).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Visit {
    /// 0 for the first visit.
    pub index: u32,
    /// Seconds from [`START_UNIX_S`] to the visit's first frame.
    pub start_offset_s: f64,
}

impl Visit {
    /// The first visit: today's recordings.
    pub const FIRST: Visit = Visit {
        index: 0,
        start_offset_s: 0.0,
    };

    /// Visit `index` of visits `interval_s` apart.
    pub fn nth(index: u32, interval_s: f64) -> Visit {
        Visit {
            index,
            start_offset_s: f64::from(index) * interval_s,
        }
    }

    /// The seed of this visit's random draws from a recording's seed (the seed itself on the
    /// first visit, so that first visits are today's).
    pub fn seed(self, seed: u64) -> u64 {
        if self.index == 0 {
            seed
        } else {
            seed ^ u64::from(self.index).wrapping_mul(0xd6e8_feb8_6659_fd93)
        }
    }

    /// Checks the offset: finite, not negative, under 100 years.
    pub fn validate(&self) -> Result<(), SimError> {
        let s = self.start_offset_s;
        if !(s.is_finite() && (0.0..=3.2e9).contains(&s)) {
            return Err(SimError::invalid(
                "visit.start_offset_s",
                s,
                "must be in 0..=3.2e9 s",
            ));
        }
        Ok(())
    }
}

impl Default for RecordConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            world: WorldConfig::default(),
            flight: FlightConfig::default(),
            width: 320,
            height: 240,
            camera: CameraConfig::default(),
            lidar: LidarConfig::default(),
            truth: TruthConfig::default(),
            building: None,
            drone_id: "sim-1".to_string(),
            pose_noise: PoseNoise::NONE,
            geodetic_origin: None,
            visit: Visit::FIRST,
        }
    }
}

/// One simulated frame, before encoding.
#[derive(Debug, Clone)]
pub struct SimFrame {
    pub sequence: u64,
    /// The true view (`view.camera` is the true T_world_camera).
    pub view: View,
    /// The true T_world_lidar, which the scan was taken from.
    pub lidar_pose: Isometry3<f64>,
    /// T_world_camera as the drone believes it: what the frame carries.
    pub carried_camera_pose: Isometry3<f64>,
    /// T_world_lidar as the drone believes it: what the frame carries.
    pub carried_lidar_pose: Isometry3<f64>,
    pub intrinsics: Intrinsics,
    pub image: Rendered,
    pub points: Vec<LidarPoint>,
    pub roofs: Vec<RoofTruth>,
}

/// The roof with the most assets (ties: the lowest index).
pub fn busiest_roof(world: &World) -> usize {
    (0..world.buildings.len())
        .max_by_key(|&i| (world.buildings[i].assets.len(), std::cmp::Reverse(i)))
        .unwrap_or(0)
}

/// Simulates the frames of a flight (camera, LiDAR and ground truth), without encoding them.
pub fn simulate(config: &RecordConfig) -> Result<(World, Vec<SimFrame>), SimError> {
    let world = World::generate(config.seed, &config.world)?;
    let frames = simulate_in(&world, config)?;
    Ok((world, frames))
}

/// Simulates the frames of a flight over `world` (the world of `config.seed` as it is at
/// `config.visit`, for example from [`crate::revisit::revise`]).
pub fn simulate_in(world: &World, config: &RecordConfig) -> Result<Vec<SimFrame>, SimError> {
    config.pose_noise.validate()?;
    config.visit.validate()?;
    if !(config.flight.rate_hz.is_finite() && config.flight.rate_hz > 0.0) {
        return Err(SimError::invalid(
            "flight.rate_hz",
            config.flight.rate_hz,
            "must be positive",
        ));
    }
    if world.buildings.is_empty() {
        return Err(SimError::invalid(
            "world",
            "no buildings",
            "the city has no building to approach",
        ));
    }
    let building = config.building.unwrap_or_else(|| busiest_roof(world));
    if building >= world.buildings.len() {
        return Err(SimError::invalid(
            "building",
            building,
            "is not a building of this world",
        ));
    }
    let intrinsics = Intrinsics::from_hfov(config.width, config.height, config.camera.hfov_deg)?;
    let seed = config.visit.seed(config.seed);
    let mut rng = SmallRng::seed_from_u64(seed ^ 0x666c_6967_6874);
    let views = approach(world, building, &config.flight, &mut rng);
    // Its own stream per approach (buildings of one world share the world's seed), so the
    // pose error changes none of the draws above.
    let noise_seed = (seed ^ 0x706f_7365_6e6f_6973)
        .wrapping_add((building as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let errors = body_errors(
        &config.pose_noise,
        noise_seed,
        views.len(),
        config.flight.rate_hz,
    );
    let mut frames = Vec::with_capacity(views.len());
    for (i, (view, error)) in views.into_iter().zip(errors).enumerate() {
        let frame_seed = seed.wrapping_mul(1_000_003).wrapping_add(i as u64);
        let lp = lidar_pose(&view.camera);
        // The drone body's origin is the camera's; the LiDAR is bolted 5 cm above it.
        let (carried_camera_pose, carried_lidar_pose) = if config.pose_noise.is_none() {
            (view.camera, lp)
        } else {
            let origin = view.camera.translation.vector;
            (
                error.apply(&origin, &view.camera),
                error.apply(&origin, &lp),
            )
        };
        let image = render(world, &intrinsics, &view.camera, &config.camera, frame_seed);
        let points = scan(world, &lp, &config.lidar, frame_seed)?;
        let roofs = ground_truth(world, &points, building, &config.truth)?;
        frames.push(SimFrame {
            sequence: i as u64,
            view,
            lidar_pose: lp,
            carried_camera_pose,
            carried_lidar_pose,
            intrinsics,
            image,
            points,
            roofs,
        });
    }
    Ok(frames)
}

/// Protobuf pose of an isometry.
pub fn pose_to_proto(p: &Isometry3<f64>) -> v1::Pose {
    let t = p.translation.vector;
    let q = p.rotation.quaternion();
    v1::Pose {
        position: Some(v1::Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        }),
        orientation: Some(v1::Quaternion {
            x: q.i,
            y: q.j,
            z: q.k,
            w: q.w,
        }),
    }
}

/// Isometry of a protobuf pose (identity when unset; the quaternion is normalised).
pub fn pose_from_proto(p: Option<&v1::Pose>) -> Isometry3<f64> {
    let Some(p) = p else {
        return Isometry3::identity();
    };
    let t = p.position.unwrap_or_default();
    let q = p.orientation.unwrap_or(v1::Quaternion {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    });
    let uq =
        nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
    Isometry3::from_parts(nalgebra::Translation3::new(t.x, t.y, t.z), uq)
}

/// The timestamp frame `sequence` of a recording of `config` carries.
pub fn frame_time(config: &RecordConfig, sequence: u64) -> prost_types::Timestamp {
    timestamp(sequence, config.flight.rate_hz, config.visit.start_offset_s)
}

/// The time of frame `sequence` at `rate_hz`, `offset_s` after [`START_UNIX_S`].
fn timestamp(sequence: u64, rate_hz: f64, offset_s: f64) -> prost_types::Timestamp {
    let ns = (sequence as f64 / rate_hz * 1e9).round() as i64 + (offset_s * 1e9).round() as i64;
    prost_types::Timestamp {
        seconds: START_UNIX_S + ns / 1_000_000_000,
        nanos: (ns % 1_000_000_000) as i32,
    }
}

fn ring(points: &[[f64; 2]], z: f64) -> v1::LinearRing {
    v1::LinearRing {
        points: points
            .iter()
            .map(|p| v1::Vector3 {
                x: p[0],
                y: p[1],
                z,
            })
            .collect(),
    }
}

/// The scan in the LiDAR frame, packed as the API's point clouds are (x, y, z, intensity float32
/// and the true class byte: [`landing_proto::cloud::pack`]).
fn lidar_cloud(
    ts: prost_types::Timestamp,
    pose: v1::Pose,
    points: &[LidarPoint],
) -> v1::PointCloud {
    let xyz: Vec<[f32; 3]> = points.iter().map(|p| p.local).collect();
    let intensities: Vec<f32> = points.iter().map(|p| p.intensity).collect();
    let classes: Vec<u8> = points.iter().map(|p| p.class).collect();
    v1::PointCloud {
        timestamp: Some(ts),
        frame_id: "lidar".to_string(),
        pose: Some(pose),
        ..landing_proto::cloud::pack(&xyz, Some(&intensities), Some(&classes))
    }
}

fn calibration(i: &Intrinsics) -> v1::CameraCalibration {
    v1::CameraCalibration {
        width: i.width,
        height: i.height,
        fx: i.fx,
        fy: i.fy,
        cx: i.cx,
        cy: i.cy,
    }
}

/// The three messages of a frame: Frame, GroundTruth and the label image. The frame and the
/// label image (pixel-registered with the camera image) carry the believed poses, the ground
/// truth the true ones.
pub fn frame_messages(
    world: &World,
    f: &SimFrame,
    config: &RecordConfig,
) -> Result<(v1::Frame, v1::GroundTruth, v1::CameraImage), SimError> {
    let ts = frame_time(config, f.sequence);
    let cam_pose = pose_to_proto(&f.carried_camera_pose);
    let lidar_pose = pose_to_proto(&f.carried_lidar_pose);
    let frame = v1::Frame {
        drone_id: config.drone_id.clone(),
        sequence: f.sequence,
        timestamp: Some(ts),
        point_cloud: Some(lidar_cloud(ts, lidar_pose, &f.points)),
        image: Some(camera_png(ts, cam_pose, f, encode_rgb_png(&f.image)?)),
        geodetic_origin: config.geodetic_origin.map(crate::geodetic::geodetic_point),
        // The true labels travel on their own topic, so that a replay is segmented by the server.
        class_image: None,
    };
    let labels = camera_png(ts, cam_pose, f, encode_label_png(&f.image)?);
    let truth = v1::GroundTruth {
        sequence: f.sequence,
        timestamp: Some(ts),
        world_seed: world.seed,
        target_building: f.view.building as u32,
        roofs: f.roofs.iter().map(roof_truth).collect(),
        camera_pose: Some(pose_to_proto(&f.view.camera)),
        lidar_pose: Some(pose_to_proto(&f.lidar_pose)),
    };
    Ok((frame, truth, labels))
}

/// A PNG from the camera of frame `f`, at `ts` with pose `pose` and the camera's calibration.
fn camera_png(
    ts: prost_types::Timestamp,
    pose: v1::Pose,
    f: &SimFrame,
    png: Vec<u8>,
) -> v1::CameraImage {
    v1::CameraImage {
        timestamp: Some(ts),
        frame_id: "camera".to_string(),
        pose: Some(pose),
        calibration: Some(calibration(&f.intrinsics)),
        image: Some(v1::camera_image::Image::Compressed(v1::CompressedImage {
            data: png.into(),
            format: "png".to_string(),
        })),
    }
}

/// The ground truth of one roof as its message, every ring at the roof's height.
fn roof_truth(r: &RoofTruth) -> v1::RoofTruth {
    v1::RoofTruth {
        building: r.building as u32,
        outline: Some(ring(&r.outline, r.height_m)),
        height_m: r.height_m,
        parapet_height_m: r.parapet_height_m,
        obstacles: r
            .obstacles
            .iter()
            .map(|o| v1::ObstacleTruth {
                asset: o.kind.name().to_string(),
                semantic_class: i32::from(o.class),
                footprint: Some(ring(&o.footprint, r.height_m)),
                height_m: o.height_m,
                seen_by_lidar: o.seen_by_lidar,
            })
            .collect(),
        landable_region: Some(v1::Polygon {
            shell: Some(ring(&r.landable_region.shell, r.height_m)),
            holes: r
                .landable_region
                .holes
                .iter()
                .map(|h| ring(h, r.height_m))
                .collect(),
            plane_height_m: r.height_m,
        }),
        best_landing_point: Some(v1::Vector3 {
            x: r.best_point[0],
            y: r.best_point[1],
            z: r.height_m,
        }),
        best_safe_radius_m: r.best_radius_m,
        lidar_point_count: r.lidar_points as u32,
    }
}

/// Simulates a flight and writes it as an MCAP file (zstd chunks). Returns the frame count.
pub fn write_recording(config: &RecordConfig, path: &Path) -> Result<usize, SimError> {
    let (world, frames) = simulate(config)?;
    let bytes = encode_recording(&world, &frames, config)?;
    std::fs::write(path, bytes).map_err(|e| SimError::io(path, e))?;
    Ok(frames.len())
}

/// Encodes simulated frames as MCAP bytes: per frame, the frame, its ground truth and its label
/// image, at the frame's timestamp ([`landing_recording`] owns the format).
pub fn encode_recording(
    world: &World,
    frames: &[SimFrame],
    config: &RecordConfig,
) -> Result<Vec<u8>, SimError> {
    let mut w = landing_recording::Writer::new(Cursor::new(Vec::new()), "landing-sim")?;
    for f in frames {
        let (frame, truth, labels) = frame_messages(world, f, config)?;
        let t = landing_recording::log_time_ns(&frame.timestamp.unwrap_or_default());
        w.write_frame(t, &frame)?;
        w.write_truth(t, &truth)?;
        w.write_labels(t, f.sequence, &labels)?;
    }
    Ok(w.finish()?.into_inner())
}

/// The (Frame, GroundTruth) pairs of a recording; frames without ground truth are skipped.
pub fn read_pairs(path: &Path) -> Result<Vec<(v1::Frame, v1::GroundTruth)>, SimError> {
    Ok(landing_recording::read(path)?
        .into_iter()
        .filter_map(|r| r.truth.map(|t| (r.frame, t)))
        .collect())
}

/// Writes points (world coordinates) as a binary little-endian PLY with `x y z` float and
/// `class` uchar ([`landing_recording::ply::write_binary`], with a comment naming the frame).
pub fn write_ply(points: &[LidarPoint], path: &Path) -> Result<(), SimError> {
    let cloud = landing_recording::ply::PlyCloud {
        points: points.iter().map(|p| p.world.map(|v| v as f32)).collect(),
        classes: Some(points.iter().map(|p| p.class).collect()),
    };
    let out = landing_recording::ply::write_binary_with_comment(
        &cloud,
        Some("landing-sim LiDAR scan, world coordinates (ENU, metres)"),
    );
    std::fs::write(path, out).map_err(|e| SimError::io(path, e))
}
