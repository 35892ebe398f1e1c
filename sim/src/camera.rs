//! The pinhole RGB camera with per-pixel class labels.
//!
//! Pixel `(col, row)` covers image coordinates `[col, col + 1) × [row, row + 1)` and its ray goes
//! through its centre, so a camera-frame point `(x, y, z)` lands in pixel
//! `(floor(fx x / z + cx), floor(fy y / z + cy))`.

use landing_geometry::SemanticClass;
use nalgebra::Isometry3;

use crate::SimError;
use crate::math::{V3, fbm2, hash3, value_noise};
use crate::scene::{Hit, NO_PRIM, Ray, Texture};
use crate::world::World;

/// Pinhole intrinsics (no distortion).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
}

impl Intrinsics {
    /// Square pixels, principal point at the image centre, the given horizontal field of view.
    pub fn from_hfov(width: u32, height: u32, hfov_deg: f64) -> Result<Self, SimError> {
        if !(16..=8192).contains(&width) {
            return Err(SimError::invalid("width", width, "must be in 16..=8192"));
        }
        if !(16..=8192).contains(&height) {
            return Err(SimError::invalid("height", height, "must be in 16..=8192"));
        }
        if !(10.0..=150.0).contains(&hfov_deg) {
            return Err(SimError::invalid(
                "hfov_deg",
                hfov_deg,
                "must be in 10..=150",
            ));
        }
        let f = f64::from(width) / 2.0 / (hfov_deg.to_radians() / 2.0).tan();
        Ok(Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: f64::from(width) / 2.0,
            cy: f64::from(height) / 2.0,
        })
    }
}

/// Appearance options of the camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraConfig {
    /// Horizontal field of view, degrees.
    pub hfov_deg: f64,
    /// Standard deviation-like amplitude of per-pixel sensor noise, in `[0, 1]` intensity.
    pub noise: f32,
    /// Whether to trace shadow rays towards the sun.
    pub shadows: bool,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            hfov_deg: 70.0,
            noise: 0.025,
            shadows: true,
        }
    }
}

/// One rendered image: RGB8 row-major pixels and a class label per pixel.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    pub width: u32,
    pub height: u32,
    /// `width * height * 3` bytes.
    pub rgb: Vec<u8>,
    /// `width * height` values of [`SemanticClass`].
    pub labels: Vec<u8>,
}

impl Rendered {
    /// The label of pixel (col, row).
    pub fn label(&self, col: u32, row: u32) -> u8 {
        self.labels[(row * self.width + col) as usize]
    }
}

