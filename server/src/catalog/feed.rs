//! What one stream tells the catalog: [`Feed`] reads each fused answer's evidence
//! ([`crate::pipeline::Evidence`]) and every `catalog.observe_interval_s`, and when the stream
//! ends, queues one observation of the stream's latest answer.
//!
//! # What is admitted
//!
//! The shipped model is imperfect (on one fresh set a fused stream put a dozen circles on a tarp
//! the model called roof), so the catalog takes less than a fused answer shows, and says what it
//! holds is a candidate for a drone to confirm, never a clearance:
//!
//! - only fused streams' answers (a frame judged alone is not catalogued), and only frames with a
//!   geodetic origin (the others are answered as always, and counted as not catalogued);
//! - a site only when every map point within its safe circle is landable ground that a camera
//!   resolved (`fusion.max_pixel_footprint_m`; a stream that turns the rule off is not
//!   catalogued), and only once `catalog.min_frames` consecutive answers of the stream found it
//!   so: each answer's site on resolved ground finds again the region of one of the answer
//!   before (overlapping circles within half a metre in height, or the earlier safest point
//!   inside the later landable polygon on that plane: an answer may pick another of a region's
//!   near-equal widest circles, metres away, and pick the first again later); its `frames` is
//!   that count;
//! - of such a site, only the disk that each of those `min_frames` answers called clear: the
//!   latest circle shrunk to lie inside the `min_frames - 1` most recent earlier circles of its
//!   streak that hold its centre (a site with fewer such circles is not admitted yet). A fused
//!   answer's circle can grow onto what the model mistakes for roof as the map fills in (on one
//!   fresh revisit set a circle grew 0.4 m in its last two answers, half a metre into a tarp);
//!   the catalog keeps what the stream agreed on, not its newest guess;
//! - nothing from a stream before `catalog.min_frames` answers: a look that short neither adds nor
//!   withdraws.
//!
//! # What the observation says it saw
//!
//! `seen` is what the latest answer's map resolved ([`crate::pipeline::Evidence::seen`]): every
//! stored site whose circle meets it and that no admitted site confirms is withdrawn (the look
//! found it blocked or found no site there), and what the map never resolved keeps its age. One
//! exception keeps a site from flickering out of the catalog: the squares wholly inside the circle
//! of a site this answer found on resolved ground but has not yet confirmed `min_frames` times are
//! left out of `seen` (the look saw that ground free; it does not vouch for it yet).
//!
//! Every time is the server's clock when the answer was computed, not the frame's timestamp:
//! recordings replayed today carry the time they were made, and drones' clocks drift; the
//! catalog's ages are how long ago the fleet confirmed a site.

use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use landing_catalog::rule::SAME_ROOF_HEIGHT_M;
use landing_catalog::{LatLon, Observation, ObservedSite, Polygon, Timestamp};

use super::Catalog;
use crate::pipeline::{Evidence, FrameOutput, NotCatalogued, SEEN_CELL_M, Site, rectangles};
use landing_geometry::geodetic::{Geodetic, enu_to_geodetic};

/// One stream's feed: dropped with the stream, when it queues the stream's last observation.
pub(crate) struct Feed {
    catalog: Catalog,
    approach_id: String,
    /// Consecutive catalogued answers since the stream (or its map) started.
    answers: u32,
    /// The previous answer's sites on resolved ground, with their streaks.
    tracked: Vec<(Site, Streak)>,
    /// The latest answer, not yet sent.
    latest: Option<Latest>,
    last_sent: Instant,
}

/// A catalogued answer, as the feed keeps it until it is sent.
struct Latest {
    at: Timestamp,
    drone_id: String,
    evidence: Evidence,
    /// The answer's sites with their streaks (a run of 0: not on resolved ground).
    sites: Vec<(Site, Streak)>,
}

/// How a site of the stream has been found.
#[derive(Debug, Clone, Default)]
struct Streak {
    /// Consecutive answers that found it on resolved ground, this one included.
    run: u32,
    /// Those of them not yet counted in an observation the catalog was sent: a site's `frames`
    /// in the catalog adds each answer once.
    unreported: u32,
    /// The safe circles of the streak's most recent answers, oldest first, this one's last (at
    /// most `min_frames +` [`WANDER_ANSWERS`]).
    circles: Vec<Circle>,
}

