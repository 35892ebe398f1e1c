//! Where a simulated world lies on the Earth: WGS-84 positions of its local ENU frame, and the
//! Manhattan places of the scenario worlds.
//!
//! A world's frame is local east-north-up, metres, with its origin at a [`Geodetic`] position;
//! [`enu_to_geodetic`] is `landing_geometry`'s, the one the server puts latitude and longitude on
//! its sites with, so the simulator's footprints and the service's sites agree exactly.
//!
//! [`scenario_origin`] places the world of a seed on the Manhattan blocks of the paper's rooftop
//! analysis: a grid of [`GRID_ACROSS`] × [`GRID_ALONG`] cells [`CELL_M`] apart, laid along the
//! avenues (29° east of true north) and centred on Midtown ([`MIDTOWN`]); world seed `s` takes
//! cell `s mod 60`, so any 60 consecutive seeds lie in different cells, which never overlap for
//! worlds up to [`max_world_extent_m`] across.
//!
//! ```
//! use landing_sim::geodetic::{enu_to_geodetic, scenario_origin};
//!
//! let o = scenario_origin(2026);
//! assert!((o.latitude_deg - 40.75).abs() < 0.05 && (o.longitude_deg + 73.98).abs() < 0.05);
//! // 1 km north is about 0.009° of latitude.
//! let north = enu_to_geodetic(o, [0.0, 1000.0, 0.0]);
//! assert!((north.latitude_deg - o.latitude_deg - 0.009).abs() < 0.0002);
//! ```

use landing_proto::v1;

pub use landing_geometry::geodetic::{
    Geodetic, ecef_to_geodetic, enu_to_geodetic, geodetic_to_ecef,
};

/// `g` as the API carries it (`Frame.geodetic_origin`).
pub fn geodetic_point(g: Geodetic) -> v1::GeodeticPoint {
    v1::GeodeticPoint {
        latitude_deg: g.latitude_deg,
        longitude_deg: g.longitude_deg,
        altitude_m: g.altitude_m,
    }
}

/// The centre of the scenario grid: Midtown Manhattan, by Bryant Park. The altitude is 0: a
/// world's ground lies on the ellipsoid, so a roof's height above its ground is also its
/// altitude (the footprints say so with `ground_elevation_m`).
pub const MIDTOWN: Geodetic = Geodetic {
    latitude_deg: 40.7536,
    longitude_deg: -73.9832,
    altitude_m: 0.0,
};

/// Spacing of the scenario grid's cells, metres.
pub const CELL_M: f64 = 500.0;
/// Cells across the island (perpendicular to the avenues).
pub const GRID_ACROSS: u64 = 3;
/// Cells along the avenues (10 km in all, from about Canal Street to 96th Street).
pub const GRID_ALONG: u64 = 20;
/// Bearing of Manhattan's avenues, degrees east of true north.
pub const AVENUE_BEARING_DEG: f64 = 29.0;

/// The WGS-84 origin of the scenario world of `world_seed` (see the module docs).
pub fn scenario_origin(world_seed: u64) -> Geodetic {
    // The ground is level with Midtown's: not lower where the Earth curves away from its plane.
    Geodetic {
        altitude_m: MIDTOWN.altitude_m,
        ..enu_to_geodetic(MIDTOWN, cell_offset(world_seed))
    }
}

/// The ENU offset from [`MIDTOWN`] of the cell of `world_seed`, metres.
fn cell_offset(world_seed: u64) -> [f64; 3] {
    let cell = world_seed % (GRID_ACROSS * GRID_ALONG);
    let across = (cell % GRID_ACROSS) as f64 - (GRID_ACROSS / 2) as f64;
    let along = (cell / GRID_ACROSS) as f64 - (GRID_ALONG / 2) as f64;
    let (s, c) = AVENUE_BEARING_DEG.to_radians().sin_cos();
    // Along the avenues: (sin, cos) in (east, north); across: (cos, -sin).
    let e = CELL_M * (along * s + across * c);
    let n = CELL_M * (along * c - across * s);
    [e, n, 0.0]
}

/// The widest world (along x or y from its origin, metres) whose square never overlaps another
/// cell's: the smallest Chebyshev distance between two cells of the grid (about 437 m).
pub fn max_world_extent_m() -> f64 {
    let mut best = f64::INFINITY;
    for a in 0..GRID_ACROSS * GRID_ALONG {
        let p = cell_offset(a);
        for b in a + 1..GRID_ACROSS * GRID_ALONG {
            let q = cell_offset(b);
            best = best.min((p[0] - q[0]).abs().max((p[1] - q[1]).abs()));
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::WorldConfig;

    #[test]
    fn ecef_round_trip_and_local_distances() {
        let g = scenario_origin(7);
        let back = ecef_to_geodetic(geodetic_to_ecef(g));
        assert!((back.latitude_deg - g.latitude_deg).abs() < 1e-12);
        assert!((back.longitude_deg - g.longitude_deg).abs() < 1e-12);
        assert!(back.altitude_m.abs() < 1e-6 && g.altitude_m == 0.0);
        // 300 m east and 200 m north, 40 m up, measured back through ECEF.
        let p = enu_to_geodetic(g, [300.0, 200.0, 40.0]);
        let (a, b) = (geodetic_to_ecef(g), geodetic_to_ecef(p));
        let d = ((0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>()).sqrt();
        let want = (300f64.powi(2) + 200f64.powi(2) + 40f64.powi(2)).sqrt();
        assert!((d - want).abs() < 1e-6, "{d} vs {want}");
        assert!((p.altitude_m - 40.0).abs() < 0.02, "{}", p.altitude_m);
        assert!(p.longitude_deg > g.longitude_deg && p.latitude_deg > g.latitude_deg);
    }

    #[test]
    fn scenario_worlds_lie_on_manhattan_in_separate_cells() {
        let extent = {
            let c = WorldConfig::default();
            f64::from(c.blocks_x.max(c.blocks_y)) * (c.block_size_m + c.street_width_m)
        };
        let room = max_world_extent_m();
        assert!(
            room > extent + 100.0,
            "{room} m of room for {extent} m worlds"
        );
        let mut seen = std::collections::HashSet::new();
        for seed in 2026..2026 + GRID_ACROSS * GRID_ALONG {
            let o = scenario_origin(seed);
            assert!(
                seen.insert(o.latitude_deg.to_bits()),
                "seed {seed} shares a cell"
            );
            // Lower to Upper Manhattan, Hudson to East River.
            assert!((40.70..40.82).contains(&o.latitude_deg), "{o:?}");
            assert!((-74.03..-73.92).contains(&o.longitude_deg), "{o:?}");
        }
        assert_eq!(scenario_origin(5), scenario_origin(65));
    }
}
