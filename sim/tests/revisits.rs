//! Scenario sets with a WGS-84 origin, revisits over changed roofs, and building footprints as
//! GeoJSON.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use landing_sim::footprints::footprints;
use landing_sim::geodetic::{enu_to_geodetic, scenario_origin};
use landing_sim::recording::{
    RecordConfig, Visit, encode_recording, read_pairs, simulate, simulate_in,
};
use landing_sim::revisit::{ChangeKind, ChangeRates, RoofChange, revise};
use landing_sim::scenarios::{
    FOOTPRINTS, MANIFEST, Origin, Revisits, ScenarioConfig, write_scenarios,
};
use landing_sim::scene::NO_PRIM;
use landing_sim::{World, WorldConfig};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "landing-sim-revisits-{}-{name}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// A small set: 1 world, 2 buildings, 2 frames of 64×48.
fn small_set(origin: Origin, revisits: Option<u32>) -> ScenarioConfig {
    let mut record = RecordConfig {
        width: 64,
        height: 48,
        ..Default::default()
    };
    record.flight.frames = 2;
    ScenarioConfig {
        seed: 2026,
        worlds: 1,
        buildings: 2,
        record,
        origin,
        revisits: revisits.map(|count| Revisits {
            count,
            interval_s: 3600.0,
            rates: ChangeRates::default(),
        }),
    }
}

/// Every file of a folder, by name.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let p = e.unwrap().path();
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            (name, std::fs::read(&p).unwrap())
        })
        .collect();
    out.sort();
    out
}

/// The (kind, footprint) of every asset on roof `bi`, as comparable bit patterns.
fn roof_assets(world: &World, bi: usize) -> BTreeSet<(String, Vec<[u64; 2]>)> {
    world.buildings[bi]
        .assets
        .iter()
        .map(|&i| {
            let a = &world.assets[i];
            (a.kind.name().to_string(), bits(&a.footprint()))
        })
        .collect()
}

fn bits(ring: &[[f64; 2]]) -> Vec<[u64; 2]> {
    ring.iter()
        .map(|p| [p[0].to_bits(), p[1].to_bits()])
        .collect()
}

/// The roof's assets before, edited by the reported changes.
fn expected_after(
    before: &World,
    bi: usize,
    changes: &[RoofChange],
) -> BTreeSet<(String, Vec<[u64; 2]>)> {
    let mut set = roof_assets(before, bi);
    for c in changes.iter().filter(|c| c.building == bi) {
        if let Some(b) = &c.before {
            assert!(set.remove(&(c.asset.name().to_string(), bits(b))), "{c:?}");
        }
        if let Some(a) = &c.after {
            assert!(set.insert((c.asset.name().to_string(), bits(a))), "{c:?}");
        }
    }
    set
}

/// Every primitive of an asset stands within its footprint (grown by 0.2 m), and every asset
/// has primitives: moved assets took their primitives along, removed ones left none.
fn assert_prims_follow_assets(world: &World) {
    let mut has = vec![false; world.assets.len()];
    for p in world.prims() {
        if p.asset == NO_PRIM {
            continue;
        }
        let a = &world.assets[p.asset as usize];
        has[p.asset as usize] = true;
        assert_eq!(p.building as usize, a.building);
        let (lo, hi) = p.bounds();
        let mid = [(lo.x + hi.x) as f64 / 2.0, (lo.y + hi.y) as f64 / 2.0];
        let d = (mid[0] - a.center[0]).hypot(mid[1] - a.center[1]);
        let reach = a.half_extents[0].hypot(a.half_extents[1]) + 0.2;
        assert!(
            d <= reach,
            "a primitive of {:?} is {d} m from its centre",
            a.kind
        );
    }
    assert!(has.iter().all(|&h| h), "an asset without primitives");
}

#[test]
fn revisits_are_seeded() {
    let world = World::generate(11, &WorldConfig::default()).unwrap();
    let (a, ca) = revise(&world, 1, &ChangeRates::default()).unwrap();
    let (b, cb) = revise(&world, 1, &ChangeRates::default()).unwrap();
    assert_eq!((&a.assets, &ca), (&b.assets, &cb));
    let (c, _) = revise(&world, 2, &ChangeRates::default()).unwrap();
    assert_ne!(a.assets, c.assets, "visits 1 and 2 drew the same changes");

    let (one, two) = (scratch("seeded-1"), scratch("seeded-2"));
    let config = small_set(Origin::Manhattan, Some(1));
    let s1 = write_scenarios(&config, &one).unwrap();
    let s2 = write_scenarios(&config, &two).unwrap();
    assert_eq!(s1, s2);
    assert_eq!(
        files(&one),
        files(&two),
        "two writes of one revisit set differ"
    );
    for d in [one, two] {
        std::fs::remove_dir_all(d).unwrap();
    }
}

