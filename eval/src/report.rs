//! Aggregation of per-frame scores into the evaluation's summary, and its renderings: a terminal
//! table, a Markdown report, and the PNG charts.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::EvalError;
use crate::approach::{ApproachFrame, breakdown};
use crate::metrics::{FrameEval, RoofEval, Verdict};
use crate::plot::{BarGroup, Canvas, bars_log, box_plot};
use crate::stats::{MeanCi, bootstrap_ci95, mean_ci95, median};

/// Where the point classes come from: the three modes the evaluation compares.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// `SEGMENTATION_MODE_NONE`: geometry only.
    Geometry,
    /// `SEGMENTATION_MODE_MODEL`: the server's segmentation model on the camera image.
    Model,
    /// `SEGMENTATION_MODE_CLASS_IMAGE` with the true label image: perfect segmentation, the
    /// upper bound of `Model` (same classification and keep-out, from the true mask).
    Truth,
}

impl Mode {
    /// All modes, in report order.
    pub const ALL: [Mode; 3] = [Mode::Geometry, Mode::Model, Mode::Truth];

    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Geometry => "geometry",
            Mode::Model => "model",
            Mode::Truth => "truth",
        }
    }

    /// The API's segmentation mode (the one definition): `Truth` is CLASS_IMAGE sent with the
    /// true label image, which is what sets it apart from a drone's own class image.
    pub fn segmentation_mode(self) -> landing_proto::v1::SegmentationMode {
        use landing_proto::v1::SegmentationMode as S;
        match self {
            Mode::Geometry => S::None,
            Mode::Model => S::Model,
            Mode::Truth => S::ClassImage,
        }
    }

    /// Parses [`Mode::name`].
    pub fn parse(s: &str) -> Option<Mode> {
        Mode::ALL.into_iter().find(|m| m.name() == s)
    }
}

/// The pipeline steps the server times, in pipeline order.
pub use landing_proto::STAGES as STEPS;

/// One frame processed in one mode, alone or as part of its approach's fused stream.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameRecord {
    pub mode: Mode,
    /// Recording file and frame sequence, e.g. `scenarios/w3.mcap#12`.
    pub frame: String,
    /// Where the frame stands in its approach (flattened into the record's JSON).
    #[serde(flatten)]
    pub at: ApproachFrame,
    /// Whether the answer came from the approach's fused stream (`--stream`), judged against the
    /// scans so far ([`crate::approach::fused_roofs`]), rather than from the frame alone.
    pub fused: bool,
    /// The server's account of the map a fused answer came from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fusion: Option<FusionInfo>,
    /// Hard-case tags of the scenario (`tarp`, `water_tower`, `parapet_edge`, ...).
    pub tags: Vec<String>,
    /// The server's per-step times, milliseconds, in [`STEPS`] order (`None` for a step that did
    /// not run).
    pub step_ms: Vec<Option<f64>>,
    /// Round trip seen by the client, milliseconds.
    pub round_trip_ms: f64,
    pub eval: FrameEval,
}

/// What a fused answer was computed from (`landing.v1.FusionSummary`).
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FusionInfo {
    /// Frames fused into the map since it (re)started, this one included.
    pub frames: u32,
    /// Map points the answer was computed from.
    pub points: u32,
    /// Cells the map holds.
    pub cells: u32,
    /// Frames whose keep-out footprints the answer kept clear of.
    pub keep_out_frames: u32,
    /// Why the map started over at this frame.
    #[serde(skip_serializing_if = "String::is_empty")]
    pub reset_reason: String,
}

impl From<&landing_proto::v1::FusionSummary> for FusionInfo {
    fn from(f: &landing_proto::v1::FusionSummary) -> Self {
        Self {
            frames: f.frames,
            points: f.points,
            cells: f.cells,
            keep_out_frames: f.keep_out_frames,
            reset_reason: f.reset_reason.clone(),
        }
    }
}

/// A frame the server did not answer with a result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameFailure {
    pub mode: Mode,
    pub frame: String,
    /// The frame was sent in its approach's fused stream.
    #[serde(skip_serializing_if = "is_false")]
    pub fused: bool,
    pub error: String,
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// The report's name of a column: the mode, with ` fused` for its fused answers.
pub fn column_name(mode: Mode, fused: bool) -> String {
    if fused {
        format!("{} fused", mode.name())
    } else {
        mode.name().to_string()
    }
}

/// Per-class results of one mode.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClassSummary {
    pub class: u8,
    pub name: &'static str,
    /// Obstacles of this class scored (in view and scanned).
    pub obstacles: usize,
    /// Obstacles some returned safe circle reached into.
    pub hit: usize,
    /// Mean fraction of the footprint left inside returned landing polygons.
    pub mean_covered: f64,
}

/// Results of one column on a subset of its answers: the frames carrying one hard-case tag, or
/// one row of the approach breakdown.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TagSummary {
    pub tag: String,
    pub frames: usize,
    pub unsafe_sites: usize,
    pub mean_iou: Option<f64>,
    pub median_ratio: Option<f64>,
}

