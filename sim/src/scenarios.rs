//! The `landing eval` scenario sets: approach flights to many buildings of Manhattan-distribution
//! worlds, one MCAP per approach, and with revisits the same approaches flown again later over
//! roofs that changed in between.
//!
//! [`write_scenarios`] takes [`ScenarioConfig::buildings`] buildings of each of the worlds of
//! seeds `seed, seed + 1, …` (hard cases first: [`scenario_buildings`]). A plain set names its
//! files `w<seed>-b<building>.mcap` (building with three digits), exactly as it always has.
//!
//! With [`Origin::Manhattan`] every frame carries its world's WGS-84 origin
//! ([`crate::geodetic::scenario_origin`]), and the set gets `footprints.geojson`, its worlds'
//! building footprints ([`crate::footprints`]).
//!
//! With [`Revisits`] (count N, interval T), every approach is flown N + 1 times: visit k starts
//! k·T after the first ([`crate::recording::Visit`]) over the world of visit k, which is the
//! world of visit k − 1 changed by [`crate::revisit::revise`]; its ground truth is that world.
//! Files are named `v<k>-w<seed>-b<building>.mcap` (k with two digits), so name order is time
//! order, and `visits.json` lists them:
//!
//! ```text
//! { "format": "landing-sim visits 1", "seed": 2026, "worlds": 6, "buildings": 6,
//!   "revisits": 2, "revisit_interval_s": 3600.0,
//!   "change_rates": { "add": 0.2, "remove": 0.2, "moved": 0.5, "tarp": 0.15 },
//!   "footprints": "footprints.geojson",
//!   "origins": [ { "world": 2026, "latitude_deg": …, "longitude_deg": …, "altitude_m": 0.0 } ],
//!   "visits": [ { "file": "v01-w2026-b029.mcap", "world": 2026, "building": 29, "visit": 1,
//!                 "drone_id": "w2026-b29-v1", "frames": 4, "time_s": 3600.0,
//!                 "start_unix_ns": …, "end_unix_ns": …, "changed_roofs_in_view": [29, 31] } ],
//!   "changes": [ { "world": 2026, "visit": 1, "building": 31, "change": "moved",
//!                  "asset": "seating", "height_m": 0.9, "asset_index": 140,
//!                  "before": [[x, y], …], "after": [[x, y], …] } ] }
//! ```
//!
//! `visits` is in time order (then by file); `changes` lists every change of every roof of the
//! set's worlds at each visit (world-frame footprints, metres; `asset_index` indexes the assets
//! of the visit's world, as `GroundTruth` obstacles do), and `changed_roofs_in_view` names the
//! roofs that changed since the visit before and that the approach's ground truth has in view.

use std::path::{Path, PathBuf};

use serde_json::{Value, json};

use crate::SimError;
use crate::assets::AssetKind;
use crate::footprints::write_footprints;
use crate::geodetic::{Geodetic, scenario_origin};
use crate::recording::{RecordConfig, Visit, encode_recording, frame_time, simulate_in};
use crate::revisit::{ChangeRates, RoofChange, revise};
use crate::world::World;

/// Where the worlds of a set lie on the Earth.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Origin {
    /// Nowhere: frames carry no geodetic origin (the plain sets' default).
    None,
    /// On Manhattan's blocks ([`scenario_origin`]).
    Manhattan,
}

/// Flying every approach again: `count` more visits, `interval_s` apart, with the roofs changed
/// at `rates` before each.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Revisits {
    pub count: u32,
    pub interval_s: f64,
    pub rates: ChangeRates,
}

impl Revisits {
    /// The most revisits a set may have (file names give the visit two digits).
    pub const MAX: u32 = 99;

    /// Checks the count, the interval and the rates.
    pub fn validate(&self) -> Result<(), SimError> {
        if self.count > Self::MAX {
            return Err(SimError::invalid(
                "revisits",
                self.count,
                "must be at most 99",
            ));
        }
        let t = self.interval_s;
        if !(t.is_finite() && t > 0.0 && t * f64::from(self.count) <= 3.2e9) {
            return Err(SimError::invalid(
                "revisit_interval_s",
                t,
                "must be positive, and all visits within 100 years",
            ));
        }
        self.rates.validate()
    }
}

