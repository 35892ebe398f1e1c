//! The `landing eval` subcommand: arguments and the command itself.

use std::io::Write;
use std::path::{Path, PathBuf};

use clap::Args;
use landing_proto::v1::{FusionOptions, PipelineOptions};

use landing_client::LandingClient;
use landing_eval::catalog::{CatalogConfig, run_catalog, write_catalog_report};
use landing_eval::report::{Mode, Summary, Targets, summarize, write_report};
use landing_eval::run::{EvalConfig, Scenario, fill_scanned_regions, run};
use landing_eval::truth::{load_scenarios, recording_files};

use crate::args::{CliError, ConnectionArgs, client_config, exit};

/// Exit code of `landing eval` when a gated mode returned an unsafe site (or answered no frame).
pub const EXIT_UNSAFE: u8 = 7;

/// `landing eval` arguments.
#[derive(Debug, Clone, Args)]
pub struct EvalArgs {
    /// Recordings with ground truth (`landing-sim` MCAP files), or folders of them.
    #[arg(required_unless_present = "scenarios")]
    pub recordings: Vec<PathBuf>,
    /// Generate a scenario set with `landing-sim scenarios` into `<out>/scenarios` first and
    /// evaluate it: `small` (9 frames over 3 buildings, the CI slice) or `full` (144 frames over
    /// 36 buildings of 6 Manhattan-distribution worlds).
    #[arg(long, value_enum)]
    pub scenarios: Option<ScenarioSet>,
    /// The `landing-sim` binary for `--scenarios` (default: next to this binary, else on PATH).
    #[arg(long)]
    pub sim_bin: Option<PathBuf>,
    /// Folder for summary.md, results.json and the PNG charts.
    #[arg(long, default_value = "eval-out")]
    pub out: PathBuf,
    /// Modes to compare: geometry (no classes), model (the server's segmentation), truth (the
    /// recording's true label image sent as the class image: perfect segmentation).
    #[arg(long, value_delimiter = ',', default_value = "geometry,model,truth", value_parser = parse_mode)]
    pub modes: Vec<Mode>,
    /// Modes in which any unsafe site fails the run (exit code 7).
    #[arg(long, value_delimiter = ',', default_value = "model", value_parser = parse_mode)]
    pub gate: Vec<Mode>,
    /// Evaluate at most this many frames (0: all), taken evenly across the recordings.
    #[arg(long, default_value_t = 0)]
    pub limit: usize,
    /// Raster cell for areas and IoU, metres.
    #[arg(long, default_value_t = 0.05)]
    pub cell: f64,
    /// Roofs whose true best radius is below this are not scored for IoU and radius, metres.
    #[arg(long, default_value_t = 1.0)]
    pub min_truth_radius: f64,
    /// Polylabel precision sent with every frame (and used as the safety tolerance), metres.
    /// Unset: the server's default.
    #[arg(long)]
    pub polylabel_precision: Option<f64>,
    /// Judge a circle unsafe when it reaches more than this into an obstacle or off its roof,
    /// metres. Unset: the declared polylabel precision (the paper's rule). A stricter judge shows
    /// how far inside the declared tolerance the circles keep.
    #[arg(long, value_parser = parse_tolerance)]
    pub tolerance: Option<f64>,
    /// At most this many sites per frame. Unset: the server's default.
    #[arg(long)]
    pub max_sites: Option<u32>,
    /// l_max sent with every frame: longest triangle edge, metres. Unset: the server's default.
    #[arg(long)]
    pub max_triangle_edge: Option<f64>,
    /// Also draw every frame top-down into `<out>/frames/` (frames with an unsafe site always are).
    #[arg(long)]
    pub overlays: bool,
    /// Also send each approach (one recording's frames, in sequence order) as one fused stream
    /// per mode, and report the fused answers beside the single-frame ones, with the approach
    /// breakdown (last quarter, time since the start, altitude). The gate then also fails on an
    /// unsafe fused site.
    #[arg(long)]
    pub stream: bool,
    /// With `--stream`: frames of a fused stream sent and unanswered at once. 1 scores each
    /// answer before sending the next frame, so that the scoring does not share the machine
    /// with the server's work (paired timing runs on one box).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(1..=64))]
    pub window: u32,
    /// Score the fleet's catalog over a revisit set (`landing-sim scenarios --revisits N`):
    /// stream every approach fused, in time order, and after each search the catalog around
    /// every target roof of every world; judge each site against the world as it is then
    /// (unsafe now and when last confirmed: must be 0; stale: unsafe now, safe when last
    /// confirmed, followed until withdrawn or confirmed again; recall of the landable roofs the
    /// approach re-scanned). The server's catalog must be FRESH (a new
    /// LANDING__CATALOG__PATH): the run refuses one that already holds sites around the set's
    /// roofs. Streams in model mode (truth when --modes names truth and not model); writes
    /// catalog.md and catalog.json; exit 7 when a gated mode returned an unsafe, not stale, site.
    #[arg(long)]
    pub catalog: bool,
    /// With `--catalog`: how long to wait after each approach for the catalog to show its
    /// confirmations, seconds: at most this, and a third of it without change once one shows
    /// (keep it at least 3 × the server's `catalog.flush_interval_s`, 1 s by default).
    #[arg(long, default_value_t = 4.0, value_parser = parse_tolerance)]
    pub catalog_wait: f64,
}