/// The summary of one column of the report: one mode's single-frame answers, or (with
/// `--stream`) its fused ones.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ModeSummary {
    pub mode: Mode,
    /// The column holds the mode's fused answers.
    #[serde(skip_serializing_if = "is_false")]
    pub fused: bool,
    pub frames: usize,
    pub failures: usize,
    pub sites: usize,
    pub unsafe_obstacle: usize,
    /// Of those, into obstacles no LiDAR point hit.
    pub unsafe_unseen: usize,
    pub unsafe_outside_roof: usize,
    pub off_roof: usize,
    /// Sites on buildings the ground truth does not list: not judged, not unsafe.
    pub unlisted_roof: usize,
    /// Target roofs (the one each flight approaches) scored for IoU and radius ratio; the
    /// headline numbers below are over these.
    pub roofs: usize,
    /// Scored target roofs without any safe site.
    pub roofs_without_site: usize,
    /// Every scored roof in view, neighbours included.
    pub roofs_all: usize,
    pub iou_all: Option<MeanCi>,
    pub ratio_median_all: Option<f64>,
    pub iou: Option<MeanCi>,
    pub iou_median: Option<f64>,
    pub ratio_median: Option<f64>,
    /// Bootstrap 95 % interval of the median radius ratio.
    pub ratio_median_ci: Option<(f64, f64)>,
    pub ratio: Option<MeanCi>,
    /// Target IoU against the landable area in the sensor's line of sight (what the scan could
    /// have shown: shadows of obstacles and parapets left out).
    pub visible_iou: Option<MeanCi>,
    /// Median target radius ratio against the best circle in that area.
    pub visible_ratio_median: Option<f64>,
    pub classes: Vec<ClassSummary>,
    /// Per hard-case tag, in name order.
    pub tags: Vec<TagSummary>,
    /// The approach breakdown ([`crate::approach::breakdown`]: all answers, the last quarter of
    /// each approach, after the first second, time and altitude bands); empty unless the records
    /// hold fused answers.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub breakdown: Vec<TagSummary>,
    /// Per-step server time, milliseconds, in [`STEPS`] order.
    pub steps: Vec<Option<MeanCi>>,
    pub round_trip: Option<MeanCi>,
}

impl ModeSummary {
    /// Sites judged unsafe: into an obstacle, past the roof edge, or off every roof.
    pub fn unsafe_sites(&self) -> usize {
        self.unsafe_obstacle + self.unsafe_outside_roof + self.off_roof
    }

    /// The column's name: [`column_name`].
    pub fn label(&self) -> String {
        column_name(self.mode, self.fused)
    }
}

/// Targets of issue #8 for the segmented mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Targets {
    pub min_mean_iou: f64,
    pub min_median_ratio: f64,
}

impl Default for Targets {
    fn default() -> Self {
        Self {
            min_mean_iou: 0.93,
            min_median_ratio: 0.9,
        }
    }
}

/// One unsafe site, for explaining it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UnsafeSite {
    pub mode: Mode,
    #[serde(skip_serializing_if = "is_false")]
    pub fused: bool,
    pub frame: String,
    pub rank: u32,
    pub radius_m: f64,
    pub height_above_roof_m: Option<f64>,
    pub verdict: Verdict,
}

/// Everything an evaluation produced.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    pub scenarios: usize,
    /// The columns: per mode, its single-frame answers, then its fused ones where there are.
    pub modes: Vec<ModeSummary>,
    /// Unsafe sites listed one by one, for explaining each.
    pub unsafe_list: Vec<UnsafeSite>,
    pub failures: Vec<FrameFailure>,
}

/// The human name of a `SemanticClass` id, from the one class table
/// ([`landing_geometry::SemanticClass`]); "unknown" for a number it does not have.
pub fn class_name(class: u8) -> &'static str {
    landing_geometry::SemanticClass::from_u8(class).map_or("unknown", |c| c.name())
}

/// Aggregates records into a summary. Each mode gets a column of its single-frame answers and,
/// when the records or failures hold fused answers of that mode (`--stream`), a column of those
/// next to it; with fused answers anywhere, every column also gets the approach breakdown.
/// Without fused answers the summary is the single-frame one of before streams existed.
pub fn summarize(records: &[FrameRecord], failures: &[FrameFailure], modes: &[Mode]) -> Summary {
    let mut scenarios: Vec<&str> = records
        .iter()
        .map(|r| r.frame.as_str())
        .chain(failures.iter().map(|f| f.frame.as_str()))
        .collect();
    scenarios.sort_unstable();
    scenarios.dedup();
    let streamed = records.iter().any(|r| r.fused);
    let mut unsafe_list = Vec::new();
    let mut out = Vec::new();
    for &mode in modes {
        let has_fused = records.iter().any(|r| r.mode == mode && r.fused)
            || failures.iter().any(|f| f.mode == mode && f.fused);
        for fused in [false, true] {
            if fused && !has_fused {
                continue;
            }
            let recs: Vec<&FrameRecord> = records
                .iter()
                .filter(|r| r.mode == mode && r.fused == fused)
                .collect();
            let failed = failures
                .iter()
                .filter(|f| f.mode == mode && f.fused == fused)
                .count();
            let mut s = summarize_column(mode, fused, &recs, failed, &mut unsafe_list);
            if streamed {
                s.breakdown = breakdown(&recs, |r: &FrameRecord| &r.at)
                    .into_iter()
                    .map(|(label, rows)| subset_summary(label, &rows))
                    .collect();
            }
            out.push(s);
        }
    }
    Summary {
        scenarios: scenarios.len(),
        modes: out,
        unsafe_list,
        failures: failures.to_vec(),
    }
}

