//! Landing sites from region polygons: hole and area filters, polylabel, ranking.
//!
//! Entry point: [`rank_sites`]. Sites are ordered by safe radius (largest first), then area, then
//! region order, so ties resolve the same way on every run. Polylabel, the costly part, runs on the
//! regions in order of an upper bound of their radius (`sqrt(area / π)`: the inscribed disc fits in
//! the polygon) and stops once `max_sites` sites beat every remaining bound: the result is the same
//! as running it on every region.

use crate::boundary::{Rings, ring_is_ccw};
use crate::polylabel::{self, Disk, PolylabelParams, polylabel_in_rings};
use crate::regions::{Region, Regions};
use crate::validation::ring_signed_area;
use crate::{GeometryError, LandingSite, Params, Polygon};

/// Parameters of [`rank_sites`]; `Default` gives the paper's values.
#[derive(Debug, Clone, PartialEq)]
pub struct RankingParams {
    pub polylabel: PolylabelParams,
    /// Sites with a smaller safe radius are dropped, metres.
    pub min_safe_radius_m: f64,
    /// Sites with a smaller area (after hole removal) are dropped, square metres.
    pub min_area_m2: f64,
    /// Holes smaller than this are removed from the polygon before polylabel, square metres.
    pub min_hole_area_m2: f64,
    /// At most this many sites are returned.
    pub max_sites: usize,
}

impl Default for RankingParams {
    fn default() -> Self {
        Self::from(&Params::default())
    }
}

impl From<&Params> for RankingParams {
    fn from(p: &Params) -> Self {
        Self {
            polylabel: PolylabelParams {
                precision_m: p.polylabel_precision_m,
                ..PolylabelParams::default()
            },
            min_safe_radius_m: p.min_safe_radius_m,
            min_area_m2: p.min_area_m2,
            min_hole_area_m2: p.min_hole_area_m2,
            max_sites: p.max_sites,
        }
    }
}

/// Obstacles that the point cloud missed (seen by the camera, say), as keep-out disks on a
/// landing plane: a site's safe circle stays clear of them.
pub trait KeepOut {
    /// The disks (world x/y) on the plane through `point` with unit `normal` (z up) that reach
    /// into `bounds` (`[min x, min y, max x, max y]`, the polygon's box); others may be left out.
    fn disks_on_plane(&self, point: [f64; 3], normal: [f64; 3], bounds: [f64; 4]) -> Vec<Disk>;

    /// [`KeepOut::disks_on_plane`] for a caller that wants fewer: every disk lying wholly within
    /// a finite box (same layout) that `wanted` refuses may be left out too, so that a source
    /// can skip whole groups of disks at once. By default, `disks_on_plane`.
    fn wanted_disks_on_plane(
        &self,
        point: [f64; 3],
        normal: [f64; 3],
        bounds: [f64; 4],
        wanted: &dyn Fn(&[f64; 4]) -> bool,
    ) -> Vec<Disk> {
        let _ = wanted;
        self.disks_on_plane(point, normal, bounds)
    }
}

impl<F: Fn([f64; 3], [f64; 3], [f64; 4]) -> Vec<Disk>> KeepOut for F {
    fn disks_on_plane(&self, point: [f64; 3], normal: [f64; 3], bounds: [f64; 4]) -> Vec<Disk> {
        self(point, normal, bounds)
    }
}

/// What a safe circle keeps clear of besides its polygon's boundary. `Default` is nothing.
#[derive(Clone, Copy, Default)]
pub struct KeepClear<'a> {
    /// Obstacles the points missed, as disks per plane.
    pub disks: Option<&'a dyn KeepOut>,
    /// One flag per point: a safe circle keeps off every triangle with a flagged vertex (ground
    /// not yet known well enough to land on, for example what no camera has seen finely). The
    /// polygons still hold those triangles.
    pub points: Option<&'a [bool]>,
}

