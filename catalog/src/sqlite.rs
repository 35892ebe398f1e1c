//! The embedded store: one SQLite file (WAL), sites indexed by an R*Tree over their boxes.
//!
//! # Schema (version 3)
//!
//! ```sql
//! schema_version(version INTEGER)                   -- one row per applied migration
//! sites(id INTEGER PRIMARY KEY, kind INTEGER,       -- 0 confirmed, 1 candidate
//!       polygon TEXT,                               -- GeoJSON Polygon geometry
//!       latitude_deg REAL, longitude_deg REAL,      -- the safest point
//!       safe_radius_m REAL, plane_height_m REAL, area_m2 REAL,
//!       first_seen_ms INTEGER, last_confirmed_ms INTEGER, frames INTEGER, approaches INTEGER,
//!       drone_id TEXT, approach_id TEXT, model_id TEXT, source_id TEXT UNIQUE,
//!       cell INTEGER)                               -- (version 3) the grid cell, crate::cells
//! sites_by_radius ON sites(kind, cell, safe_radius_m DESC, id, latitude_deg, longitude_deg,
//!       last_confirmed_ms)                          -- (version 3) each order's key per cell,
//! sites_by_freshness ON sites(kind, cell, last_confirmed_ms DESC, id, latitude_deg,
//!       longitude_deg, safe_radius_m)               -- covering what a search tests
//! sites_rtree USING rtree(id, min_lat, max_lat, min_lon, max_lon,   -- polygon ∪ safe circle
//!       +kind, +latitude_deg, +longitude_deg,       -- (version 2) auxiliary copies of what a
//!       +safe_radius_m, +last_confirmed_ms)         -- search filters and orders by
//! seen(id INTEGER PRIMARY KEY, observed_ms INTEGER, polygon TEXT)   -- areas observations resolved
//! seen_rtree USING rtree(id, min_lat, max_lat, min_lon, max_lon)
//! ```
//!
//! The R*Tree keeps 32-bit boxes rounded outward and has no nearest-k, so a search asks it for the
//! boxes meeting the search circle's box (padded), then measures, filters and orders in Rust;
//! what it filters and orders by is read from the R*Tree's auxiliary columns (no lookup in
//! `sites` per box), whole records only for the page. Nearest first reads a small circle first
//! and widens it threefold until it holds the page. Largest safe radius first and freshest first
//! read the grid cells ([`crate::cells`]) under the circle's box side by side, each in its order's
//! index from its best record on, and merge them until the page is full: about a page plus one
//! record per cell (a 500 m circle: 20-30 cells), not the whole circle. A circle narrower than
//! [`GRID_MIN_RADIUS_M`] or wider than [`MAX_CELLS`] cells reads the whole circle instead (few
//! records; or too many cells to open a cursor on each).
//! Writes take SQLite's write lock at `BEGIN IMMEDIATE`; other connections wait for it up to the
//! busy timeout (5 s). WAL with `synchronous = NORMAL`: a process killed mid-write loses at most
//! the transaction in flight (one `apply` batch); a power cut may also lose the last few commits.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;
use std::path::Path;
use std::sync::{LazyLock, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use rusqlite::{
    Connection, OptionalExtension, Row, Rows, Transaction, TransactionBehavior, params,
};

use crate::apply::{BOX_PAD_M, WriteTx, apply_sorted, validate};
use crate::cells;
use crate::error::{Error, Result};
use crate::geo::{Bbox, LatLon, Polygon, distance_m};
use crate::geojson::{polygon_geometry, stored_count, stored_polygon};
use crate::model::{Candidate, Observation, Site, SiteId, SiteKind};
use crate::query::{Found, Order, Resolved, SearchPage, SearchQuery, order_group};
use crate::rule::ApplyReport;
use crate::store::{Counts, Store};
use crate::time::Timestamp;

const BACKEND: &str = "sqlite";

/// The first circle a nearest-first search reads, metres beyond the previous page's last result
/// (it grows threefold until it holds the page).
const FIRST_REACH_M: f64 = 64.0;

/// Circles narrower than this read their whole circle by the R*Tree for the keyed orders (it
/// holds a few records; the cells under it hold many more).
pub const GRID_MIN_RADIUS_M: f64 = 150.0;
/// The most grid cells a keyed search reads side by side (one prepared cursor each): a circle of
/// about 1.5 km radius at mid latitudes; a wider one reads its whole circle.
pub const MAX_CELLS: usize = 256;

/// How much of the file each connection maps into memory (shared with the OS page cache).
const MMAP_BYTES: u64 = 1 << 30;
/// Each connection's page cache, KiB.
const CACHE_KIB: u64 = 32 * 1024;

/// How long a write waits for another connection's write lock.
pub const BUSY_TIMEOUT: Duration = Duration::from_secs(5);

/// The migrations, in order: the schema is at version `MIGRATIONS.len()`. Version 2 rebuilds the
/// sites' R*Tree with auxiliary columns, version 3 numbers every site's grid cell (by
/// `cells::cell_sql!`) and builds the two keyed indexes, version 4 rebuilds the sites table with
/// `AUTOINCREMENT` ids (a withdrawn site's id is never given to another: a client that holds an
/// id means one site): opening an older file of a million sites takes some seconds once.
const MIGRATIONS: &[&str] = &[
    r#"
CREATE TABLE sites (
    id INTEGER PRIMARY KEY,
    kind INTEGER NOT NULL CHECK (kind IN (0, 1)),
    polygon TEXT NOT NULL,
    latitude_deg REAL NOT NULL,
    longitude_deg REAL NOT NULL,
    safe_radius_m REAL NOT NULL,
    plane_height_m REAL NOT NULL,
    area_m2 REAL NOT NULL,
    first_seen_ms INTEGER NOT NULL,
    last_confirmed_ms INTEGER NOT NULL,
    frames INTEGER NOT NULL,
    approaches INTEGER NOT NULL,
    drone_id TEXT NOT NULL,
    approach_id TEXT NOT NULL,
    model_id TEXT NOT NULL,
    source_id TEXT UNIQUE
);
CREATE INDEX sites_kind_last_confirmed ON sites (kind, last_confirmed_ms);
CREATE VIRTUAL TABLE sites_rtree USING rtree (id, min_lat, max_lat, min_lon, max_lon);
CREATE TABLE seen (
    id INTEGER PRIMARY KEY,
    observed_ms INTEGER NOT NULL,
    polygon TEXT NOT NULL
);
CREATE INDEX seen_observed ON seen (observed_ms);
CREATE VIRTUAL TABLE seen_rtree USING rtree (id, min_lat, max_lat, min_lon, max_lon);
"#,
    r#"
CREATE VIRTUAL TABLE sites_rtree_v2 USING rtree (id, min_lat, max_lat, min_lon, max_lon,
    +kind, +latitude_deg, +longitude_deg, +safe_radius_m, +last_confirmed_ms);
INSERT INTO sites_rtree_v2 SELECT t.id, t.min_lat, t.max_lat, t.min_lon, t.max_lon, s.kind,
    s.latitude_deg, s.longitude_deg, s.safe_radius_m, s.last_confirmed_ms
    FROM sites_rtree t JOIN sites s ON s.id = t.id;
DROP TABLE sites_rtree;
ALTER TABLE sites_rtree_v2 RENAME TO sites_rtree;
"#,
    concat!(
        "ALTER TABLE sites ADD COLUMN cell INTEGER NOT NULL DEFAULT 0;
UPDATE sites SET cell = ",
        cells::cell_sql!(),
        ";
CREATE INDEX sites_by_radius ON sites (kind, cell, safe_radius_m DESC, id, latitude_deg,
    longitude_deg, last_confirmed_ms);
CREATE INDEX sites_by_freshness ON sites (kind, cell, last_confirmed_ms DESC, id, latitude_deg,
    longitude_deg, safe_radius_m);
"
    ),
    r#"
CREATE TABLE sites_v4 (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    kind INTEGER NOT NULL CHECK (kind IN (0, 1)),
    polygon TEXT NOT NULL,
    latitude_deg REAL NOT NULL,
    longitude_deg REAL NOT NULL,
    safe_radius_m REAL NOT NULL,
    plane_height_m REAL NOT NULL,
    area_m2 REAL NOT NULL,
    first_seen_ms INTEGER NOT NULL,
    last_confirmed_ms INTEGER NOT NULL,
    frames INTEGER NOT NULL,
    approaches INTEGER NOT NULL,
    drone_id TEXT NOT NULL,
    approach_id TEXT NOT NULL,
    model_id TEXT NOT NULL,
    source_id TEXT UNIQUE,
    cell INTEGER NOT NULL DEFAULT 0
);
INSERT INTO sites_v4 (id, kind, polygon, latitude_deg, longitude_deg, safe_radius_m,
    plane_height_m, area_m2, first_seen_ms, last_confirmed_ms, frames, approaches, drone_id,
    approach_id, model_id, source_id, cell)
    SELECT id, kind, polygon, latitude_deg, longitude_deg, safe_radius_m, plane_height_m, area_m2,
    first_seen_ms, last_confirmed_ms, frames, approaches, drone_id, approach_id, model_id,
    source_id, cell FROM sites;
DROP TABLE sites;
ALTER TABLE sites_v4 RENAME TO sites;
CREATE INDEX sites_kind_last_confirmed ON sites (kind, last_confirmed_ms);
CREATE INDEX sites_by_radius ON sites (kind, cell, safe_radius_m DESC, id, latitude_deg,
    longitude_deg, last_confirmed_ms);
CREATE INDEX sites_by_freshness ON sites (kind, cell, last_confirmed_ms DESC, id, latitude_deg,
    longitude_deg, safe_radius_m);
"#,
];

const SITE_COLUMNS: &str = "s.id, s.kind, s.polygon, s.latitude_deg, s.longitude_deg, \
    s.safe_radius_m, s.plane_height_m, s.area_m2, s.first_seen_ms, s.last_confirmed_ms, s.frames, \
    s.approaches, s.drone_id, s.approach_id, s.model_id, s.source_id";

/// The catalog in one SQLite file.
#[derive(Debug)]
pub struct SqliteStore {
    conn: Mutex<Connection>,
}

impl SqliteStore {
    /// Opens (creating when missing) the catalog file at `path`: WAL, busy timeout, migrations.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let conn = Connection::open(path).map_err(db)?;
        Self::with_connection(conn)
    }

    /// A catalog in memory, gone when dropped (tests, examples).
    pub fn open_in_memory() -> Result<Self> {
        Self::with_connection(Connection::open_in_memory().map_err(db)?)
    }

    fn with_connection(mut conn: Connection) -> Result<Self> {
        conn.busy_timeout(BUSY_TIMEOUT).map_err(db)?;
        // In memory the journal stays "memory"; on disk it becomes "wal".
        let _mode: String =
            while_busy(|| conn.query_row("PRAGMA journal_mode = WAL", [], |r| r.get(0)))
                .map_err(db)?;
        // Searches read the R*Tree's pages at random: map the file (no read call per page) and
        // keep more of it cached than SQLite's 2 MB default.
        conn.execute_batch(&format!(
            "PRAGMA synchronous = NORMAL; PRAGMA mmap_size = {MMAP_BYTES}; \
             PRAGMA cache_size = -{CACHE_KIB};"
        ))
        .map_err(db)?;
        // A keyed search holds one cursor per cell at once, each its own cached statement.
        conn.set_prepared_statement_cache_capacity(2 * MAX_CELLS + 16);
        migrate(&mut conn)?;
        Ok(SqliteStore {
            conn: Mutex::new(conn),
        })
    }

    /// The schema version the file is at.
    pub fn schema_version(&self) -> Result<u32> {
        let conn = self.lock();
        conn.query_row(
            "SELECT COALESCE(MAX(version), 0) FROM schema_version",
            [],
            |r| r.get(0),
        )
        .map_err(db)
    }

    fn lock(&self) -> MutexGuard<'_, Connection> {
        // A panic while holding the lock left no transaction open (rusqlite rolls back on drop).
        self.conn.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Store for SqliteStore {
    fn backend(&self) -> &'static str {
        BACKEND
    }

    fn apply(&self, batch: &[Observation]) -> Result<ApplyReport> {
        let sorted = validate(batch)?;
        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(db)?;
        let report = apply_sorted(&mut SqliteTx { tx: &tx }, &sorted)?;
        tx.commit().map_err(db)?;
        Ok(report)
    }

    fn search(&self, query: &SearchQuery, now: Timestamp) -> Result<SearchPage> {
        let r = Resolved::new(query, now)?;
        let conn = self.lock();
        r.page(&mut |r, kind, after, limit| {
            let mut page = group_page(&conn, r, kind, after, limit)?;
            // Whole records (polygons parsed) for the page alone.
            let mut whole = conn
                .prepare_cached(&format!(
                    "SELECT {SITE_COLUMNS} FROM sites s WHERE s.id = ?1"
                ))
                .map_err(db)?;
            for f in &mut page {
                f.site = whole
                    .query_row([f.site.id.0], site_from_row)
                    .map_err(db)??;
            }
            Ok(page)
        })
    }

    fn expire(&self, now: Timestamp, retention: Duration) -> Result<u64> {
        let cutoff = now.saturating_sub(retention).unix_ms();
        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(db)?;
        tx.execute(
            "DELETE FROM sites_rtree WHERE id IN \
             (SELECT id FROM sites WHERE kind = 0 AND last_confirmed_ms < ?1)",
            [cutoff],
        )
        .map_err(db)?;
        let n = tx
            .execute(
                "DELETE FROM sites WHERE kind = 0 AND last_confirmed_ms < ?1",
                [cutoff],
            )
            .map_err(db)?;
        tx.execute(
            "DELETE FROM seen_rtree WHERE id IN (SELECT id FROM seen WHERE observed_ms < ?1)",
            [cutoff],
        )
        .map_err(db)?;
        tx.execute("DELETE FROM seen WHERE observed_ms < ?1", [cutoff])
            .map_err(db)?;
        tx.commit().map_err(db)?;
        Ok(n as u64)
    }

    fn import_candidates(&self, candidates: &[Candidate], now: Timestamp) -> Result<u64> {
        for (i, c) in candidates.iter().enumerate() {
            c.validate(&format!("candidates[{i}]"))?;
        }
        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(db)?;
        let mut w = SqliteTx { tx: &tx };
        for c in candidates {
            if let Some(src) = &c.source_id {
                let old: Option<i64> = tx
                    .query_row("SELECT id FROM sites WHERE source_id = ?1", [src], |r| {
                        r.get(0)
                    })
                    .optional()
                    .map_err(db)?;
                if let Some(old) = old {
                    w.delete(SiteId(old))?;
                }
            }
            w.insert(&c.to_site(now))?;
        }
        tx.commit().map_err(db)?;
        Ok(candidates.len() as u64)
    }

    fn load_sites(&self, sites: &[Site]) -> Result<u64> {
        for (i, s) in sites.iter().enumerate() {
            s.validate(&format!("sites[{i}]"))?;
        }
        let mut conn = self.lock();
        let tx = conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .map_err(db)?;
        let mut w = SqliteTx { tx: &tx };
        for s in sites {
            w.insert(s)?;
        }
        tx.commit().map_err(db)?;
        Ok(sites.len() as u64)
    }

    fn counts(&self) -> Result<Counts> {
        let conn = self.lock();
        let count = |sql: &str| -> Result<u64> {
            conn.query_row(sql, [], |r| r.get::<_, i64>(0))
                .map(|n| n as u64)
                .map_err(db)
        };
        Ok(Counts {
            confirmed: count("SELECT COUNT(*) FROM sites WHERE kind = 0")?,
            candidates: count("SELECT COUNT(*) FROM sites WHERE kind = 1")?,
            seen_areas: count("SELECT COUNT(*) FROM seen")?,
        })
    }

    fn check_integrity(&self) -> Result<()> {
        let conn = self.lock();
        let mut stmt = conn.prepare("PRAGMA integrity_check").map_err(db)?;
        let lines: Vec<String> = stmt
            .query_map([], |r| r.get(0))
            .map_err(db)?
            .collect::<Result<_, _>>()
            .map_err(db)?;
        if lines != ["ok"] {
            return Err(Error::Corrupt {
                backend: BACKEND,
                what: lines.join("; "),
            });
        }
        for table in ["sites_rtree", "seen_rtree"] {
            let verdict: String = conn
                .query_row(&format!("SELECT rtreecheck('{table}')"), [], |r| r.get(0))
                .map_err(db)?;
            if verdict != "ok" {
                return Err(Error::Corrupt {
                    backend: BACKEND,
                    what: format!("{table}: {verdict}"),
                });
            }
        }
        for (table, index) in [("sites", "sites_rtree"), ("seen", "seen_rtree")] {
            let missing: i64 = conn
                .query_row(
                    &format!(
                        "SELECT (SELECT COUNT(*) FROM {table}) - (SELECT COUNT(*) FROM {index})"
                    ),
                    [],
                    |r| r.get(0),
                )
                .map_err(db)?;
            if missing != 0 {
                return Err(Error::Corrupt {
                    backend: BACKEND,
                    what: format!("{table} and {index} differ by {missing} rows"),
                });
            }
        }
        Ok(())
    }
}

