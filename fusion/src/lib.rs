//! Approach fusion: what a stream remembers of the roof it approaches.
//!
//! A drone streams ten scans a second of the roof it is about to land on. Judged alone, each
//! frame's polygons end at its own outermost points and one frame's segmentation miss can become
//! an unsafe site. A [`FusionMap`] keeps, per stream and in world coordinates:
//!
//! - the scans' points, thinned to one mean point per cubic cell of [`FusionParams::cell_size_m`]
//!   (answers take the top cell of each column: the surface seen from above);
//! - per cell, the classes the frames that saw it gave it: one vote per frame (the majority
//!   class of that frame's points in the cell), so a dense frame does not outvote a sparse one.
//!   An obstacle vote outweighs [`FusionParams::obstacle_weight`] landable ones, so obstacle
//!   evidence is not washed out by one contrary frame, and a view whose pixels there are much
//!   finer than every earlier voter's replaces their votes (a far pixel smears an edge's class
//!   over the roof beside it); and whether a camera has seen the cell
//!   finely enough to show small obstacles ([`FusionParams::max_pixel_footprint_m`]: from 40 m a
//!   small air vent is a pixel or two, and a frame's miss there would be every frame's), which
//!   answers report ([`Fused::unresolved`]) so that landing circles keep clear of the rest;
//! - the keep-out footprints of recent frames' obstacle pixels (`K`, opaque here: the server
//!   stores the camera's obstacle rays), spread over the approach.
//!
//! A scan is added in two steps, [`FusionMap::place`] (its points: the cells and their
//! positions, so the [`FusionMap::surface`] answers take is then final) and
//! [`FusionMap::vote`] (its classes, view and keep-out footprints), so that a caller can
//! triangulate the surface while the scan's classes are still being made; [`FusionMap::insert`]
//! does both. [`FusionMap::meshed_surface`] gives the surface with its Delaunay triangulation,
//! both kept between scans and changed only where a scan changed the surface (a scan moves the
//! means of the cells it hits and adds some at the edge of what was seen; the rest of the map
//! stays): the triangulation is a `landing_geometry::delaunay::KeptTriangulation`.
//!
//! Before a scan is added, [`FusionMap::register`] finds the small rigid correction that lays it
//! onto the map's planes (a drone's pose is off by centimetres and a tenth of a degree, enough
//! to smear the map); the caller moves the scan and its poses by it.
//!
//! It is bounded in cells ([`FusionParams::max_cells`], the oldest forgotten first) and in time
//! ([`FusionParams::horizon_s`]), and starts over ([`Reset`]) when the drone changes, the pose
//! jumps, time goes backwards or the caller asks. It is plain synchronous code with no I/O: the
//! server owns one per stream and drops it with the stream.
//!
//! The surface's points lie a cell or two apart, far denser than a scan's: the geometry reads
//! them as `landing_geometry::CloudKind::FusedMap` (pinholes closed, polygons to midpoints,
//! keep-out footprints trusted only over gaps), explained there.
//!
//! ```
//! use landing_fusion::{FusionMap, FusionParams, Scan};
//!
//! let mut map: FusionMap<()> = FusionMap::new(FusionParams::default())?;
//! let roof: Vec<[f64; 3]> = (0..100).map(|i| [f64::from(i % 10), f64::from(i / 10), 30.0]).collect();
//! let rooftop = vec![4u8; roof.len()];
//! for t in 0..3 {
//!     let mut classes = rooftop.clone();
//!     if t == 1 {
//!         classes[55] = 8; // one frame sees an AC unit at (5, 5)
//!     }
//!     let scan = Scan { time_s: f64::from(t) * 0.1, sensor: [0.0, -20.0, 50.0], points: &roof,
//!         classes: Some(&classes), ..Scan::new("drone-1") };
//!     map.insert(scan);
//! }
//! let fused = map.fused([[-1.0, -1.0], [10.0, 10.0]], |c| c == 4);
//! assert_eq!(fused.points.len(), 100);
//! let near = |p: &[f64; 3]| (p[0] - 5.0).abs() < 1e-4 && (p[1] - 5.0).abs() < 1e-4;
//! let at = fused.points.iter().position(near).unwrap();
//! // Two frames saw rooftop there, one an obstacle: the obstacle stands.
//! assert_eq!(fused.classes.as_ref().unwrap()[at], 8);
//! assert_eq!(map.frames(), 3);
//! # Ok::<(), landing_fusion::FusionError>(())
//! ```

#![forbid(unsafe_code)]

mod register;
mod surface;

use std::collections::{HashMap, VecDeque};
use std::hash::{BuildHasherDefault, Hasher};

pub use register::{Correction, NotRegistered};
use surface::Columns;
pub use surface::MeshedSurface;

/// Number of class ids a cell counts votes for (`landing.v1.SemanticClass` 0..=15).
pub const CLASSES: usize = 16;

