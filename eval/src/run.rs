//! Running the evaluation: every scenario frame through the real service in every mode, each
//! answer scored against the ground truth.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use landing_proto::v1::{
    CameraImage, Frame, FrameResult, LandingSite, PipelineOptions, StageTimings,
};

use crate::geom::{P2, Polygon2, convex_hull};
use crate::metrics::{MetricsParams, RoofTruth, Site, evaluate_frame};
use crate::report::{FrameFailure, FrameRecord, Mode, STEPS};
use landing_client::LandingClient;

use crate::EvalError;

/// One frame with its ground truth.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Recording file and frame sequence, e.g. `w3.mcap#12`.
    pub name: String,
    /// Hard-case tags (`tarp`, `water_tower`, ...), from the ground truth.
    pub tags: Vec<String>,
    pub frame: Frame,
    /// The true label image of the frame's camera, sent as its class image in `truth` mode.
    pub labels: Option<CameraImage>,
    /// The roofs in view with their obstacles.
    pub roofs: Vec<RoofTruth>,
}

/// How the evaluation runs.
#[derive(Debug, Clone, PartialEq)]
pub struct EvalConfig {
    /// Modes compared, in report order.
    pub modes: Vec<Mode>,
    /// Metric parameters; `tolerance_m` is replaced by the request's polylabel precision.
    pub metrics: MetricsParams,
    /// Pipeline options sent with every frame (the segmentation mode is set per mode).
    pub options: PipelineOptions,
    /// Thickness of the band around a roof's height in which LiDAR points count as hitting the
    /// roof surface, for the scanned region, metres.
    pub roof_band_m: f64,
    /// Folder for top-down pictures of frames with an unsafe site (`None`: none drawn).
    pub overlay_dir: Option<PathBuf>,
    /// Draw every frame, not only those with an unsafe site.
    pub overlay_all: bool,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            modes: Mode::ALL.to_vec(),
            metrics: MetricsParams::default(),
            options: PipelineOptions::default(),
            roof_band_m: 0.2,
            overlay_dir: None,
            overlay_all: false,
        }
    }
}

/// Fills each roof's scanned region, where the ground truth left it open, with the convex hull of
/// the frame's LiDAR returns on that roof's surface (points inside the walkable roof within
/// `band_m` of its height). A roof with fewer than three such points gets an empty region.
pub fn fill_scanned_regions(scenario: &mut Scenario, band_m: f64) -> Result<(), EvalError> {
    if scenario.roofs.iter().all(|r| r.scanned.is_some()) {
        return Ok(());
    }
    let cloud = scenario
        .frame
        .point_cloud
        .as_ref()
        .ok_or(EvalError::Invalid {
            field: "frame.point_cloud",
            reason: "missing".into(),
        })?;
    let world = landing_client::unpack_point_cloud(cloud)?.to_world(cloud.pose.as_ref());
    for roof in scenario.roofs.iter_mut().filter(|r| r.scanned.is_none()) {
        let hits: Vec<P2> = world
            .iter()
            .filter(|p| {
                (p[2] - roof.height_m).abs() <= band_m && roof.interior.contains([p[0], p[1]])
            })
            .map(|p| [p[0], p[1]])
            .collect();
        let hull = convex_hull(&hits);
        roof.scanned = Some(if hull.len() >= 3 {
            Polygon2::simple(hull)
        } else {
            Polygon2::default()
        });
    }
    Ok(())
}

/// The metrics' view of a returned site.
pub fn site_of(s: &LandingSite) -> Site {
    let ring = |r: &landing_proto::v1::LinearRing| {
        r.points.iter().map(|p| [p.x, p.y]).collect::<Vec<P2>>()
    };
    let polygon = s
        .polygon
        .as_ref()
        .map(|p| Polygon2 {
            shell: p.shell.as_ref().map(ring).unwrap_or_default(),
            holes: p.holes.iter().map(ring).collect(),
        })
        .unwrap_or_default();
    let center = s.center.as_ref().map_or([f64::NAN; 3], |c| [c.x, c.y, c.z]);
    let plane_height_m = s.polygon.as_ref().map_or(center[2], |p| p.plane_height_m);
    Site {
        rank: s.rank,
        polygon,
        center: [center[0], center[1]],
        plane_height_m,
        radius_m: s.safe_radius_m,
    }
}

