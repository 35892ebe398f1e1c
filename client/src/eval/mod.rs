//! `landing eval`: landing quality against simulator ground truth.
//!
//! For every frame of a recording with ground truth and every returned site, the evaluation
//! checks that the safe circle is clear of every true obstacle footprint and inside the roof
//! (with the declared polylabel precision as tolerance), compares the returned radius with the
//! true best radius on that roof, measures the IoU of the returned landing polygons with the true
//! landable area in the scanned region, and tallies what happened to each obstacle class. It runs
//! three modes side by side on the same frames ([`Mode`]): geometry only, the server's
//! segmentation model, and the cloud's true classes.
//!
//! The metrics are pure functions ([`metrics::evaluate_frame`]) on domain types
//! ([`metrics::Site`], [`metrics::RoofTruth`]); [`report::summarize`] aggregates them and
//! [`report::write_report`] writes the Markdown, JSON and PNG charts.
//!
//! ```
//! use landing_client::eval::geom::Polygon2;
//! use landing_client::eval::metrics::{MetricsParams, Obstacle, RoofTruth, Site, evaluate_frame};
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

pub mod cli;
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
