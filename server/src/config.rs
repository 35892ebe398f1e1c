//! The server configuration: built-in defaults ← TOML file ← `LANDING__SECTION__KEY` environment
//! variables ← command-line flags. Unknown keys are errors naming the key, and so is a value a
//! key refuses: choices are enums (`"cpu"`/`"cuda"`, `"pretty"`/`"json"`, …) and input sizes a
//! list of `"WxH"`, parsed once, here. [`Config::validate`] checks the ranges section by section
//! before anything binds.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use landing_perception::{ExecutionProvider, OrtLogLevel};
use serde::{Deserialize, Serialize};

use crate::Error;

/// The whole configuration, mirroring the TOML file section by section.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    pub server: ServerConfig,
    pub pipeline: PipelineConfig,
    pub segmentation: SegmentationConfig,
    pub auth: AuthConfig,
    pub tls: TlsConfig,
    pub log: LogConfig,
    pub fusion: FusionConfig,
    pub catalog: CatalogConfig,
}

/// `[catalog]`: the fleet's landing-site catalog, fed by fused streams whose frames carry a
/// geodetic origin and searched with `SearchLandingSites`. On by default with one SQLite file
/// (`path`), which needs no set-up; `url` (a `postgres://` URL, from a Secret through
/// `LANDING__CATALOG__URL`) selects a PostgreSQL + PostGIS database that several replicas
/// share, and wins over `path`. A store that cannot be opened does not stop the server: frames
/// are answered, writes are counted and dropped, searches answer UNAVAILABLE, and opening is
/// retried every `retry_interval_s`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CatalogConfig {
    /// Off: nothing is recorded and `SearchLandingSites` answers UNAVAILABLE.
    pub enabled: bool,
    /// The SQLite file (created, with its directory, when missing); relative to the working
    /// directory.
    pub path: PathBuf,
    /// `postgres://user:password@host:port/database`; "" = the SQLite file at `path`.
    pub url: String,
    /// Observations waiting to be written; when full, the oldest is dropped (counted).
    pub queue_capacity: u32,
    /// Most observations written in one transaction.
    pub batch_max: u32,
    /// The writer waits at most this long to gather a batch, seconds.
    pub flush_interval_s: f64,
    /// A fused stream reports what it saw at most this often, and when it ends, seconds.
    pub observe_interval_s: f64,
    /// A site is recorded only once this many consecutive answers of its stream found it, on
    /// ground the cameras resolved.
    pub min_frames: u32,
    /// Sites last confirmed longer ago are not returned unless a search asks (`max_age`),
    /// seconds.
    pub max_age_s: f64,
    /// Sites last confirmed longer ago are deleted, seconds.
    pub retention_s: f64,
    /// How often expired sites are deleted, seconds.
    pub expire_interval_s: f64,
    /// How often a store that could not be opened, or a failed write, is tried again, seconds.
    pub retry_interval_s: f64,
    /// A search the database has not answered in this long answers UNAVAILABLE (a frozen
    /// database holds the call itself longer), seconds.
    pub search_timeout_s: f64,
}

impl Default for CatalogConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            path: "data/catalog.sqlite".into(),
            url: String::new(),
            queue_capacity: 1024,
            batch_max: 64,
            flush_interval_s: 1.0,
            observe_interval_s: 5.0,
            min_frames: 3,
            max_age_s: landing_catalog::DEFAULT_MAX_AGE.as_secs_f64(),
            retention_s: 30.0 * 24.0 * 3600.0,
            expire_interval_s: 600.0,
            retry_interval_s: 5.0,
            search_timeout_s: 1.0,
        }
    }
}

impl CatalogConfig {
    /// Where the catalog lives: `url` when set, else `path`; `None` when the catalog is off.
    pub fn location(&self) -> Result<Option<landing_catalog::Location>, Error> {
        if !self.enabled {
            return Ok(None);
        }
        let (key, value) = if self.url.trim().is_empty() {
            ("catalog.path", self.path.to_string_lossy().into_owned())
        } else {
            ("catalog.url", self.url.clone())
        };
        let location = landing_catalog::Location::parse(&value, key)
            .map_err(|e| Error::config(key, e.to_string()))?;
        if key == "catalog.url" && !matches!(location, landing_catalog::Location::Postgres(_)) {
            return Err(Error::config(
                key,
                "not a postgres:// or postgresql:// URL (a SQLite file goes in catalog.path)",
            ));
        }
        Ok(Some(location))
    }

