//! Ground truth of a frame: the roofs the LiDAR sees, their obstacles, and on each roof the true
//! best landing point (pole of inaccessibility of the free roof within the scanned area).

use landing_geometry::Polygon;
use landing_geometry::polylabel::{PolylabelParams, polylabel};

use crate::SimError;
use crate::assets::AssetKind;
use crate::lidar::LidarPoint;
use crate::world::{Building, World};

/// Options of [`ground_truth`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruthConfig {
    /// A roof is "in view" with at least this many LiDAR points at its level.
    pub min_points: usize,
    /// Polylabel precision of the best landing point, metres.
    pub polylabel_precision_m: f64,
}

impl Default for TruthConfig {
    fn default() -> Self {
        Self {
            min_points: 20,
            polylabel_precision_m: 0.02,
        }
    }
}

/// An obstacle on a roof.
#[derive(Debug, Clone, PartialEq)]
pub struct ObstacleTruth {
    /// Index into [`World::assets`].
    pub asset: usize,
    pub kind: AssetKind,
    /// Class id of its surfaces.
    pub class: u8,
    /// Footprint rectangle, counter-clockwise.
    pub footprint: Vec<[f64; 2]>,
    pub height_m: f64,
    pub seen_by_lidar: bool,
}

/// One roof in view.
#[derive(Debug, Clone, PartialEq)]
pub struct RoofTruth {
    pub building: usize,
    pub outline: Vec<[f64; 2]>,
    pub height_m: f64,
    pub parapet_height_m: f64,
    pub obstacles: Vec<ObstacleTruth>,
    /// Roof interior ∩ scan coverage, obstacle footprints (clipped to it) as clockwise holes.
    pub landable_region: Polygon,
    /// x, y of the best landing point (z is `height_m`).
    pub best_point: [f64; 2],
    pub best_radius_m: f64,
    pub lidar_points: usize,
}

/// The ground truth of one scan: every roof with enough points at its level, `target` first.
pub fn ground_truth(
    world: &World,
    points: &[LidarPoint],
    target: usize,
    config: &TruthConfig,
) -> Result<Vec<RoofTruth>, SimError> {
    let (per_building, seen_assets) = roof_hits(world, points);
    let mut order: Vec<usize> = (0..world.buildings.len())
        .filter(|&i| per_building[i].len() >= config.min_points)
        .collect();
    order.sort_by_key(|&i| (i != target, i));
    let params = PolylabelParams {
        precision_m: config.polylabel_precision_m,
        ..Default::default()
    };
    let mut roofs = Vec::new();
    for bi in order {
        let b = &world.buildings[bi];
        let obstacles = obstacles_on(world, bi, &seen_assets);
        let landable_region = landable_region(b, &per_building[bi], &obstacles);
        let (best_point, best_radius_m) = if landable_region.shell.len() >= 3 {
            let pole = polylabel(&landable_region, &params)
                .map_err(|e| SimError::Geometry(e.to_string()))?;
            (pole.center, pole.distance)
        } else {
            (b.center(), 0.0)
        };
        roofs.push(RoofTruth {
            building: bi,
            outline: b.outline(),
            height_m: b.height_m,
            parapet_height_m: b.parapet_height_m,
            obstacles,
            landable_region,
            best_point,
            best_radius_m,
            lidar_points: per_building[bi].len(),
        });
    }
    Ok(roofs)
}

/// Where the scan hits each roof at its level (x, y per building), and which assets it hits.
fn roof_hits(world: &World, points: &[LidarPoint]) -> (Vec<Vec<[f64; 2]>>, Vec<bool>) {
    let mut per_building: Vec<Vec<[f64; 2]>> = vec![Vec::new(); world.buildings.len()];
    let mut seen_assets = vec![false; world.assets.len()];
    for p in points {
        let bi = p.building as usize;
        if bi >= world.buildings.len() {
            continue;
        }
        if (p.asset as usize) < seen_assets.len() {
            seen_assets[p.asset as usize] = true;
        }
        if p.world[2] >= world.buildings[bi].height_m - 0.1 {
            per_building[bi].push([p.world[0], p.world[1]]);
        }
    }
    (per_building, seen_assets)
}

