//! Drawings for the viewer, in Foxglove's own schemas: the ground truth and the service's landing
//! sites as `foxglove.SceneUpdate` in [`WORLD_FRAME`], and the sites over the camera image as
//! `foxglove.ImageAnnotations` (what `landing render` draws). They are views of `landing.v1`
//! messages recorded beside them, never read back.

use foxglove::messages as fox;
use landing_proto::v1;

use crate::convert::{WORLD_FRAME, to_fox_time};

/// Fill of a landing polygon (RGB of `landing render`, alpha of its fill).
pub const SITE_GREEN: [f64; 4] = [40.0 / 255.0, 220.0 / 255.0, 60.0 / 255.0, 0.45];
/// Outline and fill of a hole (an obstacle inside a site).
pub const HOLE_ORANGE: [f64; 4] = [1.0, 140.0 / 255.0, 0.0, 0.8];
/// The safe circle.
pub const CIRCLE_BLUE: [f64; 4] = [30.0 / 255.0, 90.0 / 255.0, 1.0, 1.0];
/// The centre (safest point).
pub const CENTRE_YELLOW: [f64; 4] = [1.0, 235.0 / 255.0, 0.0, 1.0];
/// Roof outlines and the true best circle.
pub const TRUTH_WHITE: [f64; 4] = [1.0, 1.0, 1.0, 0.9];

/// Segments of a drawn circle.
const CIRCLE_SEGMENTS: usize = 72;

/// A colour per semantic class (index = `landing.v1.SemanticClass` number), for label previews
/// and obstacle boxes.
pub fn class_color(class: u8) -> [u8; 3] {
    const C: [[u8; 3]; 15] = [
        [0, 0, 0],
        [135, 190, 235],
        [90, 90, 80],
        [170, 80, 60],
        [200, 200, 200],
        [230, 160, 40],
        [60, 140, 230],
        [240, 240, 60],
        [80, 220, 220],
        [200, 80, 200],
        [240, 110, 110],
        [130, 70, 30],
        [120, 0, 0],
        [20, 60, 200],
        [40, 170, 40],
    ];
    C[usize::from(class).min(14)]
}

/// The ground truth of one frame: each roof's outline, its obstacles as boxes coloured by class,
/// and the true best landing circle. It replaces the previous frame's drawing.
pub fn truth_scene(truth: &v1::GroundTruth) -> fox::SceneUpdate {
    let timestamp = truth.timestamp.as_ref().map(to_fox_time);
    let entities = truth
        .roofs
        .iter()
        .map(|roof| {
            let mut e = entity(timestamp, format!("roof-{}", roof.building));
            if let Some(outline) = &roof.outline {
                e.lines
                    .push(line_loop(ring_points(outline), TRUTH_WHITE, 0.08));
            }
            for o in &roof.obstacles {
                if let Some(fp) = &o.footprint {
                    let [r, g, b] = class_color(u8::try_from(o.semantic_class).unwrap_or(0));
                    let colour = [
                        f64::from(r) / 255.0,
                        f64::from(g) / 255.0,
                        f64::from(b) / 255.0,
                        0.7,
                    ];
                    e.cubes
                        .extend(footprint_box(fp, roof.height_m, o.height_m, colour));
                }
            }
            if let Some(best) = &roof.best_landing_point {
                let centre = [best.x, best.y, best.z];
                e.lines.push(line_loop(
                    circle(centre, roof.best_safe_radius_m),
                    TRUTH_WHITE,
                    0.05,
                ));
                e.spheres.push(sphere(centre, 0.4, TRUTH_WHITE));
            }
            e
        })
        .collect();
    fox::SceneUpdate {
        deletions: vec![delete_all(timestamp)],
        entities,
    }
}