    fn validate(&self) -> Result<(), Error> {
        self.location()?;
        in_range(
            "catalog.queue_capacity",
            self.queue_capacity,
            1..=1_000_000,
            "1..=1000000",
        )?;
        in_range("catalog.batch_max", self.batch_max, 1..=10_000, "1..=10000")?;
        in_range("catalog.min_frames", self.min_frames, 1..=1000, "1..=1000")?;
        let day = 24.0 * 3600.0;
        for (key, value, range, shown) in [
            (
                "catalog.flush_interval_s",
                self.flush_interval_s,
                0.001..=3600.0,
                "0.001..=3600 seconds",
            ),
            (
                "catalog.observe_interval_s",
                self.observe_interval_s,
                0.0..=3600.0,
                "0..=3600 seconds",
            ),
            (
                "catalog.max_age_s",
                self.max_age_s,
                1.0..=3650.0 * day,
                "1 second..=3650 days",
            ),
            (
                "catalog.retention_s",
                self.retention_s,
                1.0..=3650.0 * day,
                "1 second..=3650 days",
            ),
            (
                "catalog.expire_interval_s",
                self.expire_interval_s,
                1.0..=day,
                "1..=86400 seconds",
            ),
            (
                "catalog.retry_interval_s",
                self.retry_interval_s,
                0.01..=3600.0,
                "0.01..=3600 seconds",
            ),
            (
                "catalog.search_timeout_s",
                self.search_timeout_s,
                0.01..=60.0,
                "0.01..=60 seconds",
            ),
        ] {
            in_range(key, value, range, shown)?;
        }
        if self.retention_s < self.max_age_s {
            return Err(Error::config(
                "catalog.retention_s",
                format!(
                    "{} s is shorter than catalog.max_age_s = {} s: sites would be deleted before they age out",
                    self.retention_s, self.max_age_s
                ),
            ));
        }
        Ok(())
    }

    /// `max_age_s` as a duration.
    pub fn max_age(&self) -> std::time::Duration {
        std::time::Duration::from_secs_f64(self.max_age_s)
    }
}

/// `[fusion]`: the defaults of streams that ask for approach fusion (`FusionOptions`); a stream
/// may ask for other values, but never for more cells than `max_cells`. The keys are the
/// `FusionOptions` field names; [`FusionConfig::params`] and `From<&FusionParams>` are the one
/// place where each meets the fusion crate's own field (`convert` goes through them too).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FusionConfig {
    /// Side of the map's cells, metres.
    pub cell_size_m: f64,
    /// Cells and keep-out footprints older than this are forgotten, seconds.
    pub horizon_s: f64,
    /// Most cells per stream: the bound of a map's memory (about 60 bytes a cell).
    pub max_cells: u32,
    /// Most frames whose keep-out footprints a map keeps.
    pub keep_out_frames: u32,
    /// Least time between two kept keep-out frames, seconds.
    pub keep_out_interval_s: f64,
    /// A sensor jump longer than this between frames starts a map over, metres.
    pub max_jump_m: f64,
    /// One obstacle vote outweighs this many landable votes.
    pub obstacle_weight: u32,
    /// Lay each scan onto the map before fusing it (point-to-plane registration).
    pub register_scans: bool,
    /// Safe circles keep clear of places no camera pixel of at most this size on the roof has
    /// seen, metres (0: off).
    pub max_pixel_footprint_m: f64,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self::from(&landing_fusion::FusionParams::default())
    }
}

impl From<&landing_fusion::FusionParams> for FusionConfig {
    fn from(p: &landing_fusion::FusionParams) -> Self {
        Self {
            cell_size_m: p.cell_size_m,
            horizon_s: p.horizon_s,
            max_cells: u32::try_from(p.max_cells).unwrap_or(u32::MAX),
            keep_out_frames: u32::try_from(p.keep_out_frames).unwrap_or(u32::MAX),
            keep_out_interval_s: p.keep_out_interval_s,
            max_jump_m: p.max_jump_m,
            obstacle_weight: p.obstacle_weight,
            register_scans: p.register_scans,
            max_pixel_footprint_m: p.max_pixel_footprint_m,
        }
    }
}

impl FusionConfig {
    /// The map parameters these defaults describe.
    pub fn params(&self) -> landing_fusion::FusionParams {
        landing_fusion::FusionParams {
            cell_size_m: self.cell_size_m,
            horizon_s: self.horizon_s,
            max_cells: self.max_cells as usize,
            keep_out_frames: self.keep_out_frames as usize,
            keep_out_interval_s: self.keep_out_interval_s,
            max_jump_m: self.max_jump_m,
            obstacle_weight: self.obstacle_weight,
            register_scans: self.register_scans,
            max_pixel_footprint_m: self.max_pixel_footprint_m,
        }
    }

    fn validate(&self) -> Result<(), Error> {
        self.params()
            .validate()
            .map_err(|e| Error::config(format!("fusion.{}", e.field()), e.to_string()))
    }
}

/// `[server]`: listeners and limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServerConfig {
    /// gRPC listen address.
    pub listen: String,
    /// Prometheus `/metrics` listen address; "" disables it.
    pub metrics_listen: String,
    /// Foxglove live view (WebSocket, protocol `foxglove.sdk.v1`) listen address; "" (the
    /// default) disables it. Viewers see each processed frame's scan, image, poses and sites.
    pub foxglove_listen: String,
    /// Largest accepted (and sent) message, bytes.
    pub max_request_bytes: u64,
    /// In-flight frames get this long after SIGTERM, seconds.
    pub shutdown_grace_s: f64,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            listen: "0.0.0.0:50051".into(),
            metrics_listen: "0.0.0.0:9464".into(),
            foxglove_listen: String::new(),
            max_request_bytes: 64 * 1024 * 1024,
            shutdown_grace_s: 20.0,
        }
    }
}

