//! Checks on what the classes call roof, from the levels of the cloud: a landable region that
//! is no roof to land on although every point of it is landable.
//!
//! Entry point: [`no_roof`]. A segmentation model errs in ways the points can show, and two of
//! them left unsafe single-frame sites on fresh sets (issue 42):
//!
//! - **A raised platform** ([`is_raised_platform`]): the top of a small structure standing on a
//!   larger roof, which the model calls roof. A stair or lift housing is 2-4.5 m on a side and
//!   2.2-3.2 m tall (the simulator's small rooftop entrance: 2.0-3.6 × 2.4-4.4 m under a slab
//!   0.1 m wider, 2.2-3.0 m up; a city's stair bulkhead or lift machine room is at most about
//!   5 × 5 m), so its top is under [`MAX_PLATFORM_AREA_M2`] and stands at least
//!   [`MIN_PLATFORM_RISE_M`] over the roof around it. A set-back roof worth landing on is a
//!   storey's floor: tens of square metres or more, which the area bound keeps.
//! - **A street called roof** ([`is_street_level`]): a region within [`STREET_LEVEL_M`] of the
//!   lowest level of the scan within [`STREET_RADIUS_M`] (its [`LOW_QUANTILE`]), where points
//!   classed ground lie, and either a region at least as large stands [`MIN_ROOF_ABOVE_GROUND_M`]
//!   or more above that level, or most of the classed points at that level are ground
//!   ([`STREET_GROUND_SHARE`]: a patch of street called roof in the street around it). The
//!   level is the scan's, not that of the points classed ground: a model that calls part of a
//!   roof ground would otherwise put the street on the roof; and a roof the scan shows alone,
//!   or beside a taller one, with points the model calls ground on it, is kept unless a larger
//!   region stands above it or the model calls most of it ground.
//!
//! Both judge from heights, areas and classes alone, so they apply to a scan and to a fused map
//! alike.

use crate::regions::Regions;
use crate::{Polygon, SemanticClass};

/// A raised platform's region is smaller than this, square metres: the top of the largest stair
/// or lift housing (about 5 m × 5 m). A set-back roof large enough to land on is larger.
pub const MAX_PLATFORM_AREA_M2: f64 = 25.0;

/// A raised platform stands at least this far above the roof around it, metres: over an
/// AC unit's lowest top (0.8 m) and any parapet's (up to 1.1 m in the simulator, 1 m or so in a
/// city), under an entrance's (2.2 m).
pub const MIN_PLATFORM_RISE_M: f64 = 1.0;

/// The roof around a raised platform is at least this many times its area.
pub const PLATFORM_ROOF_AREA_FACTOR: f64 = 2.0;

/// A raised platform's centroid lies inside the outer ring of the roof around it, or at most this
/// far outside, metres: a structure on the roof, or at the edge of what the scan shows of it
/// (half the widest housing, 2.3 m, past the roof's last points).
pub const PLATFORM_REACH_M: f64 = 2.5;

/// A region within this height of the ground around it is street level, metres: a step, a kerb or
/// a loading dock, never a roof (the simulator's lowest roof is 10 m up, a one-storey building's
/// about 3 m).
pub const STREET_LEVEL_M: f64 = 1.5;

/// The ground around a region: the points classed ground within this horizontal distance of its
/// centroid, metres.
pub const STREET_RADIUS_M: f64 = 30.0;

/// The lowest level of the scan around a region is this quantile of the heights of its points
/// there.
pub const LOW_QUANTILE: f64 = 0.02;

/// Fewer points (or points classed ground) at the lowest level around a region say nothing of
/// the street.
pub const MIN_GROUND_POINTS: usize = 10;

/// The scan holds two levels when another region, at least as large, stands at least this high
/// over the lowest level, metres: a roof of one storey or more.
pub const MIN_ROOF_ABOVE_GROUND_M: f64 = 2.5;

/// A region at the lowest level is street when at least this share of the classed points at
/// that level around it are ground: the street around a patch the model calls roof is mostly
/// ground, a roof mostly roof (the shipped model calls 1 % of ground pixels roof and 3 % of
/// roof pixels something else; a roof part called ground is kept below half).
pub const STREET_GROUND_SHARE: f64 = 0.5;

