//! Scoring the fleet's catalog over a revisit set (`landing eval --catalog`): every approach goes
//! through the service as one fused stream, in time order (file-name order: `vKK-wW-bB`), and
//! after each one (a **check**) the catalog is searched around **every** target roof of every
//! world, the roofs any visit flies. Each returned site is judged against the world as it is at
//! that moment: a visit's changes apply to all roofs when the visit begins, so a roof changed
//! at visit v whose approach has not come yet in visit v shows what the fleet has not seen.
//! [`score`] says how a site is classed (unsafe: must be 0; stale: made unsafe by a change no
//! drone has seen yet, followed until withdrawn or confirmed again; fine) and how recall is
//! counted (the roofs the latest approach re-scanned).
//!
//! The catalog must be fresh: [`run_catalog`] refuses a catalog that already holds sites around
//! the set's roofs, since their confirmations would not be this run's.

pub mod score;

use std::time::{Duration, Instant, SystemTime};

use landing_client::v1::CatalogSite;
use landing_client::{LandingClient, SiteSearch};
use landing_geometry::geodetic::{Geodetic, enu_to_geodetic};

use crate::EvalError;
use crate::metrics::RoofTruth;
use crate::report::Mode;
use crate::run::{EvalConfig, Scenario, approaches, run_streams, scoring_params};
pub use score::{
    CatalogReport, CatalogRow, Check, Class, Found, SiteScore, StaleEpisode, Streamed, WorldTruth,
    score_check, stale_episodes, true_radius,
};

/// How the catalog is scored.
#[derive(Debug, Clone, PartialEq)]
pub struct CatalogConfig {
    /// The mode every approach is streamed in (model, or truth for the upper bound).
    pub mode: Mode,
    /// Options, metrics and window of the fused streams (its `modes` are replaced by `mode`).
    pub eval: EvalConfig,
    /// How long to wait after a stream for the catalog to show its confirmations (the server
    /// writes them in batches, every `catalog.flush_interval_s`): at most this, and a third of
    /// it without change once a confirmation of this approach shows.
    pub wait: Duration,
    /// A target roof counts for recall when its true landable circle is at least this, metres.
    pub min_truth_radius_m: f64,
}

impl Default for CatalogConfig {
    fn default() -> Self {
        Self {
            mode: Mode::Model,
            eval: EvalConfig::default(),
            wait: Duration::from_secs(4),
            min_truth_radius_m: 1.0,
        }
    }
}

/// Writes `catalog.md` and `catalog.json` into `dir`.
pub fn write_catalog_report(
    dir: &std::path::Path,
    report: &CatalogReport,
) -> Result<(), EvalError> {
    let io = |path: &std::path::Path| {
        let path = path.display().to_string();
        move |e: std::io::Error| EvalError::Io { path, source: e }
    };
    std::fs::create_dir_all(dir).map_err(io(dir))?;
    let md = dir.join("catalog.md");
    std::fs::write(&md, report.to_markdown()).map_err(io(&md))?;
    let js = dir.join("catalog.json");
    let text = serde_json::to_string_pretty(report).map_err(|e| EvalError::Invalid {
        field: "catalog.json",
        reason: e.to_string(),
    })?;
    std::fs::write(&js, text).map_err(io(&js))
}

/// One approach of the set: one recording, its frames in order.
#[derive(Debug, Clone)]
pub struct Approach {
    pub name: String,
    /// The visit index of the file name (`vKK-…`); 0 when it has none.
    pub visit: u32,
    /// Index into [`RevisitSet::worlds`].
    pub world: usize,
    pub frames: Vec<Scenario>,
    /// Every roof in view over the approach (first seen wins), targets included.
    pub roofs: Vec<RoofTruth>,
}

impl Approach {
    fn targets(&self) -> Vec<&RoofTruth> {
        self.roofs.iter().filter(|r| r.target && r.scored).collect()
    }

    /// The world's clock at the last frame, seconds.
    fn world_time_s(&self) -> f64 {
        self.frames
            .last()
            .and_then(|f| f.frame.timestamp)
            .map_or(0.0, |t| t.seconds as f64 + f64::from(t.nanos) * 1e-9)
    }
}

/// A revisit set: its approaches in time order and its worlds.
#[derive(Debug, Clone)]
pub struct RevisitSet {
    pub approaches: Vec<Approach>,
    pub worlds: Vec<WorldTruth>,
}

