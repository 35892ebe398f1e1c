//! The `landing` subcommands and their output (tables or JSON); [`run`] parses and runs one.
//!
//! Exit codes (also in `landing --help`):
//!
//! | code | meaning |
//! |---|---|
//! | 0 | success |
//! | 1 | error (bad input file, protocol error, ...) |
//! | 2 | usage error (bad flags) |
//! | 3 | server unreachable (connection refused, TLS handshake failed, deadline) |
//! | 4 | some frames failed (the server answered them with an error) |
//! | 5 | load test integrity failure: a sent frame got no answer or more than one |
//! | 6 | authentication refused (`UNAUTHENTICATED`/`PERMISSION_DENIED`) |

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use clap::{Args, Parser, Subcommand, ValueEnum};
use landing_proto::json::mode_name;
use landing_proto::v1::{
    Frame, FrameResult, LandingSite, OverflowPolicy, PipelineOptions, SegmentationMode,
    ServiceInfo, StreamLandingSitesResponse, stream_landing_sites_response,
};
use serde_json::{Value, json};

use landing_client::{
    ClientError, FrameBuilder, FrameOutcome, LandingClient, PointCloudBuilder, StreamConfig,
    StreamItem, code_label, duration_from_proto,
};
use landing_recording::RecordedFrame;

pub use crate::args::{CliError, ConnectionArgs, exit};
use crate::args::{connect, io, usage};
use crate::loadtest::{LoadTestConfig, LoadTestReport, run_load_test};
use crate::render::{RenderConfig, render};

const AFTER_HELP: &str = "Exit codes: 0 ok, 1 error, 2 usage, 3 server unreachable, 4 frames failed, \
5 load-test integrity failure (a frame unanswered or answered twice), 6 authentication refused.";

/// Client of the rooftop landing-site service.
#[derive(Debug, Parser)]
#[command(name = "landing", version, about, after_help = AFTER_HELP)]
pub struct Cli {
    /// Print machine-readable JSON instead of tables.
    #[arg(long, global = true)]
    pub json: bool,
    // Last among the flags: its `next_help_heading` ("Connection") holds for what follows.
    #[command(flatten)]
    pub connection: ConnectionArgs,
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Server version, model, classes and default parameters.
    Info,
    /// Detect landing sites in one recorded frame or a PLY point cloud.
    Detect(DetectArgs),
    /// Stream a recording through the server and print each frame's ranked sites.
    Replay(ReplayArgs),
    /// Run concurrent streams for a fixed time and report throughput and latency.
    Loadtest(LoadtestArgs),
    /// Draw a frame's landing sites over its camera image and from above, as PNG.
    Render(RenderArgs),
    /// Score landing sites against simulator ground truth in three segmentation modes (exit 7
    /// when a gated mode returned an unsafe site).
    Eval(crate::eval::EvalArgs),
    /// Landing sites the fleet's catalog knows near a place: candidates for a drone to confirm
    /// with its own stream, never a clearance to land.
    Sites(crate::catalog::SitesArgs),
    /// The fleet's landing-site catalog: import candidate roofs.
    #[command(subcommand)]
    Catalog(crate::catalog::CatalogCommand),
}

/// Pipeline options shared by the subcommands that send frames.
#[derive(Debug, Clone, Args)]
pub struct PipelineArgs {
    /// Where point classes come from.
    #[arg(long, value_parser = crate::args::segmentation_parser(), default_value = "auto")]
    pub segmentation: SegmentationMode,
    /// The paper's l_max: longest triangle edge, metres.
    #[arg(long)]
    pub max_triangle_edge: Option<f64>,
    /// The paper's dot_min: minimum |n·z| of a triangle normal.
    #[arg(long)]
    pub min_normal_dot: Option<f64>,
    /// The paper's z_min: triangles flatter than this bypass the normal test, metres.
    #[arg(long)]
    pub max_triangle_height: Option<f64>,
    /// Polylabel precision, metres.
    #[arg(long)]
    pub polylabel_precision: Option<f64>,
    /// Smallest safe radius to report, metres.
    #[arg(long)]
    pub min_safe_radius: Option<f64>,
    /// At most this many sites per frame.
    #[arg(long)]
    pub max_sites: Option<u32>,
}

impl PipelineArgs {
    fn options(&self) -> PipelineOptions {
        PipelineOptions {
            max_triangle_edge_m: self.max_triangle_edge,
            min_normal_dot: self.min_normal_dot,
            max_triangle_height_m: self.max_triangle_height,
            polylabel_precision_m: self.polylabel_precision,
            min_safe_radius_m: self.min_safe_radius,
            max_sites: self.max_sites,
            segmentation_mode: self.segmentation as i32,
            ..Default::default()
        }
    }
}

