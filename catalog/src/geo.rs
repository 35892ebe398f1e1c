//! WGS-84 geometry at rooftop scale: points, polygons with holes, distances, and the questions the
//! update rule and the queries ask, answered in a local metric frame.
//!
//! Distances between points are haversine on the mean Earth sphere (the sphere PostGIS uses for
//! `geography` without the spheroid), so the two stores agree to well under a millimetre at these
//! ranges. Questions about a polygon (does a circle meet it, its area, its inscribed circle) are
//! answered in an equirectangular frame centred on the point asked about: over a few hundred metres
//! its distortion is far below a centimetre, and the catalog's sites and seen areas span tens of
//! metres. Areas that cross the antimeridian or reach a pole are not supported (they are refused at
//! validation: no ring may span more than [`MAX_SPAN_DEG`]).

use landing_geometry::polylabel::{PolylabelParams, polylabel_in_rings};

use crate::error::{Error, Result};

/// The mean radius of the WGS-84 ellipsoid, (2a + b) / 3, in metres.
pub const EARTH_RADIUS_M: f64 = 6_371_008.771_4;

/// The widest a ring may be in latitude or longitude, in degrees (about 11 km at the equator).
pub const MAX_SPAN_DEG: f64 = 0.1;

/// The most vertices one ring may have.
pub const MAX_RING_VERTICES: usize = 100_000;

/// A WGS-84 point in degrees (the proto's `GeodeticPoint`, without altitude).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LatLon {
    /// Latitude, degrees north, in [-90, 90].
    pub latitude_deg: f64,
    /// Longitude, degrees east, in [-180, 180].
    pub longitude_deg: f64,
}

impl LatLon {
    /// The point at `latitude_deg`, `longitude_deg`.
    pub const fn new(latitude_deg: f64, longitude_deg: f64) -> Self {
        LatLon {
            latitude_deg,
            longitude_deg,
        }
    }

    /// Fails naming `field.latitude_deg` or `field.longitude_deg` when either is not finite or is
    /// out of range.
    pub fn validate(&self, field: &str) -> Result<()> {
        let lat = self.latitude_deg;
        if !lat.is_finite() || !(-90.0..=90.0).contains(&lat) {
            return Err(Error::invalid(
                format!("{field}.latitude_deg"),
                format!("{lat} is not a latitude in [-90, 90]"),
            ));
        }
        let lon = self.longitude_deg;
        if !lon.is_finite() || !(-180.0..=180.0).contains(&lon) {
            return Err(Error::invalid(
                format!("{field}.longitude_deg"),
                format!("{lon} is not a longitude in [-180, 180]"),
            ));
        }
        Ok(())
    }
}

/// A polygon with holes in WGS-84: rings of points, not closed (the last point is not the first
/// again), in any orientation.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Polygon {
    /// The outer ring.
    pub exterior: Vec<LatLon>,
    /// The holes: areas inside the outer ring that are not part of the polygon.
    pub holes: Vec<Vec<LatLon>>,
}

impl Polygon {
    /// A polygon from its outer ring and holes; a closing point equal to the first is dropped.
    pub fn new(exterior: Vec<LatLon>, holes: Vec<Vec<LatLon>>) -> Self {
        Polygon {
            exterior: open_ring(exterior),
            holes: holes.into_iter().map(open_ring).collect(),
        }
    }

    /// The axis-aligned rectangle with `south_west` and `north_east` corners.
    pub fn rectangle(south_west: LatLon, north_east: LatLon) -> Self {
        let (s, w) = (south_west.latitude_deg, south_west.longitude_deg);
        let (n, e) = (north_east.latitude_deg, north_east.longitude_deg);
        Polygon::new(
            vec![
                LatLon::new(s, w),
                LatLon::new(s, e),
                LatLon::new(n, e),
                LatLon::new(n, w),
            ],
            vec![],
        )
    }