/// The visit index of a revisit set's file name `vKK-w…`.
pub fn visit_index(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('v')?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    (rest[digits.len()..].starts_with('-') && !digits.is_empty())
        .then(|| digits.parse().ok())
        .flatten()
}

/// The world of a recording's name: `w6101` in `v00-w6101-b004.mcap` (or in `w6101-b004.mcap`);
/// the whole name when it has no such part.
pub fn world_label(name: &str) -> &str {
    let rest = match visit_index(name) {
        Some(_) => name.split_once('-').map_or(name, |(_, r)| r),
        None => name,
    };
    let end = rest.find(['-', '.']).unwrap_or(rest.len());
    if rest.starts_with('w') && end > 1 {
        &rest[..end]
    } else {
        name
    }
}

/// `scenarios` as a revisit set: approaches in time order (their recordings' names in order),
/// grouped into worlds by name. Every frame must carry a geodetic origin, the same within a world.
pub fn revisit_set(scenarios: &[Scenario]) -> Result<RevisitSet, EvalError> {
    let mut set = RevisitSet {
        approaches: Vec::new(),
        worlds: Vec::new(),
    };
    for approach in approaches(scenarios) {
        let frames: Vec<Scenario> = approach.iter().map(|&i| scenarios[i].clone()).collect();
        let name = frames[0].at.approach.clone();
        let origin = approach_origin(&name, &frames)?;
        let roofs = union(frames.iter().flat_map(|f| &f.roofs));
        let label = world_label(&name);
        let world = match set.worlds.iter().position(|w| w.label == label) {
            Some(w) if set.worlds[w].origin != origin => {
                return Err(EvalError::Invalid {
                    field: "frame.geodetic_origin",
                    reason: format!("{name}: another origin than the world's other recordings"),
                });
            }
            Some(w) => w,
            None => {
                set.worlds.push(WorldTruth {
                    label: label.to_string(),
                    origin,
                    targets: Vec::new(),
                    visits: Default::default(),
                });
                set.worlds.len() - 1
            }
        };
        set.approaches.push(Approach {
            visit: visit_index(&name).unwrap_or(0),
            name,
            world,
            frames,
            roofs,
        });
    }
    set.approaches.sort_by(|a, b| a.name.cmp(&b.name));
    for a in &set.approaches {
        let w = &mut set.worlds[a.world];
        w.targets = union(w.targets.iter().chain(a.targets()));
        let at = w.visits.entry(a.visit).or_default();
        *at = union(at.iter().chain(&a.roofs));
    }
    Ok(set)
}

/// The roofs, each once (the same id and height: first wins).
fn union<'a>(roofs: impl Iterator<Item = &'a RoofTruth>) -> Vec<RoofTruth> {
    let mut out: Vec<RoofTruth> = Vec::new();
    for r in roofs {
        if !out.iter().any(|o| o.id == r.id && o.height_m == r.height_m) {
            out.push(r.clone());
        }
    }
    out
}

fn approach_origin(name: &str, frames: &[Scenario]) -> Result<Geodetic, EvalError> {
    let p = frames[0]
        .frame
        .geodetic_origin
        .as_ref()
        .ok_or_else(|| EvalError::Invalid {
            field: "frame.geodetic_origin",
            reason: format!("{name}: --catalog needs frames with a WGS-84 origin"),
        })?;
    Ok(Geodetic {
        latitude_deg: p.latitude_deg,
        longitude_deg: p.longitude_deg,
        altitude_m: p.altitude_m,
    })
}

/// The search around `roof`: centred on its outline's bounding box in WGS-84, wide enough to
/// cover the whole roof.
pub fn roof_search(origin: Geodetic, roof: &RoofTruth) -> Option<SiteSearch> {
    let (min, max) = roof.outline.bounds()?;
    let c = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let g = enu_to_geodetic(origin, [c[0], c[1], roof.height_m]);
    let radius = (max[0] - min[0]).hypot(max[1] - min[1]) / 2.0 + 1.0;
    Some(SiteSearch::near(g.latitude_deg, g.longitude_deg, radius).page_size(1000))
}