/// One column's summary of `recs`; its unsafe sites are appended to `unsafe_list`.
fn summarize_column(
    mode: Mode,
    fused: bool,
    recs: &[&FrameRecord],
    failures: usize,
    unsafe_list: &mut Vec<UnsafeSite>,
) -> ModeSummary {
    let mut sites = SiteCounts::default();
    let mut roofs = RoofSamples::default();
    for r in recs {
        sites.add(r, mode, fused, unsafe_list);
        roofs.add(&r.eval.roofs);
    }
    let ratio_median_ci = bootstrap_ci95(&roofs.ratios, 2000, 0x5eed_0008, |x| {
        median(x).unwrap_or(f64::NAN)
    });
    ModeSummary {
        mode,
        fused,
        frames: recs.len(),
        failures,
        sites: sites.sites,
        unsafe_obstacle: sites.unsafe_obstacle,
        unsafe_unseen: sites.unsafe_unseen,
        unsafe_outside_roof: sites.unsafe_outside_roof,
        off_roof: sites.off_roof,
        unlisted_roof: sites.unlisted_roof,
        roofs: roofs.targets,
        roofs_without_site: roofs.targets_without_site,
        roofs_all: roofs.ious_all.len(),
        iou_all: mean_ci95(&roofs.ious_all),
        ratio_median_all: median(&roofs.ratios_all),
        iou: mean_ci95(&roofs.ious),
        iou_median: median(&roofs.ious),
        ratio_median: median(&roofs.ratios),
        ratio_median_ci,
        ratio: mean_ci95(&roofs.ratios),
        visible_iou: mean_ci95(&roofs.visible_ious),
        visible_ratio_median: median(&roofs.visible_ratios),
        classes: class_summaries(recs),
        tags: tag_summaries(recs),
        breakdown: Vec::new(),
        steps: step_means(recs),
        round_trip: mean_ci95(&recs.iter().map(|r| r.round_trip_ms).collect::<Vec<_>>()),
    }
}

/// The sites of a column by verdict.
#[derive(Default)]
struct SiteCounts {
    sites: usize,
    unsafe_obstacle: usize,
    unsafe_unseen: usize,
    unsafe_outside_roof: usize,
    off_roof: usize,
    unlisted_roof: usize,
}

impl SiteCounts {
    /// Counts the sites of `r`, appending the unsafe ones to `unsafe_list`.
    fn add(&mut self, r: &FrameRecord, mode: Mode, fused: bool, unsafe_list: &mut Vec<UnsafeSite>) {
        self.sites += r.eval.sites.len();
        for site in &r.eval.sites {
            match site.verdict {
                Verdict::Safe => continue,
                Verdict::Obstacle { seen, .. } => {
                    self.unsafe_obstacle += 1;
                    self.unsafe_unseen += usize::from(!seen);
                }
                Verdict::OutsideRoof { .. } => self.unsafe_outside_roof += 1,
                Verdict::OffRoof => self.off_roof += 1,
                Verdict::UnlistedRoof => {
                    self.unlisted_roof += 1;
                    continue;
                }
            }
            unsafe_list.push(UnsafeSite {
                mode,
                fused,
                frame: r.frame.clone(),
                rank: site.rank,
                radius_m: site.radius_m,
                height_above_roof_m: site.height_above_roof_m,
                verdict: site.verdict,
            });
        }
    }
}

/// The IoUs and radius ratios of a column's roofs: of every roof and of the target ones.
#[derive(Default)]
struct RoofSamples {
    ious_all: Vec<f64>,
    ratios_all: Vec<f64>,
    targets: usize,
    targets_without_site: usize,
    ious: Vec<f64>,
    ratios: Vec<f64>,
    visible_ious: Vec<f64>,
    visible_ratios: Vec<f64>,
}

impl RoofSamples {
    fn add(&mut self, roofs: &[RoofEval]) {
        for roof in roofs {
            self.ious_all.push(roof.iou);
            self.ratios_all.push(roof.radius_ratio);
            if !roof.target {
                continue;
            }
            self.targets += 1;
            if roof.best_safe_radius_m <= 0.0 {
                self.targets_without_site += 1;
            }
            self.ious.push(roof.iou);
            self.ratios.push(roof.radius_ratio);
            self.visible_ious.push(roof.visible_iou);
            self.visible_ratios.push(roof.visible_radius_ratio);
        }
    }
}

/// Obstacles, hits and mean covered fraction per class, by class number.
fn class_summaries(recs: &[&FrameRecord]) -> Vec<ClassSummary> {
    let mut classes: BTreeMap<u8, (usize, usize, f64)> = BTreeMap::new();
    for o in recs.iter().flat_map(|r| &r.eval.obstacles) {
        let e = classes.entry(o.class).or_default();
        e.0 += 1;
        e.1 += usize::from(o.hit);
        e.2 += o.covered_fraction;
    }
    classes
        .into_iter()
        .map(|(class, (n, hit, cov))| ClassSummary {
            class,
            name: class_name(class),
            obstacles: n,
            hit,
            mean_covered: cov / n.max(1) as f64,
        })
        .collect()
}

