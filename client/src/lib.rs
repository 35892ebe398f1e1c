//! Client SDK of the rooftop landing-site service, and the `landing` command line.
//!
//! A fleet back-end connects with a [`ClientConfig`] (endpoint, bearer token, TLS), then either
//! asks for one frame at a time with [`LandingClient::detect`] (retried with backoff on
//! `UNAVAILABLE`/`RESOURCE_EXHAUSTED`, honouring the server's `RetryInfo`), or streams frames with
//! [`LandingClient::open_stream`] and reads one [`StreamItem`] per frame, whose
//! [`FrameOutcome`] is a result, an error (with the decoded `BadRequest` field violations), or a
//! skip. Frames are built from raw buffers with [`PointCloudBuilder`], [`camera_image`] and
//! [`FrameBuilder`]. The wire types are the generated `landing_proto::v1` messages.
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
//! Connecting needs a running server (`landing-server`):
//!
//! ```no_run
//! # async fn demo(frame: landing_proto::v1::Frame) -> Result<(), landing_client::ClientError> {
//! use landing_client::{ClientConfig, LandingClient};
//! let client = LandingClient::connect(ClientConfig::new("http://127.0.0.1:50051")).await?;
//! let result = client.detect(frame).await?;
//! println!("{} sites", result.sites.len());
//! # Ok(()) }
//! ```

#![forbid(unsafe_code)]

pub mod cli;
mod client;
mod config;
mod error;
pub mod eval;
mod frame;
pub mod loadtest;
mod outcome;
pub mod recording;
pub mod render;

pub use client::{FrameSender, LandingClient, ResultStream, ServingStatus, StreamConfig};
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