/// Parameters of a [`FusionMap`]. `Default` gives the service's defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusionParams {
    /// Side of the cubic cells points are thinned to, metres.
    pub cell_size_m: f64,
    /// Cells not seen for this long, and keep-out footprints older than this, are forgotten,
    /// seconds.
    pub horizon_s: f64,
    /// Most cells held; past it the cells seen longest ago are forgotten.
    pub max_cells: usize,
    /// Most frames whose keep-out footprints are kept: the current one and earlier ones at least
    /// [`FusionParams::keep_out_interval_s`] apart.
    pub keep_out_frames: usize,
    /// Least time between two kept keep-out frames, seconds (consecutive frames at 10 Hz see
    /// nearly the same thing; spreading them covers more of the approach for the same cost).
    pub keep_out_interval_s: f64,
    /// A sensor that moves farther than this between consecutive frames starts the map over,
    /// metres.
    pub max_jump_m: f64,
    /// One obstacle vote outweighs this many landable votes.
    pub obstacle_weight: u32,
    /// Whether [`FusionMap::register`] corrects scans (point-to-plane alignment to the map).
    pub register_scans: bool,
    /// A cell is resolved once a camera saw it finely enough to show small obstacles: a view
    /// ([`Scan::view`]) one of whose class pixels covered at most this much of the level ground
    /// there (the longer side, metres). Answers flag the landable cells not yet resolved
    /// ([`Fused::unresolved`]). 0 turns the rule off: every cell counts as resolved.
    pub max_pixel_footprint_m: f64,
}

impl Default for FusionParams {
    fn default() -> Self {
        Self {
            cell_size_m: 0.15,
            horizon_s: 30.0,
            max_cells: 250_000,
            // Four frames a second apart cover a 4 s approach; where a much nearer frame sees a
            // place, its view replaces the older ones' (the server casts them so). Measured
            // against eight half a second apart: as safe, larger circles, a third less time
            // (EVALUATION.md, "Approach fusion").
            keep_out_frames: 4,
            keep_out_interval_s: 1.0,
            max_jump_m: 15.0,
            obstacle_weight: 4,
            register_scans: true,
            // The smallest air vents are 0.4-0.6 m across; the shipped model missed a 0.55 m
            // one at 0.2-0.25 m a pixel. At 0.2 m a 0.4 m vent spans two pixels (EVALUATION.md,
            // "Resolved cells": 0.25 and 0.3 left unsafe sites).
            max_pixel_footprint_m: 0.2,
        }
    }
}

impl FusionParams {
    /// Checks every field; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), FusionError> {
        let checks = [
            (
                "cell_size_m",
                (0.02..=5.0).contains(&self.cell_size_m),
                self.cell_size_m.to_string(),
                "must be in [0.02, 5]",
            ),
            (
                "horizon_s",
                self.horizon_s > 0.0 && self.horizon_s <= 3600.0,
                self.horizon_s.to_string(),
                "must be in (0, 3600]",
            ),
            (
                "max_cells",
                (1_000..=5_000_000).contains(&self.max_cells),
                self.max_cells.to_string(),
                "must be in [1000, 5000000]",
            ),
            (
                "keep_out_frames",
                (1..=64).contains(&self.keep_out_frames),
                self.keep_out_frames.to_string(),
                "must be in [1, 64]",
            ),
            (
                "keep_out_interval_s",
                self.keep_out_interval_s >= 0.0 && self.keep_out_interval_s.is_finite(),
                self.keep_out_interval_s.to_string(),
                "must be finite and >= 0",
            ),
            (
                "max_jump_m",
                self.max_jump_m > 0.0 && self.max_jump_m.is_finite(),
                self.max_jump_m.to_string(),
                "must be positive and finite",
            ),
            (
                "obstacle_weight",
                (1..=1000).contains(&self.obstacle_weight),
                self.obstacle_weight.to_string(),
                "must be in [1, 1000]",
            ),
            (
                "max_pixel_footprint_m",
                (0.0..=100.0).contains(&self.max_pixel_footprint_m),
                self.max_pixel_footprint_m.to_string(),
                "must be in [0, 100]",
            ),
        ];
        match checks.into_iter().find(|c| !c.1) {
            Some((field, _, value, reason)) => Err(FusionError::InvalidParam {
                field,
                value,
                reason,
            }),
            None => Ok(()),
        }
    }
}

/// Everything that can go wrong here.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FusionError {
    /// A parameter is out of range.
    #[error("fusion parameter `{field}` = {value}: {reason}")]
    InvalidParam {
        field: &'static str,
        value: String,
        reason: &'static str,
    },
}

impl FusionError {
    /// The parameter at fault, named as in `landing.v1.FusionOptions` and the `[fusion]` config.
    pub fn field(&self) -> &'static str {
        match self {
            Self::InvalidParam { field, .. } => field,
        }
    }
}

