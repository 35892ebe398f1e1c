//! Scoring the fleet's catalog over a revisit set (`landing eval --catalog`): every visit's
//! approach goes through the service as one fused stream, in time order (file-name order), and
//! after each one the catalog is searched around the visit's target roofs. Each returned site is
//! judged against the world as it is at that visit (that recording's ground truth):
//!
//! - **unsafe**: unsafe now although this visit re-confirmed it (its `last_confirmed` is at or
//!   after the visit's stream began): the catalog kept or wrote a wrong site; must be 0;
//! - **stale**: unsafe now, but last confirmed before this visit: a change the fleet has not
//!   seen yet, counted with its age;
//! - **recall**: of the target roofs with a true landable circle of at least
//!   [`CatalogConfig::min_truth_radius_m`], the share on which the catalog has a safe site.
//!
//! The catalog must be fresh: [`run_catalog`] refuses a catalog that already holds sites around
//! the set's roofs, since their confirmations would not be this run's.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant, SystemTime};

use landing_client::v1::{CatalogSite, GeodeticPoint};
use landing_client::{LandingClient, SiteSearch};
use landing_geometry::geodetic::{Geodetic, enu_to_geodetic, geodetic_to_enu};
use serde::Serialize;

use crate::EvalError;
use crate::geom::{Grid, Polygon2};
use crate::metrics::{MetricsParams, RoofTruth, Site, judge_site, landable_mask};
use crate::report::Mode;
use crate::run::{EvalConfig, Scenario, approaches, run_streams, scoring_params};

/// How the catalog is scored.
#[derive(Debug, Clone, PartialEq)]
pub struct CatalogConfig {
    /// The mode every approach is streamed in (model, or truth for the upper bound).
    pub mode: Mode,
    /// Options, metrics and window of the fused streams (its `modes` are replaced by `mode`).
    pub eval: EvalConfig,
    /// How long to wait after a stream for the catalog to show this visit's confirmations (the
    /// server writes them in batches, every `catalog.flush_interval_s`): at most this, and a
    /// third of it without change once a confirmation of this visit shows.
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

/// One returned site, judged at one visit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SiteScore {
    /// The visit's recording.
    pub visit: String,
    pub visit_index: u32,
    pub site_id: String,
    /// The roof (building id) the site stands on in the visit's truth.
    pub roof: Option<u32>,
    /// Site centre in the world's local frame, metres.
    pub center: [f64; 3],
    pub radius_m: f64,
    /// The judge's verdict, as text.
    pub verdict: String,
    pub unsafe_now: bool,
    /// Confirmed by this visit's stream (`last_confirmed` at or after its start).
    pub confirmed_this_visit: bool,
    /// Now minus `last_confirmed`, seconds.
    pub age_s: f64,
}

/// The counts of one visit index (or of all visits).
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CatalogRow {
    /// Visit index (`None`: all visits).
    pub visit_index: Option<u32>,
    /// Approaches (recordings) streamed.
    pub approaches: usize,
    /// Frames refused or unanswered in those streams.
    pub failed_frames: usize,
    /// Distinct sites returned.
    pub sites: usize,
    /// Unsafe sites this visit confirmed (must be 0).
    pub unsafe_sites: usize,
    /// Unsafe sites not confirmed by this visit, with their ages (seconds).
    pub stale: usize,
    pub stale_ages_s: Vec<f64>,
    /// Target roofs with a true landable circle of at least the minimum radius.
    pub landable_roofs: usize,
    /// Of those, the roofs on which the catalog returned a safe site.
    pub found_roofs: usize,
}

impl CatalogRow {
    /// found / landable roofs; `None` without landable roofs.
    pub fn recall(&self) -> Option<f64> {
        (self.landable_roofs > 0).then(|| self.found_roofs as f64 / self.landable_roofs as f64)
    }

    fn add(&mut self, o: &CatalogRow) {
        self.approaches += o.approaches;
        self.failed_frames += o.failed_frames;
        self.sites += o.sites;
        self.unsafe_sites += o.unsafe_sites;
        self.stale += o.stale;
        self.stale_ages_s.extend(&o.stale_ages_s);
        self.landable_roofs += o.landable_roofs;
        self.found_roofs += o.found_roofs;
    }
}