#[test]
fn a_revisit_changes_exactly_what_it_reports() {
    let mut kinds = BTreeSet::new();
    for seed in [2026, 2027] {
        let mut world = World::generate(seed, &WorldConfig::default()).unwrap();
        for visit in 1..=2 {
            let (next, changes) = revise(&world, visit, &ChangeRates::default()).unwrap();
            assert_eq!(next.buildings.len(), world.buildings.len());
            for bi in 0..world.buildings.len() {
                let (b0, b1) = (&world.buildings[bi], &next.buildings[bi]);
                assert_eq!((b0.min, b0.max, b0.height_m), (b1.min, b1.max, b1.height_m));
                let want = expected_after(&world, bi, &changes);
                assert_eq!(
                    roof_assets(&next, bi),
                    want,
                    "world {seed} visit {visit} roof {bi}"
                );
            }
            for c in &changes {
                kinds.insert(c.change);
                if let (Some(i), Some(after)) = (c.asset_index, &c.after) {
                    assert_eq!(next.assets[i].footprint(), *after);
                    assert_eq!(
                        (next.assets[i].building, next.assets[i].kind),
                        (c.building, c.asset)
                    );
                }
            }
            assert_prims_follow_assets(&next);
            world = next;
        }
    }
    assert_eq!(
        kinds,
        ChangeKind::ALL.into_iter().collect(),
        "every kind of change happens"
    );
}

/// The ground truth of a later visit is the changed world: the target roof's obstacles are its
/// assets after the change, and the scan hits what was added or moved where it now stands.
#[test]
fn the_truth_of_a_visit_is_the_world_at_that_visit() {
    let world = World::generate(2026, &WorldConfig::default()).unwrap();
    let (next, changes) = revise(&world, 1, &ChangeRates::default()).unwrap();
    let (mut checked, mut hit) = (0, 0);
    for c in changes.iter().filter(|c| c.asset_index.is_some()).take(6) {
        let config = RecordConfig {
            seed: 2026,
            building: Some(c.building),
            width: 64,
            height: 48,
            visit: Visit::nth(1, 3600.0),
            ..Default::default()
        };
        let frames = simulate_in(&next, &config).unwrap();
        let roof = frames
            .iter()
            .find_map(|f| f.roofs.iter().find(|r| r.building == c.building))
            .expect("the approach sees its roof");
        let seen: BTreeSet<_> = roof.obstacles.iter().map(|o| bits(&o.footprint)).collect();
        let want: BTreeSet<_> = roof_assets(&next, c.building)
            .into_iter()
            .map(|(_, f)| f)
            .collect();
        assert_eq!(seen, want);
        assert!(seen.contains(&bits(c.after.as_ref().unwrap())));
        if let Some(b) = &c.before {
            assert!(
                !seen.contains(&bits(b)),
                "a moved asset is still where it was"
            );
        }
        let i = c.asset_index.unwrap() as u32;
        checked += 1;
        hit += usize::from(frames.iter().any(|f| f.points.iter().any(|p| p.asset == i)));
        // What the scan hits of it lies on its new footprint: its primitives moved with it.
        let a = &next.assets[i as usize];
        let (s, co) = a.yaw.sin_cos();
        for p in frames
            .iter()
            .flat_map(|f| &f.points)
            .filter(|p| p.asset == i)
        {
            let d = [p.world[0] - a.center[0], p.world[1] - a.center[1]];
            let local = [co * d[0] + s * d[1], -s * d[0] + co * d[1]];
            assert!(
                (0..2).all(|k| local[k].abs() <= a.half_extents[k] + 0.05),
                "{:?} hit at {local:?}, half extents {:?}",
                a.kind,
                a.half_extents
            );
        }
    }
    assert!(
        checked >= 4 && hit * 2 > checked,
        "{hit} of {checked} changed assets scanned"
    );
}