/// `[pipeline]`: worker pool and queues.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineConfig {
    /// Geometry worker threads; 0 = one per CPU core.
    pub geometry_workers: u32,
    /// Frames admitted but not yet finished, all streams together.
    pub queue_capacity: u32,
    /// Memory those frames may hold together, bytes: their points (8 bytes a coordinate),
    /// classes and image bytes. A frame over it is refused like one over `queue_capacity`; a
    /// frame larger than the whole budget is admitted only into an empty queue.
    pub max_queued_bytes: u64,
    /// Frames buffered per stream before the overflow policy applies.
    pub stream_buffer: u32,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            geometry_workers: 0,
            queue_capacity: 64,
            max_queued_bytes: 512 * 1024 * 1024,
            stream_buffer: 4,
        }
    }
}

impl ServerConfig {
    fn validate(&self) -> Result<(), Error> {
        parse_addr("server.listen", &self.listen)?;
        for (key, addr) in [
            ("server.metrics_listen", &self.metrics_listen),
            ("server.foxglove_listen", &self.foxglove_listen),
        ] {
            if !addr.is_empty() {
                parse_addr(key, addr)?;
            }
        }
        in_range(
            "server.max_request_bytes",
            self.max_request_bytes,
            1024 * 1024..=1024 * 1024 * 1024,
            "1 MiB..=1 GiB",
        )?;
        in_range(
            "server.shutdown_grace_s",
            self.shutdown_grace_s,
            0.0..=3600.0,
            "0..=3600 seconds",
        )
    }
}

impl PipelineConfig {
    fn validate(&self) -> Result<(), Error> {
        if self.geometry_workers > 1024 {
            return Err(Error::config(
                "pipeline.geometry_workers",
                format!("{} is above 1024", self.geometry_workers),
            ));
        }
        in_range(
            "pipeline.queue_capacity",
            self.queue_capacity,
            1..=1_000_000,
            "1..=1000000",
        )?;
        in_range(
            "pipeline.max_queued_bytes",
            self.max_queued_bytes,
            1 << 20..=1 << 40,
            "1 MiB..=1 TiB",
        )?;
        in_range(
            "pipeline.stream_buffer",
            self.stream_buffer,
            1..=10_000,
            "1..=10000",
        )
    }

    /// The number of geometry workers, with 0 resolved to the core count.
    pub fn workers(&self) -> usize {
        match self.geometry_workers {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n as usize,
        }
    }
}

/// `[segmentation]`: the ONNX model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SegmentationConfig {
    pub enabled: bool,
    pub model_path: PathBuf,
    /// "cpu" or "cuda" (falls back to CPU with a warning).
    pub execution_provider: ExecutionProvider,
    /// ONNX Runtime threads inside one inference (default 1). More than one spin between the
    /// model's operators: with `sessions = 1` a frame at a time takes about half the time, but
    /// sessions × threads beyond the cores slow every frame (BENCHMARKS.md, "Single frames").
    pub intra_threads: u32,
    /// ONNX Runtime sessions, used in turn: this many frames are segmented at once, and a
    /// frame judged alone runs its input sizes at once on as many of them (default 2: the two
    /// default sizes side by side).
    pub sessions: u32,
    /// "" = `ORT_DYLIB_PATH`, else `.ort/libonnxruntime.so`.
    pub ort_library: PathBuf,
    /// Sizes the image is segmented at, `["WxH", …]` (in the environment `"WxH,WxH"`); a pixel
    /// is landable only where every size says so
    /// (`landing_perception::ClassMask::fuse_keeping_obstacles`). `[]` = once, at the size in the model's metadata. The default runs the shipped model
    /// (trained at 256 × 192) at the camera's 320 × 240, where it sees small obstacles best, and
    /// at its own size, where it sees rooftop-entrance tops best (EVALUATION.md). A fused
    /// stream's frames run the finest size alone (`segmentation::Judged`).
    pub input_sizes: Vec<InputSize>,
    /// The least severe of ONNX Runtime's own log messages that is logged: "verbose", "info",
    /// "warning", "error" or "fatal". ONNX Runtime writes about 200 INFO lines while it loads
    /// the model; `log.filter` still applies to what passes (its target is `ort`).
    pub ort_log_level: OrtLogLevel,
}

impl SegmentationConfig {
    /// Most input sizes a frame is segmented at.
    pub const MAX_INPUT_SIZES: usize = 4;