    /// Every ring: the outer one first, then the holes.
    pub fn rings(&self) -> impl Iterator<Item = &[LatLon]> {
        std::iter::once(self.exterior.as_slice()).chain(self.holes.iter().map(Vec::as_slice))
    }

    /// Fails naming the bad point (`field.exterior[3].latitude_deg`) or ring: every point valid,
    /// every ring at least three distinct points, no more than [`MAX_RING_VERTICES`], spanning no
    /// more than [`MAX_SPAN_DEG`].
    pub fn validate(&self, field: &str) -> Result<()> {
        validate_ring(&self.exterior, &format!("{field}.exterior"))?;
        for (i, hole) in self.holes.iter().enumerate() {
            validate_ring(hole, &format!("{field}.holes[{i}]"))?;
        }
        Ok(())
    }

    /// The area in square metres: the outer ring's less its holes'.
    pub fn area_m2(&self) -> f64 {
        let Some(&origin) = self.exterior.first() else {
            return 0.0;
        };
        let frame = LocalFrame::new(origin);
        let outer = ring_signed_area(&frame.ring(&self.exterior)).abs();
        let holes: f64 = self
            .holes
            .iter()
            .map(|h| ring_signed_area(&frame.ring(h)).abs())
            .sum();
        (outer - holes).max(0.0)
    }

    /// The polygon's bounding box.
    pub fn bbox(&self) -> Bbox {
        let mut b = Bbox::EMPTY;
        for p in &self.exterior {
            b = b.including(*p);
        }
        b
    }

    /// Whether the closed disc of `radius_m` around `center` meets the polygon (shares a point
    /// with its interior or boundary).
    pub fn meets_circle(&self, center: LatLon, radius_m: f64) -> bool {
        let frame = LocalFrame::new(center);
        let shell = frame.ring(&self.exterior);
        let holes: Vec<_> = self.holes.iter().map(|h| frame.ring(h)).collect();
        if point_in_ring(&shell, (0.0, 0.0)) && !holes.iter().any(|h| point_in_ring(h, (0.0, 0.0)))
        {
            return true;
        }
        std::iter::once(&shell)
            .chain(holes.iter())
            .any(|ring| ring_distance((0.0, 0.0), ring) <= radius_m)
    }

    /// The pole of inaccessibility: the point inside the polygon farthest from its boundary and
    /// holes, with that distance in metres, found to within `precision_m` (polylabel's cell search).
    pub fn inscribed_circle(&self, precision_m: f64) -> (LatLon, f64) {
        let Some(&origin) = self.exterior.first() else {
            return (LatLon::default(), 0.0);
        };
        let frame = LocalFrame::new(origin);
        let rings: Vec<Vec<[f64; 2]>> = self
            .rings()
            .map(|r| frame.ring(r).into_iter().map(|(x, y)| [x, y]).collect())
            .collect();
        let ring_refs: Vec<&[[f64; 2]]> = rings.iter().map(Vec::as_slice).collect();
        let params = PolylabelParams {
            precision_m: precision_m.max(landing_geometry::MIN_POLYLABEL_PRECISION_M),
            ..PolylabelParams::default()
        };
        match polylabel_in_rings(&ring_refs, &[], &params) {
            Ok(pole) => (
                frame.to_lat_lon((pole.center[0], pole.center[1])),
                pole.distance,
            ),
            // The search ran out of cells: no circle is claimed.
            Err(_) => (origin, 0.0),
        }
    }
}

/// A latitude/longitude box; [`Bbox::EMPTY`] contains nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bbox {
    /// Southern edge, degrees.
    pub min_lat: f64,
    /// Northern edge, degrees.
    pub max_lat: f64,
    /// Western edge, degrees.
    pub min_lon: f64,
    /// Eastern edge, degrees.
    pub max_lon: f64,
}

