//! `landing_geometry::detect` on arbitrary finite points, classes and parameters: an answer or
//! an error, never a panic, and every answer passes the validity checks (OGC-valid polygons,
//! centres inside them, ranked).
#![no_main]

use landing_geometry::{Params, detect, validation::check_detection};
use libfuzzer_sys::fuzz_target;

/// Points the geometry sees from one input at most (a frame has tens of thousands; the fuzzer
/// needs many runs a second more than size).
const MAX_POINTS: usize = 512;

fuzz_target!(|data: &[u8]| {
    let Some((head, body)) = data.split_first_chunk::<8>() else {
        return;
    };
    // The first bytes pick parameters within the ranges the API accepts.
    let unit = |b: u8| f64::from(b) / 255.0;
    let params = Params {
        l_max_m: 0.05 + unit(head[0]) * 20.0,
        dot_min: unit(head[1]) * 0.999,
        z_min_m: unit(head[2]) * 2.0,
        polylabel_precision_m: 0.01 + unit(head[3]) * 2.0,
        min_region_triangles: usize::from(head[4] % 16),
        max_sites: usize::from(head[5] % 8) + 1,
        ..Params::default()
    };
    let with_classes = head[6] & 1 == 1;
    // Then 13 bytes a point: x, y, z as f32 (non-finite or out-of-range values skipped, as the
    // service refuses them) and a class.
    let mut points = Vec::new();
    let mut classes = Vec::new();
    for chunk in body.chunks_exact(13).take(MAX_POINTS) {
        let v = |i: usize| f32::from_le_bytes(chunk[i * 4..i * 4 + 4].try_into().expect("4 bytes"));
        let p = [v(0), v(1), v(2)];
        if p.iter().all(|c| c.is_finite() && c.abs() <= 1.0e7) {
            points.push(p);
            classes.push(chunk[12] % 15);
        }
    }
    let classes = with_classes.then_some(classes.as_slice());
    if let Ok(detection) = detect(&points, classes, &params) {
        check_detection(&detection).expect("a valid detection");
    }
});
