//! A fused stream's frame: its scan laid onto the stream's map, and the answer computed from
//! everything the map holds ([`run_fused`]).
//!
//! The steps, each a method of [`FusedFrame`]: on a second thread, **register** the scan onto
//! the map (the frame's poses move by the correction) and **place** its points in the map,
//! bringing the map's top surface and its triangulation (both kept between frames) up to date,
//! while this one segments the frame's image; then **classify** the points, let their classes
//! **vote**, and **answer** with the geometry on the map's cells, a [`CloudKind::FusedMap`] (whose
//! mechanisms are explained there). What can be wrong with the frame's input is found before the
//! map changes; once its points are in and its classes cannot be, the map starts over.

use std::time::{Duration, Instant};

use landing_fusion::{Correction, MeshedSurface, NotRegistered, Placed, Scan, View};
use landing_geometry::{CloudKind, Triangulation};
use landing_perception::ObstacleRays;
use nalgebra::{Isometry3, Point3};

use super::evidence::{MapSurface, evidence};
use super::{
    Classified, Decoded, Frame, FrameOptions, FrameOutput, FusionSummary, Located, Pipeline,
    StreamMap, classify, decode, locate, relative_to, segment, to_local, to_world,
};
use crate::Error;
use crate::segmentation::Judged;

/// Runs the pipeline on a fused stream's frame: the frame's scan is registered, its points are
/// added to the stream's `map` and its kept top surface and triangulation brought up to date on
/// a second thread while the frame's image is segmented ([`Judged::InStream`]), its points'
/// classes then vote, and the answer is computed from all the map's
/// points (what the approach has scanned so far) as a [`CloudKind::FusedMap`], keeping clear of
/// the keep-out footprints of every frame the map remembers.
/// `reset` starts the map over first. A frame without a timestamp counts as taken at the
/// previous frame's time. The frame-local coordinates are the map's own (its origin), so that
/// the keep-out footprints of every kept frame share them.
pub fn run_fused(
    frame: &Frame,
    options: &FrameOptions,
    pipeline: &Pipeline,
    map: &mut StreamMap,
    reset: bool,
) -> Result<FrameOutput, Error> {
    let step = FusedFrame {
        frame,
        options,
        pipeline,
        start: Instant::now(),
    };
    // What can be wrong with the frame's input is found before the map changes.
    let decoded = decode(frame, options, pipeline)?;
    let (registered, surfaced, classified) = step.place_and_classify(map, reset, decoded)?;
    let voted = step.vote(map, &registered, surfaced, classified);
    step.answer(map, registered, voted)
}

/// One frame of a fused stream on its way through the map, and when it started.
struct FusedFrame<'a> {
    frame: &'a Frame,
    options: &'a FrameOptions,
    pipeline: &'a Pipeline,
    start: Instant,
}

/// The frame's scan laid onto the map: its points and sensor moved by the registration's
/// correction (none when it did not register), and the map's origin for it.
struct Registered {
    time_s: f64,
    sensor: [f64; 3],
    reset: bool,
    /// World points, in double precision (the map bins in it).
    points: Vec<[f64; 3]>,
    registration: Result<Correction, NotRegistered>,
    correction: Isometry3<f64>,
    /// The frame-local coordinates' origin, world frame.
    origin: [f64; 3],
    /// Time spent registering.
    time: Duration,
}

/// The map's top surface with the frame's points placed in it.
struct Surfaced {
    placed: Placed,
    /// The surface's points in frame-local coordinates.
    local: Vec<[f32; 3]>,
    triangulated: Result<Triangulation, landing_geometry::GeometryError>,
    /// Time spent placing the points.
    placing: Duration,
    /// Time spent bringing the surface and its triangulation up to date.
    triangulation: Duration,
}

/// The map after the frame's vote: the surface's classes, and what the answer is made from.
struct Voted {
    /// The surface's points in frame-local coordinates.
    local: Vec<[f32; 3]>,
    triangulated: Result<Triangulation, landing_geometry::GeometryError>,
    triangulation: Duration,
    classified: Classified,
    classes: Option<Vec<u8>>,
    /// Per surface point: on landable ground no camera has seen finely enough yet.
    unresolved: Vec<bool>,
    /// Why the map started over at this frame.
    reset: Option<String>,
}