    /// `input_sizes`, finest (most pixels) first; empty for the model's own size.
    pub fn input_sizes_finest_first(&self) -> Vec<(u32, u32)> {
        let mut sizes: Vec<(u32, u32)> = self
            .input_sizes
            .iter()
            .map(|s| (s.width, s.height))
            .collect();
        sizes.sort_by_key(|&(w, h)| std::cmp::Reverse(u64::from(w) * u64::from(h)));
        sizes
    }

    fn validate(&self) -> Result<(), Error> {
        in_range(
            "segmentation.intra_threads",
            self.intra_threads,
            1..=256,
            "1..=256",
        )?;
        in_range("segmentation.sessions", self.sessions, 1..=64, "1..=64")?;
        if self.input_sizes.len() > Self::MAX_INPUT_SIZES {
            return Err(Error::config(
                "segmentation.input_sizes",
                format!(
                    "{} sizes; at most {}",
                    self.input_sizes.len(),
                    Self::MAX_INPUT_SIZES
                ),
            ));
        }
        if self.enabled {
            require_file("segmentation.model_path", &self.model_path)?;
            if set(&self.ort_library) {
                require_file("segmentation.ort_library", &self.ort_library)?;
            }
        }
        Ok(())
    }
}

impl Default for SegmentationConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            model_path: "models/rooftop-segmentation.onnx".into(),
            execution_provider: ExecutionProvider::Cpu,
            intra_threads: 1,
            sessions: 2,
            ort_library: PathBuf::new(),
            input_sizes: vec![InputSize::new(320, 240), InputSize::new(256, 192)],
            ort_log_level: OrtLogLevel::default(),
        }
    }
}

/// One size the model is run at, `"WIDTHxHEIGHT"` in a config file; each side in 32..=4096.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct InputSize {
    pub width: u32,
    pub height: u32,
}

impl InputSize {
    /// Sides accepted, pixels.
    pub const SIDES: std::ops::RangeInclusive<u32> = 32..=4096;

    fn new(width: u32, height: u32) -> Self {
        Self { width, height }
    }
}

impl TryFrom<String> for InputSize {
    type Error = String;

    fn try_from(text: String) -> Result<Self, String> {
        let (width, height) = text
            .split_once(['x', 'X'])
            .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)))
            .ok_or_else(|| format!("{text:?} is not WIDTHxHEIGHT"))?;
        if !Self::SIDES.contains(&width) || !Self::SIDES.contains(&height) {
            return Err(format!("{text}: width and height must be in 32..=4096"));
        }
        Ok(Self::new(width, height))
    }
}

impl From<InputSize> for String {
    fn from(size: InputSize) -> String {
        format!("{}x{}", size.width, size.height)
    }
}

/// `[auth]`: bearer tokens.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AuthConfig {
    /// One bearer token per line; "" = no auth. Health is exempt.
    pub tokens_file: PathBuf,
}

impl AuthConfig {
    fn validate(&self) -> Result<(), Error> {
        if set(&self.tokens_file) && read_tokens(&self.tokens_file)?.is_empty() {
            return Err(Error::config("auth.tokens_file", "the file holds no token"));
        }
        Ok(())
    }
}

/// `[tls]`: server certificate and optional client CA.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TlsConfig {
    /// PEM certificate chain; all three "" = plaintext.
    pub cert_path: PathBuf,
    pub key_path: PathBuf,
    /// PEM CA; set = client certificates required.
    pub client_ca_path: PathBuf,
}

impl TlsConfig {
    fn validate(&self) -> Result<(), Error> {
        let (cert, key) = (set(&self.cert_path), set(&self.key_path));
        if cert != key {
            let missing = if cert {
                "tls.key_path"
            } else {
                "tls.cert_path"
            };
            return Err(Error::config(
                missing,
                "tls.cert_path and tls.key_path must be set together",
            ));
        }
        if set(&self.client_ca_path) && !cert {
            return Err(Error::config(
                "tls.client_ca_path",
                "client certificates need tls.cert_path and tls.key_path",
            ));
        }
        for (key, path) in [
            ("tls.cert_path", &self.cert_path),
            ("tls.key_path", &self.key_path),
            ("tls.client_ca_path", &self.client_ca_path),
        ] {
            if set(path) {
                require_file(key, path)?;
            }
        }
        Ok(())
    }
}

/// `[log]`: tracing output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogConfig {
    pub format: LogFormat,
    /// EnvFilter syntax; `RUST_LOG` overrides.
    pub filter: String,
}

impl Default for LogConfig {
    fn default() -> Self {
        Self {
            format: LogFormat::Pretty,
            filter: "info".into(),
        }
    }
}

impl LogConfig {
    fn validate(&self) -> Result<(), Error> {
        tracing_subscriber::EnvFilter::try_new(&self.filter)
            .map(drop)
            .map_err(|e| Error::config("log.filter", format!("{:?}: {e}", self.filter)))
    }
}

/// How log lines are written: `"pretty"` (for people) or `"json"` (for collectors).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    Pretty,
    Json,
}

/// Prefix of the environment variables that override config keys.
pub const ENV_PREFIX: &str = "LANDING__";

