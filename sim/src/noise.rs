//! Pose error of a real drone's navigation solution: the poses a frame *carries* (what the drone
//! believes, T_world_lidar and T_world_camera) differ from the true poses the sensors were
//! simulated from, while the ground truth keeps the true ones.
//!
//! The error is one rigid transform of the drone body per frame, so the LiDAR and the camera,
//! bolted to the same body, stay mutually consistent (T_camera_lidar is unchanged): a position
//! error (a per-approach bias plus a random walk) and an attitude error (small white noise per
//! frame plus a per-approach heading bias). [`PoseNoise`] holds the numbers and their sources,
//! [`body_errors`] draws the errors of one approach and [`BodyError::apply`] moves a sensor pose.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

use crate::SimError;

/// How wrong the drone's own pose is, as standard deviations per axis (metres, degrees).
///
/// [`PoseNoise::REALISTIC`] is an RTK-fixed GNSS receiver with a dual-antenna MEMS INS, the
/// kind of navigation a survey or delivery drone flies with:
///
/// - **Position**, from the RTK specifications: u-blox ZED-F9P/ZED-F9R integration manuals
///   (UBX-18010802, UBX-20039643) give RTK fixed 0.01 m + 1 ppm CEP horizontal; the SBG
///   Apogee hardware manual (airborne, RTK) 0.01 m + 1 ppm horizontal and 0.02 m + 1 ppm
///   vertical, i.e. vertical about twice horizontal. For a base up to 10 km away that is
///   about 2 cm horizontal and 3 cm vertical, taken here as the per-axis standard deviation of
///   a bias held for the whole approach (RTK errors, multipath and the base's own position
///   error are correlated over minutes, not white at 10 Hz), plus a random walk of
///   1 cm/√s per axis for the slow drift within the approach (2 cm over a 4 s approach).
/// - **Attitude**, from the datasheets of tactical/industrial MEMS INS with dual-antenna
///   heading (SBG Ellipse-D: roll/pitch 0.05°, heading 0.2° with RTK; VectorNav VN-300:
///   roll/pitch 0.03°, heading about 0.1-0.3° depending on the antenna baseline): white noise
///   of 0.03° in roll and pitch and 0.1° in yaw per frame, plus a per-approach heading bias of
///   0.1° (the dual-antenna baseline's misalignment, constant over a flight).
///
/// [`PoseNoise::NONE`] (the [`Default`]) carries the true poses, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseNoise {
    /// Per-approach position bias, east and north, metres (1 σ per axis).
    pub horizontal_bias_m: f64,
    /// Per-approach position bias, up, metres (1 σ).
    pub vertical_bias_m: f64,
    /// Position random walk per axis, metres per √second.
    pub random_walk_m_per_sqrt_s: f64,
    /// Roll and pitch white noise per frame, degrees (1 σ each).
    pub roll_pitch_deg: f64,
    /// Yaw (heading) white noise per frame, degrees (1 σ).
    pub yaw_deg: f64,
    /// Per-approach heading bias, degrees (1 σ).
    pub heading_bias_deg: f64,
}

impl PoseNoise {
    /// No error: frames carry the true poses.
    pub const NONE: PoseNoise = PoseNoise {
        horizontal_bias_m: 0.0,
        vertical_bias_m: 0.0,
        random_walk_m_per_sqrt_s: 0.0,
        roll_pitch_deg: 0.0,
        yaw_deg: 0.0,
        heading_bias_deg: 0.0,
    };

    /// RTK-fixed GNSS with a dual-antenna MEMS INS (see the type's docs for the sources).
    pub const REALISTIC: PoseNoise = PoseNoise {
        horizontal_bias_m: 0.02,
        vertical_bias_m: 0.03,
        random_walk_m_per_sqrt_s: 0.01,
        roll_pitch_deg: 0.03,
        yaw_deg: 0.1,
        heading_bias_deg: 0.1,
    };

    /// Whether every deviation is zero (the frames then carry the true poses unchanged).
    pub fn is_none(&self) -> bool {
        self.fields().iter().all(|&(_, v)| v == 0.0)
    }

    /// Every deviation must be finite, non-negative and below 10 (metres or degrees).
    pub fn validate(&self) -> Result<(), SimError> {
        for (field, v) in self.fields() {
            if !(v.is_finite() && (0.0..=10.0).contains(&v)) {
                return Err(SimError::invalid(field, v, "must be in 0..=10"));
            }
        }
        Ok(())
    }