/// The catalog's scores over a revisit set.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct CatalogReport {
    pub mode: Option<Mode>,
    /// One row per visit index, in order.
    pub per_visit: Vec<CatalogRow>,
    pub overall: CatalogRow,
    pub sites: Vec<SiteScore>,
}

impl CatalogReport {
    /// The report from the per-approach rows.
    pub fn from_rows(mode: Mode, rows: Vec<CatalogRow>, sites: Vec<SiteScore>) -> Self {
        let mut by_visit: BTreeMap<Option<u32>, CatalogRow> = BTreeMap::new();
        let mut overall = CatalogRow::default();
        for r in &rows {
            by_visit
                .entry(r.visit_index)
                .or_insert_with(|| CatalogRow {
                    visit_index: r.visit_index,
                    ..Default::default()
                })
                .add(r);
            overall.add(r);
        }
        Self {
            mode: Some(mode),
            per_visit: by_visit.into_values().collect(),
            overall,
            sites,
        }
    }

    /// The table: one line per visit index and one for all.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{:<6} {:>10} {:>6} {:>6} {:>6} {:>19} {:>13}",
            "visit", "approaches", "sites", "unsafe", "stale", "stale age s p50/max", "recall"
        );
        for r in self.per_visit.iter().chain([&self.overall]) {
            let _ = writeln!(s, "{}", row_text(r));
        }
        s
    }

    /// The table as Markdown, for `catalog.md`.
    pub fn to_markdown(&self) -> String {
        let mut s = String::from(
            "# Catalog\n\nEvery visit's approach streamed fused, in time order; after each, the \
             catalog searched around the visit's target roofs and each site judged against the \
             world at that visit. **unsafe**: unsafe now although this visit confirmed it (must \
             be 0); **stale**: unsafe now, last confirmed before this visit; **recall**: target \
             roofs with a true circle of at least the minimum radius on which a safe site was \
             returned.\n\n",
        );
        let _ = writeln!(s, "```\n{}```", self.to_text());
        s
    }

    /// Whether an unsafe (not stale) site was returned.
    pub fn has_unsafe(&self) -> bool {
        self.overall.unsafe_sites > 0
    }
}

fn row_text(r: &CatalogRow) -> String {
    let visit = r.visit_index.map_or("all".into(), |v| format!("v{v:02}"));
    let ages = if r.stale_ages_s.is_empty() {
        "-".to_string()
    } else {
        let mut a = r.stale_ages_s.clone();
        a.sort_by(f64::total_cmp);
        format!("{:.1}/{:.1}", a[a.len() / 2], a[a.len() - 1])
    };
    let recall = r.recall().map_or("-".into(), |v| {
        format!("{}/{} {v:.2}", r.found_roofs, r.landable_roofs)
    });
    format!(
        "{visit:<6} {:>10} {:>6} {:>6} {:>6} {ages:>19} {recall:>13}",
        r.approaches, r.sites, r.unsafe_sites, r.stale
    )
}

