//! The catalog at city scale: loads a seeded catalog of N records over a 20 km × 20 km city into
//! a store, then times first-page searches (500 m radius, 20 results) in each order.
//!
//! ```text
//! cargo run --release -p landing-catalog --example scale -- --sites 1000000 --store sqlite
//! cargo run --release -p landing-catalog --example scale -- --sites 1000000 --store postgres
//! ```
//!
//! `--store` is `sqlite` (a file in a temporary directory), `sqlite:PATH`, `postgres` (a
//! temporary PostgreSQL + PostGIS server started as the tests start theirs: needs the
//! distribution's packages, `scripts/setup-postgres.sh`) or a connection string
//! (`postgres://…`, `host=… dbname=…`) to an empty database. Other flags: `--queries N` per
//! order and round (default 2000), `--rounds R` (default 2), `--seed S` (default 41), `--apply N`
//! observations applied after the searches, timed (default 2000; 0: none).
//!
//! The city: roofs (8-40 m half-width) half spread evenly, half clustered in twelve districts
//! (Gaussian, σ 1.5-3 km); 1-8 sites per roof, safe radii 1-15 m (small ones commoner), each
//! roof last confirmed at a time spread over eight days (so one in eight is past the default
//! seven-day age and filtered out); one roof in eight is also a candidate (its footprint).
//! Records are loaded in time order, as a catalog grows. Query centres follow the roofs.

#[path = "../tests/support/postgres.rs"]
#[allow(dead_code)]
mod pg;

use std::time::{Duration, Instant};

use landing_catalog::{
    LatLon, LocalFrame, Observation, ObservedSite, Order, Polygon, PostgisStore, SearchQuery, Site,
    SiteId, SiteKind, SqliteStore, Store, Timestamp, distance_m,
};

const CITY_HALF_M: f64 = 10_000.0;
const ORIGIN: LatLon = LatLon::new(40.7128, -74.0060);
const NOW_MS: i64 = 1_796_588_100_000;
const DAY_MS: f64 = 86_400_000.0;
const LOAD_BATCH: usize = 20_000;
const QUERY_RADIUS_M: f64 = 500.0;
const APPLY_BATCH: usize = 50;

struct Args {
    sites: usize,
    store: String,
    queries: usize,
    rounds: usize,
    seed: u64,
    apply: usize,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        sites: 1_000_000,
        store: "sqlite".into(),
        queries: 2000,
        rounds: 2,
        seed: 41,
        apply: 2000,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        let number = |v: String| v.parse::<u64>().map_err(|e| format!("{flag} {v}: {e}"));
        match flag.as_str() {
            "--sites" => a.sites = number(value()?)? as usize,
            "--store" => a.store = value()?,
            "--queries" => a.queries = number(value()?)? as usize,
            "--rounds" => a.rounds = number(value()?)?.max(1) as usize,
            "--seed" => a.seed = number(value()?)?,
            "--apply" => a.apply = number(value()?)? as usize,
            other => return Err(format!("unknown flag {other}")),
        }
    }
    Ok(a)
}

/// xorshift64*: seeded, no dependency.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn gauss(&mut self) -> f64 {
        let (u, v) = (self.unit().max(1e-300), self.unit());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Where roofs are, in metres from the city's centre.
struct City {
    districts: Vec<(f64, f64, f64)>,
}

impl City {
    fn new(rng: &mut Rng) -> Self {
        let districts = (0..12)
            .map(|_| {
                (
                    rng.range(-0.7, 0.7) * CITY_HALF_M,
                    rng.range(-0.7, 0.7) * CITY_HALF_M,
                    rng.range(1500.0, 3000.0),
                )
            })
            .collect();
        City { districts }
    }

