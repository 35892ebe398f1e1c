//! What [`crate::detect`] runs on: the points, what is known of them, and what kind of cloud
//! they are ([`Cloud`], [`CloudKind`]).

use crate::ranking::KeepClear;
use crate::{GeometryError, Triangulation};

/// The kind of cloud the points are, which decides how the geometry reads their density.
/// `Default` is a single scan.
///
/// A single scan's points lie far apart, and the pipeline is the paper's. A fused map's cells lie
/// a cell apart, and three mechanisms apply, each explained where it is implemented:
/// - pinholes are closed ([`crate::regions::close_pinholes`]): range noise tilts short triangles
///   past `min_normal_dot` and punches holes that hold no point of their own;
/// - polygons end halfway to the first point that is not theirs
///   ([`crate::boundary::BoundaryParams::midpoint_max_edge_m`]), not a cell inside the true edge
///   (the safe circles stay where they were);
/// - keep-out disks bound a safe circle only over gaps in the points (the `trust` module): where
///   the points lie within two cells of each other they show the ground themselves.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum CloudKind {
    /// One LiDAR scan, the paper's input: its points lie 0.3-2.4 m apart, too sparse for a hole
    /// without a point of its own to say it is empty, or for the points to show the ground
    /// between them (`EVALUATION.md`).
    #[default]
    Scan,
    /// A fusion map's cells (`landing_fusion`): one point per occupied cell of `cell_size_m` metres,
    /// so neighbouring points lie a cell or two apart.
    FusedMap {
        /// The map's cell size, metres (finite and > 0).
        cell_size_m: f64,
    },
}

impl CloudKind {
    /// Whether the regions' pinholes are closed ([`crate::regions::close_pinholes`]).
    pub fn closes_pinholes(&self) -> bool {
        matches!(self, Self::FusedMap { .. })
    }

    /// How far a polygon's edge may reach to the midpoints of the edges to the first point that
    /// is not its own ([`crate::boundary::BoundaryParams::midpoint_max_edge_m`]): two cells for a
    /// fused map, 0 (off, the paper's polygons) for a scan.
    pub fn midpoint_max_edge_m(&self) -> f64 {
        self.within_two_cells()
    }

    /// The longest x/y edge of the regions' triangles over which the points are taken to show
    /// the ground, so that keep-out disks there bound no safe circle (the `trust` module): two
    /// cells for a fused map, 0 (every disk counts) for a scan.
    pub fn keep_out_trust_edge_m(&self) -> f64 {
        self.within_two_cells()
    }

    /// Two cells for a fused map (a neighbour's neighbour: where the landable cells lie this
    /// close they show the roof itself, and an obstacle no scan hit leaves a wider gap), 0 for
    /// a scan.
    fn within_two_cells(&self) -> f64 {
        match self {
            Self::Scan => 0.0,
            Self::FusedMap { cell_size_m } => 2.0 * cell_size_m,
        }
    }

    /// Checks the cell size; the error names the field `cell_size_m`.
    pub fn validate(&self) -> Result<(), GeometryError> {
        match *self {
            Self::Scan => Ok(()),
            Self::FusedMap { cell_size_m } if cell_size_m.is_finite() && cell_size_m > 0.0 => {
                Ok(())
            }
            Self::FusedMap { cell_size_m } => Err(GeometryError::InvalidParameter {
                field: "cell_size_m",
                value: cell_size_m.to_string(),
                reason: "must be finite and > 0",
            }),
        }
    }
}

/// The input of [`crate::detect`]: points (x, y, z in a frame with z up) and what goes with
/// them. Build it with [`Cloud::new`] and the `with_*` methods.
#[derive(Clone, Copy)]
pub struct Cloud<'a> {
    pub points: &'a [[f32; 3]],
    /// One class per point (values of [`crate::SemanticClass`], 0 = unknown), when known.
    pub classes: Option<&'a [u8]>,
    pub kind: CloudKind,
    /// What safe circles keep clear of besides the polygons' edges: obstacles the points missed
    /// (the camera's obstacle pixels, say), and ground flagged per point. Nothing by default.
    pub keep_clear: KeepClear<'a>,
    /// The points' triangulation, when it was made beforehand (say on another thread while the
    /// points' classes were still being made, or by another triangulator to cross-check): it
    /// must be one of these points ([`crate::triangulate_points`] makes the one `detect`
    /// would). Its time is the caller's and reported as zero.
    pub triangulation: Option<&'a Triangulation>,
}

impl<'a> Cloud<'a> {
    /// A [`CloudKind::Scan`] of `points` with optional per-point `classes`, nothing to keep
    /// clear of and no triangulation yet.
    pub fn new(points: &'a [[f32; 3]], classes: Option<&'a [u8]>) -> Self {
        Self {
            points,
            classes,
            kind: CloudKind::Scan,
            keep_clear: KeepClear::default(),
            triangulation: None,
        }
    }

    /// The same points, of kind `kind`.
    pub fn with_kind(self, kind: CloudKind) -> Self {
        Self { kind, ..self }
    }

    /// The same points, whose safe circles keep clear of `keep_clear`.
    pub fn with_keep_clear(self, keep_clear: KeepClear<'a>) -> Self {
        Self { keep_clear, ..self }
    }

    /// The same points, with their triangulation made beforehand.
    pub fn with_triangulation(self, triangulation: &'a Triangulation) -> Self {
        Self {
            triangulation: Some(triangulation),
            ..self
        }
    }
}
