//! The `landing-server` command line: `serve`, `check-config` and the offline `detect`.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context as _;
use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::{Args, Parser, Subcommand};
use landing_geometry::Params;

use crate::config::Config;
use crate::detect::{detect_ply, detect_recording, to_json, to_table};
use crate::pipeline::{FrameOptions, Pipeline, SegmentationMode};

/// Rooftop landing-site service.
#[derive(Debug, Parser)]
#[command(name = "landing-server", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Runs the gRPC service until SIGTERM/SIGINT.
    Serve(ServeArgs),
    /// Loads and validates a configuration, prints it, and exits 0 (valid) or 1 (naming the key).
    CheckConfig(ConfigArgs),
    /// Finds landing sites in a PLY point cloud, offline.
    Detect(DetectArgs),
}

/// Where the configuration comes from.
#[derive(Debug, Args)]
pub struct ConfigArgs {
    /// TOML configuration file; `LANDING__SECTION__KEY` variables override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Overrides `server.listen`.
    #[arg(long, value_name = "ADDR")]
    pub listen: Option<String>,
    /// Overrides `server.metrics_listen` ("" disables metrics).
    #[arg(long, value_name = "ADDR")]
    pub metrics_listen: Option<String>,
    /// Overrides `server.foxglove_listen`: serve the Foxglove live view on HOST:PORT (off by
    /// default).
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove_listen: Option<String>,
}

/// `serve` arguments.
#[derive(Debug, Args)]
pub struct ServeArgs {
    #[command(flatten)]
    pub config: ConfigArgs,
}

/// `detect` arguments: the input and the pipeline parameters (defaults: the paper's values).
#[derive(Debug, Args)]
pub struct DetectArgs {
    /// PLY point cloud (ascii or binary little-endian; x y z, optional class/label).
    #[arg(
        long,
        value_name = "FILE.ply",
        required_unless_present = "recording",
        conflicts_with = "recording"
    )]
    pub points: Option<PathBuf>,
    /// MCAP recording of frames (image + cloud + poses), as written by the simulator.
    #[arg(long, value_name = "FILE.mcap")]
    pub recording: Option<PathBuf>,
    /// Sequence number of the recorded frame to use (default: the first frame).
    #[arg(long, value_name = "K", requires = "recording")]
    pub frame: Option<u64>,
    /// Where point classes come from: auto (model if an image and a model, else the cloud's
    /// classes, else none), model, class-image (the recording's true label image), point-classes
    /// or none.
    #[arg(long, value_parser = segmentation_parser(), default_value = "auto")]
    pub segmentation: SegmentationMode,
    /// ONNX segmentation model. Default for recordings: models/rooftop-segmentation.onnx when that
    /// file exists (always tried with --segmentation model).
    #[arg(long, value_name = "FILE.onnx")]
    pub model: Option<PathBuf>,
    /// The paper's l_max: triangles with a longer edge are dropped, metres.
    #[arg(long, value_name = "M")]
    pub max_triangle_edge: Option<f64>,
    /// The paper's dot_min: minimum |n . z| of a triangle normal.
    #[arg(long, value_name = "D")]
    pub min_normal_dot: Option<f64>,
    /// The paper's z_min: triangles flatter than this bypass the normal test, metres.
    #[arg(long, value_name = "M")]
    pub max_triangle_height: Option<f64>,
    /// A class allowed in landing planes (repeat for several); default: building rooftop (4).
    #[arg(long = "landable-class", value_name = "ID")]
    pub landable_classes: Vec<u8>,
    /// Polylabel precision, metres.
    #[arg(long, value_name = "M")]
    pub polylabel_precision: Option<f64>,
    /// Planar regions with fewer triangles are dropped.
    #[arg(long, value_name = "N")]
    pub min_region_triangles: Option<usize>,
    /// At most this many sites.
    #[arg(long, value_name = "N")]
    pub max_sites: Option<usize>,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// `--segmentation`: the API's `SegmentationMode` by its command-line name (`auto` is
/// UNSPECIFIED), the same names as `landing --segmentation`.
fn segmentation_parser() -> impl TypedValueParser<Value = SegmentationMode> {
    PossibleValuesParser::new(SegmentationMode::all().map(SegmentationMode::cli_name)).try_map(
        |name: String| {
            SegmentationMode::from_cli_name(&name).ok_or_else(|| format!("unknown mode `{name}`"))
        },
    )
}

