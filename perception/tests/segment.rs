//! The shipped model through ONNX Runtime on recorded simulator frames (Manhattan test worlds),
//! checked against the simulator's ground-truth labels.

mod common;

use std::sync::Arc;

use landing_perception::{
    Confusion, ExecutionProvider, ImageData, OrtLogLevel, PerceptionError, Segmenter,
    SegmenterConfig, decode_image, resolve_ort_library,
};

/// Mean IoU, over the classes with at least [`MIN_CLASS_PIXELS`] truth pixels, that the shipped
/// model must reach on the eight committed frames (measured 0.711 with the model of 2026-11-22;
/// the model card reports the whole 500-image test set). On eight frames a class with a few dozen
/// pixels (here skylight: 29) turns the plain mean into noise (plain mean measured: 0.355).
const MIN_MEAN_IOU: f64 = 0.65;
/// Classes with fewer truth pixels in the committed frames are left out of the mean.
const MIN_CLASS_PIXELS: u64 = 200;
/// Building-rooftop IoU the shipped model must reach on the committed frames (measured 0.911).
const MIN_ROOFTOP_IOU: f64 = 0.88;
/// Pixel accuracy on the committed frames (measured 0.939).
const MIN_PIXEL_ACCURACY: f64 = 0.90;

#[test]
fn shipped_model_matches_ground_truth_on_test_frames() {
    let seg = common::segmenter();
    let mut confusion = Confusion::default();
    for (name, png, truth) in common::test_frames() {
        let image = decode_image(ImageData::Png(&png)).unwrap();
        let mask = seg.segment(&image).unwrap();
        assert_eq!(
            (mask.width(), mask.height()),
            (seg.info().input_width, seg.info().input_height),
            "{name}: mask at model resolution"
        );
        let truth = truth.resized_nearest(mask.width(), mask.height()).unwrap();
        confusion.add(&mask, &truth).unwrap();
    }
    let report = confusion.report();
    eprintln!("per-class IoU: {:?}", report.per_class);
    eprintln!(
        "mean IoU {:.3}, pixel accuracy {:.3}",
        report.mean, report.pixel_accuracy
    );
    let rooftop = report.per_class[4].expect("rooftop pixels in the test frames");
    let mean = report.mean_over_classes_with(MIN_CLASS_PIXELS).unwrap();
    eprintln!("mean IoU over classes with >= {MIN_CLASS_PIXELS} pixels: {mean:.3}");
    assert!(mean >= MIN_MEAN_IOU, "mean IoU {mean:.3} < {MIN_MEAN_IOU}");
    assert!(
        report.pixel_accuracy >= MIN_PIXEL_ACCURACY,
        "pixel accuracy {:.3} < {MIN_PIXEL_ACCURACY}",
        report.pixel_accuracy
    );
    assert!(
        rooftop >= MIN_ROOFTOP_IOU,
        "rooftop IoU {rooftop:.3} < {MIN_ROOFTOP_IOU}"
    );
}

#[test]
fn info_describes_the_loaded_model() {
    let info = common::segmenter().info();
    assert_eq!(info.sha256.len(), 64);
    assert!(info.sha256.chars().all(|c| c.is_ascii_hexdigit()));
    assert_eq!(info.execution_provider, ExecutionProvider::Cpu);
    assert_eq!((info.input_width, info.input_height), (256, 192));
    assert_eq!(info.name, "mobilenet_fcn4s");
    assert!(info.ort_library.is_file());
}

#[test]
fn raw_rgb8_and_png_give_the_same_mask() {
    let seg = common::segmenter();
    let (_, png, _) = common::test_frames().remove(0);
    let image = decode_image(ImageData::Png(&png)).unwrap();
    let raw = decode_image(ImageData::Rgb8 {
        width: image.width(),
        height: image.height(),
        step: image.width() * 3,
        data: image.as_raw(),
    })
    .unwrap();
    assert_eq!(seg.segment(&image).unwrap(), seg.segment(&raw).unwrap());
}