/// `landing detect`.
#[derive(Debug, Clone, Args)]
pub struct DetectArgs {
    /// An MCAP recording (`.mcap`) or a PLY point cloud in world coordinates (`.ply`).
    pub input: PathBuf,
    /// Which frame of the recording (0-based).
    #[arg(long, default_value_t = 0)]
    pub frame: usize,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
}

/// `landing replay`.
#[derive(Debug, Clone, Args)]
pub struct ReplayArgs {
    /// The recording.
    pub recording: PathBuf,
    /// Write the answers as MCAP (`landing.v1.StreamLandingSitesResponse` on `/landing/results`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the answers as JSON lines.
    #[arg(long)]
    pub jsonl: Option<PathBuf>,
    /// Send at this many frames per second; default: as fast as the server answers.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Replay only the first N frames.
    #[arg(long)]
    pub limit: Option<usize>,
    /// What the server does when frames arrive faster than it works.
    #[arg(long, value_enum, default_value_t = Overflow::Block)]
    pub overflow: Overflow,
    /// Frames in flight at once.
    #[arg(long, default_value_t = 4)]
    pub window: usize,
    /// Judge every frame alone (the paper's single-frame method) instead of fusing the
    /// stream's frames into a map (the default, with the server's `[fusion]` defaults).
    #[arg(long)]
    pub single_frame: bool,
    /// The WGS-84 position of the recording's world origin, `LAT,LON[,ALT]` (degrees, metres
    /// above the ellipsoid), for frames that carry none: sites get latitude and longitude, and a
    /// fused replay feeds the server's landing-site catalog.
    #[arg(long, value_name = "LAT,LON[,ALT]")]
    pub origin: Option<String>,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
}

/// `--origin LAT,LON[,ALT]`.
fn geodetic_origin(text: &str) -> Result<landing_proto::v1::GeodeticPoint, CliError> {
    let numbers: Option<Vec<f64>> = text.split(',').map(|v| v.trim().parse().ok()).collect();
    match numbers.as_deref() {
        Some(&[latitude_deg, longitude_deg]) | Some(&[latitude_deg, longitude_deg, _]) => {
            Ok(landing_proto::v1::GeodeticPoint {
                latitude_deg,
                longitude_deg,
                altitude_m: numbers
                    .as_ref()
                    .and_then(|n| n.get(2).copied())
                    .unwrap_or(0.0),
            })
        }
        _ => Err(usage(format!(
            "--origin {text:?}: expected LAT,LON or LAT,LON,ALT"
        ))),
    }
}

/// `--overflow` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Overflow {
    /// Back-pressure: the server reads no faster than it works.
    Block,
    /// Keep only the newest queued frame; older ones are skipped.
    Latest,
}

/// The stream the flags ask for: fused (with the server's `[fusion]` defaults) unless
/// `--single-frame`.
fn stream_config(
    single_frame: bool,
    overflow: Overflow,
    window: usize,
    options: PipelineOptions,
) -> StreamConfig {
    let stream = if single_frame {
        StreamConfig::single_frame()
    } else {
        StreamConfig::fused()
    };
    StreamConfig {
        max_in_flight: window.max(1),
        ..stream
            .with_overflow_policy(overflow.policy())
            .with_options(options)
    }
}

impl Overflow {
    fn policy(self) -> OverflowPolicy {
        match self {
            Self::Block => OverflowPolicy::Block,
            Self::Latest => OverflowPolicy::Latest,
        }
    }
}

/// `landing loadtest`.
#[derive(Debug, Clone, Args)]
pub struct LoadtestArgs {
    /// Recordings whose frames are replayed in a loop.
    #[arg(required = true)]
    pub recordings: Vec<PathBuf>,
    /// Concurrent streams.
    #[arg(long, default_value_t = 1)]
    pub streams: usize,
    /// Frames per second per stream; default: as fast as possible.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Seconds of sending.
    #[arg(long, default_value_t = 10.0)]
    pub duration: f64,
    /// Frames in flight per stream.
    #[arg(long, default_value_t = 2)]
    pub window: usize,
    /// What the server does when frames arrive faster than it works.
    #[arg(long, value_enum, default_value_t = Overflow::Block)]
    pub overflow: Overflow,
    /// Judge every frame alone (the paper's single-frame method) instead of fusing the
    /// stream's frames into a map (the default, with the server's `[fusion]` defaults).
    #[arg(long)]
    pub single_frame: bool,
    /// The WGS-84 position of the recordings' world origin, `LAT,LON[,ALT]`, for frames that
    /// carry none: fused streams then feed the server's landing-site catalog (its write path
    /// under load).
    #[arg(long, value_name = "LAT,LON[,ALT]")]
    pub origin: Option<String>,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
}

/// `landing render`.
#[derive(Debug, Clone, Args)]
pub struct RenderArgs {
    /// The recording.
    pub recording: PathBuf,
    /// Which frame (0-based).
    #[arg(long, default_value_t = 0)]
    pub frame: usize,
    /// Output PNG.
    #[arg(long, default_value = "landing.png")]
    pub out: PathBuf,
    /// Draw this many best sites.
    #[arg(long, default_value_t = 3)]
    pub sites: usize,
    #[command(flatten)]
    pub pipeline: PipelineArgs,
}

