//! The evaluation's metrics on real simulator ground truth (`samples/rooftops.mcap`), without a
//! server: the truth conversion agrees with the simulator's own optimum, a perfect answer scores
//! perfectly, an oversized circle is caught, and the report folder is written.

use landing_eval as eval;

use std::path::PathBuf;

use eval::geom::Polygon2;
use eval::metrics::{MetricsParams, Site, evaluate_frame, landable_mask};
use eval::report::{FrameRecord, Mode, Targets, summarize, write_report};
use eval::run::{Scenario, fill_scanned_regions};

fn sample() -> Vec<Scenario> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../samples/rooftops.mcap");
    let mut scenarios =
        eval::truth::load_file(&path).expect("samples/rooftops.mcap has frames with ground truth");
    for s in &mut scenarios {
        fill_scanned_regions(s, 0.2).unwrap();
    }
    scenarios
}

/// The answer a perfect service would give on the target roof: the true landable polygon and
/// the true best circle (shrunk by one raster cell).
fn perfect_site(s: &Scenario, params: &MetricsParams) -> Option<Site> {
    let roof = s.roofs.iter().find(|r| r.target)?;
    let scanned = roof.scanned.clone()?;
    let (lo, hi) = roof.outline.bounds()?;
    let grid = eval::geom::Grid::covering(lo, hi, params.cell_m, 0.5)?;
    let (center, radius) = landable_mask(grid, roof).largest_inscribed_circle()?;
    let holes = roof
        .obstacles
        .iter()
        .filter(|o| o.footprint.shell.iter().any(|p| scanned.contains(*p)))
        .map(|o| o.footprint.shell.clone());
    Some(Site {
        rank: 1,
        polygon: Polygon2 {
            shell: scanned.shell.clone(),
            holes: holes.collect(),
        },
        center,
        plane_height_m: roof.height_m,
        radius_m: radius - params.cell_m,
    })
}

#[test]
fn raster_truth_agrees_with_the_simulators_polylabel() {
    let scenarios = sample();
    assert!(!scenarios.is_empty());
    let params = MetricsParams::default();
    let mut compared = 0;
    for s in &scenarios {
        assert!(
            s.roofs.iter().any(|r| r.target),
            "{}: no target roof",
            s.name
        );
        for roof in evaluate_frame(&[], &s.roofs, &params).roofs {
            let stated = roof
                .stated_truth_radius_m
                .expect("the simulator states the best radius");
            assert!(
                (roof.truth_radius_m - stated).abs() < 0.15,
                "{}: raster {} vs stated {stated}",
                s.name,
                roof.truth_radius_m
            );
            compared += 1;
        }
    }
    assert!(compared >= scenarios.len(), "{compared} roofs compared");
}

#[test]
fn a_perfect_answer_scores_perfectly_and_an_oversized_circle_is_caught() {
    let params = MetricsParams::default();
    let mut checked = 0;
    for s in sample() {
        let Some(site) = perfect_site(&s, &params) else {
            continue;
        };
        if site.radius_m < params.min_truth_radius_m {
            continue;
        }
        let e = evaluate_frame(std::slice::from_ref(&site), &s.roofs, &params);
        assert!(e.sites[0].verdict.is_safe(), "{}: {:?}", s.name, e.sites[0]);
        let target = e
            .roofs
            .iter()
            .find(|r| r.target)
            .expect("target roof scored");
        assert!(target.iou > 0.97, "{}: IoU {}", s.name, target.iou);
        assert!(
            target.radius_ratio > 0.97 && target.radius_ratio <= 1.0,
            "{}: ratio {}",
            s.name,
            target.radius_ratio
        );
        // One metre more than the true optimum must reach into something beyond the tolerance.
        let big = Site {
            radius_m: site.radius_m + 0.5 + params.tolerance_m,
            ..site
        };
        let e = evaluate_frame(&[big], &s.roofs, &params);
        assert!(
            !e.sites[0].verdict.is_safe(),
            "{}: oversized circle judged safe",
            s.name
        );
        checked += 1;
    }
    assert!(checked > 0, "no frame with a scorable target roof");
}

#[test]
fn the_report_folder_has_tables_json_and_charts() {
    let params = MetricsParams::default();
    let records: Vec<FrameRecord> = sample()
        .iter()
        .filter_map(|s| {
            let site = perfect_site(s, &params)?;
            Some(FrameRecord {
                mode: Mode::Truth,
                frame: s.name.clone(),
                at: s.at.clone(),
                fused: false,
                fusion: None,
                tags: s.tags.clone(),
                step_ms: vec![Some(1.0); eval::report::STEPS.len()],
                round_trip_ms: 2.0,
                eval: evaluate_frame(&[site], &s.roofs, &params),
            })
        })
        .collect();
    let summary = summarize(&records, &[], &[Mode::Truth]);
    assert_eq!(summary.modes[0].unsafe_sites(), 0);
    let dir = std::env::temp_dir().join(format!("landing-eval-test-{}", std::process::id()));
    let md = write_report(
        &dir,
        &summary,
        &records,
        &Targets::default(),
        &[Mode::Truth],
    )
    .unwrap();
    assert!(md.contains("PASS truth: unsafe sites = 0"), "{md}");
    for f in [
        "summary.md",
        "results.json",
        "timing.png",
        "iou.png",
        "radius_ratio.png",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let png = image::open(dir.join("timing.png")).unwrap();
    assert!(png.width() > 100 && png.height() > 100);
    std::fs::remove_dir_all(&dir).unwrap();
}
