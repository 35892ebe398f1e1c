//! Judging what the catalog returns at one check, and the counts over a run: pure functions of
//! the sites found, the world's truth at each visit and the approaches streamed so far.
//!
//! A site is judged against the world as it is now (the truth of the current visit, for every
//! roof) and, when that finds it unsafe, against the world as it was when it was last confirmed
//! (the truth of the visit whose approach was streaming then):
//!
//! - [`Class::Unsafe`]: unsafe now, and unsafe in the world the confirming look saw: the
//!   catalog kept or wrote a site that a look taken after the change should have withdrawn;
//! - [`Class::Stale`]: unsafe now, safe when last confirmed: a change no drone has seen yet;
//! - [`Class::Fine`]: safe now, or on a roof the truth does not list (not judged).
//!
//! A stale site is followed from check to check ([`StaleEpisode`]) until a look withdraws it or
//! confirms it again.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt::Write as _;
use std::time::SystemTime;

use landing_client::v1::CatalogSite;
use landing_geometry::geodetic::{Geodetic, geodetic_to_enu};
use serde::Serialize;

use crate::geom::Polygon2;
use crate::metrics::{MetricsParams, RoofTruth, Site, judge_site};
use crate::report::Mode;

/// One world of the set: where it is, the roofs the fleet flies in it and its truth per visit.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldTruth {
    /// The world's name in the recordings' names (`w6101`).
    pub label: String,
    /// The WGS-84 origin of its local frame (the frames').
    pub origin: Geodetic,
    /// Every target roof that any visit flies, as first recorded (buildings do not move).
    pub targets: Vec<RoofTruth>,
    /// Per visit index, every roof in view over that visit's approaches of this world (first
    /// recorded wins).
    pub visits: BTreeMap<u32, Vec<RoofTruth>>,
}

impl WorldTruth {
    /// The roofs as they are at `visit`: that visit's truth, else the latest before it (a world
    /// no approach of `visit` flies), else the first.
    pub fn roofs_at(&self, visit: u32) -> &[RoofTruth] {
        self.visits
            .range(..=visit)
            .next_back()
            .or_else(|| self.visits.iter().next())
            .map_or(&[], |(_, r)| r.as_slice())
    }
}

/// An approach once streamed: what later checks need of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Streamed {
    pub name: String,
    pub visit: u32,
    /// Index into the set's worlds.
    pub world: usize,
    /// When its stream began, on the catalog's clock (this machine's).
    pub started: SystemTime,
    /// The world's clock at the approach's last frame, seconds (the recordings' timestamps:
    /// visit k flies k revisit intervals after the first).
    pub world_time_s: f64,
    pub failed_frames: usize,
}

/// A site a search around a roof of world `world` returned.
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    pub world: usize,
    pub site: CatalogSite,
}

/// What a returned site is now ([module docs](self)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Class {
    Fine,
    Stale,
    Unsafe,
}

/// One returned site, judged at one check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SiteScore {
    /// The check (approaches streamed before it, minus one).
    pub check: usize,
    pub visit_index: u32,
    pub world: String,
    pub site_id: String,
    /// When the fleet first saw it (Unix ms): with the id, what names one site over the run (a
    /// store may give a withdrawn site's id to a new one).
    pub first_seen_ms: i64,
    /// The roof (building id) the site stands on now.
    pub roof: Option<u32>,
    /// Site centre in the world's local frame, metres.
    pub center: [f64; 3],
    pub radius_m: f64,
    /// The judge's verdict now, as text.
    pub verdict: String,
    pub class: Class,
    /// The visit whose approach was streaming when it was last confirmed (`None`: before the run).
    pub confirmed_visit: Option<u32>,
    /// Now minus `last_confirmed`, on the catalog's clock (replay time), seconds.
    pub age_s: f64,
    /// The same on the world's clock: from the confirming approach's last frame to the current
    /// approach's, seconds.
    pub world_age_s: Option<f64>,
}

impl SiteScore {
    /// What names one site over the run: world, id and first sighting.
    fn key(&self) -> (String, String, i64) {
        (self.world.clone(), self.site_id.clone(), self.first_seen_ms)
    }
}

