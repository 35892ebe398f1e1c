//! The fleet's landing-site catalog from the command line: `landing sites` searches it through the
//! server (a table, `--json`, or `--geojson` that a GIS tool opens as it is), and `landing catalog
//! import` loads candidate roofs (building footprints with heights, GeoJSON) straight into the
//! catalog's store.
//!
//! Import goes to the store, not through the server: it is an operator's bulk load (like a
//! migration), the service has no write call to authorise and expose for it, and the store serves
//! both at once (SQLite in WAL mode, PostgreSQL).

use std::io::Write;
use std::path::PathBuf;
use std::time::SystemTime;

use clap::{Args, Subcommand, ValueEnum};
use landing_catalog::{
    Found, LatLon, Location, Polygon, Site, SiteId, SiteKind, Timestamp, geojson,
};
use landing_client::SiteSearch;
use landing_proto::v1::{CatalogSite, SiteOrder};
use serde_json::json;

use crate::args::{CliError, ConnectionArgs, connect, exit, io, usage};

/// `landing sites`.
#[derive(Debug, Clone, Args)]
pub struct SitesArgs {
    /// The centre of the search: `LAT,LON` in degrees (WGS-84).
    #[arg(long, value_name = "LAT,LON")]
    pub near: String,
    /// The search radius, metres.
    #[arg(long)]
    pub radius: f64,
    /// At most this many sites.
    #[arg(long, default_value_t = 20)]
    pub limit: i32,
    /// Leave out sites whose safe radius is smaller, metres.
    #[arg(long, default_value_t = 0.0)]
    pub min_safe_radius: f64,
    /// Leave out sites last confirmed longer ago, seconds (default: the server's
    /// `catalog.max_age_s`).
    #[arg(long)]
    pub max_age_s: Option<f64>,
    /// The order of the sites.
    #[arg(long, value_enum, default_value_t = Order::Distance)]
    pub order: Order,
    /// Also list candidate roofs known beforehand, after the confirmed sites.
    #[arg(long)]
    pub candidates: bool,
    /// Print a GeoJSON FeatureCollection (WGS-84, RFC 7946) instead of a table (over `--json`).
    #[arg(long)]
    pub geojson: bool,
}

/// `--order` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Order {
    /// Nearest first.
    Distance,
    /// Largest safe radius first.
    SafeRadius,
    /// Most recently confirmed first.
    Freshness,
}

/// `landing catalog`.
#[derive(Debug, Clone, Subcommand)]
pub enum CatalogCommand {
    /// Import candidate roofs (GeoJSON building footprints with roof heights) into the catalog's
    /// store: they are returned after confirmed sites, marked as candidates, never as sites.
    Import(ImportArgs),
}

/// `landing catalog import`.
#[derive(Debug, Clone, Args)]
pub struct ImportArgs {
    /// The GeoJSON file: a FeatureCollection of Polygon footprints with a height property.
    pub file: PathBuf,
    /// The catalog: the server's SQLite file or its `postgres://` URL (the server's
    /// `catalog.path` or `catalog.url`).
    #[arg(long, default_value = "data/catalog.sqlite")]
    pub catalog: String,
}

/// `landing sites`: one search, printed as a table, JSON (`json`) or GeoJSON.
pub async fn sites(
    connection: &ConnectionArgs,
    a: &SitesArgs,
    json: bool,
    out: &mut (dyn Write + Send),
) -> Result<u8, CliError> {
    let (lat, lon) = lat_lon(&a.near)?;
    let mut search = SiteSearch::near(lat, lon, a.radius)
        .page_size(a.limit)
        .min_safe_radius_m(a.min_safe_radius)
        .include_candidates(a.candidates)
        .order(match a.order {
            Order::Distance => SiteOrder::Unspecified,
            Order::SafeRadius => SiteOrder::SafeRadius,
            Order::Freshness => SiteOrder::Freshness,
        });
    if let Some(s) = a.max_age_s {
        if !(s > 0.0 && s.is_finite()) {
            return Err(usage(format!("--max-age-s {s} must be positive")));
        }
        search = search.max_age(std::time::Duration::from_secs_f64(s));
    }
    let client = connect(connection).await?;
    let page = client.search_landing_sites(search).await?;
    if a.geojson {
        let found: Vec<Found> = page.sites.iter().map(found).collect();
        writeln!(out, "{}", geojson::write_results(&found)).map_err(io)?;
    } else if json {
        let sites: Vec<_> = page.sites.iter().map(site_json).collect();
        writeln!(
            out,
            "{}",
            json!({ "sites": sites, "next_page_token": page.next_page_token })
        )
        .map_err(io)?;
    } else {
        print_table(&page.sites, out).map_err(io)?;
    }
    Ok(exit::OK)
}

