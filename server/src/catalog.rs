//! The fleet's landing-site catalog in the server (`landing_catalog` holds the storage and the
//! update rule): the store, opened at start on a writer thread of its own; a bounded queue of
//! observations that thread drains in batches; the periodic expiry; and searches.
//!
//! What feeds it is [`Feed`] (one per stream, `feed.rs`); what reads it is
//! `SearchLandingSites` (`search.rs` converts). The frame path never waits on the database: a
//! stream's feed pushes an observation onto the queue under a lock that is only ever held to push
//! or pop (never across a database call) and drops the oldest when the queue is full (counted).
//! A store that cannot be opened does not stop the server: frames are answered, opening is
//! retried every `catalog.retry_interval_s`, observations wait in the queue (the oldest dropped
//! when it fills) and searches answer UNAVAILABLE naming the catalog. A failed write is retried
//! after the same interval; a batch the store refuses as invalid (a bug, never the caller's) or
//! corrupt is dropped and counted.

use std::collections::VecDeque;
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::{Duration, Instant};

use landing_catalog::{Location, Observation, SearchPage, SearchQuery, Store, Timestamp};

use crate::Error;
use crate::config::CatalogConfig;
use crate::telemetry::Metrics;

mod feed;
pub(crate) mod search;

pub(crate) use feed::Feed;

/// A running catalog: shared by the service (searches, feeds) and its writer thread.
#[derive(Clone)]
pub(crate) struct Catalog {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for Catalog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Catalog")
            .field("location", &self.shared.location)
            .finish_non_exhaustive()
    }
}

struct Shared {
    config: CatalogConfig,
    location: Location,
    /// The segmentation model's id, as observations name it ("" without a model).
    model_id: String,
    queue: Mutex<Queue>,
    wake: Condvar,
    /// The handle searches use (a second connection: a search never waits for a write's
    /// transaction on SQLite, whose readers run beside its writer in WAL mode).
    reader: RwLock<Result<Arc<dyn Store>, String>>,
    metrics: Metrics,
    writer: Mutex<Option<std::thread::JoinHandle<()>>>,
    /// Searches running on blocking threads, bounded: a frozen database holds each one's thread
    /// until it answers, and a search past the bound answers UNAVAILABLE at once.
    searching: Arc<tokio::sync::Semaphore>,
}

/// The most searches that wait on the database at once.
const SEARCHES_IN_FLIGHT: usize = 32;

#[derive(Default)]
struct Queue {
    observations: VecDeque<Observation>,
    stopping: bool,
}

impl Catalog {
    /// Starts the catalog `config` describes, or `None` when it is off. The store is opened on
    /// the writer thread, so a slow or absent database delays nothing here.
    pub fn start(
        config: &CatalogConfig,
        model_id: String,
        metrics: Metrics,
    ) -> Result<Option<Self>, Error> {
        let Some(location) = config.location()? else {
            return Ok(None);
        };
        if let Location::Sqlite(path) = &location
            && let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
            && let Err(e) = std::fs::create_dir_all(dir)
        {
            // Counted and retried like any store that cannot be opened.
            tracing::warn!(dir = %dir.display(), error = %e, "cannot create the catalog's directory");
        }
        let shared = Arc::new(Shared {
            config: config.clone(),
            location,
            model_id,
            queue: Mutex::new(Queue::default()),
            wake: Condvar::new(),
            reader: RwLock::new(Err("the store is being opened".into())),
            metrics,
            writer: Mutex::new(None),
            searching: Arc::new(tokio::sync::Semaphore::new(SEARCHES_IN_FLIGHT)),
        });
        let writer = shared.clone();
        let handle = std::thread::Builder::new()
            .name("catalog-writer".into())
            .spawn(move || Writer::new(writer).run())
            .map_err(|e| Error::Internal(format!("start the catalog's writer thread: {e}")))?;
        *lock(&shared.writer) = Some(handle);
        Ok(Some(Self { shared }))
    }

    /// A feed for one stream's answers.
    pub fn feed(&self) -> Feed {
        Feed::new(self.clone())
    }

    /// Queues an observation without waiting: when the queue is full the oldest is dropped.
    fn submit(&self, observation: Observation) {
        let s = &self.shared;
        let (depth, dropped) = {
            let mut q = lock(&s.queue);
            q.observations.push_back(observation);
            let excess = q
                .observations
                .len()
                .saturating_sub(s.config.queue_capacity as usize);
            q.observations.drain(..excess);
            (q.observations.len(), excess)
        };
        if dropped > 0 {
            s.metrics.catalog_dropped(dropped);
        }
        s.metrics.catalog_queue(depth);
        s.wake.notify_one();
    }

