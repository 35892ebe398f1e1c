//! Overlay pictures like the paper's Fig. 4: the LiDAR points projected into the camera image,
//! each landing polygon in green with its holes (obstacles) in orange, the safe circle in blue
//! and a star at its centre; next to it the same from above.

use image::{Rgb, RgbImage};
use landing_proto::v1::{Frame, FrameResult, LandingSite, LinearRing, camera_image};

use landing_client::{ClientError, RigidTransform, unpack_point_cloud};

/// Fill colour of landing polygons.
pub const POLYGON_GREEN: Rgb<u8> = Rgb([40, 220, 60]);
/// Fill colour of holes.
pub const HOLE_ORANGE: Rgb<u8> = Rgb([255, 140, 0]);
/// Colour of the safe circle.
pub const CIRCLE_BLUE: Rgb<u8> = Rgb([30, 90, 255]);
/// Colour of the star at the centre.
pub const STAR_YELLOW: Rgb<u8> = Rgb([255, 235, 0]);

/// How to draw.
#[derive(Debug, Clone)]
pub struct RenderConfig {
    /// Side of the square top-down panel, pixels (the camera panel keeps the image size).
    pub top_down_px: u32,
    /// Opacity of the polygon fills.
    pub fill_alpha: f32,
    /// Draw only this many best sites.
    pub max_sites: usize,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            top_down_px: 480,
            fill_alpha: 0.45,
            max_sites: 3,
        }
    }
}

/// The picture and where each panel is, so callers (and tests) can find a world point in it.
#[derive(Debug, Clone)]
pub struct Rendered {
    /// Camera panel (when the frame has an image) on the left, top-down panel on the right.
    pub image: RgbImage,
    camera: Option<CameraView>,
    top: TopView,
}

impl Rendered {
    /// Pixel of a world point in the camera panel, if it is in front of the camera and in frame.
    pub fn camera_pixel(&self, world: [f64; 3]) -> Option<(u32, u32)> {
        let c = self.camera.as_ref()?;
        let (u, v) = c.project(world)?;
        (u >= 0.0 && v >= 0.0 && u < c.width as f64 && v < c.height as f64)
            .then_some((u as u32, v as u32))
    }

    /// Pixel of a world point in the top-down panel, if inside it.
    pub fn top_down_pixel(&self, world: [f64; 3]) -> Option<(u32, u32)> {
        let (u, v) = self.top.project(world);
        let (u, v) = (u - self.top.offset_x as f64, v);
        (u >= 0.0 && v >= 0.0 && u < self.top.size as f64 && v < self.top.size as f64)
            .then_some(((u + self.top.offset_x as f64) as u32, v as u32))
    }
}

#[derive(Debug, Clone)]
struct CameraView {
    camera_from_world: RigidTransform,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    width: u32,
    height: u32,
}

impl CameraView {
    fn project(&self, world: [f64; 3]) -> Option<(f64, f64)> {
        let p = self.camera_from_world.apply(world);
        (p[2] > 0.05).then(|| {
            (
                self.fx * p[0] / p[2] + self.cx,
                self.fy * p[1] / p[2] + self.cy,
            )
        })
    }
}

#[derive(Debug, Clone)]
struct TopView {
    offset_x: u32,
    size: u32,
    min: [f64; 2],
    scale: f64,
}

impl TopView {
    fn project(&self, world: [f64; 3]) -> (f64, f64) {
        let u = (world[0] - self.min[0]) * self.scale + self.offset_x as f64;
        let v = self.size as f64 - (world[1] - self.min[1]) * self.scale;
        (u, v)
    }
}

/// Maps a world point to canvas pixels, or `None` when it is not visible in that panel.
type Projector<'a> = &'a dyn Fn([f64; 3]) -> Option<(f64, f64)>;

