//! The rooftop landing-site service: the `landing.v1` gRPC server, its pipeline orchestration,
//! and the offline `detect` command.
//!
//! Main types and entry points:
//! - [`Config`] — the TOML/env/flag configuration ([`Config::load`], [`Config::default`]), with
//!   public fields mirroring the file's sections (`server`, `pipeline`, `segmentation`, `auth`,
//!   `tls`, `log`, `fusion`, `catalog`). Validated before anything binds.
//! - The fleet's landing-site catalog (`[catalog]`, on by default with `data/catalog.sqlite`):
//!   fused streams whose frames carry a geodetic origin feed it through a bounded queue that the
//!   frame path never waits on, and `SearchLandingSites` reads it; tests that start servers turn
//!   it off or give it a file of their own.
//! - [`start`] → [`RunningServer`] (`addr`, `metrics_addr`, [`RunningServer::shutdown`]) and
//!   [`serve`] (runs until a shutdown future resolves): the server with health, reflection, auth,
//!   TLS, metrics and graceful drain, on a listener the caller bound (use `127.0.0.1:0` in tests).
//! - [`run_pipeline`] — the same computation in process, synchronously, on a validated
//!   [`pipeline::Frame`]; [`convert`] turns `landing.v1` messages into frames and results back,
//!   so a test can compare the service's answer with the in-process one.
//! - [`cli_main`] — the binary's `main`, for tests that re-execute their own test binary as a
//!   real server process (and send it SIGTERM).
//!
//! Notes for tests that start the server in process:
//! - `Config::default()` has `segmentation.enabled = true` with the relative
//!   `models/rooftop-segmentation.onnx`; relative paths resolve against the current directory
//!   (a test's is its crate directory), so set an absolute `model_path` or disable segmentation.
//!   The model needs the ONNX Runtime library (`scripts/setup-ort.sh`).
//! - Set `server.metrics_listen = "127.0.0.1:0"` (or `""` to disable); the bound address is
//!   [`RunningServer::metrics_addr`], and [`telemetry::scrape`] fetches `/metrics` from it.
//! - [`cli::cli_main_from`] takes explicit arguments, e.g.
//!   `["landing-server", "serve", "--listen", "127.0.0.1:0"]`; `serve` logs
//!   `serving landing.v1` with an `addr` field once bound (`LANDING__LOG__FORMAT=json` gives a
//!   parseable line) and exits 0 after SIGTERM/SIGINT and the drain.
//!
//! The handlers are thin: validate and convert ([`convert`]), hand the frame to the worker pool,
//! convert back. Errors are one enum, [`Error`], mapped to gRPC statuses in one place
//! ([`status`]).
//!
//! ```
//! use landing_server::{Config, start};
//!
//! let mut config = Config::default();
//! config.segmentation.enabled = false; // no model file needed
//! config.catalog.enabled = false; // no catalog file written
//! config.server.metrics_listen = "127.0.0.1:0".into();
//! let runtime = tokio::runtime::Runtime::new().unwrap();
//! runtime.block_on(async {
//!     let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
//!     let server = start(config, listener).await.unwrap();
//!     assert_ne!(server.addr.port(), 0);
//!     assert!(server.metrics_addr.is_some());
//!     server.shutdown().await.unwrap();
//! });
//! ```
//!
//! In-process pipeline on a converted request (what the service computes for that frame):
//!
//! ```
//! use landing_proto::v1;
//! use landing_server::{convert, pipeline::Pipeline, run_pipeline};
//!
//! let points: Vec<f32> = vec![0.0, 0.0, 10.0, 1.0, 0.0, 10.0, 0.0, 1.0, 10.0];
//! let request = v1::DetectLandingSitesRequest {
//!     frame: Some(v1::Frame {
//!         sequence: 3,
//!         point_cloud: Some(convert::packed_xyz(&points)),
//!         ..Default::default()
//!     }),
//!     options: None,
//! };
//! let pipeline = Pipeline::default();
//! let (frame, options) = convert::request_parts(&request, &pipeline.defaults).unwrap();
//! let output = run_pipeline(&frame, &options, &pipeline).unwrap();
//! assert_eq!(output.sequence, 3);
//! assert_eq!(output.point_count, 3);
//! ```

#![forbid(unsafe_code)]

mod auth;
mod catalog;
pub mod cli;
pub mod config;
pub mod convert;
pub mod detect;
mod error;
pub mod frame;
mod limit;
mod live;
pub mod pipeline;
pub mod segmentation;
pub mod server;
mod service;
pub mod status;
pub mod telemetry;
mod workers;

pub use cli::cli_main;
pub use config::Config;
pub use error::{Error, FieldViolation};
pub use pipeline::run_pipeline;
pub use server::{RunningServer, serve, start};