#[test]
fn without_revisits_nothing_changes() {
    let world = World::generate(5, &WorldConfig::default()).unwrap();
    let (same, changes) = revise(&world, 1, &ChangeRates::NONE).unwrap();
    assert!(changes.is_empty());
    assert_eq!(same.assets, world.assets);
    assert_eq!(same.buildings, world.buildings);
    // The same primitives (the tree may order them otherwise), so the same frames.
    let key = |w: &World| {
        let mut p: Vec<String> = w.prims().iter().map(|p| format!("{p:?}")).collect();
        p.sort();
        p
    };
    assert_eq!(key(&same), key(&world));
    let config = RecordConfig {
        seed: 5,
        width: 64,
        height: 48,
        ..Default::default()
    };
    let (a, b) = (
        simulate_in(&world, &config).unwrap(),
        simulate_in(&same, &config).unwrap(),
    );
    for (fa, fb) in a.iter().zip(&b) {
        assert!(fa.image == fb.image && fa.points == fb.points && fa.roofs == fb.roofs);
    }

    // A plain set is today's: names, no manifest or footprints, and the bytes of the recording
    // that `simulate` makes on its own.
    let dir = scratch("plain");
    let config = small_set(Origin::None, None);
    let summary = write_scenarios(&config, &dir).unwrap();
    let written = files(&dir);
    let names: Vec<&str> = written.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["w2026-b029.mcap", "w2026-b083.mcap"]);
    assert_eq!((summary.files, summary.frames, summary.changes), (2, 4, 0));
    for (name, bytes) in &written {
        let b: usize = name[7..10].parse().unwrap();
        let rc = config.record_config(2026, b, Visit::FIRST);
        assert_eq!(rc.drone_id, format!("w2026-b{b}"));
        let (w, frames) = simulate(&rc).unwrap();
        assert!(
            encode_recording(&w, &frames, &rc).unwrap() == *bytes,
            "{name} changed"
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}

/// With an origin, every frame carries it and nothing else changes.
#[test]
fn the_origin_is_carried_and_changes_nothing_else() {
    let (plain, placed) = (scratch("origin-none"), scratch("origin-manhattan"));
    write_scenarios(&small_set(Origin::None, None), &plain).unwrap();
    write_scenarios(&small_set(Origin::Manhattan, None), &placed).unwrap();
    assert!(placed.join(FOOTPRINTS).is_file() && !placed.join(MANIFEST).exists());
    let origin = landing_sim::geodetic::geodetic_point(scenario_origin(2026));
    for name in ["w2026-b029.mcap", "w2026-b083.mcap"] {
        let a = read_pairs(&plain.join(name)).unwrap();
        let mut b = read_pairs(&placed.join(name)).unwrap();
        for (frame, _) in &mut b {
            assert_eq!(frame.geodetic_origin, Some(origin));
            frame.geodetic_origin = None;
        }
        assert_eq!(a, b, "{name}: more than the origin differs");
    }
    for d in [plain, placed] {
        std::fs::remove_dir_all(d).unwrap();
    }
}

#[test]
fn revisit_sets_are_listed_in_time_order_with_their_changes() {
    let dir = scratch("manifest");
    let summary = write_scenarios(&small_set(Origin::Manhattan, Some(2)), &dir).unwrap();
    assert_eq!((summary.files, summary.frames), (6, 12));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(MANIFEST)).unwrap()).unwrap();
    assert_eq!(m["footprints"], FOOTPRINTS);
    let visits = m["visits"].as_array().unwrap();
    assert_eq!(visits.len(), 6);
    let starts: Vec<i64> = visits
        .iter()
        .map(|v| v["start_unix_ns"].as_i64().unwrap())
        .collect();
    assert!(starts.windows(2).all(|w| w[0] <= w[1]), "{starts:?}");
    assert_eq!(m["changes"].as_array().unwrap().len(), summary.changes);
    for v in visits {
        let k = v["visit"].as_i64().unwrap();
        let file = v["file"].as_str().unwrap();
        assert!(file.starts_with(&format!("v{k:02}-w2026-b")), "{file}");
        let pairs = read_pairs(&dir.join(file)).unwrap();
        let t = pairs[0].0.timestamp.unwrap();
        assert_eq!(t.seconds, 1_767_225_600 + 3600 * k);
        assert_eq!(
            i128::from(t.seconds) * 1_000_000_000 + i128::from(t.nanos),
            i128::from(v["start_unix_ns"].as_i64().unwrap())
        );
        // Roofs said to have changed in view are in this approach's ground truth.
        for r in v["changed_roofs_in_view"].as_array().unwrap() {
            let r = r.as_u64().unwrap() as u32;
            assert!(
                pairs
                    .iter()
                    .any(|(_, t)| t.roofs.iter().any(|x| x.building == r))
            );
        }
        assert!(k > 0 || v["changed_roofs_in_view"].as_array().unwrap().is_empty());
    }
    std::fs::remove_dir_all(dir).unwrap();
}

