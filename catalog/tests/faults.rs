//! Faults at the store level: a SQLite writer killed mid-write, a PostgreSQL server stopped and
//! restarted mid-load. The server-level ones, with the real binary and frames answered
//! throughout, are in `server/tests/catalog_faults.rs`.

#[path = "support/postgres.rs"]
#[allow(dead_code)]
mod pg;

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, mpsc};
use std::time::{Duration, Instant};

use landing_catalog::{
    Error, LatLon, LocalFrame, Observation, ObservedSite, Polygon, PostgisStore, SearchQuery,
    SqliteStore, Store, Timestamp,
};

const ORIGIN: LatLon = LatLon::new(40.7484, -73.9857);
const T0: i64 = 1_796_588_100_000;

/// Observations per batch the writers apply; each observation inserts one new site.
const BATCH: u64 = 50;

/// Batch `j`: `BATCH` observations of distinct roofs on a 40 m grid, each finding one site.
fn batch(j: u64) -> Vec<Observation> {
    let f = LocalFrame::new(ORIGIN);
    let square = |x: f64, y: f64, h: f64| {
        Polygon::rectangle(f.to_lat_lon((x - h, y - h)), f.to_lat_lon((x + h, y + h)))
    };
    (0..BATCH)
        .map(|i| {
            let n = j * BATCH + i;
            let (x, y) = ((n % 200) as f64 * 40.0, (n / 200) as f64 * 40.0);
            Observation {
                t: Timestamp::from_unix_ms(T0 + n as i64),
                drone_id: "drone-1".into(),
                approach_id: format!("approach-{j}"),
                model_id: "model-a".into(),
                seen: vec![square(x, y, 15.0)],
                sites: vec![ObservedSite {
                    polygon: square(x, y, 6.0),
                    center: f.to_lat_lon((x, y)),
                    safe_radius_m: 5.0,
                    plane_height_m: 20.0,
                    frames: 1,
                }],
            }
        })
        .collect()
}

/// The child's side of the SQLite kill test: set in its environment, the file to write.
const WRITER_ENV: &str = "CATALOG_FAULT_SQLITE_WRITER";

/// Kills a child on drop, so a failing test leaves no writer behind.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A writer process (this test binary again, told by [`WRITER_ENV`]) applies batches to a SQLite
/// file in a loop, saying `begin j` before and `committed j` after each; the test SIGKILLs it
/// while a batch is in flight, three times over the same file. Each time the file opens, passes
/// the integrity check (SQLite's and the R*Tree's), and holds every batch the writer reported
/// committed and at most the one in flight, whole (a transaction is all or nothing): at most one
/// batch ([`BATCH`] observations) is lost.
/// Several processes opening one new catalog file at once (a server starting while the command
/// line imports into the same file) all open it: the first to make it a WAL file holds a lock
/// the others' busy timeout cannot wait out (SQLite answers "database is locked" at once rather
/// than deadlock), so opening waits and tries again.
#[test]
fn sqlite_opened_by_many_at_once_opens_for_all() {
    let dir = tempfile::tempdir().unwrap();
    for round in 0..40 {
        let path = dir.path().join(format!("race-{round}.sqlite"));
        let start = Arc::new(std::sync::Barrier::new(4));
        let opened: Vec<Result<SqliteStore, Error>> = std::thread::scope(|threads| {
            let openers: Vec<_> = (0..4)
                .map(|_| {
                    let (start, path) = (start.clone(), &path);
                    threads.spawn(move || {
                        start.wait();
                        SqliteStore::open(path)
                    })
                })
                .collect();
            openers.into_iter().map(|o| o.join().unwrap()).collect()
        });
        for o in opened {
            if let Err(e) = o {
                panic!("round {round}: {e}");
            }
        }
    }
}