/// The summary of the records of each tag, by tag name.
fn tag_summaries(recs: &[&FrameRecord]) -> Vec<TagSummary> {
    let mut tag_names: Vec<&str> = recs
        .iter()
        .flat_map(|r| r.tags.iter().map(String::as_str))
        .collect();
    tag_names.sort_unstable();
    tag_names.dedup();
    tag_names
        .into_iter()
        .map(|tag| {
            let tagged: Vec<&FrameRecord> = recs
                .iter()
                .copied()
                .filter(|r| r.tags.iter().any(|t| t == tag))
                .collect();
            subset_summary(tag.to_string(), &tagged)
        })
        .collect()
}

/// The mean time of each pipeline step over the records that timed it.
fn step_means(recs: &[&FrameRecord]) -> Vec<Option<MeanCi>> {
    (0..STEPS.len())
        .map(|k| {
            mean_ci95(
                &recs
                    .iter()
                    .filter_map(|r| r.step_ms.get(k).copied().flatten())
                    .collect::<Vec<_>>(),
            )
        })
        .collect()
}

/// Answers, unsafe sites, mean target IoU and median target radius ratio of a subset of records.
pub fn subset_summary(label: String, recs: &[&FrameRecord]) -> TagSummary {
    let targets = || {
        recs.iter()
            .flat_map(|r| r.eval.roofs.iter().filter(|x| x.target))
    };
    let ious: Vec<f64> = targets().map(|x| x.iou).collect();
    let ratios: Vec<f64> = targets().map(|x| x.radius_ratio).collect();
    TagSummary {
        tag: label,
        frames: recs.len(),
        unsafe_sites: recs
            .iter()
            .map(|r| {
                r.eval
                    .sites
                    .iter()
                    .filter(|x| x.verdict.is_unsafe())
                    .count()
            })
            .sum(),
        mean_iou: mean_ci95(&ious).map(|m| m.mean),
        median_ratio: median(&ratios),
    }
}

/// Table rows: a label and one cell per column.
type Rows = Vec<(String, Vec<String>)>;

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".into(), |v| format!("{v:.digits$}"))
}

fn ci(v: Option<MeanCi>, digits: usize) -> String {
    v.map_or_else(
        || "-".into(),
        |m| format!("{:.digits$} [{:.digits$}, {:.digits$}]", m.mean, m.lo, m.hi),
    )
}

impl Summary {
    /// The rows of the main table: a label and one cell per mode.
    fn main_rows(&self) -> Vec<(String, Vec<String>)> {
        let row = |label: &str, f: &dyn Fn(&ModeSummary) -> String| {
            (
                label.to_string(),
                self.modes.iter().map(f).collect::<Vec<_>>(),
            )
        };
        vec![
            row("frames answered / failed", &|m| {
                format!("{} / {}", m.frames, m.failures)
            }),
            row("sites returned", &|m| m.sites.to_string()),
            row("unsafe sites (all)", &|m| m.unsafe_sites().to_string()),
            row("  into an obstacle", &|m| m.unsafe_obstacle.to_string()),
            row("    of which unseen by the LiDAR", &|m| {
                m.unsafe_unseen.to_string()
            }),
            row("  past the roof edge", &|m| {
                m.unsafe_outside_roof.to_string()
            }),
            row("  on the ground, off every roof", &|m| {
                m.off_roof.to_string()
            }),
            row("sites on unlisted roofs (not judged)", &|m| {
                m.unlisted_roof.to_string()
            }),
            row("target roofs scored", &|m| m.roofs.to_string()),
            row("target roofs without a safe site", &|m| {
                m.roofs_without_site.to_string()
            }),
            row("target polygon IoU, mean [95% CI]", &|m| ci(m.iou, 3)),
            row("target polygon IoU, median", &|m| opt(m.iou_median, 3)),
            row("target radius ratio, median [95% CI]", &|m| match (
                m.ratio_median,
                m.ratio_median_ci,
            ) {
                (Some(v), Some((lo, hi))) => format!("{v:.3} [{lo:.3}, {hi:.3}]"),
                (v, _) => opt(v, 3),
            }),
            row("target radius ratio, mean [95% CI]", &|m| ci(m.ratio, 3)),
            row("target IoU, line of sight, mean [95% CI]", &|m| {
                ci(m.visible_iou, 3)
            }),
            row("target radius ratio, line of sight, median", &|m| {
                opt(m.visible_ratio_median, 3)
            }),
            row("all roofs in view scored", &|m| m.roofs_all.to_string()),
            row("all roofs: polygon IoU, mean [95% CI]", &|m| {
                ci(m.iou_all, 3)
            }),
            row("all roofs: radius ratio, median", &|m| {
                opt(m.ratio_median_all, 3)
            }),
            row("client round trip, ms", &|m| ci(m.round_trip, 1)),
        ]
    }

    /// Per-class rows: class name, then "hit / n (covered %)" per mode.
    fn class_rows(&self) -> Vec<(String, Vec<String>)> {
        let mut classes: Vec<u8> = self
            .modes
            .iter()
            .flat_map(|m| m.classes.iter().map(|c| c.class))
            .collect();
        classes.sort_unstable();
        classes.dedup();
        classes
            .into_iter()
            .map(|class| {
                let cells = self
                    .modes
                    .iter()
                    .map(|m| match m.classes.iter().find(|c| c.class == class) {
                        Some(c) => format!(
                            "{} / {} hit, {:.0}% covered",
                            c.hit,
                            c.obstacles,
                            100.0 * c.mean_covered
                        ),
                        None => "-".into(),
                    })
                    .collect();
                (class_name(class).to_string(), cells)
            })
            .collect()
    }