/// The server's per-step times of a result, milliseconds, in [`STEPS`] order.
pub fn step_times_ms(t: Option<&StageTimings>) -> Vec<Option<f64>> {
    let Some(t) = t else {
        return vec![None; STEPS.len()];
    };
    let ms = |d: &Option<prost_types::Duration>| {
        d.and_then(landing_client::duration_from_proto)
            .map(|d: Duration| d.as_secs_f64() * 1e3)
    };
    vec![
        ms(&t.queue),
        ms(&t.decode),
        ms(&t.segmentation),
        ms(&t.classification),
        ms(&t.triangulation),
        ms(&t.triangle_filter),
        ms(&t.plane_extraction),
        ms(&t.polygon_extraction),
        ms(&t.polylabel),
        ms(&t.total),
    ]
}

/// Scores one answer.
pub fn record_of(
    scenario: &Scenario,
    mode: Mode,
    result: &FrameResult,
    round_trip: Duration,
    params: &MetricsParams,
) -> FrameRecord {
    let sites: Vec<Site> = result.sites.iter().map(site_of).collect();
    FrameRecord {
        mode,
        frame: scenario.name.clone(),
        tags: scenario.tags.clone(),
        step_ms: step_times_ms(result.timings.as_ref()),
        round_trip_ms: round_trip.as_secs_f64() * 1e3,
        eval: evaluate_frame(&sites, &scenario.roofs, params),
    }
}

/// Sends every scenario in every mode to the service (one unary call at a time, so that the
/// timings are not inflated by queueing) and scores the answers. A frame the server refuses is a
/// [`FrameFailure`], not an error of the run; an unreachable server is.
pub async fn run(
    client: &LandingClient,
    scenarios: &[Scenario],
    config: &EvalConfig,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Vec<FrameRecord>, Vec<FrameFailure>), EvalError> {
    let info = client.info().await?;
    let precision = config
        .options
        .polylabel_precision_m
        .or_else(|| {
            info.default_options
                .as_ref()
                .and_then(|o| o.polylabel_precision_m)
        })
        .unwrap_or(config.metrics.tolerance_m);
    let params = MetricsParams {
        tolerance_m: precision,
        ..config.metrics.clone()
    };
    let mut records = Vec::new();
    let mut failures = Vec::new();
    for (i, scenario) in scenarios.iter().enumerate() {
        for &mode in &config.modes {
            let options = PipelineOptions {
                segmentation_mode: mode.segmentation_mode() as i32,
                ..config.options.clone()
            };
            let mut frame = scenario.frame.clone();
            if mode == Mode::Truth {
                frame.class_image.clone_from(&scenario.labels);
            }
            let started = Instant::now();
            match client.detect_with(frame, Some(options)).await {
                Ok(result) => {
                    let record = record_of(scenario, mode, &result, started.elapsed(), &params);
                    if let Some(dir) = &config.overlay_dir {
                        let any_unsafe = record.eval.sites.iter().any(|s| s.verdict.is_unsafe());
                        if any_unsafe || config.overlay_all {
                            write_overlay(dir, scenario, mode, &result, &record)?;
                        }
                    }
                    records.push(record);
                }
                Err(e) if e.code().is_some() && !e.is_unreachable() => {
                    failures.push(FrameFailure {
                        mode,
                        frame: scenario.name.clone(),
                        error: e.to_string(),
                    })
                }
                Err(e) => return Err(e.into()),
            }
        }
        progress(i + 1, scenarios.len());
    }
    Ok((records, failures))
}

