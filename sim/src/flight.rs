//! Drone and sensor poses: single random views of a roof (for datasets) and approach flights
//! (for recordings). The camera looks along the drone's heading, pitched down; the LiDAR sits 5 cm
//! above the camera with the same view direction.

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;

use crate::SimError;
use crate::world::World;

/// Where random views are taken from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewConfig {
    /// Camera height above the chosen roof, metres.
    pub altitude_range_m: (f64, f64),
    /// Camera pitch below the horizon, degrees (90 looks straight down).
    pub pitch_range_deg: (f64, f64),
    /// The look-at point is the roof centre moved by up to this fraction of the half-size.
    pub target_jitter: f64,
}

impl Default for ViewConfig {
    fn default() -> Self {
        Self {
            altitude_range_m: (10.0, 40.0),
            pitch_range_deg: (50.0, 90.0),
            target_jitter: 0.5,
        }
    }
}

impl ViewConfig {
    pub fn validate(&self) -> Result<(), SimError> {
        let (a, b) = self.altitude_range_m;
        if !(a >= 1.0 && b >= a && b <= 1000.0) {
            return Err(SimError::invalid(
                "altitude_range_m",
                format!("{a}..{b}"),
                "need 1 <= min <= max <= 1000",
            ));
        }
        let (p, q) = self.pitch_range_deg;
        if !(p >= 10.0 && q >= p && q <= 90.0) {
            return Err(SimError::invalid(
                "pitch_range_deg",
                format!("{p}..{q}"),
                "need 10 <= min <= max <= 90",
            ));
        }
        if !(0.0..=1.0).contains(&self.target_jitter) {
            return Err(SimError::invalid(
                "target_jitter",
                self.target_jitter,
                "must be in 0..=1",
            ));
        }
        Ok(())
    }
}

/// One view: the camera pose and how it was chosen.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Index of the roof looked at.
    pub building: usize,
    /// T_world_camera, optical convention.
    pub camera: Isometry3<f64>,
    pub altitude_m: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
}

/// The camera pose (optical: x right, y down, z forward) at `position`, heading `yaw` (radians,
/// counter-clockwise from +x) and pitched `pitch_down` radians below the horizon.
pub fn camera_pose(position: [f64; 3], yaw: f64, pitch_down: f64) -> Isometry3<f64> {
    let (sy, cy) = yaw.sin_cos();
    let (sp, cp) = pitch_down.sin_cos();
    let forward = Vector3::new(cy * cp, sy * cp, -sp);
    let right = Vector3::new(sy, -cy, 0.0);
    let down = forward.cross(&right);
    let m = Matrix3::from_columns(&[right, down, forward]);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    Isometry3::from_parts(
        Translation3::new(position[0], position[1], position[2]),
        rot,
    )
}

/// T_camera_lidar: LiDAR frame x forward, y left, z up, 5 cm above the camera.
pub fn camera_to_lidar() -> Isometry3<f64> {
    let m = Matrix3::from_columns(&[
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(-1.0, 0.0, 0.0),
        Vector3::new(0.0, -1.0, 0.0),
    ]);
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
    Isometry3::from_parts(Translation3::new(0.0, -0.05, 0.0), rot)
}

/// T_world_lidar for a camera at `camera` (T_world_camera).
pub fn lidar_pose(camera: &Isometry3<f64>) -> Isometry3<f64> {
    camera * camera_to_lidar()
}