/// The built-in scenario sets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ScenarioSet {
    /// 1 world, 3 buildings, 3 frames each: the CI slice.
    Small,
    /// 6 worlds, 6 buildings each, 4 frames each: 144 approach frames on 36 buildings.
    Full,
}

impl ScenarioSet {
    /// The `landing-sim scenarios` arguments of this set (fixed seed).
    pub fn sim_args(self) -> [&'static str; 8] {
        match self {
            ScenarioSet::Small => [
                "--seed",
                "2026",
                "--worlds",
                "1",
                "--buildings",
                "3",
                "--frames",
                "3",
            ],
            ScenarioSet::Full => [
                "--seed",
                "2026",
                "--worlds",
                "6",
                "--buildings",
                "6",
                "--frames",
                "4",
            ],
        }
    }
}

/// Runs `landing-sim scenarios` for `set` into `dir`.
fn generate_scenarios(
    set: ScenarioSet,
    sim_bin: Option<&Path>,
    dir: &Path,
) -> Result<(), CliError> {
    let err = |m: String| CliError {
        code: exit::ERROR,
        message: m,
    };
    let bin = match sim_bin {
        Some(b) => b.to_path_buf(),
        None => std::env::current_exe()
            .ok()
            .and_then(|e| e.parent().map(|d| d.join("landing-sim")))
            .filter(|p| p.is_file())
            .unwrap_or_else(|| PathBuf::from("landing-sim")),
    };
    let status = std::process::Command::new(&bin)
        .arg("scenarios")
        .args(set.sim_args())
        .arg("--out")
        .arg(dir)
        .status()
        .map_err(|e| {
            err(format!(
                "cannot run `{}` (set --sim-bin): {e}",
                bin.display()
            ))
        })?;
    if !status.success() {
        return Err(err(format!(
            "`{} scenarios` failed: {status}",
            bin.display()
        )));
    }
    Ok(())
}

fn parse_mode(s: &str) -> Result<Mode, String> {
    Mode::parse(s).ok_or_else(|| format!("unknown mode `{s}` (expected geometry, model or truth)"))
}

fn parse_tolerance(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a distance in metres (finite, >= 0)")),
    }
}

/// Runs `landing eval`: prints the table (or JSON), writes the report folder, and returns
/// [`EXIT_UNSAFE`] when a gated mode had an unsafe site or answered no frame (in its single-frame
/// or, with `--stream`, its fused answers).
pub async fn eval_cmd(
    connection: &ConnectionArgs,
    args: &EvalArgs,
    json: bool,
    out: &mut (dyn Write + Send),
) -> Result<u8, CliError> {
    if !(args.cell > 0.0 && args.cell <= 1.0) {
        return Err(CliError {
            code: exit::USAGE,
            message: format!("--cell {} must be in (0, 1] metres", args.cell),
        });
    }
    let config = eval_config(args);
    if args.catalog {
        return catalog_cmd(connection, args, config, json, out).await;
    }
    let mut scenarios = scenarios(args)?;
    for s in &mut scenarios {
        fill_scanned_regions(s, config.roof_band_m)?;
    }
    let client = LandingClient::connect(client_config(connection)?).await?;
    let (records, failures) = run(&client, &scenarios, &config, |done, total| {
        if done % 10 == 0 || done == total {
            eprintln!("landing eval: {done}/{total} frames");
        }
    })
    .await?;
    let summary = summarize(&records, &failures, &args.modes);
    let targets = Targets::default();
    write_report(&args.out, &summary, &records, &targets, &args.gate)?;
    print_summary(out, json, &summary, &targets, args)?;
    Ok(if summary.gate_failed(&args.gate) {
        EXIT_UNSAFE
    } else {
        exit::OK
    })
}