impl Config {
    /// Loads defaults ← `file` ← the `LANDING__SECTION__KEY` variables among `env`, then validates.
    /// Pass `std::env::vars()` for the process environment.
    pub fn load(
        file: Option<&Path>,
        env: impl IntoIterator<Item = (String, String)>,
    ) -> Result<Config, Error> {
        let mut table = defaults_table();
        if let Some(path) = file {
            let text = std::fs::read_to_string(path).map_err(|e| Error::Io {
                path: path.display().to_string(),
                reason: e.to_string(),
            })?;
            let parsed: toml::Table = text.parse().map_err(|e: toml::de::Error| {
                Error::config(
                    format!("(file {})", path.display()),
                    e.to_string().trim().to_owned(),
                )
            })?;
            merge_file(&mut table, parsed)?;
        }
        let mut env: Vec<(String, String)> = env
            .into_iter()
            .filter(|(k, _)| k.starts_with(ENV_PREFIX))
            .collect();
        env.sort();
        for (name, value) in env {
            apply_env(&mut table, &name, &value)?;
        }
        let config = deserialize(table)?;
        config.validate()?;
        Ok(config)
    }

    /// Checks every key, section by section; the error names the first bad one.
    pub fn validate(&self) -> Result<(), Error> {
        self.server.validate()?;
        self.pipeline.validate()?;
        self.segmentation.validate()?;
        self.auth.validate()?;
        self.tls.validate()?;
        self.fusion.validate()?;
        self.catalog.validate()?;
        self.log.validate()
    }

    /// The gRPC listen address (valid after [`Config::validate`]).
    pub fn listen_addr(&self) -> Result<SocketAddr, Error> {
        parse_addr("server.listen", &self.server.listen)
    }

    /// The metrics listen address, `None` when disabled.
    pub fn metrics_addr(&self) -> Result<Option<SocketAddr>, Error> {
        if self.server.metrics_listen.is_empty() {
            return Ok(None);
        }
        parse_addr("server.metrics_listen", &self.server.metrics_listen).map(Some)
    }

    /// The Foxglove live view's listen address, `None` when disabled.
    pub fn foxglove_addr(&self) -> Result<Option<SocketAddr>, Error> {
        if self.server.foxglove_listen.is_empty() {
            return Ok(None);
        }
        parse_addr("server.foxglove_listen", &self.server.foxglove_listen).map(Some)
    }

    /// The whole config as TOML, as `check-config` prints it.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).unwrap_or_else(|e| format!("# cannot render config: {e}\n"))
    }
}

/// The bearer tokens of a tokens file: one per line, blank lines and `#` comments ignored.
pub fn read_tokens(path: &Path) -> Result<Vec<String>, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        Error::config(
            "auth.tokens_file",
            format!("cannot read {}: {e}", path.display()),
        )
    })?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(str::to_owned)
        .collect())
}

/// `Ok` when `value` lies in `range`, else an error naming `key` and the range as `shown`.
fn in_range<T: PartialOrd + std::fmt::Display>(
    key: &str,
    value: T,
    range: std::ops::RangeInclusive<T>,
    shown: &str,
) -> Result<(), Error> {
    if range.contains(&value) {
        Ok(())
    } else {
        Err(Error::config(key, format!("{value} is outside {shown}")))
    }
}

fn set(path: &Path) -> bool {
    !path.as_os_str().is_empty()
}

fn require_file(key: &str, path: &Path) -> Result<(), Error> {
    if path.is_file() {
        Ok(())
    } else {
        Err(Error::config(
            key,
            format!("{} is not a readable file", path.display()),
        ))
    }
}

fn parse_addr(key: &str, value: &str) -> Result<SocketAddr, Error> {
    value.parse().map_err(|_| {
        Error::config(
            key,
            format!("{value:?} is not an address like 0.0.0.0:50051"),
        )
    })
}

fn defaults_table() -> toml::Table {
    match toml::Value::try_from(Config::default()) {
        Ok(toml::Value::Table(t)) => t,
        // Serialising plain structs of strings and numbers cannot fail.
        _ => toml::Table::new(),
    }
}

/// The merged table as a [`Config`]. A value of the right TOML type that its key still refuses
/// (a choice it does not know, a malformed size) is named by its key.
fn deserialize(table: toml::Table) -> Result<Config, Error> {
    Config::deserialize(toml::Value::Table(table.clone())).map_err(|e| {
        first_refused_key(&table).unwrap_or_else(|| Error::config("(config)", reason(&e)))
    })
}

/// A deserialisation error's own words, without the key path that [`Error::config`] names.
fn reason(e: &toml::de::Error) -> String {
    let text = e.to_string();
    text.lines().next().unwrap_or_default().trim().to_owned()
}

