//! The quality metrics of one frame, as pure functions of the returned sites and the ground truth:
//! whether each safe circle is clear of every obstacle and inside its roof, the ratio of the best
//! returned radius to the true best radius per roof, the IoU of the returned landing polygons with
//! the true landable area, and what happened to each obstacle.

use serde::Serialize;

use crate::geom::{Grid, Mask, P2, Polygon2};

/// Parameters of the metrics. `Default` holds the values the evaluation reports with.
#[derive(Debug, Clone, PartialEq)]
pub struct MetricsParams {
    /// Raster cell for areas, IoU and the true best circle, metres.
    pub cell_m: f64,
    /// How far a safe circle may reach into an obstacle or past the roof edge and still count as
    /// safe: the declared polylabel precision of the request.
    pub tolerance_m: f64,
    /// Roofs whose true best radius is smaller than this are not scored for radius and IoU (they
    /// are barely in view).
    pub min_truth_radius_m: f64,
    /// Obstacles with less footprint than this inside the scanned area are not scored.
    pub min_obstacle_area_m2: f64,
    /// A site off every listed roof whose plane is below this height (world z) is on the ground;
    /// above it, it is on a building the ground truth does not list.
    pub ground_max_height_m: f64,
}

impl Default for MetricsParams {
    fn default() -> Self {
        Self {
            cell_m: 0.05,
            tolerance_m: 0.5,
            min_truth_radius_m: 1.0,
            min_obstacle_area_m2: 0.05,
            ground_max_height_m: 1.0,
        }
    }
}

/// One true obstacle on a roof.
#[derive(Debug, Clone, PartialEq)]
pub struct Obstacle {
    /// `SemanticClass` id.
    pub class: u8,
    /// Footprint in the horizontal plane.
    pub footprint: Polygon2,
    /// Whether any LiDAR point of the frame hit it (an unseen obstacle cannot be avoided by
    /// geometry; only the camera can reveal it).
    pub seen: bool,
}

/// One roof in view, with what is on it.
#[derive(Debug, Clone, PartialEq)]
pub struct RoofTruth {
    /// Identifier in the world (building index), for the report.
    pub id: u32,
    /// The whole roof footprint (parapet included).
    pub outline: Polygon2,
    /// The walkable roof (inside the parapet); where a safe circle must stay.
    pub interior: Polygon2,
    /// Roof surface height, metres (world z).
    pub height_m: f64,
    /// Obstacles standing on the roof.
    pub obstacles: Vec<Obstacle>,
    /// The part of the roof the scan covered; `None` means all of it.
    pub scanned: Option<Polygon2>,
    /// Parts of the roof hidden from the sensor behind obstacles and the parapet (their shadows
    /// under a light at the sensor). No method can know what is there from this frame; the
    /// line-of-sight scores leave them out.
    pub hidden: Vec<Polygon2>,
    /// For a fused answer, the part of the roof that some frame so far had in sight: the union
    /// of each frame's scanned region less that frame's shadows ([`crate::approach::fused_roofs`]).
    /// When set, the line-of-sight scores leave out the rest instead of the current frame's
    /// `hidden` parts: what an earlier frame saw, the map holds. `None` for a single frame.
    pub in_sight: Option<Mask>,
    /// The best landing radius the recording's ground truth states, when it has one (kept to
    /// cross-check the raster optimum).
    pub stated_best_radius_m: Option<f64>,
    /// Whether IoU and radius ratio are scored on this roof. Raised roofs (a small building's top
    /// on a roof) are only used to judge sites that stand on them.
    pub scored: bool,
    /// The roof the flight approaches (the others are neighbours in view).
    pub target: bool,
}

/// A returned landing site, reduced to what the metrics need.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    /// 1 is best.
    pub rank: u32,
    /// The landing polygon (shell and holes) in the horizontal plane.
    pub polygon: Polygon2,
    /// The safest point (world x, y).
    pub center: P2,
    /// Height of the landing plane, metres.
    pub plane_height_m: f64,
    /// The returned safe radius, metres.
    pub radius_m: f64,
}