/// For each region (same order as `polygons`), whether it is no roof to land on: a raised
/// platform on a larger roof, or (with classes) a street called roof.
pub fn no_roof(
    regions: &Regions,
    polygons: &[Polygon],
    points: &[[f64; 3]],
    classes: Option<&[u8]>,
) -> Vec<bool> {
    // Without classes no point is ground, so no region is street. With them, the ground points
    // near enough the lowest region's height to count are gathered once, for every region.
    let mut drop = vec![false; regions.regions.len()];
    if let Some(classes) = classes.filter(|_| !drop.is_empty()) {
        let lowest = (regions.regions.iter()).fold(f64::INFINITY, |z, r| z.min(r.mean[2]));
        let ground = ground_points(points, classes, lowest);
        for (r, d) in drop.iter_mut().enumerate() {
            *d = street_level(regions, polygons, r, points, classes, &ground);
        }
    }
    let platforms: Vec<bool> = (0..regions.regions.len())
        .map(|r| !drop[r] && is_raised_platform(regions, polygons, r, &drop))
        .collect();
    for (d, p) in drop.iter_mut().zip(platforms) {
        *d |= p;
    }
    drop
}

/// Whether region `r` is a small platform standing well above a larger region (not `dropped`)
/// whose outer ring holds it.
pub fn is_raised_platform(
    regions: &Regions,
    polygons: &[Polygon],
    r: usize,
    dropped: &[bool],
) -> bool {
    let area = polygons[r].area();
    if area >= MAX_PLATFORM_AREA_M2 {
        return false;
    }
    let top = &regions.regions[r];
    let at = [top.mean[0], top.mean[1]];
    (0..regions.regions.len()).any(|l| {
        let (roof, outline) = (&regions.regions[l], &polygons[l]);
        l != r
            && !dropped[l]
            && top.mean[2] - roof.mean[2] >= MIN_PLATFORM_RISE_M
            && outline.area() >= PLATFORM_ROOF_AREA_FACTOR * area
            && outer(outline).signed_distance(at) >= -PLATFORM_REACH_M
    })
}

/// The polygon's shell alone.
fn outer(polygon: &Polygon) -> Polygon {
    Polygon {
        shell: polygon.shell.clone(),
        holes: Vec::new(),
    }
}

/// Whether region `r` lies within [`STREET_LEVEL_M`] of the lowest level of the scan around it
/// (the [`LOW_QUANTILE`] of the heights within [`STREET_RADIUS_M`]), where at least
/// [`MIN_GROUND_POINTS`] points classed ground lie, and either another region at least as large
/// stands at least [`MIN_ROOF_ABOVE_GROUND_M`] above that level or at least
/// [`STREET_GROUND_SHARE`] of the classed points there are ground. `classes` are the points'.
pub fn is_street_level(
    regions: &Regions,
    polygons: &[Polygon],
    r: usize,
    points: &[[f64; 3]],
    classes: &[u8],
) -> bool {
    let ground = ground_points(points, classes, regions.regions[r].mean[2]);
    street_level(regions, polygons, r, points, classes, &ground)
}

/// [`is_street_level`], given the points classed ground ([`ground_points`]) at or above a height
/// no higher than region `r`'s.
fn street_level(
    regions: &Regions,
    polygons: &[Polygon],
    r: usize,
    points: &[[f64; 3]],
    classes: &[u8],
    ground: &[[f64; 3]],
) -> bool {
    may_be_street(regions.regions[r].mean, ground)
        && street_by_level(regions, polygons, r, points, classes)
}

/// Whether enough points classed ground lie near a region at `mean` for it to be street. The
/// level lies less than [`STREET_LEVEL_M`] below the region, so the ground points counted at
/// it lie less than twice that below (three times leaves room for rounding). Most regions are
/// roofs well above the street, with fewer such ground points than the count needs: they are
/// known from the (few) points classed ground alone, without the level's two passes over every
/// point.
fn may_be_street([cx, cy, z]: [f64; 3], ground: &[[f64; 3]]) -> bool {
    let near2 = STREET_RADIUS_M * STREET_RADIUS_M;
    (ground.iter())
        .filter(|p| (p[0] - cx).powi(2) + (p[1] - cy).powi(2) <= near2 && near_below(z, p[2]))
        .nth(MIN_GROUND_POINTS - 1)
        .is_some()
}

