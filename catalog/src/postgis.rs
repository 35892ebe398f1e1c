//! The fleet store: PostgreSQL with PostGIS, one database that every replica reads and writes.
//!
//! # Schema (version 2)
//!
//! ```sql
//! catalog_schema_version(version INTEGER)
//! catalog_sites(id BIGSERIAL PRIMARY KEY, kind SMALLINT,          -- 0 confirmed, 1 candidate
//!               polygon geography(POLYGON, 4326),                -- the landable polygon
//!               center geography(POINT, 4326),                   -- the safest point (GiST)
//!               bbox geometry,                                   -- polygon ∪ safe circle (GiST)
//!               safe_radius_m, plane_height_m, area_m2 DOUBLE PRECISION,
//!               first_seen_ms, last_confirmed_ms, frames, approaches BIGINT,
//!               drone_id, approach_id, model_id TEXT, source_id TEXT UNIQUE)
//! catalog_sites_keys USING GIST (center, kind, safe_radius_m, last_confirmed_ms)
//! catalog_sites_radius USING GIST (safe_radius_m, center, kind)  -- (version 2) btree_gist
//! catalog_seen(id BIGSERIAL PRIMARY KEY, observed_ms BIGINT,
//!              area geography(POLYGON, 4326), bbox geometry)     -- GiST on bbox
//! ```
//!
//! Searches filter with `ST_DWithin(center, point, r, false)`. Every order is one
//! nearest-neighbour scan of a GiST index, bounded by the circle's box, for the page's k best
//! and a few more: nearest first by `center <-> point` (`catalog_sites_center`), largest safe
//! radius first and freshest first by the key's distance from its best value (`btree_gist`'s
//! `<->`): radius over `catalog_sites_radius`, whose tree splits by radius before place (split
//! by place, nearly every leaf in a circle holds a radius near the 15 m top and is read), and
//! freshness over `catalog_sites_keys`. It reads index entries and about a page of rows; Rust
//! sorts them by (key, id), and the few rows past the k-th show that no tie was left unread
//! (see `ranked_group`). The distance reported is that same sphere distance, so page tokens and
//! results agree. Searches are prepared once per connection and planned once, generically
//! (`plan_cache_mode`, see [`PostgisStore::connect`]). Writers serialise on a
//! transaction-scoped advisory lock ([`WRITE_LOCK`]): a batch reads what it may change and writes
//! in one transaction that no other writer interleaves with, so two replicas applying
//! overlapping observations end as if one went first (row locks alone would not stop two writers
//! inserting the same new roof twice). Readers never wait for it. Migrations run at connect under
//! the same lock.
//!
//! The client is the `postgres` crate, which drives `tokio-postgres` on a runtime of its own:
//! calling it from inside a tokio runtime panics, so the server calls it from its own threads (or
//! `spawn_blocking`). A lost connection is opened again on the next call.

use std::collections::HashMap;
use std::sync::{LazyLock, Mutex, MutexGuard};
use std::time::Duration;

use postgres::{Client, NoTls, Row, Statement, Transaction};

use crate::apply::{WriteTx, apply_sorted, validate};
use crate::error::{Error, Result};
use crate::geo::{Bbox, LatLon, Polygon};
use crate::geojson::{polygon_geometry, stored_count, stored_polygon};
use crate::model::{Candidate, MAX_RADIUS_M, Observation, Site, SiteId, SiteKind};
use crate::query::{Found, Order, Resolved, SearchPage, SearchQuery};
use crate::rule::ApplyReport;
use crate::store::{Counts, Store};
use crate::time::Timestamp;

const BACKEND: &str = "postgis";

/// The advisory lock key every catalog writer takes (`pg_advisory_xact_lock`): "landcat" in ASCII.
pub const WRITE_LOCK: i64 = 0x006c_616e_6463_6174;

/// How long a connection attempt may take, when the URL does not say (`connect_timeout`).
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);
/// Idle time before TCP keepalives probe the server, when the URL does not say.
pub const KEEPALIVE_IDLE: Duration = Duration::from_secs(15);
/// How long sent data may stay unacknowledged before the connection is dropped.
pub const TCP_USER_TIMEOUT: Duration = Duration::from_secs(15);
/// The longest statement (lock waits included) the server runs for the store, when the URL's
/// `options` do not set `statement_timeout`.
pub const STATEMENT_TIMEOUT: Duration = Duration::from_secs(30);