/// Runs `landing` with `args` (the first is the program name), writing results to `out` and
/// diagnostics to stderr. Returns the exit code.
pub async fn run<I, T>(args: I, out: &mut (dyn Write + Send)) -> u8
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            use clap::error::ErrorKind;
            return match e.kind() {
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                    let _ = write!(out, "{e}");
                    exit::OK
                }
                _ => {
                    eprint!("{e}");
                    exit::USAGE
                }
            };
        }
    };
    match execute(&cli, out).await {
        Ok(code) => code,
        Err(e) => {
            eprintln!("landing: {}", e.message);
            e.code
        }
    }
}

/// Runs a parsed command line; `Ok` carries the exit code of a run that completed.
pub async fn execute(cli: &Cli, out: &mut (dyn Write + Send)) -> Result<u8, CliError> {
    match &cli.command {
        Command::Info => {
            let client = connect(&cli.connection).await?;
            let info = client.info().await?;
            print_info(&info, cli.json, out)?;
            Ok(exit::OK)
        }
        Command::Detect(a) => detect(cli, a, out).await,
        Command::Replay(a) => replay(cli, a, out).await,
        Command::Loadtest(a) => loadtest(cli, a, out).await,
        Command::Render(a) => render_cmd(cli, a, out).await,
        Command::Eval(a) => crate::eval::eval_cmd(&cli.connection, a, cli.json, out).await,
        Command::Sites(a) => crate::catalog::sites(&cli.connection, a, cli.json, out).await,
        Command::Catalog(crate::catalog::CatalogCommand::Import(a)) => {
            crate::catalog::import(a, out).await
        }
    }
}

/// The frames of a recording as the flags send them: with `--segmentation class-image`, each
/// frame carries its recorded label image as its class image.
fn recorded_frames(path: &Path, pipeline: &PipelineArgs) -> Result<Vec<RecordedFrame>, CliError> {
    let mut frames = landing_recording::read(path).map_err(|e| CliError {
        code: exit::ERROR,
        message: format!("recording `{}`: {e}", path.display()),
    })?;
    if pipeline.segmentation == SegmentationMode::ClassImage {
        for f in &mut frames {
            let labels = f.labels.take().ok_or_else(|| {
                usage(format!(
                    "--segmentation class-image: frame {} of {} has no label image on `{}`",
                    f.frame.sequence,
                    path.display(),
                    landing_recording::LABELS_TOPIC
                ))
            })?;
            f.frame.class_image = Some(labels);
        }
    }
    Ok(frames)
}

fn load_frame(path: &Path, index: usize, pipeline: &PipelineArgs) -> Result<Frame, CliError> {
    let is_ply = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if is_ply {
        if pipeline.segmentation == SegmentationMode::ClassImage {
            return Err(usage(format!(
                "--segmentation class-image sends a recording's label images; {} is a PLY scan \
                 without one",
                path.display()
            )));
        }
        let ply = landing_recording::ply::read(path).map_err(|e| CliError {
            code: exit::ERROR,
            message: match e {
                landing_recording::ply::PlyError::Io { .. } => e.to_string(),
                other => format!("`{}`: {other}", path.display()),
            },
        })?;
        let mut builder = PointCloudBuilder::new(&ply.points).frame_id("world");
        if let Some(c) = &ply.classes {
            builder = builder.classes(c);
        }
        return Ok(FrameBuilder::new(0, builder.build()?)
            .drone_id("landing-cli")
            .build());
    }
    let frames = recorded_frames(path, pipeline)?;
    let n = frames.len();
    frames
        .into_iter()
        .nth(index)
        .map(|f| f.frame)
        .ok_or_else(|| {
            usage(format!(
                "--frame {index} is out of range: the recording has {n} frames"
            ))
        })
}

async fn detect(cli: &Cli, a: &DetectArgs, out: &mut (dyn Write + Send)) -> Result<u8, CliError> {
    let frame = load_frame(&a.input, a.frame, &a.pipeline)?;
    let client = connect(&cli.connection).await?;
    let result = client
        .detect_with(frame, Some(a.pipeline.options()))
        .await?;
    if cli.json {
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&result_json(&result)).unwrap_or_default()
        )
        .map_err(io)?;
    } else {
        print_result(&result, out).map_err(io)?;
    }
    Ok(exit::OK)
}

