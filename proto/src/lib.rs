//! The `landing.v1` API of the rooftop landing-site service.
//!
//! This crate holds only what is generated from `proto/landing/v1/*.proto`: the message types
//! ([`v1::Frame`], [`v1::FrameResult`], [`v1::LandingSite`], ...), the tonic client and server
//! stubs ([`v1::landing_service_client`], [`v1::landing_service_server`]), the `google.rpc` status
//! and error-detail messages the API sends, and the encoded [`FILE_DESCRIPTOR_SET`] used by server
//! reflection and by MCAP recordings as their schema, and [`STAGES`], the names of
//! [`v1::StageTimings`]'s steps with their fields in that order. Beside them: the packed
//! point-cloud layout ([`cloud`]: the one writer and reader), and accessors for the common reads
//! of a result ([`v1::FrameResult::best`], [`v1::LandingSite::shell`], ...). Scan and image
//! bytes are [`prost::bytes::Bytes`], so a frame clones in O(1).
//!
//! ```
//! use landing_proto::v1::{FrameResult, LandingSite, PipelineOptions, SemanticClass, Vector3};
//!
//! // Packed point classes use the enum's numbers; 0 means unknown.
//! assert_eq!(SemanticClass::BuildingRooftop as i32, 4);
//! let options = PipelineOptions { max_triangle_edge_m: Some(4.0), ..Default::default() };
//! assert_eq!(options.min_normal_dot, None);
//!
//! let site = LandingSite { center: Some(Vector3 { x: 1.0, y: 2.0, z: 3.0 }), ..Default::default() };
//! let result = FrameResult { sites: vec![site], ..Default::default() };
//! let best = result.best().expect("a site");
//! assert_eq!(best.center_xyz(), Some([1.0, 2.0, 3.0]));
//! assert!(best.shell().is_empty() && best.lat_lon().is_none());
//! ```

#![forbid(unsafe_code)]

pub mod cloud;
#[cfg(feature = "json")]
pub mod json;

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

/// Converts a protobuf duration to a std one; negative durations give `None`.
pub fn duration_from_proto(d: prost_types::Duration) -> Option<std::time::Duration> {
    if d.seconds < 0 || d.nanos < 0 {
        return None;
    }
    Some(std::time::Duration::new(d.seconds as u64, d.nanos as u32))
}

impl v1::FrameResult {
    /// The best site (rank 1, the largest safe radius), if any.
    pub fn best(&self) -> Option<&v1::LandingSite> {
        self.sites.first()
    }
}

impl v1::LandingSite {
    /// The polygon's outer ring (counter-clockwise, world xyz); empty when there is none.
    pub fn shell(&self) -> &[v1::Vector3] {
        self.polygon
            .as_ref()
            .and_then(|p| p.shell.as_ref())
            .map_or(&[], |r| r.points.as_slice())
    }

    /// The polygon's holes (obstacles, clockwise); empty when there are none.
    pub fn holes(&self) -> &[v1::LinearRing] {
        self.polygon.as_ref().map_or(&[], |p| p.holes.as_slice())
    }

    /// The safest point, world `[x, y, z]`.
    pub fn center_xyz(&self) -> Option<[f64; 3]> {
        self.center.as_ref().map(v1::Vector3::to_array)
    }

    /// The safest point in WGS-84 `(latitude, longitude)` degrees, when the frame carried a
    /// geodetic origin.
    pub fn lat_lon(&self) -> Option<(f64, f64)> {
        self.center_geodetic
            .as_ref()
            .map(|g| (g.latitude_deg, g.longitude_deg))
    }
}

impl v1::SegmentationMode {
    /// Every mode, in number order (UNSPECIFIED first).
    pub fn all() -> impl Iterator<Item = Self> {
        (0..).map_while(|n| Self::try_from(n).ok())
    }

    /// The mode's name on the command lines (`landing`, `landing-server detect`): `auto` for
    /// UNSPECIFIED (the server decides), otherwise the proto name in kebab case (`class-image`).
    pub fn cli_name(self) -> &'static str {
        match self {
            Self::Unspecified => "auto",
            Self::Model => "model",
            Self::PointClasses => "point-classes",
            Self::None => "none",
            Self::ClassImage => "class-image",
        }
    }

    /// The mode named [`Self::cli_name`].
    pub fn from_cli_name(name: &str) -> Option<Self> {
        Self::all().find(|m| m.cli_name() == name)
    }
}

impl v1::Vector3 {
    /// `[x, y, z]`.
    pub fn to_array(&self) -> [f64; 3] {
        [self.x, self.y, self.z]
    }
}

/// The encoded `google.protobuf.FileDescriptorSet` of every `.proto` file of the API, with imports.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/landing_descriptor.bin"));

#[cfg(test)]
mod tests {
    use super::v1::SegmentationMode;

    #[test]
    fn every_segmentation_mode_has_a_cli_name_that_parses_back() {
        let modes: Vec<_> = SegmentationMode::all().collect();
        assert_eq!(modes.len(), 5);
        for m in modes {
            let kebab = m.as_str_name()["SEGMENTATION_MODE_".len()..]
                .to_lowercase()
                .replace('_', "-");
            let expected = if m == SegmentationMode::Unspecified {
                "auto"
            } else {
                &kebab
            };
            assert_eq!(m.cli_name(), expected);
            assert_eq!(SegmentationMode::from_cli_name(m.cli_name()), Some(m));
        }
    }
}
