//! The catalog's faults with the real `landing-server` binary, fed by fused streams of the sample
//! recording with a geodetic origin (each stream a drone over a place of its own):
//!
//! - the server SIGKILLed while its catalog writer is busy: the SQLite file opens, passes the
//!   integrity check, holds every batch the server logged committed and at most the one in
//!   flight; what was lost is what was queued or in flight (at most `catalog.queue_capacity +
//!   catalog.batch_max` observations). A server started again on the file serves searches and
//!   keeps writing.
//! - its PostgreSQL + PostGIS (a server of the test's own, `catalog/tests/support`) stopped and
//!   started again mid-load: every frame is answered on time throughout, searches answer
//!   UNAVAILABLE naming the catalog while it is down, and writes resume without a restart.

#[path = "../../catalog/tests/support/postgres.rs"]
#[allow(dead_code)]
mod pg;

use std::io::{BufRead as _, BufReader};
use std::net::SocketAddr;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

use landing_catalog::{LatLon, SearchQuery, SqliteStore, Store as _, Timestamp};
use landing_proto::v1;
use landing_proto::v1::landing_service_client::LandingServiceClient;
use landing_server::telemetry::scrape;
use serde_json::Value;
use tokio::sync::{mpsc, watch};
use tonic::transport::Channel;

/// The demo's origin (README's Quick start); stream `i` flies `i` × 0.02° (2.2 km) north of it.
const ORIGIN: v1::GeodeticPoint = v1::GeodeticPoint {
    latitude_deg: 40.7536,
    longitude_deg: -73.9832,
    altitude_m: 0.0,
};

/// Fused streams at once: the writer always has something to write.
const STREAMS: usize = 3;

/// The catalog's queue and batch in these tests: small, so batches commit often and the bound
/// on what a kill loses is small.
const QUEUE_CAPACITY: u64 = 32;
const BATCH_MAX: u64 = 4;

/// The frames of the sample recording, each with its true label image as the class image (no
/// model needed: the catalog admits only ground a camera classified).
fn recorded_frames() -> Arc<Vec<v1::Frame>> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
    let frames: Vec<v1::Frame> = landing_recording::read(&path)
        .expect("the sample recording")
        .into_iter()
        .map(|r| v1::Frame {
            class_image: Some(r.labels.expect("the sample has label images")),
            ..r.frame
        })
        .collect();
    assert!(frames.len() >= 4, "{} frames", frames.len());
    Arc::new(frames)
}

fn origin(stream: usize) -> v1::GeodeticPoint {
    v1::GeodeticPoint {
        latitude_deg: ORIGIN.latitude_deg + 0.02 * stream as f64,
        ..ORIGIN
    }
}

/// The server's configuration for these tests, as environment variables: a catalog at
/// `location` (`path` or `url`) that writes small batches often and retries quickly, JSON logs
/// with the writer's batches at debug level.
fn catalog_env(key: &str, location: &str) -> Vec<(String, String)> {
    [
        (key, location),
        ("ENABLED", "true"),
        ("QUEUE_CAPACITY", &QUEUE_CAPACITY.to_string()),
        ("BATCH_MAX", &BATCH_MAX.to_string()),
        ("FLUSH_INTERVAL_S", "0.02"),
        ("OBSERVE_INTERVAL_S", "0"),
        ("RETRY_INTERVAL_S", "0.25"),
    ]
    .into_iter()
    .map(|(k, v)| (format!("LANDING__CATALOG__{k}"), v.to_owned()))
    .chain([
        ("LANDING__SEGMENTATION__ENABLED".into(), "false".into()),
        ("LANDING__LOG__FORMAT".into(), "json".into()),
        (
            "LANDING__LOG__FILTER".into(),
            "info,landing_server::catalog=debug".into(),
        ),
    ])
    .collect()
}

/// A `landing-server serve` process on loopback, its JSON log lines read on a thread of their
/// own. Killed (SIGKILL) when dropped.
struct ServerProcess {
    child: Child,
    url: String,
    metrics: SocketAddr,
    log: mpsc::UnboundedReceiver<Value>,
}