/// One check: after an approach, every target roof of every world searched and judged.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    pub index: usize,
    /// The approach just streamed.
    pub approach: String,
    pub visit_index: u32,
    pub failed_frames: usize,
    pub sites: Vec<SiteScore>,
    /// The approach's target roofs with a true circle of at least the minimum radius, and those
    /// on which a safe site came back (recall as now: roofs the latest approach re-scanned).
    pub landable_roofs: usize,
    pub found_roofs: usize,
}

/// Judges what a check found. `streamed` holds every approach so far, the current one last;
/// `targets` are the current approach's target roofs (its own truth); `now` is the catalog's clock.
pub fn score_check(
    streamed: &[Streamed],
    targets: &[&RoofTruth],
    worlds: &[WorldTruth],
    found: &[Found],
    now: SystemTime,
    params: &MetricsParams,
    min_truth_radius_m: f64,
) -> Check {
    let current = streamed.last().expect("a check follows an approach");
    let sites: Vec<SiteScore> = found
        .iter()
        .map(|f| score_site(streamed, &worlds[f.world], &f.site, now, params))
        .collect();
    let world = &worlds[current.world];
    let safe_on: BTreeSet<u32> = sites
        .iter()
        // Fine on a listed roof: the judge found it safe there.
        .filter(|s| s.world == world.label && s.class == Class::Fine)
        .filter_map(|s| s.roof)
        .collect();
    let landable: Vec<u32> = targets
        .iter()
        .filter(|r| true_radius(r, params.cell_m) >= min_truth_radius_m)
        .map(|r| r.id)
        .collect();
    Check {
        index: streamed.len() - 1,
        approach: current.name.clone(),
        visit_index: current.visit,
        failed_frames: current.failed_frames,
        found_roofs: landable.iter().filter(|id| safe_on.contains(id)).count(),
        landable_roofs: landable.len(),
        sites,
    }
}

/// One site judged now and, when unsafe now, as it was when last confirmed.
fn score_site(
    streamed: &[Streamed],
    world: &WorldTruth,
    s: &CatalogSite,
    now: SystemTime,
    params: &MetricsParams,
) -> SiteScore {
    let current = streamed.last().expect("a check follows an approach");
    let local = local_site(world.origin, s);
    let judged = judge_site(&local, world.roofs_at(current.visit), params);
    let confirmed = s.last_confirmed.and_then(|t| SystemTime::try_from(t).ok());
    let by = confirmed.and_then(|t| streamed.iter().rposition(|a| a.started <= t));
    let class = match by {
        _ if !judged.verdict.is_unsafe() => Class::Fine,
        // Confirmed before the run: nothing shows the look it came from was right.
        None => Class::Unsafe,
        Some(j) => {
            let then = judge_site(&local, world.roofs_at(streamed[j].visit), params);
            if then.verdict.is_unsafe() {
                Class::Unsafe
            } else {
                Class::Stale
            }
        }
    };
    let roofs = world.roofs_at(current.visit);
    SiteScore {
        check: streamed.len() - 1,
        visit_index: current.visit,
        world: world.label.clone(),
        site_id: s.id.clone(),
        first_seen_ms: s
            .first_seen
            .map_or(0, |t| t.seconds * 1000 + i64::from(t.nanos / 1_000_000)),
        roof: judged.roof.map(|i| roofs[i].id),
        center: [local.center[0], local.center[1], local.plane_height_m],
        radius_m: s.safe_radius_m,
        verdict: format!("{:?}", judged.verdict),
        class,
        confirmed_visit: by.map(|j| streamed[j].visit),
        age_s: confirmed
            .and_then(|t| now.duration_since(t).ok())
            .map_or(0.0, |d| d.as_secs_f64()),
        world_age_s: by.map(|j| current.world_time_s - streamed[j].world_time_s),
    }
}