    /// Per-tag rows: "frames, unsafe, IoU, ratio" per column, in tag order.
    fn tag_rows(&self) -> Vec<(String, Vec<String>)> {
        let mut rows = self.subset_rows(|m| &m.tags, "fr");
        rows.sort_by(|a, b| a.0.cmp(&b.0));
        rows
    }

    /// The approach breakdown's rows: "answers, unsafe, IoU, ratio" per column, in breakdown
    /// order.
    fn breakdown_rows(&self) -> Vec<(String, Vec<String>)> {
        self.subset_rows(|m| &m.breakdown, "ans")
    }

    /// One row per subset label found in any column (in the order first met), one cell per
    /// column.
    fn subset_rows(
        &self,
        of: impl Fn(&ModeSummary) -> &[TagSummary],
        unit: &str,
    ) -> Vec<(String, Vec<String>)> {
        let mut labels: Vec<&str> = Vec::new();
        for t in self.modes.iter().flat_map(|m| of(m).iter()) {
            if !labels.contains(&t.tag.as_str()) {
                labels.push(&t.tag);
            }
        }
        labels
            .into_iter()
            .map(|label| {
                let cells = self
                    .modes
                    .iter()
                    .map(|m| match of(m).iter().find(|t| t.tag == label) {
                        Some(t) => format!(
                            "{} {unit}, {} unsafe, IoU {}, ratio {}",
                            t.frames,
                            t.unsafe_sites,
                            opt(t.mean_iou, 2),
                            opt(t.median_ratio, 2)
                        ),
                        None => "-".into(),
                    })
                    .collect();
                (label.to_string(), cells)
            })
            .collect()
    }

    fn step_rows(&self) -> Vec<(String, Vec<String>)> {
        STEPS
            .iter()
            .enumerate()
            .map(|(k, step)| {
                (
                    step.to_string(),
                    self.modes
                        .iter()
                        .map(|m| ci(m.steps.get(k).copied().flatten(), 2))
                        .collect(),
                )
            })
            .collect()
    }

    /// The verdict on the targets for `mode`: one line per target and column (the
    /// single-frame answers, then the fused ones where there are).
    pub fn target_lines(&self, mode: Mode, targets: &Targets) -> Vec<(String, bool)> {
        let mut lines = Vec::new();
        for m in self.modes.iter().filter(|m| m.mode == mode) {
            let name = m.label();
            let iou = m.iou.map(|c| c.mean);
            lines.extend([
                (
                    format!("{name}: unsafe sites = {} (target 0)", m.unsafe_sites()),
                    m.unsafe_sites() == 0 && m.frames > 0,
                ),
                (
                    format!(
                        "{name}: mean polygon IoU (target roofs) = {} (target >= {})",
                        opt(iou, 3),
                        targets.min_mean_iou
                    ),
                    iou.is_some_and(|v| v >= targets.min_mean_iou),
                ),
                (
                    format!(
                        "{name}: median radius ratio (target roofs) = {} (target >= {})",
                        opt(m.ratio_median, 3),
                        targets.min_median_ratio
                    ),
                    m.ratio_median
                        .is_some_and(|v| v >= targets.min_median_ratio),
                ),
            ]);
        }
        lines
    }

    /// Whether the gate fails: a gated mode has no column, or one of its columns (single-frame
    /// or fused) answered no frame or returned an unsafe site.
    pub fn gate_failed(&self, gate: &[Mode]) -> bool {
        gate.iter().any(|&g| {
            let mut columns = self.modes.iter().filter(|m| m.mode == g).peekable();
            columns.peek().is_none() || columns.any(|m| m.unsafe_sites() > 0 || m.frames == 0)
        })
    }

    /// The titled tables of the report, shared by the text and the Markdown.
    fn tables(&self, markdown: bool) -> Vec<(&'static str, Rows)> {
        let mut t = vec![
            (
                if markdown { "Quality" } else { "quality" },
                self.main_rows(),
            ),
            (
                if markdown {
                    "Obstacles by class (hit by a safe circle / scored; share of the footprint inside landing polygons)"
                } else {
                    "obstacles by class (hit by a safe circle / scored; footprint inside landing polygons)"
                },
                self.class_rows(),
            ),
            (
                if markdown {
                    "Hard cases (frames, unsafe sites, mean IoU, median radius ratio)"
                } else {
                    "hard cases (frames, unsafe sites, mean IoU, median radius ratio)"
                },
                self.tag_rows(),
            ),
        ];
        if self.modes.iter().any(|m| !m.breakdown.is_empty()) {
            t.push((
                if markdown {
                    "Approach breakdown (answers, unsafe sites, mean target IoU, median target radius ratio)"
                } else {
                    "approach breakdown (answers, unsafe sites, mean target IoU, median target radius ratio)"
                },
                self.breakdown_rows(),
            ));
        }
        t.push((
            if markdown {
                "Server time per step, ms: mean [95 % CI]"
            } else {
                "server time per step, ms: mean [95% CI]"
            },
            self.step_rows(),
        ));
        t
    }

