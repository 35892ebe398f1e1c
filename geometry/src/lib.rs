//! Landing-site geometry: the paper's Polylidar pipeline and polylabel, with no I/O, async,
//! logging configuration or protobuf.
//!
//! Given a point cloud (x, y, z with z up) and, optionally, one semantic class per point, [`detect`]
//! finds the flat, obstacle-free places and returns them as polygons with holes, each with the point
//! farthest from every edge and obstacle and that distance (the *safe radius*), best first. Its one
//! input, [`Cloud`], holds the points, their classes, what safe circles must keep clear of
//! ([`KeepClear`]), optionally their triangulation made beforehand, and the [`CloudKind`]: a single
//! scan, or a fused map's dense cells, for which three of the steps below read the points'
//! density (explained on [`CloudKind`]).
//!
//! 1. [`triangulation`]: 2-D Delaunay triangulation of the points' x/y (exact predicates);
//! 2. [`filter`]: the paper's Algorithm 1 (edge length, normal, height bypass, classes);
//! 3. [`regions`]: the paper's Algorithm 2, region growing over triangle adjacency;
//! 4. [`boundary`]: each region's boundary half-edges walked into an OGC-valid polygon with holes,
//!    less the regions the cloud's levels show are no roof ([`levels`]: a small platform well
//!    above a larger roof, a street called roof);
//! 5. [`polylabel`]: pole of inaccessibility with its distance, within a requested precision;
//! 6. [`ranking`]: filters and ordering of the sites by safe radius.
//!
//! Main types: [`Cloud`] with its [`CloudKind`], [`Params`] (the paper's defaults), [`Detection`]
//! with its [`LandingSite`]s and [`Polygon`]s, [`GeometryError`]. [`validation`] holds the invariant checks for meshes and polygons
//! that tests call on every result, and [`synthetic`] seeded scenes for tests and benchmarks.
//!
//! ```
//! use landing_geometry::{detect, synthetic::{Scene, SceneParams}, Cloud, Params};
//!
//! // A 20 m x 20 m flat roof 10 m up, no obstacles, ground and walls around it.
//! let scene = Scene::generate(&SceneParams { obstacles: 0, ..SceneParams::default() }, 7);
//! let cloud = Cloud::new(&scene.points, Some(&scene.classes));
//! let found = detect(&cloud, &Params::default()).unwrap();
//! let best = &found.sites[0];
//! assert_eq!(best.rank, 1);
//! assert!((best.plane_height_m - 10.0).abs() < 0.05);
//! // The largest circle in a 20 m square has a radius of 10 m; the sampled edge loses a little.
//! assert!(best.safe_radius_m > 8.5 && best.safe_radius_m <= 10.0);
//! best.polygon.validate().unwrap();
//! ```

#![forbid(unsafe_code)]

mod bins;
pub mod boundary;
pub mod class;
mod cloud;
pub mod delaunay;
pub mod filter;
pub mod geodetic;
pub mod levels;
mod mesh;
pub mod polylabel;
pub mod ranking;
pub mod regions;
pub mod synthetic;
pub mod triangulation;
mod trust;
pub mod validation;

use std::time::{Duration, Instant};

pub use class::SemanticClass;
pub use cloud::{Cloud, CloudKind};
pub use polylabel::Disk;
pub use ranking::{KeepClear, KeepOut};
pub use triangulation::Triangulation;

/// A point's x, y, z as the geometry computes with them: `[f64; 3]`, or a cloud's `[f32; 3]`
/// widened as it is read (exactly, so the answers are the same), which halves the memory that
/// the steps after the triangulation read in the mesh's order rather than the points'.
pub trait Xyz: Copy {
    fn xyz(self) -> [f64; 3];
}

impl Xyz for [f64; 3] {
    #[inline]
    fn xyz(self) -> [f64; 3] {
        self
    }
}

impl Xyz for [f32; 3] {
    #[inline]
    fn xyz(self) -> [f64; 3] {
        self.map(f64::from)
    }
}

/// Largest accepted absolute coordinate, metres. Beyond it f32 input has less than a metre of
/// resolution and the result would be meaningless.
pub const MAX_ABS_COORDINATE_M: f64 = 1e7;

/// Smallest accepted polylabel precision, metres: finer precision makes the cell search explode.
pub const MIN_POLYLABEL_PRECISION_M: f64 = 1e-3;