/// What a connection's searches are planned by, set when it connects: one generic plan per
/// prepared search. PostgreSQL's default plans a statement's first five executions for their
/// values, and those plans (estimating a handful of rows in the circle) read and sort the whole
/// circle instead of scanning the index in order: 60-95 ms at a million sites for every order
/// (nearest first too: 76 ms p50 by `EXPLAIN ANALYZE`), against about 1 ms for the generic plan.
/// Writes go back to the default for their transaction.
const SEARCH_PLANS: &str = "SET plan_cache_mode = force_generic_plan";

const MIGRATIONS: &[&str] = &[
    r#"
CREATE EXTENSION IF NOT EXISTS postgis;
CREATE TABLE catalog_sites (
    id BIGSERIAL PRIMARY KEY,
    kind SMALLINT NOT NULL CHECK (kind IN (0, 1)),
    polygon geography(POLYGON, 4326) NOT NULL,
    center geography(POINT, 4326) NOT NULL,
    bbox geometry NOT NULL,
    safe_radius_m DOUBLE PRECISION NOT NULL,
    plane_height_m DOUBLE PRECISION NOT NULL,
    area_m2 DOUBLE PRECISION NOT NULL,
    first_seen_ms BIGINT NOT NULL,
    last_confirmed_ms BIGINT NOT NULL,
    frames BIGINT NOT NULL,
    approaches BIGINT NOT NULL,
    drone_id TEXT NOT NULL,
    approach_id TEXT NOT NULL,
    model_id TEXT NOT NULL,
    source_id TEXT UNIQUE
);
CREATE INDEX catalog_sites_center ON catalog_sites USING GIST (center);
CREATE INDEX catalog_sites_bbox ON catalog_sites USING GIST (bbox);
CREATE INDEX catalog_sites_kind_last_confirmed ON catalog_sites (kind, last_confirmed_ms);
CREATE TABLE catalog_seen (
    id BIGSERIAL PRIMARY KEY,
    observed_ms BIGINT NOT NULL,
    area geography(POLYGON, 4326) NOT NULL,
    bbox geometry NOT NULL
);
CREATE INDEX catalog_seen_bbox ON catalog_seen USING GIST (bbox);
CREATE INDEX catalog_seen_observed ON catalog_seen (observed_ms);
"#,
    r#"
CREATE EXTENSION IF NOT EXISTS btree_gist;
CREATE INDEX catalog_sites_keys ON catalog_sites
    USING GIST (center, kind, safe_radius_m, last_confirmed_ms);
CREATE INDEX catalog_sites_radius ON catalog_sites USING GIST (safe_radius_m, center, kind);
"#,
];

const SITE_COLUMNS: &str = "id, kind, ST_AsGeoJSON(polygon, 15), ST_Y(center::geometry), \
    ST_X(center::geometry), safe_radius_m, plane_height_m, area_m2, first_seen_ms, \
    last_confirmed_ms, frames, approaches, drone_id, approach_id, model_id, source_id";

/// The query point `$1` = latitude, `$2` = longitude, as geography.
const POINT: &str = "ST_SetSRID(ST_MakePoint($2, $1), 4326)::geography";

/// A search's parameters, in every search statement: `$1` latitude, `$2` longitude, `$3` kind,
/// `$4` radius, `$5` minimum safe radius, `$6` age cut-off (ms), `$7`, `$8` the keyset position
/// (sort key, id) to start after, `$9` how many; the keyed orders add `$10` (see [`ranked_sql`]).
///
/// Nearest first: the GiST index's nearest-neighbour scan (`ORDER BY center <-> point LIMIT k`,
/// bounded by the circle's box so a sparse area does not scan on), which PostGIS rechecks so
/// that rows come in the exact order of the distance reported; ties are ordered by id in Rust
/// ([`ranked_group`]). `ORDER BY distance, id` would read and sort the whole search circle.
static NEAREST_SQL: LazyLock<String> = LazyLock::new(|| {
    ranked_sql(
        &format!("center <-> {POINT}"),
        &format!("center <-> {POINT}"),
        "TRUE",
    )
});

/// Largest safe radius first (see [`ranked_sql`]); the nearest-neighbour scan ranks by the
/// distance from the largest radius a site may have.
static SAFE_RADIUS_SQL: LazyLock<String> = LazyLock::new(|| {
    ranked_sql(
        "(-safe_radius_m)",
        &format!("safe_radius_m <-> {MAX_RADIUS_M:.1}::float8"),
        "safe_radius_m <= $10",
    )
});

