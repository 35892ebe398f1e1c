//! Landing-site geometry: the paper's Polylidar pipeline and polylabel, with no I/O, async or
//! protobuf. (Skeleton: the contract other crates build against; modules fill it in.)

#![forbid(unsafe_code)]

pub mod class;

use std::time::Duration;

pub use class::SemanticClass;

/// Parameters of the whole pipeline. `Default` gives the paper's values.
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// `l_max`: triangles with a longer (3-D) edge are dropped, metres.
    pub l_max_m: f64,
    /// `dot_min`: minimum `|n · k|` of a triangle's unit normal.
    pub dot_min: f64,
    /// `z_min`: triangles whose vertical extent is below this bypass the normal test, metres.
    pub z_min_m: f64,
    /// `V`: point classes allowed in a landing plane. Ignored when the cloud has no classes.
    pub landable_classes: Vec<u8>,
    /// Planar regions with fewer triangles are discarded.
    pub min_region_triangles: usize,
    /// Polylabel precision: the returned radius is within this of the optimum, metres.
    pub polylabel_precision_m: f64,
    /// Sites with a smaller safe radius are dropped, metres.
    pub min_safe_radius_m: f64,
    /// Sites with a smaller area are dropped, square metres.
    pub min_area_m2: f64,
    /// Holes smaller than this are removed before polylabel, square metres.
    pub min_hole_area_m2: f64,
    /// At most this many sites are returned.
    pub max_sites: usize,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            l_max_m: 4.0,
            dot_min: 0.96,
            z_min_m: 0.10,
            landable_classes: vec![SemanticClass::BuildingRooftop as u8],
            min_region_triangles: 10,
            polylabel_precision_m: 0.5,
            min_safe_radius_m: 0.0,
            min_area_m2: 0.0,
            min_hole_area_m2: 0.0,
            max_sites: 16,
        }
    }
}

/// A polygon with holes in the plane of a landing site. Shell counter-clockwise, holes clockwise
/// (seen from above), rings not closed (last point is not a copy of the first).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Polygon {
    pub shell: Vec<[f64; 2]>,
    pub holes: Vec<Vec<[f64; 2]>>,
}

/// One ranked landing site.
#[derive(Debug, Clone, PartialEq)]
pub struct LandingSite {
    /// 1 is best (largest safe radius).
    pub rank: u32,
    /// The flat, obstacle-free area, x/y in the input's coordinates.
    pub polygon: Polygon,
    /// Mean z of the region's points.
    pub plane_height_m: f64,
    /// Pole of inaccessibility: x, y, and z on the plane.
    pub center: [f64; 3],
    /// Distance from `center` to the nearest edge or hole, within the precision of the optimum.
    pub safe_radius_m: f64,
    /// Polygon area (shell minus holes), square metres.
    pub area_m2: f64,
    /// Unit normal of the region's plane, z up.
    pub normal: [f64; 3],
    pub point_count: usize,
    pub triangle_count: usize,
}

/// Wall-clock time of each step of one run.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepTimings {
    pub triangulation: Duration,
    pub triangle_filter: Duration,
    pub plane_extraction: Duration,
    pub polygon_extraction: Duration,
    pub polylabel: Duration,
}

/// The result of one run of the pipeline.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Detection {
    /// Best first.
    pub sites: Vec<LandingSite>,
    pub point_count: usize,
    pub triangle_count: usize,
    pub timings: StepTimings,
}

/// Everything that can go wrong in this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GeometryError {
    /// A parameter is out of its valid range.
    #[error("parameter `{field}` = {value} is out of range: {reason}")]
    InvalidParameter { field: &'static str, value: String, reason: &'static str },
    /// A coordinate is NaN, infinite, or of absurd magnitude.
    #[error("point {index} has a non-finite or out-of-range coordinate {value}")]
    InvalidPoint { index: usize, value: f64 },
    /// `classes` does not have one entry per point.
    #[error("{classes} classes given for {points} points")]
    ClassCountMismatch { points: usize, classes: usize },
}

/// Runs the whole pipeline on `points` (x, y, z in a frame with z up) and optional per-point
/// classes (values of [`SemanticClass`], 0 = unknown).
pub fn detect(
    points: &[[f32; 3]],
    classes: Option<&[u8]>,
    params: &Params,
) -> Result<Detection, GeometryError> {
    let _ = (points, classes, params);
    Ok(Detection::default())
}