/// Draws `result` over `frame`.
pub fn render(
    frame: &Frame,
    result: &FrameResult,
    config: &RenderConfig,
) -> Result<Rendered, ClientError> {
    let cloud = frame
        .point_cloud
        .as_ref()
        .ok_or(ClientError::InvalidInput {
            field: "frame.point_cloud",
            reason: "missing".into(),
        })?;
    let unpacked = unpack_point_cloud(cloud)?;
    let world = unpacked.to_world(cloud.pose.as_ref());
    let sites: Vec<_> = result.sites.iter().take(config.max_sites).collect();

    let (background, camera) = match frame.image.as_ref() {
        Some(img) => {
            let (pixels, view) = camera_panel(img, config.top_down_px)?;
            (Some(pixels), Some(view))
        }
        None => (None, None),
    };
    let cam_w = background.as_ref().map_or(0, |b| b.width());
    let height = background
        .as_ref()
        .map_or(config.top_down_px, |b| b.height().max(config.top_down_px));
    let mut canvas = RgbImage::from_pixel(cam_w + config.top_down_px, height, Rgb([25, 25, 30]));
    if let Some(bg) = &background {
        image::imageops::replace(&mut canvas, bg, 0, 0);
    }
    let top = top_view(&sites, &world, cam_w, config.top_down_px);

    draw_points(&mut canvas, &world, camera.as_ref(), &top, cam_w);
    // Sites, worst first so the best is drawn on top.
    for site in sites.iter().rev() {
        let Some(shape) = SiteShape::of(site) else {
            continue;
        };
        let panels: [(Projector<'_>, u32, u32); 2] = [
            (&|w| camera.as_ref().and_then(|c| c.project(w)), 0, cam_w),
            (&|w| Some(top.project(w)), cam_w, cam_w + top.size),
        ];
        for (project, x_lo, x_hi) in panels {
            if x_hi == x_lo {
                continue;
            }
            shape.draw(&mut canvas, project, config.fill_alpha, x_lo, x_hi);
        }
    }
    Ok(Rendered {
        image: canvas,
        camera,
        top,
    })
}

/// The camera image for the left panel and how world points project into it.
fn camera_panel(
    img: &landing_proto::v1::CameraImage,
    top_down_px: u32,
) -> Result<(RgbImage, CameraView), ClientError> {
    let mut pixels = decode_camera_image(img)?;
    // Small sensor images are enlarged by a whole factor to the panel height, so that
    // both panels are about the same size; the intrinsics scale with them.
    let k = (top_down_px / pixels.height().max(1)).max(1);
    if k > 1 {
        pixels = image::imageops::resize(
            &pixels,
            pixels.width() * k,
            pixels.height() * k,
            image::imageops::FilterType::Nearest,
        );
    }
    let calib = img.calibration.unwrap_or_default();
    let pose = img.pose.unwrap_or_default();
    let k = k as f64;
    let view = CameraView {
        camera_from_world: RigidTransform::from_pose(&pose).inverse(),
        fx: calib.fx * k,
        fy: calib.fy * k,
        // Pixel i covers [i, i + 1), as where points are drawn, so the scale is plain.
        cx: calib.cx * k,
        cy: calib.cy * k,
        width: pixels.width(),
        height: pixels.height(),
    };
    Ok((pixels, view))
}

/// The top-down panel, `size` pixels square at column `offset_x`. It frames the sites and the
/// points near them, so a far-away ground return does not shrink the roof to a few pixels.
fn top_view(sites: &[&LandingSite], world: &[[f64; 3]], offset_x: u32, size: u32) -> TopView {
    let mut xs: Vec<f64> = Vec::new();
    let mut ys: Vec<f64> = Vec::new();
    for s in sites {
        if let Some(shell) = s.polygon.as_ref().and_then(|p| p.shell.as_ref()) {
            xs.extend(shell.points.iter().map(|p| p.x));
            ys.extend(shell.points.iter().map(|p| p.y));
        }
    }
    if xs.is_empty() {
        (xs, ys) = central_extent(world);
    }
    let (x0, x1) = min_max(&xs);
    let (y0, y1) = min_max(&ys);
    let span = (x1 - x0).max(y1 - y0).max(4.0) * 1.25;
    let centre = [(x0 + x1) / 2.0, (y0 + y1) / 2.0];
    TopView {
        offset_x,
        size,
        min: [centre[0] - span / 2.0, centre[1] - span / 2.0],
        scale: size as f64 / span,
    }
}

/// The 2nd and 98th percentiles of the points' x and y (a 20 m square at the origin without
/// points), for a frame without sites.
fn central_extent(world: &[[f64; 3]]) -> (Vec<f64>, Vec<f64>) {
    let mut px: Vec<f64> = world.iter().map(|p| p[0]).collect();
    let mut py: Vec<f64> = world.iter().map(|p| p[1]).collect();
    px.sort_by(f64::total_cmp);
    py.sort_by(f64::total_cmp);
    if px.is_empty() {
        return (vec![-10.0, 10.0], vec![-10.0, 10.0]);
    }
    let q = |v: &[f64], f: f64| v[((v.len() - 1) as f64 * f) as usize];
    (
        vec![q(&px, 0.02), q(&px, 0.98)],
        vec![q(&py, 0.02), q(&py, 0.98)],
    )
}

/// The points as height-coloured dots in both panels.
fn draw_points(
    canvas: &mut RgbImage,
    world: &[[f64; 3]],
    camera: Option<&CameraView>,
    top: &TopView,
    cam_w: u32,
) {
    let (z0, z1) = min_max(&world.iter().map(|p| p[2]).collect::<Vec<_>>());
    for p in world {
        let t = if z1 > z0 {
            ((p[2] - z0) / (z1 - z0)) as f32
        } else {
            0.5
        };
        let c = height_colour(t);
        if let Some(cam) = camera
            && let Some((u, v)) = cam.project(*p)
        {
            put(canvas, u, v, c, 0, cam_w);
        }
        let (u, v) = top.project(*p);
        put_panel(canvas, u, v, c, cam_w, cam_w + top.size);
    }
}

/// A landing site in world coordinates: its polygon, safe circle and centre.
struct SiteShape {
    shell: Vec<[f64; 3]>,
    holes: Vec<Vec<[f64; 3]>>,
    circle: Vec<[f64; 3]>,
    centre: [f64; 3],
}

impl SiteShape {
    /// The shape of `site`, or `None` when it has no polygon.
    fn of(site: &LandingSite) -> Option<Self> {
        let poly = site.polygon.as_ref()?;
        let ring3 = |r: &LinearRing| -> Vec<[f64; 3]> {
            r.points.iter().map(|p| [p.x, p.y, p.z]).collect()
        };
        let centre = site.center.map(|c| [c.x, c.y, c.z]).unwrap_or([0.0; 3]);
        let circle = (0..72)
            .map(|k| {
                let a = k as f64 / 72.0 * std::f64::consts::TAU;
                [
                    centre[0] + site.safe_radius_m * a.cos(),
                    centre[1] + site.safe_radius_m * a.sin(),
                    centre[2],
                ]
            })
            .collect();
        Some(Self {
            shell: poly.shell.as_ref().map(ring3).unwrap_or_default(),
            holes: poly.holes.iter().map(ring3).collect(),
            circle,
            centre,
        })
    }

    /// Draws the shape into the panel at columns `x_lo..x_hi`: the polygon filled green, its
    /// holes orange, the circle outlined blue and a star at the centre. A ring with a point the
    /// panel cannot show is left out.
    fn draw(
        &self,
        canvas: &mut RgbImage,
        project: Projector<'_>,
        alpha: f32,
        x_lo: u32,
        x_hi: u32,
    ) {
        let proj = |ring: &[[f64; 3]]| -> Option<Vec<(f64, f64)>> {
            ring.iter().map(|p| project(*p)).collect()
        };
        if let Some(s) = proj(&self.shell) {
            filled_ring(canvas, s, POLYGON_GREEN, alpha, x_lo, x_hi);
        }
        for h in &self.holes {
            if let Some(h) = proj(h) {
                filled_ring(canvas, h, HOLE_ORANGE, 0.8, x_lo, x_hi);
            }
        }
        if let Some(c) = proj(&self.circle) {
            polyline(canvas, &c, true, CIRCLE_BLUE, x_lo, x_hi);
        }
        if let Some((u, v)) = project(self.centre) {
            star(canvas, u, v, 9.0, x_lo, x_hi);
        }
    }
}

/// One ring filled with `c` at opacity `alpha` and outlined in `c`.
fn filled_ring(
    canvas: &mut RgbImage,
    ring: Vec<(f64, f64)>,
    c: Rgb<u8>,
    alpha: f32,
    x_lo: u32,
    x_hi: u32,
) {
    let rings = [ring];
    fill_polygon(canvas, &rings, c, alpha, x_lo, x_hi);
    polyline(canvas, &rings[0], true, c, x_lo, x_hi);
}

/// Decodes the frame's camera image to RGB8.
pub fn decode_camera_image(img: &landing_proto::v1::CameraImage) -> Result<RgbImage, ClientError> {
    let err = |reason: String| ClientError::Image {
        what: "frame.image",
        reason,
    };
    match img.image.as_ref() {
        Some(camera_image::Image::Compressed(c)) => {
            let format = match c.format.as_str() {
                "png" => image::ImageFormat::Png,
                "jpeg" | "jpg" => image::ImageFormat::Jpeg,
                other => return Err(err(format!("unsupported format `{other}`"))),
            };
            Ok(image::load_from_memory_with_format(&c.data, format)
                .map_err(|e| err(e.to_string()))?
                .to_rgb8())
        }
        Some(camera_image::Image::Raw(r)) => {
            let (w, h, step) = (r.width as usize, r.height as usize, r.step as usize);
            if r.encoding != "rgb8" || step < w * 3 || r.data.len() < step * h {
                return Err(err(format!(
                    "raw image {}x{} `{}` step {step} with {} bytes",
                    w,
                    h,
                    r.encoding,
                    r.data.len()
                )));
            }
            let mut data = Vec::with_capacity(w * h * 3);
            for row in r.data.chunks(step).take(h) {
                data.extend_from_slice(&row[..w * 3]);
            }
            RgbImage::from_raw(r.width, r.height, data).ok_or_else(|| err("bad raw image".into()))
        }
        None => Err(err("no pixels".into())),
    }
}

fn min_max(v: &[f64]) -> (f64, f64) {
    v.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        })
}