/// Most recently confirmed first (see [`ranked_sql`]); the nearest-neighbour scan ranks by the
/// distance from [`FRESHNESS_ANCHOR_MS`].
static FRESHNESS_SQL: LazyLock<String> = LazyLock::new(|| {
    ranked_sql(
        "(-(last_confirmed_ms::float8))",
        &format!("last_confirmed_ms <-> {FRESHNESS_ANCHOR_MS}::int8"),
        "last_confirmed_ms <= $10",
    )
});

/// The time freshest-first ranks from, ms (2^53: year 287 396; beyond it the orders' float keys
/// are not exact anyway). A site confirmed before -2^63 + 2^53 ms would overflow the distance.
const FRESHNESS_ANCHOR_MS: i64 = 1 << 53;

/// A search by an order's `key` (see [`ranked_group`]): the nearest-neighbour scan by `rank`,
/// a distance the index orders by and that is monotone in the key (the key itself for nearest
/// first; for the keyed orders the key's distance from its best value, by `btree_gist`'s `<->`
/// over `catalog_sites_keys`, with `bound` taking the cursor's key `$10` as a bound on the
/// key's column), the rank returned beside the distance. The exact keyset test is the row
/// comparison. Reads index entries and about a page of rows.
fn ranked_sql(key: &str, rank: &str, bound: &str) -> String {
    format!(
        "SELECT {SITE_COLUMNS}, center <-> {POINT} AS distance_m, ({rank})::float8 AS rank \
         FROM catalog_sites WHERE kind = $3 AND ST_DWithin(center, {POINT}, $4, false) \
         AND center <-> {POINT} <= $4 AND safe_radius_m >= $5 AND last_confirmed_ms >= $6 \
         AND {bound} AND ({key}, id) > ($7, $8) ORDER BY {rank} LIMIT $9"
    )
}

/// The catalog in a PostgreSQL database with PostGIS.
pub struct PostgisStore {
    config: postgres::Config,
    client: Mutex<Option<Client>>,
    /// The searches, prepared once per connection (emptied when it is opened again).
    statements: Mutex<HashMap<String, Statement>>,
}

impl std::fmt::Debug for PostgisStore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // The URL may hold a password.
        f.debug_struct("PostgisStore").finish_non_exhaustive()
    }
}

impl PostgisStore {
    /// Connects to `url` (`postgres://user:password@host:port/database`, or the key=value form)
    /// and brings the schema up to date. The database user needs `CREATE` there, and the
    /// PostGIS and `btree_gist` (PostgreSQL's contrib; a trusted extension, so a database owner
    /// may create it) extensions must exist or be creatable.
    ///
    /// No call waits on a lost server for long: what the URL leaves unset gets
    /// [`CONNECT_TIMEOUT`] to connect, TCP keepalives after [`KEEPALIVE_IDLE`] and a TCP user
    /// timeout of [`TCP_USER_TIMEOUT`] (a server gone from the network fails the call), and
    /// every session a server-side `statement_timeout` of [`STATEMENT_TIMEOUT`] (a statement or
    /// a wait for the write lock that runs longer is cancelled). A server that stops or restarts
    /// closes the connection: the call fails at once and the next one connects again.
    pub fn connect(url: &str) -> Result<Self> {
        let store = PostgisStore {
            config: session_config(url)?,
            client: Mutex::new(None),
            statements: Mutex::new(HashMap::new()),
        };
        {
            let mut guard = store.client()?;
            let client = guard.as_mut().ok_or_else(disconnected)?;
            migrate(client)?;
        }
        Ok(store)
    }

    /// The schema version the database is at.
    pub fn schema_version(&self) -> Result<u32> {
        let mut guard = self.client()?;
        let client = guard.as_mut().ok_or_else(disconnected)?;
        let row = client
            .query_one(
                "SELECT COALESCE(MAX(version), 0) FROM catalog_schema_version",
                &[],
            )
            .map_err(db)?;
        Ok(row.get::<_, i32>(0).max(0) as u32)
    }