struct SqliteTx<'a> {
    tx: &'a Transaction<'a>,
}

impl WriteTx for SqliteTx<'_> {
    fn confirmed_in(&mut self, b: &Bbox) -> Result<Vec<Site>> {
        let mut stmt = self
            .tx
            .prepare_cached(&format!(
                "SELECT {SITE_COLUMNS} FROM sites_rtree t CROSS JOIN sites s ON s.id = t.id \
                 WHERE t.max_lat >= ?1 AND t.min_lat <= ?2 AND t.max_lon >= ?3 AND t.min_lon <= ?4 \
                 AND s.kind = 0"
            ))
            .map_err(db)?;
        let rows = stmt
            .query_map(
                params![b.min_lat, b.max_lat, b.min_lon, b.max_lon],
                site_from_row,
            )
            .map_err(db)?;
        rows.map(|r| r.map_err(db)?).collect()
    }

    fn seen_after(&mut self, b: &Bbox, t: Timestamp) -> Result<Vec<(Timestamp, Polygon)>> {
        let mut stmt = self
            .tx
            .prepare_cached(
                "SELECT s.observed_ms, s.polygon FROM seen_rtree t CROSS JOIN seen s ON s.id = t.id \
                 WHERE t.max_lat >= ?1 AND t.min_lat <= ?2 AND t.max_lon >= ?3 AND t.min_lon <= ?4 \
                 AND s.observed_ms > ?5",
            )
            .map_err(db)?;
        let rows = stmt
            .query_map(
                params![b.min_lat, b.max_lat, b.min_lon, b.max_lon, t.unix_ms()],
                |r| Ok((r.get::<_, i64>(0)?, r.get::<_, String>(1)?)),
            )
            .map_err(db)?;
        let mut out = Vec::new();
        for row in rows {
            let (ms, text) = row.map_err(db)?;
            out.push((Timestamp::from_unix_ms(ms), stored_polygon(&text, BACKEND)?));
        }
        Ok(out)
    }

    fn insert(&mut self, s: &Site) -> Result<SiteId> {
        self.tx
            .prepare_cached(
                "INSERT INTO sites (kind, polygon, latitude_deg, longitude_deg, safe_radius_m, \
                 plane_height_m, area_m2, first_seen_ms, last_confirmed_ms, frames, approaches, \
                 drone_id, approach_id, model_id, source_id, cell) \
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16)",
            )
            .map_err(db)?
            .execute(params![
                kind_code(s.kind),
                polygon_geometry(&s.polygon, false).to_string(),
                s.center.latitude_deg,
                s.center.longitude_deg,
                s.safe_radius_m,
                s.plane_height_m,
                s.area_m2,
                s.first_seen.unix_ms(),
                s.last_confirmed.unix_ms(),
                stored_count(s.frames),
                stored_count(s.approaches),
                s.drone_id,
                s.approach_id,
                s.model_id,
                s.source_id,
                cells::cell_of(s.center),
            ])
            .map_err(db)?;
        let id = self.tx.last_insert_rowid();
        self.index_site(id, s)?;
        Ok(SiteId(id))
    }

    fn update(&mut self, s: &Site) -> Result<()> {
        self.tx
            .prepare_cached(
                "UPDATE sites SET polygon = ?2, latitude_deg = ?3, longitude_deg = ?4, \
                 safe_radius_m = ?5, plane_height_m = ?6, area_m2 = ?7, first_seen_ms = ?8, \
                 last_confirmed_ms = ?9, frames = ?10, approaches = ?11, drone_id = ?12, \
                 approach_id = ?13, model_id = ?14, cell = ?15 WHERE id = ?1",
            )
            .map_err(db)?
            .execute(params![
                s.id.0,
                polygon_geometry(&s.polygon, false).to_string(),
                s.center.latitude_deg,
                s.center.longitude_deg,
                s.safe_radius_m,
                s.plane_height_m,
                s.area_m2,
                s.first_seen.unix_ms(),
                s.last_confirmed.unix_ms(),
                stored_count(s.frames),
                stored_count(s.approaches),
                s.drone_id,
                s.approach_id,
                s.model_id,
                cells::cell_of(s.center),
            ])
            .map_err(db)?;
        self.tx
            .prepare_cached("DELETE FROM sites_rtree WHERE id = ?1")
            .map_err(db)?
            .execute([s.id.0])
            .map_err(db)?;
        self.index_site(s.id.0, s)
    }

    fn delete(&mut self, id: SiteId) -> Result<()> {
        self.tx
            .prepare_cached("DELETE FROM sites WHERE id = ?1")
            .map_err(db)?
            .execute([id.0])
            .map_err(db)?;
        self.tx
            .prepare_cached("DELETE FROM sites_rtree WHERE id = ?1")
            .map_err(db)?
            .execute([id.0])
            .map_err(db)?;
        Ok(())
    }

    fn record_seen(&mut self, t: Timestamp, areas: &[Polygon]) -> Result<()> {
        for area in areas {
            self.tx
                .prepare_cached("INSERT INTO seen (observed_ms, polygon) VALUES (?1, ?2)")
                .map_err(db)?
                .execute(params![
                    t.unix_ms(),
                    polygon_geometry(area, false).to_string()
                ])
                .map_err(db)?;
            let id = self.tx.last_insert_rowid();
            self.index("seen_rtree", id, &area.bbox())?;
        }
        Ok(())
    }
}