    /// The report as aligned plain-text tables.
    pub fn to_text(&self) -> String {
        let header: Vec<String> = self.modes.iter().map(ModeSummary::label).collect();
        let mut s = String::new();
        let _ = writeln!(
            s,
            "landing eval: {} frames, modes {}",
            self.scenarios,
            header.join(", ")
        );
        for (title, rows) in self.tables(false) {
            let _ = writeln!(s, "\n{title}");
            text_table(&mut s, &header, &rows);
        }
        s
    }

    /// The report as Markdown (tables, targets, the list of unsafe sites, and the charts).
    pub fn to_markdown(&self, targets: &Targets, gate: &[Mode], charts: &[(&str, &str)]) -> String {
        let header: Vec<String> = self
            .modes
            .iter()
            .map(|m| format!("`{}`", m.label()))
            .collect();
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} frames evaluated in {} mode(s).\n",
            self.scenarios,
            self.modes.len()
        );
        for &mode in gate {
            for (line, ok) in self.target_lines(mode, targets) {
                let _ = writeln!(s, "- {} {line}", if ok { "PASS" } else { "FAIL" });
            }
        }
        for (title, rows) in self.tables(true) {
            let _ = writeln!(s, "\n#### {title}\n");
            md_table(&mut s, &header, &rows);
        }
        if !self.unsafe_list.is_empty() {
            let _ = writeln!(
                s,
                "\n#### Unsafe sites\n\n| mode | frame | rank | radius, m | plane above roof, m | verdict |\n|---|---|---|---|---|---|"
            );
            // At most 60 per mode, so that a noisy mode does not hide the others.
            let mut left_out = 0;
            for (mode, fused) in self.modes.iter().map(|m| (m.mode, m.fused)) {
                let of_mode: Vec<&UnsafeSite> = self
                    .unsafe_list
                    .iter()
                    .filter(|u| u.mode == mode && u.fused == fused)
                    .collect();
                left_out += of_mode.len().saturating_sub(60);
                for u in of_mode.into_iter().take(60) {
                    let _ = writeln!(
                        s,
                        "| {} | {} | {} | {:.2} | {} | {} |",
                        column_name(u.mode, u.fused),
                        u.frame,
                        u.rank,
                        u.radius_m,
                        opt(u.height_above_roof_m, 2),
                        verdict_text(&u.verdict)
                    );
                }
            }
            if left_out > 0 {
                let _ = writeln!(s, "\n({left_out} more in results.json)");
            }
        }
        if !self.failures.is_empty() {
            let _ = writeln!(
                s,
                "\n#### Frames without a result\n\n| mode | frame | error |\n|---|---|---|"
            );
            for f in self.failures.iter().take(50) {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} |",
                    column_name(f.mode, f.fused),
                    f.frame,
                    f.error.replace('|', "/")
                );
            }
        }
        for (title, file) in charts {
            let _ = writeln!(s, "\n![{title}]({file})");
        }
        s
    }

    /// Draws the charts into `dir`; returns (title, file name) of each.
    pub fn write_charts(
        &self,
        dir: &Path,
        records: &[FrameRecord],
    ) -> Result<Vec<(&'static str, String)>, EvalError> {
        let labels: Vec<String> = self.modes.iter().map(ModeSummary::label).collect();
        let names: Vec<&str> = labels.iter().map(String::as_str).collect();
        let charts = [
            (
                "Per-step time with 95 % CI (log scale)",
                "timing.png",
                self.timing_chart(&names),
            ),
            (
                "Radius ratio (returned / true best) on the target roof, per mode",
                "radius_ratio.png",
                self.radius_ratio_chart(records, &names),
            ),
            (
                "Polygon IoU with the true landable area on the target roof, per mode",
                "iou.png",
                self.iou_chart(records, &names),
            ),
        ];
        let mut written = Vec::new();
        for (title, file, canvas) in charts {
            canvas.save(&dir.join(file))?;
            written.push((title, file.to_string()));
        }
        Ok(written)
    }

    /// Server time per pipeline step, a bar per column, for the steps some column timed.
    fn timing_chart(&self, names: &[&str]) -> Canvas {
        let groups: Vec<BarGroup> = STEPS
            .iter()
            .enumerate()
            .filter(|(k, _)| {
                self.modes
                    .iter()
                    .any(|m| m.steps.get(*k).copied().flatten().is_some())
            })
            .map(|(k, step)| BarGroup {
                label: step.replace('_', " "),
                values: self
                    .modes
                    .iter()
                    .map(|m| m.steps.get(k).copied().flatten())
                    .collect(),
            })
            .collect();
        bars_log(
            "SERVER TIME PER STEP, MEAN AND 95% CI",
            "MS (LOG)",
            names,
            &groups,
        )
    }

    /// The target roofs' radius ratios per column, the axis up to the largest (at least 1.2,
    /// at most 3).
    fn radius_ratio_chart(&self, records: &[FrameRecord], names: &[&str]) -> Canvas {
        let ratios = self.per_column_targets(records, names, |x| x.radius_ratio);
        let hi = ratios
            .iter()
            .flat_map(|(_, v)| v.iter().copied())
            .fold(1.2f64, f64::max)
            .min(3.0);
        box_plot(
            "TARGET ROOF: RADIUS RATIO, RETURNED / TRUE BEST",
            &ratios,
            (0.0, hi),
            Some(0.9),
        )
    }

    /// The target roofs' polygon IoUs per column.
    fn iou_chart(&self, records: &[FrameRecord], names: &[&str]) -> Canvas {
        let ious = self.per_column_targets(records, names, |x| x.iou);
        box_plot(
            "TARGET ROOF: POLYGON IOU WITH TRUE LANDABLE AREA",
            &ious,
            (0.0, 1.0),
            Some(0.93),
        )
    }

    /// `value` of every target roof of the records of each column, with the column's name.
    fn per_column_targets<'n>(
        &self,
        records: &[FrameRecord],
        names: &[&'n str],
        value: impl Fn(&RoofEval) -> f64,
    ) -> Vec<(&'n str, Vec<f64>)> {
        self.modes
            .iter()
            .zip(names)
            .map(|(m, name)| {
                (
                    *name,
                    records
                        .iter()
                        .filter(|r| r.mode == m.mode && r.fused == m.fused)
                        .flat_map(|r| r.eval.roofs.iter().filter(|x| x.target).map(&value))
                        .collect(),
                )
            })
            .collect()
    }
}

