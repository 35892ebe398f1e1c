//! The update rule: what one observation does to the stored sites it can reach. Pure: both stores
//! fetch the records near an observation, call [`plan`] and write what it says, in one transaction.
//!
//! # The rule
//!
//! A newer look replaces what the catalog says about the ground that look resolved, and nothing
//! else:
//!
//! 1. A stored confirmed site whose safe circle meets the observation's `seen` area and that no
//!    new site confirms is **withdrawn** (deleted) at once: the look saw the place and found no
//!    site there, or found it blocked. A circle that only grazes the seen area counts as seen:
//!    safety over coverage.
//! 2. A stored site that a new site confirms ([`same_roof`]) is **updated**: the new polygon,
//!    centre, radius and plane height, `last_confirmed = t`, frames added, approaches counted when
//!    the approach is not the one that confirmed it last, `first_seen` kept (the earliest of every
//!    stored site it merges).
//! 3. A new site that confirms no stored site is **inserted**.
//! 4. Stored sites whose circles do not meet the seen area and that no new site matches are
//!    **untouched** and keep their last confirmation time.
//! 5. An observation never overwrites newer knowledge: stored sites confirmed after `t` are left
//!    alone, and a new site is **dropped** when its circle meets ground that a newer observation
//!    resolved (that look's verdict stands, whether it kept a site there or withdrew one) or when
//!    it matches a site confirmed after `t`.
//!
//! Candidates are never touched by observations: they say what was known beforehand, not what the
//! fleet saw.
//!
//! # Same roof
//!
//! Two sites are the same roof when their safe circles overlap (centre distance < sum of radii)
//! and their plane heights differ by at most [`SAME_ROOF_HEIGHT_M`]. A safe circle is free roof
//! on one plane, so two overlapping circles on one plane share free roof: one landable region,
//! whose shape and best circle a newer look may have moved. Sites on separate parts of a roof
//! divided by an obstacle have disjoint circles and stay apart; a penthouse or a neighbour's roof
//! at another level differs in height by far more than the fused plane fit's error (centimetres),
//! which half a metre leaves room for. When a new site overlaps several stored ones (a roof
//! cleared of an obstacle), the nearest is updated and the rest merge into it; when several new
//! sites overlap one stored site (a roof newly divided), the largest new circle takes it and the
//! others are inserted.

use std::collections::HashSet;

use crate::geo::{Polygon, distance_m};
use crate::model::{Observation, ObservedSite, Site, SiteId, SiteKind};
use crate::time::Timestamp;

/// The largest plane-height difference between two sites of one roof, metres.
pub const SAME_ROOF_HEIGHT_M: f64 = 0.5;

/// Whether a new site and a stored one are the same roof (see the module docs).
pub fn same_roof(stored: &Site, new: &ObservedSite) -> bool {
    (stored.plane_height_m - new.plane_height_m).abs() <= SAME_ROOF_HEIGHT_M
        && distance_m(stored.center, new.center) < stored.safe_radius_m + new.safe_radius_m
}

/// What applying observations did, summed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ApplyReport {
    /// Observations applied.
    pub observations: u64,
    /// New sites stored.
    pub inserted: u64,
    /// Stored sites confirmed again.
    pub updated: u64,
    /// Stored sites the seen area held and no new site confirmed.
    pub withdrawn: u64,
    /// Stored sites merged into another that a new site confirmed.
    pub merged: u64,
    /// New sites not stored because newer knowledge covers them.
    pub dropped_stale: u64,
}

impl std::ops::AddAssign for ApplyReport {
    fn add_assign(&mut self, o: Self) {
        self.observations += o.observations;
        self.inserted += o.inserted;
        self.updated += o.updated;
        self.withdrawn += o.withdrawn;
        self.merged += o.merged;
        self.dropped_stale += o.dropped_stale;
    }
}

/// The writes one observation makes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Plan {
    /// Stored sites to overwrite (same id, new contents).
    pub updates: Vec<Site>,
    /// New sites to store (their ids are ignored).
    pub inserts: Vec<Site>,
    /// Stored sites to delete.
    pub deletes: Vec<SiteId>,
    /// The counts.
    pub report: ApplyReport,
}