    /// The connection, opened again when it was lost.
    fn client(&self) -> Result<MutexGuard<'_, Option<Client>>> {
        let mut guard = self.client.lock().unwrap_or_else(|e| e.into_inner());
        if guard.as_ref().is_none_or(Client::is_closed) {
            self.statements
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clear();
            let mut client = self.config.connect(NoTls).map_err(db)?;
            client.batch_execute(SEARCH_PLANS).map_err(db)?;
            *guard = Some(client);
        }
        Ok(guard)
    }

    /// Runs `f` in a transaction holding the write lock; commits when it returns `Ok`.
    fn write<T>(&self, f: impl FnOnce(&mut Transaction<'_>) -> Result<T>) -> Result<T> {
        let mut guard = self.client()?;
        let client = guard.as_mut().ok_or_else(disconnected)?;
        let mut tx = client.transaction().map_err(db)?;
        tx.batch_execute(&format!(
            "SET LOCAL plan_cache_mode = auto; SELECT pg_advisory_xact_lock({WRITE_LOCK})"
        ))
        .map_err(db)?;
        let out = f(&mut tx)?;
        tx.commit().map_err(db)?;
        Ok(out)
    }
}

impl Store for PostgisStore {
    fn backend(&self) -> &'static str {
        BACKEND
    }

    fn apply(&self, batch: &[Observation]) -> Result<ApplyReport> {
        let sorted = validate(batch)?;
        self.write(|tx| apply_sorted(&mut PgTx { tx }, &sorted))
    }

    fn search(&self, query: &SearchQuery, now: Timestamp) -> Result<SearchPage> {
        let r = Resolved::new(query, now)?;
        let mut guard = self.client()?;
        let client = guard.as_mut().ok_or_else(disconnected)?;
        let mut statements = self.statements.lock().unwrap_or_else(|e| e.into_inner());
        r.page(&mut |r, kind, after, limit| {
            let nearest_first = matches!(
                (r.order, kind),
                (Order::Distance, _) | (Order::Freshness, SiteKind::Candidate)
            );
            let sql = match (nearest_first, r.order) {
                (true, _) => &*NEAREST_SQL,
                (false, Order::SafeRadius) => &*SAFE_RADIUS_SQL,
                (false, _) => &*FRESHNESS_SQL,
            };
            let stmt = match statements.get(sql.as_str()) {
                Some(s) => s.clone(),
                None => {
                    let s = client.prepare(sql).map_err(db)?;
                    statements.insert(sql.clone(), s.clone());
                    s
                }
            };
            let p = GroupParams::new(r, kind, after, !nearest_first);
            ranked_group(client, &stmt, &p, r, limit)
        })
    }

    fn expire(&self, now: Timestamp, retention: Duration) -> Result<u64> {
        let cutoff = now.saturating_sub(retention).unix_ms();
        self.write(|tx| {
            let n = tx
                .execute(
                    "DELETE FROM catalog_sites WHERE kind = 0 AND last_confirmed_ms < $1",
                    &[&cutoff],
                )
                .map_err(db)?;
            tx.execute(
                "DELETE FROM catalog_seen WHERE observed_ms < $1",
                &[&cutoff],
            )
            .map_err(db)?;
            Ok(n)
        })
    }

    fn import_candidates(&self, candidates: &[Candidate], now: Timestamp) -> Result<u64> {
        for (i, c) in candidates.iter().enumerate() {
            c.validate(&format!("candidates[{i}]"))?;
        }
        self.write(|tx| {
            let mut w = PgTx { tx };
            for c in candidates {
                if let Some(src) = &c.source_id {
                    w.tx.execute("DELETE FROM catalog_sites WHERE source_id = $1", &[src])
                        .map_err(db)?;
                }
                w.insert(&c.to_site(now))?;
            }
            Ok(candidates.len() as u64)
        })
    }

    fn load_sites(&self, sites: &[Site]) -> Result<u64> {
        for (i, s) in sites.iter().enumerate() {
            s.validate(&format!("sites[{i}]"))?;
        }
        // COPY's text format: one line per record, tab-separated, geometries as EWKT.
        let mut text = String::with_capacity(sites.len() * 512);
        for s in sites {
            copy_line(&mut text, s);
        }
        self.write(|tx| {
            let mut w = tx
                .copy_in(
                    "COPY catalog_sites (kind, polygon, center, bbox, safe_radius_m, \
                     plane_height_m, area_m2, first_seen_ms, last_confirmed_ms, frames, \
                     approaches, drone_id, approach_id, model_id, source_id) FROM STDIN",
                )
                .map_err(db)?;
            std::io::Write::write_all(&mut w, text.as_bytes()).map_err(|e| Error::Storage {
                backend: BACKEND,
                source: Box::new(e),
            })?;
            w.finish().map_err(db)
        })
    }

    fn counts(&self) -> Result<Counts> {
        let mut guard = self.client()?;
        let client = guard.as_mut().ok_or_else(disconnected)?;
        let row = client
            .query_one(
                "SELECT (SELECT COUNT(*) FROM catalog_sites WHERE kind = 0), \
                 (SELECT COUNT(*) FROM catalog_sites WHERE kind = 1), \
                 (SELECT COUNT(*) FROM catalog_seen)",
                &[],
            )
            .map_err(db)?;
        let n = |i: usize| row.get::<_, i64>(i).max(0) as u64;
        Ok(Counts {
            confirmed: n(0),
            candidates: n(1),
            seen_areas: n(2),
        })
    }

    fn check_integrity(&self) -> Result<()> {
        let known = MIGRATIONS.len() as i32;
        let mut guard = self.client()?;
        let client = guard.as_mut().ok_or_else(disconnected)?;
        let at: i32 = client
            .query_one(
                "SELECT COALESCE(MAX(version), 0) FROM catalog_schema_version",
                &[],
            )
            .map_err(db)?
            .get(0);
        if at != known {
            return Err(Error::Corrupt {
                backend: BACKEND,
                what: format!("schema version {at}, this build expects {known}"),
            });
        }
        let invalid: Vec<String> = client
            .query(
                "SELECT c.relname::text FROM pg_index i JOIN pg_class c ON c.oid = i.indexrelid \
                 JOIN pg_class t ON t.oid = i.indrelid \
                 WHERE t.relname IN ('catalog_sites', 'catalog_seen') \
                 AND NOT (i.indisvalid AND i.indisready)",
                &[],
            )
            .map_err(db)?
            .iter()
            .map(|r| r.get(0))
            .collect();
        if !invalid.is_empty() {
            return Err(Error::Corrupt {
                backend: BACKEND,
                what: format!("invalid indexes: {}", invalid.join(", ")),
            });
        }
        Ok(())
    }
}

