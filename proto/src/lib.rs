//! The `landing.v1` API of the rooftop landing-site service.
//!
//! This crate holds only what is generated from `proto/landing/v1/*.proto`: the message types
//! ([`v1::Frame`], [`v1::FrameResult`], [`v1::LandingSite`], ...), the tonic client and server
//! stubs ([`v1::landing_service_client`], [`v1::landing_service_server`]), the `google.rpc` status
//! and error-detail messages the API sends, and the encoded [`FILE_DESCRIPTOR_SET`] used by server
//! reflection and by MCAP recordings as their schema, and [`STAGES`], the names of
//! [`v1::StageTimings`]'s steps with their fields in that order. It holds no other logic.
//!
//! ```
//! use landing_proto::v1::{SemanticClass, PipelineOptions};
//!
//! // Packed point classes use the enum's numbers; 0 means unknown.
//! assert_eq!(SemanticClass::BuildingRooftop as i32, 4);
//! let options = PipelineOptions { max_triangle_edge_m: Some(4.0), ..Default::default() };
//! assert_eq!(options.min_normal_dot, None);
//! ```

#![forbid(unsafe_code)]

/// The `landing` package tree, laid out as protobuf packages so generated paths resolve.
pub mod landing {
    /// `landing.v1`: frames, options, results and the `LandingService`.
    pub mod v1 {
        #![allow(missing_docs)]
        // Generated `oneof` enums hold a whole `FrameResult` beside small variants; boxing them
        // would change the generated API for no measurable gain.
        #![allow(clippy::large_enum_variant)]
        tonic::include_proto!("landing.v1");
    }
}

pub use landing::v1;

/// The `google.rpc` messages used in per-frame errors of the stream.
pub mod google {
    /// `google.rpc`: `Status`, `BadRequest`, `RetryInfo`.
    pub mod rpc {
        #![allow(missing_docs)]
        tonic::include_proto!("google.rpc");
    }
}

/// The encoded `google.protobuf.FileDescriptorSet` of every `.proto` file of the API, with imports.
/// The steps of [`v1::StageTimings`], by field name, in pipeline order (`queue` first, `total`
/// last): the one list the server's metrics, the command line's JSON and the evaluation use.
pub const STAGES: [&str; 11] = [
    "queue",
    "decode",
    "segmentation",
    "classification",
    "fusion",
    "triangulation",
    "triangle_filter",
    "plane_extraction",
    "polygon_extraction",
    "polylabel",
    "total",
];

impl v1::StageTimings {
    /// Each step's time, in [`STAGES`] order.
    pub fn by_stage(&self) -> [Option<prost_types::Duration>; 11] {
        [
            self.queue,
            self.decode,
            self.segmentation,
            self.classification,
            self.fusion,
            self.triangulation,
            self.triangle_filter,
            self.plane_extraction,
            self.polygon_extraction,
            self.polylabel,
            self.total,
        ]
    }
}

pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/landing_descriptor.bin"));
