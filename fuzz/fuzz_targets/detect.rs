//! `landing_geometry::detect` on arbitrary finite points, classes and parameters: an answer or
//! an error, never a panic, and every answer passes the validity checks (OGC-valid polygons,
//! centres inside them, ranked). The bytes are decoded by
//! `landing_geometry::synthetic::fuzz_detect_input`, so that finds replay in that crate's tests.
#![no_main]

use landing_geometry::synthetic::fuzz_detect_input;
use landing_geometry::{detect, validation::check_detection};
use libfuzzer_sys::fuzz_target;

/// Points the geometry sees from one input at most (a frame has tens of thousands; the fuzzer
/// needs many runs a second more than size).
const MAX_POINTS: usize = 512;

fuzz_target!(|data: &[u8]| {
    let Some(input) = fuzz_detect_input(data, MAX_POINTS) else {
        return;
    };
    if let Ok(detection) = detect(&input.points, input.classes.as_deref(), &input.params) {
        check_detection(&detection).expect("a valid detection");
    }
});