/// Writes `catalog.md` and `catalog.json` into `dir`.
pub fn write_catalog_report(dir: &Path, report: &CatalogReport) -> Result<(), EvalError> {
    let io = |path: &Path| {
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

/// One visit: one recording's approach, its frames in order.
#[derive(Debug, Clone)]
pub struct Visit {
    pub name: String,
    /// The visit index of the file name (`vKK-…`); `None` when it has none.
    pub index: Option<u32>,
    pub frames: Vec<Scenario>,
    /// The world's origin the frames carry.
    pub origin: Geodetic,
    /// Every roof in view over the approach (first seen wins), targets included.
    pub roofs: Vec<RoofTruth>,
}

impl Visit {
    fn targets(&self) -> impl Iterator<Item = &RoofTruth> {
        self.roofs.iter().filter(|r| r.target && r.scored)
    }
}

/// The visit index of a revisit set's file name `vKK-w…`.
pub fn visit_index(name: &str) -> Option<u32> {
    let rest = name.strip_prefix('v')?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    (rest[digits.len()..].starts_with('-') && !digits.is_empty())
        .then(|| digits.parse().ok())
        .flatten()
}

/// The visits of `scenarios` in time order (their recordings' names in order). Every frame must
/// carry a geodetic origin.
pub fn visits(scenarios: &[Scenario]) -> Result<Vec<Visit>, EvalError> {
    let mut out = Vec::new();
    for approach in approaches(scenarios) {
        let frames: Vec<Scenario> = approach.iter().map(|&i| scenarios[i].clone()).collect();
        let name = frames[0].at.approach.clone();
        let origin = frames[0]
            .frame
            .geodetic_origin
            .as_ref()
            .map(geodetic)
            .ok_or_else(|| EvalError::Invalid {
                field: "frame.geodetic_origin",
                reason: format!("{name}: --catalog needs frames with a WGS-84 origin"),
            })?;
        let mut roofs: Vec<RoofTruth> = Vec::new();
        for r in frames.iter().flat_map(|f| &f.roofs) {
            let same = |o: &&RoofTruth| o.id == r.id && o.height_m == r.height_m;
            if !roofs.iter().any(|o| same(&o)) {
                roofs.push(r.clone());
            }
        }
        out.push(Visit {
            index: visit_index(&name),
            name,
            frames,
            origin,
            roofs,
        });
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

fn geodetic(p: &GeodeticPoint) -> Geodetic {
    Geodetic {
        latitude_deg: p.latitude_deg,
        longitude_deg: p.longitude_deg,
        altitude_m: p.altitude_m,
    }
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

/// The distinct sites the catalog returns around the visit's target roofs.
async fn sites_near_targets(
    client: &LandingClient,
    visit: &Visit,
) -> Result<Vec<CatalogSite>, EvalError> {
    let mut out: Vec<CatalogSite> = Vec::new();
    for roof in visit.targets() {
        let Some(search) = roof_search(visit.origin, roof) else {
            continue;
        };
        for s in client.search_landing_sites(search).await?.sites {
            if !out.iter().any(|o| o.id == s.id) {
                out.push(s);
            }
        }
    }
    Ok(out)
}

fn confirmed_at(s: &CatalogSite) -> Option<SystemTime> {
    s.last_confirmed.and_then(|t| SystemTime::try_from(t).ok())
}

/// Refuses a catalog that already holds sites around the set's target roofs.
async fn check_fresh(client: &LandingClient, visits: &[Visit]) -> Result<(), EvalError> {
    for v in visits {
        let found = sites_near_targets(client, v).await?;
        if let Some(s) = found.first() {
            let c = s.center.unwrap_or_default();
            return Err(EvalError::Invalid {
                field: "catalog",
                reason: format!(
                    "the catalog is not fresh: it already holds {} site(s) around the target roofs of {} (e.g. `{}` at {:.6}, {:.6}); start the server on a new catalog (LANDING__CATALOG__PATH=<new file>)",
                    found.len(),
                    v.name,
                    s.id,
                    c.latitude_deg,
                    c.longitude_deg
                ),
            });
        }
    }
    Ok(())
}

/// Streams every visit in time order and scores the catalog after each ([module docs](self)).
/// `progress` gets (visits done, visits).
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
    let visits = visits(scenarios)?;
    check_fresh(client, &visits).await?;
    let (mut rows, mut sites) = (Vec::new(), Vec::new());
    for (k, visit) in visits.iter().enumerate() {
        let started = SystemTime::now();
        let (_, failures) =
            run_streams(client, &visit.frames, &eval, &fusion, &params, |_| {}).await?;
        let found = settle(client, visit, started, config.wait).await?;
        let (mut row, scores) = score_visit(visit, &found, started, &params, config);
        row.failed_frames = failures.len();
        rows.push(row);
        sites.extend(scores);
        progress(k + 1, visits.len());
    }
    Ok(CatalogReport::from_rows(config.mode, rows, sites))
}

/// The sites around the visit's targets once the catalog shows a confirmation from this visit
/// and has then stayed the same for a third of `wait` (the stream's last observation may land
/// in a later batch than its first), or after `wait` (a visit may confirm nothing).
async fn settle(
    client: &LandingClient,
    visit: &Visit,
    started: SystemTime,
    wait: Duration,
) -> Result<Vec<CatalogSite>, EvalError> {
    let deadline = Instant::now() + wait;
    let quiet = wait / 3;
    let mut last: Option<(Vec<CatalogSite>, Instant)> = None;
    loop {
        let found = sites_near_targets(client, visit).await?;
        let fresh = found
            .iter()
            .any(|s| confirmed_at(s).is_some_and(|t| t >= started));
        let since = match last {
            Some((prev, since)) if prev == found => since,
            _ => Instant::now(),
        };
        if (fresh && since.elapsed() >= quiet) || Instant::now() >= deadline {
            return Ok(found);
        }
        last = Some((found, since));
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Judges the sites found after `visit` against its truth.
pub fn score_visit(
    visit: &Visit,
    found: &[CatalogSite],
    started: SystemTime,
    params: &MetricsParams,
    config: &CatalogConfig,
) -> (CatalogRow, Vec<SiteScore>) {
    let now = SystemTime::now();
    let mut row = CatalogRow {
        visit_index: visit.index,
        approaches: 1,
        sites: found.len(),
        ..Default::default()
    };
    let mut scores = Vec::new();
    let mut safe_on: Vec<u32> = Vec::new();
    for s in found {
        let score = score_site(visit, s, started, now, params);
        if score.unsafe_now && score.confirmed_this_visit {
            row.unsafe_sites += 1;
        } else if score.unsafe_now {
            row.stale += 1;
            row.stale_ages_s.push(score.age_s);
        } else if let Some(id) = score.roof {
            safe_on.push(id);
        }
        scores.push(score);
    }
    for roof in visit.targets() {
        if true_radius(roof, params.cell_m) >= config.min_truth_radius_m {
            row.landable_roofs += 1;
            row.found_roofs += usize::from(safe_on.contains(&roof.id));
        }
    }
    (row, scores)
}

/// One catalog site judged against the visit's roofs, in the world's local frame.
fn score_site(
    visit: &Visit,
    s: &CatalogSite,
    started: SystemTime,
    now: SystemTime,
    params: &MetricsParams,
) -> SiteScore {
    let c = s.center.as_ref().map_or(
        Geodetic {
            latitude_deg: f64::NAN,
            longitude_deg: f64::NAN,
            altitude_m: f64::NAN,
        },
        geodetic,
    );
    let enu = geodetic_to_enu(visit.origin, c);
    let site = Site {
        rank: 0,
        polygon: Polygon2::default(),
        center: [enu[0], enu[1]],
        plane_height_m: enu[2],
        radius_m: s.safe_radius_m,
    };
    let judged = judge_site(&site, &visit.roofs, params);
    let confirmed = confirmed_at(s);
    SiteScore {
        visit: visit.name.clone(),
        visit_index: visit.index.unwrap_or(0),
        site_id: s.id.clone(),
        roof: judged.roof.map(|i| visit.roofs[i].id),
        center: enu,
        radius_m: s.safe_radius_m,
        verdict: format!("{:?}", judged.verdict),
        unsafe_now: judged.verdict.is_unsafe(),
        confirmed_this_visit: confirmed.is_some_and(|t| t >= started),
        age_s: confirmed
            .and_then(|t| now.duration_since(t).ok())
            .map_or(0.0, |d| d.as_secs_f64()),
    }
}

/// The radius of the largest circle on the whole walkable roof clear of its obstacles, on a grid
/// of `cell_m` (0 when the roof has none).
pub fn true_radius(roof: &RoofTruth, cell_m: f64) -> f64 {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn visit_index_from_file_names() {
        assert_eq!(visit_index("v00-w6101-b003.mcap"), Some(0));
        assert_eq!(visit_index("v12-w1-b000.mcap"), Some(12));
        assert_eq!(visit_index("w1-b000.mcap"), None);
        assert_eq!(visit_index("v-w1.mcap"), None);
    }

    #[test]
    fn rows_add_up_per_visit_and_overall() {
        let row = |v, unsafe_sites, stale, landable, found| CatalogRow {
            visit_index: Some(v),
            approaches: 1,
            sites: unsafe_sites + stale + found,
            unsafe_sites,
            stale,
            stale_ages_s: vec![5.0; stale],
            landable_roofs: landable,
            found_roofs: found,
            ..Default::default()
        };
        let r = CatalogReport::from_rows(
            Mode::Model,
            vec![row(0, 0, 0, 1, 1), row(1, 0, 1, 1, 0), row(1, 1, 0, 1, 1)],
            vec![],
        );
        assert_eq!(r.per_visit.len(), 2);
        assert_eq!(r.per_visit[1].approaches, 2);
        assert_eq!(r.per_visit[1].recall(), Some(0.5));
        assert_eq!((r.overall.unsafe_sites, r.overall.stale), (1, 1));
        assert!(r.has_unsafe());
        assert!(r.to_text().contains("all"), "{}", r.to_text());
    }

    /// A 20 m square roof at 20 m with a 4 m obstacle in its north-east corner.
    fn roof_with_obstacle() -> RoofTruth {
        RoofTruth {
            obstacles: vec![crate::metrics::Obstacle {
                class: 1,
                footprint: Polygon2::rect([14.0, 14.0], [18.0, 18.0]),
                seen: true,
            }],
            outline: Polygon2::rect([0.0, 0.0], [20.0, 20.0]),
            interior: Polygon2::rect([0.0, 0.0], [20.0, 20.0]),
            ..square_roof()
        }
    }

    const ORIGIN: Geodetic = Geodetic {
        latitude_deg: 40.75,
        longitude_deg: -73.98,
        altitude_m: 10.0,
    };

    fn catalog_site(id: &str, enu: [f64; 3], radius_m: f64, at: SystemTime) -> CatalogSite {
        let g = enu_to_geodetic(ORIGIN, enu);
        CatalogSite {
            id: id.into(),
            center: Some(GeodeticPoint {
                latitude_deg: g.latitude_deg,
                longitude_deg: g.longitude_deg,
                altitude_m: g.altitude_m,
            }),
            safe_radius_m: radius_m,
            last_confirmed: Some(at.into()),
            ..Default::default()
        }
    }

    #[test]
    fn unsafe_when_confirmed_by_the_visit_stale_when_older() {
        let visit = Visit {
            name: "v01-w1-b000.mcap".into(),
            index: Some(1),
            frames: vec![],
            origin: ORIGIN,
            roofs: vec![roof_with_obstacle()],
        };
        let started = SystemTime::now() - Duration::from_secs(10);
        let before = started - Duration::from_secs(3600);
        let found = [
            // Safe, in the clear south-west: counts for recall.
            catalog_site(
                "safe",
                [5.0, 5.0, 20.0],
                3.0,
                started + Duration::from_secs(1),
            ),
            // On the obstacle, confirmed by this visit: unsafe.
            catalog_site(
                "bad",
                [15.0, 15.0, 20.0],
                2.0,
                started + Duration::from_secs(2),
            ),
            // On the obstacle, confirmed an hour before the visit: stale.
            catalog_site("old", [16.0, 16.0, 20.0], 1.5, before),
        ];
        let params = MetricsParams::default();
        let (row, scores) =
            score_visit(&visit, &found, started, &params, &CatalogConfig::default());
        assert_eq!(
            (row.sites, row.unsafe_sites, row.stale),
            (3, 1, 1),
            "{scores:#?}"
        );
        assert_eq!((row.found_roofs, row.landable_roofs), (1, 1));
        assert!((row.stale_ages_s[0] - 3610.0).abs() < 5.0, "{row:?}");
        // The centres come back into the local frame.
        assert!(
            (scores[0].center[0] - 5.0).abs() < 1e-6 && (scores[0].center[2] - 20.0).abs() < 1e-6
        );
        assert_eq!(scores[0].roof, Some(0));
    }

    fn square_roof() -> RoofTruth {
        RoofTruth {
            id: 0,
            outline: Polygon2::rect([0.0, 0.0], [10.0, 10.0]),
            interior: Polygon2::rect([0.0, 0.0], [10.0, 10.0]),
            height_m: 20.0,
            obstacles: vec![],
            scanned: Some(Polygon2::default()),
            hidden: vec![],
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target: true,
        }
    }

    #[test]
    fn true_radius_of_a_clear_square_roof() {
        let roof = square_roof();
        let r = true_radius(&roof, 0.05);
        assert!((r - 5.0).abs() < 0.1, "{r}");
    }
}
