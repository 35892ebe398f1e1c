//! Approaches on the real sample recording (`samples/rooftops.mcap`): each frame's place in its
//! approach, and the fused truth growing with the scans.

use std::path::PathBuf;

use landing_eval as eval;

use eval::approach::fused_roofs;
use eval::metrics::{MetricsParams, evaluate_frame};
use eval::run::{Scenario, approaches, fill_scanned_regions};

fn sample() -> Vec<Scenario> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
    let mut scenarios = eval::truth::load_file(&path).expect("sample has ground truth");
    for s in &mut scenarios {
        fill_scanned_regions(s, 0.2).unwrap();
    }
    scenarios
}

#[test]
fn frames_know_their_place_in_the_approach() {
    let scenarios = sample();
    let groups = approaches(&scenarios);
    assert_eq!(groups.len(), 1, "one file, one approach");
    let frames: Vec<&Scenario> = groups[0].iter().map(|&i| &scenarios[i]).collect();
    assert_eq!(frames.len(), scenarios.len());
    for (k, s) in frames.iter().enumerate() {
        assert_eq!(s.at.index, k);
        assert_eq!(s.at.approach_frames, frames.len());
        assert_eq!(s.at.approach, "rooftops.mcap");
        assert!(
            s.at.camera_above_roof_m.is_some_and(|h| h > 0.0),
            "{:?}",
            s.at
        );
    }
    assert_eq!(frames[0].at.time_s, Some(0.0));
    let times: Vec<f64> = frames.iter().map(|s| s.at.time_s.unwrap()).collect();
    assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
    let seqs: Vec<u64> = frames.iter().map(|s| s.frame.sequence).collect();
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "{seqs:?}");
}

#[test]
fn the_fused_truth_grows_with_the_scans_of_the_approach() {
    let scenarios = sample();
    let order = &approaches(&scenarios)[0];
    let frames: Vec<&Scenario> = order.iter().map(|&i| &scenarios[i]).collect();
    let fused = fused_roofs(
        &frames
            .iter()
            .map(|s| s.roofs.as_slice())
            .collect::<Vec<_>>(),
        MetricsParams::default().cell_m,
    );
    let params = MetricsParams::default();
    let target_area = |roofs: &[eval::metrics::RoofTruth]| {
        let r = roofs.iter().find(|r| r.target).expect("target roof");
        r.scanned.as_ref().map_or(f64::INFINITY, |s| s.area())
    };
    let mut last = 0.0;
    for (k, (frame, roofs)) in frames.iter().zip(&fused).enumerate() {
        let area = target_area(roofs);
        // Never smaller than this frame's own scan, nor than the union before it.
        assert!(area >= target_area(&frame.roofs) - 1e-6, "frame {k}");
        assert!(area >= last - 1e-6, "frame {k}: {area} < {last}");
        last = area;
        // The fused truth can only hold more landable area than the frame's own.
        let single = evaluate_frame(&[], &frame.roofs, &params);
        let union = evaluate_frame(&[], roofs, &params);
        let t = |e: &eval::metrics::FrameEval| {
            e.roofs.iter().find(|r| r.target).map(|r| r.truth_area_m2)
        };
        if let (Some(a), Some(b)) = (t(&single), t(&union)) {
            assert!(
                b >= a - 0.05,
                "frame {k}: fused truth {b} m² < single {a} m²"
            );
        }
        // So can its line of sight: what the frame saw, every earlier frame's sight added.
        let sight = |e: &eval::metrics::FrameEval| {
            e.roofs.iter().find(|r| r.target).map(|r| r.visible_area_m2)
        };
        if let (Some(a), Some(b)) = (sight(&single), sight(&union)) {
            assert!(
                b >= a - 0.05,
                "frame {k}: fused line of sight {b} m² < single {a} m²"
            );
        }
    }
    assert_eq!(
        fused[0], frames[0].roofs,
        "the first frame's fused truth is its own"
    );
    // The sample descends: its last scans see less of the roof than the approach has seen.
    let (own, union) = (
        target_area(&frames[frames.len() - 1].roofs),
        target_area(&fused[fused.len() - 1]),
    );
    assert!(
        union > 1.2 * own,
        "last frame: union {union} m², own {own} m²"
    );
}
