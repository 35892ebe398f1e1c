//! The load test behind `landing loadtest`: N concurrent streams replay frames at a fixed rate
//! (or as fast as the server lets them) for a fixed time, and every sent frame must get exactly
//! one answer.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::{Duration, Instant};

use landing_proto::v1::Frame;

use landing_client::{
    ClientError, FrameOutcome, FrameSender, LandingClient, StreamConfig, StreamItem,
};

/// What to run.
#[derive(Debug, Clone)]
pub struct LoadTestConfig {
    /// Concurrent streams, each on the shared connection.
    pub streams: usize,
    /// Frames per second per stream; `None` sends as fast as the window allows.
    pub rate_hz: Option<f64>,
    /// How long to keep sending; the answers of frames in flight are awaited afterwards.
    pub duration: Duration,
    /// Settings of each stream (overflow policy, options, window).
    pub stream: StreamConfig,
}

impl Default for LoadTestConfig {
    fn default() -> Self {
        Self {
            streams: 1,
            rate_hz: None,
            duration: Duration::from_secs(10),
            stream: StreamConfig {
                max_in_flight: 4,
                ..StreamConfig::default()
            },
        }
    }
}

/// Latency percentiles, milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Percentiles {
    pub p50: f64,
    pub p95: f64,
    pub p99: f64,
    pub max: f64,
    pub mean: f64,
}

impl Percentiles {
    /// Nearest-rank percentiles of `samples` (any order).
    pub fn of(samples: &[f64]) -> Self {
        if samples.is_empty() {
            return Self::default();
        }
        let mut s = samples.to_vec();
        s.sort_by(f64::total_cmp);
        let at = |q: f64| s[((q * s.len() as f64).ceil() as usize).clamp(1, s.len()) - 1];
        Self {
            p50: at(0.50),
            p95: at(0.95),
            p99: at(0.99),
            max: s[s.len() - 1],
            mean: s.iter().sum::<f64>() / s.len() as f64,
        }
    }
}

/// The outcome of a load test.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct LoadTestReport {
    pub streams: usize,
    pub rate_hz_per_stream: Option<f64>,
    /// Wall time from the first send to the last answer, seconds.
    pub elapsed_s: f64,
    pub sent: u64,
    pub answered: u64,
    /// Answers per outcome label (`ok`, `skipped`, `resource_exhausted`, ...).
    pub outcomes: BTreeMap<String, u64>,
    /// Frames that got no answer.
    pub unanswered: u64,
    /// Answers that matched no frame in flight (duplicates or strangers).
    pub unexpected: u64,
    /// Processed frames per second over the whole run.
    pub throughput_fps: f64,
    /// Latency of processed frames, send to answer.
    pub latency_ms: Percentiles,
    /// Latency of every answer, whatever the outcome.
    pub all_latency_ms: Percentiles,
    /// Mean number of sites per processed frame.
    pub mean_sites: f64,
    /// Errors that ended a stream early.
    pub stream_errors: Vec<String>,
}

impl LoadTestReport {
    /// Every sent frame got exactly one answer.
    pub fn exactly_once(&self) -> bool {
        self.unanswered == 0 && self.unexpected == 0 && self.sent == self.answered
    }

    /// Answers that were not `ok` or `skipped`.
    pub fn failed(&self) -> u64 {
        self.outcomes
            .iter()
            .filter(|(k, _)| *k != "ok" && *k != "skipped")
            .map(|(_, v)| v)
            .sum()
    }
}

/// What one stream (or all of them) sent and got back.
#[derive(Default)]
struct StreamTally {
    sent: u64,
    answered: u64,
    outcomes: BTreeMap<String, u64>,
    unanswered: u64,
    unexpected: u64,
    ok_latency: Vec<f64>,
    all_latency: Vec<f64>,
    sites: u64,
    errors: Vec<String>,
}

impl StreamTally {
    /// Adds another stream's tally to this one.
    fn merge(&mut self, t: StreamTally) {
        self.sent += t.sent;
        self.answered += t.answered;
        for (k, v) in t.outcomes {
            *self.outcomes.entry(k).or_default() += v;
        }
        self.unanswered += t.unanswered;
        self.unexpected += t.unexpected;
        self.ok_latency.extend(t.ok_latency);
        self.all_latency.extend(t.all_latency);
        self.sites += t.sites;
        self.errors.extend(t.errors);
    }