/// A blue-to-red ramp for point heights, kept free of green so points never read as a polygon.
fn height_colour(t: f32) -> Rgb<u8> {
    let t = t.clamp(0.0, 1.0);
    Rgb([
        (60.0 + 195.0 * t) as u8,
        60,
        (60.0 + 195.0 * (1.0 - t)) as u8,
    ])
}

fn put(img: &mut RgbImage, u: f64, v: f64, c: Rgb<u8>, x_lo: u32, x_hi: u32) {
    if u.is_finite() && v.is_finite() && u >= 0.0 && v >= 0.0 {
        let (x, y) = (u as u32 + x_lo, v as u32);
        if x < x_hi && y < img.height() {
            img.put_pixel(x, y, c);
        }
    }
}

/// Like [`put`] but `u` is already in canvas coordinates.
fn put_panel(img: &mut RgbImage, u: f64, v: f64, c: Rgb<u8>, x_lo: u32, x_hi: u32) {
    if u.is_finite() && v.is_finite() && u >= x_lo as f64 && v >= 0.0 {
        let (x, y) = (u as u32, v as u32);
        if x < x_hi && y < img.height() {
            img.put_pixel(x, y, c);
        }
    }
}

fn blend(img: &mut RgbImage, x: u32, y: u32, c: Rgb<u8>, alpha: f32) {
    let p = img.get_pixel_mut(x, y);
    for k in 0..3 {
        p.0[k] = (p.0[k] as f32 * (1.0 - alpha) + c.0[k] as f32 * alpha).round() as u8;
    }
}

