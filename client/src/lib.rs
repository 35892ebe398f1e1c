//! Client SDK of the rooftop landing-site service.
//!
//! A fleet back-end connects with a [`ClientConfig`] (endpoint, bearer token, TLS), then either
//! asks for one frame at a time with [`LandingClient::detect`] (retried with backoff on
//! `UNAVAILABLE`/`RESOURCE_EXHAUSTED`, honouring the server's `RetryInfo`), or streams frames with
//! [`LandingClient::open_stream`] and reads one [`StreamItem`] per frame, whose
//! [`FrameOutcome`] is a result, an error (with the decoded `BadRequest` field violations), or a
//! skip. The fleet's landing-site catalog is searched by place with
//! [`LandingClient::search_landing_sites`] ([`SiteSearch`] builds the request); what it returns is
//! a candidate for a drone to confirm with its own stream, never a clearance to land.
//! Frames are built from raw buffers with [`PointCloudBuilder`], [`camera_image`] and
//! [`FrameBuilder`]. The wire types are the generated `landing_proto::v1` messages, re-exported as
//! [`v1`], with accessors for the common reads of an answer ([`v1::FrameResult::best`],
//! [`v1::LandingSite::shell`], [`v1::LandingSite::holes`], [`v1::LandingSite::center_xyz`],
//! [`v1::LandingSite::lat_lon`]); scans and images are [`Bytes`], so a retried frame is not
//! copied.
//!
//! A fused approach in three lines: connect, open a fused stream, read the answers (compiled, not
//! run: it needs a running `landing-server`):
//!
//! ```no_run
//! # async fn demo(frames: Vec<landing_client::v1::Frame>) -> Result<(), landing_client::ClientError> {
//! use landing_client::{ClientConfig, LandingClient, StreamConfig};
//!
//! let client = LandingClient::connect(ClientConfig::new("http://127.0.0.1:50051")).await?;
//! let mut answers = client.stream(tokio_stream::iter(frames), StreamConfig::fused());
//! while let Some(item) = answers.next().await {
//!     if let Some(best) = item?.outcome.result().and_then(|r| r.best()) {
//!         println!("land at {:?}, {:.1} m clear", best.center_xyz(), best.safe_radius_m);
//!     }
//! }
//! # Ok(()) }
//! ```
//!
//! Streams fuse unless they opt out: `StreamConfig::single_frame()` judges every frame alone, as
//! `detect` does (the paper's single-frame method), and no setting can send fusion options that
//! are not applied.
//!
//! ```
//! use landing_client::{StreamConfig, StreamMode};
//!
//! assert!(matches!(StreamConfig::default().mode, StreamMode::Fused(_)));
//! assert_eq!(StreamConfig::single_frame().mode, StreamMode::SingleFrame);
//! ```
//!
//! The crate is what a fleet back end adds to its build: tonic, prost, tokio and what they need.
//! The `landing` command line (`landing-cli`), the evaluation (`landing-eval`) and the file
//! formats (`landing-recording`) are crates of their own.
//!
//! ```
//! use landing_client::{FrameBuilder, PointCloudBuilder, unpack_point_cloud};
//!
//! let points = [[0.0f32, 0.0, 10.0], [1.0, 0.0, 10.0], [0.0, 1.0, 10.0]];
//! let cloud = PointCloudBuilder::new(&points).classes(&[4, 4, 4]).build()?;
//! assert_eq!(cloud.point_stride, 13); // x, y, z float32 + class byte
//! let frame = FrameBuilder::new(1, cloud).drone_id("drone-7").build();
//! let back = unpack_point_cloud(frame.point_cloud.as_ref().unwrap())?;
//! assert_eq!(back.points, points);
//! assert_eq!(back.classes.as_deref(), Some(&[4u8, 4, 4][..]));
//! # Ok::<(), landing_client::ClientError>(())
//! ```
//!
//! One frame at a time, and a stream fed from a task of its own (compiled, not run):
//!
//! ```no_run
//! # async fn demo(frames: Vec<landing_client::v1::Frame>) -> Result<(), landing_client::ClientError> {
//! use landing_client::{ClientConfig, FrameOutcome, LandingClient, StreamConfig};
//!
//! let config = ClientConfig::new("http://127.0.0.1:50051").with_token("t");
//! let client = LandingClient::connect(config).await?;
//! // One frame, retried on UNAVAILABLE / RESOURCE_EXHAUSTED.
//! let result = client.detect(frames[0].clone()).await?;
//! println!("{} sites", result.sites.len());
//!
//! // A stream: `send` waits while `max_in_flight` frames are unanswered, so frames go out from
//! // their own task while this one reads the answers, one per frame, in order.
//! let (mut tx, mut rx) = client.open_stream(StreamConfig::default());
//! tokio::spawn(async move {
//!     for frame in frames {
//!         if tx.send(frame).await.is_err() {
//!             break;
//!         }
//!     }
//!     tx.finish();
//! });
//! while let Some(item) = rx.next().await {
//!     match item?.outcome {
//!         FrameOutcome::Result(r) => println!("{} sites, best first", r.sites.len()),
//!         FrameOutcome::Error(e) => println!("{}: {:?}", e.code, e.field_violations),
//!         FrameOutcome::Skipped { superseded_by } => println!("skipped for {superseded_by}"),
//!     }
//! }
//! # Ok(()) }
//! ```

#![forbid(unsafe_code)]

mod client;
mod config;
mod error;
mod frame;
mod outcome;
mod search;

pub use client::{
    FrameSender, LandingClient, ResultStream, ServingStatus, StreamConfig, StreamMode,
};
pub use config::{ClientConfig, DEFAULT_SERVER, RetryPolicy, TlsConfig};
pub use error::ClientError;
pub use frame::{
    FrameBuilder, ImageData, PointCloudBuilder, RigidTransform, UnpackedCloud, camera_image,
    identity_pose, intrinsics, intrinsics_from_fov, pose, unpack_point_cloud,
};
pub use landing_proto::v1;
pub use outcome::{
    FieldViolation, FrameError, FrameOutcome, StreamItem, code_label, duration_from_proto,
};
pub use prost::bytes::Bytes;
pub use search::SiteSearch;