/// A search statement's parameters for one group (see [`NEAREST_SQL`] and [`ranked_sql`]).
struct GroupParams {
    latitude_deg: f64,
    longitude_deg: f64,
    kind: i16,
    radius_m: f64,
    min_safe_radius_m: f64,
    cutoff: i64,
    after_key: f64,
    after_id: i64,
    /// The keyed orders' `$10`, the cursor's key as a bound on the key's column.
    bound: Option<Box<dyn postgres::types::ToSql + Sync>>,
}

impl GroupParams {
    fn new(r: &Resolved, kind: SiteKind, after: Option<(f64, i64)>, keyed: bool) -> Self {
        let (after_key, after_id) = after.unwrap_or((f64::NEG_INFINITY, i64::MIN));
        let bound: Option<Box<dyn postgres::types::ToSql + Sync>> = match (keyed, r.order) {
            (false, _) => None,
            (true, Order::SafeRadius) => Some(Box::new(-after_key)),
            (true, _) => Some(Box::new((-after_key).ceil() as i64)),
        };
        GroupParams {
            latitude_deg: r.center.latitude_deg,
            longitude_deg: r.center.longitude_deg,
            kind: kind_code(kind),
            radius_m: r.radius_m,
            min_safe_radius_m: r.min_safe_radius_m,
            cutoff: match kind {
                SiteKind::Confirmed => r.cutoff.map_or(i64::MIN, Timestamp::unix_ms),
                SiteKind::Candidate => i64::MIN,
            },
            after_key,
            after_id,
            bound,
        }
    }

    /// Up to `limit` rows: each record, its distance and its rank.
    fn query(
        &self,
        client: &mut Client,
        stmt: &Statement,
        limit: usize,
    ) -> Result<Vec<(Found, f64)>> {
        let limit = i64::try_from(limit).unwrap_or(i64::MAX);
        let mut params: Vec<&(dyn postgres::types::ToSql + Sync)> = vec![
            &self.latitude_deg,
            &self.longitude_deg,
            &self.kind,
            &self.radius_m,
            &self.min_safe_radius_m,
            &self.cutoff,
            &self.after_key,
            &self.after_id,
            &limit,
        ];
        if let Some(b) = &self.bound {
            params.push(b.as_ref());
        }
        let rows = client.query(stmt, &params).map_err(db)?;
        rows.iter()
            .map(|row| {
                let found = Found {
                    site: site_from_row(row)?,
                    distance_m: row.get(16),
                };
                Ok((found, row.get(17)))
            })
            .collect()
    }
}