/// `landing eval --catalog`: streams the revisit set and scores the catalog after each approach
/// ([`landing_eval::catalog`]); prints the table (or JSON) and writes catalog.md and catalog.json.
async fn catalog_cmd(
    connection: &ConnectionArgs,
    args: &EvalArgs,
    eval: landing_eval::run::EvalConfig,
    json: bool,
    out: &mut (dyn Write + Send),
) -> Result<u8, CliError> {
    let mode = if args.modes.contains(&Mode::Model) || !args.modes.contains(&Mode::Truth) {
        Mode::Model
    } else {
        Mode::Truth
    };
    let config = CatalogConfig {
        mode,
        eval: EvalConfig {
            stream: Some(FusionOptions::default()),
            ..eval
        },
        wait: std::time::Duration::from_secs_f64(args.catalog_wait),
        min_truth_radius_m: args.min_truth_radius,
    };
    if args.limit != 0 || args.scenarios.is_some() {
        return Err(CliError {
            code: exit::USAGE,
            message: "--catalog takes a whole revisit set (`landing-sim scenarios --revisits N`): no --limit, no --scenarios".into(),
        });
    }
    let scenarios = scenarios(args)?;
    let client = LandingClient::connect(client_config(connection)?).await?;
    let report = run_catalog(&client, &scenarios, &config, |done, total| {
        eprintln!("landing eval --catalog: {done}/{total} approaches");
    })
    .await?;
    write_catalog_report(&args.out, &report)?;
    let io = |e: std::io::Error| CliError {
        code: exit::ERROR,
        message: format!("cannot write output: {e}"),
    };
    if json {
        let v = serde_json::to_string_pretty(&report).map_err(|e| CliError {
            code: exit::ERROR,
            message: e.to_string(),
        })?;
        writeln!(out, "{v}").map_err(io)?;
    } else {
        write!(out, "{}", report.to_text()).map_err(io)?;
        writeln!(out, "report: {}", args.out.join("catalog.md").display()).map_err(io)?;
    }
    let gated = args.gate.contains(&mode);
    Ok(if gated && report.has_unsafe() {
        EXIT_UNSAFE
    } else {
        exit::OK
    })
}

/// The scenarios to evaluate: the recordings named, a generated set, at most `--limit` frames
/// taken evenly.
fn scenarios(args: &EvalArgs) -> Result<Vec<Scenario>, CliError> {
    let mut inputs = args.recordings.clone();
    if let Some(set) = args.scenarios {
        let dir = args.out.join("scenarios");
        generate_scenarios(set, args.sim_bin.as_deref(), &dir)?;
        inputs.push(dir);
    }
    let files = recording_files(&inputs)?;
    let scenarios = load_scenarios(&files)?;
    if args.limit == 0 || scenarios.len() <= args.limit {
        return Ok(scenarios);
    }
    let step = scenarios.len() as f64 / args.limit as f64;
    Ok((0..args.limit)
        .map(|k| scenarios[(k as f64 * step) as usize].clone())
        .collect())
}

/// What every frame is sent with and scored by.
fn eval_config(args: &EvalArgs) -> EvalConfig {
    EvalConfig {
        modes: args.modes.clone(),
        options: PipelineOptions {
            polylabel_precision_m: args.polylabel_precision,
            max_sites: args.max_sites,
            max_triangle_edge_m: args.max_triangle_edge,
            ..Default::default()
        },
        metrics: landing_eval::MetricsParams {
            cell_m: args.cell,
            min_truth_radius_m: args.min_truth_radius,
            ..Default::default()
        },
        overlay_dir: Some(args.out.join("frames")),
        overlay_all: args.overlays,
        // Fused, with the server's defaults.
        stream: args.stream.then(FusionOptions::default),
        stream_max_in_flight: args.window as usize,
        tolerance_m: args.tolerance,
        ..Default::default()
    }
}

/// The summary as a table with each gated mode's verdicts, or as JSON.
fn print_summary(
    out: &mut (dyn Write + Send),
    json: bool,
    summary: &Summary,
    targets: &Targets,
    args: &EvalArgs,
) -> Result<(), CliError> {
    let io = |e: std::io::Error| CliError {
        code: exit::ERROR,
        message: format!("cannot write output: {e}"),
    };
    if json {
        let v = serde_json::to_string_pretty(summary).map_err(|e| CliError {
            code: exit::ERROR,
            message: e.to_string(),
        })?;
        return writeln!(out, "{v}").map_err(io);
    }
    write!(out, "{}", summary.to_text()).map_err(io)?;
    for &mode in &args.gate {
        for (line, ok) in summary.target_lines(mode, targets) {
            writeln!(out, "{} {line}", if ok { "PASS" } else { "FAIL" }).map_err(io)?;
        }
    }
    writeln!(out, "report: {}", args.out.join("summary.md").display()).map_err(io)
}