/// Turns the polygons of `regions` (one each, same order) into ranked landing sites, each safe
/// circle also clear of what `keep_out` gives for its plane and, where `parts` has rings for the
/// region (see [`crate::boundary::region_parts`]), inside them; a polygon that the keep-out disks
/// cover entirely, or whose part is empty, gives no site.
pub fn rank_sites(
    regions: &Regions,
    polygons: Vec<Polygon>,
    parts: Option<&[Option<Rings>]>,
    params: &RankingParams,
    keep_out: Option<&dyn KeepOut>,
) -> Result<Vec<LandingSite>, GeometryError> {
    if polygons.len() != regions.regions.len()
        || parts.is_some_and(|p| p.len() != regions.regions.len())
    {
        return Err(GeometryError::InvalidMesh {
            reason: format!(
                "{} polygons and {} parts for {} regions",
                polygons.len(),
                parts.map_or(polygons.len(), <[_]>::len),
                regions.regions.len()
            ),
        });
    }
    let mut sites: Vec<(usize, LandingSite)> = Vec::new();
    for c in candidates(polygons, params) {
        if sites.len() >= params.max_sites {
            // The max_sites-th best radius so far; nothing with a smaller bound can displace it.
            let mut radii: Vec<f64> = sites.iter().map(|s| s.1.safe_radius_m).collect();
            radii.sort_by(|a, b| b.total_cmp(a));
            if radii[params.max_sites - 1] > c.bound {
                break;
            }
        }
        let r = c.region;
        let part = parts.and_then(|p| p[r].as_ref());
        if let Some(site) = site_of(&regions.regions[r], c, part, keep_out, params)? {
            sites.push((r, site));
        }
    }
    Ok(ranked(sites, params.max_sites))
}

/// A region's polygon that can qualify, with the upper bound of its safe radius.
struct Candidate {
    bound: f64,
    region: usize,
    polygon: Polygon,
    area: f64,
}

/// Holes smaller than [`RankingParams::min_hole_area_m2`] are left out.
fn is_small(ring: &[[f64; 2]], params: &RankingParams) -> bool {
    ring_signed_area(ring).abs() < params.min_hole_area_m2
}

/// The polygons, less their small holes, whose area and radius bound can pass the filters,
/// largest bound first (then in region order).
fn candidates(polygons: Vec<Polygon>, params: &RankingParams) -> Vec<Candidate> {
    let mut candidates = Vec::new();
    for (region, mut polygon) in polygons.into_iter().enumerate() {
        if params.min_hole_area_m2 > 0.0 {
            polygon.holes.retain(|h| !is_small(h, params));
        }
        let area = polygon.area();
        if area < params.min_area_m2 {
            continue;
        }
        let bound = (area.max(0.0) / std::f64::consts::PI).sqrt();
        if bound < params.min_safe_radius_m {
            continue;
        }
        candidates.push(Candidate {
            bound,
            region,
            polygon,
            area,
        });
    }
    candidates.sort_by(|a, b| b.bound.total_cmp(&a.bound).then(a.region.cmp(&b.region)));
    candidates
}

/// The candidate's site: polylabel in its `part` (or its polygon), clear of the keep-out disks
/// on its plane; `None` when the circle is too small or there is nothing to put it in.
fn site_of(
    region: &Region,
    candidate: Candidate,
    part: Option<&Rings>,
    keep_out: Option<&dyn KeepOut>,
    params: &RankingParams,
) -> Result<Option<LandingSite>, GeometryError> {
    let Candidate { polygon, area, .. } = candidate;
    let disks = keep_out.map_or_else(Vec::new, |k| {
        k.disks_on_plane(region.mean, region.normal, polygon.bounds())
    });
    let rings: Vec<&[[f64; 2]]> = match part {
        // The part's holes (its clockwise rings) were not filtered above.
        Some(part) => part
            .iter()
            .filter(|ring| ring_is_ccw(ring) || !is_small(ring, params))
            .map(Vec::as_slice)
            .collect(),
        None => polylabel::rings(&polygon),
    };
    if rings.is_empty() {
        return Ok(None);
    }
    let pole = polylabel_in_rings(&rings, &disks, &params.polylabel)?;
    if pole.distance < params.min_safe_radius_m || (!disks.is_empty() && pole.distance <= 0.0) {
        return Ok(None);
    }
    let [nx, ny, nz] = region.normal;
    let [mx, my, mz] = region.mean;
    let cz = mz - (nx * (pole.center[0] - mx) + ny * (pole.center[1] - my)) / nz;
    Ok(Some(LandingSite {
        rank: 0,
        polygon,
        plane_height_m: mz,
        center: [pole.center[0], pole.center[1], cz],
        safe_radius_m: pole.distance,
        area_m2: area,
        normal: region.normal,
        point_count: region.point_count,
        triangle_count: region.triangles.len(),
    }))
}