impl SqliteTx<'_> {
    /// A site's box, and beside it (auxiliary columns) what a search filters and orders by.
    fn index_site(&self, id: i64, s: &Site) -> Result<()> {
        let b = s.bbox();
        self.tx
            .prepare_cached(
                "INSERT INTO sites_rtree (id, min_lat, max_lat, min_lon, max_lon, kind, \
                 latitude_deg, longitude_deg, safe_radius_m, last_confirmed_ms) \
                 VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10)",
            )
            .map_err(db)?
            .execute(params![
                id,
                b.min_lat,
                b.max_lat,
                b.min_lon,
                b.max_lon,
                kind_code(s.kind),
                s.center.latitude_deg,
                s.center.longitude_deg,
                s.safe_radius_m,
                s.last_confirmed.unix_ms()
            ])
            .map_err(db)?;
        Ok(())
    }

    fn index(&self, table: &str, id: i64, b: &Bbox) -> Result<()> {
        self.tx
            .prepare_cached(&format!(
                "INSERT INTO {table} (id, min_lat, max_lat, min_lon, max_lon) VALUES (?1, ?2, ?3, ?4, ?5)"
            ))
            .map_err(db)?
            .execute(params![id, b.min_lat, b.max_lat, b.min_lon, b.max_lon])
            .map_err(db)?;
        Ok(())
    }
}