    /// Counts one item of stream `stream_index`: an answer, or how the stream broke.
    fn record(&mut self, stream_index: usize, item: Result<StreamItem, ClientError>) {
        match item {
            Ok(item) => {
                self.answered += 1;
                let ms = item.latency.as_secs_f64() * 1e3;
                self.all_latency.push(ms);
                if let FrameOutcome::Result(r) = &item.outcome {
                    self.ok_latency.push(ms);
                    self.sites += r.sites.len() as u64;
                }
                *self.outcomes.entry(item.outcome.label()).or_default() += 1;
            }
            Err(ClientError::StreamBroken { unanswered, status }) => {
                self.unanswered += unanswered.len() as u64;
                self.errors.push(format!(
                    "stream {stream_index}: {} frame(s) unanswered{}",
                    unanswered.len(),
                    status.map(|s| format!(" ({s})")).unwrap_or_default()
                ));
            }
            Err(ClientError::Protocol(m)) => {
                self.unexpected += 1;
                self.errors.push(format!("stream {stream_index}: {m}"));
            }
            Err(e) => self.errors.push(format!("stream {stream_index}: {e}")),
        }
    }

    /// The report of the whole run, which took `elapsed_s`.
    fn report(self, config: &LoadTestConfig, elapsed_s: f64) -> LoadTestReport {
        let ok = self.outcomes.get("ok").copied().unwrap_or(0);
        LoadTestReport {
            streams: config.streams,
            rate_hz_per_stream: config.rate_hz,
            elapsed_s,
            sent: self.sent,
            answered: self.answered,
            outcomes: self.outcomes,
            unanswered: self.unanswered,
            unexpected: self.unexpected,
            throughput_fps: if elapsed_s > 0.0 {
                ok as f64 / elapsed_s
            } else {
                0.0
            },
            latency_ms: Percentiles::of(&self.ok_latency),
            all_latency_ms: Percentiles::of(&self.all_latency),
            mean_sites: if ok > 0 {
                self.sites as f64 / ok as f64
            } else {
                0.0
            },
            stream_errors: self.errors,
        }
    }
}

/// Runs the load test. `frames` are replayed in a loop by every stream with fresh sequence
/// numbers. `progress` is called about once a second with (answered so far, elapsed).
pub async fn run_load_test(
    client: &LandingClient,
    frames: Arc<Vec<Frame>>,
    config: &LoadTestConfig,
    progress: Option<&(dyn Fn(u64, Duration) + Sync)>,
) -> Result<LoadTestReport, ClientError> {
    check_input(&frames, config)?;
    let answered = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let started = Instant::now();
    let mut tasks = Vec::with_capacity(config.streams);
    for stream_index in 0..config.streams {
        let client = client.clone();
        let frames = frames.clone();
        let config = config.clone();
        let answered = answered.clone();
        tasks.push(tokio::spawn(async move {
            one_stream(client, frames, config, stream_index, answered, started).await
        }));
    }
    let mut all = StreamTally::default();
    let mut joined = std::pin::pin!(futures_join(tasks));
    loop {
        tokio::select! {
            done = &mut joined => {
                for t in done {
                    all.merge(t.map_err(|e| ClientError::Protocol(format!("load-test task failed: {e}")))?);
                }
                break;
            }
            _ = tokio::time::sleep(Duration::from_secs(1)) => {
                if let Some(p) = progress {
                    p(answered.load(std::sync::atomic::Ordering::Relaxed), started.elapsed());
                }
            }
        }
    }
    Ok(all.report(config, started.elapsed().as_secs_f64()))
}

/// Refuses a run without frames, without streams or with a rate that is not a positive number.
fn check_input(frames: &[Frame], config: &LoadTestConfig) -> Result<(), ClientError> {
    if frames.is_empty() {
        return Err(ClientError::InvalidInput {
            field: "frames",
            reason: "no frames to send".into(),
        });
    }
    if config.streams == 0 {
        return Err(ClientError::InvalidInput {
            field: "streams",
            reason: "must be at least 1".into(),
        });
    }
    if let Some(r) = config.rate_hz
        && !(r.is_finite() && r > 0.0)
    {
        return Err(ClientError::InvalidInput {
            field: "rate",
            reason: format!("{r} is not a positive rate"),
        });
    }
    Ok(())
}