/// The first key of `table` that the defaults with that one key set do not deserialise.
fn first_refused_key(table: &toml::Table) -> Option<Error> {
    let defaults = defaults_table();
    table.iter().find_map(|(section, values)| {
        values.as_table()?.iter().find_map(|(key, value)| {
            let mut probe = defaults.clone();
            if let Some(toml::Value::Table(target)) = probe.get_mut(section) {
                target.insert(key.clone(), value.clone());
            }
            Config::deserialize(toml::Value::Table(probe))
                .err()
                .map(|e| Error::config(format!("{section}.{key}"), reason(&e)))
        })
    })
}

/// Merges a parsed file into the defaults, rejecting unknown sections/keys and wrong types.
fn merge_file(table: &mut toml::Table, file: toml::Table) -> Result<(), Error> {
    for (section, value) in file {
        let Some(toml::Value::Table(target)) = table.get_mut(&section) else {
            return Err(Error::config(section, "unknown section"));
        };
        let toml::Value::Table(values) = value else {
            return Err(Error::config(section, "must be a [section] table"));
        };
        for (key, value) in values {
            let path = format!("{section}.{key}");
            let Some(default) = target.get(&key) else {
                return Err(Error::config(path, "unknown key"));
            };
            let value = coerce(&path, default, value)?;
            target.insert(key, value);
        }
    }
    Ok(())
}

/// Applies `LANDING__SECTION__KEY=value`, parsing the value as the key's type (a list as its
/// items between commas).
fn apply_env(table: &mut toml::Table, name: &str, raw: &str) -> Result<(), Error> {
    let rest = &name[ENV_PREFIX.len()..];
    let parts: Vec<String> = rest.split("__").map(str::to_ascii_lowercase).collect();
    let [section, key] = parts.as_slice() else {
        return Err(Error::config(name, "expected LANDING__SECTION__KEY"));
    };
    let path = format!("{section}.{key}");
    let Some(toml::Value::Table(target)) = table.get_mut(section) else {
        return Err(Error::config(format!("{name} ({path})"), "unknown section"));
    };
    let Some(default) = target.get(key) else {
        return Err(Error::config(format!("{name} ({path})"), "unknown key"));
    };
    let value =
        match default {
            toml::Value::String(_) => toml::Value::String(raw.to_owned()),
            toml::Value::Integer(_) => toml::Value::Integer(raw.trim().parse().map_err(|_| {
                Error::config(&path, format!("{raw:?} (from {name}) is not an integer"))
            })?),
            toml::Value::Float(_) => toml::Value::Float(raw.trim().parse().map_err(|_| {
                Error::config(&path, format!("{raw:?} (from {name}) is not a number"))
            })?),
            toml::Value::Boolean(_) => toml::Value::Boolean(match raw.trim() {
                "true" | "1" => true,
                "false" | "0" => false,
                _ => {
                    return Err(Error::config(
                        &path,
                        format!("{raw:?} (from {name}) is not true/false"),
                    ));
                }
            }),
            toml::Value::Array(_) => toml::Value::Array(
                raw.split(',')
                    .map(str::trim)
                    .filter(|item| !item.is_empty())
                    .map(|item| toml::Value::String(item.to_owned()))
                    .collect(),
            ),
            _ => return Err(Error::config(&path, "cannot be set from the environment")),
        };
    target.insert(key.clone(), value);
    Ok(())
}