/// One kind's page of a search, its records holding only what filters and orders them (from an
/// index alone). Nearest first reads a small circle first and widens it until it holds the page:
/// everything within `reach` is read, so what lies beyond ranks after the page. The keyed orders
/// merge the grid's cells ([`keyed_page`]), or read the whole circle where that is not used.
fn group_page(
    conn: &Connection,
    r: &Resolved,
    kind: SiteKind,
    after: Option<(f64, i64)>,
    limit: usize,
) -> Result<Vec<Found>> {
    let nearest_first = matches!(
        (r.order, kind),
        (Order::Distance, _) | (Order::Freshness, SiteKind::Candidate)
    );
    if !nearest_first && let Some(page) = keyed_page(conn, r, kind, after, limit)? {
        return Ok(page);
    }
    let mut reach = if nearest_first {
        (after.map_or(0.0, |(key, _)| key.max(0.0)) + FIRST_REACH_M).min(r.radius_m)
    } else {
        r.radius_m
    };
    loop {
        let page = order_group(r, in_reach(conn, r, kind, reach)?, after, limit);
        if page.len() >= limit || reach >= r.radius_m {
            return Ok(page);
        }
        reach = (reach * 3.0).min(r.radius_m);
    }
}

/// Largest safe radius first: one cell's records in the order's index, from the cursor's key
/// on (`?3`), with the search's filters (`?4` minimum radius, `?5` age cut-off).
const BY_RADIUS_SQL: &str = "SELECT /* cursor */ id, latitude_deg, longitude_deg, safe_radius_m, \
    last_confirmed_ms FROM sites INDEXED BY sites_by_radius WHERE kind = ?1 AND cell = ?2 \
    AND safe_radius_m <= ?3 AND safe_radius_m >= ?4 AND last_confirmed_ms >= ?5 \
    ORDER BY safe_radius_m DESC, id";