    /// One page of a search, run on a blocking thread: UNAVAILABLE naming the catalog when the
    /// database has not answered within `catalog.search_timeout_s`, or when
    /// [`SEARCHES_IN_FLIGHT`] searches already wait on it. The blocking `postgres` client has no
    /// deadline of its own; a search past its deadline holds its thread (and its place in the
    /// bound) until the database answers or the connection drops.
    pub async fn search(&self, query: SearchQuery) -> Result<SearchPage, Error> {
        let location = &self.shared.location;
        let Ok(permit) = self.shared.searching.clone().try_acquire_owned() else {
            query.validate(Timestamp::now())?;
            return Err(Error::CatalogUnavailable(format!(
                "{location:?}: {SEARCHES_IN_FLIGHT} searches are waiting on it already"
            )));
        };
        let catalog = self.clone();
        let searched = tokio::task::spawn_blocking(move || {
            let _permit = permit;
            catalog.search_blocking(&query)
        });
        let timeout = Duration::from_secs_f64(self.shared.config.search_timeout_s);
        match tokio::time::timeout(timeout, searched).await {
            Ok(Ok(page)) => page,
            Ok(Err(e)) => Err(Error::Internal(format!("catalog search: {e}"))),
            Err(_) => Err(Error::CatalogUnavailable(format!(
                "{location:?} did not answer within catalog.search_timeout_s = {} s",
                timeout.as_secs_f64()
            ))),
        }
    }

    /// One page of a search; blocks on the database.
    fn search_blocking(&self, query: &SearchQuery) -> Result<SearchPage, Error> {
        let reader = match &*self.shared.reader.read().unwrap_or_else(|e| e.into_inner()) {
            Ok(store) => store.clone(),
            Err(why) => {
                // A bad request is the caller's to fix whether or not the store is open; an open
                // store checks the request itself.
                query.validate(Timestamp::now())?;
                return Err(Error::CatalogUnavailable(format!(
                    "{:?} is not open: {why}",
                    self.shared.location
                )));
            }
        };
        let start = Instant::now();
        let page = reader.search(query, Timestamp::now());
        self.shared.metrics.catalog_query(start.elapsed());
        Ok(page?)
    }

    /// The age past which sites are left out when a search does not say.
    pub fn max_age(&self) -> Duration {
        self.shared.config.max_age()
    }

    /// Writes what is queued (one try) and stops the writer thread; waits at most `grace`. The
    /// search handle is closed off the async runtime too (the PostgreSQL client blocks on a
    /// runtime of its own when it closes).
    pub async fn stop(&self, grace: Duration) {
        lock(&self.shared.queue).stopping = true;
        self.shared.wake.notify_all();
        let reader = std::mem::replace(
            &mut *self
                .shared
                .reader
                .write()
                .unwrap_or_else(|e| e.into_inner()),
            Err("the catalog has stopped".into()),
        );
        let handle = lock(&self.shared.writer).take();
        let joined = tokio::task::spawn_blocking(move || {
            drop(reader);
            handle.map(std::thread::JoinHandle::join)
        });
        if tokio::time::timeout(grace, joined).await.is_err() {
            tracing::warn!(
                "the catalog's writer did not finish in time; queued observations are lost"
            );
        }
    }
}