    fn fields(&self) -> [(&'static str, f64); 6] {
        [
            ("pose_noise.horizontal_bias_m", self.horizontal_bias_m),
            ("pose_noise.vertical_bias_m", self.vertical_bias_m),
            (
                "pose_noise.random_walk_m_per_sqrt_s",
                self.random_walk_m_per_sqrt_s,
            ),
            ("pose_noise.roll_pitch_deg", self.roll_pitch_deg),
            ("pose_noise.yaw_deg", self.yaw_deg),
            ("pose_noise.heading_bias_deg", self.heading_bias_deg),
        ]
    }
}

impl Default for PoseNoise {
    fn default() -> Self {
        Self::NONE
    }
}

/// The error of the drone body's pose at one frame, in world axes (east, north, up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BodyError {
    /// Position error of the body, metres.
    pub position_m: Vector3<f64>,
    /// Attitude error, a rotation in world axes about the body's origin.
    pub attitude: UnitQuaternion<f64>,
}

impl BodyError {
    /// No error.
    pub fn identity() -> Self {
        Self {
            position_m: Vector3::zeros(),
            attitude: UnitQuaternion::identity(),
        }
    }

    /// The believed pose of a sensor whose true pose is `sensor`, on a body whose true origin
    /// is `body_origin` (world): the sensor turns with the body about that origin and moves
    /// with it, so two sensors of one body keep their relative pose.
    pub fn apply(&self, body_origin: &Vector3<f64>, sensor: &Isometry3<f64>) -> Isometry3<f64> {
        self.about(body_origin) * sensor
    }

    /// The world-frame transform that takes true poses to believed ones: rotate by the
    /// attitude error about `body_origin`, then shift by the position error.
    pub fn about(&self, body_origin: &Vector3<f64>) -> Isometry3<f64> {
        let t = body_origin + self.position_m - self.attitude * body_origin;
        Isometry3::from_parts(Translation3::from(t), self.attitude)
    }
}

