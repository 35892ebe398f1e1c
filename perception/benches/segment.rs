//! Per-frame cost of camera perception with the shipped model: PNG decode, resize + normalise,
//! ONNX Runtime inference (1 and 2 intra-op threads; at the shipped 256×192 and at 320×240), and
//! classification of a 20,000-point cloud, alone and as one frame.
//!
//! Run: `scripts/setup-ort.sh && cargo bench -p landing-perception --bench segment`

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use landing_perception::{
    CameraModel, ImageData, Segmenter, SegmenterConfig, classify_points, decode_image, preprocess,
    workspace_root,
};
use nalgebra::Isometry3;
use rand::{Rng, SeedableRng, rngs::SmallRng};

fn first_test_frame() -> Vec<u8> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/images");
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .expect("tests/data/images")
        .map(|e| e.expect("entry").path())
        .collect();
    files.sort();
    std::fs::read(&files[0]).expect("read frame")
}

fn segmenter(threads: usize, input_size: Option<(u32, u32)>) -> Segmenter {
    Segmenter::new(&SegmenterConfig {
        model_path: workspace_root().join("models/rooftop-segmentation.onnx"),
        intra_threads: threads,
        input_size,
        ..SegmenterConfig::default()
    })
    .expect("shipped model")
}

/// A camera looking along +z and 20,000 points in front of it, a seeded random cloud.
fn scene(width: u32, height: u32) -> (CameraModel, Vec<[f32; 3]>) {
    let camera = CameraModel {
        pose: Isometry3::identity(),
        fx: 180.0,
        fy: 180.0,
        cx: f64::from(width) / 2.0,
        cy: f64::from(height) / 2.0,
        width,
        height,
    };
    let mut rng = SmallRng::seed_from_u64(42);
    let points = (0..20_000)
        .map(|_| {
            let z: f32 = rng.random_range(5.0..40.0);
            [
                z * rng.random_range(-0.8..0.8),
                z * rng.random_range(-0.6..0.6),
                z,
            ]
        })
        .collect();
    (camera, points)
}

fn bench(c: &mut Criterion) {
    let png = first_test_frame();
    let image = decode_image(ImageData::Png(&png)).expect("decode");
    let (w, h) = (image.width(), image.height());

    c.bench_function(&format!("decode_png/{w}x{h}"), |b| {
        b.iter(|| decode_image(ImageData::Png(black_box(&png))).expect("decode"))
    });
    c.bench_function("preprocess/640x480_to_256x192", |b| {
        let big = image::imageops::resize(&image, 640, 480, image::imageops::FilterType::Triangle);
        b.iter(|| preprocess(black_box(&big), 256, 192))
    });
    // The service's second input size from the simulator camera's 320 × 240, and the same
    // resampling by `image`'s generic resize (bit-identical; what `preprocess` used before).
    let camera_size =
        image::imageops::resize(&image, 320, 240, image::imageops::FilterType::Triangle);
    c.bench_function("preprocess/320x240_to_256x192", |b| {
        b.iter(|| preprocess(black_box(&camera_size), 256, 192))
    });
    c.bench_function("image_resize/320x240_to_256x192", |b| {
        b.iter(|| {
            image::imageops::resize(
                black_box(&camera_size),
                256,
                192,
                image::imageops::FilterType::Triangle,
            )
        })
    });
    c.bench_function("preprocess/320x240_no_resize", |b| {
        b.iter(|| preprocess(black_box(&camera_size), 320, 240))
    });
    let (camera, points) = scene(w, h);
    let mask = segmenter(1, None).segment(&image).expect("segment");
    c.bench_function("classify_points/20k", |b| {
        b.iter(|| classify_points(black_box(&points), &camera, &mask))
    });

    for threads in [1usize, 2] {
        for size in [(256u32, 192u32), (320, 240)] {
            let seg = segmenter(threads, Some(size));
            let input = preprocess(&image, size.0, size.1);
            c.bench_function(
                &format!("inference/{}x{}/threads_{threads}", size.0, size.1),
                |b| b.iter(|| seg.run(black_box(&input), size.0, size.1).expect("run")),
            );
        }
        let seg = segmenter(threads, None);
        c.bench_function(&format!("frame/{w}x{h}/threads_{threads}"), |b| {
            b.iter(|| {
                let image = decode_image(ImageData::Png(black_box(&png))).expect("decode");
                let mask = seg.segment(&image).expect("segment");
                classify_points(&points, &camera, &mask)
            })
        });
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .sample_size(30)
        .warm_up_time(std::time::Duration::from_secs(1))
        .measurement_time(std::time::Duration::from_secs(3));
    targets = bench
}
criterion_main!(benches);