/// One frame's scan, in the world frame.
#[derive(Debug, Clone)]
pub struct Scan<'a, K> {
    /// The drone; a change starts the map over.
    pub drone_id: &'a str,
    /// When the scan was taken, seconds on any clock that does not go backwards.
    pub time_s: f64,
    /// Where the sensor was, world frame.
    pub sensor: [f64; 3],
    /// The points, world frame. Non-finite points are skipped.
    pub points: &'a [[f64; 3]],
    /// One class id per point, when the frame was classified.
    pub classes: Option<&'a [u8]>,
    /// The camera the classes came from, when they came from one: how finely it saw each cell
    /// ([`FusionParams::max_pixel_footprint_m`]). Classes from elsewhere count as seen finely.
    pub view: Option<View<'a>>,
    /// The frame's keep-out footprints, when it has any.
    pub keep_out: Option<K>,
    /// Start the map over at this scan.
    pub reset: bool,
}

impl<'a, K> Scan<'a, K> {
    /// An empty scan of `drone_id` at time 0, for struct-update syntax.
    pub fn new(drone_id: &'a str) -> Self {
        Self {
            drone_id,
            time_s: 0.0,
            sensor: [0.0; 3],
            points: &[],
            classes: None,
            view: None,
            keep_out: None,
            reset: false,
        }
    }
}

/// How finely a scan's camera saw the world: for a world position, the longer side, metres, of
/// the patch of level ground that one of its class pixels covers there, or `None` where the
/// camera did not see.
#[derive(Clone, Copy)]
pub struct View<'a>(pub &'a (dyn Fn(&[f64; 3]) -> Option<f64> + Sync));

impl std::fmt::Debug for View<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("View(..)")
    }
}

/// Why a map started over.
#[derive(Debug, Clone, PartialEq)]
pub enum Reset {
    /// The caller asked.
    Requested,
    /// Another drone's frame.
    DroneChanged,
    /// The sensor moved `metres` since the previous frame.
    PoseJump { metres: f64 },
    /// The frame is older than the previous one.
    TimeBackwards { seconds: f64 },
    /// Nothing was fused for longer than the horizon.
    Gap { seconds: f64 },
}

impl std::fmt::Display for Reset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Requested => write!(f, "reset requested"),
            Self::DroneChanged => write!(f, "drone_id changed"),
            Self::PoseJump { metres } => write!(f, "the sensor jumped {metres:.1} m"),
            Self::TimeBackwards { seconds } => {
                write!(f, "the frame is {seconds:.3} s older than the previous one")
            }
            Self::Gap { seconds } => write!(f, "no frame for {seconds:.1} s"),
        }
    }
}

/// The map's points inside an answer's bounds, in a deterministic order (by cell).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Fused {
    /// One mean point per cell, world frame.
    pub points: Vec<[f64; 3]>,
    /// The cell's class when any frame classified it (0 where none did).
    pub classes: Option<Vec<u8>>,
    /// Per point, whether its cell's class is landable but no view fine enough to show small
    /// obstacles has seen it ([`FusionParams::max_pixel_footprint_m`]): the cell could lie on an
    /// obstacle the camera could not resolve. All `false` with the rule off.
    pub unresolved: Vec<bool>,
}

/// A scan [`FusionMap::place`]d and not yet voted: where its points fell.
#[derive(Debug)]
pub struct Placed {
    /// (cell, point index) of every usable point, grouped by cell.
    keyed: Vec<([i32; 3], u32)>,
    time_s: f64,
    reset: Option<Reset>,
}

impl Placed {
    /// Why placing the scan started the map over, if it did.
    pub fn reset(&self) -> Option<&Reset> {
        self.reset.as_ref()
    }
}

/// The map's top surface ([`FusionMap::surface`]): one point per column, in a deterministic
/// order (by cell).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Surface {
    /// The top cell of each column.
    keys: Vec<[i32; 3]>,
    /// Its mean point, world frame.
    pub points: Vec<[f64; 3]>,
}

/// The centre of the bounding box of the finite `points`, or `fallback` when none is: a local
/// origin near the points wherever the world origin is, so that coordinates relative to it stay
/// small enough for single precision.
pub fn centre(points: &[[f64; 3]], fallback: [f64; 3]) -> [f64; 3] {
    let mut bounds: Option<([f64; 3], [f64; 3])> = None;
    for p in points.iter().filter(|p| p.iter().all(|v| v.is_finite())) {
        let (lo, hi) = bounds.get_or_insert((*p, *p));
        for i in 0..3 {
            lo[i] = lo[i].min(p[i]);
            hi[i] = hi[i].max(p[i]);
        }
    }
    bounds.map_or(fallback, |(lo, hi)| {
        std::array::from_fn(|i| lo[i] + (hi[i] - lo[i]) / 2.0)
    })
}

/// The origin a map takes from its first scan: the cell corner nearest the [`centre`] of its
/// points on the grid of cells through the sensor, so that where cell boundaries fall depends
/// only on where the sensor was (as with the sensor itself as the origin), while the origin
/// lies among the points even when a cloud came in world coordinates with the sensor at 0.
fn anchor<K>(scan: &Scan<'_, K>, cell: f64) -> [f64; 3] {
    let c = centre(scan.points, scan.sensor);
    std::array::from_fn(|i| scan.sensor[i] + ((c[i] - scan.sensor[i]) / cell).round() * cell)
}