impl Drop for Shared {
    /// A catalog dropped without [`Catalog::stop`] (a server task aborted) may be dropped on an
    /// async runtime's thread, where closing a PostgreSQL handle would panic: it is closed on a
    /// thread of its own.
    fn drop(&mut self) {
        let reader = std::mem::replace(
            self.reader.get_mut().unwrap_or_else(|e| e.into_inner()),
            Err(String::new()),
        );
        if let Ok(store) = reader
            && tokio::runtime::Handle::try_current().is_ok()
        {
            let _ = std::thread::Builder::new()
                .name("catalog-close".into())
                .spawn(move || drop(store));
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The writer thread's state: the store it writes (once open) and when it next does what.
struct Writer {
    shared: Arc<Shared>,
    store: Option<Box<dyn Store>>,
    next_open: Instant,
    next_write: Instant,
    next_expire: Instant,
}

impl Writer {
    fn new(shared: Arc<Shared>) -> Self {
        let now = Instant::now();
        Self {
            shared,
            store: None,
            next_open: now,
            next_write: now,
            next_expire: now,
        }
    }

    /// Opens the store, then writes batches as they come and expires old sites, until stopped
    /// and the queue is written (or cannot be).
    fn run(mut self) {
        loop {
            if self.store.is_none() && Instant::now() >= self.next_open {
                self.open();
            }
            let (batch, stopping) = self.take_batch();
            if !batch.is_empty() {
                self.write(batch, stopping);
            }
            if Instant::now() >= self.next_expire {
                self.expire();
            }
            if stopping
                && (self.store.is_none() || lock(&self.shared.queue).observations.is_empty())
            {
                break;
            }
        }
        let left = lock(&self.shared.queue).observations.len();
        if left > 0 {
            self.shared.metrics.catalog_dropped(left);
            tracing::warn!(
                observations = left,
                "catalog stopped with observations unwritten"
            );
        }
    }

    fn open(&mut self) {
        let s = &self.shared;
        let retry = Duration::from_secs_f64(s.config.retry_interval_s);
        let opened = s.location.open().and_then(|w| Ok((w, s.location.open()?)));
        match opened {
            Ok((writer, reader)) => {
                tracing::info!(location = ?s.location, backend = writer.backend(), "catalog open");
                if let Ok(counts) = writer.counts() {
                    s.metrics.catalog_sites(&counts);
                }
                self.store = Some(writer);
                *s.reader.write().unwrap_or_else(|e| e.into_inner()) = Ok(Arc::from(reader));
                s.metrics.catalog_connected(true);
            }
            Err(e) => {
                tracing::warn!(location = ?s.location, error = %e, retry_s = retry.as_secs_f64(), "cannot open the catalog; frames are answered, writes wait");
                *s.reader.write().unwrap_or_else(|e| e.into_inner()) = Err(e.to_string());
                s.metrics.catalog_write_failed();
                self.next_open = Instant::now() + retry;
            }
        }
    }

    /// Waits up to `flush_interval_s` for a batch (sooner when `batch_max` are queued, the
    /// catalog stops, or opening or expiring is due), then takes what is queued, up to
    /// `batch_max`, when the store can take it. Also says whether the catalog is stopping.
    fn take_batch(&self) -> (Vec<Observation>, bool) {
        let s = &self.shared;
        let max = s.config.batch_max as usize;
        let deadline = Instant::now() + Duration::from_secs_f64(s.config.flush_interval_s);
        let mut q = lock(&s.queue);
        loop {
            let now = Instant::now();
            let writable = self.store.is_some() && now >= self.next_write;
            if q.stopping || (writable && q.observations.len() >= max) {
                break;
            }
            let mut until = deadline.min(self.next_expire);
            if self.store.is_none() {
                until = until.min(self.next_open);
            } else if self.next_write > now && !q.observations.is_empty() {
                // A failed write is retried when its interval is up, not at the next flush.
                until = until.min(self.next_write);
            }
            if now >= until {
                break;
            }
            q = s
                .wake
                .wait_timeout(q, until - now)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        let stopping = q.stopping;
        if self.store.is_none() || (!stopping && Instant::now() < self.next_write) {
            return (Vec::new(), stopping);
        }
        let n = q.observations.len().min(max);
        let batch: Vec<Observation> = q.observations.drain(..n).collect();
        s.metrics.catalog_queue(q.observations.len());
        (batch, stopping)
    }

    /// Applies a batch; on a storage failure puts it back (oldest first, within the capacity)
    /// and waits `retry_interval_s` before the next write, unless stopping. Each batch is logged
    /// at debug level before and after (with the store's counts): what a killed server had
    /// committed can be read back from its log.
    fn write(&mut self, batch: Vec<Observation>, stopping: bool) {
        let s = self.shared.clone();
        let Some(store) = &self.store else {
            return self.requeue(batch);
        };
        tracing::debug!(
            observations = batch.len(),
            seen_areas = batch.iter().map(|o| o.seen.len()).sum::<usize>(),
            queued = lock(&s.queue).observations.len(),
            "writing a catalog batch"
        );
        match store.apply(&batch) {
            Ok(report) => {
                s.metrics.catalog_connected(true);
                s.metrics.catalog_written(&report);
                let counts = store.counts();
                if let Ok(counts) = &counts {
                    s.metrics.catalog_sites(counts);
                }
                let counts = counts.ok();
                tracing::debug!(
                    observations = report.observations,
                    sites = counts.map(|c| c.confirmed),
                    seen_areas = counts.map(|c| c.seen_areas),
                    "catalog batch written"
                );
            }
            Err(e @ landing_catalog::Error::Storage { .. }) if !stopping => {
                tracing::warn!(error = %e, observations = batch.len(), "catalog write failed; retrying");
                s.metrics.catalog_write_failed();
                s.metrics.catalog_connected(false);
                self.next_write =
                    Instant::now() + Duration::from_secs_f64(s.config.retry_interval_s);
                self.requeue(batch);
            }
            Err(e) => {
                tracing::error!(error = %e, observations = batch.len(), "catalog refused a batch; dropped");
                s.metrics.catalog_write_failed();
                s.metrics.catalog_dropped(batch.len());
            }
        }
    }

    /// Puts a batch back at the front of the queue, dropping the oldest beyond the capacity.
    fn requeue(&self, batch: Vec<Observation>) {
        let s = &self.shared;
        let mut q = lock(&s.queue);
        for o in batch.into_iter().rev() {
            q.observations.push_front(o);
        }
        let excess = q
            .observations
            .len()
            .saturating_sub(s.config.queue_capacity as usize);
        q.observations.drain(..excess);
        drop(q);
        if excess > 0 {
            s.metrics.catalog_dropped(excess);
        }
    }

    fn expire(&mut self) {
        let s = &self.shared;
        self.next_expire = Instant::now() + Duration::from_secs_f64(s.config.expire_interval_s);
        let Some(store) = &self.store else {
            return;
        };
        let retention = Duration::from_secs_f64(s.config.retention_s);
        match store.expire(Timestamp::now(), retention) {
            Ok(0) => {}
            Ok(n) => tracing::info!(sites = n, "expired catalog sites"),
            Err(e) => tracing::warn!(error = %e, "catalog expiry failed"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value of the series written exactly as `series`.
    fn value(text: &str, series: &str) -> Option<f64> {
        text.lines()
            .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
            .and_then(|v| v.trim().parse().ok())
    }

    fn observation(i: i64) -> Observation {
        Observation {
            t: Timestamp::from_unix_ms(1_796_588_100_000 + i),
            drone_id: format!("d{i}"),
            ..Default::default()
        }
    }

    #[test]
    fn with_the_store_down_the_queue_keeps_the_newest_and_counts_the_rest() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let config = CatalogConfig {
            url: format!("postgres://landing@127.0.0.1:{port}/catalog?connect_timeout=1"),
            queue_capacity: 2,
            retry_interval_s: 60.0,
            ..CatalogConfig::default()
        };
        let metrics = Metrics::default();
        let catalog = Catalog::start(&config, String::new(), metrics.clone())
            .unwrap()
            .unwrap();
        for i in 0..5 {
            catalog.submit(observation(i));
        }
        let kept: Vec<String> = lock(&catalog.shared.queue)
            .observations
            .iter()
            .map(|o| o.drone_id.clone())
            .collect();
        assert_eq!(kept, ["d3", "d4"], "the oldest are dropped");
        let text = metrics.render();
        assert_eq!(value(&text, "landing_catalog_dropped_total"), Some(3.0));
        assert_eq!(value(&text, "landing_catalog_queue_depth"), Some(2.0));
        // Searches say the catalog is not open, naming it; the writer keeps retrying.
        let give_up = Instant::now() + Duration::from_secs(10);
        loop {
            let e = catalog
                .search_blocking(&SearchQuery::new(
                    landing_catalog::LatLon::new(40.7, -74.0),
                    500.0,
                ))
                .unwrap_err();
            assert!(matches!(e, Error::CatalogUnavailable(_)), "{e}");
            if !e.to_string().contains("being opened") || Instant::now() > give_up {
                assert!(e.to_string().contains("Postgres"), "{e}");
                break;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let runtime = tokio::runtime::Runtime::new().unwrap();
        runtime.block_on(catalog.stop(Duration::from_secs(5)));
        let text = metrics.render();
        assert_eq!(
            value(&text, "landing_catalog_dropped_total"),
            Some(5.0),
            "what could not be written when it stopped is counted"
        );
    }
}