/// `landing catalog import`: reads the file, opens the store (off the async runtime: the
/// PostgreSQL client runs a runtime of its own) and stores the candidates in one transaction.
pub async fn import(a: &ImportArgs, out: &mut (dyn Write + Send)) -> Result<u8, CliError> {
    let text = std::fs::read_to_string(&a.file).map_err(|e| CliError {
        code: exit::ERROR,
        message: format!("cannot read `{}`: {e}", a.file.display()),
    })?;
    let candidates = geojson::read_candidates(&text).map_err(|e| CliError {
        code: exit::ERROR,
        message: format!("`{}`: {e}", a.file.display()),
    })?;
    let location = Location::parse(&a.catalog, "--catalog").map_err(|e| usage(e.to_string()))?;
    if let Location::Sqlite(path) = &location
        && let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
    {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let n = candidates.len();
    let stored = tokio::task::spawn_blocking(move || {
        location
            .open()?
            .import_candidates(&candidates, Timestamp::now())
    })
    .await
    .map_err(|e| CliError {
        code: exit::ERROR,
        message: format!("import: {e}"),
    })?
    .map_err(|e| CliError {
        code: exit::ERROR,
        message: format!("catalog {}: {e}", a.catalog_shown()),
    })?;
    writeln!(
        out,
        "imported {stored} candidate roofs of {n} features from {}",
        a.file.display()
    )
    .map_err(io)?;
    Ok(exit::OK)
}

impl ImportArgs {
    /// The catalog as it may be printed: a URL without its password.
    fn catalog_shown(&self) -> String {
        match Location::parse(&self.catalog, "--catalog") {
            Ok(l @ Location::Postgres(_)) => format!("{l:?}"),
            _ => self.catalog.clone(),
        }
    }
}

/// `LAT,LON` in degrees.
fn lat_lon(text: &str) -> Result<(f64, f64), CliError> {
    let parsed = text
        .split_once(',')
        .and_then(|(a, b)| Some((a.trim().parse().ok()?, b.trim().parse().ok()?)));
    parsed.ok_or_else(|| usage(format!("--near {text:?}: expected LAT,LON in degrees")))
}

fn print_table(sites: &[CatalogSite], out: &mut dyn Write) -> std::io::Result<()> {
    if sites.is_empty() {
        return writeln!(out, "no sites known there");
    }
    writeln!(
        out,
        "{:>6}  {:<9}  {:>11}  {:>12}  {:>8}  {:>8}  {:>9}  {:>6}  {:>5}",
        "id", "kind", "latitude", "longitude", "radius_m", "dist_m", "age", "frames", "appr"
    )?;
    let now = SystemTime::now();
    for s in sites {
        let center = s.center.unwrap_or_default();
        let age = s
            .last_confirmed
            .and_then(|t| SystemTime::try_from(t).ok())
            .and_then(|t| now.duration_since(t).ok())
            .map_or_else(|| "-".to_owned(), |d| format!("{:.0} s", d.as_secs_f64()));
        let kind = if s.kind == landing_proto::v1::SiteKind::Candidate as i32 {
            "candidate"
        } else {
            "site"
        };
        writeln!(
            out,
            "{:>6}  {:<9}  {:>11.6}  {:>12.6}  {:>8.2}  {:>8.1}  {:>9}  {:>6}  {:>5}",
            s.id,
            kind,
            center.latitude_deg,
            center.longitude_deg,
            s.safe_radius_m,
            s.distance_m,
            age,
            s.frames,
            s.approaches
        )?;
    }
    writeln!(
        out,
        "catalog sites are candidates for a drone to confirm with its own stream, never a clearance to land"
    )
}

fn site_json(s: &CatalogSite) -> serde_json::Value {
    let center = s.center.unwrap_or_default();
    let time = |t: &Option<prost_types::Timestamp>| {
        t.and_then(|t| SystemTime::try_from(t).ok())
            .map(|t| Timestamp::from(t).to_rfc3339())
    };
    json!({
        "id": s.id,
        "kind": if s.kind == landing_proto::v1::SiteKind::Candidate as i32 { "candidate" } else { "site" },
        "latitude_deg": center.latitude_deg,
        "longitude_deg": center.longitude_deg,
        "safe_radius_m": s.safe_radius_m,
        "plane_height_m": s.plane_height_m,
        "area_m2": s.area_m2,
        "distance_m": s.distance_m,
        "first_seen": time(&s.first_seen),
        "last_confirmed": time(&s.last_confirmed),
        "frames": s.frames,
        "approaches": s.approaches,
        "drone_id": s.drone_id,
        "model_id": s.model_id,
    })
}

/// A returned site as the catalog's own record, for its GeoJSON writer.
fn found(s: &CatalogSite) -> Found {
    let ring = |r: &landing_proto::v1::GeodeticRing| {
        r.points
            .iter()
            .map(|p| LatLon::new(p.latitude_deg, p.longitude_deg))
            .collect::<Vec<_>>()
    };
    let mut rings = s.polygon.iter().map(ring);
    let exterior = rings.next().unwrap_or_default();
    let center = s.center.unwrap_or_default();
    let time = |t: &Option<prost_types::Timestamp>| {
        t.and_then(|t| SystemTime::try_from(t).ok())
            .map(Timestamp::from)
            .unwrap_or_default()
    };
    let candidate = s.kind == landing_proto::v1::SiteKind::Candidate as i32;
    Found {
        site: Site {
            id: SiteId(s.id.parse().unwrap_or(0)),
            kind: if candidate {
                SiteKind::Candidate
            } else {
                SiteKind::Confirmed
            },
            polygon: Polygon::new(exterior, rings.collect()),
            center: LatLon::new(center.latitude_deg, center.longitude_deg),
            safe_radius_m: s.safe_radius_m,
            plane_height_m: s.plane_height_m,
            area_m2: s.area_m2,
            first_seen: time(&s.first_seen),
            last_confirmed: time(&s.last_confirmed),
            frames: s.frames,
            approaches: s.approaches,
            drone_id: s.drone_id.clone(),
            approach_id: String::new(),
            model_id: s.model_id.clone(),
            source_id: None,
        },
        distance_m: s.distance_m,
    }
}