impl Bbox {
    /// The box that contains nothing; any point widens it to that point.
    pub const EMPTY: Bbox = Bbox {
        min_lat: f64::INFINITY,
        max_lat: f64::NEG_INFINITY,
        min_lon: f64::INFINITY,
        max_lon: f64::NEG_INFINITY,
    };

    /// The box around the disc of `radius_m` about `center` (clamped to the globe's ranges).
    pub fn around(center: LatLon, radius_m: f64) -> Bbox {
        let dlat = (radius_m / EARTH_RADIUS_M).to_degrees();
        let cos = center.latitude_deg.to_radians().cos().max(1e-6);
        let dlon = (dlat / cos).min(360.0);
        Bbox {
            min_lat: (center.latitude_deg - dlat).max(-90.0),
            max_lat: (center.latitude_deg + dlat).min(90.0),
            min_lon: (center.longitude_deg - dlon).max(-180.0),
            max_lon: (center.longitude_deg + dlon).min(180.0),
        }
    }

    /// Whether the box contains nothing.
    pub fn is_empty(&self) -> bool {
        !(self.min_lat <= self.max_lat && self.min_lon <= self.max_lon)
    }

    /// This box widened to hold `p`.
    pub fn including(self, p: LatLon) -> Bbox {
        Bbox {
            min_lat: self.min_lat.min(p.latitude_deg),
            max_lat: self.max_lat.max(p.latitude_deg),
            min_lon: self.min_lon.min(p.longitude_deg),
            max_lon: self.max_lon.max(p.longitude_deg),
        }
    }

    /// The smallest box holding both.
    pub fn union(self, o: Bbox) -> Bbox {
        Bbox {
            min_lat: self.min_lat.min(o.min_lat),
            max_lat: self.max_lat.max(o.max_lat),
            min_lon: self.min_lon.min(o.min_lon),
            max_lon: self.max_lon.max(o.max_lon),
        }
    }

    /// Whether the two boxes share a point.
    pub fn intersects(&self, o: &Bbox) -> bool {
        self.min_lat <= o.max_lat
            && o.min_lat <= self.max_lat
            && self.min_lon <= o.max_lon
            && o.min_lon <= self.max_lon
    }

    /// This box widened by `m` metres on every side (measured at its widest latitude).
    pub fn padded_m(self, m: f64) -> Bbox {
        if self.is_empty() {
            return self;
        }
        let dlat = (m / EARTH_RADIUS_M).to_degrees();
        let widest = self.min_lat.abs().max(self.max_lat.abs()).min(89.999);
        let dlon = (dlat / widest.to_radians().cos()).min(360.0);
        Bbox {
            min_lat: (self.min_lat - dlat).max(-90.0),
            max_lat: (self.max_lat + dlat).min(90.0),
            min_lon: (self.min_lon - dlon).max(-180.0),
            max_lon: (self.max_lon + dlon).min(180.0),
        }
    }
}

/// The great-circle distance in metres between two points (haversine on [`EARTH_RADIUS_M`]).
pub fn distance_m(a: LatLon, b: LatLon) -> f64 {
    let (la, lb) = (a.latitude_deg.to_radians(), b.latitude_deg.to_radians());
    let dlat = lb - la;
    let dlon = (b.longitude_deg - a.longitude_deg).to_radians();
    let h = (dlat / 2.0).sin().powi(2) + la.cos() * lb.cos() * (dlon / 2.0).sin().powi(2);
    2.0 * EARTH_RADIUS_M * h.sqrt().min(1.0).asin()
}

/// An equirectangular frame in metres (x east, y north) around an origin.
#[derive(Debug, Clone, Copy)]
pub struct LocalFrame {
    origin: LatLon,
    m_per_deg_lon: f64,
    m_per_deg_lat: f64,
}