/// The distinct sites the catalog returns around `roofs` of world `world`, added to `out`.
async fn search_roofs(
    client: &LandingClient,
    world: (usize, &WorldTruth),
    roofs: &[&RoofTruth],
    out: &mut Vec<Found>,
) -> Result<(), EvalError> {
    for roof in roofs {
        let Some(search) = roof_search(world.1.origin, roof) else {
            continue;
        };
        for site in client.search_landing_sites(search).await?.sites {
            if !out
                .iter()
                .any(|o| o.world == world.0 && o.site.id == site.id)
            {
                out.push(Found {
                    world: world.0,
                    site,
                });
            }
        }
    }
    Ok(())
}

/// Every site the catalog returns around every target roof of every world.
async fn sweep(client: &LandingClient, worlds: &[WorldTruth]) -> Result<Vec<Found>, EvalError> {
    let mut out = Vec::new();
    for (w, world) in worlds.iter().enumerate() {
        let targets: Vec<&RoofTruth> = world.targets.iter().collect();
        search_roofs(client, (w, world), &targets, &mut out).await?;
    }
    Ok(out)
}

fn confirmed_at(s: &CatalogSite) -> Option<SystemTime> {
    s.last_confirmed.and_then(|t| SystemTime::try_from(t).ok())
}

/// Refuses a catalog that already holds sites around the set's target roofs.
async fn check_fresh(client: &LandingClient, worlds: &[WorldTruth]) -> Result<(), EvalError> {
    let found = sweep(client, worlds).await?;
    let Some(f) = found.first() else {
        return Ok(());
    };
    let c = f.site.center.unwrap_or_default();
    Err(EvalError::Invalid {
        field: "catalog",
        reason: format!(
            "the catalog is not fresh: it already holds {} site(s) around the target roofs of {} (e.g. `{}` at {:.6}, {:.6}); start the server on a new catalog (LANDING__CATALOG__PATH=<new file>)",
            found.len(),
            worlds[f.world].label,
            f.site.id,
            c.latitude_deg,
            c.longitude_deg
        ),
    })
}

/// Streams every approach in time order and checks the catalog after each ([module
/// docs](self)). `progress` gets (approaches done, approaches).
pub async fn run_catalog(
    client: &LandingClient,
    scenarios: &[Scenario],
    config: &CatalogConfig,
    mut progress: impl FnMut(usize, usize),
) -> Result<CatalogReport, EvalError> {
    let eval = EvalConfig {
        modes: vec![config.mode],
        ..config.eval.clone()
    };
    let params = scoring_params(client, &eval).await?;
    let fusion = eval.stream.unwrap_or_default();
    let set = revisit_set(scenarios)?;
    check_fresh(client, &set.worlds).await?;
    let (mut streamed, mut checks) = (Vec::new(), Vec::new());
    for (k, a) in set.approaches.iter().enumerate() {
        let started = SystemTime::now();
        let (_, failures) = run_streams(client, &a.frames, &eval, &fusion, &params, |_| {}).await?;
        streamed.push(Streamed {
            name: a.name.clone(),
            visit: a.visit,
            world: a.world,
            started,
            world_time_s: a.world_time_s(),
            failed_frames: failures.len(),
        });
        let world = (a.world, &set.worlds[a.world]);
        settle(client, world, &a.targets(), started, config.wait).await?;
        let found = sweep(client, &set.worlds).await?;
        checks.push(score_check(
            &streamed,
            &a.targets(),
            &set.worlds,
            &found,
            SystemTime::now(),
            &params,
            config.min_truth_radius_m,
        ));
        progress(k + 1, set.approaches.len());
    }
    Ok(CatalogReport::from_checks(config.mode, checks))
}