/// Why a site is unsafe, or that it is safe.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Verdict {
    /// The circle is clear of every obstacle and inside the roof (within the tolerance).
    Safe,
    /// The circle reaches `intrusion_m` into an obstacle of class `class`; `seen` tells whether
    /// any LiDAR point hit that obstacle.
    Obstacle {
        class: u8,
        intrusion_m: f64,
        seen: bool,
    },
    /// The circle reaches `intrusion_m` past the edge of the walkable roof.
    OutsideRoof { intrusion_m: f64 },
    /// The centre is on no roof and the plane is at ground level (the street).
    OffRoof,
    /// The centre is on no roof of the ground truth but the plane is above the ground: a building
    /// the truth does not list (too few LiDAR points on it). Not judged either way.
    UnlistedRoof,
}

impl Verdict {
    /// True for [`Verdict::Safe`].
    pub fn is_safe(&self) -> bool {
        matches!(self, Verdict::Safe)
    }

    /// True for the verdicts that count as unsafe (everything but safe and unjudged).
    pub fn is_unsafe(&self) -> bool {
        !matches!(self, Verdict::Safe | Verdict::UnlistedRoof)
    }
}

/// The verdict on one returned site.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SiteEval {
    pub rank: u32,
    pub radius_m: f64,
    /// Index of the roof (in the frame's truth) the centre lies on.
    pub roof: Option<usize>,
    /// Height of the site's plane above that roof, metres (about 0 on the roof itself; an
    /// obstacle's height when the plane is the top of an obstacle).
    pub height_above_roof_m: Option<f64>,
    pub verdict: Verdict,
}

/// The scores of one roof.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RoofEval {
    /// Index of the roof in the frame's truth.
    pub roof: usize,
    /// Its identifier in the world.
    pub roof_id: u32,
    /// Whether it is the roof the flight approaches.
    pub target: bool,
    /// True landable area in the scanned region, square metres.
    pub truth_area_m2: f64,
    /// Radius of the largest circle in the true landable area.
    pub truth_radius_m: f64,
    /// The ground truth's own statement of that radius, when it has one.
    pub stated_truth_radius_m: Option<f64>,
    /// Area of the union of returned polygons on this roof.
    pub returned_area_m2: f64,
    /// Largest safe radius returned on this roof; 0 when none.
    pub best_safe_radius_m: f64,
    /// `best_safe_radius_m / truth_radius_m`.
    pub radius_ratio: f64,
    /// IoU of the returned polygons with the true landable area (0 when nothing was returned).
    pub iou: f64,
    /// The true landable area in the sensor's line of sight (less [`hidden_mask`]: the frame's
    /// shadows, or for a fused answer what no frame so far had in sight), square metres.
    pub visible_area_m2: f64,
    /// Radius of the largest circle in that area.
    pub visible_radius_m: f64,
    /// `best_safe_radius_m / visible_radius_m` (0 when nothing is visible).
    pub visible_radius_ratio: f64,
    /// IoU of the returned polygons with that area.
    pub visible_iou: f64,
}

/// What happened to one obstacle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObstacleEval {
    pub roof: usize,
    pub class: u8,
    /// Footprint area inside the scanned region, square metres.
    pub scanned_area_m2: f64,
    /// Fraction of that footprint lying inside returned landing polygons (0 = carved out).
    pub covered_fraction: f64,
    /// True when some returned safe circle reaches into it beyond the tolerance.
    pub hit: bool,
}

/// All scores of one frame in one mode.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct FrameEval {
    pub sites: Vec<SiteEval>,
    pub roofs: Vec<RoofEval>,
    pub obstacles: Vec<ObstacleEval>,
}

/// The roof a site stands on: among roofs whose outline holds the centre, the one whose height is
/// nearest the site's plane. `None` when no outline holds it.
pub fn roof_of(site: &Site, roofs: &[RoofTruth]) -> Option<usize> {
    roofs
        .iter()
        .enumerate()
        .filter(|(_, r)| r.outline.contains(site.center))
        .min_by(|(_, a), (_, b)| {
            (a.height_m - site.plane_height_m)
                .abs()
                .total_cmp(&(b.height_m - site.plane_height_m).abs())
        })
        .map(|(i, _)| i)
}