/// A view of building `building` with a random height, pitch, heading and aim.
pub fn view_of<R: Rng + ?Sized>(
    world: &World,
    building: usize,
    config: &ViewConfig,
    rng: &mut R,
) -> View {
    let b = &world.buildings[building];
    let c = b.center();
    let s = b.size();
    let j = config.target_jitter;
    let tx = c[0] + rng.random_range(-1.0..=1.0) * j * s[0] / 2.0;
    let ty = c[1] + rng.random_range(-1.0..=1.0) * j * s[1] / 2.0;
    let (a0, a1) = config.altitude_range_m;
    let altitude = if a1 > a0 {
        rng.random_range(a0..a1)
    } else {
        a0
    };
    let (p0, p1) = config.pitch_range_deg;
    let pitch_deg = if p1 > p0 {
        rng.random_range(p0..p1)
    } else {
        p0
    };
    let yaw = rng.random_range(0.0..std::f64::consts::TAU);
    let pitch = pitch_deg.to_radians();
    let back = altitude / pitch.tan().max(1e-9);
    let position = [
        tx - back * yaw.cos(),
        ty - back * yaw.sin(),
        b.height_m + altitude,
    ];
    View {
        building,
        camera: camera_pose(position, yaw, pitch),
        altitude_m: altitude,
        pitch_deg,
        yaw_deg: yaw.to_degrees(),
    }
}

/// A random view of a random building.
pub fn random_view<R: Rng + ?Sized>(world: &World, config: &ViewConfig, rng: &mut R) -> View {
    let building = rng.random_range(0..world.buildings.len().max(1));
    view_of(world, building, config, rng)
}

/// An approach flight: the drone descends towards a roof while flying in, the camera pitching
/// from `pitch_range_deg.0` to `.1` and staying aimed near the roof centre.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlightConfig {
    /// Number of frames.
    pub frames: u32,
    /// Frame rate, Hz (the LiDAR's 10 Hz).
    pub rate_hz: f64,
    /// Height above the roof at the first and last frame, metres.
    pub altitude_m: (f64, f64),
    /// Pitch below the horizon at the first and last frame, degrees.
    pub pitch_deg: (f64, f64),
}

impl Default for FlightConfig {
    fn default() -> Self {
        Self {
            frames: 20,
            rate_hz: 10.0,
            altitude_m: (40.0, 10.0),
            pitch_deg: (50.0, 85.0),
        }
    }
}

/// Camera poses of an approach to `building`, one per frame. The heading is drawn at random;
/// where the path at that heading would enter another building or lose sight of the roof
/// behind one (a drone flies around a tower, not through it), the next of [`HEADING_TRIES`]
/// headings a golden angle apart is taken. The random draws are the same either way, so every
/// approach whose drawn heading is clear is as it was.
pub fn approach<R: Rng + ?Sized>(
    world: &World,
    building: usize,
    config: &FlightConfig,
    rng: &mut R,
) -> Vec<View> {
    let b = &world.buildings[building];
    let c = b.center();
    let s = b.size();
    let drawn = rng.random_range(0.0..std::f64::consts::TAU);
    let aim = [
        c[0] + rng.random_range(-0.2..0.2) * s[0],
        c[1] + rng.random_range(-0.2..0.2) * s[1],
    ];
    let n = config.frames.max(1);
    let frames = |yaw: f64| {
        (0..n).map(move |i| {
            let f = if n > 1 {
                f64::from(i) / f64::from(n - 1)
            } else {
                0.0
            };
            let altitude = config.altitude_m.0 + (config.altitude_m.1 - config.altitude_m.0) * f;
            let pitch_deg = config.pitch_deg.0 + (config.pitch_deg.1 - config.pitch_deg.0) * f;
            let back = altitude / pitch_deg.to_radians().tan().max(1e-9);
            let position = [
                aim[0] - back * yaw.cos(),
                aim[1] - back * yaw.sin(),
                b.height_m + altitude,
            ];
            (position, altitude, pitch_deg)
        })
    };
    let target = [aim[0], aim[1], b.height_m];
    let clear = |yaw: f64| {
        frames(yaw).all(|(position, ..)| {
            world.buildings.iter().enumerate().all(|(j, other)| {
                j == building
                    || !(other.contains_within(position, FLIGHT_CLEARANCE_M)
                        || other.blocks(position, target))
            })
        })
    };
    let yaw = (0..HEADING_TRIES)
        .map(|k| (drawn + f64::from(k) * GOLDEN_ANGLE).rem_euclid(std::f64::consts::TAU))
        .find(|&yaw| clear(yaw))
        .unwrap_or(drawn);
    frames(yaw)
        .map(|(position, altitude, pitch_deg)| View {
            building,
            camera: camera_pose(position, yaw, pitch_deg.to_radians()),
            altitude_m: altitude,
            pitch_deg,
            yaw_deg: yaw.to_degrees(),
        })
        .collect()
}

