//! Property tests of the update rule on seeded random scenes: stored sites and one observation in
//! a 200 m square, checked against the rule's statements one by one (`landing_catalog::rule`).

use std::collections::HashSet;

use landing_catalog::rule::{plan, same_roof};
use landing_catalog::{
    LatLon, LocalFrame, Observation, ObservedSite, Polygon, Site, SiteId, SiteKind, Timestamp,
};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};

const ORIGIN: LatLon = LatLon::new(47.3769, 8.5417);

fn square(x: f64, y: f64, half: f64) -> Polygon {
    let f = LocalFrame::new(ORIGIN);
    Polygon::rectangle(
        f.to_lat_lon((x - half, y - half)),
        f.to_lat_lon((x + half, y + half)),
    )
}

fn t(s: i64) -> Timestamp {
    Timestamp::from_unix_ms(s * 1000)
}

/// (x, y, radius, height level, time)
fn stored_site() -> impl Strategy<Value = (f64, f64, f64, u8, i64)> {
    (0.0..200.0, 0.0..200.0, 0.5..8.0, 0u8..3, 0i64..100)
}

fn new_site() -> impl Strategy<Value = (f64, f64, f64, u8)> {
    (0.0..200.0, 0.0..200.0, 0.5..8.0, 0u8..3)
}

fn scene() -> impl Strategy<Value = (Vec<Site>, Observation, Vec<(Timestamp, Polygon)>)> {
    (
        prop::collection::vec(stored_site(), 0..25),
        prop::collection::vec(new_site(), 0..8),
        prop::collection::vec((0.0..200.0, 0.0..200.0, 5.0..60.0), 0..3),
        prop::collection::vec((0.0..200.0, 0.0..200.0, 5.0..60.0, 0i64..100), 0..3),
        0i64..100,
    )
        .prop_map(|(stored, new, seen, newer, obs_t)| {
            let f = LocalFrame::new(ORIGIN);
            let stored = stored
                .into_iter()
                .enumerate()
                .map(|(i, (x, y, r, level, at))| Site {
                    id: SiteId(i as i64 + 1),
                    kind: if i % 7 == 6 {
                        SiteKind::Candidate
                    } else {
                        SiteKind::Confirmed
                    },
                    polygon: square(x, y, r + 1.0),
                    center: f.to_lat_lon((x, y)),
                    safe_radius_m: r,
                    plane_height_m: f64::from(level) * 0.4,
                    area_m2: 0.0,
                    first_seen: t(at - 5),
                    last_confirmed: t(at),
                    frames: 3,
                    approaches: 1,
                    drone_id: "d".into(),
                    approach_id: format!("old{}", i % 2),
                    model_id: "m".into(),
                    source_id: None,
                })
                .collect();
            let obs = Observation {
                t: t(obs_t),
                drone_id: "d2".into(),
                approach_id: "old0".into(),
                model_id: "m2".into(),
                seen: seen.into_iter().map(|(x, y, h)| square(x, y, h)).collect(),
                sites: new
                    .into_iter()
                    .map(|(x, y, r, level)| ObservedSite {
                        polygon: square(x, y, r + 1.0),
                        center: f.to_lat_lon((x, y)),
                        safe_radius_m: r,
                        plane_height_m: f64::from(level) * 0.4,
                        frames: 2,
                    })
                    .collect(),
            };
            let newer = newer
                .into_iter()
                .map(|(x, y, h, at)| (t(at), square(x, y, h)))
                .collect();
            (stored, obs, newer)
        })
}