impl LocalFrame {
    /// The frame centred on `origin`.
    pub fn new(origin: LatLon) -> Self {
        let m_per_deg_lat = EARTH_RADIUS_M.to_radians().abs();
        LocalFrame {
            origin,
            m_per_deg_lat,
            m_per_deg_lon: m_per_deg_lat * origin.latitude_deg.to_radians().cos(),
        }
    }

    /// `p` in metres east and north of the origin.
    pub fn to_xy(&self, p: LatLon) -> (f64, f64) {
        (
            (p.longitude_deg - self.origin.longitude_deg) * self.m_per_deg_lon,
            (p.latitude_deg - self.origin.latitude_deg) * self.m_per_deg_lat,
        )
    }

    /// The point `xy` metres east and north of the origin.
    pub fn to_lat_lon(&self, (x, y): (f64, f64)) -> LatLon {
        LatLon::new(
            self.origin.latitude_deg + y / self.m_per_deg_lat,
            self.origin.longitude_deg + x / self.m_per_deg_lon.max(1e-9),
        )
    }

    fn ring(&self, ring: &[LatLon]) -> Vec<(f64, f64)> {
        ring.iter().map(|p| self.to_xy(*p)).collect()
    }
}

/// The signed area of a ring in lon/lat degrees (planar): positive when counter-clockwise (east
/// right, north up). The GeoJSON writer orients rings with it.
pub fn ring_orientation(ring: &[LatLon]) -> f64 {
    let pts: Vec<(f64, f64)> = ring
        .iter()
        .map(|p| (p.longitude_deg, p.latitude_deg))
        .collect();
    ring_signed_area(&pts)
}

fn open_ring(mut ring: Vec<LatLon>) -> Vec<LatLon> {
    if ring.len() > 1 && ring.first() == ring.last() {
        ring.pop();
    }
    ring
}

fn validate_ring(ring: &[LatLon], field: &str) -> Result<()> {
    if ring.len() > MAX_RING_VERTICES {
        return Err(Error::invalid(
            field,
            format!("{} points, more than {MAX_RING_VERTICES}", ring.len()),
        ));
    }
    for (i, p) in ring.iter().enumerate() {
        p.validate(&format!("{field}[{i}]"))?;
    }
    let mut distinct: Vec<(u64, u64)> = ring
        .iter()
        .map(|p| (p.latitude_deg.to_bits(), p.longitude_deg.to_bits()))
        .collect();
    distinct.sort_unstable();
    distinct.dedup();
    if distinct.len() < 3 {
        return Err(Error::invalid(
            field,
            format!(
                "a ring needs at least 3 distinct points, it has {}",
                distinct.len()
            ),
        ));
    }
    let b = ring.iter().fold(Bbox::EMPTY, |b, p| b.including(*p));
    if b.max_lat - b.min_lat > MAX_SPAN_DEG || b.max_lon - b.min_lon > MAX_SPAN_DEG {
        return Err(Error::invalid(
            field,
            format!(
                "the ring spans more than {MAX_SPAN_DEG} degrees (or crosses the antimeridian)"
            ),
        ));
    }
    Ok(())
}

fn ring_signed_area(ring: &[(f64, f64)]) -> f64 {
    let n = ring.len();
    let mut twice = 0.0;
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        twice += a.0 * b.1 - b.0 * a.1;
    }
    twice / 2.0
}

/// Even-odd crossing test; a point on an edge may fall either way (callers also test distance).
fn point_in_ring(ring: &[(f64, f64)], (x, y): (f64, f64)) -> bool {
    let n = ring.len();
    let mut inside = false;
    let mut j = n.wrapping_sub(1);
    for i in 0..n {
        let (xi, yi) = ring[i];
        let (xj, yj) = ring[j];
        if (yi > y) != (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi {
            inside = !inside;
        }
        j = i;
    }
    inside
}

fn segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let (cx, cy) = (a.0 + t * dx, a.1 + t * dy);
    ((p.0 - cx).powi(2) + (p.1 - cy).powi(2)).sqrt()
}