/// Whether height `h` lies less than three street levels below `z`, or above it: where the
/// ground points a street at `z` would count lie ([`may_be_street`]).
fn near_below(z: f64, h: f64) -> bool {
    z - h < 3.0 * STREET_LEVEL_M
}

/// [`is_street_level`] from the scan's level around region `r` and the classes there.
fn street_by_level(
    regions: &Regions,
    polygons: &[Polygon],
    r: usize,
    points: &[[f64; 3]],
    classes: &[u8],
) -> bool {
    let [cx, cy, z] = regions.regions[r].mean;
    let Some(low) = street_level_below(points, [cx, cy], z) else {
        return false;
    };
    let near2 = STREET_RADIUS_M * STREET_RADIUS_M;
    let (mut on_ground, mut classed) = (0usize, 0usize);
    for (p, &c) in points.iter().zip(classes) {
        if c != 0
            && (p[0] - cx).powi(2) + (p[1] - cy).powi(2) <= near2
            && (p[2] - low).abs() < STREET_LEVEL_M
        {
            classed += 1;
            on_ground += usize::from(c == SemanticClass::Ground as u8);
        }
    }
    if on_ground < MIN_GROUND_POINTS {
        return false;
    }
    let area = polygons[r].area();
    let roof_above = (regions.regions.iter().zip(polygons))
        .any(|(o, p)| o.mean[2] - low >= MIN_ROOF_ABOVE_GROUND_M && p.area() >= area);
    roof_above || on_ground as f64 >= STREET_GROUND_SHARE * classed as f64
}

/// The points classed ground that a street at height `lowest` or above could count
/// ([`near_below`]): in a scan whose roofs stand well above the street, none.
fn ground_points(points: &[[f64; 3]], classes: &[u8], lowest: f64) -> Vec<[f64; 3]> {
    (points.iter().zip(classes))
        .filter(|(p, c)| **c == SemanticClass::Ground as u8 && near_below(lowest, p[2]))
        .map(|(p, _)| *p)
        .collect()
}