/// Judges one site against the roofs in view.
pub fn judge_site(site: &Site, roofs: &[RoofTruth], params: &MetricsParams) -> SiteEval {
    let roof = roof_of(site, roofs);
    let verdict = match roof {
        None if site.plane_height_m < params.ground_max_height_m => Verdict::OffRoof,
        None => Verdict::UnlistedRoof,
        Some(i) => judge_on_roof(site.center, site.radius_m, &roofs[i], params.tolerance_m),
    };
    SiteEval {
        rank: site.rank,
        radius_m: site.radius_m,
        roof,
        height_above_roof_m: roof.map(|i| site.plane_height_m - roofs[i].height_m),
        verdict,
    }
}

/// The verdict for a circle at `center` of `radius_m` on `roof`: the deepest intrusion wins.
pub fn judge_on_roof(center: P2, radius_m: f64, roof: &RoofTruth, tolerance_m: f64) -> Verdict {
    let mut worst = Verdict::Safe;
    let mut worst_intrusion = tolerance_m;
    for o in &roof.obstacles {
        // Signed distance is positive inside the footprint: the circle reaches radius + depth in.
        let intrusion = radius_m + o.footprint.signed_distance(center);
        if intrusion > worst_intrusion {
            worst_intrusion = intrusion;
            worst = Verdict::Obstacle {
                class: o.class,
                intrusion_m: intrusion,
                seen: o.seen,
            };
        }
    }
    let edge = radius_m - roof.interior.signed_distance(center);
    if edge > worst_intrusion {
        worst = Verdict::OutsideRoof { intrusion_m: edge };
    }
    worst
}

/// The true landable area of a roof on `grid`: walkable roof, inside the scanned region, minus
/// every obstacle footprint.
pub fn landable_mask(grid: Grid, roof: &RoofTruth) -> Mask {
    let mut m = Mask::of_polygon(grid, &roof.interior);
    if let Some(s) = &roof.scanned {
        m.and(&Mask::of_polygon(grid, s));
    }
    let mut blocked = Mask::empty(grid);
    for o in &roof.obstacles {
        blocked.add_polygon(&o.footprint);
    }
    m.and_not(&blocked);
    m
}

/// The part of a roof hidden from the sensor on `grid`: outside [`RoofTruth::in_sight`] when
/// it is set, else inside the [`RoofTruth::hidden`] shadows.
pub fn hidden_mask(grid: Grid, roof: &RoofTruth) -> Mask {
    if let Some(seen) = &roof.in_sight {
        return Mask::from_fn(grid, |p| !seen.contains(p));
    }
    let mut m = Mask::empty(grid);
    for h in &roof.hidden {
        m.add_polygon(h);
    }
    m
}

/// Scores every site, roof and obstacle of one frame.
pub fn evaluate_frame(sites: &[Site], roofs: &[RoofTruth], params: &MetricsParams) -> FrameEval {
    let site_evals: Vec<SiteEval> = sites.iter().map(|s| judge_site(s, roofs, params)).collect();
    let mut out = FrameEval {
        sites: site_evals,
        ..Default::default()
    };
    for (ri, roof) in roofs.iter().enumerate() {
        let on_roof: Vec<usize> = (0..sites.len())
            .filter(|&k| out.sites[k].roof == Some(ri))
            .collect();
        let matched: Vec<&Site> = on_roof.iter().map(|&k| &sites[k]).collect();
        let Some(grid) = roof_grid(roof, &matched, params.cell_m) else {
            continue;
        };
        let mut returned = Mask::empty(grid);
        for s in &matched {
            returned.add_polygon(&s.polygon);
        }
        out.obstacles
            .extend(obstacle_evals(ri, roof, grid, &returned, &matched, params));
        let best_safe = on_roof
            .iter()
            .filter(|&&k| out.sites[k].verdict.is_safe())
            .map(|&k| sites[k].radius_m)
            .fold(0.0f64, f64::max);
        out.roofs
            .extend(roof_eval(ri, roof, grid, &returned, best_safe, params));
    }
    out
}