/// A catalog site in the world's local frame, as the judge takes it.
fn local_site(origin: Geodetic, s: &CatalogSite) -> Site {
    let c = s.center.as_ref().map_or(
        Geodetic {
            latitude_deg: f64::NAN,
            longitude_deg: f64::NAN,
            altitude_m: f64::NAN,
        },
        |p| Geodetic {
            latitude_deg: p.latitude_deg,
            longitude_deg: p.longitude_deg,
            altitude_m: p.altitude_m,
        },
    );
    let enu = geodetic_to_enu(origin, c);
    Site {
        rank: 0,
        polygon: Polygon2::default(),
        center: [enu[0], enu[1]],
        plane_height_m: enu[2],
        radius_m: s.safe_radius_m,
    }
}

/// The radius of the largest circle on the whole walkable roof clear of its obstacles, on a grid
/// of `cell_m` (0 when the roof has none).
pub fn true_radius(roof: &RoofTruth, cell_m: f64) -> f64 {
    use crate::geom::Grid;
    use crate::metrics::landable_mask;
    let whole = RoofTruth {
        scanned: None,
        ..roof.clone()
    };
    let Some((min, max)) = roof.interior.bounds() else {
        return 0.0;
    };
    Grid::covering(min, max, cell_m, cell_m)
        .and_then(|g| landable_mask(g, &whole).largest_inscribed_circle())
        .map_or(0.0, |(_, r)| r)
}

/// How a stale site stopped being stale.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Resolution {
    /// No longer returned: a look withdrew it (or merged it into another site).
    Withdrawn,
    /// Returned again and no longer stale: a look confirmed it again (moved or shrunk clear of
    /// the change).
    Reconfirmed,
}

/// A stale site over the consecutive checks that found it stale.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StaleEpisode {
    pub world: String,
    pub site_id: String,
    pub first_seen_ms: i64,
    pub roof: Option<u32>,
    /// The visit of its first stale check: the visit whose change made it unsafe.
    pub visit_index: u32,
    pub first_check: usize,
    pub last_check: usize,
    /// Its age at its last stale check, on the world's clock, seconds.
    pub world_age_s: Option<f64>,
    /// The same on the catalog's clock (replay time), seconds.
    pub age_s: f64,
    /// How it ended; `None`: still stale at the run's last check.
    pub resolution: Option<Resolution>,
    /// Approaches of its visit flown until the check that found it resolved (1: the visit's
    /// first); `None` while unresolved.
    pub resolved_after: Option<usize>,
}

/// Follows every stale site from its first stale check until it is withdrawn or confirmed again.
pub fn stale_episodes(checks: &[Check]) -> Vec<StaleEpisode> {
    let mut first_of_visit: BTreeMap<u32, usize> = BTreeMap::new();
    let mut open: HashMap<(String, String, i64), StaleEpisode> = HashMap::new();
    let mut done = Vec::new();
    for c in checks {
        first_of_visit.entry(c.visit_index).or_insert(c.index);
        for s in c.sites.iter().filter(|s| s.class == Class::Stale) {
            let e = open.entry(s.key()).or_insert_with(|| StaleEpisode {
                world: s.world.clone(),
                site_id: s.site_id.clone(),
                first_seen_ms: s.first_seen_ms,
                roof: s.roof,
                visit_index: c.visit_index,
                first_check: c.index,
                last_check: c.index,
                world_age_s: None,
                age_s: 0.0,
                resolution: None,
                resolved_after: None,
            });
            e.last_check = c.index;
            e.world_age_s = s.world_age_s;
            e.age_s = s.age_s;
        }
        let ended: Vec<(String, String, i64)> = open
            .iter()
            .filter(|(_, e)| e.last_check != c.index)
            .map(|(k, _)| k.clone())
            .collect();
        for key in ended {
            let mut e = open.remove(&key).expect("an open episode");
            let returned = c.sites.iter().any(|s| s.key() == key);
            e.resolution = Some(if returned {
                Resolution::Reconfirmed
            } else {
                Resolution::Withdrawn
            });
            e.resolved_after = Some(c.index - first_of_visit[&e.visit_index] + 1);
            done.push(e);
        }
    }
    done.extend(open.into_values());
    done.sort_by(|a, b| {
        (a.first_check, &a.world, &a.site_id).cmp(&(b.first_check, &b.world, &b.site_id))
    });
    done
}