/// Renders the view of a camera at `pose` (T_world_camera, optical convention). `seed` drives
/// the sensor noise and exposure, so a frame is reproducible.
pub fn render(
    world: &World,
    intrinsics: &Intrinsics,
    pose: &Isometry3<f64>,
    config: &CameraConfig,
    seed: u64,
) -> Rendered {
    let (w, h) = (intrinsics.width, intrinsics.height);
    let n = (w * h) as usize;
    let mut rgb = vec![0u8; n * 3];
    let mut labels = vec![0u8; n];
    let r = pose.rotation.to_rotation_matrix();
    let m = r.matrix();
    let col = |j: usize| V3::new(m[(0, j)] as f32, m[(1, j)] as f32, m[(2, j)] as f32);
    let (cx_axis, cy_axis, cz_axis) = (col(0), col(1), col(2));
    let t = pose.translation.vector;
    let origin = V3::new(t.x as f32, t.y as f32, t.z as f32);
    let salt = (seed ^ (seed >> 32)) as u32;
    // Exposure and white balance vary a little per image.
    let exposure = 0.9 + 0.2 * hash3(1, 2, 3, salt);
    let tint = [
        1.0 + 0.06 * (hash3(4, 5, 6, salt) - 0.5),
        1.0,
        1.0 + 0.06 * (hash3(7, 8, 9, salt) - 0.5),
    ];
    let (fx, fy) = (intrinsics.fx as f32, intrinsics.fy as f32);
    let (pcx, pcy) = (intrinsics.cx as f32, intrinsics.cy as f32);
    for row in 0..h {
        let yc = (row as f32 + 0.5 - pcy) / fy;
        for c in 0..w {
            let xc = (c as f32 + 0.5 - pcx) / fx;
            let d = (cx_axis * xc + cy_axis * yc + cz_axis).normalized();
            let ray = Ray::new(origin, d);
            let (color, label) = shade_ray(world, &ray, config.shadows);
            let i = (row * w + c) as usize;
            labels[i] = label;
            let noise = config.noise * (hash3(c as i32, row as i32, 17, salt) - 0.5) * 2.0;
            for k in 0..3 {
                let v = (color[k] * exposure * tint[k]).max(0.0).sqrt() + noise;
                rgb[i * 3 + k] = (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
            }
        }
    }
    Rendered {
        width: w,
        height: h,
        rgb,
        labels,
    }
}

/// The class seen along `ray`, without shading.
pub fn label_along(world: &World, ray: &Ray) -> u8 {
    match world.bvh.intersect(ray, f32::INFINITY) {
        Some(hit) => class_of_hit(world, &hit),
        None => SemanticClass::Sky as u8,
    }
}

/// The class of a hit surface.
pub fn class_of_hit(world: &World, hit: &Hit) -> u8 {
    if hit.prim == NO_PRIM {
        SemanticClass::Ground as u8
    } else {
        world.prims()[hit.prim as usize].class_for_normal(hit.normal)
    }
}

/// The albedo at a hit (linear RGB), also used for LiDAR intensity.
pub fn albedo_at(world: &World, ray: &Ray, hit: &Hit) -> [f32; 3] {
    let p = ray.at(hit.t);
    if hit.prim == NO_PRIM {
        return ground_albedo(world, p.x, p.y);
    }
    let prim = &world.prims()[hit.prim as usize];
    let n = hit.normal;
    let (u, v) = if n.z.abs() > 0.7 {
        (p.x, p.y)
    } else if n.x.abs() > n.y.abs() {
        (p.y, p.z)
    } else {
        (p.x, p.z)
    };
    let top = n.z > 0.7;
    let m = if top {
        prim.material
    } else {
        prim.side_material
    };
    let k = texture(m.texture, u, v, m.salt, n.z.abs() > 0.7);
    [m.albedo[0] * k[0], m.albedo[1] * k[1], m.albedo[2] * k[2]]
}

fn sky(d: V3, sun: V3) -> [f32; 3] {
    let up = d.z.max(0.0);
    let glow = d.dot(sun).max(0.0).powi(32) * 0.6;
    [
        0.80 - 0.45 * up + glow,
        0.84 - 0.30 * up + glow,
        0.90 - 0.05 * up + glow * 0.8,
    ]
}

fn shade_ray(world: &World, ray: &Ray, shadows: bool) -> ([f32; 3], u8) {
    let Some(hit) = world.bvh.intersect(ray, f32::INFINITY) else {
        let s = sky(ray.d, world.sun_dir);
        return (
            [s[0] * s[0], s[1] * s[1], s[2] * s[2]],
            SemanticClass::Sky as u8,
        );
    };
    let label = class_of_hit(world, &hit);
    let albedo = albedo_at(world, ray, &hit);
    let sun = world.sun_dir;
    let mut direct = hit.normal.dot(sun).max(0.0);
    if shadows && direct > 0.0 {
        let p = ray.at(hit.t) + hit.normal * 0.01;
        if world.bvh.occluded(&Ray::new(p, sun), 1.0e4) {
            direct = 0.0;
        }
    }
    let amb = world.ambient;
    // Sky light is bluish, sunlight warm; vertical faces see half the sky.
    let sky_vis = 0.5 + 0.5 * hit.normal.z.max(0.0);
    let light = [
        amb * sky_vis * 0.95 + (1.0 - amb) * direct * 1.05,
        amb * sky_vis * 1.0 + (1.0 - amb) * direct * 1.0,
        amb * sky_vis * 1.1 + (1.0 - amb) * direct * 0.92,
    ];
    let haze = 1.0 - (-hit.t / 900.0).exp();
    let mut c = [0.0; 3];
    for k in 0..3 {
        c[k] = albedo[k] * light[k] * 1.25 * (1.0 - haze) + 0.6 * haze;
    }
    (c, label)
}

fn frac(x: f32) -> f32 {
    x - x.floor()
}

/// Brightness multipliers of a pattern at surface coordinates (u, v).
fn texture(t: Texture, u: f32, v: f32, salt: u32, top: bool) -> [f32; 3] {
    let g = |k: f32| [k, k, k];
    match t {
        Texture::Plain => g(0.85 + 0.3 * fbm2(u * 0.4, v * 0.4, salt)),
        Texture::Gravel => {
            let speck = hash3((u * 8.0).floor() as i32, (v * 8.0).floor() as i32, 0, salt) - 0.5;
            g(0.8 + 0.3 * fbm2(u * 0.3, v * 0.3, salt) + 0.2 * speck)
        }
        Texture::Membrane => {
            let seam = if frac(u / 2.6) < 0.025 { 0.8 } else { 1.0 };
            g(seam * (0.88 + 0.22 * fbm2(u * 0.25, v * 0.25, salt)))
        }
        Texture::Tiles => {
            let grout = frac(u / 1.2) < 0.06 || frac(v / 1.2) < 0.06;
            let tile = hash3((u / 1.2).floor() as i32, (v / 1.2).floor() as i32, 1, salt);
            if grout { g(0.7) } else { g(0.9 + 0.18 * tile) }
        }
        Texture::Brick => {
            if top {
                return g(0.9 + 0.2 * value_noise(u, v, salt));
            }
            let course = (v / 0.25).floor();
            let shift = if course as i32 % 2 == 0 { 0.0 } else { 0.25 };
            let mortar = frac(v / 0.25) < 0.12 || frac((u + shift) / 0.5) < 0.06;
            let b = hash3(((u + shift) / 0.5).floor() as i32, course as i32, 2, salt);
            if mortar { g(1.25) } else { g(0.85 + 0.25 * b) }
        }
        Texture::Windows => {
            if top {
                return g(0.9 + 0.2 * value_noise(u, v, salt));
            }
            let fu = frac(u / 3.0);
            let fv = frac(v / 3.5);
            if (0.2..0.8).contains(&fu) && (0.3..0.8).contains(&fv) {
                let lit = hash3((u / 3.0).floor() as i32, (v / 3.5).floor() as i32, 3, salt);
                [0.35 + 0.2 * lit, 0.42 + 0.2 * lit, 0.55 + 0.2 * lit]
            } else {
                g(0.95 + 0.1 * value_noise(u * 0.5, v * 0.5, salt))
            }
        }
        Texture::Metal => {
            let rib = 0.92 + 0.08 * (u * 40.0).sin();
            g(rib * (0.9 + 0.15 * value_noise(u * 0.8, v * 0.8, salt)))
        }
        Texture::Glass => {
            let mullion = frac(u / 0.7) < 0.08 || frac(v / 0.7) < 0.08;
            if mullion {
                g(1.8)
            } else {
                g(0.8 + 0.4 * value_noise(u * 0.6, v * 0.6, salt))
            }
        }
        Texture::Wood => {
            let plank = hash3((u / 0.16).floor() as i32, 0, 4, salt);
            let line = if frac(u / 0.16) < 0.08 { 0.7 } else { 1.0 };
            g(line * (0.8 + 0.35 * plank))
        }
        Texture::Foliage => {
            let k = value_noise(u * 5.0, v * 5.0, salt);
            [0.6 + 0.9 * k, 0.6 + 0.8 * k, 0.6 + 0.5 * k]
        }
        Texture::Asphalt | Texture::Grass => g(0.85 + 0.3 * fbm2(u, v, salt)),
    }
}

/// Ground albedo: streets with lane markings, sidewalks, and paved or grassy lots.
fn ground_albedo(world: &World, x: f32, y: f32) -> [f32; 3] {
    let period = world.block_period_m() as f32;
    let street = world.config.street_width_m as f32;
    let gx = x.rem_euclid(period);
    let gy = y.rem_euclid(period);
    // Distance into the block from the street edge (negative: in the street).
    let half = street / 2.0;
    let inx = (gx - half).min(period - half - gx);
    let iny = (gy - half).min(period - half - gy);
    let inside = inx.min(iny);
    let salt = world.seed as u32;
    if inside < -3.0 {
        // Roadway; centre lines where the street's centre is.
        let cxd = (gx.min(period - gx)).abs();
        let cyd = (gy.min(period - gy)).abs();
        let in_x_street = inx < -3.0;
        let in_y_street = iny < -3.0;
        let dash_x = in_x_street && !in_y_street && cxd < 0.12 && frac(y / 6.0) < 0.5;
        let dash_y = in_y_street && !in_x_street && cyd < 0.12 && frac(x / 6.0) < 0.5;
        if dash_x || dash_y {
            return [0.8, 0.75, 0.45];
        }
        let k = 0.85 + 0.3 * fbm2(x * 0.7, y * 0.7, salt);
        return [0.16 * k, 0.16 * k, 0.17 * k];
    }
    if inside < 0.0 {
        let tile = if frac(x / 1.5) < 0.05 || frac(y / 1.5) < 0.05 {
            0.8
        } else {
            1.0
        };
        let k = tile * (0.9 + 0.15 * value_noise(x, y, salt));
        return [0.52 * k, 0.51 * k, 0.49 * k];
    }
    let grassy = fbm2(x * 0.05, y * 0.05, salt ^ 99);
    if grassy > 0.55 {
        let k = 0.75 + 0.5 * value_noise(x * 2.0, y * 2.0, salt);
        [0.16 * k, 0.32 * k, 0.11 * k]
    } else {
        let k = 0.85 + 0.3 * fbm2(x * 0.3, y * 0.3, salt);
        [0.38 * k, 0.36 * k, 0.33 * k]
    }
}