impl ServerProcess {
    /// Starts the server and waits (at most 30 s) for its "serving" line.
    async fn start(env: &[(String, String)]) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_landing-server"))
            .args(["serve", "--listen", "127.0.0.1:0"])
            .args(["--metrics-listen", "127.0.0.1:0"])
            .envs(env.iter().map(|(k, v)| (k, v)))
            .env_remove("RUST_LOG")
            .stderr(Stdio::piped())
            .spawn()
            .expect("start landing-server");
        let stderr = child.stderr.take().unwrap();
        let (tx, mut log) = mpsc::unbounded_channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                let doc = serde_json::from_str(&line).unwrap_or(Value::String(line));
                if tx.send(doc).is_err() {
                    break;
                }
            }
        });
        let serving = next_message(&mut log, "serving landing.v1", Duration::from_secs(30)).await;
        let fields = &serving["fields"];
        let metrics = fields["metrics"].as_str().unwrap_or_default();
        let metrics = metrics
            .strip_prefix("Some(")
            .and_then(|m| m.strip_suffix(')'))
            .and_then(|m| m.parse().ok())
            .unwrap_or_else(|| panic!("no metrics address in {serving}"));
        Self {
            child,
            url: format!("http://{}", fields["addr"].as_str().unwrap()),
            metrics,
            log,
        }
    }

    async fn channel(&self) -> Channel {
        Channel::from_shared(self.url.clone())
            .unwrap()
            .connect()
            .await
            .expect("connect to the server")
    }

    /// A counter or gauge of the server's metrics (0 when not yet registered).
    async fn metric(&self, series: &str) -> f64 {
        let text = scrape(self.metrics).await.expect("scrape the metrics");
        text.lines()
            .find_map(|l| l.strip_prefix(series)?.strip_prefix(' '))
            .map_or(0.0, |v| v.trim().parse().expect("a number"))
    }

    /// SIGKILL, and the log lines it wrote before it died.
    fn kill(&mut self) -> Vec<Value> {
        self.child.kill().expect("SIGKILL the server");
        self.child.wait().unwrap();
        // The reader thread ends at the pipe's end: everything written is in the channel.
        let mut rest = Vec::new();
        while let Some(line) = self.log.blocking_recv() {
            rest.push(line);
        }
        rest
    }
}

impl Drop for ServerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A log line's message.
fn message(line: &Value) -> &str {
    line["fields"]["message"].as_str().unwrap_or_default()
}

/// A numeric field of a log line.
fn field(line: &Value, name: &str) -> u64 {
    line["fields"][name]
        .as_u64()
        .unwrap_or_else(|| panic!("no {name} in {line}"))
}

/// Waits for the next log line with this message.
async fn next_message(
    log: &mut mpsc::UnboundedReceiver<Value>,
    wanted: &str,
    within: Duration,
) -> Value {
    let deadline = tokio::time::Instant::now() + within;
    loop {
        match tokio::time::timeout_at(deadline, log.recv()).await {
            Ok(Some(line)) if message(&line) == wanted => return line,
            Ok(Some(_)) => {}
            Ok(None) => panic!("the server exited before logging {wanted:?}"),
            Err(_) => panic!("no {wanted:?} within {within:?}"),
        }
    }
}

/// What one stream saw: frames sent and answered, each answer's send time and latency, and
/// what ended it.
#[derive(Debug, Default)]
struct StreamReport {
    sent: u64,
    answered: u64,
    latencies: Vec<(Instant, Duration)>,
    error: Option<String>,
}

/// A fused stream that sends the recording's frames over and over, one at a time (each after the
/// previous answer), until `stop` turns true; the map starts over at each repeat (time goes
/// back). Every answer must be a result within 30 s.
async fn fly(
    channel: Channel,
    frames: Arc<Vec<v1::Frame>>,
    stream: usize,
    stop: watch::Receiver<bool>,
) -> StreamReport {
    let mut report = StreamReport::default();
    if let Err(e) = fly_until(channel, &frames, stream, stop, &mut report).await {
        report.error = Some(e);
    }
    report
}