/// The counts of one visit index (or of the whole run).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CatalogRow {
    /// Visit index (`None`: all visits).
    pub visit_index: Option<u32>,
    /// Approaches streamed, one check after each.
    pub approaches: usize,
    /// Frames refused or unanswered in those streams.
    pub failed_frames: usize,
    /// Distinct sites returned over the checks.
    pub sites: usize,
    /// Distinct sites found unsafe at some check (must be 0).
    pub unsafe_sites: usize,
    /// Stale sites (episodes) that began in these checks.
    pub stale: usize,
    /// Their ages at their last stale check, world clock, seconds.
    pub stale_ages_s: Vec<f64>,
    /// Of them, approaches of their visit flown until withdrawn or confirmed again.
    pub stale_resolved_after: Vec<usize>,
    /// Of them, those still stale at the run's end.
    pub stale_open: usize,
    /// The checks' target roofs with a true circle of at least the minimum radius.
    pub landable_roofs: usize,
    /// Of those, the roofs on which a safe site came back.
    pub found_roofs: usize,
}

impl CatalogRow {
    /// found / landable roofs; `None` without landable roofs.
    pub fn recall(&self) -> Option<f64> {
        (self.landable_roofs > 0).then(|| self.found_roofs as f64 / self.landable_roofs as f64)
    }

    /// The row of `checks` (and of the episodes that began in them).
    fn of(visit_index: Option<u32>, checks: &[&Check], episodes: &[&StaleEpisode]) -> Self {
        let distinct = |keep: &dyn Fn(&SiteScore) -> bool| {
            checks
                .iter()
                .flat_map(|c| &c.sites)
                .filter(|s| keep(s))
                .map(SiteScore::key)
                .collect::<BTreeSet<_>>()
                .len()
        };
        Self {
            visit_index,
            approaches: checks.len(),
            failed_frames: checks.iter().map(|c| c.failed_frames).sum(),
            sites: distinct(&|_| true),
            unsafe_sites: distinct(&|s| s.class == Class::Unsafe),
            stale: episodes.len(),
            stale_ages_s: episodes.iter().filter_map(|e| e.world_age_s).collect(),
            stale_resolved_after: episodes.iter().filter_map(|e| e.resolved_after).collect(),
            stale_open: episodes.iter().filter(|e| e.resolution.is_none()).count(),
            landable_roofs: checks.iter().map(|c| c.landable_roofs).sum(),
            found_roofs: checks.iter().map(|c| c.found_roofs).sum(),
        }
    }
}

/// The catalog's scores over a revisit set.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CatalogReport {
    pub mode: Option<Mode>,
    /// One row per visit index, in order.
    pub per_visit: Vec<CatalogRow>,
    pub overall: CatalogRow,
    pub stale: Vec<StaleEpisode>,
    pub checks: Vec<Check>,
}

impl CatalogReport {
    /// The report of a run's checks, in order.
    pub fn from_checks(mode: Mode, checks: Vec<Check>) -> Self {
        let stale = stale_episodes(&checks);
        let visits: BTreeSet<u32> = checks.iter().map(|c| c.visit_index).collect();
        let per_visit = visits
            .into_iter()
            .map(|v| {
                let cs: Vec<&Check> = checks.iter().filter(|c| c.visit_index == v).collect();
                let es: Vec<&StaleEpisode> = stale.iter().filter(|e| e.visit_index == v).collect();
                CatalogRow::of(Some(v), &cs, &es)
            })
            .collect();
        let overall = CatalogRow::of(
            None,
            &checks.iter().collect::<Vec<_>>(),
            &stale.iter().collect::<Vec<_>>(),
        );
        Self {
            mode: Some(mode),
            per_visit,
            overall,
            stale,
            checks,
        }
    }