fn verdict_text(v: &Verdict) -> String {
    match v {
        Verdict::Safe => "safe".into(),
        Verdict::Obstacle {
            class,
            intrusion_m,
            seen,
        } => format!(
            "{intrusion_m:.2} m into a {}{}",
            class_name(*class),
            if *seen { "" } else { " (no LiDAR point on it)" }
        ),
        Verdict::OutsideRoof { intrusion_m } => format!("{intrusion_m:.2} m past the roof edge"),
        Verdict::OffRoof => "centre on the ground, off every roof".into(),
        Verdict::UnlistedRoof => "on a roof the ground truth does not list".into(),
    }
}

fn text_table(s: &mut String, header: &[String], rows: &[(String, Vec<String>)]) {
    let first = rows.iter().map(|r| r.0.chars().count()).max().unwrap_or(0);
    let widths: Vec<usize> = (0..header.len())
        .map(|k| {
            rows.iter()
                .map(|r| r.1[k].chars().count())
                .chain([header[k].len()])
                .max()
                .unwrap_or(0)
        })
        .collect();
    let _ = write!(s, "  {:first$}", "");
    for (h, w) in header.iter().zip(&widths) {
        let _ = write!(s, "  {h:>w$}");
    }
    s.push('\n');
    for (label, cells) in rows {
        let _ = write!(s, "  {label:first$}");
        for (c, w) in cells.iter().zip(&widths) {
            let _ = write!(s, "  {c:>w$}");
        }
        s.push('\n');
    }
}

fn md_table(s: &mut String, header: &[String], rows: &[(String, Vec<String>)]) {
    let _ = writeln!(s, "| | {} |", header.join(" | "));
    let _ = writeln!(s, "|---|{}", "---:|".repeat(header.len()));
    for (label, cells) in rows {
        let _ = writeln!(s, "| {} | {} |", label.trim(), cells.join(" | "));
    }
}