async fn replay(cli: &Cli, a: &ReplayArgs, out: &mut (dyn Write + Send)) -> Result<u8, CliError> {
    if let Some(r) = a.rate
        && !(r > 0.0 && r.is_finite())
    {
        return Err(usage(format!("--rate {r} must be positive")));
    }
    let mut frames = recorded_frames(&a.recording, &a.pipeline)?;
    if let Some(l) = a.limit {
        frames.truncate(l);
    }
    if let Some(text) = &a.origin {
        let origin = geodetic_origin(text)?;
        for f in &mut frames {
            f.frame.geodetic_origin.get_or_insert(origin);
        }
    }
    let client = connect(&cli.connection).await?;
    let mut mcap = a
        .out
        .as_deref()
        .map(|p| {
            landing_recording::Writer::create(p, concat!("landing ", env!("CARGO_PKG_VERSION")))
        })
        .transpose()?;
    let mut jsonl = match &a.jsonl {
        Some(p) => Some(std::io::BufWriter::new(std::fs::File::create(p).map_err(
            |e| CliError {
                code: exit::ERROR,
                message: format!("cannot create `{}`: {e}", p.display()),
            },
        )?)),
        None => None,
    };
    let config = stream_config(a.single_frame, a.overflow, a.window, a.pipeline.options());
    let summary = replay_frames(&client, &frames, config, a.rate, |rec, item| {
        if cli.json {
            writeln!(out, "{}", item_json(item))?;
        } else {
            print_item_row(item, out)?;
        }
        if let Some(w) = jsonl.as_mut() {
            writeln!(w, "{}", item_json(item))?;
        }
        if let Some(w) = mcap.as_mut() {
            write_replayed(w, rec, &response_of(item)).map_err(std::io::Error::other)?;
        }
        Ok(())
    })
    .await?;
    if let Some(w) = mcap {
        w.finish()?;
    }
    if let Some(mut w) = jsonl {
        w.flush().map_err(io)?;
    }
    let failed = summary.failed;
    if !cli.json {
        writeln!(
            out,
            "{} frames: {} ok, {} failed, {} skipped in {:.2} s",
            summary.answered, summary.ok, summary.failed, summary.skipped, summary.elapsed_s
        )
        .map_err(io)?;
    }
    Ok(if failed > 0 {
        exit::FRAMES_FAILED
    } else {
        exit::OK
    })
}

/// A replayed frame in the output recording: its inputs as recorded (so that the output replays
/// and opens in Foxglove on its own) and the answer with its drawings, at the frame's log time.
fn write_replayed<W: std::io::Write + std::io::Seek>(
    w: &mut landing_recording::Writer<W>,
    rec: &RecordedFrame,
    response: &StreamLandingSitesResponse,
) -> Result<(), landing_recording::Error> {
    let t = rec.log_time_ns;
    w.write_frame(t, &rec.frame)?;
    if let Some(truth) = &rec.truth {
        w.write_truth(t, truth)?;
    }
    if let Some(labels) = &rec.labels {
        w.write_labels(t, rec.frame.sequence, labels)?;
    }
    w.write_result(t, response, rec.frame.image.as_ref())
}

/// Counts of a replay.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReplaySummary {
    pub answered: usize,
    pub ok: usize,
    pub failed: usize,
    pub skipped: usize,
    pub elapsed_s: f64,
}

/// Streams `frames` in order and calls `each` with every answer and the frame it answers.
pub async fn replay_frames<F>(
    client: &LandingClient,
    frames: &[RecordedFrame],
    config: StreamConfig,
    rate: Option<f64>,
    mut each: F,
) -> Result<ReplaySummary, CliError>
where
    F: FnMut(&RecordedFrame, &StreamItem) -> std::io::Result<()>,
{
    let started = Instant::now();
    let (mut sender, mut results) = client.open_stream(config);
    let to_send: Vec<Frame> = frames.iter().map(|f| f.frame.clone()).collect();
    let send = tokio::spawn(async move {
        let mut ticker = rate.map(|r| tokio::time::interval(Duration::from_secs_f64(1.0 / r)));
        for f in to_send {
            if let Some(t) = ticker.as_mut() {
                t.tick().await;
            }
            sender.send(f).await?;
        }
        Ok::<(), ClientError>(())
    });
    let by_seq: std::collections::HashMap<u64, &RecordedFrame> =
        frames.iter().map(|f| (f.frame.sequence, f)).collect();
    let progress = std::io::stderr().is_terminal();
    let mut s = ReplaySummary::default();
    while let Some(item) = results.next().await {
        let item = item?;
        s.answered += 1;
        match &item.outcome {
            FrameOutcome::Result(_) => s.ok += 1,
            FrameOutcome::Error(_) => s.failed += 1,
            FrameOutcome::Skipped { .. } => s.skipped += 1,
        }
        let rec = by_seq.get(&item.sequence).copied().unwrap_or(&frames[0]);
        each(rec, &item).map_err(io)?;
        if progress {
            eprint!("\rreplay: {}/{} frames", s.answered, frames.len());
        }
    }
    if progress {
        eprintln!();
    }
    match send.await {
        Ok(Ok(())) => {}
        Ok(Err(e)) => return Err(e.into()),
        Err(e) => {
            return Err(CliError {
                code: exit::ERROR,
                message: format!("sender failed: {e}"),
            });
        }
    }
    s.elapsed_s = started.elapsed().as_secs_f64();
    Ok(s)
}