/// What [`write_scenarios`] writes.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioConfig {
    pub seed: u64,
    /// Worlds, of seeds `seed..seed + worlds`.
    pub worlds: u64,
    /// Buildings per world.
    pub buildings: usize,
    /// The flight, image size, LiDAR, pose error and world of every approach; the seed,
    /// building, drone id, origin and visit are set per recording.
    pub record: RecordConfig,
    pub origin: Origin,
    pub revisits: Option<Revisits>,
}

/// What a set holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct SetSummary {
    /// Recordings written.
    pub files: usize,
    /// Frames in them.
    pub frames: usize,
    /// Roof changes between visits, over all the set's worlds.
    pub changes: usize,
}

/// The name of the manifest of a set with revisits.
pub const MANIFEST: &str = "visits.json";
/// The name of the footprints of a set with an origin.
pub const FOOTPRINTS: &str = "footprints.geojson";

impl ScenarioConfig {
    /// The recording of building `b` of world `world_seed` at `visit`.
    pub fn record_config(&self, world_seed: u64, b: usize, visit: Visit) -> RecordConfig {
        let drone_id = match visit.index {
            0 => format!("w{world_seed}-b{b}"),
            k => format!("w{world_seed}-b{b}-v{k}"),
        };
        RecordConfig {
            seed: world_seed,
            building: Some(b),
            drone_id,
            geodetic_origin: self.origin_of(world_seed),
            visit,
            ..self.record.clone()
        }
    }

    /// The origin frames of world `world_seed` carry.
    pub fn origin_of(&self, world_seed: u64) -> Option<Geodetic> {
        match self.origin {
            Origin::None => None,
            Origin::Manhattan => Some(scenario_origin(world_seed)),
        }
    }

    /// The file of building `b` of world `world_seed` at visit `visit`.
    pub fn file_name(&self, world_seed: u64, b: usize, visit: u32) -> String {
        match self.revisits {
            None => format!("w{world_seed}-b{b:03}.mcap"),
            Some(_) => format!("v{visit:02}-w{world_seed}-b{b:03}.mcap"),
        }
    }
}

/// The buildings of `world` in the order the scenario set takes them: hard cases first (tarps,
/// water towers on legs), then a seeded order.
pub fn scenario_buildings(world: &World, world_seed: u64) -> Vec<usize> {
    let has = |b: usize, kind: AssetKind| {
        world.buildings[b]
            .assets
            .iter()
            .any(|&a| world.assets[a].kind == kind)
    };
    let mut order: Vec<usize> = (0..world.buildings.len()).collect();
    order.sort_by_key(|&b| {
        let mix = (b as u64 ^ world_seed).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        (
            !has(b, AssetKind::Tarp),
            !has(b, AssetKind::WaterTower),
            mix,
        )
    });
    order
}

/// Writes the set of `config` into the folder `out` (created if missing; see the module docs).
pub fn write_scenarios(config: &ScenarioConfig, out: &Path) -> Result<SetSummary, SimError> {
    if let Some(r) = &config.revisits {
        r.validate()?;
    }
    std::fs::create_dir_all(out).map_err(|e| SimError::io(out, e))?;
    let mut set = SetWriter {
        config,
        out: out.to_path_buf(),
        summary: SetSummary::default(),
        visits: Vec::new(),
        changes: Vec::new(),
        worlds: Vec::new(),
    };
    for world_seed in config.seed..config.seed + config.worlds {
        set.world(world_seed)?;
    }
    set.finish()
}

/// A set being written.
struct SetWriter<'a> {
    config: &'a ScenarioConfig,
    out: PathBuf,
    summary: SetSummary,
    /// Manifest entries of the recordings, and of the changes.
    visits: Vec<Value>,
    changes: Vec<Value>,
    /// Each world as first visited, with its origin, for the footprints.
    worlds: Vec<(World, Geodetic)>,
}