/// The body errors of one approach of `frames` frames at `rate_hz`, from `seed` alone (its
/// own stream, so drawing them changes no other draw of the simulator). The first frame's
/// position error is the bias; the random walk then steps by `√(1/rate_hz)` × its deviation
/// per axis and frame. With [`PoseNoise::NONE`] every error is exactly the identity.
pub fn body_errors(noise: &PoseNoise, seed: u64, frames: usize, rate_hz: f64) -> Vec<BodyError> {
    if noise.is_none() {
        return vec![BodyError::identity(); frames];
    }
    let mut rng = SmallRng::seed_from_u64(seed);
    let mut normal = || -> f64 { rng.sample(StandardNormal) };
    let bias = Vector3::new(
        normal() * noise.horizontal_bias_m,
        normal() * noise.horizontal_bias_m,
        normal() * noise.vertical_bias_m,
    );
    let heading_bias = normal() * noise.heading_bias_deg;
    let step = noise.random_walk_m_per_sqrt_s * (1.0 / rate_hz).sqrt();
    let mut walk = Vector3::zeros();
    (0..frames)
        .map(|i| {
            if i > 0 {
                walk += Vector3::new(normal(), normal(), normal()) * step;
            }
            let roll = normal() * noise.roll_pitch_deg;
            let pitch = normal() * noise.roll_pitch_deg;
            let yaw = heading_bias + normal() * noise.yaw_deg;
            BodyError {
                position_m: bias + walk,
                // Roll about east, pitch about north, yaw about up: for a few hundredths of a
                // degree the order and the heading-aligned axes make no measurable difference.
                attitude: UnitQuaternion::from_euler_angles(
                    roll.to_radians(),
                    pitch.to_radians(),
                    yaw.to_radians(),
                ),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::flight::{camera_pose, camera_to_lidar, lidar_pose};

    fn cameras(n: usize) -> Vec<Isometry3<f64>> {
        (0..n)
            .map(|i| {
                let f = i as f64 / n as f64;
                camera_pose([10.0 * f, -5.0 + f, 40.0 - 30.0 * f], 0.7, 1.0 + 0.4 * f)
            })
            .collect()
    }

    #[test]
    fn none_leaves_poses_identical() {
        assert!(PoseNoise::default().is_none());
        let cams = cameras(41);
        for (e, cam) in body_errors(&PoseNoise::NONE, 7, cams.len(), 10.0)
            .iter()
            .zip(&cams)
        {
            assert_eq!(*e, BodyError::identity());
            assert_eq!(e.apply(&cam.translation.vector, cam), *cam);
        }
    }

    #[test]
    fn realistic_errors_have_the_stated_magnitude() {
        let noise = PoseNoise::REALISTIC;
        assert!(!noise.is_none());
        noise.validate().unwrap();
        // Many approaches of one frame each: the error is the bias plus the attitude noise.
        let n = 4000;
        let firsts: Vec<BodyError> = (0..n).map(|s| body_errors(&noise, s, 1, 10.0)[0]).collect();
        let rms = |f: &dyn Fn(&BodyError) -> f64| {
            (firsts.iter().map(|e| f(e).powi(2)).sum::<f64>() / n as f64).sqrt()
        };
        let within = |got: f64, want: f64| (got - want).abs() < 0.1 * want;
        let (ex, ey, ez) = (
            rms(&|e| e.position_m.x),
            rms(&|e| e.position_m.y),
            rms(&|e| e.position_m.z),
        );
        assert!(within(ex, 0.02) && within(ey, 0.02), "{ex} {ey}");
        assert!(within(ez, 0.03), "{ez}");
        let (roll, pitch, yaw) = {
            let angles: Vec<(f64, f64, f64)> =
                firsts.iter().map(|e| e.attitude.euler_angles()).collect();
            let r = |k: usize| {
                let s: f64 = angles
                    .iter()
                    .map(|a| [a.0, a.1, a.2][k].to_degrees().powi(2))
                    .sum();
                (s / n as f64).sqrt()
            };
            (r(0), r(1), r(2))
        };
        assert!(within(roll, 0.03) && within(pitch, 0.03), "{roll} {pitch}");
        // Heading: bias and white noise, 0.1° each.
        assert!(within(yaw, 0.1 * 2f64.sqrt()), "{yaw}");

        // Within an approach the bias holds and the walk grows as √t: after 4 s at 10 Hz the
        // change since the first frame has 1 cm/√s × 2 s^½ = 2 cm per axis.
        let drift: Vec<f64> = (0..1000)
            .flat_map(|s| {
                let e = body_errors(&noise, 10_000 + s, 41, 10.0);
                let d = e[40].position_m - e[0].position_m;
                [d.x, d.y, d.z]
            })
            .collect();
        let d = (drift.iter().map(|v| v * v).sum::<f64>() / drift.len() as f64).sqrt();
        assert!(within(d, 0.02), "{d}");
        // And it is seeded.
        assert_eq!(
            body_errors(&noise, 3, 41, 10.0),
            body_errors(&noise, 3, 41, 10.0)
        );
        assert_ne!(
            body_errors(&noise, 3, 41, 10.0),
            body_errors(&noise, 4, 41, 10.0)
        );
    }

    #[test]
    fn camera_and_lidar_move_as_one_body() {
        let cams = cameras(41);
        let errors = body_errors(&PoseNoise::REALISTIC, 11, cams.len(), 10.0);
        for (e, cam) in errors.iter().zip(&cams) {
            let true_lidar = lidar_pose(cam);
            let origin = cam.translation.vector;
            let (c, l) = (e.apply(&origin, cam), e.apply(&origin, &true_lidar));
            let rel = c.inverse() * l;
            let want = camera_to_lidar();
            assert!((rel.translation.vector - want.translation.vector).norm() < 1e-9);
            assert!(rel.rotation.angle_to(&want.rotation) < 1e-9);
            // The camera's believed position is off by exactly the body's position error.
            let moved = c.translation.vector - cam.translation.vector;
            assert!((moved - e.position_m).norm() < 1e-12);
            assert!(e.position_m.norm() > 0.0);
        }
    }

    #[test]
    fn bad_deviations_are_named() {
        let bad = PoseNoise {
            yaw_deg: f64::NAN,
            ..PoseNoise::REALISTIC
        };
        let msg = bad.validate().unwrap_err().to_string();
        assert!(msg.contains("pose_noise.yaw_deg"), "{msg}");
    }
}
