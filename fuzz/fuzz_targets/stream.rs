//! A fused stream on arbitrary sequences of frames: drone ids, times (backwards, gaps), poses
//! (jumps, far from the origin), resets, clouds with and without classes, each run as the
//! stream handler runs it (`run_fused` on the stream's map, the server's default fusion
//! settings). Every frame gets an answer or an error, never a panic; the map stays within its
//! cell bound; every answer says how many frames it fused.
#![no_main]

use landing_geometry::Params;
use landing_server::pipeline::{
    Cloud, Frame, FrameOptions, Pipeline, SegmentationMode, StreamMap, pose, run_fused,
};
use libfuzzer_sys::fuzz_target;

/// Frames in one input, and points in one frame.
const MAX_FRAMES: usize = 12;
const MAX_POINTS: usize = 256;

/// Bytes of one frame's header: drone (1), reset (1), time step (2), position (3 × 4), heading (1).
const HEADER: usize = 17;

fuzz_target!(|data: &[u8]| {
    let fusion = landing_server::Config::default().fusion.params();
    let max_cells = fusion.max_cells;
    let Ok(mut map) = StreamMap::new(fusion) else {
        return;
    };
    let pipeline = Pipeline::geometry_only(Params::default());
    let options = FrameOptions {
        params: Params::default(),
        segmentation_mode: SegmentationMode::Unspecified,
    };
    let mut time_ms: i64 = 1_000_000;
    // Frames are separated by 0xFE bytes.
    let mut sequence = 0;
    for chunk in data.split(|&b| b == 0xFE).take(MAX_FRAMES) {
        let Some((head, body)) = chunk.split_first_chunk::<HEADER>() else {
            continue;
        };
        let f32_at = |i: usize| f32::from_le_bytes(head[i..i + 4].try_into().expect("4 bytes"));
        // Time mostly forwards (100 ms), sometimes backwards or by a gap.
        time_ms += i64::from(i16::from_le_bytes([head[2], head[3]]));
        let position = [f32_at(4), f32_at(8), f32_at(12)].map(f64::from);
        let heading = f64::from(head[16]) / 255.0 * std::f64::consts::TAU;
        let (s, c) = (heading / 2.0).sin_cos();
        let Some(lidar) = pose(position, [0.0, 0.0, s, c]) else {
            continue;
        };
        if position.iter().any(|v| v.abs() > 1.0e7) {
            continue;
        }
        let with_classes = head[0] & 0x80 != 0;
        let mut points = Vec::new();
        let mut classes = Vec::new();
        for p in body.chunks_exact(4).take(MAX_POINTS) {
            // A point a byte a coordinate (a 25 cm grid around the sensor), and its class.
            let v = |b: u8| f64::from(b as i8) * 0.25;
            points.push([v(p[0]), v(p[1]), v(p[2]) - 20.0]);
            classes.push(p[3] % 15);
        }
        sequence += 1;
        let frame = Frame {
            drone_id: format!("d{}", head[0] & 3),
            sequence,
            timestamp: Some(prost_types_timestamp(time_ms)),
            cloud: Cloud {
                points,
                classes: with_classes.then_some(classes),
                pose: lidar,
            },
            image: None,
            class_image: None,
            geodetic_origin: None,
        };
        if let Ok(out) = run_fused(&frame, &options, &pipeline, &mut map, head[1] == 1) {
            let summary = out.fusion.expect("a fused answer says what it fused");
            assert!(summary.frames >= 1);
            assert!(summary.cells <= max_cells);
        }
    }
});

fn prost_types_timestamp(ms: i64) -> prost_types::Timestamp {
    prost_types::Timestamp {
        seconds: ms.div_euclid(1000),
        nanos: (ms.rem_euclid(1000) * 1_000_000) as i32,
    }
}
