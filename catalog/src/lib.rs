//! The fleet's landing-site catalog: what the fleet's drones have seen safe, where, and how
//! recently, queryable by place. Pure storage and update rules: no gRPC, no async, no pipeline.
//!
//! Every fused approach reports an [`Observation`]: the ground its cameras resolved and the
//! landing sites it found there, at a time. A [`Store`] applies batches of them by one rule
//! ([`rule`]: a newer look replaces what the catalog says about the ground it saw, withdrawing at
//! once a site it no longer finds; what it did not see keeps its age), and answers searches by
//! place ([`SearchQuery`]: a circle, filters, an order, AIP-158 paging with checked tokens). Roofs
//! known beforehand (building footprints with heights, [`geojson::read_candidates`]) are imported
//! as [`SiteKind::Candidate`]s and returned after confirmed sites, never as sites. A catalog site
//! is a candidate for a drone to confirm with its own stream, never a clearance to land.
//!
//! Main types:
//! - [`Store`], the one storage interface, with [`SqliteStore`] (the embedded default: one file,
//!   WAL, R*Tree) and [`PostgisStore`] (PostgreSQL + PostGIS, shared by a fleet's replicas); one
//!   conformance suite (`tests/conformance.rs`) runs against both.
//! - [`Site`] (a stored record), [`Observation`] (what one approach saw), [`Candidate`].
//! - [`SearchQuery`] → [`SearchPage`] of [`Found`] (a site and its distance).
//!
//! Every method blocks on its database: the server calls the store from its write-queue thread
//! and `spawn_blocking`, never on the async runtime (and [`PostgisStore`] never inside one).
//!
//! ```
//! use landing_catalog::{
//!     LatLon, LocalFrame, Observation, ObservedSite, Polygon, SearchQuery, SqliteStore, Store,
//!     Timestamp,
//! };
//!
//! let dir = tempfile::tempdir()?;
//! let store = SqliteStore::open(dir.path().join("catalog.sqlite"))?;
//!
//! // One approach saw a 40 m x 40 m roof and found a site 8 m in radius on it.
//! let roof = LatLon::new(40.7484, -73.9857);
//! let f = LocalFrame::new(roof);
//! let square = |h: f64| Polygon::rectangle(f.to_lat_lon((-h, -h)), f.to_lat_lon((h, h)));
//! let t = Timestamp::from_unix_ms(1_796_588_100_000);
//! let seen = Observation {
//!     t,
//!     drone_id: "drone-7".into(),
//!     approach_id: "approach-1".into(),
//!     model_id: "rooftop-segmentation".into(),
//!     seen: vec![square(20.0)],
//!     sites: vec![ObservedSite {
//!         polygon: square(10.0),
//!         center: roof,
//!         safe_radius_m: 8.0,
//!         plane_height_m: 52.0,
//!         frames: 12,
//!     }],
//! };
//! assert_eq!(store.apply(&[seen.clone()])?.inserted, 1);
//!
//! // A ground station 300 m away asks what is within 500 m.
//! let station = f.to_lat_lon((300.0, 0.0));
//! let page = store.search(&SearchQuery::new(station, 500.0), t)?;
//! assert_eq!(page.sites.len(), 1);
//! assert!((page.sites[0].distance_m - 300.0).abs() < 0.01);
//!
//! // A later approach sees the same roof blocked: the site is withdrawn at once.
//! let blocked = Observation { t: Timestamp::from_unix_ms(t.unix_ms() + 60_000), sites: vec![], ..seen };
//! assert_eq!(store.apply(&[blocked])?.withdrawn, 1);
//! assert!(store.search(&SearchQuery::new(station, 500.0), t)?.sites.is_empty());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # For the server (what comes next)
//!
//! - Config: `[catalog] path` or `url` → [`Location::parse`] → [`Location::open`] (at start, on
//!   a thread of its own: it runs the migrations), shared as `Arc<dyn Store>`.
//! - Observations: `seen` is the ground the cameras resolved (a fused answer's cells seen finely
//!   enough, as polygons) and only sites whose circles lie in it are admitted. Each observation's
//!   `seen` polygons are kept (until [`Store::expire`]) to turn away late observations, so send
//!   few, large observations (one per stream every few seconds, or per approach), not one per
//!   frame. Frames without a geodetic origin have no WGS-84 and are not observations.
//! - Write path: a bounded queue drained by one thread that calls [`Store::apply`] with batches;
//!   on `Err` it counts the failure and drops (oldest first), the frame path never waits.
//!   [`ApplyReport`] gives the write metrics, [`Store::counts`] the stored-sites gauge.
//! - Query path: `SearchLandingSitesRequest` → [`SearchQuery`] (the catalog's field names follow
//!   the proto's: `center.latitude_deg`, `radius_m`, `page_size`, `page_token`, ...);
//!   [`Error::InvalidArgument`] → `INVALID_ARGUMENT` with its `field`, the storage variants →
//!   `UNAVAILABLE` naming the catalog.
//! - A periodic [`Store::expire`] with the configured retention; `max_age` in the query is the
//!   configured "not returned unless asked" age ([`DEFAULT_MAX_AGE`] otherwise).
//! - The CLI: [`geojson::read_candidates`] + [`Store::import_candidates`] for `catalog import`,
//!   [`geojson::write_results`] for `sites --geojson`.

#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod apply;
mod cells;
mod error;
pub mod geo;
pub mod geojson;
mod model;
mod open;
mod postgis;
mod query;
pub mod rule;
mod sqlite;
mod store;
mod time;

pub use error::{Error, Result};
pub use geo::{Bbox, LatLon, LocalFrame, Polygon, distance_m};
pub use model::{Candidate, Observation, ObservedSite, Site, SiteId, SiteKind};
pub use open::Location;
pub use postgis::PostgisStore;
pub use query::{
    DEFAULT_MAX_AGE, DEFAULT_PAGE_SIZE, Found, MAX_PAGE_SIZE, MAX_SEARCH_RADIUS_M, Order,
    SearchPage, SearchQuery,
};
pub use rule::ApplyReport;
pub use sqlite::SqliteStore;
pub use store::{Counts, Store};
pub use time::Timestamp;