/// Writes `summary.md`, `results.json` and the charts into `dir` (created if missing); returns
/// the Markdown.
pub fn write_report(
    dir: &Path,
    summary: &Summary,
    records: &[FrameRecord],
    targets: &Targets,
    gate: &[Mode],
) -> Result<String, EvalError> {
    let io = |path: PathBuf| {
        move |e: std::io::Error| EvalError::Io {
            path: path.display().to_string(),
            source: e,
        }
    };
    std::fs::create_dir_all(dir).map_err(io(dir.to_path_buf()))?;
    let charts = summary.write_charts(dir, records)?;
    let chart_refs: Vec<(&str, &str)> = charts.iter().map(|(t, f)| (*t, f.as_str())).collect();
    let md = summary.to_markdown(targets, gate, &chart_refs);
    std::fs::write(dir.join("summary.md"), &md).map_err(io(dir.join("summary.md")))?;
    let json = serde_json::json!({ "summary": summary, "records": records });
    let text = serde_json::to_string_pretty(&json).map_err(|e| EvalError::Invalid {
        field: "results",
        reason: e.to_string(),
    })?;
    std::fs::write(dir.join("results.json"), text).map_err(io(dir.join("results.json")))?;
    Ok(md)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{ObstacleEval, RoofEval, SiteEval};

    fn record(mode: Mode, frame: &str, verdict: Verdict, iou: f64, ratio: f64) -> FrameRecord {
        FrameRecord {
            mode,
            frame: frame.into(),
            at: ApproachFrame::default(),
            fused: false,
            fusion: None,
            tags: vec![],
            step_ms: vec![Some(1.0); STEPS.len()],
            round_trip_ms: 5.0,
            eval: FrameEval {
                sites: vec![SiteEval {
                    rank: 1,
                    radius_m: 3.0,
                    roof: Some(0),
                    height_above_roof_m: Some(0.0),
                    verdict,
                }],
                roofs: vec![RoofEval {
                    roof: 0,
                    roof_id: 1,
                    target: true,
                    truth_area_m2: 100.0,
                    truth_radius_m: 4.0,
                    stated_truth_radius_m: None,
                    returned_area_m2: 90.0,
                    best_safe_radius_m: if verdict.is_safe() { 3.0 } else { 0.0 },
                    radius_ratio: ratio,
                    iou,
                    visible_area_m2: 80.0,
                    visible_radius_m: 3.5,
                    visible_radius_ratio: ratio * 4.0 / 3.5,
                    visible_iou: iou,
                }],
                obstacles: vec![ObstacleEval {
                    roof: 0,
                    class: 13,
                    scanned_area_m2: 4.0,
                    covered_fraction: 1.0 - iou,
                    hit: !verdict.is_safe(),
                }],
            },
        }
    }

    #[test]
    fn summary_counts_and_targets() {
        let tarp = Verdict::Obstacle {
            class: 13,
            intrusion_m: 1.0,
            seen: true,
        };
        let records = vec![
            record(Mode::Geometry, "a#1", tarp, 0.8, 0.0),
            record(Mode::Geometry, "a#2", Verdict::Safe, 0.9, 0.8),
            record(Mode::Model, "a#1", Verdict::Safe, 0.95, 0.92),
            record(Mode::Model, "a#2", Verdict::Safe, 0.97, 0.95),
        ];
        let s = summarize(&records, &[], &[Mode::Geometry, Mode::Model]);
        assert_eq!(s.scenarios, 2);
        assert_eq!(s.modes[0].unsafe_obstacle, 1);
        assert_eq!(s.modes[0].classes[0].hit, 1);
        assert_eq!(s.modes[1].unsafe_sites(), 0);
        assert!((s.modes[1].iou.unwrap().mean - 0.96).abs() < 1e-9);
        let lines = s.target_lines(Mode::Model, &Targets::default());
        assert!(lines.iter().all(|(_, ok)| *ok), "{lines:?}");
        assert!(
            s.target_lines(Mode::Geometry, &Targets::default())
                .iter()
                .any(|(_, ok)| !ok)
        );
        assert_eq!(s.unsafe_list.len(), 1);
        let text = s.to_text();
        assert!(text.contains("tarp") && text.contains("geometry"), "{text}");
        let md = s.to_markdown(&Targets::default(), &[Mode::Model], &[]);
        assert!(md.contains("- PASS model: unsafe sites = 0"), "{md}");
        assert!(md.contains("into a tarp"), "{md}");
    }

    #[test]
    fn fused_answers_get_their_own_columns_breakdown_and_gate() {
        let tarp = Verdict::Obstacle {
            class: 13,
            intrusion_m: 1.0,
            seen: true,
        };
        let single = vec![
            record(Mode::Model, "a#1", Verdict::Safe, 0.95, 0.92),
            record(Mode::Model, "a#2", Verdict::Safe, 0.97, 0.95),
        ];
        // Without fused answers: one column per mode and no breakdown, as before streams.
        let s = summarize(&single, &[], &[Mode::Model]);
        assert_eq!(s.modes.len(), 1);
        assert!(s.modes[0].breakdown.is_empty());
        assert!(!s.gate_failed(&[Mode::Model]));
        assert!(!s.to_text().contains("breakdown"));
        let json = serde_json::to_value(&s).unwrap();
        assert!(json["modes"][0].get("fused").is_none(), "{json}");
        // The fused stream of the same approach: the second answer puts a circle on the tarp.
        let mut records = single.clone();
        for (k, (verdict, iou)) in [(Verdict::Safe, 0.9), (tarp, 0.99)].into_iter().enumerate() {
            let mut r = record(Mode::Model, &format!("a#{}", k + 1), verdict, iou, 1.0);
            r.fused = true;
            r.at = ApproachFrame {
                approach: "a".into(),
                index: k,
                approach_frames: 2,
                time_s: Some(1.5 * k as f64),
                camera_above_roof_m: Some(40.0 - 30.0 * k as f64),
            };
            records.push(r);
        }
        for r in records.iter_mut().take(2) {
            r.at.approach_frames = 2;
        }
        records[1].at.index = 1;
        let s = summarize(&records, &[], &[Mode::Model]);
        let labels: Vec<String> = s.modes.iter().map(ModeSummary::label).collect();
        assert_eq!(labels, ["model", "model fused"]);
        assert_eq!(
            (s.modes[0].unsafe_sites(), s.modes[1].unsafe_sites()),
            (0, 1)
        );
        assert_eq!(s.scenarios, 2);
        let fused = &s.modes[1].breakdown;
        let row = |label: &str| fused.iter().find(|t| t.tag == label).unwrap();
        assert_eq!(row("all answers").frames, 2);
        let last = row("last quarter of each approach");
        assert_eq!((last.frames, last.unsafe_sites), (1, 1));
        assert_eq!(last.mean_iou, Some(0.99));
        assert_eq!(row("after the first second").frames, 1);
        assert_eq!(row("altitude 40-30 m").unsafe_sites, 0);
        assert_eq!(row("altitude 10-0 m").unsafe_sites, 1);
        // The single-frame column gets the breakdown too, for the side-by-side.
        assert_eq!(s.modes[0].breakdown[1].frames, 1);
        // The gate fails on the fused column alone.
        assert!(s.gate_failed(&[Mode::Model]));
        assert!(
            s.gate_failed(&[Mode::Geometry]),
            "a gated mode without a column fails"
        );
        let lines = s.target_lines(Mode::Model, &Targets::default());
        assert!(
            lines
                .iter()
                .any(|(l, ok)| l.starts_with("model fused: unsafe sites = 1") && !ok)
        );
        let text = s.to_text();
        assert!(
            text.contains("approach breakdown") && text.contains("model fused"),
            "{text}"
        );
        let md = s.to_markdown(&Targets::default(), &[Mode::Model], &[]);
        assert!(md.contains("| model fused | a#2 |"), "{md}");
    }
}