async fn loadtest(
    cli: &Cli,
    a: &LoadtestArgs,
    out: &mut (dyn Write + Send),
) -> Result<u8, CliError> {
    if !(a.duration > 0.0 && a.duration.is_finite()) {
        return Err(usage(format!("--duration {} must be positive", a.duration)));
    }
    if a.streams == 0 {
        return Err(usage("--streams must be at least 1"));
    }
    if let Some(r) = a.rate
        && !(r > 0.0 && r.is_finite())
    {
        return Err(usage(format!("--rate {r} must be positive")));
    }
    let origin = a.origin.as_deref().map(geodetic_origin).transpose()?;
    let mut frames = Vec::new();
    for r in &a.recordings {
        frames.extend(recorded_frames(r, &a.pipeline)?.into_iter().map(|mut f| {
            if let Some(origin) = origin {
                f.frame.geodetic_origin.get_or_insert(origin);
            }
            f.frame
        }));
    }
    let client = connect(&cli.connection).await?;
    let config = LoadTestConfig {
        streams: a.streams,
        rate_hz: a.rate,
        duration: Duration::from_secs_f64(a.duration),
        stream: stream_config(a.single_frame, a.overflow, a.window, a.pipeline.options()),
    };
    let show = std::io::stderr().is_terminal();
    let progress = move |answered: u64, elapsed: Duration| {
        if show {
            eprint!(
                "\rloadtest: {answered} answers in {:.0} s",
                elapsed.as_secs_f64()
            );
        }
    };
    let report = run_load_test(&client, Arc::new(frames), &config, Some(&progress)).await?;
    if show {
        eprintln!();
    }
    if cli.json {
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&report).unwrap_or_default()
        )
        .map_err(io)?;
    } else {
        print_load_report(&report, out).map_err(io)?;
    }
    Ok(if !report.exactly_once() {
        exit::INTEGRITY
    } else if report.failed() > 0 {
        exit::FRAMES_FAILED
    } else {
        exit::OK
    })
}

async fn render_cmd(
    cli: &Cli,
    a: &RenderArgs,
    out: &mut (dyn Write + Send),
) -> Result<u8, CliError> {
    let frame = load_frame(&a.recording, a.frame, &a.pipeline)?;
    let client = connect(&cli.connection).await?;
    let result = client
        .detect_with(frame.clone(), Some(a.pipeline.options()))
        .await?;
    let rendered = render(
        &frame,
        &result,
        &RenderConfig {
            max_sites: a.sites,
            ..RenderConfig::default()
        },
    )?;
    rendered.image.save(&a.out).map_err(|e| CliError {
        code: exit::ERROR,
        message: format!("cannot write `{}`: {e}", a.out.display()),
    })?;
    if cli.json {
        let v = json!({ "out": a.out.display().to_string(), "width": rendered.image.width(),
            "height": rendered.image.height(), "result": result_json(&result) });
        writeln!(out, "{v}").map_err(io)?;
    } else {
        writeln!(
            out,
            "wrote {} ({}x{}, {} site(s) drawn)",
            a.out.display(),
            rendered.image.width(),
            rendered.image.height(),
            result.sites.len().min(a.sites)
        )
        .map_err(io)?;
    }
    Ok(exit::OK)
}

// ---------------------------------------------------------------------------------------------
// Output
// ---------------------------------------------------------------------------------------------

fn print_info(
    info: &ServiceInfo,
    as_json: bool,
    out: &mut (dyn Write + Send),
) -> Result<(), CliError> {
    if as_json {
        writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&info_json(info)).unwrap_or_default()
        )
        .map_err(io)?;
        return Ok(());
    }
    let mut s = String::new();
    use std::fmt::Write as _;
    let _ = writeln!(s, "version            {}", info.version);
    match &info.model {
        Some(m) => {
            let _ = writeln!(
                s,
                "model              {} ({}x{}, {})",
                m.name, m.input_width, m.input_height, m.execution_provider
            );
            let _ = writeln!(s, "model sha256       {}", m.sha256);
        }
        None => {
            let _ = writeln!(s, "model              none (geometry only)");
        }
    }
    let _ = writeln!(s, "max request        {} bytes", info.max_request_bytes);
    if let Some(o) = &info.default_options {
        let _ = writeln!(s, "defaults");
        for (k, v) in options_pairs(o) {
            let _ = writeln!(s, "  {k:<24} {v}");
        }
    }
    let _ = writeln!(s, "classes");
    for c in &info.classes {
        let _ = writeln!(s, "  {:>3}  {}", c.class, c.name);
    }
    out.write_all(s.as_bytes()).map_err(io)
}

