//! Shared helpers of the integration tests: the shipped model and the committed simulator frames.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use landing_perception::{ClassMask, Segmenter, SegmenterConfig, workspace_root};

/// The shipped model.
pub fn model_path() -> PathBuf {
    workspace_root().join("models/rooftop-segmentation.onnx")
}

/// One shared segmenter (one thread) over the shipped model.
pub fn segmenter() -> &'static Segmenter {
    static SEGMENTER: OnceLock<Segmenter> = OnceLock::new();
    SEGMENTER.get_or_init(|| {
        Segmenter::new(&SegmenterConfig {
            model_path: model_path(),
            ..SegmenterConfig::default()
        })
        .unwrap_or_else(|e| panic!("cannot load the shipped model: {e}"))
    })
}

/// The committed frames: `(name, png bytes, truth mask)`, rendered by
/// `landing-sim dataset --split test` (Manhattan worlds, never seen in training).
pub fn test_frames() -> Vec<(String, Vec<u8>, ClassMask)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut names: Vec<PathBuf> = std::fs::read_dir(dir.join("images"))
        .expect("tests/data/images")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    names.sort();
    assert!(!names.is_empty(), "no test frames in {}", dir.display());
    names
        .into_iter()
        .map(|image_path| {
            let file = image_path.file_name().expect("file name").to_owned();
            let png = std::fs::read(&image_path).expect("read image");
            let labels = image::open(dir.join("labels").join(&file))
                .expect("read label")
                .into_luma8();
            let truth = ClassMask::from_label_image(&labels).expect("label ids");
            (file.to_string_lossy().into_owned(), png, truth)
        })
        .collect()
}