/// Rows a search reads beyond the page, so that its last row usually ranks after the page's
/// last and shows that no tie with it was left unread.
const RANK_SLACK: usize = 8;

/// One group's page: the nearest-neighbour scan's first `limit` + [`RANK_SLACK`] rows by rank,
/// sorted by (key, id). Exact when the scan ran out or its last row ranks after the
/// `limit`-th: the rank is monotone in the key, so every record as good as the `limit`-th best
/// was read (ties by id included). Otherwise (a run of equal keys longer than the slack) it
/// reads four times as many and looks again.
fn ranked_group(
    client: &mut Client,
    stmt: &Statement,
    p: &GroupParams,
    r: &Resolved,
    limit: usize,
) -> Result<Vec<Found>> {
    let mut fetch = limit + RANK_SLACK;
    loop {
        let rows = p.query(client, stmt, fetch)?;
        let ranks_past = match (rows.get(limit - 1), rows.last()) {
            (Some(nth), Some(last)) => nth.1 < last.1,
            _ => true,
        };
        if rows.len() < fetch || ranks_past {
            let mut found: Vec<Found> = rows.into_iter().map(|(f, _)| f).collect();
            let key = |f: &Found| (r.sort_key(&f.site, f.distance_m), f.site.id.0);
            found.sort_by(|a, b| {
                let (ka, ia) = key(a);
                let (kb, ib) = key(b);
                ka.total_cmp(&kb).then(ia.cmp(&ib))
            });
            found.truncate(limit);
            return Ok(found);
        }
        fetch = fetch.saturating_mul(4);
    }
}

struct PgTx<'a, 'b> {
    tx: &'a mut Transaction<'b>,
}

impl WriteTx for PgTx<'_, '_> {
    fn confirmed_in(&mut self, b: &Bbox) -> Result<Vec<Site>> {
        let rows = self
            .tx
            .query(
                &format!(
                    "SELECT {SITE_COLUMNS} FROM catalog_sites WHERE kind = 0 \
                     AND bbox && ST_MakeEnvelope($1, $2, $3, $4, 4326)"
                ),
                &[&b.min_lon, &b.min_lat, &b.max_lon, &b.max_lat],
            )
            .map_err(db)?;
        rows.iter().map(site_from_row).collect()
    }

    fn seen_after(&mut self, b: &Bbox, t: Timestamp) -> Result<Vec<(Timestamp, Polygon)>> {
        let rows = self
            .tx
            .query(
                "SELECT observed_ms, ST_AsGeoJSON(area, 15) FROM catalog_seen \
                 WHERE observed_ms > $5 AND bbox && ST_MakeEnvelope($1, $2, $3, $4, 4326)",
                &[&b.min_lon, &b.min_lat, &b.max_lon, &b.max_lat, &t.unix_ms()],
            )
            .map_err(db)?;
        rows.iter()
            .map(|r| {
                Ok((
                    Timestamp::from_unix_ms(r.get(0)),
                    stored_polygon(r.get(1), BACKEND)?,
                ))
            })
            .collect()
    }

    fn insert(&mut self, s: &Site) -> Result<SiteId> {
        let b = s.bbox();
        let row = self
            .tx
            .query_one(
                "INSERT INTO catalog_sites (kind, polygon, center, bbox, safe_radius_m, \
                 plane_height_m, area_m2, first_seen_ms, last_confirmed_ms, frames, approaches, \
                 drone_id, approach_id, model_id, source_id) VALUES ($1, \
                 ST_GeomFromGeoJSON($2)::geography, ST_SetSRID(ST_MakePoint($4, $3), 4326)::geography, \
                 ST_MakeEnvelope($5, $6, $7, $8, 4326), $9, $10, $11, $12, $13, $14, $15, $16, $17, \
                 $18, $19) RETURNING id",
                &[
                    &kind_code(s.kind),
                    &polygon_geometry(&s.polygon, false).to_string(),
                    &s.center.latitude_deg,
                    &s.center.longitude_deg,
                    &b.min_lon,
                    &b.min_lat,
                    &b.max_lon,
                    &b.max_lat,
                    &s.safe_radius_m,
                    &s.plane_height_m,
                    &s.area_m2,
                    &s.first_seen.unix_ms(),
                    &s.last_confirmed.unix_ms(),
                    &stored_count(s.frames),
                    &stored_count(s.approaches),
                    &s.drone_id,
                    &s.approach_id,
                    &s.model_id,
                    &s.source_id,
                ],
            )
            .map_err(db)?;
        Ok(SiteId(row.get(0)))
    }

