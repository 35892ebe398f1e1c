//! The JSON form of a [`FrameResult`]: the one schema that `landing detect --json`, `landing
//! replay --jsonl` and `landing-server detect --json` print (feature `json`).
//!
//! Vectors are `[x, y, z]` arrays, rings arrays of them, timings milliseconds by
//! [`STAGES`](crate::STAGES) name (`null` for a step that did not run), the segmentation mode
//! its proto name in lower case without the prefix (`point_classes`).
//!
//! ```
//! use landing_proto::v1::{FrameResult, LandingSite, SegmentationMode};
//!
//! let result = FrameResult {
//!     segmentation_mode: SegmentationMode::PointClasses as i32,
//!     sites: vec![LandingSite { rank: 1, ..Default::default() }],
//!     ..Default::default()
//! };
//! let doc = landing_proto::json::frame_result(&result);
//! assert_eq!(doc["segmentation_mode"], "point_classes");
//! assert_eq!(doc["sites"][0]["rank"], 1);
//! assert!(doc["timings_ms"]["queue"].is_null());
//! ```

use serde_json::{Value, json};

use crate::v1::{FrameResult, LandingSite, LinearRing, SegmentationMode, Vector3};

/// The JSON document of one result.
pub fn frame_result(r: &FrameResult) -> Value {
    let ms = |d: Option<prost_types::Duration>| {
        d.and_then(crate::duration_from_proto)
            .map(|d| d.as_secs_f64() * 1e3)
    };
    let t = r.timings.unwrap_or_default();
    let timings: serde_json::Map<String, Value> = crate::STAGES
        .iter()
        .zip(t.by_stage())
        .map(|(name, d)| (name.to_string(), json!(ms(d))))
        .collect();
    json!({
        "drone_id": r.drone_id,
        "sequence": r.sequence,
        "segmentation_mode": mode_name(r.segmentation_mode),
        "point_count": r.point_count,
        "triangle_count": r.triangle_count,
        "timings_ms": timings,
        "sites": r.sites.iter().map(site).collect::<Vec<_>>(),
        "fusion": r.fusion.as_ref().map(|f| json!({
            "frames": f.frames, "points": f.points, "cells": f.cells,
            "reset_reason": (!f.reset_reason.is_empty()).then_some(&f.reset_reason),
            "keep_out_frames": f.keep_out_frames,
            "registration": f.registration.map(|r| json!({
                "translation_m": r.translation_m, "rotation_deg": r.rotation_deg,
                "matched_points": r.matched_points, "rms_before_m": r.rms_before_m, "rms_after_m": r.rms_after_m,
            })),
            "registration_skipped": (!f.registration_skipped.is_empty()).then_some(&f.registration_skipped),
        })),
    })
}

/// A segmentation mode as the JSON and the tables print it: the proto name in lower case
/// without its prefix (`class_image`); `unspecified` for a number the enum does not have.
pub fn mode_name(mode: i32) -> String {
    let name = SegmentationMode::try_from(mode)
        .unwrap_or_default()
        .as_str_name();
    name.trim_start_matches("SEGMENTATION_MODE_").to_lowercase()
}

fn site(s: &LandingSite) -> Value {
    let v3 = |v: Option<Vector3>| v.map(|v| v.to_array());
    let ring = |r: &LinearRing| r.points.iter().map(Vector3::to_array).collect::<Vec<_>>();
    json!({
        "rank": s.rank,
        "safe_radius_m": s.safe_radius_m,
        "area_m2": s.area_m2,
        "center": v3(s.center),
        "center_geodetic": s.center_geodetic.map(|g| json!({"latitude_deg": g.latitude_deg, "longitude_deg": g.longitude_deg, "altitude_m": g.altitude_m})),
        "normal": v3(s.normal),
        "plane_height_m": s.polygon.as_ref().map(|p| p.plane_height_m),
        "shell": s.polygon.as_ref().and_then(|p| p.shell.as_ref()).map(ring),
        "holes": s.polygon.as_ref().map(|p| p.holes.iter().map(ring).collect::<Vec<_>>()),
        "point_count": s.point_count,
        "triangle_count": s.triangle_count,
    })
}