/// The grid of cells `cell_m` wide over the roof and every polygon matched to it, so that
/// spill-over counts as error; `None` when there is nothing to cover.
fn roof_grid(roof: &RoofTruth, matched: &[&Site], cell_m: f64) -> Option<Grid> {
    let mut pts: Vec<P2> = roof.outline.shell.clone();
    for s in matched {
        pts.extend(s.polygon.shell.iter().copied());
    }
    let (lo, hi) = crate::geom::bounds_of(&pts)?;
    Grid::covering(lo, hi, cell_m, 2.0 * cell_m)
}

/// The scanned obstacles of roof `ri` big enough to count: how much of each the `returned`
/// polygons cover, and whether a matched site's circle reaches into it.
fn obstacle_evals(
    ri: usize,
    roof: &RoofTruth,
    grid: Grid,
    returned: &Mask,
    matched: &[&Site],
    params: &MetricsParams,
) -> Vec<ObstacleEval> {
    let scanned = match &roof.scanned {
        Some(s) => Mask::of_polygon(grid, s),
        None => Mask::of_polygon(grid, &roof.outline),
    };
    let mut out = Vec::new();
    for o in &roof.obstacles {
        let mut fp = Mask::of_polygon(grid, &o.footprint);
        fp.and(&scanned);
        let n = fp.count();
        if (n as f64) * grid.cell_area() < params.min_obstacle_area_m2 {
            continue;
        }
        let hit = matched
            .iter()
            .any(|s| s.radius_m + o.footprint.signed_distance(s.center) > params.tolerance_m);
        out.push(ObstacleEval {
            roof: ri,
            class: o.class,
            scanned_area_m2: n as f64 * grid.cell_area(),
            covered_fraction: fp.intersection_count(returned) as f64 / n as f64,
            hit,
        });
    }
    out
}

