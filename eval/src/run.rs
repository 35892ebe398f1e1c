//! Running the evaluation: every scenario frame through the real service in every mode, each
//! answer scored against the ground truth; with [`EvalConfig::stream`], also every approach as
//! one fused stream per mode.

use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use landing_proto::v1::{
    CameraImage, Frame, FrameResult, FusionOptions, LandingSite, OverflowPolicy, PipelineOptions,
    StageTimings,
};

use crate::approach::{ApproachFrame, fused_roofs};
use crate::geom::{P2, Polygon2, convex_hull};
use crate::metrics::{MetricsParams, RoofTruth, Site, evaluate_frame};
use crate::report::{FrameFailure, FrameRecord, FusionInfo, Mode, STEPS, column_name};
use landing_client::{
    ClientError, FrameError, FrameOutcome, LandingClient, StreamConfig, StreamItem, StreamMode,
};

use crate::EvalError;

/// One frame with its ground truth.
#[derive(Debug, Clone)]
pub struct Scenario {
    /// Recording file and frame sequence, e.g. `w3.mcap#12`.
    pub name: String,
    /// Where the frame stands in its approach (its recording).
    pub at: ApproachFrame,
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
    /// Metric parameters; `tolerance_m` is replaced by `tolerance_m` below, else by the
    /// request's polylabel precision.
    pub metrics: MetricsParams,
    /// Safety tolerance, metres, when it should be stricter (or looser) than the declared
    /// polylabel precision, the paper's rule; `None`: the declared precision.
    pub tolerance_m: Option<f64>,
    /// Pipeline options sent with every frame (the segmentation mode is set per mode).
    pub options: PipelineOptions,
    /// Thickness of the band around a roof's height in which LiDAR points count as hitting the
    /// roof surface, for the scanned region, metres.
    pub roof_band_m: f64,
    /// Folder for top-down pictures of frames with an unsafe site (`None`: none drawn).
    pub overlay_dir: Option<PathBuf>,
    /// Draw every frame, not only those with an unsafe site.
    pub overlay_all: bool,
    /// Also send each approach as one fused stream per mode, with these fusion options
    /// (`landing eval --stream`); `None`: single frames only.
    pub stream: Option<FusionOptions>,
    /// Frames of a fused stream sent and unanswered at once.
    pub stream_max_in_flight: usize,
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
            stream: None,
            stream_max_in_flight: 4,
            tolerance_m: None,
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
    t.by_stage()
        .iter()
        .map(|d| {
            d.and_then(landing_client::duration_from_proto)
                .map(|d: Duration| d.as_secs_f64() * 1e3)
        })
        .collect()
}

/// Scores one single-frame answer against the frame's truth.
pub fn record_of(
    scenario: &Scenario,
    mode: Mode,
    result: &FrameResult,
    round_trip: Duration,
    params: &MetricsParams,
) -> FrameRecord {
    score(
        scenario,
        &scenario.roofs,
        false,
        mode,
        result,
        round_trip,
        params,
    )
}

/// Scores one answer of a fused stream against `roofs`, the truth of the approach's scans so far
/// ([`fused_roofs`]).
pub fn fused_record_of(
    scenario: &Scenario,
    roofs: &[RoofTruth],
    mode: Mode,
    result: &FrameResult,
    round_trip: Duration,
    params: &MetricsParams,
) -> FrameRecord {
    score(scenario, roofs, true, mode, result, round_trip, params)
}

fn score(
    scenario: &Scenario,
    roofs: &[RoofTruth],
    fused: bool,
    mode: Mode,
    result: &FrameResult,
    round_trip: Duration,
    params: &MetricsParams,
) -> FrameRecord {
    let sites: Vec<Site> = result.sites.iter().map(site_of).collect();
    FrameRecord {
        mode,
        frame: scenario.name.clone(),
        at: scenario.at.clone(),
        fused,
        fusion: result.fusion.as_ref().map(FusionInfo::from),
        tags: scenario.tags.clone(),
        step_ms: step_times_ms(result.timings.as_ref()),
        round_trip_ms: round_trip.as_secs_f64() * 1e3,
        eval: evaluate_frame(&sites, roofs, params),
    }
}