    fn place(&self, rng: &mut Rng) -> (f64, f64) {
        loop {
            let (x, y) = if rng.unit() < 0.5 {
                (
                    rng.range(-CITY_HALF_M, CITY_HALF_M),
                    rng.range(-CITY_HALF_M, CITY_HALF_M),
                )
            } else {
                let d = self.districts[(rng.next() % self.districts.len() as u64) as usize];
                (d.0 + d.2 * rng.gauss(), d.1 + d.2 * rng.gauss())
            };
            if x.abs() < CITY_HALF_M && y.abs() < CITY_HALF_M {
                return (x, y);
            }
        }
    }
}

fn square(f: &LocalFrame, (x, y): (f64, f64), half: f64) -> Polygon {
    Polygon::rectangle(
        f.to_lat_lon((x - half, y - half)),
        f.to_lat_lon((x + half, y + half)),
    )
}

/// The catalog's records, in the order they are loaded (oldest first).
fn generate(n: usize, city: &City, rng: &mut Rng) -> Vec<Site> {
    let f = LocalFrame::new(ORIGIN);
    let mut roofs: Vec<(i64, Vec<Site>)> = Vec::new();
    let mut count = 0;
    let mut roof_no = 0u64;
    while count < n {
        roof_no += 1;
        let at = city.place(rng);
        let half = rng.range(8.0, 40.0);
        let height = rng.range(5.0, 200.0);
        let t = NOW_MS - (rng.unit() * 8.0 * DAY_MS) as i64;
        let mut records = Vec::new();
        let per_roof = 1 + (rng.unit() * rng.unit() * 8.0) as usize;
        for k in 0..per_roof {
            let u = rng.unit();
            let r = (1.0 + 14.0 * u * u).min(half - 1.0).max(1.0);
            let room = (half - r - 1.0).max(0.0);
            let c = (at.0 + rng.range(-room, room), at.1 + rng.range(-room, room));
            records.push(Site {
                id: SiteId(0),
                kind: SiteKind::Confirmed,
                polygon: square(&f, c, r + 1.0),
                center: f.to_lat_lon(c),
                safe_radius_m: r,
                plane_height_m: height,
                area_m2: (2.0 * (r + 1.0)).powi(2),
                first_seen: Timestamp::from_unix_ms(t - (rng.unit() * 30.0 * DAY_MS) as i64),
                last_confirmed: Timestamp::from_unix_ms(t + k as i64),
                frames: 1 + rng.next() % 40,
                approaches: 1 + rng.next() % 5,
                drone_id: format!("drone-{}", rng.next() % 64),
                approach_id: format!("approach-{roof_no}"),
                model_id: "rooftop-segmentation".into(),
                source_id: None,
            });
        }
        if rng.unit() < 0.125 {
            records.push(Site {
                id: SiteId(0),
                kind: SiteKind::Candidate,
                polygon: square(&f, at, half),
                center: f.to_lat_lon(at),
                safe_radius_m: half,
                plane_height_m: height,
                area_m2: (2.0 * half).powi(2),
                first_seen: Timestamp::from_unix_ms(NOW_MS - 30 * DAY_MS as i64),
                last_confirmed: Timestamp::from_unix_ms(NOW_MS - 30 * DAY_MS as i64),
                frames: 0,
                approaches: 0,
                drone_id: String::new(),
                approach_id: String::new(),
                model_id: String::new(),
                source_id: Some(format!("building-{roof_no}")),
            });
        }
        count += records.len();
        roofs.push((t, records));
    }
    roofs.sort_by_key(|r| r.0);
    let mut all: Vec<Site> = roofs.into_iter().flat_map(|r| r.1).collect();
    all.truncate(n);
    all
}

/// What a store needs kept alive: a temporary directory or server.
type Guard = Box<dyn std::any::Any>;

/// A store, what it needs kept alive, and for PostGIS its connection string.
type Opened = (Box<dyn Store>, Guard, Option<String>);