/// The writes `obs` makes, given the stored records near it (`stored`: at least every confirmed
/// site whose box meets `obs.reach()`; candidates and far sites are ignored) and the areas that
/// newer observations resolved there (`newer_seen`: each with its time; older ones are ignored).
pub fn plan(obs: &Observation, stored: &[Site], newer_seen: &[(Timestamp, Polygon)]) -> Plan {
    let t = obs.t;
    let confirmed: Vec<&Site> = stored
        .iter()
        .filter(|s| s.kind == SiteKind::Confirmed)
        .collect();
    let newer_areas: Vec<&Polygon> = newer_seen
        .iter()
        .filter(|(at, _)| *at > t)
        .map(|(_, p)| p)
        .collect();
    let mut out = Plan {
        report: ApplyReport {
            observations: 1,
            ..Default::default()
        },
        ..Default::default()
    };

    // Largest circles first: they take the stored site they overlap before smaller pieces do.
    let mut order: Vec<&ObservedSite> = obs.sites.iter().collect();
    order.sort_by(|a, b| b.safe_radius_m.total_cmp(&a.safe_radius_m));

    let mut taken: HashSet<SiteId> = HashSet::new();
    let mut merged: HashSet<SiteId> = HashSet::new();
    for new in order {
        let stale = newer_areas
            .iter()
            .any(|p| p.meets_circle(new.center, new.safe_radius_m))
            || confirmed
                .iter()
                .any(|s| s.last_confirmed > t && same_roof(s, new));
        if stale {
            out.report.dropped_stale += 1;
            continue;
        }
        let mut matches: Vec<&Site> = confirmed
            .iter()
            .copied()
            .filter(|s| s.last_confirmed <= t && !taken.contains(&s.id) && same_roof(s, new))
            .collect();
        matches.sort_by(|a, b| {
            distance_m(a.center, new.center)
                .total_cmp(&distance_m(b.center, new.center))
                .then(a.id.cmp(&b.id))
        });
        let Some((primary, rest)) = matches.split_first() else {
            out.inserts.push(site_from(obs, new, None));
            out.report.inserted += 1;
            continue;
        };
        taken.insert(primary.id);
        let mut site = site_from(obs, new, Some(primary));
        for other in rest {
            site.first_seen = site.first_seen.min(other.first_seen);
            merged.insert(other.id);
        }
        out.updates.push(site);
        out.report.updated += 1;
    }

    for s in &confirmed {
        if s.last_confirmed > t || taken.contains(&s.id) {
            continue;
        }
        if merged.contains(&s.id) {
            out.deletes.push(s.id);
            out.report.merged += 1;
        } else if obs
            .seen
            .iter()
            .any(|p| p.meets_circle(s.center, s.safe_radius_m))
        {
            out.deletes.push(s.id);
            out.report.withdrawn += 1;
        }
    }
    out
}

fn site_from(obs: &Observation, new: &ObservedSite, stored: Option<&Site>) -> Site {
    let frames = u64::from(new.frames);
    Site {
        id: stored.map_or(SiteId(0), |s| s.id),
        kind: SiteKind::Confirmed,
        polygon: new.polygon.clone(),
        center: new.center,
        safe_radius_m: new.safe_radius_m,
        plane_height_m: new.plane_height_m,
        area_m2: new.polygon.area_m2(),
        first_seen: stored.map_or(obs.t, |s| s.first_seen.min(obs.t)),
        last_confirmed: obs.t,
        frames: stored.map_or(frames, |s| s.frames.saturating_add(frames)),
        approaches: stored.map_or(1, |s| {
            s.approaches
                .saturating_add(u64::from(s.approach_id != obs.approach_id))
        }),
        drone_id: obs.drone_id.clone(),
        approach_id: obs.approach_id.clone(),
        model_id: obs.model_id.clone(),
        source_id: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geo::{LatLon, LocalFrame};

    /// Seed 6101, building 64 of world 6102: a rooftop structure 2.8 m tall stands on the roof,
    /// and an approach finds a circle on its top and one on the roof beside it, 12.5 m apart.
    /// Their radii agreed to a centimetre (2.54 m) at visit 2, which read like a duplicate; they
    /// are two landable regions on two planes, and stay two records however often they are seen.
    #[test]
    fn circles_of_one_radius_on_a_roof_and_on_a_structure_on_it_stay_two_sites() {
        let origin = LatLon::new(40.7737, -73.9747);
        let f = LocalFrame::new(origin);
        let at = |x: f64, y: f64| f.to_lat_lon((x, y));
        let observed = |x: f64, y: f64, r: f64, h: f64| ObservedSite {
            polygon: Polygon::rectangle(at(x - r - 0.5, y - r - 0.5), at(x + r + 0.5, y + r + 0.5)),
            center: at(x, y),
            safe_radius_m: r,
            plane_height_m: h,
            frames: 30,
        };
        let look = |s: i64| Observation {
            t: Timestamp::from_unix_ms(s * 1000),
            approach_id: format!("a{s}"),
            seen: vec![Polygon::rectangle(at(-20.0, -20.0), at(20.0, 20.0))],
            sites: vec![
                observed(3.6, 12.0, 2.5434, 58.04),
                observed(0.0, 0.0, 2.5389, 55.26),
            ],
            ..Default::default()
        };
        let first = plan(&look(1), &[], &[]);
        assert_eq!(first.report.inserted, 2);
        let stored: Vec<Site> = first
            .inserts
            .into_iter()
            .enumerate()
            .map(|(i, s)| Site {
                id: SiteId(i as i64 + 1),
                ..s
            })
            .collect();
        let again = plan(&look(2), &stored, &[]);
        assert_eq!(
            (
                again.report.updated,
                again.report.inserted,
                again.report.merged
            ),
            (2, 0, 0),
            "{again:?}"
        );
        assert!(again.deletes.is_empty());
    }
}