/// Default smallest safe radius returned, metres: half a delivery drone's span (≈ 0.5 m) plus
/// its positioning error (≈ 0.5 m). Smaller circles are no landing site, and in the evaluation
/// they were mostly tops of rooftop entrances and patches of street that segmentation took for
/// roof (`EVALUATION.md`).
pub const DEFAULT_MIN_SAFE_RADIUS_M: f64 = 1.0;

/// Parameters of the whole pipeline. `Default` gives the paper's values, and one of ours: sites
/// whose safe radius is under [`DEFAULT_MIN_SAFE_RADIUS_M`] are not returned (the paper returns
/// every circle).
#[derive(Debug, Clone, PartialEq)]
pub struct Params {
    /// `l_max`: triangles with a longer (3-D) edge are dropped, metres.
    pub max_triangle_edge_m: f64,
    /// `min_normal_dot`: minimum `|n · k|` of a triangle's unit normal.
    pub min_normal_dot: f64,
    /// `z_min`: triangles whose vertical extent is below this bypass the normal test, metres.
    pub max_triangle_height_m: f64,
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
            max_triangle_edge_m: 4.0,
            min_normal_dot: 0.96,
            max_triangle_height_m: 0.10,
            landable_classes: vec![SemanticClass::BuildingRooftop as u8],
            min_region_triangles: 10,
            polylabel_precision_m: 0.5,
            min_safe_radius_m: DEFAULT_MIN_SAFE_RADIUS_M,
            min_area_m2: 0.0,
            min_hole_area_m2: 0.0,
            max_sites: 16,
        }
    }
}

impl Params {
    /// Checks every parameter's range. The error names the field as in this struct, which is also
    /// its `landing.v1.PipelineOptions` name (`max_triangle_edge_m`).
    pub fn validate(&self) -> Result<(), GeometryError> {
        fn bad(field: &'static str, value: impl ToString, reason: &'static str) -> GeometryError {
            GeometryError::InvalidParameter {
                field,
                value: value.to_string(),
                reason,
            }
        }
        let finite_positive = |field, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(bad(field, v, "must be finite and > 0"))
            }
        };
        let finite_non_negative = |field, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(bad(field, v, "must be finite and >= 0"))
            }
        };
        finite_positive("max_triangle_edge_m", self.max_triangle_edge_m)?;
        if self.max_triangle_edge_m > MAX_ABS_COORDINATE_M {
            return Err(bad(
                "max_triangle_edge_m",
                self.max_triangle_edge_m,
                "must be <= 1e7",
            ));
        }
        if !(self.min_normal_dot >= 0.0 && self.min_normal_dot < 1.0) {
            return Err(bad(
                "min_normal_dot",
                self.min_normal_dot,
                "must be in [0, 1)",
            ));
        }
        finite_non_negative("max_triangle_height_m", self.max_triangle_height_m)?;
        if let Some(&c) = self
            .landable_classes
            .iter()
            .find(|&&c| SemanticClass::from_u8(c).is_none())
        {
            return Err(bad("landable_classes", c, "not a semantic class (0..=14)"));
        }
        finite_positive("polylabel_precision_m", self.polylabel_precision_m)?;
        if self.polylabel_precision_m < MIN_POLYLABEL_PRECISION_M {
            return Err(bad(
                "polylabel_precision_m",
                self.polylabel_precision_m,
                "must be >= 0.001",
            ));
        }
        finite_non_negative("min_safe_radius_m", self.min_safe_radius_m)?;
        finite_non_negative("min_area_m2", self.min_area_m2)?;
        finite_non_negative("min_hole_area_m2", self.min_hole_area_m2)?;
        if self.max_sites == 0 {
            return Err(bad("max_sites", self.max_sites, "must be >= 1"));
        }
        Ok(())
    }
}

/// A polygon with holes in the plane of a landing site. Shell counter-clockwise, holes clockwise
/// (seen from above), rings not closed (last point is not a copy of the first).
///
/// Polygons made by [`detect`] are OGC-valid (see [`Polygon::validate`]) and canonical: each ring
/// starts at its lexicographically smallest (x, y) vertex and holes are sorted.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Polygon {
    pub shell: Vec<[f64; 2]>,
    pub holes: Vec<Vec<[f64; 2]>>,
}

impl Polygon {
    /// Area of the shell minus the holes, square metres.
    pub fn area(&self) -> f64 {
        validation::ring_signed_area(&self.shell).abs()
            - self
                .holes
                .iter()
                .map(|h| validation::ring_signed_area(h).abs())
                .sum::<f64>()
    }