fn coerce(path: &str, default: &toml::Value, value: toml::Value) -> Result<toml::Value, Error> {
    use toml::Value as V;
    match (default, value) {
        (V::String(_), v @ V::String(_))
        | (V::Boolean(_), v @ V::Boolean(_))
        | (V::Float(_), v @ V::Float(_))
        | (V::Array(_), v @ V::Array(_)) => Ok(v),
        (V::Integer(_), V::Integer(i)) => {
            if i < 0 {
                Err(Error::config(path, format!("{i} is negative")))
            } else {
                Ok(V::Integer(i))
            }
        }
        (V::Float(_), V::Integer(i)) => Ok(V::Float(i as f64)),
        (d, v) => Err(Error::config(
            path,
            format!("expected a {}, found {} {v}", d.type_str(), v.type_str()),
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("landing-config-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn write(name: &str, text: &str) -> PathBuf {
        let p = dir().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    fn no_model() -> Vec<(String, String)> {
        vec![("LANDING__SEGMENTATION__ENABLED".into(), "false".into())]
    }

    #[test]
    fn defaults_match_the_contract() {
        let c = Config::default();
        assert_eq!(c.server.listen, "0.0.0.0:50051");
        assert_eq!(c.server.metrics_listen, "0.0.0.0:9464");
        assert_eq!(c.server.max_request_bytes, 67_108_864);
        assert_eq!(c.server.shutdown_grace_s, 20.0);
        assert_eq!(
            (
                c.pipeline.geometry_workers,
                c.pipeline.queue_capacity,
                c.pipeline.max_queued_bytes,
                c.pipeline.stream_buffer
            ),
            (0, 64, 512 << 20, 4)
        );
        assert_eq!(
            c.segmentation.model_path,
            PathBuf::from("models/rooftop-segmentation.onnx")
        );
        assert_eq!(
            (c.log.format, c.log.filter.as_str()),
            (LogFormat::Pretty, "info")
        );
        assert_eq!(c.segmentation.ort_log_level, OrtLogLevel::Warning);
        assert_eq!(c.segmentation.execution_provider, ExecutionProvider::Cpu);
        assert_eq!(
            c.segmentation.input_sizes_finest_first(),
            vec![(320, 240), (256, 192)]
        );
    }

    #[test]
    fn file_then_env_override_defaults() {
        let path = write(
            "layered.toml",
            "[server]\nlisten = \"127.0.0.1:6000\"\nshutdown_grace_s = 3\n[pipeline]\nqueue_capacity = 8\n\
             [segmentation]\nenabled = false\n",
        );
        let env = vec![
            (
                "LANDING__SERVER__LISTEN".to_owned(),
                "127.0.0.1:7000".to_owned(),
            ),
            (
                "LANDING__PIPELINE__STREAM_BUFFER".to_owned(),
                "9".to_owned(),
            ),
            (
                "LANDING__SEGMENTATION__ORT_LOG_LEVEL".to_owned(),
                "error".to_owned(),
            ),
            ("UNRELATED".to_owned(), "x".to_owned()),
        ];
        let c = Config::load(Some(&path), env).unwrap();
        assert_eq!(c.segmentation.ort_log_level, OrtLogLevel::Error);
        assert_eq!(c.server.listen, "127.0.0.1:7000");
        assert_eq!(c.server.shutdown_grace_s, 3.0);
        assert_eq!(c.pipeline.queue_capacity, 8);
        assert_eq!(c.pipeline.stream_buffer, 9);
        assert_eq!(c.server.metrics_listen, "0.0.0.0:9464");
    }

    #[test]
    fn unknown_keys_are_named() {
        let path = write(
            "unknown.toml",
            "[server]\nlisten = \"127.0.0.1:1\"\nlisen = \"x\"\n",
        );
        let e = Config::load(Some(&path), no_model())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("server.lisen") && e.contains("unknown key"),
            "{e}"
        );
        let path = write("unknown-section.toml", "[sever]\nlisten = \"x\"\n");
        let e = Config::load(Some(&path), no_model())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("`sever`") && e.contains("unknown section"),
            "{e}"
        );
        let env = vec![("LANDING__SERVER__PORT".to_owned(), "1".to_owned())];
        let e = Config::load(None, env).unwrap_err().to_string();
        assert!(
            e.contains("LANDING__SERVER__PORT") && e.contains("unknown key"),
            "{e}"
        );
    }

    #[test]
    fn bad_values_are_named() {
        let cases = [
            ("[server]\nlisten = \"nowhere\"\n", "server.listen"),
            (
                "[server]\nmax_request_bytes = 10\n",
                "server.max_request_bytes",
            ),
            (
                "[server]\nshutdown_grace_s = \"soon\"\n",
                "server.shutdown_grace_s",
            ),
            (
                "[pipeline]\nqueue_capacity = 0\n",
                "pipeline.queue_capacity",
            ),
            (
                "[pipeline]\nmax_queued_bytes = 1000\n",
                "pipeline.max_queued_bytes",
            ),
            (
                "[pipeline]\ngeometry_workers = -1\n",
                "pipeline.geometry_workers",
            ),
            (
                "[segmentation]\nexecution_provider = \"tpu\"\n",
                "segmentation.execution_provider",
            ),
            (
                "[segmentation]\nmodel_path = \"/nonexistent/model.onnx\"\n",
                "segmentation.model_path",
            ),
            (
                "[segmentation]\ninput_sizes = [\"320x8\"]\n",
                "segmentation.input_sizes",
            ),
            (
                "[segmentation]\ninput_sizes = [\"320\"]\n",
                "segmentation.input_sizes",
            ),
            (
                "[segmentation]\ninput_sizes = \"320x240\"\n",
                "segmentation.input_sizes",
            ),
            (
                "[segmentation]\ninput_sizes = [\"64x64\", \"96x96\", \"128x128\", \"160x160\", \
                 \"192x192\"]\n",
                "segmentation.input_sizes",
            ),
            (
                "[segmentation]\nort_log_level = \"loud\"\n",
                "segmentation.ort_log_level",
            ),
            (
                "[auth]\ntokens_file = \"/nonexistent/tokens\"\n",
                "auth.tokens_file",
            ),
            (
                "[tls]\ncert_path = \"/nonexistent/cert.pem\"\n",
                "tls.key_path",
            ),
            ("[log]\nformat = \"xml\"\n", "log.format"),
            ("[fusion]\ncell_size_m = 0.0\n", "fusion.cell_size_m"),
            (
                "[fusion]\nmax_pixel_footprint_m = -1.0\n",
                "fusion.max_pixel_footprint_m",
            ),
            ("[log]\nfilter = \"[[[\"\n", "log.filter"),
            ("[catalog]\nqueue_capacity = 0\n", "catalog.queue_capacity"),
            ("[catalog]\nurl = \"mysql://db/catalog\"\n", "catalog.url"),
            ("[catalog]\npath = \" \"\n", "catalog.path"),
            ("[catalog]\nretention_s = 60.0\n", "catalog.retention_s"),
            ("[catalog]\nmin_frames = 0\n", "catalog.min_frames"),
            (
                "[catalog]\nflush_interval_s = -1.0\n",
                "catalog.flush_interval_s",
            ),
        ];
        for (i, (text, key)) in cases.into_iter().enumerate() {
            let path = write(&format!("bad{i}.toml"), text);
            let env = if key.starts_with("segmentation") {
                vec![]
            } else {
                no_model()
            };
            let e = Config::load(Some(&path), env).unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        let e = Config::load(
            None,
            vec![(
                "LANDING__PIPELINE__STREAM_BUFFER".to_owned(),
                "many".to_owned(),
            )],
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("pipeline.stream_buffer") && e.contains("many"),
            "{e}"
        );
    }

    #[test]
    fn tokens_file_and_round_trip() {
        let tokens = write("tokens", "# fleet\nalpha\n\n  beta \n");
        assert_eq!(read_tokens(&tokens).unwrap(), vec!["alpha", "beta"]);
        let mut c = Config::default();
        c.segmentation.enabled = false;
        c.auth.tokens_file = tokens;
        let path = write("round.toml", &c.to_toml());
        assert_eq!(Config::load(Some(&path), vec![]).unwrap(), c);
    }

    #[test]
    fn choices_are_refused_by_name_with_what_is_allowed() {
        let path = write(
            "provider.toml",
            "[segmentation]\nexecution_provider = \"tpu\"\n",
        );
        let e = Config::load(Some(&path), no_model())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("segmentation.execution_provider")
                && e.contains("tpu")
                && e.contains("cuda"),
            "{e}"
        );
        let env = vec![("LANDING__LOG__FORMAT".to_owned(), "xml".to_owned())];
        let e = Config::load(None, [no_model(), env].concat())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("log.format") && e.contains("xml") && e.contains("json"),
            "{e}"
        );
    }

    #[test]
    fn input_sizes_are_a_list_in_a_file_and_commas_in_the_environment() {
        let path = write(
            "sizes.toml",
            "[segmentation]\nenabled = false\ninput_sizes = [\"256x192\", \"320 x 240\"]\n",
        );
        let c = Config::load(Some(&path), vec![]).unwrap();
        assert_eq!(
            c.segmentation.input_sizes_finest_first(),
            vec![(320, 240), (256, 192)]
        );
        let env = vec![(
            "LANDING__SEGMENTATION__INPUT_SIZES".to_owned(),
            "256x192, 320X240".to_owned(),
        )];
        let c = Config::load(None, [no_model(), env].concat()).unwrap();
        assert_eq!(
            c.segmentation.input_sizes_finest_first(),
            vec![(320, 240), (256, 192)]
        );
        let env = vec![(
            "LANDING__SEGMENTATION__INPUT_SIZES".to_owned(),
            String::new(),
        )];
        let c = Config::load(None, [no_model(), env].concat()).unwrap();
        assert!(
            c.segmentation.input_sizes.is_empty(),
            "\"\" is the model's own size"
        );
        let env = vec![(
            "LANDING__SEGMENTATION__INPUT_SIZES".to_owned(),
            "320x240,tiny".to_owned(),
        )];
        let e = Config::load(None, [no_model(), env].concat())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("segmentation.input_sizes") && e.contains("tiny"),
            "{e}"
        );
    }

    /// The shipped config files set every key the server has, each to its default but for the
    /// deployment's own choices, and load as they are (the model path aside).
    #[test]
    fn shipped_config_files_list_every_key() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
        let keys = |table: &toml::Table| -> Vec<String> {
            table
                .iter()
                .flat_map(|(section, values)| {
                    let values = values.as_table().expect("a [section]");
                    values.keys().map(move |key| format!("{section}.{key}"))
                })
                .collect()
        };
        let mut every = keys(&defaults_table());
        every.sort();
        for file in ["deploy/config/server.toml", "deploy/k8s/base/server.toml"] {
            let path = root.join(file);
            let text = std::fs::read_to_string(&path).unwrap();
            let mut listed = keys(&text.parse().unwrap());
            listed.sort();
            assert_eq!(listed, every, "{file} lists every key, once");
            let model = root.join("models/rooftop-segmentation.onnx");
            let env = vec![
                (
                    "LANDING__SEGMENTATION__MODEL_PATH".to_owned(),
                    model.display().to_string(),
                ),
                ("LANDING__AUTH__TOKENS_FILE".to_owned(), String::new()),
            ];
            let c = Config::load(Some(&path), env).unwrap_or_else(|e| panic!("{file}: {e}"));
            assert_eq!(c.fusion, FusionConfig::default(), "{file}");
            assert_eq!(
                c.segmentation.input_sizes,
                Config::default().segmentation.input_sizes
            );
        }
    }
}
