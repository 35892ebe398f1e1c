//! What every subcommand shares: how to reach the server, the exit codes, and the error that
//! carries one of them.

use std::path::PathBuf;
use std::time::Duration;

use clap::Args;
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use landing_client::{ClientConfig, ClientError, LandingClient, TlsConfig};
use landing_proto::v1::SegmentationMode;

/// Process exit codes of `landing`.
pub mod exit {
    /// Success.
    pub const OK: u8 = 0;
    /// Any other error.
    pub const ERROR: u8 = 1;
    /// Bad command line.
    pub const USAGE: u8 = 2;
    /// The server could not be reached.
    pub const UNREACHABLE: u8 = 3;
    /// Some frames were answered with an error.
    pub const FRAMES_FAILED: u8 = 4;
    /// A load test saw a frame unanswered or answered twice.
    pub const INTEGRITY: u8 = 5;
    /// The server refused the credentials.
    pub const AUTH: u8 = 6;
}

/// How to reach the server; the same options as the server's TLS and auth settings. Listed
/// under their own heading in `--help`.
#[derive(Debug, Clone, Args)]
#[command(next_help_heading = "Connection")]
pub struct ConnectionArgs {
    /// Server URL (`https://` for TLS).
    #[arg(long, global = true, env = "LANDING_SERVER", default_value = landing_client::DEFAULT_SERVER)]
    pub server: String,
    /// Bearer token.
    #[arg(long, global = true, env = "LANDING_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// CA certificate (PEM) that signed the server's certificate.
    #[arg(long, global = true)]
    pub ca_cert: Option<PathBuf>,
    /// Client certificate (PEM) for mutual TLS.
    #[arg(long, global = true, requires = "client_key")]
    pub client_cert: Option<PathBuf>,
    /// Client key (PEM) for mutual TLS.
    #[arg(long, global = true, requires = "client_cert")]
    pub client_key: Option<PathBuf>,
    /// Name to check the server certificate against, when it differs from the URL's host.
    #[arg(long, global = true)]
    pub tls_domain: Option<String>,
    /// Seconds to wait for the connection.
    #[arg(long, global = true, default_value_t = 5.0)]
    pub connect_timeout: f64,
    /// Deadline of each unary call, seconds.
    #[arg(long, global = true, default_value_t = 60.0)]
    pub timeout: f64,
}

/// `--segmentation`: the API's `SegmentationMode` by its command-line name
/// ([`SegmentationMode::cli_name`]: `auto`, `model`, `point-classes`, `none`, `class-image`).
pub fn segmentation_parser() -> impl TypedValueParser<Value = SegmentationMode> {
    let values = SegmentationMode::all()
        .map(|m| PossibleValue::new(m.cli_name()).help(segmentation_help(m)));
    PossibleValuesParser::new(values).try_map(|name: String| {
        SegmentationMode::from_cli_name(&name).ok_or_else(|| format!("unknown mode `{name}`"))
    })
}

/// What each `--segmentation` value does, for `--help`.
fn segmentation_help(mode: SegmentationMode) -> &'static str {
    match mode {
        SegmentationMode::Unspecified => {
            "The server decides: the model when the frame has an image"
        }
        SegmentationMode::Model => "The server's segmentation model",
        SegmentationMode::ClassImage => {
            "The recording's label images (`/camera/labels`, the simulator's ground truth) sent \
             as each frame's class image, as a drone with its own segmentation would"
        }
        SegmentationMode::PointClasses => {
            "The classes carried by the point cloud (ground truth in recordings)"
        }
        SegmentationMode::None => "Geometry only",
    }
}

/// A failure with the exit code it maps to.
#[derive(Debug)]
pub struct CliError {
    /// One of [`exit`].
    pub code: u8,
    /// What to tell the user.
    pub message: String,
}

impl From<ClientError> for CliError {
    fn from(e: ClientError) -> Self {
        let code = if e.is_unreachable() {
            exit::UNREACHABLE
        } else if matches!(
            e.code(),
            Some(tonic::Code::Unauthenticated | tonic::Code::PermissionDenied)
        ) {
            exit::AUTH
        } else if matches!(e.code(), Some(tonic::Code::DeadlineExceeded)) {
            exit::UNREACHABLE
        } else {
            exit::ERROR
        };
        let mut message = e.to_string();
        if let ClientError::Status(f) = &e {
            message = format!("server answered {f}");
        }
        Self { code, message }
    }
}

pub fn usage(message: impl Into<String>) -> CliError {
    CliError {
        code: exit::USAGE,
        message: message.into(),
    }
}

/// The client configuration described by the connection flags.
pub fn client_config(c: &ConnectionArgs) -> Result<ClientConfig, CliError> {
    let mut config = ClientConfig::new(c.server.clone());
    config.token = c.token.clone().filter(|t| !t.is_empty());
    if !(c.connect_timeout > 0.0 && c.connect_timeout.is_finite()) {
        return Err(usage(format!(
            "--connect-timeout {} must be positive",
            c.connect_timeout
        )));
    }
    if !(c.timeout > 0.0 && c.timeout.is_finite()) {
        return Err(usage(format!("--timeout {} must be positive", c.timeout)));
    }
    config.connect_timeout = Duration::from_secs_f64(c.connect_timeout);
    config.request_timeout = Some(Duration::from_secs_f64(c.timeout));
    if c.ca_cert.is_some() || c.client_cert.is_some() || c.server.starts_with("https://") {
        let mut tls = TlsConfig::from_files(
            c.ca_cert.as_deref(),
            c.client_cert.as_deref(),
            c.client_key.as_deref(),
        )?;
        tls.domain_name = c.tls_domain.clone();
        config.tls = Some(tls);
    }
    Ok(config)
}

pub async fn connect(c: &ConnectionArgs) -> Result<LandingClient, CliError> {
    let config = client_config(c)?;
    match LandingClient::connect(config).await {
        Ok(client) => Ok(client),
        Err(e @ ClientError::InvalidConfig { .. }) => Err(usage(e.to_string())),
        Err(e) => Err(e.into()),
    }
}

pub fn io(e: std::io::Error) -> CliError {
    CliError {
        code: exit::ERROR,
        message: format!("cannot write output: {e}"),
    }
}

impl From<landing_recording::Error> for CliError {
    fn from(e: landing_recording::Error) -> Self {
        Self {
            code: exit::ERROR,
            message: e.to_string(),
        }
    }
}

impl From<landing_eval::EvalError> for CliError {
    fn from(e: landing_eval::EvalError) -> Self {
        match e {
            landing_eval::EvalError::Client(e) => e.into(),
            other => Self {
                code: exit::ERROR,
                message: other.to_string(),
            },
        }
    }
}
