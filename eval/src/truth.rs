//! Scenarios from `landing-sim` recordings: each `landing.v1.Frame` (topic `/frame`) with its
//! `landing.v1.GroundTruth` (`/ground_truth`) and true label image (`/camera/labels`), read by
//! the simulator's own reader and converted to the metrics' domain types.

use std::path::{Path, PathBuf};

use landing_proto::v1::{CameraImage, Frame, GroundTruth, LinearRing, SemanticClass};

use crate::EvalError;
use crate::approach::ApproachFrame;
use crate::geom::{P2, Polygon2, bounds_of, prism_shadow};
use crate::metrics::{Obstacle, RoofTruth};
use crate::run::Scenario;

/// Parapet walls of the simulated city are this thick at least and at most, metres. The ground
/// truth gives the parapet's height, not its thickness; the thickness is read off the landable
/// region where the scan reaches the parapet and kept within these bounds.
pub const PARAPET_THICKNESS_M: (f64, f64) = (0.2, 0.45);

/// Reads every file and pairs frames with their ground truth; frames without truth are skipped.
/// Each file is one approach: its frames, in the order read, get their place in it
/// ([`place_in_approach`]).
pub fn load_scenarios(files: &[PathBuf]) -> Result<Vec<Scenario>, EvalError> {
    let mut out = Vec::new();
    for f in files {
        let recorded = landing_recording::read(f).map_err(|source| EvalError::Recording {
            path: f.display().to_string(),
            source,
        })?;
        let name = short_name(f);
        let mut of_file: Vec<Scenario> = recorded
            .into_iter()
            .filter_map(|r| {
                r.truth
                    .map(|truth| scenario_of(&name, r.frame, &truth, r.labels))
            })
            .collect();
        place_in_approach(&mut of_file);
        out.extend(of_file);
    }
    if out.is_empty() {
        return Err(EvalError::Invalid {
            field: "recordings",
            reason: format!("no frame with ground truth (`/ground_truth`) in {files:?}"),
        });
    }
    Ok(out)
}

/// Sets the approach index, length and time since the start of the frames of one approach
/// (one recording): the index is the rank by sequence (the recording's time order), the time is
/// the frame's timestamp minus the earliest one. The frames stay in the order given.
pub fn place_in_approach(frames: &mut [Scenario]) {
    let mut order: Vec<usize> = (0..frames.len()).collect();
    order.sort_by_key(|&i| frames[i].frame.sequence);
    let ns = |s: &Scenario| {
        s.frame
            .timestamp
            .map(|t| i128::from(t.seconds) * 1_000_000_000 + i128::from(t.nanos))
    };
    let start = frames.iter().filter_map(ns).min();
    let n = frames.len();
    for (rank, &i) in order.iter().enumerate() {
        let time_s = ns(&frames[i])
            .zip(start)
            .map(|(t, t0)| (t - t0) as f64 * 1e-9);
        let at = &mut frames[i].at;
        at.index = rank;
        at.approach_frames = n;
        at.time_s = time_s;
    }
}

/// The MCAP files named, with folders expanded to their `*.mcap` files in name order.
pub fn recording_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>, EvalError> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| EvalError::Io {
                    path: p.display().to_string(),
                    source: e,
                })?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "mcap"))
                .collect();
            found.sort();
            out.extend(found);
        } else {
            out.push(p.clone());
        }
    }
    if out.is_empty() {
        return Err(EvalError::Invalid {
            field: "recordings",
            reason: format!("no .mcap files in {paths:?}"),
        });
    }
    Ok(out)
}

/// The file name of `path`, which names its scenarios in the report.
pub fn short_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    )
}

fn ring(r: Option<&LinearRing>) -> Vec<P2> {
    r.map(|r| r.points.iter().map(|p| [p.x, p.y]).collect())
        .unwrap_or_default()
}

