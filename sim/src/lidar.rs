//! The 16-beam LiDAR: a 40° × 60° window of a spinning scanner at 10 Hz and 100,000 points/s,
//! i.e. 16 beams × 104 azimuth steps ≈ 1,660 points per scan, with range noise and dropout.
//!
//! The LiDAR frame is x forward, y left, z up. Every point carries the class of the surface it
//! hit (the same class the camera's label image shows there).

use nalgebra::{Isometry3, Point3};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};

use crate::SimError;
use crate::camera::{albedo_at, class_of_hit};
use crate::math::V3;
use crate::scene::{NO_PRIM, Ray};
use crate::world::World;

/// Scanner parameters. `Default` is the paper's sensor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarConfig {
    pub beams: u32,
    pub vertical_fov_deg: f64,
    pub horizontal_fov_deg: f64,
    pub rate_hz: f64,
    pub points_per_second: f64,
    /// Returns beyond this are lost, metres.
    pub max_range_m: f64,
    /// Standard deviation of the range noise, metres.
    pub range_noise_m: f64,
    /// Probability that a return is lost.
    pub dropout: f64,
}

impl Default for LidarConfig {
    fn default() -> Self {
        Self {
            beams: 16,
            vertical_fov_deg: 40.0,
            horizontal_fov_deg: 60.0,
            rate_hz: 10.0,
            points_per_second: 100_000.0,
            max_range_m: 100.0,
            range_noise_m: 0.02,
            dropout: 0.02,
        }
    }
}

impl LidarConfig {
    pub fn validate(&self) -> Result<(), SimError> {
        if !(2..=256).contains(&self.beams) {
            return Err(SimError::invalid("beams", self.beams, "must be in 2..=256"));
        }
        if !(1.0..=180.0).contains(&self.vertical_fov_deg) {
            return Err(SimError::invalid(
                "vertical_fov_deg",
                self.vertical_fov_deg,
                "must be in 1..=180",
            ));
        }
        if !(1.0..=360.0).contains(&self.horizontal_fov_deg) {
            return Err(SimError::invalid(
                "horizontal_fov_deg",
                self.horizontal_fov_deg,
                "must be in 1..=360",
            ));
        }
        if !(self.rate_hz > 0.0 && self.rate_hz <= 100.0) {
            return Err(SimError::invalid(
                "rate_hz",
                self.rate_hz,
                "must be in (0, 100]",
            ));
        }
        if !(self.points_per_second >= 100.0 && self.points_per_second <= 1e8) {
            return Err(SimError::invalid(
                "points_per_second",
                self.points_per_second,
                "must be in 100..=1e8",
            ));
        }
        if !(self.max_range_m > 0.0 && self.max_range_m <= 1e4) {
            return Err(SimError::invalid(
                "max_range_m",
                self.max_range_m,
                "must be in (0, 1e4]",
            ));
        }
        if !(0.0..=1.0).contains(&self.range_noise_m) {
            return Err(SimError::invalid(
                "range_noise_m",
                self.range_noise_m,
                "must be in 0..=1",
            ));
        }
        if !(0.0..1.0).contains(&self.dropout) {
            return Err(SimError::invalid(
                "dropout",
                self.dropout,
                "must be in [0, 1)",
            ));
        }
        Ok(())
    }

    /// Azimuth steps across the horizontal field of view.
    pub fn columns(&self) -> u32 {
        let per_rev = self.points_per_second / self.rate_hz / f64::from(self.beams);
        ((per_rev * self.horizontal_fov_deg / 360.0).round() as u32).max(2)
    }
}

/// One return.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LidarPoint {
    /// Position in the LiDAR frame, metres.
    pub local: [f32; 3],
    /// Position in the world (the exact pose applied to `local`), metres.
    pub world: [f64; 3],
    /// Reflectance-like intensity in `[0, 1]`.
    pub intensity: f32,
    /// [`landing_geometry::SemanticClass`] id of the surface hit.
    pub class: u8,
    /// Building hit (or whose rooftop asset was hit), `u32::MAX` for the ground.
    pub building: u32,
    /// Asset hit, `u32::MAX` if none.
    pub asset: u32,
}

/// Scans from `pose` (T_world_lidar). `seed` drives noise and dropout.
pub fn scan(
    world: &World,
    pose: &Isometry3<f64>,
    config: &LidarConfig,
    seed: u64,
) -> Result<Vec<LidarPoint>, SimError> {
    config.validate()?;
    let mut rng = SmallRng::seed_from_u64(seed ^ 0x6c69_6461_7200_0000);
    let noise = Normal::new(0.0, config.range_noise_m).map_err(|_| {
        SimError::invalid(
            "range_noise_m",
            config.range_noise_m,
            "must be finite and >= 0",
        )
    })?;
    let cols = config.columns();
    let t = pose.translation.vector;
    let origin = V3::new(t.x as f32, t.y as f32, t.z as f32);
    let mut out = Vec::with_capacity((cols * config.beams) as usize);
    for b in 0..config.beams {
        let el = (-config.vertical_fov_deg / 2.0
            + config.vertical_fov_deg * f64::from(b) / f64::from(config.beams - 1))
        .to_radians();
        for c in 0..cols {
            let az = (config.horizontal_fov_deg / 2.0
                - config.horizontal_fov_deg * f64::from(c) / f64::from(cols - 1))
            .to_radians();
            let local_dir =
                nalgebra::Vector3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
            let wd = pose.rotation * local_dir;
            let ray = Ray::new(origin, V3::new(wd.x as f32, wd.y as f32, wd.z as f32));
            let n: f64 = noise.sample(&mut rng);
            let lost = rng.random_bool(config.dropout);
            let Some(hit) = world.bvh.intersect(&ray, config.max_range_m as f32) else {
                continue;
            };
            if lost {
                continue;
            }
            let range = (f64::from(hit.t) + n).max(0.01);
            let lp = local_dir * range;
            let wp = pose * Point3::from(lp);
            let albedo = albedo_at(world, &ray, &hit);
            let cos_inc = hit.normal.dot(-ray.d).abs();
            let intensity =
                ((albedo[0] + albedo[1] + albedo[2]) / 3.0 * (0.3 + 0.7 * cos_inc)).clamp(0.0, 1.0);
            let (building, asset) = if hit.prim == NO_PRIM {
                (u32::MAX, u32::MAX)
            } else {
                let p = &world.prims()[hit.prim as usize];
                (p.building, p.asset)
            };
            out.push(LidarPoint {
                local: [lp.x as f32, lp.y as f32, lp.z as f32],
                world: [wp.x, wp.y, wp.z],
                intensity,
                class: class_of_hit(world, &hit),
                building,
                asset,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_sensor_gives_about_1660_points_in_view() {
        let c = LidarConfig::default();
        assert_eq!(c.columns(), 104);
        assert_eq!(c.columns() * c.beams, 1664);
    }
}