/// Sends every scenario in every mode to the service (one unary call at a time, so that the
/// timings are not inflated by queueing) and scores the answers; then, with
/// [`EvalConfig::stream`], every approach again as one fused stream per mode ([`run_streams`]).
/// A frame the server refuses is a [`FrameFailure`], not an error of the run; an unreachable
/// server is. `progress` gets (frames done, frames to do) over both passes.
pub async fn run(
    client: &LandingClient,
    scenarios: &[Scenario],
    config: &EvalConfig,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Vec<FrameRecord>, Vec<FrameFailure>), EvalError> {
    let params = scoring_params(client, config).await?;
    let passes = if config.stream.is_some() { 2 } else { 1 };
    let total = scenarios.len() * passes;
    let mut records = Vec::new();
    let mut failures = Vec::new();
    for (i, scenario) in scenarios.iter().enumerate() {
        for &mode in &config.modes {
            let frame = frame_to_send(scenario, mode);
            let started = Instant::now();
            match client
                .detect_with(frame, Some(mode_options(config, mode)))
                .await
            {
                Ok(result) => {
                    let record = record_of(scenario, mode, &result, started.elapsed(), &params);
                    let title = format!("{} {}", scenario.name, mode.name());
                    draw_if_asked(config, &title, &scenario.roofs, &result, &record)?;
                    records.push(record);
                }
                Err(e) if e.code().is_some() && !e.is_unreachable() => {
                    failures.push(FrameFailure {
                        mode,
                        frame: scenario.name.clone(),
                        fused: false,
                        error: e.to_string(),
                    })
                }
                Err(e) => return Err(e.into()),
            }
        }
        progress(i + 1, total);
    }
    if let Some(fusion) = &config.stream {
        let done = scenarios.len();
        let (r, f) = run_streams(client, scenarios, config, fusion, &params, |k| {
            progress(done + k, total)
        })
        .await?;
        records.extend(r);
        failures.extend(f);
    }
    Ok((records, failures))
}

/// The metric parameters the answers are judged with: the safety tolerance is
/// [`EvalConfig::tolerance_m`], else the request's polylabel precision, else the server's.
pub async fn scoring_params(
    client: &LandingClient,
    config: &EvalConfig,
) -> Result<MetricsParams, EvalError> {
    let info = client.info().await?;
    let tolerance = config
        .tolerance_m
        .or(config.options.polylabel_precision_m)
        .or_else(|| {
            info.default_options
                .as_ref()
                .and_then(|o| o.polylabel_precision_m)
        })
        .unwrap_or(config.metrics.tolerance_m);
    Ok(MetricsParams {
        tolerance_m: tolerance,
        ..config.metrics.clone()
    })
}

/// The approaches of `scenarios`: the indices of each recording's frames, in approach order
/// (by [`ApproachFrame::index`]), the approaches in the order their first frame appears.
pub fn approaches(scenarios: &[Scenario]) -> Vec<Vec<usize>> {
    let mut out: Vec<(&str, Vec<usize>)> = Vec::new();
    for (i, s) in scenarios.iter().enumerate() {
        match out.iter_mut().find(|(name, _)| *name == s.at.approach) {
            Some((_, v)) => v.push(i),
            None => out.push((&s.at.approach, vec![i])),
        }
    }
    out.into_iter()
        .map(|(_, mut v)| {
            v.sort_by_key(|&i| scenarios[i].at.index);
            v
        })
        .collect()
}

/// Sends every approach ([`approaches`]) in every mode as one fused stream (`OVERFLOW_POLICY_BLOCK`,
/// at most [`EvalConfig::stream_max_in_flight`] frames in flight, the mode's options on every
/// frame, `fusion` on the first) and scores each answer against the truth of the approach's
/// scans so far ([`fused_roofs`]). Round trips include the wait behind the frames in flight.
/// Every frame sent gets one record or one [`FrameFailure`]: a refused frame, a broken stream
/// (its unanswered frames, and those not sent) are failures; an unreachable server is an error,
/// and so is a result without a fusion summary (the server does not fuse: the fused columns
/// would silently be single-frame ones). `progress` gets the frames done so far.
pub async fn run_streams(
    client: &LandingClient,
    scenarios: &[Scenario],
    config: &EvalConfig,
    fusion: &FusionOptions,
    params: &MetricsParams,
    mut progress: impl FnMut(usize),
) -> Result<(Vec<FrameRecord>, Vec<FrameFailure>), EvalError> {
    let mut records = Vec::new();
    let mut failures = Vec::new();
    let mut done = 0;
    for approach in approaches(scenarios) {
        let frames: Vec<&Scenario> = approach.iter().map(|&i| &scenarios[i]).collect();
        let roofs = fused_roofs(
            &frames
                .iter()
                .map(|s| s.roofs.as_slice())
                .collect::<Vec<_>>(),
            params.cell_m,
        );
        for &mode in &config.modes {
            let (r, f) =
                stream_approach(client, &frames, &roofs, mode, config, fusion, params).await?;
            records.extend(r);
            failures.extend(f);
        }
        done += frames.len();
        progress(done);
    }
    Ok((records, failures))
}