/// Converts one frame's ground truth. Small buildings standing on a roof (obstacles of class
/// building rooftop) are also added as raised roofs, not scored, so that a site on their top is
/// judged against their footprint instead of counting as a site inside an obstacle.
pub fn scenario_of(
    file: &str,
    frame: Frame,
    truth: &GroundTruth,
    labels: Option<CameraImage>,
) -> Scenario {
    let eye = sensor_position(&frame);
    let mut roofs: Vec<RoofTruth> = truth
        .roofs
        .iter()
        .enumerate()
        // The ground truth lists the approached roof first.
        .map(|(k, r)| scored_roof(r, eye, k == 0 && r.building == truth.target_building))
        .collect();
    roofs.extend(truth.roofs.iter().flat_map(raised_roofs));
    let camera_above_roof_m = truth
        .camera_pose
        .as_ref()
        .and_then(|p| p.position.as_ref())
        .zip(truth.roofs.first())
        .map(|(p, target)| p.z - target.height_m);
    Scenario {
        name: format!("{file}#{}", frame.sequence),
        // Index, length and time are the approach's: `place_in_approach`.
        at: ApproachFrame {
            approach: file.to_string(),
            camera_above_roof_m,
            ..Default::default()
        },
        tags: tags_of(truth),
        frame,
        labels,
        roofs,
    }
}

/// A roof of the ground truth, scored; the part of it hidden from a sensor at `eye`, if known.
fn scored_roof(r: &landing_proto::v1::RoofTruth, eye: Option<[f64; 3]>, target: bool) -> RoofTruth {
    let outline = Polygon2::simple(ring(r.outline.as_ref()));
    let landable = r
        .landable_region
        .as_ref()
        .map(|p| Polygon2 {
            shell: ring(p.shell.as_ref()),
            holes: vec![],
        })
        .unwrap_or_default();
    let interior = interior_of(&outline, &landable, r.parapet_height_m);
    let hidden = eye.map_or_else(Vec::new, |eye| hidden_parts(eye, r, &interior));
    let obstacles: Vec<Obstacle> = r
        .obstacles
        .iter()
        .map(|o| Obstacle {
            class: u8::try_from(o.semantic_class).unwrap_or(0),
            footprint: Polygon2::simple(ring(o.footprint.as_ref())),
            seen: o.seen_by_lidar,
        })
        .collect();
    RoofTruth {
        id: r.building,
        outline,
        interior,
        height_m: r.height_m,
        obstacles,
        // The simulator's scanned region: interior ∩ convex hull of the scan on this roof.
        scanned: (landable.shell.len() >= 3).then_some(landable),
        hidden,
        in_sight: None,
        stated_best_radius_m: Some(r.best_safe_radius_m),
        scored: true,
        target,
    }
}

/// The small buildings standing on roof `r` as roofs of their own, raised by their height and
/// not scored.
fn raised_roofs(r: &landing_proto::v1::RoofTruth) -> impl Iterator<Item = RoofTruth> + '_ {
    r.obstacles
        .iter()
        .filter(|o| o.semantic_class == SemanticClass::BuildingRooftop as i32)
        .map(move |o| {
            let fp = Polygon2::simple(ring(o.footprint.as_ref()));
            RoofTruth {
                id: r.building,
                outline: fp.clone(),
                interior: fp,
                height_m: r.height_m + o.height_m,
                obstacles: vec![],
                scanned: None,
                hidden: vec![],
                in_sight: None,
                stated_best_radius_m: None,
                scored: false,
                target: false,
            }
        })
}

/// The LiDAR's origin in the world, where the frame's cloud has a pose.
fn sensor_position(frame: &Frame) -> Option<[f64; 3]> {
    let pose = frame.point_cloud.as_ref()?.pose.as_ref()?;
    Some(landing_client::RigidTransform::from_pose(pose).translation)
}

/// The shadows, under a light at `eye`, of a roof's obstacles (solid boxes on their footprints:
/// a water tower's legs are taken as solid too, which hides a little more than they do) and of
/// its parapet (a wall of the parapet's height on every edge of the walkable roof). An eye below
/// the roof sees none of it.
fn hidden_parts(
    eye: [f64; 3],
    roof: &landing_proto::v1::RoofTruth,
    interior: &Polygon2,
) -> Vec<Polygon2> {
    let z = roof.height_m;
    let obstacles = roof
        .obstacles
        .iter()
        .map(|o| (ring(o.footprint.as_ref()), o.height_m));
    let shell = &interior.shell;
    let n = if roof.parapet_height_m > 0.0 {
        shell.len()
    } else {
        0
    };
    let walls = (0..n).map(|i| (vec![shell[i], shell[(i + 1) % n]], roof.parapet_height_m));
    let mut out = Vec::new();
    for (base, height) in obstacles.chain(walls) {
        match prism_shadow(eye, z, &base, height) {
            Some(shadow) if shadow.len() >= 3 => out.push(Polygon2::simple(shadow)),
            Some(_) => {}
            None => return vec![interior.clone()],
        }
    }
    out
}