#[test]
fn the_rule_holds_on_random_scenes() {
    let config = Config {
        cases: 2000,
        failure_persistence: None,
        ..Config::default()
    };
    let mut runner =
        TestRunner::new_with_rng(config, TestRng::deterministic_rng(RngAlgorithm::ChaCha));
    runner
        .run(&scene(), |(stored, obs, newer)| {
            let p = plan(&obs, &stored, &newer);
            let updated: HashSet<SiteId> = p.updates.iter().map(|s| s.id).collect();
            let deleted: HashSet<SiteId> = p.deletes.iter().copied().collect();
            prop_assert_eq!(
                updated.len(),
                p.updates.len(),
                "a site is updated at most once"
            );
            prop_assert!(updated.is_disjoint(&deleted), "updated and deleted");
            // Every new site is inserted, updates one stored site, or is dropped as stale.
            prop_assert_eq!(
                p.inserts.len() + p.updates.len() + p.report.dropped_stale as usize,
                obs.sites.len()
            );
            prop_assert_eq!(p.report.withdrawn + p.report.merged, p.deletes.len() as u64);
            for s in &stored {
                let touched = updated.contains(&s.id) || deleted.contains(&s.id);
                if s.kind == SiteKind::Candidate || s.last_confirmed > obs.t {
                    prop_assert!(!touched, "candidates and newer sites are never touched");
                    continue;
                }
                let in_seen = obs
                    .seen
                    .iter()
                    .any(|a| a.meets_circle(s.center, s.safe_radius_m));
                let matched = obs.sites.iter().any(|n| same_roof(s, n));
                if in_seen {
                    // Seen: confirmed by a new site, else gone (withdrawn or merged).
                    prop_assert!(touched, "a seen site is re-judged");
                }
                if !in_seen && !matched {
                    prop_assert!(!touched, "an unseen, unmatched site keeps its age");
                }
            }
            for u in &p.updates {
                let before = stored.iter().find(|s| s.id == u.id).unwrap();
                prop_assert_eq!(u.last_confirmed, obs.t);
                prop_assert!(u.first_seen <= before.first_seen);
                prop_assert_eq!(u.frames, before.frames + 2);
                let same_approach = before.approach_id == obs.approach_id;
                prop_assert_eq!(u.approaches, before.approaches + u64::from(!same_approach));
                prop_assert!(
                    obs.sites
                        .iter()
                        .any(|n| n.center == u.center && same_roof(before, n))
                );
            }
            for i in &p.inserts {
                prop_assert_eq!(
                    (i.first_seen, i.last_confirmed, i.approaches),
                    (obs.t, obs.t, 1)
                );
            }
            // No new site that newer knowledge covers is written.
            for w in p.inserts.iter().chain(&p.updates) {
                for (at, area) in &newer {
                    prop_assert!(!(*at > obs.t && area.meets_circle(w.center, w.safe_radius_m)));
                }
            }
            Ok(())
        })
        .unwrap();
}

/// Regression: a roof divided by a new obstacle into two sites that both overlap the stored one:
/// the larger takes the stored record, the smaller is a new site, nothing is withdrawn.
#[test]
fn a_divided_roof_keeps_its_record_and_gains_one() {
    let f = LocalFrame::new(ORIGIN);
    let stored = Site {
        id: SiteId(1),
        kind: SiteKind::Confirmed,
        polygon: square(0.0, 0.0, 9.0),
        center: f.to_lat_lon((0.0, 0.0)),
        safe_radius_m: 8.0,
        plane_height_m: 20.0,
        area_m2: 0.0,
        first_seen: t(1),
        last_confirmed: t(2),
        frames: 1,
        approaches: 1,
        drone_id: String::new(),
        approach_id: "a".into(),
        model_id: String::new(),
        source_id: None,
    };
    let piece = |x: f64, r: f64| ObservedSite {
        polygon: square(x, 0.0, r),
        center: f.to_lat_lon((x, 0.0)),
        safe_radius_m: r,
        plane_height_m: 20.0,
        frames: 1,
    };
    let obs = Observation {
        t: t(10),
        approach_id: "b".into(),
        seen: vec![square(0.0, 0.0, 12.0)],
        sites: vec![piece(-5.0, 3.0), piece(5.0, 3.5)],
        ..Default::default()
    };
    let p = plan(&obs, &[stored], &[]);
    assert_eq!(
        (p.updates.len(), p.inserts.len(), p.deletes.len()),
        (1, 1, 0)
    );
    assert_eq!(p.updates[0].safe_radius_m, 3.5);
    assert_eq!(p.updates[0].first_seen, t(1));
    assert_eq!(p.inserts[0].first_seen, t(10));
}

/// Regression: a roof cleared of an obstacle: one new site overlaps two stored ones; the nearer is
/// updated, the other merged into it, with the earliest first-seen time.
#[test]
fn a_cleared_roof_merges_its_records() {
    let f = LocalFrame::new(ORIGIN);
    let stored = |id: i64, x: f64, first: i64| Site {
        id: SiteId(id),
        kind: SiteKind::Confirmed,
        polygon: square(x, 0.0, 3.0),
        center: f.to_lat_lon((x, 0.0)),
        safe_radius_m: 3.0,
        plane_height_m: 20.0,
        area_m2: 0.0,
        first_seen: t(first),
        last_confirmed: t(5),
        frames: 1,
        approaches: 1,
        drone_id: String::new(),
        approach_id: "a".into(),
        model_id: String::new(),
        source_id: None,
    };
    let obs = Observation {
        t: t(10),
        approach_id: "b".into(),
        seen: vec![],
        sites: vec![ObservedSite {
            polygon: square(1.0, 0.0, 8.0),
            center: f.to_lat_lon((1.0, 0.0)),
            safe_radius_m: 7.0,
            plane_height_m: 20.2,
            frames: 1,
        }],
        ..Default::default()
    };
    let p = plan(&obs, &[stored(1, -4.0, 4), stored(2, 4.0, 2)], &[]);
    assert_eq!(p.updates.len(), 1);
    assert_eq!(p.updates[0].id, SiteId(2), "the nearer record");
    assert_eq!(p.updates[0].first_seen, t(2));
    assert_eq!(p.deletes, [SiteId(1)]);
    assert_eq!(p.report.merged, 1);
}