#[test]
fn any_input_size_is_resized_to_the_model_input() {
    let seg = common::segmenter();
    let (_, png, _) = common::test_frames().remove(0);
    let image = decode_image(ImageData::Png(&png)).unwrap();
    let big = image::imageops::resize(&image, 640, 480, image::imageops::FilterType::Triangle);
    let a = seg.segment(&image).unwrap();
    let b = seg.segment(&big).unwrap();
    assert_eq!((b.width(), b.height()), (a.width(), a.height()));
    let same = a
        .as_slice()
        .iter()
        .zip(b.as_slice())
        .filter(|(x, y)| x == y)
        .count();
    assert!(
        // Measured 94.6 %: resampling twice moves class borders by a pixel here and there.
        same as f64 / a.as_slice().len() as f64 > 0.90,
        "upscaled input changes {} of {} pixels",
        a.as_slice().len() - same,
        a.as_slice().len()
    );
}

#[test]
fn segmenter_is_shared_across_threads() {
    let seg = Arc::new(
        Segmenter::new(&SegmenterConfig {
            model_path: common::model_path(),
            intra_threads: 2,
            ..SegmenterConfig::default()
        })
        .unwrap(),
    );
    let frames = common::test_frames();
    let image = decode_image(ImageData::Png(&frames[0].1)).unwrap();
    let expected = seg.segment(&image).unwrap();
    let handles: Vec<_> = (0..3)
        .map(|_| {
            let seg = Arc::clone(&seg);
            let image = image.clone();
            std::thread::spawn(move || seg.segment(&image).unwrap())
        })
        .collect();
    for h in handles {
        assert_eq!(h.join().unwrap(), expected);
    }
}

#[test]
fn cuda_request_falls_back_to_cpu_here() {
    // No GPU on this machine (and the default build has no `cuda` feature): the session must
    // still come up, on the CPU, and say so.
    let seg = Segmenter::new(&SegmenterConfig {
        model_path: common::model_path(),
        execution_provider: ExecutionProvider::Cuda,
        ..SegmenterConfig::default()
    })
    .unwrap();
    assert_eq!(seg.info().execution_provider, ExecutionProvider::Cpu);
}

#[test]
fn missing_model_names_the_path() {
    let err = Segmenter::new(&SegmenterConfig {
        model_path: "/nonexistent/model.onnx".into(),
        ..SegmenterConfig::default()
    })
    .unwrap_err();
    assert!(matches!(err, PerceptionError::ModelRead { .. }), "{err}");
    assert!(err.to_string().contains("/nonexistent/model.onnx"), "{err}");
}

#[test]
fn a_file_that_is_not_a_model_is_refused() {
    let dir = std::env::temp_dir().join(format!("landing-perception-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("garbage.onnx");
    std::fs::write(&path, b"not an onnx model").unwrap();
    let err = Segmenter::new(&SegmenterConfig {
        model_path: path.clone(),
        ..SegmenterConfig::default()
    })
    .unwrap_err();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(matches!(err, PerceptionError::ModelShape { .. }), "{err}");
}

#[test]
fn missing_runtime_library_says_how_to_install_it() {
    let err = resolve_ort_library(Some("/nonexistent/libonnxruntime.so".as_ref())).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("scripts/setup-ort.sh"), "{msg}");
    assert!(msg.contains("/nonexistent/libonnxruntime.so"), "{msg}");
    assert!(msg.contains("ort_library"), "{msg}");
}

#[test]
fn bad_config_is_refused_before_loading() {
    let err = Segmenter::new(&SegmenterConfig {
        intra_threads: 0,
        ..SegmenterConfig::default()
    })
    .unwrap_err();
    assert!(err.to_string().contains("intra_threads"), "{err}");
    let err = Segmenter::new(&SegmenterConfig {
        input_size: Some((16, 4000)),
        ..SegmenterConfig::default()
    })
    .unwrap_err();
    assert!(err.to_string().contains("input_size"), "{err}");
}

#[test]
fn ort_log_levels_parse_by_name_and_a_bad_one_is_named() {
    for level in OrtLogLevel::ALL {
        assert_eq!(level.as_str().parse::<OrtLogLevel>().unwrap(), level);
    }
    assert_eq!("WARN".parse::<OrtLogLevel>().unwrap(), OrtLogLevel::Warning);
    assert_eq!(OrtLogLevel::default(), OrtLogLevel::Warning);
    assert_eq!(
        SegmenterConfig::default().ort_log_level,
        OrtLogLevel::Warning
    );
    let err = "loud".parse::<OrtLogLevel>().unwrap_err().to_string();
    assert!(
        err.contains("ort_log_level") && err.contains("loud"),
        "{err}"
    );
}