/// Opens the store `spec` names.
fn open(spec: &str) -> Result<Opened, String> {
    let err = |e: landing_catalog::Error| e.to_string();
    if spec == "sqlite" {
        let dir = tempfile::tempdir().map_err(|e| e.to_string())?;
        let store = SqliteStore::open(dir.path().join("catalog.sqlite")).map_err(err)?;
        return Ok((Box::new(store), Box::new(dir), None));
    }
    if let Some(path) = spec.strip_prefix("sqlite:") {
        return Ok((
            Box::new(SqliteStore::open(path).map_err(err)?),
            Box::new(()),
            None,
        ));
    }
    if spec == "postgres" {
        let server = pg::shared();
        let url = server.create_database();
        let store = PostgisStore::connect(&url).map_err(err)?;
        return Ok((Box::new(store), Box::new(server), Some(url)));
    }
    Ok((
        Box::new(PostgisStore::connect(spec).map_err(err)?),
        Box::new(()),
        Some(spec.to_string()),
    ))
}

fn percentile(sorted: &[Duration], p: f64) -> f64 {
    let i = ((sorted.len() as f64 - 1.0) * p).round() as usize;
    sorted[i].as_secs_f64() * 1000.0
}

fn main() -> Result<(), String> {
    let args = parse_args()?;
    let mut rng = Rng::new(args.seed);
    let city = City::new(&mut rng);
    let t0 = Instant::now();
    let sites = generate(args.sites, &city, &mut rng);
    let candidates = sites
        .iter()
        .filter(|s| s.kind == SiteKind::Candidate)
        .count();
    println!(
        "generated {} records ({} candidates) in {:.1} s, seed {}",
        sites.len(),
        candidates,
        t0.elapsed().as_secs_f64(),
        args.seed
    );
    let (store, _guard, pg_url) = open(&args.store)?;
    load(&*store, &sites, pg_url.as_deref())?;
    let f = LocalFrame::new(ORIGIN);
    let centers: Vec<LatLon> = (0..args.queries)
        .map(|_| f.to_lat_lon(city.place(&mut rng)))
        .collect();
    let in_circle = density(&sites, &centers[..centers.len().min(200)]);
    println!(
        "a {QUERY_RADIUS_M} m circle around a query centre holds {:.0} records on average, {} at most (of the first {})",
        in_circle.0,
        in_circle.1,
        centers.len().min(200)
    );
    time_searches(&*store, &centers, args.rounds)?;
    if args.apply > 0 {
        time_applies(&*store, &sites, args.apply, &mut rng)?;
    }
    Ok(())
}

/// Loads the records in batches and, on PostGIS, gathers statistics as autovacuum would.
fn load(store: &dyn Store, sites: &[Site], pg_url: Option<&str>) -> Result<(), String> {
    let t0 = Instant::now();
    for batch in sites.chunks(LOAD_BATCH) {
        store.load_sites(batch).map_err(|e| e.to_string())?;
    }
    let load_s = t0.elapsed().as_secs_f64();
    println!(
        "store {}: loaded in {load_s:.1} s: {:.0} sites/s (batches of {LOAD_BATCH}, one transaction each)",
        store.backend(),
        sites.len() as f64 / load_s
    );
    if let Some(url) = pg_url {
        // What autovacuum would do on its own a little later: statistics and the visibility map.
        let t0 = Instant::now();
        postgres::Client::connect(url, postgres::NoTls)
            .and_then(|mut c| c.batch_execute("VACUUM ANALYZE catalog_sites"))
            .map_err(|e| e.to_string())?;
        println!("VACUUM ANALYZE in {:.1} s", t0.elapsed().as_secs_f64());
    }
    Ok(())
}