#[test]
fn sqlite_killed_mid_write_loses_at_most_the_batch_in_flight() {
    if let Ok(path) = std::env::var(WRITER_ENV) {
        return sqlite_writer(&path);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("catalog.sqlite");
    let started = Instant::now();
    let mut in_flight_lost = 0;
    for round in 0..3 {
        let child = Command::new(std::env::current_exe().unwrap())
            .args([
                "--exact",
                "sqlite_killed_mid_write_loses_at_most_the_batch_in_flight",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(WRITER_ENV, &path)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut child = KillOnDrop(child);
        let lines = lines_of(child.0.stdout.take().unwrap());
        let mut committed: Option<u64> = None;
        let mut began: u64;
        // Let a few batches commit, then kill while the next is being written.
        loop {
            let line = lines
                .recv_timeout(Duration::from_secs(20))
                .expect("the writer reports within 20 s");
            if let Some(j) = line.strip_prefix("committed ") {
                committed = Some(j.parse().unwrap());
            } else if let Some(j) = line.strip_prefix("begin ") {
                began = j.parse().unwrap();
                if committed.is_some_and(|c| c >= 3 + round * 3) {
                    break;
                }
            }
        }
        // The batch takes milliseconds: a short sleep lands inside it.
        std::thread::sleep(Duration::from_millis(2));
        child.0.kill().unwrap(); // SIGKILL
        child.0.wait().unwrap();
        // Lines the writer wrote before it died.
        while let Ok(line) = lines.recv_timeout(Duration::from_millis(200)) {
            if let Some(j) = line.strip_prefix("committed ") {
                committed = Some(j.parse().unwrap());
            } else if let Some(j) = line.strip_prefix("begin ") {
                began = j.parse().unwrap();
            }
        }
        let committed = committed.unwrap();
        let store = SqliteStore::open(&path).expect("the file opens after SIGKILL");
        store
            .check_integrity()
            .expect("integrity_check and rtreecheck pass after SIGKILL");
        let stored = store.counts().unwrap().confirmed;
        let reported = (committed + 1) * BATCH;
        assert_eq!(stored % BATCH, 0, "a batch is stored whole or not at all");
        assert!(
            stored == reported || (began == committed + 1 && stored == reported + BATCH),
            "round {round}: the writer reported batches 0..={committed} committed (began {began}), \
             the file holds {stored} sites"
        );
        if began == committed + 1 && stored == reported {
            in_flight_lost += 1;
        }
        // The store still searches and writes.
        let q = SearchQuery::new(ORIGIN, 100.0);
        assert!(
            !store
                .search(&q, Timestamp::from_unix_ms(T0))
                .unwrap()
                .sites
                .is_empty()
        );
    }
    eprintln!(
        "3 kills; the batch in flight ({BATCH} observations) was lost {in_flight_lost} times \
         (else it had committed); {:.1} s",
        started.elapsed().as_secs_f64()
    );
    assert!(started.elapsed() < Duration::from_secs(60));
}

/// The writer: continues after what the file holds, forever (until killed).
fn sqlite_writer(path: &str) {
    let store = SqliteStore::open(path).unwrap();
    let mut j = store.counts().unwrap().confirmed / BATCH;
    let out = std::io::stdout();
    loop {
        let b = batch(j);
        writeln!(out.lock(), "begin {j}").unwrap();
        store.apply(&b).unwrap();
        writeln!(out.lock(), "committed {j}").unwrap();
        j += 1;
    }
}

/// The lines a child writes, through a channel (so the reader can time out).
fn lines_of(stdout: std::process::ChildStdout) -> mpsc::Receiver<String> {
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    rx
}

/// One write call: batches written so far, its outcome, how long it took.
type Call = (u64, Result<(), String>, Duration);

/// A PostgreSQL server of its own is stopped at once (`pg_ctl stop -m immediate`, as a crash)
/// while a writer thread applies batches through one store handle, and started again: while it
/// is down every call fails as unavailable storage, quickly (no panic, no hang), and after the
/// restart writes resume through the same handle, with nothing committed lost.
#[test]
fn postgres_stopped_and_restarted_mid_load() {
    let server = pg::dedicated();
    let url = server.create_database();
    let store = Arc::new(PostgisStore::connect(&url).unwrap());
    let stop = Arc::new(AtomicBool::new(false));
    let (tx, rx) = mpsc::channel::<Call>();
    let writer = {
        let (store, stop) = (store.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut j = 0;
            while !stop.load(Ordering::Relaxed) {
                let t = Instant::now();
                let out = store.apply(&batch(j));
                let took = t.elapsed();
                let r = match out {
                    Ok(_) => {
                        j += 1;
                        Ok(())
                    }
                    Err(e @ Error::Storage { .. }) => {
                        // Down: try again shortly (the server's write queue would drop it).
                        std::thread::sleep(Duration::from_millis(20));
                        Err(e.to_string())
                    }
                    Err(e) => panic!("not a storage error: {e}"),
                };
                if tx.send((j, r, took)).is_err() {
                    break;
                }
            }
        })
    };
    // Some batches in, then the crash.
    let wait_for = |pred: &dyn Fn(&Call) -> bool, what: &str| {
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut seen = Vec::new();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let ev = rx
                .recv_timeout(left)
                .unwrap_or_else(|_| panic!("{what} within 30 s"));
            let done = pred(&ev);
            seen.push(ev);
            if done {
                return seen;
            }
        }
    };
    let before = wait_for(&|e| e.0 >= 5, "five batches written");
    server.stop_immediately();
    let stopped_at = Instant::now();
    let down = wait_for(&|e| e.1.is_err(), "a failed write while the server is down");
    // Reads fail too, and fast.
    for _ in 0..3 {
        let t = Instant::now();
        let e = store
            .search(
                &SearchQuery::new(ORIGIN, 100.0),
                Timestamp::from_unix_ms(T0),
            )
            .unwrap_err();
        assert!(
            matches!(
                e,
                Error::Storage {
                    backend: "postgis",
                    ..
                }
            ),
            "{e}"
        );
        assert!(t.elapsed() < Duration::from_secs(6), "{:?}", t.elapsed());
    }
    // A while down: every write fails as storage, each within the connect timeout.
    let mut failures = down.iter().filter(|e| e.1.is_err()).count();
    let mut slowest = down.iter().map(|e| e.2).max().unwrap_or_default();
    while stopped_at.elapsed() < Duration::from_millis(500) {
        let e = rx
            .recv_timeout(Duration::from_secs(10))
            .expect("calls return while down");
        assert!(e.1.is_err(), "a write succeeded while the server was down");
        assert!(
            e.2 < Duration::from_secs(6),
            "a call took {:?} while down",
            e.2
        );
        slowest = slowest.max(e.2);
        failures += 1;
    }
    server.start_again();
    let after = wait_for(&|e| e.1.is_ok(), "a write after the restart");
    let resumed_at = after.last().unwrap().0;
    wait_for(
        &|e| e.0 >= resumed_at + 5,
        "five more batches after the restart",
    );
    stop.store(true, Ordering::Relaxed);
    drop(rx);
    writer.join().expect("the writer thread did not panic");
    let written = before.last().unwrap().0;
    let stored = store.counts().unwrap().confirmed;
    assert_eq!(stored % BATCH, 0, "batches are stored whole");
    assert!(
        stored >= (written + 5) * BATCH,
        "{stored} sites stored, {written} batches before"
    );
    store.check_integrity().unwrap();
    eprintln!(
        "{failures} calls failed while down, the slowest in {slowest:?}; writes resumed through \
         the same handle; {stored} sites stored"
    );
}
