//! Landing sites from region polygons: hole and area filters, polylabel, ranking.
//!
//! Entry point: [`rank_sites`]. Sites are ordered by safe radius (largest first), then area, then
//! region order, so ties resolve the same way on every run. Polylabel, the costly part, runs on the
//! regions in order of an upper bound of their radius (`sqrt(area / π)`: the inscribed disc fits in
//! the polygon) and stops once `max_sites` sites beat every remaining bound: the result is the same
//! as running it on every region.

use crate::boundary::{Rings, ring_is_ccw};
use crate::polylabel::{self, Disk, PolylabelParams, polylabel_in_rings};
use crate::regions::Regions;
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
    // Holes smaller than the parameter are left out.
    let small = |ring: &Vec<[f64; 2]>| ring_signed_area(ring).abs() < params.min_hole_area_m2;
    // (upper bound of the radius, region index, polygon, area) of every region that can qualify.
    let mut candidates: Vec<(f64, usize, Polygon, f64)> = Vec::new();
    for (r, mut polygon) in polygons.into_iter().enumerate() {
        if params.min_hole_area_m2 > 0.0 {
            polygon.holes.retain(|h| !small(h));
        }
        let area = polygon.area();
        if area < params.min_area_m2 {
            continue;
        }
        let bound = (area.max(0.0) / std::f64::consts::PI).sqrt();
        if bound < params.min_safe_radius_m {
            continue;
        }
        candidates.push((bound, r, polygon, area));
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));

    let mut sites: Vec<(usize, LandingSite)> = Vec::new();
    for (bound, r, polygon, area) in candidates {
        if sites.len() >= params.max_sites {
            // The max_sites-th best radius so far; nothing with a smaller bound can displace it.
            let mut radii: Vec<f64> = sites.iter().map(|s| s.1.safe_radius_m).collect();
            radii.sort_by(|a, b| b.total_cmp(a));
            if radii[params.max_sites - 1] > bound {
                break;
            }
        }
        let region = &regions.regions[r];
        let disks = keep_out.map_or_else(Vec::new, |k| {
            k.disks_on_plane(region.mean, region.normal, polygon.bounds())
        });
        let rings: Vec<&[[f64; 2]]> = match parts.and_then(|p| p[r].as_ref()) {
            // The part's holes (its clockwise rings) were not filtered above.
            Some(part) => part
                .iter()
                .filter(|ring| ring_is_ccw(ring) || !small(ring))
                .map(Vec::as_slice)
                .collect(),
            None => polylabel::rings(&polygon),
        };
        if rings.is_empty() {
            continue;
        }
        let pole = polylabel_in_rings(&rings, &disks, &params.polylabel)?;
        if pole.distance < params.min_safe_radius_m || (!disks.is_empty() && pole.distance <= 0.0) {
            continue;
        }
        let [nx, ny, nz] = region.normal;
        let [mx, my, mz] = region.mean;
        let cz = mz - (nx * (pole.center[0] - mx) + ny * (pole.center[1] - my)) / nz;
        sites.push((
            r,
            LandingSite {
                rank: 0,
                polygon,
                plane_height_m: mz,
                center: [pole.center[0], pole.center[1], cz],
                safe_radius_m: pole.distance,
                area_m2: area,
                normal: region.normal,
                point_count: region.point_count,
                triangle_count: region.triangles.len(),
            },
        ));
    }
    sites.sort_by(|a, b| {
        b.1.safe_radius_m
            .total_cmp(&a.1.safe_radius_m)
            .then(b.1.area_m2.total_cmp(&a.1.area_m2))
            .then(a.0.cmp(&b.0))
    });
    sites.truncate(params.max_sites);
    Ok(sites
        .into_iter()
        .enumerate()
        .map(|(i, (_, mut s))| {
            s.rank = i as u32 + 1;
            s
        })
        .collect())
}