/// Draws one answer over the truth into `dir` as `<recording>-<sequence>-<mode>.png`.
fn write_overlay(
    dir: &std::path::Path,
    scenario: &Scenario,
    mode: Mode,
    result: &FrameResult,
    record: &FrameRecord,
) -> Result<(), EvalError> {
    std::fs::create_dir_all(dir).map_err(|e| EvalError::Io {
        path: dir.display().to_string(),
        source: e,
    })?;
    let sites: Vec<Site> = result.sites.iter().map(site_of).collect();
    let title = format!("{} {}", scenario.name, mode.name());
    if let Some(canvas) =
        crate::overlay::draw_overlay(&title, &scenario.roofs, &sites, &record.eval.sites)
    {
        let stem: String = scenario
            .name
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect();
        canvas.save(&dir.join(format!("{stem}-{}.png", mode.name())))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use landing_client::{FrameBuilder, PointCloudBuilder};
    use landing_proto::v1::{LinearRing, Vector3};

    #[test]
    fn sites_convert_with_holes_and_height() {
        let v = |x, y| Vector3 { x, y, z: 30.0 };
        let site = LandingSite {
            rank: 2,
            polygon: Some(landing_proto::v1::Polygon {
                shell: Some(LinearRing {
                    points: vec![v(0.0, 0.0), v(4.0, 0.0), v(4.0, 4.0), v(0.0, 4.0)],
                }),
                holes: vec![LinearRing {
                    points: vec![v(1.0, 1.0), v(1.0, 2.0), v(2.0, 2.0)],
                }],
                plane_height_m: 30.0,
            }),
            center: Some(v(3.0, 3.0)),
            safe_radius_m: 1.0,
            ..Default::default()
        };
        let s = site_of(&site);
        assert_eq!(
            (s.rank, s.center, s.plane_height_m, s.radius_m),
            (2, [3.0, 3.0], 30.0, 1.0)
        );
        assert_eq!(s.polygon.holes.len(), 1);
        assert!((s.polygon.area() - 15.5).abs() < 1e-9);
    }

    #[test]
    fn scanned_region_is_the_hull_of_roof_surface_points() {
        // Points on a roof at 20 m over x, y in 2..6, a point on an obstacle top and one on the
        // street: only the roof surface counts.
        let mut pts: Vec<[f32; 3]> = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                pts.push([2.0 + i as f32, 2.0 + j as f32, 20.02]);
            }
        }
        pts.push([9.0, 9.0, 21.5]);
        pts.push([30.0, 5.0, 0.0]);
        let cloud = PointCloudBuilder::new(&pts).build().unwrap();
        let frame = FrameBuilder::new(1, cloud).build();
        let roof = RoofTruth {
            id: 0,
            outline: Polygon2::rect([0.0, 0.0], [10.0, 10.0]),
            interior: Polygon2::rect([0.0, 0.0], [10.0, 10.0]),
            height_m: 20.0,
            obstacles: vec![],
            scanned: None,
            hidden: vec![],
            stated_best_radius_m: None,
            scored: true,
            target: true,
        };
        let mut sc = Scenario {
            name: "t#1".into(),
            tags: vec![],
            frame,
            labels: None,
            roofs: vec![roof],
        };
        fill_scanned_regions(&mut sc, 0.2).unwrap();
        let s = sc.roofs[0].scanned.as_ref().unwrap();
        assert!((s.area() - 16.0).abs() < 1e-6, "{s:?}");
    }

    #[test]
    fn missing_timings_are_none() {
        assert_eq!(step_times_ms(None), vec![None; STEPS.len()]);
        let t = StageTimings {
            total: Some(prost_types::Duration {
                seconds: 0,
                nanos: 2_500_000,
            }),
            ..Default::default()
        };
        let ms = step_times_ms(Some(&t));
        assert_eq!(ms[9], Some(2.5));
        assert_eq!(ms[0], None);
    }
}