fn ring_distance(p: (f64, f64), ring: &[(f64, f64)]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| segment_distance(p, ring[i], ring[(i + 1) % n]))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(center: LatLon, half_m: f64) -> Polygon {
        let f = LocalFrame::new(center);
        Polygon::rectangle(
            f.to_lat_lon((-half_m, -half_m)),
            f.to_lat_lon((half_m, half_m)),
        )
    }

    const MANHATTAN: LatLon = LatLon::new(40.7484, -73.9857);

    #[test]
    fn haversine_matches_known_distances() {
        // One degree of latitude on the mean sphere.
        let d = distance_m(LatLon::new(0.0, 0.0), LatLon::new(1.0, 0.0));
        assert!((d - 111_195.08).abs() < 0.1, "{d}");
        // The local frame agrees with haversine to millimetres over 200 m.
        let f = LocalFrame::new(MANHATTAN);
        let p = f.to_lat_lon((120.0, -160.0));
        assert!((distance_m(MANHATTAN, p) - 200.0).abs() < 0.005);
    }

    #[test]
    fn area_of_a_square_with_a_hole() {
        let outer = square(MANHATTAN, 10.0);
        let hole = square(MANHATTAN, 2.0);
        let p = Polygon::new(outer.exterior, vec![hole.exterior]);
        assert!((p.area_m2() - 384.0).abs() < 0.01, "{}", p.area_m2());
    }

    #[test]
    fn circle_meets_polygon_inside_near_and_in_hole() {
        let f = LocalFrame::new(MANHATTAN);
        let outer = square(MANHATTAN, 10.0);
        let hole = square(MANHATTAN, 4.0);
        let p = Polygon::new(outer.exterior, vec![hole.exterior]);
        assert!(p.meets_circle(f.to_lat_lon((7.0, 0.0)), 0.1)); // in the ring of roof
        assert!(!p.meets_circle(MANHATTAN, 3.9)); // inside the hole, clear of its edge
        assert!(p.meets_circle(MANHATTAN, 4.1)); // reaches the hole's edge
        assert!(!p.meets_circle(f.to_lat_lon((13.0, 0.0)), 2.9)); // outside, clear
        assert!(p.meets_circle(f.to_lat_lon((13.0, 0.0)), 3.1)); // outside, reaching in
    }

    #[test]
    fn inscribed_circle_of_a_rectangle() {
        let f = LocalFrame::new(MANHATTAN);
        let p = Polygon::rectangle(f.to_lat_lon((0.0, 0.0)), f.to_lat_lon((30.0, 10.0)));
        let (c, r) = p.inscribed_circle(0.05);
        assert!((r - 5.0).abs() < 0.06, "{r}");
        let (x, y) = f.to_xy(c);
        assert!(
            (y - 5.0).abs() < 0.1 && (5.0..=25.0).contains(&x),
            "{x} {y}"
        );
    }

    #[test]
    fn validation_names_the_point() {
        let mut p = square(MANHATTAN, 5.0);
        p.exterior[2].latitude_deg = f64::NAN;
        let e = p.validate("site.polygon").unwrap_err();
        assert_eq!(e.field(), Some("site.polygon.exterior[2].latitude_deg"));
        let two = Polygon::new(vec![MANHATTAN, MANHATTAN, LatLon::new(40.0, -73.0)], vec![]);
        assert_eq!(two.validate("p").unwrap_err().field(), Some("p.exterior"));
    }

    #[test]
    fn box_around_a_circle_holds_it() {
        let b = Bbox::around(MANHATTAN, 100.0);
        let f = LocalFrame::new(MANHATTAN);
        for (x, y) in [(99.9, 0.0), (-99.9, 0.0), (0.0, 99.9), (0.0, -99.9)] {
            let p = f.to_lat_lon((x, y));
            assert!(b.intersects(&Bbox::EMPTY.including(p)));
        }
    }
}