fn options_pairs(o: &PipelineOptions) -> Vec<(&'static str, String)> {
    let f = |v: Option<f64>| v.map_or("-".to_owned(), |v| format!("{v}"));
    vec![
        ("max_triangle_edge_m", f(o.max_triangle_edge_m)),
        ("min_normal_dot", f(o.min_normal_dot)),
        ("max_triangle_height_m", f(o.max_triangle_height_m)),
        ("polylabel_precision_m", f(o.polylabel_precision_m)),
        (
            "min_region_triangles",
            o.min_region_triangles.map_or("-".into(), |v| v.to_string()),
        ),
        ("min_safe_radius_m", f(o.min_safe_radius_m)),
        ("min_area_m2", f(o.min_area_m2)),
        ("min_hole_area_m2", f(o.min_hole_area_m2)),
        (
            "max_sites",
            o.max_sites.map_or("-".into(), |v| v.to_string()),
        ),
        ("landable_classes", format!("{:?}", o.landable_classes)),
        ("segmentation_mode", mode_name(o.segmentation_mode)),
    ]
}

fn info_json(info: &ServiceInfo) -> Value {
    json!({
        "version": info.version,
        "model": info.model.as_ref().map(|m| json!({
            "name": m.name, "sha256": m.sha256, "input_width": m.input_width,
            "input_height": m.input_height, "execution_provider": m.execution_provider,
        })),
        "classes": info.classes.iter().map(|c| json!({"class": c.class, "name": c.name})).collect::<Vec<_>>(),
        "default_options": info.default_options.as_ref().map(|o| {
            options_pairs(o).into_iter().map(|(k, v)| (k.to_owned(), Value::String(v))).collect::<serde_json::Map<_, _>>()
        }),
        "max_request_bytes": info.max_request_bytes,
    })
}

fn print_result(r: &FrameResult, out: &mut (dyn Write + Send)) -> std::io::Result<()> {
    let total = r
        .timings
        .and_then(|t| t.total)
        .and_then(duration_from_proto);
    writeln!(
        out,
        "frame {} ({}): {} points, {} triangles, segmentation {}, {} site(s){}",
        r.sequence,
        if r.drone_id.is_empty() {
            "-"
        } else {
            &r.drone_id
        },
        r.point_count,
        r.triangle_count,
        mode_name(r.segmentation_mode),
        r.sites.len(),
        total
            .map(|t| format!(", {:.1} ms", t.as_secs_f64() * 1e3))
            .unwrap_or_default()
    )?;
    if r.sites.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "{:>4}  {:>9}  {:>9}  {:>28}  {:>6}  {:>6}",
        "rank", "radius_m", "area_m2", "centre (x, y, z)", "holes", "points"
    )?;
    for s in &r.sites {
        writeln!(out, "{}", site_row(s))?;
    }
    Ok(())
}

fn site_row(s: &LandingSite) -> String {
    let [x, y, z] = s.center_xyz().unwrap_or_default();
    format!(
        "{:>4}  {:>9.2}  {:>9.1}  {:>28}  {:>6}  {:>6}",
        s.rank,
        s.safe_radius_m,
        s.area_m2,
        format!("({x:.2}, {y:.2}, {z:.2})"),
        s.holes().len(),
        s.point_count
    )
}

fn print_item_row(item: &StreamItem, out: &mut (dyn Write + Send)) -> std::io::Result<()> {
    let ms = item.latency.as_secs_f64() * 1e3;
    match &item.outcome {
        FrameOutcome::Result(r) => {
            let fused = r.fusion.as_ref().map_or(String::new(), |f| {
                let reset = if f.reset_reason.is_empty() {
                    String::new()
                } else {
                    format!(", map reset: {}", f.reset_reason)
                };
                format!("  fused {} frame(s), {} points{reset}", f.frames, f.points)
            });
            writeln!(
                out,
                "frame {:>5}  ok       {:>2} site(s)  {:>7.1} ms{fused}",
                item.sequence,
                r.sites.len(),
                ms
            )?;
            for s in &r.sites {
                writeln!(out, "      {}", site_row(s))?;
            }
            Ok(())
        }
        FrameOutcome::Error(e) => writeln!(out, "frame {:>5}  error    {e}", item.sequence),
        FrameOutcome::Skipped { superseded_by } => {
            writeln!(
                out,
                "frame {:>5}  skipped  (superseded by {superseded_by})",
                item.sequence
            )
        }
    }
}