    /// The table: one line per visit index and one for all.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<6} {:>10} {:>6} {:>6} {:>6} {:>19} {:>18} {:>13}",
            "visit",
            "approaches",
            "sites",
            "unsafe",
            "stale",
            "stale age h p50/max",
            "gone after p50/max",
            "recall"
        );
        for r in self.per_visit.iter().chain([&self.overall]) {
            let _ = writeln!(s, "{}", row_text(r));
        }
        s
    }

    /// The tables as Markdown, for `catalog.md`: the counts, then every stale site.
    pub fn to_markdown(&self) -> String {
        let mut s = String::from(
            "# Catalog\n\nEvery approach streamed fused, in time order; after each (a check), the \
             catalog searched around every target roof of every world and each site judged \
             against the world as it is now (a visit's changes apply to all roofs when the visit \
             begins). **unsafe**: unsafe now and in the world the look that last confirmed it \
             saw (must be 0); **stale**: unsafe now, safe when last confirmed (a change no drone \
             has seen yet), counted once per site from its first stale check, with its age on \
             the world's clock at its last stale check and how many approaches of its visit \
             flew before it was withdrawn or confirmed again (gone after; open: still stale at \
             the end); **recall**: at each check, the roofs the approach re-scanned with a true \
             circle of at least the minimum radius on which a safe site was returned.\n\n",
        );
        let _ = writeln!(s, "```\n{}```\n", self.to_text());
        if !self.stale.is_empty() {
            s.push_str(
                "## Stale sites\n\n| world | site | roof | visit | checks | age (world) h | \
                 age (replay) s | ended | after approaches |\n|---|---|---|---|---|---|---|---|---|\n",
            );
            for e in &self.stale {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {}-{} | {} | {:.1} | {} | {} |",
                    e.world,
                    e.site_id,
                    e.roof.map_or("-".into(), |r| r.to_string()),
                    e.visit_index,
                    e.first_check,
                    e.last_check,
                    e.world_age_s
                        .map_or("-".into(), |a| format!("{:.2}", a / 3600.0)),
                    e.age_s,
                    e.resolution.map_or("open".into(), |r| format!("{r:?}")),
                    e.resolved_after.map_or("-".into(), |n| n.to_string()),
                );
            }
        }
        s
    }

    /// Whether an unsafe (not stale) site was returned.
    pub fn has_unsafe(&self) -> bool {
        self.overall.unsafe_sites > 0
    }
}

/// `p50/max` of `v`, or `-` when empty.
fn median_max<T: Copy + PartialOrd>(v: &[T], show: impl Fn(T) -> String) -> String {
    if v.is_empty() {
        return "-".into();
    }
    let mut a = v.to_vec();
    a.sort_by(|x, y| x.partial_cmp(y).unwrap_or(std::cmp::Ordering::Equal));
    format!("{}/{}", show(a[a.len() / 2]), show(a[a.len() - 1]))
}