impl Streak {
    /// The circle the catalog may take: after `min_frames` answers, the disk they
    /// [`agreed`] on.
    fn admitted(&self, min_frames: u32) -> Option<Circle> {
        if self.run < min_frames {
            return None;
        }
        agreed(&self.circles, min_frames)
    }
}

/// A safe circle in the map's frame: centre (east, north) and radius, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Circle {
    center: [f64; 2],
    radius: f64,
}

/// How many answers a streak remembers beyond `min_frames`: an answer may pick another of a
/// region's near-equal widest circles for a while (four answers on seed 6101) and come back; the
/// circles from before it left still vouch for the one it came back to.
const WANDER_ANSWERS: usize = 10;

impl Feed {
    pub fn new(catalog: Catalog) -> Self {
        static APPROACHES: AtomicU64 = AtomicU64::new(0);
        let n = APPROACHES.fetch_add(1, Ordering::Relaxed);
        let approach_id = format!(
            "{:x}-{}-{n}",
            Timestamp::now().unix_ms(),
            std::process::id()
        );
        Self {
            catalog,
            approach_id,
            answers: 0,
            tracked: Vec::new(),
            latest: None,
            last_sent: Instant::now(),
        }
    }

    /// Reads one answer of the stream; queues an observation when one is due.
    pub fn answered(&mut self, out: &FrameOutput) {
        let Some(verdict) = &out.catalog else {
            return; // judged alone: not a fused stream
        };
        let shared = &self.catalog.shared;
        let evidence = match verdict {
            Ok(e) => e,
            Err(why) => {
                shared.metrics.catalog_frame(match why {
                    NotCatalogued::NoGeodeticOrigin => "no_geodetic_origin",
                    NotCatalogued::Unresolvable => "unresolvable",
                });
                // Not consecutive any more.
                self.answers = 0;
                self.tracked.clear();
                self.latest = None;
                return;
            }
        };
        shared.metrics.catalog_frame("catalogued");
        let restarted = out.fusion.as_ref().is_some_and(|f| f.reset.is_some())
            || self
                .latest
                .as_ref()
                .is_some_and(|l| l.evidence.origin != evidence.origin);
        if restarted {
            self.answers = 0;
            self.tracked.clear();
        }
        self.answers = self.answers.saturating_add(1);
        let history = shared.config.min_frames as usize + WANDER_ANSWERS;
        let sites = streaks(&self.tracked, &out.sites, &evidence.resolved, history);
        self.tracked = sites.iter().filter(|(_, s)| s.run > 0).cloned().collect();
        self.latest = Some(Latest {
            at: Timestamp::now(),
            drone_id: out.drone_id.clone(),
            evidence: evidence.clone(),
            sites,
        });
        let interval = Duration::from_secs_f64(shared.config.observe_interval_s);
        if self.last_sent.elapsed() >= interval {
            self.send();
        }
    }

    /// Queues the latest answer's observation, once the stream has looked long enough.
    fn send(&mut self) {
        let min_frames = self.catalog.shared.config.min_frames;
        if self.answers < min_frames {
            return;
        }
        let Some(latest) = self.latest.take() else {
            return;
        };
        let observation = observation(
            &latest,
            min_frames,
            &self.approach_id,
            &self.catalog.shared.model_id,
        );
        // What was admitted is reported: the next observation counts only newer answers.
        for (_, streak) in &mut self.tracked {
            if streak.admitted(min_frames).is_some() {
                streak.unreported = 0;
            }
        }
        match observation.validate("observation") {
            Ok(()) => self.catalog.submit(observation),
            Err(e) => {
                tracing::warn!(error = %e, "an observation the catalog would refuse; dropped");
                self.catalog.shared.metrics.catalog_dropped(1);
            }
        }
        self.last_sent = Instant::now();
    }
}

impl Drop for Feed {
    /// The stream ended: its latest answer is what the approach saw last.
    fn drop(&mut self) {
        self.send();
    }
}