/// Even-odd scanline fill of rings in canvas coordinates, clipped to columns `x_lo..x_hi`.
/// Camera-panel rings come in panel coordinates, which equal canvas ones since that panel is at 0.
fn fill_polygon(
    img: &mut RgbImage,
    rings: &[Vec<(f64, f64)>],
    c: Rgb<u8>,
    alpha: f32,
    x_lo: u32,
    x_hi: u32,
) {
    let ys = rings.iter().flatten().map(|p| p.1);
    let (y0, y1) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
        (a.min(y), b.max(y))
    });
    if !y0.is_finite() || !y1.is_finite() {
        return;
    }
    let row_lo = y0.floor().max(0.0) as u32;
    let row_hi = (y1.ceil().max(0.0) as u32).min(img.height());
    let mut xs = Vec::new();
    for row in row_lo..row_hi {
        let yc = row as f64 + 0.5;
        xs.clear();
        for ring in rings {
            for i in 0..ring.len() {
                let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                if (a.1 <= yc) != (b.1 <= yc) {
                    xs.push(a.0 + (yc - a.1) / (b.1 - a.1) * (b.0 - a.0));
                }
            }
        }
        xs.sort_by(f64::total_cmp);
        for pair in xs.chunks_exact(2) {
            let from = (pair[0].round().max(x_lo as f64)) as u32;
            let to = (pair[1].round().min(x_hi as f64).max(0.0)) as u32;
            for x in from..to.min(img.width()) {
                blend(img, x, row, c, alpha);
            }
        }
    }
}

fn polyline(
    img: &mut RgbImage,
    pts: &[(f64, f64)],
    closed: bool,
    c: Rgb<u8>,
    x_lo: u32,
    x_hi: u32,
) {
    let n = pts.len();
    let segments = if closed { n } else { n.saturating_sub(1) };
    for i in 0..segments {
        let (a, b) = (pts[i], pts[(i + 1) % n]);
        let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil() as usize).clamp(1, 10_000);
        for s in 0..=steps {
            let t = s as f64 / steps as f64;
            let (u, v) = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            for (du, dv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                put_panel(img, u + du - 0.5, v + dv - 0.5, c, x_lo, x_hi);
            }
        }
    }
}