    fn update(&mut self, s: &Site) -> Result<()> {
        let b = s.bbox();
        self.tx
            .execute(
                "UPDATE catalog_sites SET polygon = ST_GeomFromGeoJSON($2)::geography, \
                 center = ST_SetSRID(ST_MakePoint($4, $3), 4326)::geography, \
                 bbox = ST_MakeEnvelope($5, $6, $7, $8, 4326), safe_radius_m = $9, \
                 plane_height_m = $10, area_m2 = $11, first_seen_ms = $12, last_confirmed_ms = $13, \
                 frames = $14, approaches = $15, drone_id = $16, approach_id = $17, model_id = $18 \
                 WHERE id = $1",
                &[
                    &s.id.0,
                    &polygon_geometry(&s.polygon, false).to_string(),
                    &s.center.latitude_deg,
                    &s.center.longitude_deg,
                    &b.min_lon,
                    &b.min_lat,
                    &b.max_lon,
                    &b.max_lat,
                    &s.safe_radius_m,
                    &s.plane_height_m,
                    &s.area_m2,
                    &s.first_seen.unix_ms(),
                    &s.last_confirmed.unix_ms(),
                    &stored_count(s.frames),
                    &stored_count(s.approaches),
                    &s.drone_id,
                    &s.approach_id,
                    &s.model_id,
                ],
            )
            .map_err(db)?;
        Ok(())
    }

    fn delete(&mut self, id: SiteId) -> Result<()> {
        self.tx
            .execute("DELETE FROM catalog_sites WHERE id = $1", &[&id.0])
            .map_err(db)?;
        Ok(())
    }

    fn record_seen(&mut self, t: Timestamp, areas: &[Polygon]) -> Result<()> {
        // One statement for the observation's few hundred rectangles: a round trip each cost
        // 0.3-0.8 s per batch of four observations on a loaded box.
        let boxes: Vec<_> = areas.iter().map(Polygon::bbox).collect();
        let column = |f: fn(&Bbox) -> f64| boxes.iter().map(f).collect::<Vec<f64>>();
        let geometries: Vec<String> = areas
            .iter()
            .map(|a| polygon_geometry(a, false).to_string())
            .collect();
        self.tx
            .execute(
                "INSERT INTO catalog_seen (observed_ms, area, bbox) \
                 SELECT $1, ST_GeomFromGeoJSON(g)::geography, ST_MakeEnvelope(x0, y0, x1, y1, 4326) \
                 FROM unnest($2::text[], $3::float8[], $4::float8[], $5::float8[], $6::float8[]) \
                 AS u(g, x0, y0, x1, y1)",
                &[
                    &t.unix_ms(),
                    &geometries,
                    &column(|b| b.min_lon),
                    &column(|b| b.min_lat),
                    &column(|b| b.max_lon),
                    &column(|b| b.max_lat),
                ],
            )
            .map_err(db)?;
        Ok(())
    }
}

/// The URL's settings with the store's timeouts where it leaves them unset.
fn session_config(url: &str) -> Result<postgres::Config> {
    let mut c: postgres::Config = url.parse().map_err(db)?;
    if c.get_connect_timeout().is_none() {
        c.connect_timeout(CONNECT_TIMEOUT);
    }
    if c.get_keepalives_idle() == Duration::from_secs(2 * 3600) {
        c.keepalives_idle(KEEPALIVE_IDLE);
    }
    if c.get_tcp_user_timeout().is_none() {
        c.tcp_user_timeout(TCP_USER_TIMEOUT);
    }
    let options = c.get_options().unwrap_or_default().to_string();
    if !options.contains("statement_timeout") {
        let ms = STATEMENT_TIMEOUT.as_millis();
        c.options(format!("{options} -c statement_timeout={ms}").trim());
    }
    Ok(c)
}

