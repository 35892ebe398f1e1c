//! The one storage interface both backends implement, and what they report.

use std::time::Duration;

use crate::error::Result;
use crate::model::{Candidate, Observation, Site};
use crate::query::{SearchPage, SearchQuery};
use crate::rule::ApplyReport;
use crate::time::Timestamp;

/// A catalog store. Every method blocks on the database: call it from a thread of your own (the
/// server's write queue thread) or `tokio::task::spawn_blocking`, never on an async runtime's
/// worker. [`crate::PostgisStore`] must not be called from inside a tokio runtime at all (its
/// client runs a runtime of its own).
///
/// One handle serialises its own calls (one connection behind a mutex); open several handles for
/// parallel readers. Several handles, processes or replicas may write one database at once: each
/// `apply` is one transaction that holds the database's write lock, so the result is the same as
/// applying the batches one after the other.
pub trait Store: Send + Sync {
    /// `sqlite` or `postgis`: for logs, metrics and errors.
    fn backend(&self) -> &'static str;

    /// Applies a batch of observations in one transaction, oldest first (stable for equal times),
    /// by the rule in [`crate::rule`]. Every observation is validated first (errors name
    /// `observations[i]....`); on any error nothing is written.
    fn apply(&self, batch: &[Observation]) -> Result<ApplyReport>;

    /// One page of records near a place. `now` fixes the age cut-off on the first page; later
    /// pages keep the first page's.
    fn search(&self, query: &SearchQuery, now: Timestamp) -> Result<SearchPage>;

    /// Deletes confirmed sites last confirmed before `now - retention`, and the seen areas as old
    /// (the rule keeps them to turn away late observations). Candidates stay. Returns the sites
    /// deleted.
    fn expire(&self, now: Timestamp, retention: Duration) -> Result<u64>;

    /// Stores candidate roofs, imported at `now`, in one transaction; a candidate whose
    /// `source_id` is already stored replaces that record. Returns how many were stored.
    fn import_candidates(&self, candidates: &[Candidate], now: Timestamp) -> Result<u64>;

    /// Stores records as they are, in one transaction, bypassing the update rule: copying a
    /// catalog from one store to another, or loading a benchmark's catalog fast (SQLite: one
    /// prepared insert per record; PostGIS: `COPY`). Ids are assigned anew (`site.id` is
    /// ignored). Records are validated first (errors name `sites[i]....`); a `source_id` already
    /// stored fails the whole call. Returns how many were stored. Load large catalogs in batches
    /// of tens of thousands: each call is one statement on PostGIS, under its statement timeout.
    fn load_sites(&self, sites: &[Site]) -> Result<u64>;

    /// How many records are stored, by kind (for the `sites stored` metric).
    fn counts(&self) -> Result<Counts>;

    /// The database's own consistency check (SQLite's `PRAGMA integrity_check` and the R*Tree's;
    /// PostgreSQL: the schema is there and the indexes are valid). `Ok` when it passes.
    fn check_integrity(&self) -> Result<()>;
}

/// How many records a store holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Counts {
    /// Confirmed sites.
    pub confirmed: u64,
    /// Candidate roofs.
    pub candidates: u64,
    /// Seen areas kept for the update rule.
    pub seen_areas: u64,
}