/// One approach through one fused stream in one mode.
async fn stream_approach(
    client: &LandingClient,
    frames: &[&Scenario],
    roofs: &[Vec<RoofTruth>],
    mode: Mode,
    config: &EvalConfig,
    fusion: &FusionOptions,
    params: &MetricsParams,
) -> Result<(Vec<FrameRecord>, Vec<FrameFailure>), EvalError> {
    let window = config.stream_max_in_flight.max(1);
    let (sender, mut results) = client.open_stream(StreamConfig {
        overflow_policy: OverflowPolicy::Block,
        options: Some(mode_options(config, mode)),
        max_in_flight: window,
        mode: StreamMode::Fused(*fusion),
    });
    let mut scoring = StreamScoring::new(frames, roofs, mode, config, params);
    // Sending and receiving alternate on this task: a frame is only sent while the window has
    // room, so a send never waits on an answer that nobody is reading. Once every frame is sent,
    // dropping the sender ends the request stream: the server answers what is in flight and
    // closes, which ends `results`.
    let mut sender = Some(sender);
    let mut next = 0;
    loop {
        if let Some(tx) = sender.as_mut() {
            if next < frames.len() && tx.in_flight() < window {
                match tx.send(frame_to_send(frames[next], mode)).await {
                    Ok(()) => next += 1,
                    // The stream is over; what it left unanswered comes out of `results`.
                    Err(_) => sender = None,
                }
                continue;
            }
            if next == frames.len() {
                sender = None;
            }
        }
        let Some(item) = results.next().await else {
            break;
        };
        match item {
            Ok(item) => scoring.answer(item)?,
            Err(ClientError::StreamBroken { unanswered, status })
                if status
                    .as_ref()
                    .is_none_or(|s| landing_client::code_label(s.code) != "unavailable") =>
            {
                scoring.broken(&unanswered, status.as_deref());
                break;
            }
            Err(e) => return Err(e.into()),
        }
    }
    Ok(scoring.finish())
}

/// The answers of one fused stream of an approach, scored as they come; every frame ends up with
/// one record or one failure.
struct StreamScoring<'a> {
    frames: &'a [&'a Scenario],
    roofs: &'a [Vec<RoofTruth>],
    mode: Mode,
    config: &'a EvalConfig,
    params: &'a MetricsParams,
    /// The index in `frames` of each frame sequence.
    by_sequence: HashMap<u64, usize>,
    answered: Vec<bool>,
    records: Vec<FrameRecord>,
    failures: Vec<FrameFailure>,
}

impl<'a> StreamScoring<'a> {
    fn new(
        frames: &'a [&'a Scenario],
        roofs: &'a [Vec<RoofTruth>],
        mode: Mode,
        config: &'a EvalConfig,
        params: &'a MetricsParams,
    ) -> Self {
        let by_sequence = frames
            .iter()
            .enumerate()
            .map(|(k, s)| (s.frame.sequence, k))
            .collect();
        Self {
            frames,
            roofs,
            mode,
            config,
            params,
            by_sequence,
            answered: vec![false; frames.len()],
            records: Vec::new(),
            failures: Vec::new(),
        }
    }

    /// Scores one answer. A result without a fusion summary is an error: the server does not
    /// fuse, and the fused columns would silently be single-frame ones.
    fn answer(&mut self, item: StreamItem) -> Result<(), EvalError> {
        let Some(&k) = self.by_sequence.get(&item.sequence) else {
            return Ok(());
        };
        self.answered[k] = true;
        let frame = self.frames[k];
        match item.outcome {
            FrameOutcome::Result(result) => {
                if result.fusion.is_none() {
                    return Err(EvalError::Invalid {
                        field: "FrameResult.fusion",
                        reason: format!(
                            "frame {} of a fused stream was answered without a fusion summary: the server does not fuse",
                            frame.name
                        ),
                    });
                }
                let (roofs, mode) = (&self.roofs[k], self.mode);
                let record =
                    fused_record_of(frame, roofs, mode, &result, item.latency, self.params);
                let title = format!("{} {}", frame.name, column_name(mode, true));
                draw_if_asked(self.config, &title, roofs, &result, &record)?;
                self.records.push(record);
            }
            FrameOutcome::Error(e) => self.fail(k, e.to_string()),
            FrameOutcome::Skipped { superseded_by } => {
                self.fail(k, format!("skipped, superseded by frame {superseded_by}"))
            }
        }
        Ok(())
    }

    /// The stream broke with `unanswered` frames in flight: each is a failure.
    fn broken(&mut self, unanswered: &[u64], status: Option<&FrameError>) {
        let why = status.map_or_else(
            || "the stream ended without an answer".to_string(),
            |s| format!("the stream broke: {s}"),
        );
        for seq in unanswered {
            if let Some(&k) = self.by_sequence.get(seq) {
                self.answered[k] = true;
                self.fail(k, why.clone());
            }
        }
    }

    fn fail(&mut self, k: usize, error: String) {
        self.failures.push(FrameFailure {
            mode: self.mode,
            frame: self.frames[k].name.clone(),
            fused: true,
            error,
        });
    }

    /// The records and failures, with a failure for each frame the stream never answered.
    fn finish(mut self) -> (Vec<FrameRecord>, Vec<FrameFailure>) {
        let unanswered: Vec<usize> = (0..self.frames.len())
            .filter(|&k| !self.answered[k])
            .collect();
        for k in unanswered {
            self.fail(k, "not answered: the stream closed first".into());
        }
        (self.records, self.failures)
    }
}