/// The assets on building `bi`, each seen when the scan hit it.
fn obstacles_on(world: &World, bi: usize, seen_assets: &[bool]) -> Vec<ObstacleTruth> {
    world.buildings[bi]
        .assets
        .iter()
        .map(|&ai| {
            let a = &world.assets[ai];
            ObstacleTruth {
                asset: ai,
                kind: a.kind,
                class: a.kind.class() as u8,
                footprint: a.footprint(),
                height_m: a.height_m,
                seen_by_lidar: seen_assets[ai],
            }
        })
        .collect()
}

/// The roof interior of `b` within the convex hull of the scan's `hits` on it, the obstacle
/// footprints clipped to it as clockwise holes (empty when the scan covers no area).
// The polygon is spelled with a default tail so that fields the geometry crate adds keep their
// defaults.
#[allow(clippy::needless_update)]
fn landable_region(b: &Building, hits: &[[f64; 2]], obstacles: &[ObstacleTruth]) -> Polygon {
    let hull = convex_hull(hits);
    let shell = if hull.len() >= 3 {
        clip_convex(&b.roof_interior(), &hull)
    } else {
        Vec::new()
    };
    let mut holes = Vec::new();
    if shell.len() >= 3 {
        for o in obstacles {
            let mut h = clip_convex(&o.footprint, &shell);
            if h.len() >= 3 && ring_area(&h).abs() > 1e-6 {
                h.reverse();
                holes.push(h);
            }
        }
    }
    Polygon {
        shell,
        holes,
        ..Default::default()
    }
}

/// Signed area (positive for counter-clockwise).
pub fn ring_area(r: &[[f64; 2]]) -> f64 {
    let n = r.len();
    (0..n)
        .map(|i| {
            let (a, b) = (r[i], r[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Convex hull (Andrew's monotone chain), counter-clockwise, collinear points dropped.
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(p.len() * 2);
    for &q in &p {
        while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
            h.pop();
        }
        h.push(q);
    }
    let lower = h.len() + 1;
    for &q in p.iter().rev().skip(1) {
        while h.len() >= lower && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
            h.pop();
        }
        h.push(q);
    }
    h.pop();
    h
}

/// Sutherland-Hodgman: `subject` clipped by the convex counter-clockwise `clip`.
pub fn clip_convex(subject: &[[f64; 2]], clip: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut out = subject.to_vec();
    let n = clip.len();
    for i in 0..n {
        if out.is_empty() {
            break;
        }
        let (a, b) = (clip[i], clip[(i + 1) % n]);
        let input = std::mem::take(&mut out);
        let m = input.len();
        for j in 0..m {
            let p = input[j];
            let q = input[(j + 1) % m];
            let dp = cross(a, b, p);
            let dq = cross(a, b, q);
            if dp >= 0.0 {
                out.push(p);
            }
            if (dp >= 0.0) != (dq >= 0.0) {
                let t = dp / (dp - dq);
                out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
            }
        }
    }
    // Drop repeated vertices left by edges through a corner.
    out.dedup_by(|a, b| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
    if out.len() > 1 {
        let (f, l) = (out[0], out[out.len() - 1]);
        if (f[0] - l[0]).abs() < 1e-9 && (f[1] - l[1]).abs() < 1e-9 {
            out.pop();
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_and_clip_of_squares() {
        let pts = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [1.0, 1.0],
            [1.0, 0.0],
        ];
        let h = convex_hull(&pts);
        assert_eq!(h.len(), 4);
        assert!((ring_area(&h) - 4.0).abs() < 1e-12);
        let other = [[1.0, 1.0], [3.0, 1.0], [3.0, 3.0], [1.0, 3.0]];
        let c = clip_convex(&other, &h);
        assert!((ring_area(&c) - 1.0).abs() < 1e-12, "{c:?}");
    }
}