impl FusedFrame<'_> {
    /// The scan as taken: the frame's time (or the previous frame's) and its sensor.
    fn scan<'s>(&'s self, registered: &'s Registered) -> Scan<'s, ObstacleRays> {
        Scan {
            time_s: registered.time_s,
            sensor: registered.sensor,
            reset: registered.reset,
            points: &registered.points,
            ..Scan::new(&self.frame.drone_id)
        }
    }

    /// Lays the scan onto the map: the frame's poses (LiDAR and cameras alike, one rigid body)
    /// move by the correction, so its classes and keep-out footprints land where its points do.
    /// A map about to start over has nothing to register to.
    fn register(&self, map: &StreamMap, reset: bool) -> Registered {
        let start = Instant::now();
        let mut points = to_world(&self.frame.cloud);
        let time_s = self
            .frame
            .timestamp
            .map(|t| t.seconds as f64 + f64::from(t.nanos) * 1e-9)
            .or(map.last_time_s())
            .unwrap_or(0.0);
        let mut sensor = Point3::from(self.frame.cloud.pose.translation.vector);
        let taken = Scan::<ObstacleRays> {
            time_s,
            sensor: sensor.into(),
            reset,
            ..Scan::new(&self.frame.drone_id)
        };
        let registration = match map.would_reset(&taken) {
            Some(_) => Err(NotRegistered::Nothing),
            None => map.register(&points, taken.sensor),
        };
        let time = start.elapsed();
        let correction = registration
            .as_ref()
            .map_or_else(|_| Isometry3::identity(), Correction::isometry);
        if registration.is_ok() {
            for p in &mut points {
                *p = (correction * Point3::from(*p)).into();
            }
            sensor = correction * sensor;
        }
        let mut registered = Registered {
            time_s,
            sensor: sensor.into(),
            reset,
            points,
            registration,
            correction,
            origin: [0.0; 3],
            time,
        };
        registered.origin = map.origin_for(&self.scan(&registered));
        registered
    }

    /// Registers the scan, places its points in the map and brings the map's top surface and
    /// the surface's triangulation up to date on a second thread while this one segments the
    /// frame's image (which needs no pose), then classifies the points: votes do not move the
    /// map's points. The answer covers everything the map holds: what the approach has scanned
    /// of the roof (and around it) within the horizon, not only the current scan's footprint,
    /// which shrinks as the drone descends. The map starts over when either fails.
    fn place_and_classify(
        &self,
        map: &mut StreamMap,
        reset: bool,
        decoded: Decoded,
    ) -> Result<(Registered, Surfaced, Classified), Error> {
        let (segmented, placed) = std::thread::scope(|threads| {
            let placing = threads.spawn(|| {
                let registered = self.register(map, reset);
                let surfaced = place(map, &self.scan(&registered), registered.origin);
                (registered, surfaced)
            });
            let segmented = segment(decoded, self.options, self.pipeline, Judged::InStream);
            (segmented, placing.join())
        });
        let Ok((registered, surfaced)) = placed else {
            map.clear();
            return Err(Error::Internal("fusing the frame's points panicked".into()));
        };
        let origin = registered.origin;
        let by = to_local(origin) * registered.correction;
        let points = relative_to(&registered.points, origin);
        match segmented.and_then(|s| classify(self.frame, s, &by, points, self.options)) {
            Ok(classified) => Ok((registered, surfaced, classified)),
            Err(e) => {
                // The scan's points are in and its classes cannot be: start the map over.
                map.clear();
                Err(e)
            }
        }
    }

    /// The frame's classes vote in the map's cells, where its camera saw finely enough, and the
    /// surface gets the map's classes.
    fn vote(
        &self,
        map: &mut StreamMap,
        registered: &Registered,
        surfaced: Surfaced,
        mut classified: Classified,
    ) -> Voted {
        let map_start = Instant::now();
        // How finely the frame's camera saw each place (the map's positions are world ones, the
        // view's frame-local): safe circles keep clear of what no fine view has seen.
        let local = to_local(registered.origin);
        let footprint = classified.view.as_ref().map(|view| {
            move |p: &[f64; 3]| view.footprint_on_level_ground(&(local * Point3::from(*p)))
        });
        let Surfaced {
            placed,
            local,
            triangulated,
            placing,
            triangulation,
        } = surfaced;
        let reset = map.vote(
            placed,
            Scan {
                classes: classified.classes.as_deref(),
                view: footprint.as_ref().map(|f| View(f)),
                keep_out: classified.obstacles.take(),
                ..self.scan(registered)
            },
        );
        let landable = &self.options.params.landable_classes;
        let (classes, unresolved) = map.meshed_classes(|class| landable.contains(&class));
        let fusion = registered.time + placing + map_start.elapsed();
        classified.timings.fusion = Some(fusion);
        Voted {
            local,
            triangulated,
            triangulation,
            classified,
            classes,
            unresolved,
            reset: reset.map(|r| r.to_string()),
        }
    }

    /// The geometry on the map's cells, keeping clear of the footprints of every frame the map
    /// remembers, with what the answer came from.
    fn answer(
        &self,
        map: &StreamMap,
        registered: Registered,
        voted: Voted,
    ) -> Result<FrameOutput, Error> {
        let Voted {
            local,
            triangulated,
            triangulation,
            classified,
            classes,
            unresolved,
            reset,
        } = voted;
        let keep_out: Vec<&ObstacleRays> = map.keep_outs().collect();
        let summary = FusionSummary {
            frames: map.frames(),
            points: local.len(),
            cells: map.cells(),
            registration: registered.registration,
            reset,
            keep_out_frames: keep_out.len(),
        };
        let located = Located {
            points: &local,
            classes: classes.as_deref(),
            kind: CloudKind::FusedMap {
                cell_size_m: map.params().cell_size_m,
            },
            keep_out: &keep_out,
            unresolved: &unresolved,
            origin: registered.origin,
            params: &self.options.params,
            triangulated: Some((triangulated?, triangulation)),
        };
        let mode = classified.mode;
        let mut out = locate(self.frame, located, mode, classified.timings, self.start)?;
        out.fusion = Some(summary);
        if self.pipeline.catalogue {
            let surface = MapSurface {
                points: &local,
                origin: registered.origin,
                classes: classes.as_deref(),
                unresolved: &unresolved,
                landable: &self.options.params.landable_classes,
                resolving: map.params().max_pixel_footprint_m > 0.0,
            };
            out.catalog = Some(evidence(self.frame.geodetic_origin, &surface, &out.sites));
        }
        Ok(out)
    }
}

