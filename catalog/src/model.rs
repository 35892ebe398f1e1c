//! The catalog's records: what is stored ([`Site`]), what a fused approach reports
//! ([`Observation`]) and what is imported beforehand ([`Candidate`]).

use crate::error::{Error, Result};
use crate::geo::{Bbox, LatLon, Polygon};
use crate::time::Timestamp;

/// The largest safe radius or roof dimension the catalog accepts, in metres.
pub const MAX_RADIUS_M: f64 = 5_000.0;

/// The plane heights the catalog accepts, in metres (WGS-84 ellipsoidal or local: the catalog only
/// compares them): from below the Dead Sea to above any building.
pub const PLANE_HEIGHT_RANGE_M: std::ops::RangeInclusive<f64> = -1_000.0..=10_000.0;

/// The longest drone, approach, model or source id, in bytes.
pub const MAX_ID_BYTES: usize = 256;

/// A stored record's id, assigned by the store.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SiteId(pub i64);

/// Whether a record is a landing site a drone confirmed or a roof known beforehand.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SiteKind {
    /// Seen safe by a fused approach: the safe circle was free when `last_confirmed`.
    Confirmed,
    /// An imported building footprint with its roof height: never seen by the fleet, never a site.
    /// Its circle is the footprint's inscribed circle, an upper bound on any safe circle there.
    Candidate,
}

/// A catalog record in WGS-84.
///
/// For a [`SiteKind::Candidate`], `first_seen` and `last_confirmed` are the import time, `frames`
/// and `approaches` are 0, `drone_id`, `approach_id` and `model_id` are empty, and `source_id` is
/// the GeoJSON feature's `id` when it had one.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    /// The store's id.
    pub id: SiteId,
    /// Confirmed site or candidate roof.
    pub kind: SiteKind,
    /// The landable polygon with its holes (a candidate: the building footprint).
    pub polygon: Polygon,
    /// The safest point: farthest from every edge and obstacle.
    pub center: LatLon,
    /// The distance from `center` to the nearest edge or obstacle, metres.
    pub safe_radius_m: f64,
    /// The roof plane's height (altitude), metres.
    pub plane_height_m: f64,
    /// The polygon's area, square metres.
    pub area_m2: f64,
    /// When the fleet first saw this roof's site (kept across updates).
    pub first_seen: Timestamp,
    /// When an approach last saw it free.
    pub last_confirmed: Timestamp,
    /// How many frames confirmed it, over all approaches.
    pub frames: u64,
    /// How many approaches confirmed it: counted when the confirming approach differs from the
    /// one before (only the last is stored), so two approaches confirming one roof in turn count
    /// each turn.
    pub approaches: u64,
    /// The drone that last confirmed it.
    pub drone_id: String,
    /// The approach (stream) that last confirmed it.
    pub approach_id: String,
    /// The segmentation model that last confirmed it.
    pub model_id: String,
    /// A candidate's id in the file it came from (re-importing the same id replaces it).
    pub source_id: Option<String>,
}

impl Site {
    /// Fails naming the first bad field under `field` (for [`crate::Store::load_sites`]).
    pub(crate) fn validate(&self, field: &str) -> Result<()> {
        self.polygon.validate(&format!("{field}.polygon"))?;
        self.center.validate(&format!("{field}.center"))?;
        if !(self.safe_radius_m.is_finite() && self.safe_radius_m >= 0.0)
            || self.safe_radius_m > MAX_RADIUS_M
        {
            return Err(Error::invalid(
                format!("{field}.safe_radius_m"),
                format!(
                    "{} is not a radius in [0, {MAX_RADIUS_M}] m",
                    self.safe_radius_m
                ),
            ));
        }
        check_height(self.plane_height_m, &format!("{field}.plane_height_m"))?;
        if !(self.area_m2.is_finite() && self.area_m2 >= 0.0) {
            return Err(Error::invalid(
                format!("{field}.area_m2"),
                format!("{} is not an area >= 0", self.area_m2),
            ));
        }
        check_id(&self.drone_id, &format!("{field}.drone_id"))?;
        check_id(&self.approach_id, &format!("{field}.approach_id"))?;
        check_id(&self.model_id, &format!("{field}.model_id"))?;
        if let Some(id) = &self.source_id {
            check_id(id, &format!("{field}.source_id"))?;
        }
        Ok(())
    }

    /// The box the stores index a record by: its polygon's and its safe circle's.
    pub fn bbox(&self) -> Bbox {
        self.polygon
            .bbox()
            .union(Bbox::around(self.center, self.safe_radius_m))
    }
}

/// One landing site as a fused approach found it.
#[derive(Debug, Clone, PartialEq)]
pub struct ObservedSite {
    /// The landable polygon with its holes.
    pub polygon: Polygon,
    /// The safest point.
    pub center: LatLon,
    /// Its distance to the nearest edge or obstacle, metres (> 0).
    pub safe_radius_m: f64,
    /// The roof plane's height, metres.
    pub plane_height_m: f64,
    /// How many frames of this observation found it (>= 1): the server sends either one
    /// observation per answered frame (1) or one per approach (the frames that answered it).
    pub frames: u32,
}