/// The lowest level of the points within [`STREET_RADIUS_M`] of `at`, the [`LOW_QUANTILE`] of
/// their heights (a few stray returns below the street do not move it), when it lies within
/// [`STREET_LEVEL_M`] of `z`; `None` without [`MIN_GROUND_POINTS`] points or when it lies lower.
/// A roof's is lower, and is known from a count alone: when more of the points than the
/// quantile's rank lie that far below `z`, so does the quantile.
fn street_level_below(points: &[[f64; 3]], [cx, cy]: [f64; 2], z: f64) -> Option<f64> {
    let near2 = STREET_RADIUS_M * STREET_RADIUS_M;
    let near = |p: &&[f64; 3]| (p[0] - cx).powi(2) + (p[1] - cy).powi(2) <= near2;
    // `z - h` falls as `h` rises (rounding keeps the order), so the quantile's `z - low` is at
    // least that of one of the points counted here.
    let below = |h: f64| z - h >= STREET_LEVEL_M;
    let (n, lower) = (points.iter().filter(near)).fold((0, 0), |(n, lower), p| {
        (n + 1, lower + usize::from(below(p[2])))
    });
    if n < MIN_GROUND_POINTS {
        return None;
    }
    let k = ((n - 1) as f64 * LOW_QUANTILE).round() as usize;
    if lower > k {
        return None;
    }
    // At most k points lie that far below: the quantile does not.
    let mut heights: Vec<f64> = points.iter().filter(near).map(|p| p[2]).collect();
    let (_, &mut level, _) = heights.select_nth_unstable_by(k, f64::total_cmp);
    Some(level)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Cloud, Params, detect};

    const ROOF: u8 = SemanticClass::BuildingRooftop as u8;
    const GROUND: u8 = SemanticClass::Ground as u8;

    /// A scan-like grid of points 0.3 m apart over `x0..x1` × `y0..y1` at height `z` (jittered
    /// so the triangulation is unique), all of class `class`, left out where `skip` says.
    fn grid(
        [x0, y0, x1, y1]: [f64; 4],
        z: f64,
        class: u8,
        skip: impl Fn(f64, f64) -> bool,
        out: &mut (Vec<[f32; 3]>, Vec<u8>),
    ) {
        let step = 0.3;
        let (nx, ny) = (((x1 - x0) / step) as i32, ((y1 - y0) / step) as i32);
        for j in 0..=ny {
            for i in 0..=nx {
                let x = x0 + step * f64::from(i) + 0.002 * f64::from((i * 7 + j * 3) % 5);
                let y = y0 + step * f64::from(j) - 0.002 * f64::from((i * 3 + j * 5) % 7);
                if !skip(x, y) {
                    out.0.push([x as f32, y as f32, z as f32]);
                    out.1.push(class);
                }
            }
        }
    }

    /// [`grid`] over `rect`, its jittered points that fall outside `rect` left out.
    fn block(rect: [f64; 4], z: f64, class: u8, out: &mut (Vec<[f32; 3]>, Vec<u8>)) {
        let [x0, y0, x1, y1] = rect;
        let outside = |x: f64, y: f64| !((x0..=x1).contains(&x) && (y0..=y1).contains(&y));
        grid(rect, z, class, outside, out);
    }

    /// The sites' (plane height, safe radius).
    fn sites(cloud: &(Vec<[f32; 3]>, Vec<u8>)) -> Vec<(f64, f64)> {
        let found = detect(&Cloud::new(&cloud.0, Some(&cloud.1)), &Params::default()).unwrap();
        (found.sites.iter())
            .map(|s| (s.plane_height_m, s.safe_radius_m))
            .collect()
    }

    /// A 20 m roof 20 m up with a structure of `side` metres, `rise` metres tall, in its middle
    /// (both called roof); ground around it.
    fn roof_with_structure(side: f64, rise: f64) -> (Vec<[f32; 3]>, Vec<u8>) {
        let mut cloud = (Vec::new(), Vec::new());
        let inside = |x: f64, y: f64, a: f64, b: f64| x >= a && x <= b && y >= a && y <= b;
        let (a, b) = (10.0 - side / 2.0, 10.0 + side / 2.0);
        grid(
            [0.0, 0.0, 20.0, 20.0],
            20.0,
            ROOF,
            |x, y| inside(x, y, a - 0.2, b + 0.2),
            &mut cloud,
        );
        grid([a, a, b, b], 20.0 + rise, ROOF, |_, _| false, &mut cloud);
        let building = |x, y| inside(x, y, -0.5, 20.5);
        grid(
            [-10.0, -10.0, 30.0, 30.0],
            0.0,
            GROUND,
            building,
            &mut cloud,
        );
        cloud
    }

    #[test]
    fn an_entrance_top_called_roof_gives_no_site() {
        // A stair housing of 3.3 m, 2.85 m tall: its top holds a circle of over 1 m.
        let cloud = roof_with_structure(3.3, 2.85);
        let found = sites(&cloud);
        assert!(found.iter().all(|s| (s.0 - 20.0).abs() < 0.1), "{found:?}");
        assert!(!found.is_empty());
        // The same region, judged by the check directly: the platform is dropped, the roof kept.
        let (points, classes) = (&cloud.0, &cloud.1);
        let pts: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
        let (regions, polygons) = regions_of(&pts, classes);
        let drop = no_roof(&regions, &polygons, &pts, Some(classes));
        let high: Vec<bool> = regions.regions.iter().map(|r| r.mean[2] > 21.0).collect();
        assert_eq!(drop, high);
        assert!(high.contains(&true));
    }

    #[test]
    fn a_set_back_roof_or_a_low_platform_stays() {
        // An upper storey of 9 m (81 m²), 3 m up: a roof to land on.
        let found = sites(&roof_with_structure(9.0, 3.0));
        assert!(found.iter().any(|s| (s.0 - 23.0).abs() < 0.1), "{found:?}");
        // A 3.3 m deck 0.6 m up: no structure by height.
        let found = sites(&roof_with_structure(3.3, 0.6));
        assert!(found.iter().any(|s| (s.0 - 20.6).abs() < 0.1), "{found:?}");
    }

    #[test]
    fn a_street_called_roof_gives_no_site_and_a_low_roof_stays() {
        // A 14 m roof 20 m up; east of it, street. A 6 m patch of the street is called roof, and
        // a 6 m roof 3 m up stands south of it.
        let mut cloud = (Vec::new(), Vec::new());
        grid([0.0, 0.0, 14.0, 14.0], 20.0, ROOF, |_, _| false, &mut cloud);
        let patch = |x: f64, y: f64| (20.0..=26.0).contains(&x) && (4.0..=10.0).contains(&y);
        let taken = |x: f64, y: f64| {
            ((-0.5..=14.5).contains(&x) && (-0.5..=14.5).contains(&y))
                || patch(x, y)
                || (19.5..=26.5).contains(&x) && (-12.5..=-5.5).contains(&y)
        };
        grid([-10.0, -20.0, 40.0, 30.0], 0.0, GROUND, taken, &mut cloud);
        block([20.0, 4.0, 26.0, 10.0], 0.0, ROOF, &mut cloud);
        block([20.0, -12.0, 26.0, -6.0], 3.0, ROOF, &mut cloud);
        let found = sites(&cloud);
        assert!(found.iter().all(|s| s.0 > 1.0), "{found:?}");
        assert!(found.iter().any(|s| (s.0 - 3.0).abs() < 0.1), "{found:?}");
        assert!(found.iter().any(|s| (s.0 - 20.0).abs() < 0.1), "{found:?}");
        // With no roof in the scan at all, the street around the patch, classed ground, still
        // says what the patch is.
        let street: (Vec<[f32; 3]>, Vec<u8>) = (cloud.0.iter().zip(&cloud.1))
            .filter(|(p, _)| p[2] < 1.0)
            .map(|(p, c)| (*p, *c))
            .unzip();
        assert!(sites(&street).is_empty(), "{:?}", sites(&street));
    }

    #[test]
    fn a_street_called_roof_larger_than_the_roofs_beside_it_gives_no_site() {
        // A 16 m × 12 m stretch of street called roof between two 6 m roofs 20 m up (fresh set
        // 5798: no roof in the frame was as large as the street's patch), and the same street
        // with nothing called roof on it but the patch.
        let mut cloud = (Vec::new(), Vec::new());
        let patch = |x: f64, y: f64| (12.0..=28.0).contains(&x) && (4.0..=16.0).contains(&y);
        let taken = |x: f64, y: f64| {
            patch(x, y)
                || (1.5..=8.5).contains(&x) && (6.5..=13.5).contains(&y)
                || (31.5..=38.5).contains(&x) && (6.5..=13.5).contains(&y)
        };
        grid([-10.0, -15.0, 50.0, 35.0], 0.0, GROUND, taken, &mut cloud);
        block([12.0, 4.0, 28.0, 16.0], 0.0, ROOF, &mut cloud);
        block([2.0, 7.0, 8.0, 13.0], 20.0, ROOF, &mut cloud);
        block([32.0, 7.0, 38.0, 13.0], 20.0, ROOF, &mut cloud);
        let found = sites(&cloud);
        assert!(found.iter().all(|s| s.0 > 1.0), "{found:?}");
        assert_eq!(
            found.iter().filter(|s| (s.0 - 20.0).abs() < 0.1).count(),
            2,
            "{found:?}"
        );
    }

    #[test]
    fn a_roof_beside_a_taller_one_with_ground_on_it_stays() {
        // A 20 m roof 10 m up, the lowest level of the scan (no street in it), a quarter of it
        // called ground, beside a taller, smaller roof 14 m up (fresh fused set 5858, where a
        // check that took any region over 25 m² above as the roof dropped the whole roof).
        let mut cloud = (Vec::new(), Vec::new());
        let band = |_: f64, y: f64| y > 15.0;
        grid([0.0, 0.0, 20.0, 20.0], 10.0, ROOF, band, &mut cloud);
        grid(
            [0.0, 15.05, 20.0, 20.0],
            10.0,
            GROUND,
            |x, y| !band(x, y),
            &mut cloud,
        );
        grid(
            [21.0, 0.0, 31.0, 20.0],
            14.0,
            ROOF,
            |_, _| false,
            &mut cloud,
        );
        let found = sites(&cloud);
        assert!(found.iter().any(|s| (s.0 - 10.0).abs() < 0.1), "{found:?}");
    }

    #[test]
    fn a_roof_the_model_calls_ground_in_part_stays_when_no_street_is_in_the_scan() {
        // A 14 m roof 20 m up seen alone (no street in the scan), a 4 m band of it called
        // ground, and a 3 m structure called roof standing 2.85 m above: the lowest level is
        // the roof's, with points called ground on it, but nothing larger stands above it.
        let mut cloud = (Vec::new(), Vec::new());
        let band = |_: f64, y: f64| y > 10.0;
        let top = |x: f64, y: f64| (5.3..=8.7).contains(&x) && (3.3..=6.7).contains(&y);
        grid(
            [0.0, 0.0, 14.0, 14.0],
            20.0,
            ROOF,
            |x, y| band(x, y) || top(x, y),
            &mut cloud,
        );
        grid(
            [0.0, 10.05, 14.0, 14.0],
            20.0,
            GROUND,
            |x, y| !band(x, y),
            &mut cloud,
        );
        grid([5.5, 3.5, 8.5, 6.5], 22.85, ROOF, |_, _| false, &mut cloud);
        let found = sites(&cloud);
        assert!(found.iter().any(|s| (s.0 - 20.0).abs() < 0.1), "{found:?}");
    }

    /// The lowest level of a scan that shows mostly roofs is a lower roof's (the street is under
    /// [`LOW_QUANTILE`] of the points): points classed ground far below that level are not a
    /// street at it, so the lower roof stays. (The count once took every ground point less than
    /// [`STREET_LEVEL_M`] above the level, those far below included, and dropped such roofs.)
    #[test]
    fn the_street_level_is_the_quantile_of_the_heights_around_when_it_is_near() {
        // Seeded clouds of roofs and streets at every height around z, some exactly a street
        // level below it: the count's shortcut answers as the quantile of every height does.
        let mut rng = crate::synthetic::Pcg32::new(11);
        for round in 0..400 {
            let n = 10 + (rng.next_u32() % 400) as usize;
            let z = 20.0 + rng.unit();
            // Every other round, all points near and as many a street level below as the
            // quantile's rank, one fewer or one more.
            let rank = ((n - 1) as f64 * LOW_QUANTILE).round() as usize;
            let lower = (rank + (rng.next_u32() % 3) as usize).saturating_sub(1);
            let points: Vec<[f64; 3]> = (0..n)
                .map(|i| {
                    if round % 2 == 0 {
                        let h = if i < lower {
                            z - STREET_LEVEL_M - rng.unit()
                        } else {
                            z
                        };
                        return [10.0 * rng.unit(), 10.0 * rng.unit(), h];
                    }
                    let h = match rng.next_u32() % 4 {
                        0 => z - STREET_LEVEL_M,
                        1 => z - 10.0 * rng.unit(),
                        2 => z - STREET_LEVEL_M + 0.1 * (rng.unit() - 0.5),
                        _ => z + 3.0 * (rng.unit() - 0.5),
                    };
                    [70.0 * rng.unit() - 20.0, 70.0 * rng.unit() - 20.0, h]
                })
                .collect();
            let at = [25.0 * rng.unit(), 25.0 * rng.unit()];
            let near = |p: &&[f64; 3]| {
                (p[0] - at[0]).powi(2) + (p[1] - at[1]).powi(2) <= STREET_RADIUS_M.powi(2)
            };
            let mut heights: Vec<f64> = points.iter().filter(near).map(|p| p[2]).collect();
            let want = (heights.len() >= MIN_GROUND_POINTS)
                .then(|| {
                    let k = ((heights.len() - 1) as f64 * LOW_QUANTILE).round() as usize;
                    *heights.select_nth_unstable_by(k, f64::total_cmp).1
                })
                .filter(|low| z - low < STREET_LEVEL_M);
            assert_eq!(street_level_below(&points, at, z), want, "round {round}");
        }
    }

    /// The shortcut from the ground points alone never says "no street" where the level and
    /// the classes would say "street": seeded scans of streets, low and high roofs, every class
    /// mixed in.
    #[test]
    fn the_ground_points_alone_rule_out_only_regions_that_are_no_street() {
        let mut rng = crate::synthetic::Pcg32::new(5);
        let mut streets = 0;
        for _ in 0..60 {
            let mut cloud = (Vec::new(), Vec::new());
            for _ in 0..4 {
                let (x, y) = (40.0 * rng.unit(), 40.0 * rng.unit());
                let (w, d) = (4.0 + 10.0 * rng.unit(), 4.0 + 10.0 * rng.unit());
                let z = [0.0, 0.0, 1.4, 2.9, 4.4, 20.0][(rng.next_u32() % 6) as usize];
                let class = if rng.next_u32().is_multiple_of(3) {
                    GROUND
                } else {
                    ROOF
                };
                grid([x, y, x + w, y + d], z, class, |_, _| false, &mut cloud);
            }
            let pts: Vec<[f64; 3]> = cloud.0.iter().map(|p| p.map(f64::from)).collect();
            let (regions, polygons) = regions_of(&pts, &cloud.1);
            let lowest = (regions.regions.iter()).fold(f64::INFINITY, |z, r| z.min(r.mean[2]));
            let ground = ground_points(&pts, &cloud.1, lowest);
            for r in 0..regions.regions.len() {
                if street_by_level(&regions, &polygons, r, &pts, &cloud.1) {
                    streets += 1;
                    assert!(may_be_street(regions.regions[r].mean, &ground));
                }
            }
        }
        assert!(streets > 0);
    }

    #[test]
    fn ground_far_below_the_lowest_level_is_no_street_at_it() {
        let mut cloud = (Vec::new(), Vec::new());
        grid([0.0, 0.0, 12.0, 12.0], 10.0, ROOF, |_, _| false, &mut cloud);
        grid(
            [14.0, 0.0, 34.0, 20.0],
            20.0,
            ROOF,
            |_, _| false,
            &mut cloud,
        );
        grid(
            [13.0, -3.0, 16.0, -1.0],
            0.0,
            GROUND,
            |_, _| false,
            &mut cloud,
        );
        let (points, classes) = (&cloud.0, &cloud.1);
        let street = classes.iter().filter(|&&c| c == GROUND).count();
        assert!(
            street >= MIN_GROUND_POINTS && (street as f64) < LOW_QUANTILE * points.len() as f64
        );
        let pts: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
        let (regions, polygons) = regions_of(&pts, classes);
        let lower = (regions.regions.iter())
            .position(|r| (r.mean[2] - 10.0).abs() < 0.1)
            .expect("the lower roof's region");
        assert!(!is_street_level(&regions, &polygons, lower, &pts, classes));
        assert!(sites(&cloud).iter().any(|s| (s.0 - 10.0).abs() < 0.1));
    }

    /// The regions and polygons `detect` finds in `pts`.
    fn regions_of(pts: &[[f64; 3]], classes: &[u8]) -> (Regions, Vec<Polygon>) {
        let tri = crate::triangulation::triangulate(pts).unwrap();
        let params = Params::default();
        let mask = crate::filter::filter_triangles(
            &tri,
            pts,
            Some(classes),
            &crate::filter::FilterParams::from(&params),
        );
        let regions = crate::regions::extract_regions(
            &tri,
            pts,
            mask,
            &crate::regions::RegionParams::default(),
        )
        .unwrap();
        let polygons = crate::boundary::region_polygons(
            &tri,
            pts,
            &regions,
            &crate::boundary::BoundaryParams::default(),
        )
        .unwrap();
        (regions, polygons)
    }
}