/// Awaits every task, in order.
async fn futures_join<T>(
    tasks: Vec<tokio::task::JoinHandle<T>>,
) -> Vec<Result<T, tokio::task::JoinError>> {
    let mut out = Vec::with_capacity(tasks.len());
    for t in tasks {
        out.push(t.await);
    }
    out
}

/// One stream of the load test: sends on its own task while this one counts the answers.
async fn one_stream(
    client: LandingClient,
    frames: Arc<Vec<Frame>>,
    config: LoadTestConfig,
    stream_index: usize,
    answered: Arc<std::sync::atomic::AtomicU64>,
    started: Instant,
) -> StreamTally {
    let (sender, mut results) = client.open_stream(config.stream.clone());
    let drone = format!("loadtest-{stream_index}");
    let send_task = tokio::spawn(send_frames(
        sender,
        frames,
        drone,
        config.rate_hz,
        started,
        config.duration,
    ));
    let mut tally = StreamTally::default();
    while let Some(item) = results.next().await {
        if item.is_ok() {
            answered.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
        tally.record(stream_index, item);
    }
    match send_task.await {
        Ok((sent, error)) => {
            tally.sent = sent;
            if let Some(e) = error {
                tally
                    .errors
                    .push(format!("stream {stream_index}: send failed: {e}"));
            }
        }
        Err(e) => tally
            .errors
            .push(format!("stream {stream_index}: sender task failed: {e}")),
    }
    tally
}

/// Replays `frames` in a loop as drone `drone`, with fresh sequence numbers, at `rate` frames
/// per second (as fast as the window allows when `None`) until `duration` after `started`; then
/// finishes the stream. Returns the frames sent and the error that stopped sending, if any.
async fn send_frames(
    mut sender: FrameSender,
    frames: Arc<Vec<Frame>>,
    drone: String,
    rate: Option<f64>,
    started: Instant,
    duration: Duration,
) -> (u64, Option<String>) {
    let mut sent = 0u64;
    let mut ticker = rate.map(|r| {
        let mut i = tokio::time::interval(Duration::from_secs_f64(1.0 / r));
        i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        i
    });
    let mut error = None;
    while started.elapsed() < duration {
        if let Some(t) = ticker.as_mut() {
            t.tick().await;
            if started.elapsed() >= duration {
                break;
            }
        }
        let mut frame = frames[(sent % frames.len() as u64) as usize].clone();
        frame.sequence = sent;
        frame.drone_id = drone.clone();
        // A full window blocks here until answers come back: the back-pressure under test.
        let send = tokio::time::timeout(
            duration.saturating_sub(started.elapsed()) + Duration::from_millis(1),
            sender.send(frame),
        );
        match send.await {
            Ok(Ok(())) => sent += 1,
            Ok(Err(e)) => {
                error = Some(e.to_string());
                break;
            }
            Err(_) => break,
        }
    }
    sender.finish();
    (sent, error)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_rank_percentiles() {
        let s: Vec<f64> = (1..=100).map(f64::from).collect();
        let p = Percentiles::of(&s);
        assert_eq!((p.p50, p.p95, p.p99, p.max), (50.0, 95.0, 99.0, 100.0));
        assert!((p.mean - 50.5).abs() < 1e-12);
        assert_eq!(Percentiles::of(&[]), Percentiles::default());
        assert_eq!(Percentiles::of(&[3.0]).p99, 3.0);
    }

    #[test]
    fn exactly_once_needs_every_frame_answered() {
        let mut r = LoadTestReport {
            sent: 3,
            answered: 3,
            ..Default::default()
        };
        assert!(r.exactly_once());
        r.unanswered = 1;
        assert!(!r.exactly_once());
        r.outcomes.insert("ok".into(), 2);
        r.outcomes.insert("resource_exhausted".into(), 1);
        r.outcomes.insert("skipped".into(), 4);
        assert_eq!(r.failed(), 1);
    }
}