/// Hard-case tags of a frame, from its target roof (the first) and the roofs around it.
pub fn tags_of(truth: &GroundTruth) -> Vec<String> {
    let mut tags = Vec::new();
    let Some(target) = truth.roofs.first() else {
        return tags;
    };
    let seen = |c: SemanticClass| {
        target
            .obstacles
            .iter()
            .any(|o| o.semantic_class == c as i32 && o.seen_by_lidar)
    };
    if seen(SemanticClass::Tarp) {
        tags.push("tarp".to_string());
    }
    if seen(SemanticClass::WaterTower) {
        tags.push("water_tower".to_string());
    }
    if target.parapet_height_m > 0.0 {
        tags.push("parapet".to_string());
    }
    if truth
        .roofs
        .iter()
        .skip(1)
        .any(|r| (r.height_m - target.height_m).abs() > 0.5)
    {
        tags.push("adjacent_roofs".to_string());
    }
    // Point density on the roof falls with height: tag the frames with the LiDAR's height above
    // the target roof.
    if let Some(z) = truth
        .lidar_pose
        .as_ref()
        .and_then(|p| p.position.as_ref())
        .map(|p| p.z)
    {
        let above = z - target.height_m;
        // Nearest 10 m: approaches fly at 40, 30, 20 and 10 m.
        let band = ((above / 10.0).round().clamp(0.0, 99.0) as u32) * 10;
        tags.push(format!("altitude_{band:02}m"));
    }
    tags
}

/// The walkable roof: for an axis-aligned rectangular outline with a parapet, the outline shrunk
/// by the parapet's thickness, read off the gap between the outline and the landable region (the
/// narrowest side) and kept within [`PARAPET_THICKNESS_M`]; without a parapet, the outline.
pub fn interior_of(outline: &Polygon2, landable: &Polygon2, parapet_height_m: f64) -> Polygon2 {
    if parapet_height_m <= 0.0 {
        return outline.clone();
    }
    let Some((lo, hi)) = outline.bounds() else {
        return outline.clone();
    };
    let is_rect = outline.shell.len() == 4
        && outline.shell.iter().all(|p| {
            ((p[0] - lo[0]).abs() < 1e-6 || (p[0] - hi[0]).abs() < 1e-6)
                && ((p[1] - lo[1]).abs() < 1e-6 || (p[1] - hi[1]).abs() < 1e-6)
        });
    if !is_rect {
        return outline.clone();
    }
    let gap = bounds_of(&landable.shell)
        .map(|(a, b)| {
            (a[0] - lo[0])
                .min(a[1] - lo[1])
                .min(hi[0] - b[0])
                .min(hi[1] - b[1])
        })
        .unwrap_or(PARAPET_THICKNESS_M.1);
    let t = gap.clamp(PARAPET_THICKNESS_M.0, PARAPET_THICKNESS_M.1);
    Polygon2::rect([lo[0] + t, lo[1] + t], [hi[0] - t, hi[1] - t])
}

/// Convenience for tests and tools: the scenarios of one file.
pub fn load_file(path: &Path) -> Result<Vec<Scenario>, EvalError> {
    load_scenarios(&[path.to_path_buf()])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interior_reads_the_parapet_thickness_off_the_landable_region() {
        let outline = Polygon2::rect([0.0, 0.0], [20.0, 10.0]);
        // The scan reaches the parapet on the left side, 0.3 m in.
        let landable = Polygon2::rect([0.3, 2.0], [12.0, 9.0]);
        let i = interior_of(&outline, &landable, 0.8);
        assert_eq!(i.bounds().unwrap(), ([0.3, 0.3], [19.7, 9.7]));
        // No parapet: the outline.
        assert_eq!(interior_of(&outline, &landable, 0.0), outline);
        // A scan that reaches no edge: the thickest parapet.
        let i = interior_of(&outline, &Polygon2::rect([5.0, 3.0], [8.0, 6.0]), 0.8);
        assert_eq!(i.bounds().unwrap(), ([0.45, 0.45], [19.55, 9.55]));
    }
}