/// Freshest first: as [`BY_RADIUS_SQL`], by last confirmation.
const BY_FRESHNESS_SQL: &str = "SELECT /* cursor */ id, latitude_deg, longitude_deg, safe_radius_m, \
    last_confirmed_ms FROM sites INDEXED BY sites_by_freshness WHERE kind = ?1 AND cell = ?2 \
    AND last_confirmed_ms <= ?3 AND safe_radius_m >= ?4 AND last_confirmed_ms >= ?5 \
    ORDER BY last_confirmed_ms DESC, id";

/// [`BY_RADIUS_SQL`] and [`BY_FRESHNESS_SQL`] once per cursor a search may hold, told apart by
/// a comment: the statement cache keeps one statement per text, and a search needs its cursors
/// prepared side by side (preparing them anew each search cost more than the search).
static CURSOR_SQL: LazyLock<[Vec<String>; 2]> = LazyLock::new(|| {
    [BY_RADIUS_SQL, BY_FRESHNESS_SQL].map(|sql| {
        (0..MAX_CELLS)
            .map(|i| sql.replace("/* cursor */", &format!("/* cursor {i} */")))
            .collect()
    })
});

/// A keyed order's page by the grid: a cursor per cell under the circle's box, each yielding its
/// admitted records in (key, id) order, merged by a heap until the page is full. Exact: every
/// record the page leaves out ranks after the cursor it sits behind, which ranks after the
/// page's last. `None` when the circle is narrower than [`GRID_MIN_RADIUS_M`] or needs more
/// than [`MAX_CELLS`] cells.
fn keyed_page(
    conn: &Connection,
    r: &Resolved,
    kind: SiteKind,
    after: Option<(f64, i64)>,
    limit: usize,
) -> Result<Option<Vec<Found>>> {
    if r.radius_m < GRID_MIN_RADIUS_M {
        return Ok(None);
    }
    let bbox = Bbox::around(r.center, r.radius_m).padded_m(BOX_PAD_M);
    let Some(cells) = cells::covering(&bbox, MAX_CELLS) else {
        return Ok(None);
    };
    // The cursor's key as a bound on the indexed column (the exact keyset test is in Rust).
    let (sqls, bound) = match r.order {
        Order::SafeRadius => (
            &CURSOR_SQL[0],
            rusqlite::types::Value::Real(after.map_or(f64::MAX, |(key, _)| -key)),
        ),
        _ => (
            &CURSOR_SQL[1],
            rusqlite::types::Value::Integer(
                after.map_or(i64::MAX, |(key, _)| (-key).ceil() as i64),
            ),
        ),
    };
    let mut statements = Vec::with_capacity(cells.len());
    for sql in &sqls[..cells.len()] {
        statements.push(conn.prepare_cached(sql).map_err(db)?);
    }
    let mut cursors = Vec::with_capacity(cells.len());
    for (stmt, cell) in statements.iter_mut().zip(&cells) {
        let rows = stmt
            .query(params![
                kind_code(kind),
                cell,
                bound,
                r.min_safe_radius_m,
                cutoff_ms(r, kind)
            ])
            .map_err(db)?;
        cursors.push(rows);
    }
    let mut heads = BinaryHeap::with_capacity(cursors.len());
    for (i, rows) in cursors.iter_mut().enumerate() {
        if let Some(head) = next_head(rows, i, r, kind)? {
            heads.push(Reverse(head));
        }
    }
    // Records are tested as they leave the heap, in the order's order: a cell that the circle
    // barely meets is read only as far as the page's last key, not until it yields a record
    // inside the circle.
    let mut page = Vec::with_capacity(limit);
    while page.len() < limit {
        let Some(Reverse(head)) = heads.pop() else {
            break;
        };
        if let Some(next) = next_head(&mut cursors[head.cursor], head.cursor, r, kind)? {
            heads.push(Reverse(next));
        }
        let (key, id) = (head.key, head.id);
        let later = after.is_none_or(|(ak, aid)| key.total_cmp(&ak).then(id.cmp(&aid)).is_gt());
        if later && r.admits(&head.found.site, head.found.distance_m) {
            page.push(head.found);
        }
    }
    Ok(Some(page))
}