/// Signed area of a ring of [lon, lat] (positive counter-clockwise).
fn signed_area(ring: &[[f64; 2]]) -> f64 {
    (0..ring.len() - 1)
        .map(|i| ring[i][0] * ring[i + 1][1] - ring[i + 1][0] * ring[i][1])
        .sum::<f64>()
        / 2.0
}

#[test]
fn footprints_are_valid_geojson_matching_the_buildings() {
    let worlds: Vec<World> = (2026..2028)
        .map(|s| World::generate(s, &WorldConfig::default()).unwrap())
        .collect();
    let placed: Vec<_> = worlds
        .iter()
        .map(|w| (w, scenario_origin(w.seed)))
        .collect();
    let doc = footprints(&placed);
    assert_eq!(doc["type"], "FeatureCollection");
    let features = doc["features"].as_array().unwrap();
    assert_eq!(
        features.len(),
        worlds.iter().map(|w| w.buildings.len()).sum::<usize>()
    );
    let mut ids = BTreeSet::new();
    for f in features {
        assert_eq!(
            (f["type"].as_str(), f["geometry"]["type"].as_str()),
            (Some("Feature"), Some("Polygon"))
        );
        assert!(ids.insert(f["id"].as_str().unwrap().to_string()));
        let p = &f["properties"];
        let (seed, bi) = (
            p["world"].as_u64().unwrap(),
            p["building"].as_u64().unwrap() as usize,
        );
        let (world, origin) = placed.iter().find(|(w, _)| w.seed == seed).unwrap();
        let b = &world.buildings[bi];
        // The catalog's reader takes `roof_height_m` first and adds `ground_elevation_m`.
        assert_eq!(p["roof_height_m"].as_f64(), Some(b.height_m));
        assert_eq!(p["ground_elevation_m"].as_f64(), Some(origin.altitude_m));
        let rings = f["geometry"]["coordinates"].as_array().unwrap();
        assert_eq!(rings.len(), 1);
        let ring: Vec<[f64; 2]> = rings[0]
            .as_array()
            .unwrap()
            .iter()
            .map(|q| [q[0].as_f64().unwrap(), q[1].as_f64().unwrap()])
            .collect();
        assert_eq!(ring.len(), 5);
        assert_eq!(ring[0], ring[4], "the ring is closed");
        assert!(
            signed_area(&ring) > 0.0,
            "the outer ring is counter-clockwise"
        );
        for (q, corner) in ring.iter().zip(b.outline()) {
            assert!((-180.0..=180.0).contains(&q[0]) && (-90.0..=90.0).contains(&q[1]));
            let want = enu_to_geodetic(*origin, [corner[0], corner[1], 0.0]);
            assert_eq!(*q, [want.longitude_deg, want.latitude_deg]);
        }
        // A few metres of the building are a few metres on the ground.
        let m_per_deg_lat = 111_000.0;
        let height = (ring[2][1] - ring[1][1]) * m_per_deg_lat;
        assert!((height - (b.max[1] - b.min[1])).abs() < 0.5, "{height}");
    }
    // Worlds of a set do not overlap: every footprint of one lies outside the other's box.
    let bbox = |seed: u64| {
        let fs = features.iter().filter(|f| f["properties"]["world"] == seed);
        let pts: Vec<[f64; 2]> = fs
            .flat_map(|f| f["geometry"]["coordinates"][0].as_array().unwrap().clone())
            .map(|q| [q[0].as_f64().unwrap(), q[1].as_f64().unwrap()])
            .collect();
        let lo = pts
            .iter()
            .fold([f64::MAX; 2], |a, p| [a[0].min(p[0]), a[1].min(p[1])]);
        let hi = pts
            .iter()
            .fold([f64::MIN; 2], |a, p| [a[0].max(p[0]), a[1].max(p[1])]);
        (lo, hi)
    };
    let ((alo, ahi), (blo, bhi)) = (bbox(2026), bbox(2027));
    assert!(ahi[0] < blo[0] || bhi[0] < alo[0] || ahi[1] < blo[1] || bhi[1] < alo[1]);
}