/// The landing sites of one answer: each polygon filled (holes left open) and outlined at its
/// plane height, its holes outlined, the safe circle, the centre, and a label with rank and
/// radius. It replaces the previous answer's drawing; an answer without a result clears it.
pub fn sites_scene(response: &v1::StreamLandingSitesResponse) -> fox::SceneUpdate {
    let Some(v1::stream_landing_sites_response::Outcome::Result(result)) = &response.outcome else {
        return fox::SceneUpdate {
            deletions: vec![delete_all(None)],
            entities: Vec::new(),
        };
    };
    let timestamp = result.frame_timestamp.as_ref().map(to_fox_time);
    let entities = result
        .sites
        .iter()
        .map(|site| {
            let mut e = entity(timestamp, format!("site-{}", site.rank));
            let centre = site.center.map_or([0.0; 3], |c| [c.x, c.y, c.z]);
            if let Some(poly) = &site.polygon {
                let shell = poly.shell.as_ref().map(ring_points).unwrap_or_default();
                let holes: Vec<_> = poly.holes.iter().map(ring_points).collect();
                e.triangles.push(fill(&shell, &holes, poly.plane_height_m));
                e.lines.push(line_loop(shell, opaque(SITE_GREEN), 0.06));
                for hole in holes {
                    e.lines.push(line_loop(hole, HOLE_ORANGE, 0.06));
                }
            }
            e.lines.push(line_loop(
                circle(centre, site.safe_radius_m),
                CIRCLE_BLUE,
                0.06,
            ));
            e.spheres.push(sphere(centre, 0.35, CENTRE_YELLOW));
            e.texts.push(fox::TextPrimitive {
                pose: Some(pose_at([centre[0], centre[1], centre[2] + 1.0])),
                billboard: true,
                font_size: 14.0,
                scale_invariant: true,
                color: Some(color(opaque(CENTRE_YELLOW))),
                text: site_label(site),
            });
            e
        })
        .collect();
    fox::SceneUpdate {
        deletions: vec![delete_all(timestamp)],
        entities,
    }
}

/// The landing sites of one answer drawn over the frame's camera image, as `landing render` does:
/// polygons filled green, holes orange, the safe circle blue, the centre yellow with its rank and
/// radius. `None` when the answer has no result or the image no pose or calibration. Shapes that
/// reach behind the camera are left out.
pub fn sites_annotations(
    response: &v1::StreamLandingSitesResponse,
    camera: &v1::CameraImage,
) -> Option<fox::ImageAnnotations> {
    let Some(v1::stream_landing_sites_response::Outcome::Result(result)) = &response.outcome else {
        return None;
    };
    let view = Pinhole::new(camera)?;
    let timestamp = camera.timestamp.as_ref().map(to_fox_time);
    let mut out = fox::ImageAnnotations {
        timestamp,
        ..Default::default()
    };
    let outline = |points: Vec<fox::Point2>, rgba: [f64; 4], filled: bool| fox::PointsAnnotation {
        timestamp,
        r#type: fox::points_annotation::Type::LineLoop as i32,
        points,
        outline_color: Some(color(opaque(rgba))),
        outline_colors: Vec::new(),
        fill_color: filled.then(|| color(rgba)),
        thickness: 2.0,
        metadata: Vec::new(),
    };
    // Worst first, so that the best is drawn on top.
    for site in result.sites.iter().rev() {
        let centre = site.center.map_or([0.0; 3], |c| [c.x, c.y, c.z]);
        if let Some(poly) = &site.polygon {
            if let Some(shell) = poly.shell.as_ref().and_then(|r| view.ring(&ring_points(r))) {
                out.points.push(outline(shell, SITE_GREEN, true));
            }
            for hole in &poly.holes {
                if let Some(hole) = view.ring(&ring_points(hole)) {
                    out.points.push(outline(hole, HOLE_ORANGE, true));
                }
            }
        }
        if let Some(c) = view.ring(&circle(centre, site.safe_radius_m)) {
            out.points.push(outline(c, CIRCLE_BLUE, false));
        }
        if let Some(position) = view.project(centre) {
            out.circles.push(fox::CircleAnnotation {
                timestamp,
                position: Some(position),
                diameter: 9.0,
                thickness: 1.0,
                fill_color: Some(color(CENTRE_YELLOW)),
                outline_color: Some(color([0.0, 0.0, 0.0, 1.0])),
                metadata: Vec::new(),
            });
            out.texts.push(fox::TextAnnotation {
                timestamp,
                position: Some(fox::Point2 {
                    x: position.x + 8.0,
                    y: position.y - 8.0,
                }),
                text: site_label(site),
                font_size: 14.0,
                text_color: Some(color([1.0, 1.0, 1.0, 1.0])),
                background_color: Some(color([0.0, 0.0, 0.0, 0.6])),
                metadata: Vec::new(),
            });
        }
    }
    Some(out)
}