    /// OGC validity: see [`validation::check_polygon`].
    pub fn validate(&self) -> Result<(), GeometryError> {
        validation::check_polygon(self)
    }

    /// The shell's bounding box `[min x, min y, max x, max y]` (zeros when empty).
    pub fn bounds(&self) -> [f64; 4] {
        ring_bounds(&self.shell)
    }

    /// Signed distance from `p` to the polygon's boundary: positive inside, negative outside.
    pub fn signed_distance(&self, p: [f64; 2]) -> f64 {
        polylabel::signed_distance(self, p)
    }
}

/// A ring's bounding box `[min x, min y, max x, max y]` (zeros when empty).
pub(crate) fn ring_bounds(ring: &[[f64; 2]]) -> [f64; 4] {
    let Some(&[x, y]) = ring.first() else {
        return [0.0; 4];
    };
    ring.iter().fold([x, y, x, y], |b, p| {
        [
            b[0].min(p[0]),
            b[1].min(p[1]),
            b[2].max(p[0]),
            b[3].max(p[1]),
        ]
    })
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
    /// Polylabel and ranking.
    pub polylabel: Duration,
}

impl StepTimings {
    /// Sum of all steps.
    pub fn total(&self) -> Duration {
        self.triangulation
            + self.triangle_filter
            + self.plane_extraction
            + self.polygon_extraction
            + self.polylabel
    }
}

/// The result of one run of the pipeline.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Detection {
    /// Best first.
    pub sites: Vec<LandingSite>,
    /// Number of input points.
    pub point_count: usize,
    /// Number of Delaunay triangles.
    pub triangle_count: usize,
    pub timings: StepTimings,
}

