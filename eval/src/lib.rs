//! Landing quality against simulator ground truth: what `landing eval` runs.
//!
//! For every frame of a recording with ground truth and every returned site, the evaluation
//! checks that the safe circle is clear of every true obstacle footprint and inside the roof
//! (with the declared polylabel precision as tolerance), compares the returned radius with the
//! true best radius on that roof, measures the IoU of the returned landing polygons with the true
//! landable area in the scanned region, and tallies what happened to each obstacle class. It runs
//! three modes side by side on the same frames ([`Mode`]): geometry only, the server's
//! segmentation model, and the cloud's true classes.
//!
//! With `--stream` ([`run::EvalConfig::stream`]) each approach (the frames of one recording, in
//! sequence order) is also sent as one fused stream per mode, and the report sets the fused
//! answers (columns `<mode> fused`) beside the single-frame ones. A fused answer is judged
//! against what the approach has scanned so far ([`approach::fused_roofs`]: the convex hull of
//! the union of every frame's scan on each roof up to this one), a single-frame answer against
//! its own frame's scan; the safety rules are the same. The approach breakdown
//! ([`approach::breakdown`]) splits every column by the last quarter of each approach, time since
//! the approach started and the camera's height above the target roof.
//!
//! The metrics are pure functions ([`metrics::evaluate_frame`]) on domain types
//! ([`metrics::Site`], [`metrics::RoofTruth`]); [`report::summarize`] aggregates them and
//! [`report::write_report`] writes the Markdown, JSON and PNG charts; [`run::run`] sends the
//! scenarios ([`truth::load_scenarios`], read with `landing_recording`) through the real service
//! with the SDK (unary calls, then fused streams). The crate scores answers; it never
//! re-implements the pipeline, and fusion is the server's.
//!
//! ```
//! use landing_eval::geom::Polygon2;
//! use landing_eval::metrics::{MetricsParams, Obstacle, RoofTruth, Site, evaluate_frame};
//!
//! // A 20 × 10 m roof with a 2 × 2 m AC unit; the site's circle overlaps the unit by 1 m.
//! let roof = RoofTruth {
//!     id: 0,
//!     outline: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
//!     interior: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
//!     height_m: 30.0,
//!     obstacles: vec![Obstacle { class: 8, footprint: Polygon2::rect([4.0, 4.0], [6.0, 6.0]), seen: true }],
//!     scanned: None,
//!     hidden: vec![],
//!     in_sight: None,
//!     stated_best_radius_m: None,
//!     scored: true,
//!     target: true,
//! };
//! let site = Site {
//!     rank: 1,
//!     polygon: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
//!     center: [7.5, 5.0],
//!     plane_height_m: 30.0,
//!     radius_m: 2.5,
//! };
//! let eval = evaluate_frame(&[site], &[roof], &MetricsParams::default());
//! assert!(!eval.sites[0].verdict.is_safe());
//! assert!(eval.roofs[0].iou > 0.97); // the polygon only misses the 4 m² unit
//! ```

#![forbid(unsafe_code)]

pub mod approach;
pub mod catalog;
pub mod geom;
pub mod metrics;
pub mod overlay;
pub mod plot;
pub mod report;
pub mod run;
pub mod stats;
pub mod truth;

pub use metrics::{MetricsParams, evaluate_frame};
pub use report::{FrameRecord, Mode, Summary, Targets, summarize, write_report};

/// Everything that can go wrong in an evaluation. Messages name the file or value at fault.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// The service or the SDK failed.
    #[error(transparent)]
    Client(#[from] landing_client::ClientError),
    /// A scenario recording could not be read.
    #[error("recording `{path}`: {source}")]
    Recording {
        path: String,
        #[source]
        source: landing_recording::Error,
    },
    /// A report file or folder could not be written.
    #[error("cannot write `{path}`: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A chart could not be encoded.
    #[error("image `{path}`: {reason}")]
    Image { path: String, reason: String },
    /// An input is unusable (no ground truth, a frame without a cloud, ...).
    #[error("invalid `{field}`: {reason}")]
    Invalid { field: &'static str, reason: String },
}