/// A cell cursor's next record, with its place in the order.
fn next_head(
    rows: &mut Rows<'_>,
    cursor: usize,
    r: &Resolved,
    kind: SiteKind,
) -> Result<Option<Head>> {
    let Some(row) = rows.next().map_err(db)? else {
        return Ok(None);
    };
    let site = indexed_site(row, kind).map_err(db)?;
    let distance_m = distance_m(r.center, site.center);
    Ok(Some(Head {
        key: r.sort_key(&site, distance_m),
        id: site.id.0,
        cursor,
        found: Found { site, distance_m },
    }))
}

/// A cell cursor's next record, ordered by (key, id) for the merge.
struct Head {
    key: f64,
    id: i64,
    cursor: usize,
    found: Found,
}

impl Ord for Head {
    fn cmp(&self, other: &Self) -> Ordering {
        self.key.total_cmp(&other.key).then(self.id.cmp(&other.id))
    }
}

impl PartialOrd for Head {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Head {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Head {}

/// Confirmed sites older than the search's cut-off are left out; candidates have no age.
fn cutoff_ms(r: &Resolved, kind: SiteKind) -> i64 {
    match kind {
        SiteKind::Confirmed => r.cutoff.map_or(i64::MIN, Timestamp::unix_ms),
        SiteKind::Candidate => i64::MIN,
    }
}

/// A record as an index holds it: (id, latitude, longitude, safe radius, last confirmation).
fn indexed_site(row: &Row<'_>, kind: SiteKind) -> rusqlite::Result<Site> {
    Ok(Site {
        id: SiteId(row.get(0)?),
        kind,
        polygon: Polygon::default(),
        center: LatLon::new(row.get(1)?, row.get(2)?),
        safe_radius_m: row.get(3)?,
        plane_height_m: 0.0,
        area_m2: 0.0,
        first_seen: Timestamp::default(),
        last_confirmed: Timestamp::from_unix_ms(row.get(4)?),
        frames: 0,
        approaches: 0,
        drone_id: String::new(),
        approach_id: String::new(),
        model_id: String::new(),
        source_id: None,
    })
}

/// The sites of `kind` within `reach` of the search's centre that the search admits, as the
/// R*Tree's auxiliary columns hold them (id, centre, radius, last confirmation).
fn in_reach(conn: &Connection, r: &Resolved, kind: SiteKind, reach: f64) -> Result<Vec<Found>> {
    let mut stmt = conn
        .prepare_cached(
            "SELECT id, latitude_deg, longitude_deg, safe_radius_m, last_confirmed_ms \
             FROM sites_rtree WHERE max_lat >= ?1 AND min_lat <= ?2 AND max_lon >= ?3 \
             AND min_lon <= ?4 AND kind = ?5 AND safe_radius_m >= ?6 \
             AND last_confirmed_ms >= ?7",
        )
        .map_err(db)?;
    let bbox = Bbox::around(r.center, reach).padded_m(BOX_PAD_M);
    let rows = stmt
        .query_map(
            params![
                bbox.min_lat,
                bbox.max_lat,
                bbox.min_lon,
                bbox.max_lon,
                kind_code(kind),
                r.min_safe_radius_m,
                cutoff_ms(r, kind)
            ],
            |row| indexed_site(row, kind),
        )
        .map_err(db)?;
    let mut found = Vec::new();
    for row in rows {
        let site = row.map_err(db)?;
        let distance_m = distance_m(r.center, site.center);
        if distance_m <= reach && r.admits(&site, distance_m) {
            found.push(Found { site, distance_m });
        }
    }
    Ok(found)
}

fn migrate(conn: &mut Connection) -> Result<()> {
    let tx = conn
        .transaction_with_behavior(TransactionBehavior::Immediate)
        .map_err(db)?;
    tx.execute_batch("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)")
        .map_err(db)?;
    let at: i64 = tx
        .query_row(
            "SELECT COALESCE(MAX(version), 0) FROM schema_version",
            [],
            |r| r.get(0),
        )
        .map_err(db)?;
    let known = MIGRATIONS.len() as i64;
    if at > known {
        return Err(Error::Corrupt {
            backend: BACKEND,
            what: format!("schema version {at} is newer than this build's {known}"),
        });
    }
    for (i, sql) in MIGRATIONS.iter().enumerate().skip(at as usize) {
        tx.execute_batch(sql).map_err(db)?;
        tx.execute(
            "INSERT INTO schema_version (version) VALUES (?1)",
            [i as i64 + 1],
        )
        .map_err(db)?;
    }
    tx.commit().map_err(db)
}

fn site_from_row(r: &Row<'_>) -> rusqlite::Result<Result<Site>> {
    let kind = match r.get::<_, i64>(1)? {
        0 => SiteKind::Confirmed,
        _ => SiteKind::Candidate,
    };
    let polygon_text: String = r.get(2)?;
    let polygon = match stored_polygon(&polygon_text, BACKEND) {
        Ok(p) => p,
        Err(e) => return Ok(Err(e)),
    };
    Ok(Ok(Site {
        id: SiteId(r.get(0)?),
        kind,
        polygon,
        center: LatLon::new(r.get(3)?, r.get(4)?),
        safe_radius_m: r.get(5)?,
        plane_height_m: r.get(6)?,
        area_m2: r.get(7)?,
        first_seen: Timestamp::from_unix_ms(r.get(8)?),
        last_confirmed: Timestamp::from_unix_ms(r.get(9)?),
        frames: r.get::<_, i64>(10)?.max(0) as u64,
        approaches: r.get::<_, i64>(11)?.max(0) as u64,
        drone_id: r.get(12)?,
        approach_id: r.get(13)?,
        model_id: r.get(14)?,
        source_id: r.get(15)?,
    }))
}

fn kind_code(kind: SiteKind) -> i64 {
    match kind {
        SiteKind::Confirmed => 0,
        SiteKind::Candidate => 1,
    }
}

/// `op`, tried again while SQLite answers "database is locked" at once, for at most
/// [`BUSY_TIMEOUT`]. The busy timeout waits out another connection's lock, but not a lock it could
/// deadlock on: connections making a new file a WAL file at the same moment (a server starting
/// while the command line imports into its file) get that answer without waiting.
fn while_busy<T>(mut op: impl FnMut() -> rusqlite::Result<T>) -> rusqlite::Result<T> {
    let give_up = Instant::now() + BUSY_TIMEOUT;
    loop {
        match op() {
            Err(e)
                if e.sqlite_error_code() == Some(rusqlite::ErrorCode::DatabaseBusy)
                    && Instant::now() < give_up =>
            {
                std::thread::sleep(Duration::from_millis(5));
            }
            done => return done,
        }
    }
}

fn db(e: rusqlite::Error) -> Error {
    Error::Storage {
        backend: BACKEND,
        source: Box::new(e),
    }
}