/// Everything that can go wrong in this crate.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GeometryError {
    /// A parameter is out of its valid range.
    #[error("parameter `{field}` = {value} is out of range: {reason}")]
    InvalidParameter {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
    /// A coordinate is NaN, infinite, or of absurd magnitude.
    #[error("point {index} has a non-finite or out-of-range coordinate {value}")]
    InvalidPoint { index: usize, value: f64 },
    /// `classes` does not have one entry per point.
    #[error("{classes} classes given for {points} points")]
    ClassCountMismatch { points: usize, classes: usize },
    /// [`KeepClear::points`] does not have one flag per point.
    #[error("{flags} keep-clear flags given for {points} points")]
    FlagCountMismatch { points: usize, flags: usize },
    /// A bounded loop reached its bound: a bug or pathological input, reported instead of spinning.
    #[error("{step} gave up after {limit} iterations")]
    IterationLimit { step: &'static str, limit: usize },
    /// A triangulation broke one of its invariants (see [`Triangulation::check_invariants`]).
    #[error("invalid mesh: {reason}")]
    InvalidMesh { reason: String },
    /// A polygon is not OGC-valid (see [`Polygon::validate`]).
    #[error("invalid polygon: {reason}")]
    InvalidPolygon { reason: String },
}

/// Runs the whole pipeline on `cloud` with `params`.
///
/// Fewer than three distinct points, or points all on one line, give an empty [`Detection`], not an
/// error: there is simply no surface. Non-finite or out-of-range coordinates (|c| > 1e7 m) give
/// [`GeometryError::InvalidPoint`]; a duplicated x/y position is triangulated once (its other
/// copies are left out). A class list or flag list of the wrong length gives
/// [`GeometryError::ClassCountMismatch`] or [`GeometryError::FlagCountMismatch`], a triangulation
/// that names a point the cloud lacks [`GeometryError::InvalidMesh`]. On a fused map with
/// keep-out disks it gathers the long-edged triangles ([`CloudKind::keep_out_trust_edge_m`]) on
/// a second, scoped thread while this one traces the polygons; the answer does not depend on it.
pub fn detect(cloud: &Cloud<'_>, params: &Params) -> Result<Detection, GeometryError> {
    params.validate()?;
    cloud.kind.validate()?;
    check_points(cloud.points, cloud.classes)?;
    check_flags(cloud)?;
    let pts = widen(cloud.points);
    let mut timings = StepTimings::default();

    let t0 = Instant::now();
    let made;
    let tri = match cloud.triangulation {
        Some(tri) => check_triangulation(tri, cloud.points.len())?,
        None => {
            made = triangulation::triangulate(&pts)?;
            &made
        }
    };
    let t1 = Instant::now();
    timings.triangulation = t1 - t0;

    let mask = filter::filter_triangles(
        tri,
        cloud.points,
        cloud.classes,
        &filter::FilterParams::from(params),
    );
    let t2 = Instant::now();
    timings.triangle_filter = t2 - t1;

    let mut regions = planar_regions(tri, cloud.points, &pts, mask, params, cloud.kind)?;
    let t3 = Instant::now();
    timings.plane_extraction = t3 - t2;

    // A fused map's keep-out disks are judged against its long-edged triangles ([`trust`]),
    // gathered on a second thread while this one traces the polygons.
    let trust_edge = cloud.kind.keep_out_trust_edge_m();
    let (traced, mut gaps) = std::thread::scope(|threads| {
        let gaps = (cloud.keep_clear.disks.is_some() && trust_edge > 0.0)
            .then(|| threads.spawn(|| trust::Gaps::new(tri, &pts, &regions, trust_edge)));
        let traced = outlines(tri, &pts, &regions, cloud).map(|outlines| {
            let drop = levels::no_roof(&regions, &outlines.polygons, &pts, cloud.classes);
            (outlines, drop)
        });
        let gaps = gaps.map(|g| {
            g.join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
        });
        (traced, gaps)
    });
    let (mut outlines, drop) = traced?;
    if drop.contains(&true) {
        let keep: Vec<bool> = drop.iter().map(|d| !d).collect();
        drop_regions(&mut regions, &mut outlines, &keep);
        if let Some(gaps) = &mut gaps {
            gaps.keep_regions(&keep);
        }
    }
    let t4 = Instant::now();
    timings.polygon_extraction = t4 - t3;

    let sites = safe_sites(&regions, outlines, params, cloud, gaps.as_ref())?;
    timings.polylabel = t4.elapsed();

    Ok(Detection {
        sites,
        point_count: cloud.points.len(),
        triangle_count: tri.len(),
        timings,
    })
}

/// The triangulation [`detect`] makes of `points`, to give it in [`Cloud::with_triangulation`]:
/// made beforehand, say on another thread while the points' classes are still being made.
pub fn triangulate_points(points: &[[f32; 3]]) -> Result<Triangulation, GeometryError> {
    triangulation::triangulate(&widen(points))
}

/// `points` in the double precision the geometry works in.
fn widen(points: &[[f32; 3]]) -> Vec<[f64; 3]> {
    points.iter().map(|p| p.map(f64::from)).collect()
}

/// A triangulation given with the cloud, if every vertex it names is one of the `points` points.
fn check_triangulation(
    tri: &Triangulation,
    points: usize,
) -> Result<&Triangulation, GeometryError> {
    if tri.halfedges.len() != tri.triangles.len()
        || !tri.triangles.len().is_multiple_of(3)
        || tri.triangles.iter().any(|&v| v as usize >= points)
    {
        return Err(GeometryError::InvalidMesh {
            reason: format!(
                "a triangulation of {} vertex slots for {points} points",
                tri.triangles.len(),
            ),
        });
    }
    Ok(tri)
}

/// The paper's Algorithm 2 on the kept triangles, with a fused map's pinholes closed; `points`
/// are the cloud's, `pts` the same widened.
fn planar_regions(
    tri: &Triangulation,
    points: &[[f32; 3]],
    pts: &[[f64; 3]],
    mask: Vec<bool>,
    params: &Params,
    kind: CloudKind,
) -> Result<regions::Regions, GeometryError> {
    let mut regions = regions::extract_regions(
        tri,
        points,
        mask,
        &regions::RegionParams {
            min_triangles: params.min_region_triangles,
        },
    )?;
    if kind.closes_pinholes() {
        regions::close_pinholes(
            tri,
            pts,
            &mut regions,
            params.max_triangle_edge_m,
            params.max_triangle_height_m,
        );
    }
    Ok(regions)
}

/// Each region's returned polygon, and the rings its safe circle stays in where those are not
/// the polygon itself (`None` for all: the polygons).
struct Outlines {
    polygons: Vec<Polygon>,
    parts: Option<Vec<Option<boundary::Rings>>>,
}

/// The regions' polygons, and the rings their safe circles stay in: where points are flagged,
/// the part of each region without them; with midpoint edges (a fused map), the polygon of the
/// region's own points, while the grown one is returned.
fn outlines(
    tri: &Triangulation,
    pts: &[[f64; 3]],
    regions: &regions::Regions,
    cloud: &Cloud<'_>,
) -> Result<Outlines, GeometryError> {
    let parts = match cloud.keep_clear.points {
        Some(flags) if flags.iter().any(|&f| f) => {
            Some(boundary::region_parts(tri, pts, regions, |t| {
                let t = 3 * t as usize;
                !tri.triangles[t..t + 3].iter().any(|&v| flags[v as usize])
            })?)
        }
        _ => None,
    };
    let max_edge = cloud.kind.midpoint_max_edge_m();
    if max_edge <= 0.0 {
        let params = boundary::BoundaryParams::default();
        let polygons = boundary::region_polygons(tri, pts, regions, &params)?;
        return Ok(Outlines { polygons, parts });
    }
    // Each region has two polygons from one walk of its boundary: the one of its own points,
    // which the safe circle stays in (or in its part), and the grown one, which is returned.
    let pairs = boundary::region_polygons_with_midpoints(tri, pts, regions, max_edge)?;
    let mut own: Vec<Option<boundary::Rings>> = parts.unwrap_or_else(|| vec![None; pairs.len()]);
    for (part, (polygon, _)) in own.iter_mut().zip(&pairs) {
        part.get_or_insert_with(|| {
            std::iter::once(polygon.shell.clone())
                .chain(polygon.holes.iter().cloned())
                .collect()
        });
    }
    // By construction a grown polygon is valid; should rounding ever make one not, the region
    // keeps the polygon of its own points.
    let polygons = pairs
        .into_iter()
        .map(|(p, g)| if g.validate().is_ok() { g } else { p })
        .collect();
    Ok(Outlines {
        polygons,
        parts: Some(own),
    })
}

/// Keeps the regions (with their outlines) whose `keep` is true: those the cloud's levels do not
/// show to be no roof ([`levels::no_roof`]).
fn drop_regions(regions: &mut regions::Regions, outlines: &mut Outlines, keep: &[bool]) {
    regions.retain(keep);
    let mut k = keep.iter();
    outlines.polygons.retain(|_| *k.next().unwrap_or(&true));
    if let Some(parts) = &mut outlines.parts {
        let mut k = keep.iter();
        parts.retain(|_| *k.next().unwrap_or(&true));
    }
}

/// The ranked sites: polylabel in each outline, clear of the cloud's keep-out disks. Where a
/// fused map's points are dense they answer for the ground (`gaps`, made for such a map), and
/// disks there bound nothing.
fn safe_sites(
    regions: &regions::Regions,
    outlines: Outlines,
    params: &Params,
    cloud: &Cloud<'_>,
    gaps: Option<&trust::Gaps>,
) -> Result<Vec<LandingSite>, GeometryError> {
    let over_gaps;
    let disks = match (cloud.keep_clear.disks, gaps) {
        (Some(inner), Some(gaps)) => {
            over_gaps = trust::OverGaps { inner, gaps };
            Some(&over_gaps as &dyn ranking::KeepOut)
        }
        (other, _) => other,
    };
    ranking::rank_sites(
        regions,
        outlines.polygons,
        outlines.parts.as_deref(),
        &ranking::RankingParams::from(params),
        disks,
    )
}

/// One keep-clear flag per point, when there are flags.
fn check_flags(cloud: &Cloud<'_>) -> Result<(), GeometryError> {
    match cloud.keep_clear.points {
        Some(flags) if flags.len() != cloud.points.len() => Err(GeometryError::FlagCountMismatch {
            points: cloud.points.len(),
            flags: flags.len(),
        }),
        _ => Ok(()),
    }
}

/// Boundary checks on the input, once: finite, in range, one class per point.
fn check_points(points: &[[f32; 3]], classes: Option<&[u8]>) -> Result<(), GeometryError> {
    if let Some(c) = classes
        && c.len() != points.len()
    {
        return Err(GeometryError::ClassCountMismatch {
            points: points.len(),
            classes: c.len(),
        });
    }
    for (index, p) in points.iter().enumerate() {
        for &c in p {
            let v = f64::from(c);
            if !v.is_finite() || v.abs() > MAX_ABS_COORDINATE_M {
                return Err(GeometryError::InvalidPoint { index, value: v });
            }
        }
    }
    Ok(())
}