/// The pipeline options of every frame sent in `mode`.
fn mode_options(config: &EvalConfig, mode: Mode) -> PipelineOptions {
    PipelineOptions {
        segmentation_mode: mode.segmentation_mode() as i32,
        ..config.options.clone()
    }
}

/// The frame of `scenario` as sent in `mode`: with the true labels as its class image in
/// `truth` mode.
fn frame_to_send(scenario: &Scenario, mode: Mode) -> Frame {
    let mut frame = scenario.frame.clone();
    if mode == Mode::Truth {
        frame.class_image.clone_from(&scenario.labels);
    }
    frame
}

/// Draws the answer ([`write_overlay`]) when [`EvalConfig::overlay_dir`] is set and it has an
/// unsafe site (any answer with [`EvalConfig::overlay_all`]).
fn draw_if_asked(
    config: &EvalConfig,
    title: &str,
    roofs: &[RoofTruth],
    result: &FrameResult,
    record: &FrameRecord,
) -> Result<(), EvalError> {
    let Some(dir) = &config.overlay_dir else {
        return Ok(());
    };
    let any_unsafe = record.eval.sites.iter().any(|s| s.verdict.is_unsafe());
    if any_unsafe || config.overlay_all {
        write_overlay(dir, title, roofs, result, record)?;
    }
    Ok(())
}

/// Draws one answer over `roofs` into `dir`, titled `title` (`<recording>#<sequence> <column>`),
/// as `<recording>-<sequence>-<column>.png`.
fn write_overlay(
    dir: &std::path::Path,
    title: &str,
    roofs: &[RoofTruth],
    result: &FrameResult,
    record: &FrameRecord,
) -> Result<(), EvalError> {
    std::fs::create_dir_all(dir).map_err(|e| EvalError::Io {
        path: dir.display().to_string(),
        source: e,
    })?;
    let sites: Vec<Site> = result.sites.iter().map(site_of).collect();
    if let Some(canvas) = crate::overlay::draw_overlay(title, roofs, &sites, &record.eval.sites) {
        let stem: String = title
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
            .collect();
        canvas.save(&dir.join(format!("{stem}.png")))?;
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
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target: true,
        };
        let mut sc = Scenario {
            name: "t#1".into(),
            at: ApproachFrame::default(),
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
    fn approaches_group_by_recording_in_sequence_order() {
        let sc = |approach: &str, index: usize| Scenario {
            name: format!("{approach}#{index}"),
            at: ApproachFrame {
                approach: approach.into(),
                index,
                ..Default::default()
            },
            tags: vec![],
            frame: Frame::default(),
            labels: None,
            roofs: vec![],
        };
        let scenarios = [sc("b", 1), sc("a", 0), sc("b", 0), sc("a", 1), sc("b", 2)];
        assert_eq!(approaches(&scenarios), [vec![2, 0, 4], vec![1, 3]]);
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
        assert_eq!(ms[STEPS.len() - 1], Some(2.5), "total is the last step");
        assert_eq!(ms[0], None);
    }
}