impl SetWriter<'_> {
    /// Every visit of every approach of world `world_seed`.
    fn world(&mut self, world_seed: u64) -> Result<(), SimError> {
        let c = self.config;
        let mut world = World::generate(world_seed, &c.record.world)?;
        let targets: Vec<usize> = scenario_buildings(&world, world_seed)
            .into_iter()
            .take(c.buildings)
            .collect();
        if let Some(origin) = c.origin_of(world_seed) {
            self.worlds.push((world.clone(), origin));
        }
        let revisits = c.revisits.map_or(0, |r| r.count);
        let mut changed: Vec<RoofChange> = Vec::new();
        for k in 0..=revisits {
            let visit = match c.revisits {
                Some(r) if k > 0 => {
                    let (next, changes) = revise(&world, k, &r.rates)?;
                    world = next;
                    changed = changes;
                    self.record_changes(world_seed, k, &changed);
                    Visit::nth(k, r.interval_s)
                }
                _ => Visit::FIRST,
            };
            for &b in &targets {
                self.approach(&world, world_seed, b, visit, &changed)?;
            }
        }
        Ok(())
    }

    /// One recording: building `b` of `world` at `visit`, after the roof changes `changed`.
    fn approach(
        &mut self,
        world: &World,
        world_seed: u64,
        b: usize,
        visit: Visit,
        changed: &[RoofChange],
    ) -> Result<(), SimError> {
        let rc = self.config.record_config(world_seed, b, visit);
        let frames = simulate_in(world, &rc)?;
        let name = self.config.file_name(world_seed, b, visit.index);
        let path = self.out.join(&name);
        let bytes = encode_recording(world, &frames, &rc)?;
        std::fs::write(&path, bytes).map_err(|e| SimError::io(&path, e))?;
        self.summary.files += 1;
        self.summary.frames += frames.len();
        let mut in_view: Vec<usize> = frames
            .iter()
            .flat_map(|f| f.roofs.iter().map(|r| r.building))
            .filter(|bi| changed.iter().any(|c| c.building == *bi))
            .collect();
        in_view.sort_unstable();
        in_view.dedup();
        let ns = |seq: u64| {
            let t = frame_time(&rc, seq);
            i128::from(t.seconds) * 1_000_000_000 + i128::from(t.nanos)
        };
        let last = frames.len().saturating_sub(1) as u64;
        self.visits.push(json!({
            "file": name,
            "world": world_seed,
            "building": b,
            "visit": visit.index,
            "drone_id": rc.drone_id,
            "frames": frames.len(),
            "time_s": visit.start_offset_s,
            "start_unix_ns": ns(0) as i64,
            "end_unix_ns": ns(last) as i64,
            "changed_roofs_in_view": in_view,
        }));
        Ok(())
    }

    fn record_changes(&mut self, world_seed: u64, visit: u32, changes: &[RoofChange]) {
        self.summary.changes += changes.len();
        self.changes.extend(changes.iter().map(|c| {
            json!({
                "world": world_seed,
                "visit": visit,
                "building": c.building,
                "change": c.change.name(),
                "asset": c.asset.name(),
                "height_m": c.height_m,
                "asset_index": c.asset_index,
                "before": c.before,
                "after": c.after,
            })
        }));
    }

    /// Writes the footprints (with an origin) and the manifest (with revisits).
    fn finish(mut self) -> Result<SetSummary, SimError> {
        let c = self.config;
        let footprints = (!self.worlds.is_empty()).then_some(FOOTPRINTS);
        if footprints.is_some() {
            let worlds: Vec<(&World, Geodetic)> =
                self.worlds.iter().map(|(w, g)| (w, *g)).collect();
            write_footprints(&worlds, &self.out.join(FOOTPRINTS))?;
        }
        let Some(r) = c.revisits else {
            return Ok(self.summary);
        };
        let key = |v: &Value| {
            (
                v["start_unix_ns"].as_i64(),
                v["file"].as_str().map(str::to_owned),
            )
        };
        self.visits.sort_by_key(key);
        let origins: Vec<Value> = self
            .worlds
            .iter()
            .map(|(w, g)| {
                json!({ "world": w.seed, "latitude_deg": g.latitude_deg,
                        "longitude_deg": g.longitude_deg, "altitude_m": g.altitude_m })
            })
            .collect();
        let manifest = json!({
            "format": "landing-sim visits 1",
            "seed": c.seed,
            "worlds": c.worlds,
            "buildings": c.buildings,
            "revisits": r.count,
            "revisit_interval_s": r.interval_s,
            "change_rates": { "add": r.rates.add, "remove": r.rates.remove,
                              "moved": r.rates.moved, "tarp": r.rates.tarp },
            "footprints": footprints,
            "origins": origins,
            "visits": self.visits,
            "changes": self.changes,
        });
        let path = self.out.join(MANIFEST);
        let text = serde_json::to_string_pretty(&manifest).map_err(|e| SimError::Io {
            path: path.display().to_string(),
            source: e.into(),
        })?;
        std::fs::write(&path, text + "\n").map_err(|e| SimError::io(&path, e))?;
        Ok(self.summary)
    }
}
