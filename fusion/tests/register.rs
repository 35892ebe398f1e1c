//! Scan-to-map registration alone: it undoes a pose error where the scene constrains it, holds
//! still where it does not, refuses what is not a pose error, and does not care where the world
//! origin is.

use landing_fusion::{Correction, FusionMap, FusionParams, NotRegistered, Scan};
use proptest::prelude::*;

/// Off the cell grid of the building's walls and roof (a map is anchored at its first sensor).
const SENSOR: [f64; 3] = [-5.0123, -25.0456, 40.0789];

/// A 10 × 10 m building 10 m tall with a 2 × 2 × 1.2 m box on its roof, sampled every 0.1 m from
/// `start` (in 0..0.1, so two scans sample it at different places; off the map's cell
/// boundaries, so that rounding far from the origin cannot move a point across one), shifted by `offset`.
fn building(start: f64, offset: [f64; 3]) -> Vec<[f64; 3]> {
    let steps = |from: f64, to: f64| {
        let n = ((to - from) / 0.1) as i32;
        (0..n).map(move |i| from + start + f64::from(i) * 0.1)
    };
    let mut p = Vec::new();
    for x in steps(0.0, 10.0) {
        for y in steps(0.0, 10.0) {
            let on_box = (4.0..6.0).contains(&x) && (4.0..6.0).contains(&y);
            p.push([x, y, if on_box { 11.2 } else { 10.0 }]);
        }
        for z in steps(0.0, 10.0) {
            p.push([x, 0.0, z]);
            p.push([x, 10.0, z]);
            p.push([0.0, x, z]);
            p.push([10.0, x, z]);
        }
    }
    for a in steps(4.0, 6.0) {
        for z in steps(10.0, 11.2) {
            p.push([a, 4.0, z]);
            p.push([a, 6.0, z]);
            p.push([4.0, a, z]);
            p.push([6.0, a, z]);
        }
    }
    p.into_iter()
        .map(|q| [q[0] + offset[0], q[1] + offset[1], q[2] + offset[2]])
        .collect()
}

/// A bare flat roof: nothing says where it is horizontally, or its heading.
fn flat_roof(start: f64) -> Vec<[f64; 3]> {
    (0..10_000)
        .map(|i| {
            let (x, y) = (f64::from(i % 100), f64::from(i / 100));
            [x * 0.1 + start, y * 0.1 + start, 10.0]
        })
        .collect()
}

/// The pose error: a rotation (rotation vector, radians) about the sensor, then a translation.
fn perturb(points: &[[f64; 3]], error: &Correction) -> Vec<[f64; 3]> {
    points.iter().map(|&p| error.apply(p)).collect()
}

fn error(rotation_deg: [f64; 3], translation: [f64; 3], sensor: [f64; 3]) -> Correction {
    Correction {
        rotation: rotation_deg.map(f64::to_radians),
        translation,
        pivot: sensor,
        matched: 0,
        rms_before_m: 0.0,
        rms_after_m: 0.0,
    }
}

fn map_of(points: &[[f64; 3]], sensor: [f64; 3]) -> FusionMap<()> {
    let mut map = FusionMap::new(FusionParams::default()).unwrap();
    map.insert(Scan {
        sensor,
        points,
        ..Scan::new("drone")
    });
    map
}

fn worst(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
        })
        .fold(0.0, f64::max)
}

#[test]
fn undoes_a_realistic_pose_error_where_walls_and_roof_constrain_it() {
    let map = map_of(&building(0.0137, [0.0; 3]), SENSOR);
    let truth = building(0.0637, [0.0; 3]);
    // Larger than the realistic error (0.1° heading, 3 cm): 0.3° heading, 5 cm.
    let seen = perturb(
        &truth,
        &error([0.05, -0.05, 0.3], [0.05, -0.03, 0.04], SENSOR),
    );
    let before = worst(&seen, &truth);
    let c = map.register(&seen, SENSOR).expect("registered");
    let after = worst(&perturb(&seen, &c), &truth);
    assert!(before > 0.1, "the error moves points by {before} m");
    assert!(after < 0.01, "{before} m before, {after} m after: {c:?}");
    assert!(c.rms_after_m < c.rms_before_m / 3.0, "{c:?}");
    assert!(c.matched >= 500, "{c:?}");
}