fn print_load_report(r: &LoadTestReport, out: &mut (dyn Write + Send)) -> std::io::Result<()> {
    writeln!(out, "streams            {}", r.streams)?;
    writeln!(
        out,
        "rate per stream    {}",
        r.rate_hz_per_stream
            .map_or("max".into(), |v| format!("{v} Hz"))
    )?;
    writeln!(out, "elapsed            {:.2} s", r.elapsed_s)?;
    writeln!(out, "sent / answered    {} / {}", r.sent, r.answered)?;
    writeln!(out, "throughput         {:.2} frames/s", r.throughput_fps)?;
    let p = r.latency_ms;
    writeln!(
        out,
        "latency (ok)       p50 {:.1} ms  p95 {:.1} ms  p99 {:.1} ms  max {:.1} ms",
        p.p50, p.p95, p.p99, p.max
    )?;
    writeln!(out, "mean sites/frame   {:.2}", r.mean_sites)?;
    let outcomes: Vec<String> = r.outcomes.iter().map(|(k, v)| format!("{k} {v}")).collect();
    writeln!(out, "outcomes           {}", outcomes.join(", "))?;
    writeln!(
        out,
        "exactly once       {} (unanswered {}, unexpected {})",
        if r.exactly_once() { "yes" } else { "NO" },
        r.unanswered,
        r.unexpected
    )?;
    for e in &r.stream_errors {
        writeln!(out, "stream error       {e}")?;
    }
    Ok(())
}

/// The JSON form of a frame result (used by `--json` and JSON lines): the one schema, which
/// `landing-server detect --json` prints too.
pub use landing_proto::json::frame_result as result_json;

/// The JSON line of one stream answer.
pub fn item_json(item: &StreamItem) -> Value {
    let mut v = json!({ "sequence": item.sequence, "outcome": item.outcome.label(), "latency_ms": item.latency.as_secs_f64() * 1e3 });
    match &item.outcome {
        FrameOutcome::Result(r) => v["result"] = result_json(r),
        FrameOutcome::Error(e) => {
            v["error"] = json!({
                "code": code_label(e.code), "message": e.message,
                "field_violations": e.field_violations.iter().map(|f| json!({"field": f.field, "description": f.description})).collect::<Vec<_>>(),
                "retry_delay_ms": e.retry_delay.map(|d| d.as_secs_f64() * 1e3),
            })
        }
        FrameOutcome::Skipped { superseded_by } => v["superseded_by"] = json!(superseded_by),
    }
    v
}