/// Headings [`approach`] tries before it keeps the drawn one.
pub const HEADING_TRIES: u32 = 64;

/// π (3 − √5): consecutive headings this far apart spread evenly around the roof.
const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;

/// How far an approach keeps from other buildings' walls and roofs, metres.
const FLIGHT_CLEARANCE_M: f64 = 2.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// A 20 m roof walled in by 80 m towers on three sides: every approach comes in over the
    /// open side, whatever heading was drawn; walled in on all four, it keeps the drawn one.
    #[test]
    fn approaches_fly_around_other_buildings() {
        use crate::world::{Building, WorldConfig};
        use rand::SeedableRng;
        let block = |min: [f64; 2], max: [f64; 2], height_m: f64| Building {
            min,
            max,
            height_m,
            parapet_height_m: 0.0,
            parapet_thickness_m: 0.0,
            assets: Vec::new(),
        };
        let mut world = World::generate(1, &WorldConfig::default()).unwrap();
        world.buildings = vec![
            block([0.0, 0.0], [20.0, 20.0], 10.0),
            block([-80.0, -80.0], [-5.0, 100.0], 80.0),
            block([-80.0, -80.0], [100.0, -5.0], 80.0),
            block([25.0, -80.0], [100.0, 100.0], 80.0),
        ];
        let config = FlightConfig {
            frames: 41,
            ..FlightConfig::default()
        };
        for seed in 0..20 {
            let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
            let views = approach(&world, 0, &config, &mut rng);
            assert_eq!(views.len(), 41);
            let start = views[0].camera.translation.vector;
            assert!(
                start.y > 20.0,
                "seed {seed}: the approach starts at {start:?}"
            );
            for v in &views {
                let p = v.camera.translation.vector;
                assert!(
                    v.yaw_deg.to_radians().sin() < 0.0,
                    "seed {seed}: not flying south"
                );
                for other in &world.buildings[1..] {
                    assert!(!other.contains_within([p.x, p.y, p.z], FLIGHT_CLEARANCE_M));
                }
            }
        }
        world
            .buildings
            .push(block([-80.0, 25.0], [100.0, 100.0], 80.0));
        let mut rng = rand::rngs::SmallRng::seed_from_u64(0);
        assert_eq!(approach(&world, 0, &config, &mut rng).len(), 41);
    }

    #[test]
    fn nadir_camera_looks_down_with_x_right_of_heading() {
        let pose = camera_pose([0.0, 0.0, 10.0], 0.0, std::f64::consts::FRAC_PI_2);
        let fwd = pose.rotation * Vector3::z();
        assert!((fwd - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-9);
        let right = pose.rotation * Vector3::x();
        assert!((right - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-9);
        let down = pose.rotation * Vector3::y();
        // Image "down" is the heading's backwards direction at nadir.
        assert!((down - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-9);
    }

    #[test]
    fn lidar_x_axis_is_camera_forward() {
        let cam = camera_pose([1.0, 2.0, 30.0], 0.7, 1.0);
        let lidar = lidar_pose(&cam);
        let a = lidar.rotation * Vector3::x();
        let b = cam.rotation * Vector3::z();
        assert!((a - b).norm() < 1e-9);
        let up = lidar.rotation * Vector3::z();
        assert!((up + cam.rotation * Vector3::y()).norm() < 1e-9);
    }
}