async fn fly_until(
    channel: Channel,
    frames: &[v1::Frame],
    stream: usize,
    mut stop: watch::Receiver<bool>,
    report: &mut StreamReport,
) -> Result<(), String> {
    let (tx, rx) = mpsc::channel(1);
    let mut client = LandingServiceClient::new(channel);
    let mut call = Some(Box::pin(
        client.stream_landing_sites(tokio_stream::wrappers::ReceiverStream::new(rx)),
    ));
    let mut answers = None;
    for (i, frame) in frames.iter().cycle().enumerate() {
        if *stop.borrow_and_update() {
            break;
        }
        let sent_at = Instant::now();
        tx.send(request(frame, i, stream))
            .await
            .map_err(|_| "the request stream closed")?;
        report.sent += 1;
        // The call answers once the server has the stream's first message.
        if let Some(c) = call.take() {
            answers = Some(c.await.map_err(|s| format!("{s:?}"))?.into_inner());
        }
        let next = answers.as_mut().expect("the call answered").message();
        let answer = tokio::time::timeout(Duration::from_secs(30), next)
            .await
            .map_err(|_| format!("frame {i} unanswered after 30 s"))?
            .map_err(|s| format!("{s:?}"))?
            .ok_or("the stream ended early")?;
        if !matches!(
            answer.outcome,
            Some(v1::stream_landing_sites_response::Outcome::Result(_))
        ) {
            return Err(format!("frame {i}: {:?}", answer.outcome));
        }
        report.answered += 1;
        report.latencies.push((sent_at, sent_at.elapsed()));
    }
    Ok(())
}

/// The `i`th message of stream `stream`: the frame as drone `faults-{stream}` saw it over its
/// origin, classed by its label image; the first message asks for fusion with the server's
/// defaults.
fn request(frame: &v1::Frame, i: usize, stream: usize) -> v1::StreamLandingSitesRequest {
    v1::StreamLandingSitesRequest {
        frame: Some(v1::Frame {
            drone_id: format!("faults-{stream}"),
            sequence: i as u64,
            geodetic_origin: Some(origin(stream)),
            ..frame.clone()
        }),
        options: Some(v1::PipelineOptions {
            segmentation_mode: v1::SegmentationMode::ClassImage as i32,
            ..Default::default()
        }),
        overflow_policy: v1::OverflowPolicy::Block as i32,
        fusion: (i == 0).then(v1::FusionOptions::default),
        ..Default::default()
    }
}

/// Starts [`STREAMS`] streams; `stop` ends them.
async fn fleet(
    server: &ServerProcess,
    frames: &Arc<Vec<v1::Frame>>,
) -> (
    watch::Sender<bool>,
    Vec<tokio::task::JoinHandle<StreamReport>>,
) {
    let (stop, stopped) = watch::channel(false);
    let mut streams = Vec::new();
    for i in 0..STREAMS {
        let channel = server.channel().await;
        streams.push(tokio::spawn(fly(
            channel,
            frames.clone(),
            i,
            stopped.clone(),
        )));
    }
    (stop, streams)
}

fn search_near(center: v1::GeodeticPoint) -> v1::SearchLandingSitesRequest {
    v1::SearchLandingSitesRequest {
        center: Some(center),
        radius_m: 1000.0,
        page_size: 1000,
        ..Default::default()
    }
}

/// A batch the server logged before it died: begun (in flight) or committed.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Batch {
    Writing {
        observations: u64,
        seen_areas: u64,
        queued: u64,
    },
    /// With the store's counts after the commit (absent when they could not be read: a
    /// database that went down right after the commit).
    Written {
        sites: Option<u64>,
        seen_areas: Option<u64>,
    },
}

fn batch(line: &Value) -> Option<Batch> {
    match message(line) {
        "writing a catalog batch" => Some(Batch::Writing {
            observations: field(line, "observations"),
            seen_areas: field(line, "seen_areas"),
            queued: field(line, "queued"),
        }),
        "catalog batch written" => Some(Batch::Written {
            sites: line["fields"]["sites"].as_u64(),
            seen_areas: line["fields"]["seen_areas"].as_u64(),
        }),
        _ => None,
    }
}