#[test]
fn a_flat_roof_fixes_height_and_tilt_and_leaves_heading_and_position_alone() {
    let sensor = [5.0, 5.0, 40.0];
    let map = map_of(&flat_roof(0.0137), sensor);
    let truth = flat_roof(0.0637);
    let seen = perturb(&truth, &error([0.1, 0.0, 0.3], [0.05, 0.05, 0.04], sensor));
    let c = map.register(&seen, sensor).expect("registered");
    let fixed = perturb(&seen, &c);
    let height = fixed
        .iter()
        .map(|p| (p[2] - 10.0).abs())
        .fold(0.0, f64::max);
    assert!(height < 0.005, "height off by {height} m: {c:?}");
    // Heading and horizontal position are unobservable: the prior keeps them unchanged.
    assert!(c.rotation[2].abs() < 1e-4, "{c:?}");
    assert!(
        c.translation[0].abs() < 0.005 && c.translation[1].abs() < 0.005,
        "{c:?}"
    );
}

#[test]
fn nothing_to_register_to_and_nothing_in_common() {
    let empty: FusionMap<()> = FusionMap::new(FusionParams::default()).unwrap();
    let scan = building(0.0637, [0.0; 3]);
    assert_eq!(empty.register(&scan, SENSOR), Err(NotRegistered::Nothing));

    let map = map_of(&building(0.0137, [0.0; 3]), SENSOR);
    let elsewhere = building(0.0637, [200.0, 0.0, 0.0]);
    assert!(matches!(
        map.register(&elsewhere, SENSOR),
        Err(NotRegistered::TooFewMatches { .. })
    ));

    let off = FusionParams {
        register_scans: false,
        ..FusionParams::default()
    };
    let mut map: FusionMap<()> = FusionMap::new(off).unwrap();
    map.insert(Scan {
        sensor: SENSOR,
        points: &scan,
        ..Scan::new("drone")
    });
    assert_eq!(map.register(&scan, SENSOR), Err(NotRegistered::Nothing));
}

#[test]
fn a_shift_larger_than_a_pose_error_is_refused_not_applied() {
    let map = map_of(&building(0.0137, [0.0; 3]), SENSOR);
    // The same building 2.5° of heading off: farther than any navigation error.
    let seen = perturb(
        &building(0.0637, [0.0; 3]),
        &error([0.0, 0.0, 2.5], [0.0; 3], SENSOR),
    );
    match map.register(&seen, SENSOR) {
        Ok(c) => assert!(c.rotation_deg() <= 2.0, "{c:?}"),
        Err(e) => assert!(
            matches!(
                e,
                NotRegistered::TooLarge { .. } | NotRegistered::TooFewMatches { .. }
            ),
            "{e}"
        ),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, ..ProptestConfig::default() })]

    /// Wherever the world origin is and however the cells fall on the scene, the correction
    /// shrinks a realistic error to a few centimetres, and the same scene and error give the same correction
    /// far from the origin.
    #[test]
    fn the_correction_does_not_depend_on_the_world_origin(
        east in -1.0e7f64..1.0e7,
        north in -1.0e7f64..1.0e7,
        up in -1.0e4f64..1.0e4,
        grid in prop::array::uniform3(0.0f64..0.15),
        yaw in -0.3f64..0.3,
    ) {
        let at = |offset: [f64; 3]| {
            let sensor = std::array::from_fn(|i| SENSOR[i] + grid[i] + offset[i]);
            let map = map_of(&building(0.0137, offset), sensor);
            let truth = building(0.0637, offset);
            let seen = perturb(&truth, &error([0.02, 0.0, yaw], [0.03, 0.02, -0.02], sensor));
            let c = map.register(&seen, sensor).expect("registered");
            (worst(&seen, &truth), worst(&perturb(&seen, &c), &truth), c)
        };
        let ((before, near_error, here), (_, far_error, there)) = (at([0.0; 3]), at([east, north, up]));
        // Cells that straddle an edge (roof and wall in one cell) bias the planes near it by up
        // to a few centimetres, whatever the origin: the error shrinks, to under 3 cm.
        prop_assert!(near_error < 0.03 && near_error < before, "{before} {near_error} {here:?}");
        prop_assert!((near_error - far_error).abs() < 1e-4, "{near_error} {far_error} {there:?}");
        for i in 0..3 {
            prop_assert!((here.rotation[i] - there.rotation[i]).abs() < 1e-6, "{here:?} {there:?}");
            prop_assert!((here.translation[i] - there.translation[i]).abs() < 1e-4, "{here:?} {there:?}");
        }
    }
}