/// A stream's map (see the crate docs).
#[derive(Debug)]
pub struct FusionMap<K> {
    params: FusionParams,
    /// World position of cell (0, 0, 0)'s corner: near the [`centre`] of the first scan's
    /// points, so that cell coordinates stay small wherever the world origin is (see
    /// [`anchor`]).
    origin: Option<[f64; 3]>,
    cells: HashMap<[i32; 3], Cell, BuildHasherDefault<CellHasher>>,
    /// (time, footprints), oldest first; the last is the newest frame's.
    keep_out: VecDeque<(f64, K)>,
    drone_id: String,
    /// Time and sensor position of the previous scan.
    last: Option<(f64, [f64; 3])>,
    /// Time of the first scan since the map (re)started.
    start_s: f64,
    frames: u32,
    /// Whether any scan came with classes.
    classified: bool,
    /// The top surface kept between scans, with its triangulation.
    columns: Columns,
}

/// The hash of a cell key: its three coordinates mixed by multiplication (deterministic, so a
/// map's iteration order depends only on what it was given, and several times cheaper than the
/// standard SipHash on the lookups registration and fusion make per frame). A stream can only
/// crowd its own map, which is bounded in cells.
#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn finish(&self) -> u64 {
        // The final avalanche of MurmurHash3: every input bit reaches the high bits hashbrown
        // takes its control bytes from.
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u8(b);
        }
    }

    fn write_u8(&mut self, b: u8) {
        self.write_u64(u64::from(b));
    }

    fn write_u32(&mut self, v: u32) {
        self.write_u64(u64::from(v));
    }

    fn write_i32(&mut self, v: i32) {
        self.write_u32(v as u32);
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(21) ^ v).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }

    fn write_usize(&mut self, v: usize) {
        self.write_u64(v as u64);
    }
}

/// One cell: the mean of its points (relative to the map origin) and its votes.
#[derive(Debug, Clone)]
struct Cell {
    mean: [f32; 3],
    points: u16,
    /// Frames that gave the cell each class (saturating; halved together when one fills).
    votes: [u8; CLASSES],
    /// Time of the last frame that saw the cell, seconds since the map started.
    seen_s: f32,
    /// Whether a view fine enough to show small obstacles saw the cell
    /// ([`FusionParams::max_pixel_footprint_m`]).
    resolved: bool,
    /// The finest pixel footprint of the views whose votes the cell holds, metres (infinite
    /// before the first view).
    finest: f32,
}

impl Cell {
    /// The cell's mean point in the world frame (`key` its key, `origin` the map's, `c` the
    /// cell side).
    fn position(&self, key: &[i32; 3], origin: [f64; 3], c: f64) -> [f64; 3] {
        std::array::from_fn(|i| origin[i] + (f64::from(key[i]) + f64::from(self.mean[i])) * c)
    }
}

/// Lists of at least this many cells have their classes looked up on two threads
/// ([`decide_cells`]).
const PARALLEL_LOOKUPS: usize = 8192;

/// Cells whose mean weighs at most this many points, so that the mean keeps following new
/// scans (a drone's pose error changes slowly over an approach).
const MAX_MEAN_WEIGHT: u16 = 64;

/// A view whose pixel footprint on a cell is at most this fraction of the finest that voted on
/// it before replaces those votes (as a much nearer camera replaces a farther one's keep-out
/// footprints).
const FINER_VIEW: f32 = 0.8;

/// Expired cells are looked for every this many frames (and whenever the map is full).
const EXPIRY_EVERY_FRAMES: u32 = 10;