/// The server is SIGKILLed while its writer is busy, three times over one SQLite file: right
/// after it logs that a batch is being written, then `KILL_DELAYS` later (the kill lands before,
/// inside or after the batch's transaction). Each time the file opens, passes SQLite's integrity
/// check and the R*Tree's, and holds exactly what the server logged committed, plus the batch in
/// flight when that one committed before the kill landed (all or nothing: its seen areas are
/// there whole or not at all). Seen areas are only ever added (expiry deletes them after 30
/// days), so their count tells which batches the file holds. What a kill lost is what was queued
/// and in flight: at most `QUEUE_CAPACITY + BATCH_MAX` observations. A server started again on
/// the file answers searches from it at once and writes on.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_server_killed_mid_write_keeps_what_it_committed() {
    let started = Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("catalog.sqlite");
    let env = catalog_env("PATH", path.to_str().unwrap());
    let frames = recorded_frames();
    let mut held: Option<landing_catalog::Counts> = None;
    for (round, delay) in KILL_DELAYS.into_iter().enumerate() {
        let now = killed_mid_write(&env, &frames, &path, round, delay, held).await;
        assert!(
            now.seen_areas > held.map_or(0, |h| h.seen_areas),
            "round {round} wrote on after the previous kill: {now:?}"
        );
        held = Some(now);
    }
    restarted_server_serves_and_writes(&env, &frames, held.unwrap()).await;
    assert!(started.elapsed() < Duration::from_secs(90));
}

/// How long after the server logs "writing a catalog batch" each round kills it.
const KILL_DELAYS: [Duration; 3] = [
    Duration::ZERO,
    Duration::from_millis(2),
    Duration::from_millis(5),
];

/// One round: a server on the file (after the first round, it finds the sites the previous one
/// left), the fleet's streams, 8 batches committed, then SIGKILL `delay` after the next batch
/// begins; the file checked. Returns what the file holds.
async fn killed_mid_write(
    env: &[(String, String)],
    frames: &Arc<Vec<v1::Frame>>,
    path: &Path,
    round: usize,
    delay: Duration,
    held: Option<landing_catalog::Counts>,
) -> landing_catalog::Counts {
    let mut server = ServerProcess::start(env).await;
    if let Some(before) = held {
        let mut client = LandingServiceClient::new(server.channel().await);
        search_when_open(&mut client, origin(0)).await;
        assert_eq!(
            sites_near_origins(&mut client).await as u64,
            before.confirmed,
            "round {round}: the restarted server finds every site the file holds"
        );
    }
    let (stop, streams) = fleet(&server, frames).await;
    let mut logged = Vec::new();
    let mut committed = 0;
    loop {
        let line = next_message_any(&mut server.log, Duration::from_secs(30)).await;
        let Some(b) = batch(&line) else { continue };
        logged.push((b, log_seconds(&line)));
        match b {
            Batch::Written { .. } => committed += 1,
            Batch::Writing { .. } if committed >= 8 => break,
            Batch::Writing { .. } => {}
        }
    }
    tokio::time::sleep(delay).await;
    let rest = tokio::task::block_in_place(|| server.kill());
    logged.extend(
        rest.iter()
            .filter_map(|l| Some((batch(l)?, log_seconds(l)))),
    );
    stop.send_replace(true);
    for s in streams {
        // Each ends with the connection the kill closed.
        s.await.unwrap();
    }
    let counts = tokio::task::block_in_place(|| check_file(path, &logged, round));
    let durations = batch_seconds(&logged);
    eprintln!(
        "round {round}: killed {delay:?} after a batch began, {committed} batches committed \
         (each took p50 {:.1} ms, max {:.1} ms); the file holds {} sites, {} seen areas",
        durations[durations.len() / 2] * 1e3,
        durations.last().unwrap() * 1e3,
        counts.confirmed,
        counts.seen_areas,
    );
    counts
}