/// Waits until the catalog shows a confirmation from this approach around its targets and has
/// then stayed the same there for a third of `wait` (the stream's last observation may land in
/// a later batch than its first), or until `wait` is over (an approach may confirm nothing).
async fn settle(
    client: &LandingClient,
    world: (usize, &WorldTruth),
    targets: &[&RoofTruth],
    started: SystemTime,
    wait: Duration,
) -> Result<(), EvalError> {
    let deadline = Instant::now() + wait;
    let quiet = wait / 3;
    let mut last: Option<(Vec<Found>, Instant)> = None;
    loop {
        let mut found = Vec::new();
        search_roofs(client, world, targets, &mut found).await?;
        let fresh = found
            .iter()
            .any(|f| confirmed_at(&f.site).is_some_and(|t| t >= started));
        let since = match last {
            Some((prev, since)) if prev == found => since,
            _ => Instant::now(),
        };
        if (fresh && since.elapsed() >= quiet) || Instant::now() >= deadline {
            return Ok(());
        }
        last = Some((found, since));
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::approach::ApproachFrame;
    use landing_client::v1::{Frame, GeodeticPoint};

    #[test]
    fn visit_index_and_world_from_file_names() {
        assert_eq!(visit_index("v00-w6101-b003.mcap"), Some(0));
        assert_eq!(visit_index("v12-w1-b000.mcap"), Some(12));
        assert_eq!(visit_index("w1-b000.mcap"), None);
        assert_eq!(visit_index("v-w1.mcap"), None);
        assert_eq!(world_label("v00-w6101-b003.mcap"), "w6101");
        assert_eq!(world_label("w7-b000.mcap"), "w7");
        assert_eq!(world_label("approach.mcap"), "approach.mcap");
    }

    fn roof(id: u32, target: bool) -> RoofTruth {
        RoofTruth {
            id,
            outline: crate::geom::Polygon2::rect([0.0, 0.0], [10.0, 10.0]),
            interior: crate::geom::Polygon2::rect([0.0, 0.0], [10.0, 10.0]),
            height_m: 20.0,
            obstacles: vec![],
            scanned: None,
            hidden: vec![],
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target,
        }
    }

    /// One frame of recording `name` over roofs `target` (and `neighbour`) at latitude `lat`.
    fn frame(name: &str, target: u32, neighbour: u32, lat: f64) -> Scenario {
        Scenario {
            name: format!("{name}#0"),
            at: ApproachFrame {
                approach: name.into(),
                ..Default::default()
            },
            tags: vec![],
            frame: Frame {
                geodetic_origin: Some(GeodeticPoint {
                    latitude_deg: lat,
                    longitude_deg: -73.98,
                    altitude_m: 0.0,
                }),
                ..Default::default()
            },
            labels: None,
            roofs: vec![roof(target, true), roof(neighbour, false)],
        }
    }

    #[test]
    fn a_revisit_set_in_time_order_with_each_worlds_targets_and_truth_per_visit() {
        let scenarios = [
            frame("v01-w2-b005.mcap", 5, 6, 40.8),
            frame("v00-w1-b001.mcap", 1, 2, 40.7),
            frame("v00-w2-b005.mcap", 5, 6, 40.8),
            frame("v00-w1-b003.mcap", 3, 1, 40.7),
            frame("v01-w1-b001.mcap", 1, 2, 40.7),
        ];
        let set = revisit_set(&scenarios).unwrap();
        let names: Vec<&str> = set.approaches.iter().map(|a| a.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "v00-w1-b001.mcap",
                "v00-w1-b003.mcap",
                "v00-w2-b005.mcap",
                "v01-w1-b001.mcap",
                "v01-w2-b005.mcap"
            ]
        );
        let labels: Vec<&str> = set.worlds.iter().map(|w| w.label.as_str()).collect();
        assert_eq!(labels, ["w2", "w1"], "in the order first read");
        let w1 = &set.worlds[1];
        let ids = |roofs: &[RoofTruth]| roofs.iter().map(|r| r.id).collect::<Vec<_>>();
        assert_eq!(ids(&w1.targets), [1, 3], "every roof any visit flies");
        assert_eq!(
            ids(w1.roofs_at(0)),
            [1, 2, 3],
            "visit 0: both approaches' roofs"
        );
        assert_eq!(ids(w1.roofs_at(1)), [1, 2]);
        assert_eq!(set.approaches[3].visit, 1);

        let mut moved = scenarios.to_vec();
        moved[4]
            .frame
            .geodetic_origin
            .as_mut()
            .unwrap()
            .latitude_deg = 41.0;
        let err = revisit_set(&moved).unwrap_err().to_string();
        assert!(
            err.contains("geodetic_origin") && err.contains("v01-w1-b001"),
            "{err}"
        );
        let mut bare = scenarios.to_vec();
        bare[0].frame.geodetic_origin = None;
        let err = revisit_set(&bare).unwrap_err().to_string();
        assert!(err.contains("WGS-84 origin"), "{err}");
    }
}