impl DetectArgs {
    /// The options these flags ask for.
    pub fn options(&self) -> FrameOptions {
        let d = Params::default();
        let params = Params {
            max_triangle_edge_m: self.max_triangle_edge.unwrap_or(d.max_triangle_edge_m),
            min_normal_dot: self.min_normal_dot.unwrap_or(d.min_normal_dot),
            max_triangle_height_m: self.max_triangle_height.unwrap_or(d.max_triangle_height_m),
            landable_classes: if self.landable_classes.is_empty() {
                d.landable_classes.clone()
            } else {
                self.landable_classes.clone()
            },
            polylabel_precision_m: self.polylabel_precision.unwrap_or(d.polylabel_precision_m),
            min_region_triangles: self.min_region_triangles.unwrap_or(d.min_region_triangles),
            max_sites: self.max_sites.unwrap_or(d.max_sites),
            ..d
        };
        FrameOptions {
            params,
            segmentation_mode: self.segmentation,
        }
    }

    /// The pipeline for this run: with the model when a recording may use it.
    pub fn pipeline(&self) -> anyhow::Result<Pipeline> {
        let mut pipeline = Pipeline::geometry_only(Params::default());
        let default_model = crate::config::SegmentationConfig::default().model_path;
        let model = match (&self.model, self.segmentation) {
            (Some(m), _) => Some(m.clone()),
            (None, SegmentationMode::Model) => Some(default_model),
            (None, SegmentationMode::Unspecified)
                if self.recording.is_some() && default_model.is_file() =>
            {
                Some(default_model)
            }
            (None, _) => None,
        };
        if let Some(model_path) = model {
            let config = crate::config::SegmentationConfig {
                model_path,
                ..Default::default()
            };
            let segmenter = crate::segmentation::Segmenter::load(&config)
                .with_context(|| format!("load the model {}", config.model_path.display()))?;
            pipeline.segmenter = Some(std::sync::Arc::new(segmenter));
        }
        Ok(pipeline)
    }
}

/// Runs the command line on the process arguments: the whole `main` of the binary, callable from
/// tests that re-execute their own binary as a server process.
pub fn cli_main() -> ExitCode {
    cli_main_from(std::env::args_os())
}

/// Like [`cli_main`] with explicit arguments (the first is the program name).
pub fn cli_main_from<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(cli) => cli,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(2)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Detect(args) => {
            let pipeline = args.pipeline()?;
            let options = args.options();
            let out = match (&args.points, &args.recording) {
                (Some(points), _) => detect_ply(points, &options, &pipeline)
                    .with_context(|| format!("detect on {}", points.display()))?,
                (None, Some(recording)) => {
                    detect_recording(recording, args.frame, &options, &pipeline)
                        .with_context(|| format!("detect on {}", recording.display()))?
                }
                (None, None) => anyhow::bail!("give --points FILE.ply or --recording FILE.mcap"),
            };
            if args.json {
                println!("{}", serde_json::to_string_pretty(&to_json(&out))?);
            } else {
                print!("{}", to_table(&out));
            }
            Ok(())
        }
        Command::CheckConfig(args) => {
            let config = load_config(&args)?;
            print!("{}", config.to_toml());
            eprintln!("configuration is valid");
            Ok(())
        }
        Command::Serve(args) => {
            let config = load_config(&args.config)?;
            crate::telemetry::init_tracing(&config.log)?;
            let runtime = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .thread_name("landing-rt")
                .build()
                .context("start the async runtime")?;
            runtime.block_on(async move {
                let shutdown = crate::server::shutdown_signal()?;
                let listener = tokio::net::TcpListener::bind(config.listen_addr()?)
                    .await
                    .with_context(|| format!("bind server.listen {}", config.server.listen))?;
                crate::server::serve(config, listener, shutdown).await
            })
        }
    }
}

/// Loads the configuration: file ← environment ← flags, validated.
pub fn load_config(args: &ConfigArgs) -> anyhow::Result<Config> {
    let mut env: Vec<(String, String)> = std::env::vars().collect();
    // Flags come last, so they override the environment the same way it overrides the file.
    if let Some(listen) = &args.listen {
        env.push(("LANDING__SERVER__LISTEN".into(), listen.clone()));
    }
    if let Some(metrics) = &args.metrics_listen {
        env.push(("LANDING__SERVER__METRICS_LISTEN".into(), metrics.clone()));
    }
    if let Some(foxglove) = &args.foxglove_listen {
        env.push(("LANDING__SERVER__FOXGLOVE_LISTEN".into(), foxglove.clone()));
    }
    let config =
        Config::load(args.config.as_deref(), dedup_last(env)).context("invalid configuration")?;
    Ok(config)
}

/// Keeps the last value of each variable, so a flag beats the variable it overrides.
fn dedup_last(env: Vec<(String, String)>) -> Vec<(String, String)> {
    let mut map = std::collections::BTreeMap::new();
    for (k, v) in env {
        map.insert(k, v);
    }
    map.into_iter().collect()
}