/// How the `returned` polygons and the best safe radius among them, `best_safe`, compare with
/// the truth of roof `ri`, in all and in the part the sensor saw; `None` for a roof not scored
/// or with too small a true landing circle.
fn roof_eval(
    ri: usize,
    roof: &RoofTruth,
    grid: Grid,
    returned: &Mask,
    best_safe: f64,
    params: &MetricsParams,
) -> Option<RoofEval> {
    let truth = landable_mask(grid, roof);
    let truth_radius = truth.largest_inscribed_circle().map_or(0.0, |(_, r)| r);
    if !roof.scored || truth_radius < params.min_truth_radius_m {
        return None;
    }
    let mut visible = truth.clone();
    visible.and_not(&hidden_mask(grid, roof));
    let visible_radius = visible.largest_inscribed_circle().map_or(0.0, |(_, r)| r);
    Some(RoofEval {
        roof: ri,
        roof_id: roof.id,
        target: roof.target,
        truth_area_m2: truth.area(),
        truth_radius_m: truth_radius,
        stated_truth_radius_m: roof.stated_best_radius_m,
        returned_area_m2: returned.area(),
        best_safe_radius_m: best_safe,
        radius_ratio: best_safe / truth_radius,
        iou: truth.iou(returned).unwrap_or(0.0),
        visible_area_m2: visible.area(),
        visible_radius_m: visible_radius,
        visible_radius_ratio: if visible_radius > 0.0 {
            best_safe / visible_radius
        } else {
            0.0
        },
        visible_iou: visible.iou(returned).unwrap_or(0.0),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 20 × 10 m roof at 30 m with a 0.3 m parapet and a 2 × 2 m AC unit at (5, 5).
    fn roof() -> RoofTruth {
        RoofTruth {
            id: 7,
            outline: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
            interior: Polygon2::rect([0.3, 0.3], [19.7, 9.7]),
            height_m: 30.0,
            obstacles: vec![Obstacle {
                class: 8,
                footprint: Polygon2::rect([4.0, 4.0], [6.0, 6.0]),
                seen: true,
            }],
            scanned: None,
            hidden: vec![],
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target: true,
        }
    }

    fn site(center: P2, radius_m: f64, polygon: Polygon2) -> Site {
        Site {
            rank: 1,
            polygon,
            center,
            plane_height_m: 30.0,
            radius_m,
        }
    }

    #[test]
    fn a_circle_clear_of_everything_is_safe() {
        let s = site([15.0, 5.0], 4.6, Polygon2::default());
        assert_eq!(
            judge_site(&s, &[roof()], &MetricsParams::default()).verdict,
            Verdict::Safe
        );
    }

    #[test]
    fn a_circle_over_an_obstacle_is_unsafe_with_its_class() {
        // Centre 1.5 m from the AC unit's edge with radius 2.5: 1 m into it, beyond 0.5 m.
        let s = site([7.5, 5.0], 2.5, Polygon2::default());
        match judge_site(&s, &[roof()], &MetricsParams::default()).verdict {
            Verdict::Obstacle {
                class, intrusion_m, ..
            } => {
                assert_eq!(class, 8);
                assert!((intrusion_m - 1.0).abs() < 1e-9);
            }
            v => panic!("{v:?}"),
        }
        // 0.4 m in is within the declared precision.
        let s = site([7.5, 5.0], 1.9, Polygon2::default());
        assert!(
            judge_site(&s, &[roof()], &MetricsParams::default())
                .verdict
                .is_safe()
        );
        // A centre inside the obstacle reaches radius + depth in.
        let s = site([5.0, 5.0], 0.2, Polygon2::default());
        assert!(matches!(
            judge_site(&s, &[roof()], &MetricsParams::default()).verdict,
            Verdict::Obstacle { intrusion_m, .. } if (intrusion_m - 1.2).abs() < 1e-9
        ));
    }

    #[test]
    fn a_circle_past_the_parapet_or_off_the_roof_is_unsafe() {
        let s = site([17.0, 5.0], 3.5, Polygon2::default());
        assert!(matches!(
            judge_site(&s, &[roof()], &MetricsParams::default()).verdict,
            Verdict::OutsideRoof { intrusion_m } if (intrusion_m - 0.8).abs() < 1e-9
        ));
        let mut s = site([25.0, 5.0], 1.0, Polygon2::default());
        s.plane_height_m = 0.05;
        let e = judge_site(&s, &[roof()], &MetricsParams::default());
        assert_eq!((e.roof, e.verdict), (None, Verdict::OffRoof));
        assert!(e.verdict.is_unsafe());
        // Off every listed roof but 20 m up: a building the truth does not list, not judged.
        s.plane_height_m = 20.0;
        let v = judge_site(&s, &[roof()], &MetricsParams::default()).verdict;
        assert_eq!(v, Verdict::UnlistedRoof);
        assert!(!v.is_unsafe() && !v.is_safe());
    }

    #[test]
    fn perfect_answer_scores_one() {
        // The exact landable polygon with the true best circle: IoU 1, ratio 1.
        let r = roof();
        let polygon = Polygon2 {
            shell: r.interior.shell.clone(),
            holes: vec![r.obstacles[0].footprint.shell.clone()],
        };
        let s = site([14.85, 5.0], 4.7, polygon);
        let e = evaluate_frame(&[s], &[r], &MetricsParams::default());
        assert_eq!(e.roofs.len(), 1);
        let roof = &e.roofs[0];
        assert!((roof.iou - 1.0).abs() < 0.01, "{roof:?}");
        assert!((roof.truth_radius_m - 4.7).abs() < 0.06, "{roof:?}");
        assert!((roof.radius_ratio - 1.0).abs() < 0.02, "{roof:?}");
        assert_eq!(e.obstacles.len(), 1);
        assert!(
            e.obstacles[0].covered_fraction < 0.05 && !e.obstacles[0].hit,
            "{:?}",
            e.obstacles[0]
        );
    }

    #[test]
    fn a_missed_flat_obstacle_is_covered_and_hit() {
        // Geometry alone sees through a tarp: the polygon has no hole and the circle sits on it.
        let mut r = roof();
        r.obstacles[0].class = 13;
        let s = site(
            [6.0, 5.0],
            4.7,
            Polygon2 {
                shell: r.interior.shell.clone(),
                holes: vec![],
            },
        );
        let e = evaluate_frame(&[s], &[r], &MetricsParams::default());
        assert!(matches!(
            e.sites[0].verdict,
            Verdict::Obstacle { class: 13, .. }
        ));
        assert!(e.obstacles[0].hit && e.obstacles[0].covered_fraction > 0.95);
        // Unsafe sites do not count towards the radius ratio; the polygon still overlaps mostly.
        assert_eq!(e.roofs[0].radius_ratio, 0.0);
        let iou = e.roofs[0].iou;
        assert!(
            (iou - (19.4 * 9.4 - 4.0) / (19.4 * 9.4)).abs() < 0.01,
            "{iou}"
        );
    }

    #[test]
    fn line_of_sight_scores_leave_out_what_the_sensor_could_not_see() {
        // The right half (x > 10) lies in a shadow; the answer covers exactly the left half
        // (less the AC unit), with a 2 m circle.
        let mut r = roof();
        r.hidden = vec![Polygon2::rect([10.0, -1.0], [21.0, 11.0])];
        let polygon = Polygon2 {
            shell: Polygon2::rect([0.3, 0.3], [10.0, 9.7]).shell,
            holes: vec![r.obstacles[0].footprint.shell.clone()],
        };
        let s = site([8.0, 5.0], 2.0, polygon);
        let e = evaluate_frame(&[s], &[r], &MetricsParams::default());
        let roof = &e.roofs[0];
        assert!((roof.visible_iou - 1.0).abs() < 0.01, "{roof:?}");
        assert!(roof.iou < 0.5, "{roof:?}");
        assert!(
            (roof.visible_area_m2 - (9.7 * 9.4 - 4.0)).abs() < 0.2,
            "{roof:?}"
        );
        // The truth's best circle is in the hidden half; the visible half, 9.4 m tall with the
        // AC unit in it, holds circles of about 2.2 m.
        assert!((roof.truth_radius_m - 4.7).abs() < 0.06, "{roof:?}");
        assert!(
            roof.visible_radius_m > 2.0 && roof.visible_radius_m < 2.5,
            "{roof:?}"
        );
        let ratio = 2.0 / roof.visible_radius_m;
        assert!(
            (roof.visible_radius_ratio - ratio).abs() < 1e-12,
            "{roof:?}"
        );
    }

    #[test]
    fn the_scanned_region_limits_the_truth() {
        // Only the left 8 m were scanned: the best circle there is limited by the AC unit.
        let mut r = roof();
        r.scanned = Some(Polygon2::rect([0.0, 0.0], [8.0, 10.0]));
        let e = evaluate_frame(&[], &[r], &MetricsParams::default());
        assert_eq!(e.roofs.len(), 1);
        let truth = e.roofs[0].truth_radius_m;
        assert!(truth > 1.5 && truth < 2.5, "{truth}");
        assert_eq!((e.roofs[0].iou, e.roofs[0].radius_ratio), (0.0, 0.0));
    }

    #[test]
    fn the_site_goes_to_the_roof_at_its_height() {
        // Two stacked roof records over the same outline (a shed on a roof): height decides.
        let low = roof();
        let mut high = roof();
        high.id = 8;
        high.height_m = 33.0;
        let mut s = site([15.0, 5.0], 1.0, Polygon2::default());
        s.plane_height_m = 32.8;
        assert_eq!(roof_of(&s, &[low.clone(), high.clone()]), Some(1));
        s.plane_height_m = 30.1;
        assert_eq!(roof_of(&s, &[low, high]), Some(0));
    }
}