/// What one fused approach says at time `t` about the ground its cameras resolved.
///
/// `seen` is the area the approach actually saw finely enough to show obstacles (the server
/// admits only such answers: every site's circle lies in it). Every stored site whose circle meets
/// `seen` is re-judged by this observation; everything else is left as it is (see
/// [`crate::rule`]).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Observation {
    /// When the frames were taken (the newest frame's time).
    pub t: Timestamp,
    /// The drone that flew the approach.
    pub drone_id: String,
    /// The approach: one fused stream.
    pub approach_id: String,
    /// The segmentation model that classified the frames.
    pub model_id: String,
    /// The ground the cameras resolved, as polygons.
    pub seen: Vec<Polygon>,
    /// The sites found there.
    pub sites: Vec<ObservedSite>,
}

impl Observation {
    /// Fails naming the first bad field under `field` (e.g. `observations[2].sites[0].frames`).
    pub fn validate(&self, field: &str) -> Result<()> {
        check_id(&self.drone_id, &format!("{field}.drone_id"))?;
        check_id(&self.approach_id, &format!("{field}.approach_id"))?;
        check_id(&self.model_id, &format!("{field}.model_id"))?;
        for (i, p) in self.seen.iter().enumerate() {
            p.validate(&format!("{field}.seen[{i}]"))?;
        }
        for (i, s) in self.sites.iter().enumerate() {
            let f = format!("{field}.sites[{i}]");
            s.polygon.validate(&format!("{f}.polygon"))?;
            s.center.validate(&format!("{f}.center"))?;
            if !(s.safe_radius_m.is_finite() && s.safe_radius_m > 0.0)
                || s.safe_radius_m > MAX_RADIUS_M
            {
                return Err(Error::invalid(
                    format!("{f}.safe_radius_m"),
                    format!(
                        "{} is not a radius in (0, {MAX_RADIUS_M}] m",
                        s.safe_radius_m
                    ),
                ));
            }
            check_height(s.plane_height_m, &format!("{f}.plane_height_m"))?;
            if s.frames == 0 {
                return Err(Error::invalid(
                    format!("{f}.frames"),
                    "0: a site is seen by at least one frame",
                ));
            }
        }
        Ok(())
    }

    /// The box of everything this observation can change: its seen area and its sites' circles.
    pub fn reach(&self) -> Bbox {
        let seen = self.seen.iter().fold(Bbox::EMPTY, |b, p| b.union(p.bbox()));
        self.sites.iter().fold(seen, |b, s| {
            b.union(Bbox::around(s.center, s.safe_radius_m))
                .union(s.polygon.bbox())
        })
    }
}

/// A roof known beforehand: a building footprint and its roof height (what city open-data portals
/// publish). See [`crate::geojson::read_candidates`].
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// The building's footprint.
    pub footprint: Polygon,
    /// The roof's height, metres (the same datum the fleet's plane heights use).
    pub roof_height_m: f64,
    /// The feature's id in its source file; importing a candidate with an id that is already
    /// stored replaces the stored one.
    pub source_id: Option<String>,
}

impl Candidate {
    /// Fails naming the first bad field under `field`.
    pub fn validate(&self, field: &str) -> Result<()> {
        self.footprint.validate(&format!("{field}.footprint"))?;
        check_height(self.roof_height_m, &format!("{field}.roof_height_m"))?;
        if let Some(id) = &self.source_id {
            check_id(id, &format!("{field}.source_id"))?;
        }
        Ok(())
    }

    /// The record a store keeps for it, imported at `now` (id 0 until stored).
    pub fn to_site(&self, now: Timestamp) -> Site {
        let (center, safe_radius_m) = self.footprint.inscribed_circle(0.1);
        Site {
            id: SiteId(0),
            kind: SiteKind::Candidate,
            polygon: self.footprint.clone(),
            center,
            safe_radius_m,
            plane_height_m: self.roof_height_m,
            area_m2: self.footprint.area_m2(),
            first_seen: now,
            last_confirmed: now,
            frames: 0,
            approaches: 0,
            drone_id: String::new(),
            approach_id: String::new(),
            model_id: String::new(),
            source_id: self.source_id.clone(),
        }
    }
}

fn check_id(id: &str, field: &str) -> Result<()> {
    if id.len() > MAX_ID_BYTES {
        return Err(Error::invalid(
            field,
            format!("{} bytes, more than {MAX_ID_BYTES}", id.len()),
        ));
    }
    Ok(())
}

fn check_height(h: f64, field: &str) -> Result<()> {
    if !h.is_finite() || !PLANE_HEIGHT_RANGE_M.contains(&h) {
        return Err(Error::invalid(
            field,
            format!(
                "{h} is not a height in [{}, {}] m",
                PLANE_HEIGHT_RANGE_M.start(),
                PLANE_HEIGHT_RANGE_M.end()
            ),
        ));
    }
    Ok(())
}