fn site_label(site: &v1::LandingSite) -> String {
    format!("#{}  r = {:.1} m", site.rank, site.safe_radius_m)
}

/// Triangles covering the polygon `shell` minus `holes` (world xy, drawn at height `z`): a
/// constrained Delaunay triangulation of the rings, keeping the triangles inside the shell and
/// outside every hole. Rings that cross are drawn as far as the triangulation allows; nothing
/// here can panic on a malformed polygon.
fn fill(shell: &[[f64; 3]], holes: &[Vec<[f64; 3]>], z: f64) -> fox::TriangleListPrimitive {
    use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};
    let mut cdt = ConstrainedDelaunayTriangulation::<Point2<f64>>::new();
    let rings: Vec<&[[f64; 3]]> = std::iter::once(shell)
        .chain(holes.iter().map(Vec::as_slice))
        .collect();
    for ring in &rings {
        let handles: Vec<_> = ring
            .iter()
            .filter(|p| p[0].is_finite() && p[1].is_finite())
            .filter_map(|p| cdt.insert(Point2::new(p[0], p[1])).ok())
            .collect();
        for (i, &a) in handles.iter().enumerate() {
            let b = handles[(i + 1) % handles.len()];
            if a != b {
                // Refuses (adds nothing) where the edge would cross an earlier one.
                cdt.try_add_constraint(a, b);
            }
        }
    }
    let mut points = Vec::new();
    for face in cdt.inner_faces() {
        let [a, b, c] = face.positions();
        let centroid = [(a.x + b.x + c.x) / 3.0, (a.y + b.y + c.y) / 3.0];
        // Even-odd over all rings: inside the shell and outside the holes.
        let crossings = rings.iter().filter(|r| inside(r, centroid)).count();
        if crossings % 2 == 1 {
            points.extend([a, b, c].map(|p| fox::Point3 { x: p.x, y: p.y, z }));
        }
    }
    fox::TriangleListPrimitive {
        pose: Some(pose_at([0.0; 3])),
        points,
        color: Some(color(SITE_GREEN)),
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

/// Whether `p` is inside `ring` (even-odd rule; a point on the boundary may go either way).
fn inside(ring: &[[f64; 3]], p: [f64; 2]) -> bool {
    let mut inside = false;
    for (i, a) in ring.iter().enumerate() {
        let b = ring[(i + 1) % ring.len()];
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// An obstacle's footprint as a box standing on the roof: oriented along the footprint's first
/// edge, as long and wide as the footprint's extent in that frame.
fn footprint_box(
    footprint: &v1::LinearRing,
    roof_z: f64,
    height_m: f64,
    rgba: [f64; 4],
) -> Option<fox::CubePrimitive> {
    let pts = &footprint.points;
    let (a, b) = (pts.first()?, pts.get(1)?);
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    let len = dx.hypot(dy);
    if len == 0.0 || !len.is_finite() {
        return None;
    }
    let (ux, uy) = (dx / len, dy / len);
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        let s = [
            (p.x - a.x) * ux + (p.y - a.y) * uy,
            -(p.x - a.x) * uy + (p.y - a.y) * ux,
        ];
        for k in 0..2 {
            lo[k] = lo[k].min(s[k]);
            hi[k] = hi[k].max(s[k]);
        }
    }
    let (cs, ct) = ((lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0);
    let yaw = uy.atan2(ux);
    Some(fox::CubePrimitive {
        pose: Some(fox::Pose {
            position: Some(fox::Vector3 {
                x: a.x + cs * ux - ct * uy,
                y: a.y + cs * uy + ct * ux,
                z: roof_z + height_m / 2.0,
            }),
            orientation: Some(fox::Quaternion {
                x: 0.0,
                y: 0.0,
                z: (yaw / 2.0).sin(),
                w: (yaw / 2.0).cos(),
            }),
        }),
        size: Some(fox::Vector3 {
            x: hi[0] - lo[0],
            y: hi[1] - lo[1],
            z: height_m.max(0.05),
        }),
        color: Some(color(rgba)),
    })
}

/// A pinhole camera looking at the world: `landing.v1`'s optical convention (x right, y down,
/// z forward), pixel centres at integer + 0.5 as Foxglove's annotations expect.
struct Pinhole {
    /// `T_world_camera`: rotation (unit quaternion x, y, z, w) and position.
    q: [f64; 4],
    t: [f64; 3],
    k: v1::CameraCalibration,
}

impl Pinhole {
    fn new(camera: &v1::CameraImage) -> Option<Self> {
        let pose = camera.pose.as_ref()?;
        let q = pose.orientation?;
        let n = (q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w).sqrt();
        if n == 0.0 || !n.is_finite() {
            return None;
        }
        let p = pose.position.unwrap_or_default();
        Some(Self {
            q: [q.x / n, q.y / n, q.z / n, q.w / n],
            t: [p.x, p.y, p.z],
            k: camera.calibration?,
        })
    }

    /// The pixel of a world point, if it is in front of the camera.
    fn project(&self, world: [f64; 3]) -> Option<fox::Point2> {
        let d = [
            world[0] - self.t[0],
            world[1] - self.t[1],
            world[2] - self.t[2],
        ];
        // Camera coordinates: the inverse rotation (conjugate quaternion) applied to d.
        let [x, y, z, w] = self.q;
        let c = rotate([-x, -y, -z, w], d);
        (c[2] > 0.05).then(|| fox::Point2 {
            x: self.k.fx * c[0] / c[2] + self.k.cx,
            y: self.k.fy * c[1] / c[2] + self.k.cy,
        })
    }

    /// A whole ring's pixels, or `None` when any point is behind the camera.
    fn ring(&self, ring: &[[f64; 3]]) -> Option<Vec<fox::Point2>> {
        ring.iter().map(|p| self.project(*p)).collect()
    }
}

/// `v` rotated by the unit quaternion `q` (x, y, z, w). The same as
/// `landing_client::RigidTransform::rotate`, which `landing render` projects with; the format
/// cannot call it, since depending on the SDK would put the client into the simulator's tree.
fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [x, y, z, w] = q;
    // t = 2 (q.xyz × v); v' = v + w t + q.xyz × t
    let t = [
        2.0 * (y * v[2] - z * v[1]),
        2.0 * (z * v[0] - x * v[2]),
        2.0 * (x * v[1] - y * v[0]),
    ];
    [
        v[0] + w * t[0] + (y * t[2] - z * t[1]),
        v[1] + w * t[1] + (z * t[0] - x * t[2]),
        v[2] + w * t[2] + (x * t[1] - y * t[0]),
    ]
}

fn ring_points(ring: &v1::LinearRing) -> Vec<[f64; 3]> {
    ring.points.iter().map(|p| [p.x, p.y, p.z]).collect()
}

fn circle(centre: [f64; 3], radius: f64) -> Vec<[f64; 3]> {
    (0..CIRCLE_SEGMENTS)
        .map(|k| {
            let a = k as f64 / CIRCLE_SEGMENTS as f64 * std::f64::consts::TAU;
            [
                centre[0] + radius * a.cos(),
                centre[1] + radius * a.sin(),
                centre[2],
            ]
        })
        .collect()
}

fn entity(timestamp: Option<fox::Timestamp>, id: String) -> fox::SceneEntity {
    fox::SceneEntity {
        timestamp,
        frame_id: WORLD_FRAME.to_string(),
        id,
        ..Default::default()
    }
}

fn delete_all(timestamp: Option<fox::Timestamp>) -> fox::SceneEntityDeletion {
    fox::SceneEntityDeletion {
        timestamp,
        r#type: fox::scene_entity_deletion::Type::All as i32,
        id: String::new(),
    }
}

fn line_loop(points: Vec<[f64; 3]>, rgba: [f64; 4], thickness: f64) -> fox::LinePrimitive {
    fox::LinePrimitive {
        r#type: fox::line_primitive::Type::LineLoop as i32,
        pose: Some(pose_at([0.0; 3])),
        thickness,
        scale_invariant: false,
        points: points
            .into_iter()
            .map(|[x, y, z]| fox::Point3 { x, y, z })
            .collect(),
        color: Some(color(rgba)),
        colors: Vec::new(),
        indices: Vec::new(),
    }
}

fn sphere(centre: [f64; 3], diameter: f64, rgba: [f64; 4]) -> fox::SpherePrimitive {
    fox::SpherePrimitive {
        pose: Some(pose_at(centre)),
        size: Some(fox::Vector3 {
            x: diameter,
            y: diameter,
            z: diameter,
        }),
        color: Some(color(rgba)),
    }
}

fn pose_at([x, y, z]: [f64; 3]) -> fox::Pose {
    fox::Pose {
        position: Some(fox::Vector3 { x, y, z }),
        orientation: Some(fox::Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }),
    }
}

fn opaque([r, g, b, _]: [f64; 4]) -> [f64; 4] {
    [r, g, b, 1.0]
}

fn color([r, g, b, a]: [f64; 4]) -> fox::Color {
    fox::Color { r, g, b, a }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(points: &[[f64; 2]], z: f64) -> v1::LinearRing {
        v1::LinearRing {
            points: points
                .iter()
                .map(|&[x, y]| v1::Vector3 { x, y, z })
                .collect(),
        }
    }

    fn response() -> v1::StreamLandingSitesResponse {
        let z = 20.0;
        let (x0, y0) = (5.0e5, -3.0e5);
        let sq = |lo: f64, hi: f64| {
            ring(
                &[
                    [x0 + lo, y0 + lo],
                    [x0 + hi, y0 + lo],
                    [x0 + hi, y0 + hi],
                    [x0 + lo, y0 + hi],
                ],
                z,
            )
        };
        v1::StreamLandingSitesResponse {
            sequence: 1,
            outcome: Some(v1::stream_landing_sites_response::Outcome::Result(
                v1::FrameResult {
                    sites: vec![v1::LandingSite {
                        rank: 1,
                        polygon: Some(v1::Polygon {
                            shell: Some(sq(0.0, 10.0)),
                            holes: vec![sq(4.0, 6.0)],
                            plane_height_m: z,
                        }),
                        center: Some(v1::Vector3 {
                            x: x0 + 2.0,
                            y: y0 + 2.0,
                            z,
                        }),
                        safe_radius_m: 2.0,
                        ..Default::default()
                    }],
                    ..Default::default()
                },
            )),
        }
    }

    fn triangle_area(t: &[fox::Point3]) -> f64 {
        ((t[1].x - t[0].x) * (t[2].y - t[0].y) - (t[2].x - t[0].x) * (t[1].y - t[0].y)).abs() / 2.0
    }

    #[test]
    fn a_polygon_with_a_hole_is_filled_exactly_around_the_hole() {
        let scene = sites_scene(&response());
        assert_eq!(scene.entities.len(), 1);
        let fill = &scene.entities[0].triangles[0];
        let area: f64 = fill.points.chunks(3).map(triangle_area).sum();
        assert!((area - 96.0).abs() < 1e-6, "filled area {area}");
        assert!(fill.points.iter().all(|p| p.z == 20.0));
        // Shell, hole and safe circle.
        assert_eq!(scene.entities[0].lines.len(), 3);
        assert_eq!(scene.entities[0].texts[0].text, "#1  r = 2.0 m");
    }

    #[test]
    fn an_error_answer_clears_the_sites() {
        let r = v1::StreamLandingSitesResponse {
            sequence: 2,
            outcome: Some(v1::stream_landing_sites_response::Outcome::Error(
                Default::default(),
            )),
        };
        let scene = sites_scene(&r);
        assert!(scene.entities.is_empty());
        assert_eq!(scene.deletions.len(), 1);
    }

    #[test]
    fn crossing_rings_do_not_panic() {
        let bow = ring(&[[0.0, 0.0], [4.0, 4.0], [4.0, 0.0], [0.0, 4.0]], 0.0);
        let t = fill(&ring_points(&bow), &[], 0.0);
        assert_eq!(t.points.len() % 3, 0);
    }

    #[test]
    fn annotations_land_where_the_camera_sees_the_centre() {
        let r = response();
        let v1::stream_landing_sites_response::Outcome::Result(result) =
            r.outcome.as_ref().unwrap()
        else {
            unreachable!()
        };
        let c = result.sites[0].center.unwrap();
        // A camera 30 m above the centre, looking straight down (optical z = world -z): a
        // rotation of 180° about the x axis.
        let camera = v1::CameraImage {
            pose: Some(v1::Pose {
                position: Some(v1::Vector3 {
                    x: c.x,
                    y: c.y,
                    z: c.z + 30.0,
                }),
                orientation: Some(v1::Quaternion {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                    w: 0.0,
                }),
            }),
            calibration: Some(v1::CameraCalibration {
                width: 320,
                height: 240,
                fx: 200.0,
                fy: 200.0,
                cx: 160.0,
                cy: 120.0,
            }),
            ..Default::default()
        };
        let a = sites_annotations(&r, &camera).unwrap();
        let p = a.circles[0].position.unwrap();
        assert!(
            (p.x - 160.0).abs() < 1e-6 && (p.y - 120.0).abs() < 1e-6,
            "{p:?}"
        );
        // Shell, hole (filled) and circle (outline only).
        assert_eq!(a.points.len(), 3);
        assert!(a.points[2].fill_color.is_none());
        // A point 1 m east of the centre is 200/30 px to the right (x right in the image).
        let east = Pinhole::new(&camera)
            .unwrap()
            .project([c.x + 1.0, c.y, c.z])
            .unwrap();
        assert!((east.x - (160.0 + 200.0 / 30.0)).abs() < 1e-6, "{east:?}");
    }

    #[test]
    fn truth_boxes_follow_rotated_footprints() {
        // A 2 m × 1 m footprint rotated by 30°.
        let (s, c) = (30f64.to_radians().sin(), 30f64.to_radians().cos());
        let corner = |u: f64, v: f64| [10.0 + u * c - v * s, 20.0 + u * s + v * c];
        let fp = ring(
            &[
                corner(0.0, 0.0),
                corner(2.0, 0.0),
                corner(2.0, 1.0),
                corner(0.0, 1.0),
            ],
            15.0,
        );
        let cube = footprint_box(&fp, 15.0, 1.5, [1.0; 4]).unwrap();
        let size = cube.size.unwrap();
        assert!((size.x - 2.0).abs() < 1e-9 && (size.y - 1.0).abs() < 1e-9);
        let p = cube.pose.unwrap().position.unwrap();
        let mid = corner(1.0, 0.5);
        assert!((p.x - mid[0]).abs() < 1e-9 && (p.y - mid[1]).abs() < 1e-9);
        assert!((p.z - 15.75).abs() < 1e-9);
    }
}