impl<K> FusionMap<K> {
    /// An empty map.
    pub fn new(params: FusionParams) -> Result<Self, FusionError> {
        params.validate()?;
        Ok(Self {
            params,
            origin: None,
            cells: HashMap::default(),
            keep_out: VecDeque::new(),
            drone_id: String::new(),
            last: None,
            start_s: 0.0,
            frames: 0,
            classified: false,
            columns: Columns::new(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &FusionParams {
        &self.params
    }

    /// Forgets everything.
    pub fn clear(&mut self) {
        self.origin = None;
        self.cells.clear();
        self.keep_out.clear();
        self.last = None;
        self.frames = 0;
        self.classified = false;
        self.columns.forget();
    }

    /// Adds a scan; returns why the map started over first, if it did. The same as
    /// [`FusionMap::place`] then [`FusionMap::vote`].
    pub fn insert(&mut self, scan: Scan<'_, K>) -> Option<Reset> {
        let placed = self.place(&scan);
        self.vote(placed, scan)
    }

    /// Adds a scan's points (starting the map over first where [`FusionMap::would_reset`] says
    /// so): the map's cells, their positions and so its [`FusionMap::surface`] are then final
    /// for this scan; its classes, view and keep-out footprints (ignored here) come with
    /// [`FusionMap::vote`]. A caller can thus work on the surface while the scan's classes are
    /// still being made. Until `vote`, the scan's cells hold no vote of it.
    pub fn place(&mut self, scan: &Scan<'_, K>) -> Placed {
        let reset = self.would_reset(scan);
        if reset.is_some() {
            self.clear();
        }
        self.drone_id.clear();
        self.drone_id.push_str(scan.drone_id);
        let cell = self.params.cell_size_m;
        let origin = *self.origin.get_or_insert_with(|| anchor(scan, cell));
        if self.last.is_none() {
            self.start_s = scan.time_s;
        }
        self.last = Some((scan.time_s, scan.sensor));
        self.frames += 1;
        let seen_s = (scan.time_s - self.start_s) as f32;
        let keyed = self.add_points(scan, origin, seen_s);
        self.forget_cells(seen_s);
        Placed {
            keyed,
            time_s: scan.time_s,
            reset,
        }
    }

    /// Adds the classes, view and keep-out footprints of the scan `placed` came from (`scan`,
    /// whose points must be those given to [`FusionMap::place`]: where it has fewer, its classes
    /// are ignored); returns why the map started over, if it did.
    pub fn vote(&mut self, placed: Placed, scan: Scan<'_, K>) -> Option<Reset> {
        let Some(origin) = self.origin else {
            return placed.reset;
        };
        self.add_votes(&placed.keyed, &scan);
        if let Some(view) = scan.view.filter(|_| scan.classes.is_some()) {
            self.resolve(view, origin);
        }
        if let Some(k) = scan.keep_out {
            self.add_keep_out(placed.time_s, k);
        }
        placed.reset
    }

    /// The map's top surface: of each column of cells (same x/y), the highest, whose x/y lie
    /// inside `bounds` (`[min, max]`), with the class each cell's votes decide. What lies under
    /// the top of a column (a wall below its roof edge, a roof under a water tank) cannot be
    /// landed on, and the 2-D triangulation would only make slivers of it. Each cell's class is
    /// an obstacle (any class `is_landable` rejects, other than 0 = unknown) when its votes
    /// times [`FusionParams::obstacle_weight`] reach the landable votes, else the most voted
    /// landable class (flagged [`Fused::unresolved`] until a fine enough view saw the cell),
    /// else 0.
    pub fn fused(&self, bounds: [[f64; 2]; 2], is_landable: impl Fn(u8) -> bool) -> Fused {
        let surface = self.surface(bounds);
        let (classes, unresolved) = self.classes_of(&surface, is_landable);
        Fused {
            points: surface.points,
            classes,
            unresolved,
        }
    }

    /// The points of [`FusionMap::fused`] alone: its votes and views do not move them.
    pub fn surface(&self, bounds: [[f64; 2]; 2]) -> Surface {
        match self.origin {
            Some(origin) => top_surface(&self.cells, origin, self.params.cell_size_m, bounds),
            None => Surface::default(),
        }
    }

    /// The whole top surface ([`FusionMap::surface`] without bounds) with its Delaunay
    /// triangulation, in the map's own coordinates (relative to the origin
    /// [`FusionMap::origin_for`] gives), for the geometry. Both are kept between scans and
    /// changed only where the scans since the last call changed the surface (see
    /// [`MeshedSurface`] for the order of its points): most of a map stays as it was from one
    /// scan to the next. The triangulation is the one `landing_geometry::triangulate_points`
    /// makes of the points, but for the order of its triangles.
    pub fn meshed_surface(&mut self) -> MeshedSurface {
        let Some(origin) = self.origin else {
            return MeshedSurface {
                surface: Surface::default(),
                points: Vec::new(),
                triangulation: Ok(landing_geometry::Triangulation::default()),
            };
        };
        let c = self.params.cell_size_m;
        let cells = &self.cells;
        let everything = [[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]];
        self.columns.meshed(
            || top_surface(cells, origin, c, everything),
            |key| {
                cells
                    .get(key)
                    .map_or([f64::NAN; 3], |cell| cell.position(key, origin, c))
            },
            origin,
        )
    }

    /// What the kept triangulation of [`FusionMap::meshed_surface`] has done since the map was
    /// made: updates repaired in place and made from scratch, points moved and inserted.
    pub fn mesh_stats(&self) -> landing_geometry::delaunay::KeptStats {
        self.columns.mesh_stats()
    }

    /// The classes and [`Fused::unresolved`] flags of a `surface` of this map, as
    /// [`FusionMap::fused`] gives them (a cell forgotten since reads as unknown).
    pub fn classes_of(
        &self,
        surface: &Surface,
        is_landable: impl Fn(u8) -> bool,
    ) -> (Option<Vec<u8>>, Vec<bool>) {
        let landable: [bool; CLASSES] = std::array::from_fn(|i| is_landable(i as u8));
        let (classes, unresolved) =
            decide_cells(&self.cells, &self.params, &landable, &surface.keys);
        (self.classified.then_some(classes), unresolved)
    }

    /// [`FusionMap::classes_of`] the surface [`FusionMap::meshed_surface`] last gave, kept
    /// between scans: decided again only for the columns whose top cell the scans since took
    /// votes on, were resolved or changed. (Debug builds check the answer against
    /// `classes_of`.)
    pub fn meshed_classes(
        &mut self,
        is_landable: impl Fn(u8) -> bool,
    ) -> (Option<Vec<u8>>, Vec<bool>) {
        let landable: [bool; CLASSES] = std::array::from_fn(|i| is_landable(i as u8));
        let (cells, params) = (&self.cells, &self.params);
        let (classes, unresolved) = self.columns.classes(landable, |keys| {
            decide_cells(cells, params, &landable, keys)
        });
        let kept = (
            self.classified.then(|| classes.to_vec()),
            unresolved.to_vec(),
        );
        #[cfg(debug_assertions)]
        {
            let keys = self.columns.top_keys();
            let fresh = decide_cells(&self.cells, &self.params, &landable, keys);
            assert_eq!(
                (kept.0.as_deref().unwrap_or(&fresh.0), &kept.1),
                (&fresh.0[..], &fresh.1),
                "kept and fresh classes"
            );
        }
        kept
    }

    /// The kept keep-out footprints, oldest first.
    pub fn keep_outs(&self) -> impl ExactSizeIterator<Item = &K> {
        self.keep_out.iter().map(|(_, k)| k)
    }

    /// Time of the newest scan, when there is one.
    pub fn last_time_s(&self) -> Option<f64> {
        self.last.map(|(t, _)| t)
    }

    /// Frames fused since the map (re)started.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Cells held.
    pub fn cells(&self) -> usize {
        self.cells.len()
    }

    /// Bytes the cells take (table slots included) with the kept surface and its triangulation
    /// ([`FusionMap::meshed_surface`]), not counting the keep-out footprints, whose size only
    /// their owner knows.
    pub fn cell_bytes(&self) -> usize {
        self.cells.capacity() * (std::mem::size_of::<([i32; 3], Cell)>() + 1) + self.columns.bytes()
    }

    /// The world position the map's coordinates are relative to once `scan` is inserted: its
    /// origin, or one near the [`centre`] of the scan's points when the map is empty or `scan`
    /// would start it over. The caller can compute the frame in the same local coordinates the map answers
    /// in, so that every frame since the start shares them.
    pub fn origin_for(&self, scan: &Scan<'_, K>) -> [f64; 3] {
        match self.origin {
            Some(origin) if self.would_reset(scan).is_none() => origin,
            _ => anchor(scan, self.params.cell_size_m),
        }
    }

    /// Why [`FusionMap::insert`]ing `scan` would start the map over, if it would (only the
    /// scan's drone, time, sensor and reset flag count).
    pub fn would_reset(&self, scan: &Scan<'_, K>) -> Option<Reset> {
        let (time, sensor) = self.last?;
        if scan.reset {
            return Some(Reset::Requested);
        }
        if scan.drone_id != self.drone_id {
            return Some(Reset::DroneChanged);
        }
        if scan.time_s < time {
            return Some(Reset::TimeBackwards {
                seconds: time - scan.time_s,
            });
        }
        if scan.time_s - time > self.params.horizon_s {
            return Some(Reset::Gap {
                seconds: scan.time_s - time,
            });
        }
        let jump = distance(scan.sensor, sensor);
        if jump.is_nan() || jump > self.params.max_jump_m {
            return Some(Reset::PoseJump { metres: jump });
        }
        None
    }
}

impl<K> FusionMap<K> {
    /// Thins the scan's points into the cells; returns (cell, point index) of every usable
    /// point, grouped by cell.
    fn add_points(
        &mut self,
        scan: &Scan<'_, K>,
        origin: [f64; 3],
        seen_s: f32,
    ) -> Vec<([i32; 3], u32)> {
        let c = self.params.cell_size_m;
        // (cell, offset in the cell in cell units, index) of every usable point.
        let mut keyed: Vec<([i32; 3], [f32; 3], u32)> = Vec::with_capacity(scan.points.len());
        for (i, p) in scan.points.iter().enumerate() {
            let rel = [
                (p[0] - origin[0]) / c,
                (p[1] - origin[1]) / c,
                (p[2] - origin[2]) / c,
            ];
            // Beyond ±2^30 cells (> 1e7 m at 1 cm cells) a point cannot be binned.
            if !rel.iter().all(|v| v.is_finite() && v.abs() < 1.0e9) {
                continue;
            }
            let key = rel.map(|v| v.floor() as i32);
            let offset = std::array::from_fn(|k| (rel[k] - f64::from(key[k])) as f32);
            keyed.push((key, offset, i as u32));
        }
        keyed.sort_unstable_by_key(|k| k.0);
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            let cell = self.cells.entry(group[0].0).or_insert(Cell {
                mean: [0.0; 3],
                points: 0,
                votes: [0; CLASSES],
                seen_s,
                resolved: false,
                finest: f32::INFINITY,
            });
            cell.seen_s = seen_s;
            self.columns.touch(group[0].0);
            for &(_, offset, _) in group {
                let n = f32::from(cell.points.min(MAX_MEAN_WEIGHT - 1));
                for (mean, o) in cell.mean.iter_mut().zip(offset) {
                    *mean = (*mean * n + o) / (n + 1.0);
                }
                cell.points = cell.points.saturating_add(1);
            }
        }
        keyed.into_iter().map(|(key, _, i)| (key, i)).collect()
    }

    /// Gives each cell the scan's points fell in one vote: the majority class of its points
    /// there (`keyed` as [`FusionMap::add_points`] returned it).
    fn add_votes(&mut self, keyed: &[([i32; 3], u32)], scan: &Scan<'_, K>) {
        let Some(classes) = scan.classes.filter(|k| k.len() == scan.points.len()) else {
            return;
        };
        // Not the scan that was placed: its points cannot be told apart from the others'.
        if keyed.iter().any(|&(_, i)| i as usize >= classes.len()) {
            return;
        }
        self.classified = true;
        // Classes that came from no camera are as fine as their source.
        let resolved = scan.view.is_none();
        for group in keyed.chunk_by(|a, b| a.0 == b.0) {
            // Forgotten already where the scan alone overfilled the map.
            let Some(cell) = self.cells.get_mut(&group[0].0) else {
                continue;
            };
            cell.resolved |= resolved;
            let mut counts = [0u32; CLASSES];
            for &(_, i) in group {
                counts[usize::from(classes[i as usize]).min(CLASSES - 1)] += 1;
            }
            // A much finer view than every earlier one that voted here replaces their votes: a
            // far frame's pixel is smeared over the cell's surroundings (an edge, a parapet, a
            // camera blocked while its LiDAR sees), and votes of views about as fine add up.
            let footprint = scan
                .view
                .and_then(|view| (view.0)(&scan.points[group[0].1 as usize]))
                .map(|f| f as f32);
            if let Some(f) = footprint {
                if f <= FINER_VIEW * cell.finest {
                    cell.votes = [0; CLASSES];
                }
                cell.finest = cell.finest.min(f);
            }
            // The frame's majority class; ties go to the obstacle-most (highest) id.
            let (class, _) = counts
                .iter()
                .enumerate()
                .max_by_key(|&(i, &n)| (n, i))
                .unwrap_or((0, &0));
            if cell.votes[class] == u8::MAX {
                for v in &mut cell.votes {
                    *v = v.div_ceil(2);
                }
            }
            cell.votes[class] += 1;
        }
    }

    /// Marks the cells `view` saw finely enough (the whole view, not only where the scan's
    /// points fell: a scan's points hit few of the cells its camera sees). Occlusion is not
    /// checked: a cell behind something nearer the camera counts as seen, which can only
    /// matter for the cells a nearer obstacle hides, whose own class votes still decide.
    fn resolve(&mut self, view: View<'_>, origin: [f64; 3]) {
        let max = self.params.max_pixel_footprint_m;
        if max <= 0.0 {
            return;
        }
        let c = self.params.cell_size_m;
        for (key, cell) in self.cells.iter_mut().filter(|(_, cell)| !cell.resolved) {
            let p = cell.position(key, origin, c);
            cell.resolved = (view.0)(&p).is_some_and(|f| f <= max);
            if cell.resolved {
                self.columns.resolved(*key);
            }
        }
    }

    /// Keeps the newest frame's footprints and older ones spread at least the interval apart.
    fn add_keep_out(&mut self, time_s: f64, k: K) {
        let n = self.keep_out.len();
        if n >= 2
            && self.keep_out[n - 1].0 - self.keep_out[n - 2].0 < self.params.keep_out_interval_s
        {
            // The previous newest did not earn a slot of its own.
            self.keep_out.pop_back();
        }
        self.keep_out.push_back((time_s, k));
        while self.keep_out.len() > self.params.keep_out_frames {
            self.keep_out.pop_front();
        }
        let horizon = self.params.horizon_s;
        self.keep_out.retain(|(t, _)| time_s - t <= horizon);
    }

    /// Forgets cells past the horizon, then the oldest cells past the bound.
    fn forget_cells(&mut self, now_s: f32) {
        let held = self.cells.len();
        self.forget_old_cells(now_s);
        if self.cells.len() < held {
            self.columns.forget();
        }
    }

    /// [`FusionMap::forget_cells`] on the cells alone.
    fn forget_old_cells(&mut self, now_s: f32) {
        let horizon = self.params.horizon_s as f32;
        let full = self.cells.len() > self.params.max_cells;
        if full || self.frames.is_multiple_of(EXPIRY_EVERY_FRAMES) {
            self.cells.retain(|_, cell| now_s - cell.seen_s <= horizon);
        }
        if self.cells.len() > self.params.max_cells {
            // The cells seen longest ago go first.
            let excess = self.cells.len() - self.params.max_cells;
            let mut by_age: Vec<([i32; 3], f32)> =
                self.cells.iter().map(|(k, c)| (*k, c.seen_s)).collect();
            by_age.select_nth_unstable_by(excess - 1, |a, b| a.1.total_cmp(&b.1));
            for (key, _) in &by_age[..excess] {
                self.cells.remove(key);
            }
        }
    }
}

/// The top surface of `cells` (of a map with `origin` and cells of side `c`) inside `bounds`
/// ([`FusionMap::surface`]).
fn top_surface(
    cells: &HashMap<[i32; 3], Cell, BuildHasherDefault<CellHasher>>,
    origin: [f64; 3],
    c: f64,
    bounds: [[f64; 2]; 2],
) -> Surface {
    let inside = |p: &[f64; 3]| {
        p[0] >= bounds[0][0] && p[0] <= bounds[1][0] && p[1] >= bounds[0][1] && p[1] <= bounds[1][1]
    };
    // Read in the table's own (memory) order: sorting references instead would chase each one
    // afterwards. Keys are packed into one integer in (x, y, z) order, one comparison per step
    // of the sort.
    let mut columns: Vec<(u128, [f64; 3])> = cells
        .iter()
        .map(|(key, cell)| (sort_key(key), cell.position(key, origin, c)))
        .collect();
    columns.sort_unstable_by_key(|column| column.0);
    // Sorted by (x, y, z): the last cell of each column is its top.
    columns.dedup_by(|upper, lower| {
        let same_column = upper.0 >> 32 == lower.0 >> 32;
        if same_column {
            *lower = *upper;
        }
        same_column
    });
    columns.retain(|column| inside(&column.1));
    Surface {
        keys: columns.iter().map(|column| unsort_key(column.0)).collect(),
        points: columns.into_iter().map(|column| column.1).collect(),
    }
}

/// A cell key as one unsigned integer ordered as the key is, x first.
fn sort_key(key: &[i32; 3]) -> u128 {
    let flip = |v: i32| u128::from((v as u32) ^ 0x8000_0000);
    flip(key[0]) << 64 | flip(key[1]) << 32 | flip(key[2])
}

/// The key [`sort_key`] packed.
fn unsort_key(packed: u128) -> [i32; 3] {
    std::array::from_fn(|i| ((packed >> (64 - 32 * i)) as u32 ^ 0x8000_0000) as i32)
}

/// The class each of the cells `keys` decides ([`decide`]) and whether it is landable ground
/// not yet seen finely; a cell not held reads as unknown. A long list is looked up in two
/// halves at once: a lookup is mostly a wait on memory.
fn decide_cells(
    cells: &HashMap<[i32; 3], Cell, BuildHasherDefault<CellHasher>>,
    params: &FusionParams,
    landable: &[bool; CLASSES],
    keys: &[[i32; 3]],
) -> (Vec<u8>, Vec<bool>) {
    let weight = params.obstacle_weight;
    let resolving = params.max_pixel_footprint_m > 0.0;
    let of = |keys: &[[i32; 3]]| -> (Vec<u8>, Vec<bool>) {
        (keys.iter())
            .map(|key| {
                let Some(cell) = cells.get(key) else {
                    return (0, false);
                };
                let class = decide(&cell.votes, landable, weight);
                (
                    class,
                    resolving && !cell.resolved && landable[usize::from(class)],
                )
            })
            .unzip()
    };
    if keys.len() < PARALLEL_LOOKUPS {
        return of(keys);
    }
    let (first, second) = keys.split_at(keys.len() / 2);
    let ((mut classes, mut unresolved), (rest, rest_unresolved)) = std::thread::scope(|threads| {
        let half = threads.spawn(|| of(second));
        let mine = of(first);
        (
            mine,
            half.join().unwrap_or_else(|p| std::panic::resume_unwind(p)),
        )
    });
    classes.extend(rest);
    unresolved.extend(rest_unresolved);
    (classes, unresolved)
}

/// The class a cell's votes decide (see [`FusionMap::fused`]).
fn decide(votes: &[u8; CLASSES], landable: &[bool; CLASSES], weight: u32) -> u8 {
    let (mut obstacle, mut safe) = (0u32, 0u32);
    let (mut top_obstacle, mut top_safe) = ((0u8, 0u8), (0u8, 0u8));
    for (class, &n) in votes.iter().enumerate().skip(1) {
        let pick = (n, class as u8);
        if landable[class] {
            safe += u32::from(n);
            top_safe = top_safe.max(pick);
        } else {
            obstacle += u32::from(n);
            top_obstacle = top_obstacle.max(pick);
        }
    }
    if obstacle > 0 && obstacle * weight >= safe {
        top_obstacle.1
    } else if safe > 0 {
        top_safe.1
    } else {
        0
    }
}

fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}