/// Times first pages in each order (and nearest first's second page), `rounds` times over.
fn time_searches(store: &dyn Store, centers: &[LatLon], rounds: usize) -> Result<(), String> {
    let now = Timestamp::from_unix_ms(NOW_MS);
    let kinds: [(&str, Order, bool); 4] = [
        ("distance", Order::Distance, false),
        ("safe_radius", Order::SafeRadius, false),
        ("freshness", Order::Freshness, false),
        ("distance, page 2", Order::Distance, true),
    ];
    // Warm-up: the first queries of a fresh process read the file or the tables from the cache.
    for c in centers.iter().take(200) {
        let q = SearchQuery::new(*c, QUERY_RADIUS_M);
        store.search(&q, now).map_err(|e| e.to_string())?;
    }
    println!("| round | query | p50 ms | p99 ms | max ms | mean results |");
    println!("|---|---|---|---|---|---|");
    for round in 1..=rounds {
        for (name, order, second_page) in kinds {
            let mut times = Vec::with_capacity(centers.len());
            let mut results = 0usize;
            for c in centers {
                let mut q = SearchQuery::new(*c, QUERY_RADIUS_M);
                q.page_size = 20;
                q.order = order;
                if second_page {
                    let first = store.search(&q, now).map_err(|e| e.to_string())?;
                    if first.next_page_token.is_empty() {
                        continue;
                    }
                    q.page_token = first.next_page_token;
                }
                let t = Instant::now();
                let page = store.search(&q, now).map_err(|e| e.to_string())?;
                times.push(t.elapsed());
                results += page.sites.len();
            }
            times.sort();
            println!(
                "| {round} | {name} | {:.2} | {:.2} | {:.2} | {:.1} |",
                percentile(&times, 0.5),
                percentile(&times, 0.99),
                percentile(&times, 1.0),
                results as f64 / times.len().max(1) as f64
            );
        }
    }
    Ok(())
}

/// Times the update rule's writes: `n` observations, each a drone confirming one stored site
/// again (its polygon seen, the site found as it was: an update of its confirmation time; sites
/// beside it whose circles meet the seen polygon are withdrawn), in batches of [`APPLY_BATCH`]
/// as the server's write queue sends them. Runs after the searches: it changes the catalog.
fn time_applies(store: &dyn Store, sites: &[Site], n: usize, rng: &mut Rng) -> Result<(), String> {
    let confirmed: Vec<&Site> = sites
        .iter()
        .filter(|s| s.kind == SiteKind::Confirmed)
        .collect();
    let observations: Vec<Observation> = (0..n)
        .map(|i| {
            let s = confirmed[(rng.next() % confirmed.len() as u64) as usize];
            Observation {
                t: Timestamp::from_unix_ms(NOW_MS + i as i64 * 100),
                drone_id: "drone-bench".into(),
                approach_id: format!("bench-{i}"),
                model_id: s.model_id.clone(),
                seen: vec![s.polygon.clone()],
                sites: vec![ObservedSite {
                    polygon: s.polygon.clone(),
                    center: s.center,
                    safe_radius_m: s.safe_radius_m,
                    plane_height_m: s.plane_height_m,
                    frames: 1,
                }],
            }
        })
        .collect();
    let t0 = Instant::now();
    let mut updated = 0;
    for batch in observations.chunks(APPLY_BATCH) {
        let report = store.apply(batch).map_err(|e| e.to_string())?;
        updated += report.updated;
    }
    let s = t0.elapsed().as_secs_f64();
    println!(
        "apply: {n} observations in batches of {APPLY_BATCH} in {s:.2} s: {:.0} observations/s, {:.1} ms a batch ({updated} sites updated)",
        n as f64 / s,
        s * 1000.0 / n.div_ceil(APPLY_BATCH) as f64
    );
    Ok(())
}

/// Records within the query radius of each centre: mean and max.
fn density(sites: &[Site], centers: &[LatLon]) -> (f64, usize) {
    let counts: Vec<usize> = centers
        .iter()
        .map(|c| {
            sites
                .iter()
                .filter(|s| distance_m(*c, s.center) <= QUERY_RADIUS_M)
                .count()
        })
        .collect();
    let mean = counts.iter().sum::<usize>() as f64 / counts.len().max(1) as f64;
    (mean, counts.into_iter().max().unwrap_or(0))
}
