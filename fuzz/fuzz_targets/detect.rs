//! `landing_geometry::detect` on arbitrary finite points, classes, keep-out disks, cloud kinds and
//! parameters: an answer or an error, never a panic, and every answer
//! passes the validity checks (OGC-valid polygons, centres inside them, ranked). The bytes are decoded by
//! `landing_geometry::synthetic::fuzz_detect_input`, so that finds replay in that crate's tests.
#![no_main]

use landing_geometry::synthetic::fuzz_detect_input;
use landing_geometry::{Cloud, KeepClear, KeepOut, detect, validation::check_detection};
use libfuzzer_sys::fuzz_target;

/// Points the geometry sees from one input at most (a frame has tens of thousands; the fuzzer
/// needs many runs a second more than size).
const MAX_POINTS: usize = 512;

fuzz_target!(|data: &[u8]| {
    let Some(input) = fuzz_detect_input(data, MAX_POINTS) else {
        return;
    };
    let disks = |_: [f64; 3], _: [f64; 3], _: [f64; 4]| input.disks.clone();
    let keep_clear = KeepClear {
        disks: (!input.disks.is_empty()).then_some(&disks as &dyn KeepOut),
        points: None,
    };
    let cloud = Cloud::new(&input.points, input.classes.as_deref())
        .with_kind(input.kind)
        .with_keep_clear(keep_clear);
    let result = detect(&cloud, &input.params);
    if let Ok(detection) = result {
        check_detection(&detection).expect("a valid detection");
    }
});