/// Opens the file a killed server left, checks it and compares it with what the server logged;
/// returns its counts.
fn check_file(path: &Path, logged: &[(Batch, f64)], round: usize) -> landing_catalog::Counts {
    let store = SqliteStore::open(path).expect("the file opens after SIGKILL");
    store
        .check_integrity()
        .expect("integrity_check and rtreecheck pass after SIGKILL");
    let counts = store.counts().unwrap();
    let (sites, seen) = logged
        .iter()
        .rev()
        .find_map(|(b, _)| match *b {
            Batch::Written { sites, seen_areas } => Some((sites, seen_areas)),
            Batch::Writing { .. } => None,
        })
        .unwrap();
    let (sites, seen) = (
        sites.expect("SQLite counts after each batch"),
        seen.expect("SQLite counts after each batch"),
    );
    let in_flight = match logged.last().unwrap().0 {
        Batch::Writing {
            observations,
            seen_areas,
            queued,
        } => Some((observations, seen_areas, queued)),
        Batch::Written { .. } => None,
    };
    let in_flight_committed = match in_flight {
        Some((_, batch_seen, _)) if batch_seen > 0 && counts.seen_areas == seen + batch_seen => {
            true
        }
        _ => {
            assert_eq!(
                (counts.confirmed, counts.seen_areas),
                (sites, seen),
                "round {round}: the file holds what the server logged committed (sites, seen \
                 areas); in flight: {in_flight:?}"
            );
            false
        }
    };
    // What the kill lost: the batch in flight (unless it committed) and the queue behind it.
    let lost = in_flight.map_or(0, |(n, _, queued)| {
        queued + if in_flight_committed { 0 } else { n }
    });
    assert!(lost <= QUEUE_CAPACITY + BATCH_MAX, "{lost}");
    assert!(counts.confirmed > 0, "{counts:?}");
    let now = Timestamp::now();
    let found: usize = (0..STREAMS)
        .map(|i| {
            let o = origin(i);
            let q = SearchQuery {
                page_size: 1000,
                ..SearchQuery::new(LatLon::new(o.latitude_deg, o.longitude_deg), 1000.0)
            };
            store.search(&q, now).unwrap().sites.len()
        })
        .sum();
    assert_eq!(
        found as u64, counts.confirmed,
        "every site is near an origin"
    );
    let when = match in_flight {
        None => "between batches".to_owned(),
        Some((n, seen, queued)) if in_flight_committed => format!(
            "after a batch of {n} observations ({seen} seen areas; {queued} queued behind it) \
             committed, before the server logged it"
        ),
        Some((n, seen, queued)) => format!(
            "during a batch of {n} observations ({seen} seen areas; {queued} queued behind it), \
             which is not in the file"
        ),
    };
    eprintln!(
        "round {round}: the kill landed {when}; lost {lost} observations (bound {})",
        QUEUE_CAPACITY + BATCH_MAX
    );
    counts
}

/// The time of day of a JSON log line, seconds.
fn log_seconds(line: &Value) -> f64 {
    let t = line["timestamp"].as_str().unwrap_or_default();
    let clock = t
        .split_once('T')
        .map_or("", |(_, c)| c.trim_end_matches('Z'));
    let parts: Vec<f64> = clock.split(':').filter_map(|p| p.parse().ok()).collect();
    match parts[..] {
        [h, m, s] => h * 3600.0 + m * 60.0 + s,
        _ => panic!("no timestamp in {line}"),
    }
}

/// How long each logged batch took, from "writing" to "written", sorted.
fn batch_seconds(logged: &[(Batch, f64)]) -> Vec<f64> {
    let mut out: Vec<f64> = logged
        .windows(2)
        .filter_map(|w| match (w[0].0, w[1].0) {
            (Batch::Writing { .. }, Batch::Written { .. }) => {
                Some((w[1].1 - w[0].1).rem_euclid(86_400.0))
            }
            _ => None,
        })
        .collect();
    out.sort_by(f64::total_cmp);
    out
}

/// The next log line, whatever it says.
async fn next_message_any(log: &mut mpsc::UnboundedReceiver<Value>, within: Duration) -> Value {
    tokio::time::timeout(within, log.recv())
        .await
        .unwrap_or_else(|_| panic!("no log line within {within:?}"))
        .expect("the server is running")
}

/// A server on the killed one's file: searches find every site it `held` at once, and the
/// streams' observations are written on after them.
async fn restarted_server_serves_and_writes(
    env: &[(String, String)],
    frames: &Arc<Vec<v1::Frame>>,
    held: landing_catalog::Counts,
) {
    let seen_before = held.seen_areas;
    let mut server = ServerProcess::start(env).await;
    let mut client = LandingServiceClient::new(server.channel().await);
    search_when_open(&mut client, origin(0)).await;
    let found = sites_near_origins(&mut client).await;
    assert!(
        found as u64 == held.confirmed && found > 0,
        "the restarted server finds the {} sites written before the kill: {found}",
        held.confirmed
    );
    let (stop, streams) = fleet(&server, frames).await;
    loop {
        let line = next_message_any(&mut server.log, Duration::from_secs(30)).await;
        if let Some(Batch::Written { seen_areas, .. }) = batch(&line) {
            assert!(seen_areas > Some(seen_before), "{line}");
            break;
        }
    }
    assert!(server.metric("landing_catalog_writes_total").await > 0.0);
    stop.send_replace(true);
    for s in streams {
        let report = s.await.unwrap();
        assert_eq!(report.error, None, "{report:?}");
        assert_eq!(report.sent, report.answered, "{report:?}");
    }
}