fn row_text(r: &CatalogRow) -> String {
    let visit = r.visit_index.map_or("all".into(), |v| format!("v{v:02}"));
    let ages = median_max(&r.stale_ages_s, |a| format!("{:.2}", a / 3600.0));
    let mut gone = median_max(&r.stale_resolved_after, |n| n.to_string());
    if r.stale_open > 0 {
        let _ = write!(gone, " ({} open)", r.stale_open);
    }
    let recall = r.recall().map_or("-".into(), |v| {
        format!("{}/{} {v:.2}", r.found_roofs, r.landable_roofs)
    });
    format!(
        "{visit:<6} {:>10} {:>6} {:>6} {:>6} {ages:>19} {gone:>18} {recall:>13}",
        r.approaches, r.sites, r.unsafe_sites, r.stale
    )
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use landing_client::v1::GeodeticPoint;
    use landing_geometry::geodetic::enu_to_geodetic;

    use super::*;
    use crate::metrics::Obstacle;

    const ORIGIN: Geodetic = Geodetic {
        latitude_deg: 40.75,
        longitude_deg: -73.98,
        altitude_m: 10.0,
    };

    /// A 20 m square roof at 20 m, target of the approaches.
    fn roof(obstacles: Vec<Obstacle>) -> RoofTruth {
        RoofTruth {
            id: 7,
            outline: Polygon2::rect([0.0, 0.0], [20.0, 20.0]),
            interior: Polygon2::rect([0.0, 0.0], [20.0, 20.0]),
            height_m: 20.0,
            obstacles,
            scanned: Some(Polygon2::default()),
            hidden: vec![],
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target: true,
        }
    }

    /// A 4 m unit in the north-east corner.
    fn unit() -> Obstacle {
        Obstacle {
            class: 1,
            footprint: Polygon2::rect([14.0, 14.0], [18.0, 18.0]),
            seen: true,
        }
    }

    /// Visit 0: the roof clear; visit 1: the unit laid down.
    fn world() -> WorldTruth {
        WorldTruth {
            label: "w1".into(),
            origin: ORIGIN,
            targets: vec![roof(vec![])],
            visits: BTreeMap::from([(0, vec![roof(vec![])]), (1, vec![roof(vec![unit()])])]),
        }
    }

    fn site(id: &str, enu: [f64; 3], radius_m: f64, at: SystemTime) -> Found {
        let g = enu_to_geodetic(ORIGIN, enu);
        Found {
            world: 0,
            site: CatalogSite {
                id: id.into(),
                center: Some(GeodeticPoint {
                    latitude_deg: g.latitude_deg,
                    longitude_deg: g.longitude_deg,
                    altitude_m: g.altitude_m,
                }),
                safe_radius_m: radius_m,
                last_confirmed: Some(at.into()),
                ..Default::default()
            },
        }
    }

    /// Approaches streamed 100 s apart on the catalog's clock, visit 1 an hour after visit 0 on
    /// the world's.
    fn streamed(visits: &[u32], t0: SystemTime) -> Vec<Streamed> {
        visits
            .iter()
            .enumerate()
            .map(|(k, &visit)| Streamed {
                name: format!("v{visit:02}-w1-b{k:03}.mcap"),
                visit,
                world: 0,
                started: t0 + Duration::from_secs(100 * k as u64),
                world_time_s: f64::from(visit) * 3600.0 + k as f64,
                failed_frames: 0,
            })
            .collect()
    }

    #[test]
    fn unsafe_when_the_confirming_look_saw_the_change_stale_when_it_did_not() {
        let t0 = SystemTime::now() - Duration::from_secs(1000);
        let s = streamed(&[0, 1], t0);
        let in_visit = |k: u64| t0 + Duration::from_secs(100 * k + 5);
        let found = [
            // Safe in the clear south-west: counts for recall.
            site("safe", [5.0, 5.0, 20.0], 3.0, in_visit(1)),
            // On the unit, confirmed in visit 1 which has it: unsafe.
            site("bad", [15.0, 15.0, 20.0], 2.0, in_visit(1)),
            // On the unit, confirmed in visit 0 before it was laid down: stale.
            site("old", [16.0, 16.0, 20.0], 1.5, in_visit(0)),
        ];
        let w = [world()];
        let targets = w[0].roofs_at(1).iter().collect::<Vec<_>>();
        let now = in_visit(1) + Duration::from_secs(10);
        let c = score_check(
            &s,
            &targets,
            &w,
            &found,
            now,
            &MetricsParams::default(),
            1.0,
        );
        let classes: Vec<Class> = c.sites.iter().map(|s| s.class).collect();
        assert_eq!(
            classes,
            [Class::Fine, Class::Unsafe, Class::Stale],
            "{c:#?}"
        );
        assert_eq!((c.found_roofs, c.landable_roofs), (1, 1));
        let old = &c.sites[2];
        assert_eq!(old.confirmed_visit, Some(0));
        assert_eq!(
            old.world_age_s,
            Some(3601.0),
            "world clock: visit 1's second approach"
        );
        assert!((old.age_s - 110.0).abs() < 1.0, "{old:?}");
        // The centres come back into the local frame, on the roof.
        assert!(
            (c.sites[0].center[0] - 5.0).abs() < 1e-6 && (c.sites[0].center[2] - 20.0).abs() < 1e-6
        );
        assert_eq!(c.sites[0].roof, Some(7));
    }

    /// A check at `index` of `visit` returning `sites` as (id, class).
    fn check(index: usize, visit: u32, sites: &[(&str, Class)]) -> Check {
        Check {
            index,
            approach: format!("a{index}"),
            visit_index: visit,
            failed_frames: 0,
            sites: sites
                .iter()
                .map(|&(id, class)| SiteScore {
                    check: index,
                    visit_index: visit,
                    world: "w1".into(),
                    site_id: id.into(),
                    first_seen_ms: 0,
                    roof: Some(7),
                    center: [0.0; 3],
                    radius_m: 1.0,
                    verdict: String::new(),
                    class,
                    confirmed_visit: Some(0),
                    age_s: index as f64,
                    world_age_s: Some(3600.0 + index as f64),
                })
                .collect(),
            landable_roofs: 1,
            found_roofs: usize::from(sites.iter().any(|s| s.1 == Class::Fine)),
        }
    }

    #[test]
    fn stale_sites_are_followed_until_withdrawn_or_confirmed_again() {
        use Class::{Fine, Stale, Unsafe};
        // b withdrawn by visit 1's first approach, and its id given to a new site.
        let mut reused = check(3, 1, &[("a", Stale), ("c", Stale), ("b", Fine)]);
        reused.sites[2].first_seen_ms = 99;
        let checks = [
            check(0, 0, &[("a", Fine), ("b", Fine), ("c", Fine)]),
            check(1, 0, &[("a", Fine), ("b", Fine), ("c", Fine)]),
            // Visit 1 changes every roof: a, b and c are stale from its first check.
            check(2, 1, &[("a", Stale), ("b", Stale), ("c", Stale)]),
            reused,
            // a confirmed again (moved clear) by its second; c stays stale to the end.
            check(4, 1, &[("a", Fine), ("c", Stale), ("d", Unsafe)]),
        ];
        let e = stale_episodes(&checks);
        let got: Vec<_> = e
            .iter()
            .map(|e| {
                (
                    e.site_id.as_str(),
                    e.first_check,
                    e.last_check,
                    e.resolution,
                    e.resolved_after,
                )
            })
            .collect();
        assert_eq!(
            got,
            [
                ("a", 2, 3, Some(Resolution::Reconfirmed), Some(3)),
                ("b", 2, 2, Some(Resolution::Withdrawn), Some(2)),
                ("c", 2, 4, None, None),
            ]
        );
        assert_eq!(
            e[0].world_age_s,
            Some(3603.0),
            "its age at its last stale check"
        );

        let r = CatalogReport::from_checks(Mode::Model, checks.to_vec());
        assert_eq!(r.per_visit.len(), 2);
        let (v0, v1, all) = (&r.per_visit[0], &r.per_visit[1], &r.overall);
        assert_eq!(
            (v0.approaches, v0.sites, v0.stale, v0.unsafe_sites),
            (2, 3, 0, 0)
        );
        assert_eq!(
            (v1.approaches, v1.sites, v1.stale, v1.unsafe_sites),
            (3, 5, 3, 1)
        );
        assert_eq!(
            (v1.stale_resolved_after.clone(), v1.stale_open),
            (vec![3, 2], 1)
        );
        assert_eq!((all.sites, all.stale, all.unsafe_sites), (5, 3, 1));
        assert_eq!((all.found_roofs, all.landable_roofs), (4, 5));
        assert!(r.has_unsafe());
        let text = r.to_text();
        assert!(text.contains("all") && text.contains("(1 open)"), "{text}");
        assert!(
            r.to_markdown().contains("| w1 | c | 7 | 1 | 2-4 |"),
            "{}",
            r.to_markdown()
        );
    }

    #[test]
    fn a_world_without_an_approach_at_a_visit_keeps_its_latest_truth() {
        let w = world();
        assert!(w.roofs_at(0)[0].obstacles.is_empty());
        assert_eq!(w.roofs_at(1)[0].obstacles.len(), 1);
        assert_eq!(
            w.roofs_at(5)[0].obstacles.len(),
            1,
            "visit 5: visit 1's world"
        );
    }

    #[test]
    fn true_radius_of_a_clear_square_roof() {
        let r = true_radius(&roof(vec![]), 0.05);
        assert!((r - 10.0).abs() < 0.1, "{r}");
    }
}