fn star(img: &mut RgbImage, u: f64, v: f64, r: f64, x_lo: u32, x_hi: u32) {
    let pts: Vec<(f64, f64)> = (0..10)
        .map(|k| {
            let a = -std::f64::consts::FRAC_PI_2 + k as f64 * std::f64::consts::PI / 5.0;
            let rr = if k % 2 == 0 { r } else { r * 0.45 };
            (u + rr * a.cos(), v + rr * a.sin())
        })
        .collect();
    fill_polygon(
        img,
        std::slice::from_ref(&pts),
        STAR_YELLOW,
        1.0,
        x_lo,
        x_hi,
    );
    polyline(img, &pts, true, Rgb([0, 0, 0]), x_lo, x_hi);
}

#[cfg(test)]
mod tests {
    use super::*;
    use landing_client::{
        FrameBuilder, ImageData, PointCloudBuilder, camera_image, intrinsics_from_fov, pose,
    };
    use landing_proto::v1::{Polygon, Vector3};

    fn v(x: f64, y: f64, z: f64) -> Vector3 {
        Vector3 { x, y, z }
    }

    /// A 10 m square roof at z = 0 seen straight down from 30 m, with one hole.
    fn scene() -> (Frame, FrameResult) {
        let pts: Vec<[f32; 3]> = (0..400)
            .map(|i| [(i % 20) as f32 - 10.0, (i / 20) as f32 - 10.0, 0.0])
            .collect();
        let cloud = PointCloudBuilder::new(&pts).build().unwrap();
        // Camera at 30 m looking down: optical z = world -z, x = world x, y = world -y.
        let cam_pose = pose([0.0, 0.0, 30.0], [1.0, 0.0, 0.0, 0.0]);
        let calib = intrinsics_from_fov(160, 120, 60.0);
        let img = camera_image(
            ImageData::Rgb8 {
                width: 160,
                height: 120,
                data: vec![128; 160 * 120 * 3],
            },
            cam_pose,
            calib,
        )
        .unwrap();
        let frame = FrameBuilder::new(1, cloud).image(img).build();
        let ring = |pts: &[(f64, f64)]| LinearRing {
            points: pts.iter().map(|p| v(p.0, p.1, 0.0)).collect(),
        };
        let site = LandingSite {
            rank: 1,
            polygon: Some(Polygon {
                shell: Some(ring(&[(-5.0, -5.0), (5.0, -5.0), (5.0, 5.0), (-5.0, 5.0)])),
                holes: vec![ring(&[(2.0, 2.0), (2.0, 4.0), (4.0, 4.0), (4.0, 2.0)])],
                plane_height_m: 0.0,
            }),
            center: Some(v(-1.0, -1.0, 0.0)),
            safe_radius_m: 3.0,
            ..Default::default()
        };
        (
            frame,
            FrameResult {
                sites: vec![site],
                ..Default::default()
            },
        )
    }

    fn greenish(p: Rgb<u8>) -> bool {
        p.0[1] > p.0[0] + 30 && p.0[1] > p.0[2] + 30
    }

    #[test]
    fn polygon_hole_and_star_land_where_the_site_is() {
        let (frame, result) = scene();
        let r = render(&frame, &result, &RenderConfig::default()).unwrap();
        // The 160x120 image is enlarged 4x to the 480-pixel panel height.
        assert_eq!(r.image.width(), 160 * 4 + 480);
        for panel in [Rendered::camera_pixel, Rendered::top_down_pixel] {
            // Inside the shell, away from hole, circle and star: green.
            let (x, y) = panel(&r, [-4.0, 3.5, 0.0]).expect("in view");
            assert!(
                greenish(*r.image.get_pixel(x, y)),
                "{:?}",
                r.image.get_pixel(x, y)
            );
            // Inside the hole: orange.
            let (x, y) = panel(&r, [3.0, 3.0, 0.0]).unwrap();
            let p = r.image.get_pixel(x, y);
            assert!(p.0[0] > 200 && p.0[1] > 100 && p.0[2] < 80, "{p:?}");
            // The centre: the yellow star.
            let (x, y) = panel(&r, [-1.0, -1.0, 0.0]).unwrap();
            assert_eq!(*r.image.get_pixel(x, y), STAR_YELLOW);
            // Outside the shell: not green.
            let (x, y) = panel(&r, [-5.7, 5.7, 0.0]).unwrap();
            assert!(!greenish(*r.image.get_pixel(x, y)));
        }
    }

    #[test]
    fn frames_without_an_image_get_only_the_top_down_panel() {
        let (mut frame, result) = scene();
        frame.image = None;
        let r = render(&frame, &result, &RenderConfig::default()).unwrap();
        assert_eq!(r.image.width(), 480);
        assert!(r.camera_pixel([0.0; 3]).is_none());
        assert!(r.top_down_pixel([-4.0, 3.5, 0.0]).is_some());
    }
}