/// A search, once the catalog is open: UNAVAILABLE while it is being opened (at most 10 s).
async fn search_when_open(
    client: &mut LandingServiceClient<Channel>,
    center: v1::GeodeticPoint,
) -> v1::SearchLandingSitesResponse {
    let give_up = Instant::now() + Duration::from_secs(10);
    loop {
        match client.search_landing_sites(search_near(center)).await {
            Ok(page) => return page.into_inner(),
            Err(status) => {
                assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
                assert!(
                    Instant::now() < give_up,
                    "the catalog never opened: {status:?}"
                );
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        }
    }
}

/// The sites a search finds near the streams' origins, all together.
async fn sites_near_origins(client: &mut LandingServiceClient<Channel>) -> usize {
    let mut n = 0;
    for i in 0..STREAMS {
        let page = client.search_landing_sites(search_near(origin(i))).await;
        n += page.expect("a search").into_inner().sites.len();
    }
    n
}

/// The harness's key=value connection string as the `postgres://` URL `catalog.url` takes.
fn postgres_url(conninfo: &str) -> String {
    let get = |key: &str| {
        conninfo
            .split_whitespace()
            .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
            .unwrap_or_else(|| panic!("no {key} in {conninfo}"))
    };
    format!(
        "postgres://{}@{}:{}/{}",
        get("user"),
        get("host"),
        get("port"),
        get("dbname")
    )
}

/// Polls `metric` until `done` says so, for at most `within`; its last value.
async fn until_metric(
    server: &ServerProcess,
    series: &str,
    within: Duration,
    done: impl Fn(f64) -> bool,
) -> f64 {
    let give_up = Instant::now() + within;
    loop {
        let v = server.metric(series).await;
        if done(v) {
            return v;
        }
        assert!(Instant::now() < give_up, "{series} = {v} after {within:?}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// How long the database stays down.
const DOWN: Duration = Duration::from_secs(3);

/// The most a frame may take while the database is down: generous for this loaded 2-core box
/// (a fused frame of the sample takes tens of milliseconds when it is quiet).
const ON_TIME: Duration = Duration::from_secs(2);

/// The server on a PostgreSQL + PostGIS of the test's own, fused streams with an origin running
/// throughout; the database is stopped at once (`pg_ctl stop -m immediate`, as a crash) mid-load,
/// stays down for [`DOWN`] while the streams go on, and is started again. Every frame sent is
/// answered, each within [`ON_TIME`]; while the database is down searches answer UNAVAILABLE
/// naming the catalog, writes fail (counted, retried every `retry_interval_s`) and the catalog
/// reports itself disconnected; after the restart writes resume and searches find sites, with
/// no restart of the server.
#[test]
fn postgres_stopped_and_restarted_with_the_server_running() {
    on_dedicated_postgres(&[], postgres_fault);
}

/// Runs `fault` on a PostgreSQL + PostGIS of the test's own with a fresh database, given the
/// server's environment for it (`extra` settings added) and the recorded frames, on a
/// two-thread runtime, in at most 90 s.
fn on_dedicated_postgres<F: std::future::Future<Output = ()>>(
    extra: &[(&str, String)],
    fault: impl FnOnce(Arc<pg::PgServer>, Vec<(String, String)>, Arc<Vec<v1::Frame>>) -> F,
) {
    let started = Instant::now();
    let db = Arc::new(pg::dedicated());
    let url = postgres_url(&db.create_database());
    let mut env = catalog_env("URL", &url);
    env.extend(extra.iter().map(|(k, v)| ((*k).to_owned(), v.clone())));
    let frames = recorded_frames();
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
        .block_on(fault(db, env, frames));
    assert!(started.elapsed() < Duration::from_secs(90));
}

async fn postgres_fault(
    db: Arc<pg::PgServer>,
    env: Vec<(String, String)>,
    frames: Arc<Vec<v1::Frame>>,
) {
    let mut server = ServerProcess::start(&env).await;
    let mut client = LandingServiceClient::new(server.channel().await);
    let (stop, streams) = fleet(&server, &frames).await;
    until_metric(&server, WRITES, Duration::from_secs(30), |n| n >= 8.0).await;

    let pg = db.clone();
    tokio::task::spawn_blocking(move || pg.stop_immediately())
        .await
        .unwrap();
    let down_at = Instant::now();
    let down = while_down(&server, &mut client).await;
    let pg = db.clone();
    tokio::task::spawn_blocking(move || pg.start_again())
        .await
        .unwrap();
    let up_at = Instant::now();
    let resumed = until_metric(&server, WRITES, Duration::from_secs(15), |n| {
        n > down.written
    })
    .await;
    let resumed_in = up_at.elapsed();
    assert_eq!(server.metric("landing_catalog_connected").await, 1.0);
    // Which of the streams' roofs hold a site at a given moment varies (each repeat of the
    // recording starts its map over): any of them will do.
    let give_up = Instant::now() + Duration::from_secs(15);
    while sites_near_origins(&mut client).await == 0 {
        assert!(
            Instant::now() < give_up,
            "no search finds sites after the restart"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let dropped = server.metric("landing_catalog_dropped_total").await;

    stop.send_replace(true);
    let (sent, before, during) = latencies(streams, down_at, up_at).await;
    let mut logged = Vec::new();
    while let Ok(line) = server.log.try_recv() {
        if let Some(b) = batch(&line) {
            logged.push((b, log_seconds(&line)));
        }
    }
    let batches = batch_seconds(&logged);
    let ms = |d: &Duration| d.as_secs_f64() * 1e3;
    eprintln!(
        "{sent} frames sent and answered; latency before the stop p50 {:.0} ms max {:.0} ms ({} \
         frames), while down p50 {:.0} ms max {:.0} ms ({} frames); {} searches UNAVAILABLE \
         while down; {} write failures; writes resumed {:.2} s after the restart ({} → {resumed} \
         observations written); {} batches written, each in p50 {:.0} ms, max {:.0} ms; \
         {dropped} observations dropped (queue full or down)",
        ms(&before[before.len() / 2]),
        ms(before.last().unwrap()),
        before.len(),
        ms(&during[during.len() / 2]),
        ms(during.last().unwrap()),
        during.len(),
        down.searches,
        down.failures,
        resumed_in.as_secs_f64(),
        down.written,
        batches.len(),
        batches[batches.len() / 2] * 1e3,
        batches.last().unwrap() * 1e3,
    );
}

const WRITES: &str = "landing_catalog_writes_total";

/// What the test saw while the database was down.
struct Down {
    /// Searches answered UNAVAILABLE.
    searches: u32,
    /// Write failures counted.
    failures: f64,
    /// Observations written (the same all along).
    written: f64,
}

/// For [`DOWN`] after the database stopped: every search answers UNAVAILABLE naming the
/// catalog, within [`ON_TIME`]; then the writes that failed are counted, nothing was written,
/// and the catalog says it is not connected.
async fn while_down(server: &ServerProcess, client: &mut LandingServiceClient<Channel>) -> Down {
    let down_at = Instant::now();
    let written = server.metric(WRITES).await;
    let mut searches = 0;
    while down_at.elapsed() < DOWN {
        let (_, took) = unavailable_search(client).await;
        assert!(took < ON_TIME, "a search took {took:?}");
        searches += 1;
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let failures = server.metric("landing_catalog_write_failures_total").await;
    assert!(
        failures > 0.0,
        "the writes while down failed and were counted"
    );
    assert_eq!(server.metric("landing_catalog_connected").await, 0.0);
    assert_eq!(
        written,
        server.metric(WRITES).await,
        "nothing is written while down"
    );
    Down {
        searches,
        failures,
        written,
    }
}

/// A search near the first origin, which must answer UNAVAILABLE naming the catalog: its status
/// and how long it took.
async fn unavailable_search(
    client: &mut LandingServiceClient<Channel>,
) -> (tonic::Status, Duration) {
    let asked = Instant::now();
    let status = client
        .search_landing_sites(search_near(origin(0)))
        .await
        .expect_err("no search answers while the database is down or frozen");
    let took = asked.elapsed();
    assert_eq!(status.code(), tonic::Code::Unavailable, "{status:?}");
    assert!(status.message().contains("catalog"), "{status:?}");
    (status, took)
}

/// Every stream's frames answered, each within [`ON_TIME`]: how many, and the latencies of the
/// frames sent before `down_at` and between it and `up_at`, sorted.
async fn latencies(
    streams: Vec<tokio::task::JoinHandle<StreamReport>>,
    down_at: Instant,
    up_at: Instant,
) -> (u64, Vec<Duration>, Vec<Duration>) {
    let (mut sent, mut before, mut during) = (0, Vec::new(), Vec::new());
    for s in streams {
        let report = s.await.unwrap();
        assert_eq!(report.error, None, "{report:?}");
        assert_eq!(
            report.sent, report.answered,
            "every frame answered: {report:?}"
        );
        sent += report.sent;
        for (at, took) in report.latencies {
            assert!(took < ON_TIME, "a frame took {took:?}");
            if at < down_at {
                before.push(took);
            } else if at < up_at {
                during.push(took);
            }
        }
    }
    assert!(
        !before.is_empty() && !during.is_empty(),
        "frames before and while down"
    );
    before.sort();
    during.sort();
    (sent, before, during)
}

/// How long a search may wait on the database in [`frozen_postgres_holds_no_search_past_its_deadline`].
const SEARCH_TIMEOUT: Duration = Duration::from_millis(500);

/// The server on a PostgreSQL + PostGIS of the test's own, fused streams running throughout; the
/// database freezes mid-load (every process SIGSTOPped, as a paused VM: connections stay open and
/// the kernel still acknowledges, so neither TCP keepalives nor the user timeout fire) for
/// [`DOWN`], then runs on. Every frame is answered within [`ON_TIME`]; every search answers
/// UNAVAILABLE naming the catalog once `catalog.search_timeout_s` has passed, not when the
/// database answers; after the thaw searches find sites again and writes resume.
#[test]
fn frozen_postgres_holds_no_search_past_its_deadline() {
    let timeout = SEARCH_TIMEOUT.as_secs_f64().to_string();
    on_dedicated_postgres(
        &[("LANDING__CATALOG__SEARCH_TIMEOUT_S", timeout)],
        postgres_frozen,
    );
}

async fn postgres_frozen(
    db: Arc<pg::PgServer>,
    env: Vec<(String, String)>,
    frames: Arc<Vec<v1::Frame>>,
) {
    let server = ServerProcess::start(&env).await;
    let mut client = LandingServiceClient::new(server.channel().await);
    let (stop, streams) = fleet(&server, &frames).await;
    until_metric(&server, WRITES, Duration::from_secs(30), |n| n >= 8.0).await;
    search_when_open(&mut client, origin(0)).await;

    db.freeze();
    let frozen_at = Instant::now();
    let mut searches = Vec::new();
    while frozen_at.elapsed() < DOWN {
        let (status, took) = unavailable_search(&mut client).await;
        assert!(status.message().contains("did not answer"), "{status:?}");
        assert!(
            took >= SEARCH_TIMEOUT && took < SEARCH_TIMEOUT + Duration::from_millis(500),
            "a search took {took:?}"
        );
        searches.push(took);
    }
    let written = server.metric(WRITES).await;
    db.thaw();
    let thawed_at = Instant::now();
    let give_up = thawed_at + Duration::from_secs(15);
    while sites_near_origins(&mut client).await == 0 {
        assert!(
            Instant::now() < give_up,
            "no search finds sites after the thaw"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let resumed = until_metric(&server, WRITES, Duration::from_secs(15), |n| n > written).await;

    stop.send_replace(true);
    let (sent, before, during) = latencies(streams, frozen_at, thawed_at).await;
    let ms = |d: &Duration| d.as_secs_f64() * 1e3;
    eprintln!(
        "{sent} frames sent and answered; latency before the freeze p50 {:.0} ms max {:.0} ms, \
         while frozen p50 {:.0} ms max {:.0} ms ({} frames); {} searches UNAVAILABLE while \
         frozen, in {:.0}-{:.0} ms; writes resumed after the thaw ({written} → {resumed})",
        ms(&before[before.len() / 2]),
        ms(before.last().unwrap()),
        ms(&during[during.len() / 2]),
        ms(during.last().unwrap()),
        during.len(),
        searches.len(),
        ms(searches.iter().min().unwrap()),
        ms(searches.iter().max().unwrap()),
    );
}