/// The streaks of an answer's `sites` (`resolved`: per site, whether it lies on resolved ground)
/// given the previous answer's `tracked` sites: a site on resolved ground continues the longest
/// streak of a tracked site it [`continues`], remembering at most `history` circles; any other
/// starts at 0.
fn streaks(
    tracked: &[(Site, Streak)],
    sites: &[Site],
    resolved: &[bool],
    history: usize,
) -> Vec<(Site, Streak)> {
    sites
        .iter()
        .zip(resolved)
        .map(|(site, &resolved)| {
            if !resolved {
                return (site.clone(), Streak::default());
            }
            let before = tracked
                .iter()
                .filter(|(t, _)| continues(t, site))
                .map(|(_, streak)| streak)
                .max_by_key(|streak| streak.run);
            let mut circles = before.map(|b| b.circles.clone()).unwrap_or_default();
            circles.push(Circle {
                center: [site.center[0], site.center[1]],
                radius: site.safe_radius_m,
            });
            let excess = circles.len().saturating_sub(history);
            circles.drain(..excess);
            let streak = Streak {
                run: before.map_or(0, |b| b.run) + 1,
                unreported: before.map_or(0, |b| b.unreported) + 1,
                circles,
            };
            (site.clone(), streak)
        })
        .collect()
}

/// The disk `min_frames` answers of the streak all called clear: the latest circle shrunk to lie
/// inside each of the `min_frames - 1` most recent earlier circles that hold its centre; `None`
/// when the streak remembers fewer of them.
fn agreed(circles: &[Circle], min_frames: u32) -> Option<Circle> {
    let (&latest, earlier) = circles.split_last()?;
    let holding = earlier.iter().rev().filter_map(|c| {
        let d = (c.center[0] - latest.center[0]).hypot(c.center[1] - latest.center[1]);
        (d < c.radius).then_some(c.radius - d)
    });
    let needed = min_frames.saturating_sub(1) as usize;
    let mut radius = latest.radius;
    let mut found = 0;
    for room in holding.take(needed) {
        radius = radius.min(room);
        found += 1;
    }
    (found == needed).then_some(Circle { radius, ..latest })
}

/// Whether `new` finds again the landable region where the previous answer found `old`: the
/// same roof (the catalog's rule: overlapping safe circles, plane heights within
/// [`SAME_ROOF_HEIGHT_M`]), or, on the same plane, `old`'s safest point inside `new`'s landable
/// polygon. The second holds when an answer picks another of a region's near-equal widest circles:
/// polylabel's pick can jump between two maxima metres apart from one answer to the next and
/// back, and the region was found all along.
fn continues(old: &Site, new: &Site) -> bool {
    if (old.plane_height_m - new.plane_height_m).abs() > SAME_ROOF_HEIGHT_M {
        return false;
    }
    let d = (old.center[0] - new.center[0]).hypot(old.center[1] - new.center[1]);
    let flat = |ring: &[[f64; 3]]| ring.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>();
    let region = landing_geometry::Polygon {
        shell: flat(&new.shell),
        holes: new.holes.iter().map(|h| flat(h)).collect(),
    };
    d < old.safe_radius_m + new.safe_radius_m
        || (region.shell.len() >= 3 && region.signed_distance([old.center[0], old.center[1]]) > 0.0)
}

/// The observation of `latest`: its [admitted](Streak::admitted) sites (valid in WGS-84) and its
/// seen area less the squares wholly inside the circles of sites on resolved ground not admitted
/// yet.
fn observation(latest: &Latest, min_frames: u32, approach_id: &str, model_id: &str) -> Observation {
    let origin = latest.evidence.origin;
    let pending: Vec<&Site> = latest
        .sites
        .iter()
        .filter(|(_, s)| s.run > 0 && s.admitted(min_frames).is_none())
        .map(|(s, _)| s)
        .collect();
    let squares = latest
        .evidence
        .seen
        .iter()
        .copied()
        .filter(|&square| !pending.iter().any(|s| square_inside(square, s)));
    let seen = rectangles(squares)
        .into_iter()
        .map(|[x0, y0, x1, y1]| {
            let corner = |x: f64, y: f64| lat_lon(origin, [x, y, 0.0]);
            Polygon::new(
                vec![
                    corner(x0, y0),
                    corner(x1, y0),
                    corner(x1, y1),
                    corner(x0, y1),
                ],
                vec![],
            )
        })
        .collect();
    let sites = latest
        .sites
        .iter()
        .filter_map(|(site, s)| {
            let circle = s.admitted(min_frames)?;
            let site = Site {
                safe_radius_m: circle.radius,
                ..site.clone()
            };
            Some(observed(origin, &site, s.unreported.max(1)))
        })
        .filter(|s| {
            let alone = Observation {
                sites: vec![s.clone()],
                ..Default::default()
            };
            alone.validate("site").is_ok()
        })
        .collect();
    Observation {
        t: latest.at,
        drone_id: truncated(&latest.drone_id),
        approach_id: approach_id.to_owned(),
        model_id: truncated(model_id),
        seen,
        sites,
    }
}