/// The wire form of one answer, for MCAP output.
fn response_of(item: &StreamItem) -> StreamLandingSitesResponse {
    use stream_landing_sites_response::Outcome;
    let outcome = match &item.outcome {
        FrameOutcome::Result(r) => Outcome::Result(r.clone()),
        FrameOutcome::Skipped { superseded_by } => {
            Outcome::Skipped(landing_proto::v1::FrameSkipped {
                superseded_by_sequence: *superseded_by,
            })
        }
        FrameOutcome::Error(e) => Outcome::Error(landing_proto::google::rpc::Status {
            code: e.code as i32,
            message: e.message.clone(),
            details: Vec::new(),
        }),
    };
    StreamLandingSitesResponse {
        sequence: item.sequence,
        outcome: Some(outcome),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use landing_client::StreamMode;

    #[test]
    fn help_lists_the_connection_flags_under_their_own_heading() {
        use clap::CommandFactory;
        let help = Cli::command().render_long_help().to_string();
        let (options, connection) = help.split_once("\nConnection:\n").expect("a heading");
        assert!(options.contains("--json"), "{help}");
        for flag in [
            "--server",
            "--token",
            "--ca-cert",
            "--tls-domain",
            "--timeout",
        ] {
            assert!(
                connection.contains(flag),
                "{flag} not under Connection: {help}"
            );
            assert!(!options.contains(flag), "{flag} outside Connection: {help}");
        }
    }

    #[test]
    fn segmentation_names_are_the_api_modes() {
        let parse = |name: &str| {
            Cli::try_parse_from(["landing", "detect", "x.ply", "--segmentation", name]).map(|cli| {
                match cli.command {
                    Command::Detect(a) => a.pipeline.segmentation,
                    other => panic!("{other:?}"),
                }
            })
        };
        for mode in SegmentationMode::all() {
            assert_eq!(parse(mode.cli_name()).unwrap(), mode);
        }
        assert_eq!(parse("auto").unwrap(), SegmentationMode::Unspecified);
        assert!(parse("unspecified").is_err());
        let fused = stream_config(false, Overflow::Latest, 0, PipelineOptions::default());
        assert!(matches!(fused.mode, StreamMode::Fused(_)));
        assert_eq!(fused.max_in_flight, 1);
        assert_eq!(
            stream_config(true, Overflow::Block, 4, PipelineOptions::default()).mode,
            StreamMode::SingleFrame
        );
    }

    async fn run_capture(args: &[&str]) -> (u8, String) {
        let mut out = Vec::new();
        let code = run(args.iter().copied(), &mut out).await;
        (code, String::from_utf8(out).unwrap())
    }

    #[tokio::test]
    async fn help_documents_exit_codes() {
        let (code, out) = run_capture(&["landing", "--help"]).await;
        assert_eq!(code, exit::OK);
        assert!(out.contains("3 server unreachable"), "{out}");
        for sub in ["info", "detect", "replay", "loadtest", "render"] {
            assert!(out.contains(sub), "{sub} missing from help");
        }
    }

    #[tokio::test]
    async fn bad_flags_are_usage_errors() {
        assert_eq!(run_capture(&["landing", "frobnicate"]).await.0, exit::USAGE);
        assert_eq!(run_capture(&["landing", "loadtest"]).await.0, exit::USAGE);
        assert_eq!(
            run_capture(&["landing", "info", "--client-cert", "/x.pem"])
                .await
                .0,
            exit::USAGE,
            "a client cert without its key"
        );
        assert_eq!(
            run_capture(&["landing", "info", "--server", "ftp://x"])
                .await
                .0,
            exit::USAGE
        );
    }

    #[tokio::test]
    async fn nothing_listening_is_exit_3() {
        // Bind and drop to find a port with nothing behind it.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let server = format!("http://127.0.0.1:{port}");
        let (code, _) = run_capture(&[
            "landing",
            "info",
            "--server",
            &server,
            "--connect-timeout",
            "2",
        ])
        .await;
        assert_eq!(code, exit::UNREACHABLE);
    }

    #[tokio::test]
    async fn missing_input_file_is_exit_1() {
        let (code, _) = run_capture(&["landing", "detect", "/nonexistent/frame.ply"]).await;
        assert_eq!(code, exit::ERROR);
    }

    #[test]
    fn pipeline_flags_become_options() {
        let cli = Cli::try_parse_from([
            "landing",
            "detect",
            "x.ply",
            "--segmentation",
            "point-classes",
            "--max-triangle-edge",
            "3.5",
            "--max-sites",
            "2",
        ])
        .unwrap();
        let Command::Detect(a) = cli.command else {
            panic!("not detect")
        };
        let o = a.pipeline.options();
        assert_eq!(o.segmentation_mode, SegmentationMode::PointClasses as i32);
        assert_eq!(o.max_triangle_edge_m, Some(3.5));
        assert_eq!(o.max_sites, Some(2));
        assert_eq!(o.min_normal_dot, None);
    }

    #[test]
    fn eval_tolerance_is_a_distance() {
        let parse =
            |t: &str| Cli::try_parse_from(["landing", "eval", "dir", &format!("--tolerance={t}")]);
        let Command::Eval(a) = parse("0.15").unwrap().command else {
            panic!("not eval")
        };
        assert_eq!(a.tolerance, Some(0.15));
        for bad in ["-0.1", "NaN", "inf", "wide"] {
            let e = parse(bad).unwrap_err().to_string();
            assert!(
                e.contains("--tolerance") && e.contains("metres"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn class_image_mode_sends_the_recorded_labels() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let args = |input: &str| {
            let cli =
                Cli::try_parse_from(["landing", "detect", input, "--segmentation", "class-image"])
                    .unwrap();
            let Command::Detect(a) = cli.command else {
                panic!("not detect")
            };
            a
        };
        let mcap = root.join("samples/rooftops.mcap");
        let a = args(mcap.to_str().unwrap());
        let frame = load_frame(&a.input, 2, &a.pipeline).unwrap();
        let labels = landing_recording::read(&mcap).unwrap()[2].labels.clone();
        assert!(labels.is_some());
        assert_eq!(frame.class_image, labels);
        // Other modes send the frame as recorded.
        let mut plain = a.pipeline.clone();
        plain.segmentation = SegmentationMode::Model;
        assert_eq!(load_frame(&a.input, 2, &plain).unwrap().class_image, None);
        // A PLY scan has no labels to send.
        let ply = root.join("samples/roof.ply");
        let a = args(ply.to_str().unwrap());
        let e = load_frame(&a.input, 0, &a.pipeline).unwrap_err();
        assert_eq!(e.code, exit::USAGE);
        assert!(e.message.contains("PLY"), "{}", e.message);
    }

    #[test]
    fn item_json_carries_field_violations() {
        let item = StreamItem {
            sequence: 3,
            outcome: FrameOutcome::Error(landing_client::FrameError {
                code: tonic::Code::InvalidArgument,
                message: "bad".into(),
                field_violations: vec![landing_client::FieldViolation {
                    field: "frame.point_cloud".into(),
                    description: "missing".into(),
                }],
                retry_delay: None,
            }),
            latency: Duration::from_millis(2),
        };
        let v = item_json(&item);
        assert_eq!(v["outcome"], "invalid_argument");
        assert_eq!(
            v["error"]["field_violations"][0]["field"],
            "frame.point_cloud"
        );
        let r = response_of(&item);
        assert!(
            matches!(r.outcome, Some(stream_landing_sites_response::Outcome::Error(ref s)) if s.code == 3)
        );
    }
}
