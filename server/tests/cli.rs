//! The `landing-server` binary: `detect` on generated PLY files and `check-config`.

use std::path::PathBuf;
use std::process::Command;

use landing_geometry::synthetic::{Scene, SceneParams};
use landing_recording::ply::{PlyCloud, write_ascii, write_binary};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_landing-server"))
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("landing-server-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn scene_ply(name: &str, binary: bool) -> (PathBuf, Scene) {
    let scene = Scene::generate(&SceneParams::default(), 11);
    let cloud = PlyCloud {
        points: scene.points.clone(),
        classes: Some(scene.classes.clone()),
    };
    let path = temp(name);
    std::fs::write(
        &path,
        if binary {
            write_binary(&cloud)
        } else {
            write_ascii(&cloud)
        },
    )
    .unwrap();
    (path, scene)
}

#[test]
fn detect_json_on_a_generated_roof() {
    let (path, scene) = scene_ply("roof.ply", true);
    let out = bin()
        .args(["detect", "--points"])
        .arg(&path)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["point_count"], scene.points.len());
    assert_eq!(doc["segmentation_mode"], "point_classes");
    let sites = doc["sites"].as_array().unwrap();
    assert!(!sites.is_empty(), "no site on the roof: {doc}");
    let best = &sites[0];
    assert_eq!(best["rank"], 1);
    // The best site is on the 10 m roof, inside its 20 m x 20 m outline.
    let center = best["center"].as_array().unwrap();
    let (x, y, z) = (
        center[0].as_f64().unwrap(),
        center[1].as_f64().unwrap(),
        center[2].as_f64().unwrap(),
    );
    assert!(
        (0.0..=20.0).contains(&x) && (0.0..=20.0).contains(&y),
        "{center:?}"
    );
    assert!((z - 10.0).abs() < 0.2, "{center:?}");
    assert!(best["safe_radius_m"].as_f64().unwrap() > 1.0);
    assert!(best["shell"].as_array().unwrap().len() >= 3);
    assert!(best["shell"][0].as_array().unwrap().len() == 3);
    assert!(best["holes"].is_array());
    assert!(best["triangle_count"].as_u64().unwrap() > 0);
    for step in [
        "triangulation",
        "triangle_filter",
        "plane_extraction",
        "polygon_extraction",
        "polylabel",
        "total",
    ] {
        assert!(
            doc["timings_ms"][step].is_f64(),
            "timings_ms.{step} missing: {doc}"
        );
    }
    // Ranked by safe radius.
    let radii: Vec<f64> = sites
        .iter()
        .map(|s| s["safe_radius_m"].as_f64().unwrap())
        .collect();
    assert!(radii.windows(2).all(|w| w[0] >= w[1]), "{radii:?}");
}

#[test]
fn detect_table_on_ascii_and_parameters_matter() {
    let (path, _) = scene_ply("roof-ascii.ply", false);
    let out = bin()
        .args(["detect", "--points"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("rank") && text.contains("radius"), "{text}");
    // A landable class that no point has leaves no site.
    let out = bin()
        .args(["detect", "--json", "--landable-class", "14", "--points"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["sites"].as_array().unwrap().len(), 0, "{doc}");
}

#[test]
fn malformed_files_fail_with_a_named_error() {
    let path = temp("broken.ply");
    std::fs::write(&path, "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nend_header\n1 2\n3 4\n").unwrap();
    let out = bin()
        .args(["detect", "--points"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("`z`") && err.contains("vertex"), "{err}");

    let out = bin()
        .args(["detect", "--points", "/nonexistent/cloud.ply"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/cloud.ply"));
}

#[test]
fn check_config_accepts_good_and_names_bad_keys() {
    let good = temp("good.toml");
    std::fs::write(
        &good,
        "[server]\nlisten = \"127.0.0.1:0\"\n[segmentation]\nenabled = false\n",
    )
    .unwrap();
    let out = bin()
        .args(["check-config", "--config"])
        .arg(&good)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("127.0.0.1:0"));

    let bad = temp("bad.toml");
    std::fs::write(
        &bad,
        "[pipeline]\nqueue_capacity = 0\n[segmentation]\nenabled = false\n",
    )
    .unwrap();
    let out = bin()
        .args(["check-config", "--config"])
        .arg(&bad)
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("pipeline.queue_capacity"));

    // The environment overrides the file, and the flag overrides the environment.
    let out = bin()
        .args(["check-config", "--listen", "127.0.0.1:9", "--config"])
        .arg(&good)
        .env("LANDING__SERVER__LISTEN", "127.0.0.1:8")
        .env("LANDING__SERVER__METRICS_LISTEN", "")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success()
            && stdout.contains("127.0.0.1:9")
            && stdout.contains("metrics_listen = \"\""),
        "{stdout}"
    );

    let out = bin()
        .args(["check-config", "--config"])
        .arg(&good)
        .env("LANDING__SERVER__LISTN", "x")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("LANDING__SERVER__LISTN"));
}

fn sample(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../samples")
        .join(name)
}

#[test]
fn detect_on_the_committed_samples() {
    let out = bin()
        .args(["detect", "--json", "--points"])
        .arg(sample("roof.ply"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(!doc["sites"].as_array().unwrap().is_empty(), "{doc}");

    // A recorded frame with its own point classes (no model needed).
    let out = bin()
        .args([
            "detect",
            "--json",
            "--segmentation",
            "point-classes",
            "--frame",
            "14",
            "--recording",
        ])
        .arg(sample("rooftops.mcap"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["segmentation_mode"], "point_classes");
    assert!(
        doc["timings_ms"]["decode"].is_f64(),
        "the image is decoded: {doc}"
    );
    assert!(!doc["sites"].as_array().unwrap().is_empty(), "{doc}");

    let out = bin()
        .args(["detect", "--frame", "999", "--recording"])
        .arg(sample("rooftops.mcap"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no frame with sequence 999"));
}

#[test]
fn detect_a_recorded_frame_with_the_model() {
    // Needs the ONNX Runtime library (scripts/setup-ort.sh) and the shipped model.
    let model = sample("../models/rooftop-segmentation.onnx");
    let out = bin()
        .args([
            "detect",
            "--json",
            "--segmentation",
            "model",
            "--frame",
            "14",
            "--recording",
        ])
        .arg(sample("rooftops.mcap"))
        .arg("--model")
        .arg(&model)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["segmentation_mode"], "model");
    for step in ["decode", "segmentation", "classification", "triangulation"] {
        assert!(
            doc["timings_ms"][step].is_f64(),
            "timings_ms.{step} missing: {doc}"
        );
    }
}