/// Whether the seen square lies wholly inside the site's safe circle.
fn square_inside((i, j): (i64, i64), site: &Site) -> bool {
    let r2 = site.safe_radius_m.powi(2);
    [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
        .into_iter()
        .all(|(x, y)| {
            let dx = x as f64 * SEEN_CELL_M - site.center[0];
            let dy = y as f64 * SEEN_CELL_M - site.center[1];
            dx * dx + dy * dy <= r2
        })
}

/// A site of the answer in WGS-84: its plane height is the centre's height above the ellipsoid.
fn observed(origin: Geodetic, s: &Site, frames: u32) -> ObservedSite {
    let ring = |r: &[[f64; 3]]| r.iter().map(|p| lat_lon(origin, *p)).collect::<Vec<_>>();
    let center = enu_to_geodetic(origin, s.center);
    ObservedSite {
        polygon: Polygon::new(ring(&s.shell), s.holes.iter().map(|h| ring(h)).collect()),
        center: LatLon::new(center.latitude_deg, center.longitude_deg),
        safe_radius_m: s.safe_radius_m,
        plane_height_m: center.altitude_m,
        frames,
    }
}

fn lat_lon(origin: Geodetic, enu: [f64; 3]) -> LatLon {
    let g = enu_to_geodetic(origin, enu);
    LatLon::new(g.latitude_deg, g.longitude_deg)
}

/// An id cut to what the catalog keeps, on a character boundary.
fn truncated(id: &str) -> String {
    let mut end = id.len().min(MAX_ID_BYTES);
    while !id.is_char_boundary(end) {
        end -= 1;
    }
    id[..end].to_owned()
}

/// The longest id the catalog keeps, in bytes (the catalog's own limit, which it does not
/// export; a longer one would make it refuse the whole batch).
const MAX_ID_BYTES: usize = 256;

#[cfg(test)]
mod tests {
    use super::*;

    /// A site on the plane at `height` whose landable polygon is the rectangle `[x0, y0, x1, y1]`,
    /// with its safe circle at `center`.
    fn site(rect: [f64; 4], center: [f64; 2], radius: f64, height: f64) -> Site {
        let [x0, y0, x1, y1] = rect;
        Site {
            rank: 1,
            shell: vec![
                [x0, y0, height],
                [x1, y0, height],
                [x1, y1, height],
                [x0, y1, height],
            ],
            holes: vec![],
            plane_height_m: height,
            center: [center[0], center[1], height],
            center_geodetic: None,
            safe_radius_m: radius,
            area_m2: (x1 - x0) * (y1 - y0),
            normal: [0.0, 0.0, 1.0],
            point_count: 0,
            triangle_count: 0,
        }
    }

    /// The streaks of `answers` (each one site on resolved ground) fed in order.
    fn fed(answers: &[Site]) -> Vec<Streak> {
        let mut tracked: Vec<(Site, Streak)> = Vec::new();
        let mut out = Vec::new();
        for a in answers {
            tracked = streaks(
                &tracked,
                std::slice::from_ref(a),
                &[true],
                3 + WANDER_ANSWERS,
            );
            out.push(tracked[0].1.clone());
        }
        out
    }

    fn runs(answers: &[Site]) -> Vec<u32> {
        fed(answers).iter().map(|s| s.run).collect()
    }

    /// The radius the catalog takes after `answers`, with `min_frames` 3.
    fn admitted_radius(answers: &[Site]) -> Option<f64> {
        let last = fed(answers).pop()?;
        last.admitted(3).map(|c| c.radius)
    }

    /// Seed 7301 with realistic pose noise, building 31 at visit 0: the fused answers' circle on
    /// the target roof grew from 4.08 m to 4.48 m in the last two answers, 0.53 m into a tarp the
    /// model called roof, and the catalog took the last answer's circle. It takes the disk the
    /// last three answers agree on, inside the 4.23 m circle 0.4 m away.
    #[test]
    fn the_catalog_takes_the_disk_the_last_answers_agree_on_not_the_newest_guess() {
        let roof = [120.0, 33.0, 139.0, 50.0];
        let answers = [
            site(roof, [129.5, 41.3], 4.08, 31.5),
            site(roof, [129.3, 41.5], 4.23, 31.5),
            site(roof, [129.3, 41.9], 4.48, 31.5),
            site(roof, [129.3, 41.9], 4.48, 31.5),
        ];
        let radius = admitted_radius(&answers).unwrap();
        assert!((radius - 3.83).abs() < 1e-9, "{radius}");
        // Answers that agree give the whole circle; two answers are not enough.
        let steady = [answers[0].clone(), answers[0].clone(), answers[0].clone()];
        assert_eq!(admitted_radius(&steady), Some(4.08));
        assert_eq!(admitted_radius(&steady[..2]), None);
    }

    #[test]
    fn a_circle_that_no_earlier_circle_holds_is_not_admitted_until_the_answers_settle() {
        let roof = [163.0, 245.0, 167.0, 255.0];
        let north = site(roof, [165.0, 252.7], 1.8, 28.0);
        let south = site(roof, [165.2, 246.8], 1.9, 28.0);
        // Streak of 3, but the north circle holds the south centre of none before it.
        let jumped = [south.clone(), south.clone(), north.clone()];
        assert_eq!(runs(&jumped), [1, 2, 3]);
        assert_eq!(admitted_radius(&jumped), None);
        // The circles from before the answer wandered still vouch for the one it came back to.
        let back = [
            north.clone(),
            north.clone(),
            south.clone(),
            south.clone(),
            north,
        ];
        assert_eq!(admitted_radius(&back), Some(1.8));
    }

    /// Seed 6101, building 63 of world 6102 at visit 2: a 4 x 12 m roof whose widest circles lie
    /// at both ends; the fused answers picked one end for 27 answers, the other for 4, then the
    /// first again in the last answer, and the catalog got nothing from the approach (the last
    /// answer's site had a run of 1).
    #[test]
    fn a_streak_survives_the_answer_picking_another_widest_circle_of_the_region() {
        let roof = [163.0, 245.0, 167.0, 255.0];
        let north = site(roof, [165.0, 252.7], 1.8, 28.0);
        let south = site(roof, [165.2, 246.8], 1.9, 28.0);
        let answers = [north.clone(), north.clone(), south.clone(), south, north];
        assert_eq!(runs(&answers), [1, 2, 3, 4, 5]);
    }

    #[test]
    fn a_streak_restarts_on_another_region_or_plane_and_off_resolved_ground() {
        let roof = site([0.0, 0.0, 4.0, 12.0], [2.0, 2.0], 1.8, 28.0);
        // A separate roof beside it: the earlier point is outside its polygon.
        let beside = site([6.0, 0.0, 10.0, 12.0], [8.0, 9.0], 1.8, 28.0);
        assert_eq!(runs(&[roof.clone(), roof.clone(), beside]), [1, 2, 1]);
        // The same outline a storey higher (a rooftop structure's top): another plane.
        let above = site([0.0, 0.0, 4.0, 12.0], [2.0, 9.0], 1.8, 31.0);
        assert_eq!(runs(&[roof.clone(), roof.clone(), above]), [1, 2, 1]);
        // Not on resolved ground: no streak, and the next answer starts again.
        let tracked = streaks(
            &[],
            std::slice::from_ref(&roof),
            &[true],
            3 + WANDER_ANSWERS,
        );
        let off = streaks(
            &tracked,
            std::slice::from_ref(&roof),
            &[false],
            3 + WANDER_ANSWERS,
        );
        assert_eq!(off[0].1.run, 0);
        let again = streaks(
            &off[..0],
            std::slice::from_ref(&roof),
            &[true],
            3 + WANDER_ANSWERS,
        );
        assert_eq!(again[0].1.run, 1);
    }
}
