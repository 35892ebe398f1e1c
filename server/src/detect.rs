//! The offline `detect` command: a PLY file through the same pipeline as the service, printed as
//! JSON or as a table.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Duration;

use nalgebra::Isometry3;
use serde_json::json;

use crate::Error;
use crate::pipeline::{
    Cloud, Frame, FrameOptions, FrameOutput, Pipeline, SegmentationMode, run_pipeline,
};

/// Reads the PLY at `path` and runs the pipeline on it (classes from the file when it has them).
pub fn detect_ply(
    path: &Path,
    options: &FrameOptions,
    pipeline: &Pipeline,
) -> Result<FrameOutput, Error> {
    let cloud = landing_recording::ply::read(path).map_err(|e| Error::from_ply(path, e))?;
    let frame = Frame {
        drone_id: String::new(),
        sequence: 0,
        timestamp: None,
        cloud: Cloud {
            points: cloud.points.iter().map(|p| p.map(f64::from)).collect(),
            classes: cloud.classes,
            pose: Isometry3::identity(),
        },
        image: None,
        class_image: None,
        geodetic_origin: None,
    };
    run_pipeline(&frame, options, pipeline)
}

/// Reads the MCAP recording at `path` and runs the pipeline on the frame with sequence number
/// `sequence` (the first frame when `None`): image, cloud and poses, as the service would. In
/// class-image mode the frame's class image is the recording's true label image.
pub fn detect_recording(
    path: &Path,
    sequence: Option<u64>,
    options: &FrameOptions,
    pipeline: &Pipeline,
) -> Result<FrameOutput, Error> {
    let io = |reason: String| Error::Io {
        path: path.display().to_string(),
        reason,
    };
    let frames = landing_recording::read(path).map_err(|e| io(e.to_string()))?;
    let recorded = match sequence {
        Some(k) => frames
            .iter()
            .find(|r| r.frame.sequence == k)
            .ok_or_else(|| {
                let first = frames.first().map_or(0, |r| r.frame.sequence);
                let last = frames.last().map_or(0, |r| r.frame.sequence);
                io(format!(
                    "no frame with sequence {k}; it has {} frames, sequences {first}..={last}",
                    frames.len()
                ))
            })?,
        None => frames
            .first()
            .ok_or_else(|| io("the recording has no frame".into()))?,
    };
    let mut frame = recorded.frame.clone();
    if options.segmentation_mode == SegmentationMode::ClassImage {
        frame.class_image = Some(recorded.labels.clone().ok_or_else(|| {
            io(format!(
                "frame {} has no label image ({}) for --segmentation class-image",
                frame.sequence,
                landing_recording::LABELS_TOPIC
            ))
        })?);
    }
    run_pipeline(&Frame::try_from(&frame)?, options, pipeline)
}

/// The result as the JSON document of `detect --json`: the API's result in the one schema
/// that `landing detect --json` prints too ([`landing_proto::json`]).
pub fn to_json(out: &FrameOutput) -> serde_json::Value {
    landing_proto::json::frame_result(&landing_proto::v1::FrameResult::from(out))
}

/// The result as a readable table.
pub fn to_table(out: &FrameOutput) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{} points, {} triangles, classes: {}, {} site(s)",
        out.point_count,
        out.triangle_count,
        landing_proto::json::mode_name(out.segmentation_mode as i32),
        out.sites.len()
    );
    if !out.sites.is_empty() {
        let _ = writeln!(
            s,
            "{:>4}  {:>28}  {:>10}  {:>10}  {:>5}  {:>9}",
            "rank", "center x, y, z (m)", "radius (m)", "area (m2)", "holes", "triangles"
        );
    }
    for site in &out.sites {
        let c = site.center;
        let _ = writeln!(
            s,
            "{:>4}  {:>28}  {:>10.2}  {:>10.1}  {:>5}  {:>9}",
            site.rank,
            format!("{:.2}, {:.2}, {:.2}", c[0], c[1], c[2]),
            site.safe_radius_m,
            site.area_m2,
            site.holes.len(),
            site.triangle_count
        );
    }
    let timings = timings_us(out);
    let steps: Vec<String> = timings
        .as_object()
        .into_iter()
        .flatten()
        .map(|(k, v)| format!("{k} {v} µs"))
        .collect();
    let _ = writeln!(s, "timings: {}", steps.join(", "));
    s
}

fn timings_us(out: &FrameOutput) -> serde_json::Value {
    // The offline command has no queue; every other step that ran is reported.
    let map = out
        .timings
        .named()
        .filter(|(name, _)| *name != "queue")
        .map(|(name, d)| (name.to_owned(), json!(micros(d))))
        .collect();
    serde_json::Value::Object(map)
}

fn micros(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}