/// Places the scan's points in the map and brings its kept top surface and triangulation up to
/// date (in the map's coordinates: relative to its origin, which is `origin`), timing both.
fn place(map: &mut StreamMap, scan: &Scan<'_, ObstacleRays>, origin: [f64; 3]) -> Surfaced {
    let t = Instant::now();
    let placed = map.place(scan);
    let placing = t.elapsed();
    let t = Instant::now();
    let MeshedSurface {
        surface,
        points: local,
        triangulation: triangulated,
    } = map.meshed_surface();
    debug_assert!(
        surface.points.is_empty() || map.origin_for(scan) == origin,
        "the map's coordinates are relative to the frame's origin"
    );
    #[cfg(debug_assertions)]
    if let Ok(kept) = &triangulated {
        check_kept(&local, kept);
    }
    Surfaced {
        placed,
        local,
        triangulated,
        placing,
        triangulation: t.elapsed(),
    }
}

/// Debug builds (the tests) check every kept triangulation against a fresh one of the same
/// points: a Delaunay triangulation of them with the same number of triangles.
#[cfg(debug_assertions)]
fn check_kept(points: &[[f32; 3]], kept: &Triangulation) {
    let xy: Vec<[f64; 2]> = points
        .iter()
        .map(|p| [f64::from(p[0]), f64::from(p[1])])
        .collect();
    if let Err(e) = kept.check_invariants(&xy, true) {
        panic!("the kept triangulation is no Delaunay triangulation: {e}");
    }
    let fresh = landing_geometry::triangulate_points(points).map_or(0, |t| t.len());
    assert_eq!(kept.len(), fresh, "kept and fresh triangle counts");
}