/// The best `max_sites` of the (region index, site) pairs, ranked: by safe radius, then area,
/// then region order.
fn ranked(mut sites: Vec<(usize, LandingSite)>, max_sites: usize) -> Vec<LandingSite> {
    sites.sort_by(|a, b| {
        b.1.safe_radius_m
            .total_cmp(&a.1.safe_radius_m)
            .then(b.1.area_m2.total_cmp(&a.1.area_m2))
            .then(a.0.cmp(&b.0))
    });
    sites.truncate(max_sites);
    sites
        .into_iter()
        .enumerate()
        .map(|(i, (_, mut s))| {
            s.rank = i as u32 + 1;
            s
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::Pcg32;

    #[test]
    fn the_sites_are_those_of_every_region_ranked() {
        // Seeded squares and L-shapes of every size, some holed, and keep-out disks on them: the
        // search that stops once the best sites beat every remaining bound keeps what judging
        // every region and ranking them keeps.
        let mut rng = Pcg32::new(5);
        for round in 0..60 {
            let n = 1 + (rng.next_u32() % 14) as usize;
            let mut polygons = Vec::new();
            let mut regions = Regions::default();
            for i in 0..n {
                let (x, y, side) = (30.0 * i as f64, 5.0 * rng.unit(), 0.5 + 12.0 * rng.unit());
                let mut shell = vec![[x, y], [x + side, y], [x + side, y + side], [x, y + side]];
                if rng.next_u32().is_multiple_of(2) {
                    shell.insert(3, [x + side / 2.0, y + side]);
                    shell.insert(4, [x + side / 2.0, y + side / 2.0]);
                    shell[5] = [x, y + side / 2.0];
                }
                let holes = if rng.next_u32().is_multiple_of(3) {
                    let (hx, hy) = (x + side / 4.0, y + side / 8.0);
                    let s = side / 10.0;
                    vec![vec![[hx, hy], [hx, hy + s], [hx + s, hy + s], [hx + s, hy]]]
                } else {
                    Vec::new()
                };
                polygons.push(Polygon { shell, holes });
                regions.regions.push(Region {
                    triangles: vec![i as u32],
                    mean: [x, y, 10.0],
                    normal: [0.0, 0.0, 1.0],
                    point_count: 3,
                });
            }
            let disks: Vec<Disk> = (0..(rng.next_u32() % 30))
                .map(|_| Disk {
                    center: [30.0 * n as f64 * rng.unit(), 15.0 * rng.unit()],
                    radius: 2.0 * rng.unit(),
                })
                .collect();
            let keep_out = |_: [f64; 3], _: [f64; 3], _: [f64; 4]| disks.clone();
            let params = RankingParams {
                max_sites: 1 + (rng.next_u32() % 5) as usize,
                min_hole_area_m2: 0.05,
                ..RankingParams::default()
            };
            let found = rank_sites(&regions, polygons.clone(), None, &params, Some(&keep_out));
            let every: Vec<(usize, LandingSite)> = candidates(polygons, &params)
                .into_iter()
                .filter_map(|c| {
                    let r = c.region;
                    site_of(&regions.regions[r], c, None, Some(&keep_out), &params)
                        .unwrap()
                        .map(|s| (r, s))
                })
                .collect();
            let want = ranked(every, params.max_sites);
            assert_eq!(found.unwrap(), want, "round {round}");
        }
    }
}
