//! `landing_geometry::detect` (or `detect_keeping_out`, with keep-out disks) on arbitrary finite
//! points, classes and parameters: an answer or an error, never a panic, and every answer
//! passes the validity checks (OGC-valid polygons, centres inside them, ranked). The bytes are decoded by
//! `landing_geometry::synthetic::fuzz_detect_input`, so that finds replay in that crate's tests.
#![no_main]

use landing_geometry::synthetic::fuzz_detect_input;
use landing_geometry::{KeepClear, detect, detect_keeping_out, validation::check_detection};
use libfuzzer_sys::fuzz_target;

/// Points the geometry sees from one input at most (a frame has tens of thousands; the fuzzer
/// needs many runs a second more than size).
const MAX_POINTS: usize = 512;

fuzz_target!(|data: &[u8]| {
    let Some(input) = fuzz_detect_input(data, MAX_POINTS) else {
        return;
    };
    let classes = input.classes.as_deref();
    let result = if input.disks.is_empty() {
        detect(&input.points, classes, &input.params)
    } else {
        let disks = |_: [f64; 3], _: [f64; 3], _: [f64; 4]| input.disks.clone();
        let keep_clear = KeepClear {
            disks: Some(&disks),
            points: None,
        };
        detect_keeping_out(&input.points, classes, &input.params, keep_clear)
    };
    if let Ok(detection) = result {
        check_detection(&detection).expect("a valid detection");
    }
});