fn migrate(client: &mut Client) -> Result<()> {
    let mut tx = client.transaction().map_err(db)?;
    tx.execute("SELECT pg_advisory_xact_lock($1)", &[&WRITE_LOCK])
        .map_err(db)?;
    tx.batch_execute(
        "CREATE TABLE IF NOT EXISTS catalog_schema_version (version INTEGER NOT NULL)",
    )
    .map_err(db)?;
    let at: i32 = tx
        .query_one(
            "SELECT COALESCE(MAX(version), 0) FROM catalog_schema_version",
            &[],
        )
        .map_err(db)?
        .get(0);
    let known = MIGRATIONS.len() as i32;
    if at > known {
        return Err(Error::Corrupt {
            backend: BACKEND,
            what: format!("schema version {at} is newer than this build's {known}"),
        });
    }
    for (i, sql) in MIGRATIONS.iter().enumerate().skip(at.max(0) as usize) {
        tx.batch_execute(sql).map_err(db)?;
        tx.execute(
            "INSERT INTO catalog_schema_version (version) VALUES ($1)",
            &[&(i as i32 + 1)],
        )
        .map_err(db)?;
    }
    tx.commit().map_err(db)
}

fn site_from_row(r: &Row) -> Result<Site> {
    let kind = match r.get::<_, i16>(1) {
        0 => SiteKind::Confirmed,
        _ => SiteKind::Candidate,
    };
    Ok(Site {
        id: SiteId(r.get(0)),
        kind,
        polygon: stored_polygon(r.get(2), BACKEND)?,
        center: LatLon::new(r.get(3), r.get(4)),
        safe_radius_m: r.get(5),
        plane_height_m: r.get(6),
        area_m2: r.get(7),
        first_seen: Timestamp::from_unix_ms(r.get(8)),
        last_confirmed: Timestamp::from_unix_ms(r.get(9)),
        frames: r.get::<_, i64>(10).max(0) as u64,
        approaches: r.get::<_, i64>(11).max(0) as u64,
        drone_id: r.get(12),
        approach_id: r.get(13),
        model_id: r.get(14),
        source_id: r.get(15),
    })
}

/// One record as a line of `COPY … FROM STDIN` text (the columns of [`Store::load_sites`]).
fn copy_line(out: &mut String, s: &Site) {
    use std::fmt::Write as _;
    let ring = |out: &mut String, r: &[LatLon]| {
        out.push('(');
        for p in r.iter().chain(r.first()) {
            if !out.ends_with('(') {
                out.push(',');
            }
            let _ = write!(out, "{} {}", p.longitude_deg, p.latitude_deg);
        }
        out.push(')');
    };
    let _ = write!(out, "{}\tSRID=4326;POLYGON(", kind_code(s.kind));
    for (i, r) in s.polygon.rings().enumerate() {
        if i > 0 {
            out.push(',');
        }
        ring(out, r);
    }
    let b = s.bbox();
    let _ = write!(
        out,
        ")\tSRID=4326;POINT({} {})\tSRID=4326;POLYGON(({w} {so},{w} {n},{e} {n},{e} {so},{w} {so}))",
        s.center.longitude_deg,
        s.center.latitude_deg,
        w = b.min_lon,
        e = b.max_lon,
        so = b.min_lat,
        n = b.max_lat,
    );
    let _ = write!(
        out,
        "\t{}\t{}\t{}\t{}\t{}\t{}\t{}",
        s.safe_radius_m,
        s.plane_height_m,
        s.area_m2,
        s.first_seen.unix_ms(),
        s.last_confirmed.unix_ms(),
        stored_count(s.frames),
        stored_count(s.approaches),
    );
    for text in [&s.drone_id, &s.approach_id, &s.model_id] {
        out.push('\t');
        copy_text(out, text);
    }
    out.push('\t');
    match &s.source_id {
        Some(id) => copy_text(out, id),
        None => out.push_str("\\N"),
    }
    out.push('\n');
}

/// `text` escaped for COPY's text format.
fn copy_text(out: &mut String, text: &str) {
    for c in text.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\t' => out.push_str("\\t"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            c => out.push(c),
        }
    }
}

fn kind_code(kind: SiteKind) -> i16 {
    match kind {
        SiteKind::Confirmed => 0,
        SiteKind::Candidate => 1,
    }
}

fn disconnected() -> Error {
    Error::Storage {
        backend: BACKEND,
        source: "no connection to the database".into(),
    }
}

fn db(e: postgres::Error) -> Error {
    Error::Storage {
        backend: BACKEND,
        source: Box::new(e),
    }
}
