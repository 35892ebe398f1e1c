//! The fusion map alone: class evidence, resets, bounds in cells and time, keep-out memory, and
//! independence from the world origin.

use landing_fusion::{FusionMap, FusionParams, Reset, Scan, View};
use proptest::prelude::*;

const ROOFTOP: u8 = 4;
const AC_UNIT: u8 = 8;

fn landable(c: u8) -> bool {
    c == ROOFTOP
}

/// A 10 × 10 m roof 30 m up sampled every 0.5 m, shifted by `offset`. The coordinates stay off
/// the cell boundaries of a map anchored at [`SENSOR`]: a point exactly on one may fall on
/// either side once rounded, wherever the origin is.
fn roof(offset: [f64; 3]) -> Vec<[f64; 3]> {
    (0..400)
        .map(|i| {
            let (x, y) = (
                f64::from(i % 20) * 0.5 + 0.1037,
                f64::from(i / 20) * 0.5 + 0.0913,
            );
            [x + offset[0], y + offset[1], 30.037 + offset[2]]
        })
        .collect()
}

const SENSOR: [f64; 3] = [5.0, -20.0, 60.0];

fn map() -> FusionMap<u32> {
    FusionMap::new(FusionParams::default()).unwrap()
}

fn scan<'a>(t: f64, points: &'a [[f64; 3]], classes: &'a [u8]) -> Scan<'a, u32> {
    Scan {
        time_s: t,
        sensor: SENSOR,
        points,
        classes: Some(classes),
        ..Scan::new("d")
    }
}

/// The fused class of the cell at the roof point `p`, and whether it is flagged unresolved.
fn cell_at(map: &FusionMap<u32>, p: [f64; 3]) -> (u8, bool) {
    let f = map.fused([[-100.0, -100.0], [100.0, 100.0]], landable);
    let i = f
        .points
        .iter()
        .position(|q| (q[0] - p[0]).abs() < 1e-3 && (q[1] - p[1]).abs() < 1e-3)
        .expect("the point's cell");
    (f.classes.unwrap()[i], f.unresolved[i])
}

/// The fused class at the roof point `p`.
fn class_at(map: &FusionMap<u32>, p: [f64; 3]) -> u8 {
    cell_at(map, p).0
}

#[test]
fn an_obstacle_vote_outweighs_up_to_weight_landable_ones() {
    let pts = roof([0.0; 3]);
    let rooftop = vec![ROOFTOP; pts.len()];
    let mut ac = rooftop.clone();
    ac[210] = AC_UNIT;
    let mut m = map();
    m.insert(scan(0.0, &pts, &ac));
    for k in 1..=4 {
        m.insert(scan(f64::from(k) * 0.1, &pts, &rooftop));
        assert_eq!(class_at(&m, pts[210]), AC_UNIT, "after {k} contrary frames");
    }
    m.insert(scan(0.5, &pts, &rooftop));
    assert_eq!(
        class_at(&m, pts[210]),
        ROOFTOP,
        "5 landable votes beat one obstacle"
    );
    // Every other cell stayed rooftop, and the points were not duplicated.
    let f = m.fused([[-100.0, -100.0], [100.0, 100.0]], landable);
    assert_eq!(f.points.len(), pts.len());
    assert_eq!(
        f.classes.unwrap().iter().filter(|&&c| c == ROOFTOP).count(),
        pts.len()
    );
}

#[test]
fn unclassified_cells_are_unknown_and_unclassified_maps_have_no_classes() {
    let pts = roof([0.0; 3]);
    let mut m = map();
    m.insert(Scan {
        points: &pts,
        sensor: SENSOR,
        ..Scan::new("d")
    });
    assert!(m.fused([[-1e3; 2], [1e3; 2]], landable).classes.is_none());
    let other: Vec<[f64; 3]> = pts.iter().map(|p| [p[0] + 20.0, p[1], p[2]]).collect();
    let classes = vec![ROOFTOP; other.len()];
    m.insert(scan(0.1, &other, &classes));
    let f = m.fused([[-1e3; 2], [1e3; 2]], landable);
    let classes = f.classes.unwrap();
    assert_eq!(classes.len(), 2 * pts.len());
    assert_eq!(classes.iter().filter(|&&c| c == 0).count(), pts.len());
}

#[test]
fn each_reset_reason_starts_over() {
    let pts = roof([0.0; 3]);
    let classes = vec![ROOFTOP; pts.len()];
    let mut m = map();
    assert_eq!(m.insert(scan(1.0, &pts, &classes)), None);
    assert_eq!(m.insert(scan(1.1, &pts, &classes)), None);
    assert_eq!(m.frames(), 2);
    let requested = Scan {
        reset: true,
        ..scan(1.2, &pts, &classes)
    };
    assert_eq!(m.insert(requested), Some(Reset::Requested));
    assert_eq!(m.frames(), 1);
    let other = Scan {
        drone_id: "e",
        ..scan(1.3, &pts, &classes)
    };
    assert_eq!(m.insert(other), Some(Reset::DroneChanged));
    let jumped = Scan {
        drone_id: "e",
        sensor: [500.0, -20.0, 60.0],
        ..scan(1.4, &pts, &classes)
    };
    assert!(matches!(m.insert(jumped), Some(Reset::PoseJump { metres }) if metres > 400.0));
    let back = Scan {
        drone_id: "e",
        sensor: [500.0, -20.0, 60.0],
        ..scan(1.0, &pts, &classes)
    };
    assert!(matches!(m.insert(back), Some(Reset::TimeBackwards { .. })));
    let late = Scan {
        drone_id: "e",
        sensor: [500.0, -20.0, 60.0],
        ..scan(100.0, &pts, &classes)
    };
    assert!(matches!(m.insert(late), Some(Reset::Gap { .. })));
    assert_eq!(m.frames(), 1);
    assert_eq!(m.cells(), pts.len());
    // Starting over is not a reason on the first frame.
    let mut fresh = map();
    let first = Scan {
        reset: true,
        ..scan(0.0, &pts, &classes)
    };
    assert_eq!(fresh.insert(first), None);
}

#[test]
fn answers_are_the_top_surface_seen_from_above() {
    // The roof, and a wall below its first row of points: 20 cells straight down.
    let mut pts = roof([0.0; 3]);
    let edge: Vec<[f64; 3]> = pts.iter().take(20).copied().collect();
    for p in &edge {
        for k in 1..=20 {
            pts.push([p[0], p[1], p[2] - f64::from(k) * 0.15]);
        }
    }
    let mut classes = vec![ROOFTOP; 400];
    classes.resize(pts.len(), AC_UNIT);
    let mut m = map();
    m.insert(scan(0.0, &pts, &classes));
    assert_eq!(m.cells(), pts.len());
    let f = m.fused([[-100.0, -100.0], [100.0, 100.0]], landable);
    // One point per column: the roof's, with the roof's class.
    assert_eq!(f.points.len(), 400);
    assert!(f.points.iter().all(|p| (p[2] - 30.037).abs() < 1e-4));
    assert!(f.classes.unwrap().iter().all(|&c| c == ROOFTOP));
}

#[test]
fn answers_hold_only_the_cells_inside_the_bounds() {
    let pts = roof([0.0; 3]);
    let classes = vec![ROOFTOP; pts.len()];
    let mut m = map();
    m.insert(scan(0.0, &pts, &classes));
    let f = m.fused([[0.0, 0.0], [5.0, 5.0]], landable);
    assert!(!f.points.is_empty() && f.points.len() < pts.len());
    assert!(
        f.points
            .iter()
            .all(|p| (0.0..=5.0).contains(&p[0]) && (0.0..=5.0).contains(&p[1]))
    );
    assert_eq!(f.points.len(), f.classes.unwrap().len());
}

/// Whether the fused cell at `p` is flagged unresolved.
fn unresolved_at(map: &FusionMap<u32>, p: [f64; 3]) -> bool {
    cell_at(map, p).1
}

#[test]
fn landable_cells_are_unresolved_until_a_fine_view_saw_them() {
    let pts = roof([0.0; 3]);
    let max = FusionParams::default().max_pixel_footprint_m;
    let rooftop = vec![ROOFTOP; pts.len()];
    let mut ac = rooftop.clone();
    ac[210] = AC_UNIT;
    // A far view: its pixels cover more of the roof than the rule allows, but on the near
    // half (y < 5 m); it sees nothing past x = 8 m.
    let far = |p: &[f64; 3]| (p[0] < 8.0).then_some(if p[1] < 5.0 { max } else { max * 1.5 });
    let mut m = map();
    for k in 0..5 {
        m.insert(Scan {
            view: Some(View(&far)),
            ..scan(
                f64::from(k) * 0.1,
                &pts,
                if k == 2 { &ac } else { &rooftop },
            )
        });
    }
    assert!(!unresolved_at(&m, pts[10]), "seen at the limit");
    assert!(unresolved_at(&m, pts[300]), "only coarse views");
    assert!(unresolved_at(&m, pts[19]), "never in view");
    // The votes decide the class as before, and an obstacle is not flagged.
    assert_eq!(class_at(&m, pts[300]), ROOFTOP);
    assert_eq!(class_at(&m, pts[210]), AC_UNIT);
    assert!(!unresolved_at(&m, pts[210]));
    // A near view resolves every cell it sees, not only those its scan's points fell in.
    let near = |p: &[f64; 3]| (p[0] < 8.0).then_some(max / 4.0);
    m.insert(Scan {
        view: Some(View(&near)),
        ..scan(0.5, &pts[..1], &rooftop[..1])
    });
    assert!(!unresolved_at(&m, pts[300]));
    assert!(unresolved_at(&m, pts[19]), "still never in view");
    // With the rule off, or with classes that came from no camera, nothing is flagged.
    let off = FusionParams {
        max_pixel_footprint_m: 0.0,
        ..FusionParams::default()
    };
    for (params, view) in [(off, Some(View(&far))), (FusionParams::default(), None)] {
        let mut m: FusionMap<u32> = FusionMap::new(params).unwrap();
        m.insert(Scan {
            view,
            ..scan(0.0, &pts, &rooftop)
        });
        let f = m.fused([[-100.0, -100.0], [100.0, 100.0]], landable);
        assert_eq!(f.unresolved, vec![false; f.points.len()]);
    }
}

#[test]
fn a_much_finer_view_replaces_the_votes_of_coarser_ones() {
    let pts = roof([0.0; 3]);
    let rooftop = vec![ROOFTOP; pts.len()];
    let mut ac = rooftop.clone();
    ac[100] = AC_UNIT;
    let wall = vec![3u8; pts.len()];
    let (far, similar) = (|_: &[f64; 3]| Some(0.5), |_: &[f64; 3]| Some(0.45));
    let (near, nearer) = (|_: &[f64; 3]| Some(0.35), |_: &[f64; 3]| Some(0.3));
    let insert = |m: &mut FusionMap<u32>, t: f64, view: View<'_>, classes: &[u8]| {
        m.insert(Scan {
            view: Some(view),
            ..scan(t, &pts, classes)
        });
    };
    // A far frame calls the whole roof wall; three frames from about as far call it roof: the
    // wall vote outweighs them, and would outweigh one more.
    let mut m = map();
    insert(&mut m, 0.0, View(&far), &wall);
    for k in 1..4 {
        insert(&mut m, f64::from(k) * 0.1, View(&similar), &rooftop);
    }
    assert_eq!(class_at(&m, pts[150]), 3);
    // One frame from much nearer (0.35 m pixels against 0.45 m) replaces every earlier vote.
    insert(&mut m, 0.5, View(&near), &ac);
    assert_eq!(class_at(&m, pts[150]), ROOFTOP);
    assert_eq!(class_at(&m, pts[100]), AC_UNIT);
    // Its obstacle vote then outweighs views about as fine as it...
    for k in 6..10 {
        insert(&mut m, f64::from(k) * 0.1, View(&nearer), &rooftop);
    }
    assert_eq!(class_at(&m, pts[100]), AC_UNIT);
    // ...and votes without a camera view add up as before.
    let mut m = map();
    m.insert(scan(0.0, &pts, &ac));
    for k in 1..5 {
        m.insert(scan(f64::from(k) * 0.1, &pts, &rooftop));
    }
    assert_eq!(class_at(&m, pts[100]), AC_UNIT);
}

#[test]
fn cells_are_bounded_in_number_and_time() {
    let params = FusionParams {
        max_cells: 1_000,
        horizon_s: 2.0,
        ..FusionParams::default()
    };
    let mut m: FusionMap<u32> = FusionMap::new(params).unwrap();
    // The drone flies on, scanning new ground every frame.
    for k in 0..40 {
        let pts = roof([f64::from(k) * 0.5, 0.0, 0.0]);
        let classes = vec![ROOFTOP; pts.len()];
        let s = Scan {
            sensor: [f64::from(k) * 0.5, -20.0, 60.0],
            ..scan(f64::from(k) * 0.1, &pts, &classes)
        };
        m.insert(s);
        assert!(m.cells() <= 1_000, "frame {k}: {} cells", m.cells());
        // The kept surface and its triangulation count too: at most one point per cell.
        let meshed = m.meshed_surface();
        assert!(meshed.points.len() <= m.cells());
    }
    // About 100 bytes a cell, and 150 more a column for the kept surface (table slots and
    // spare capacity included).
    assert!(m.cell_bytes() < 1_000 * 350, "{} bytes", m.cell_bytes());
    // The newest scan's cells are the ones kept.
    let newest = roof([39.0 * 0.5, 0.0, 0.0]);
    let f = m.fused([[19.5, 0.0], [29.5, 10.0]], landable);
    assert!(f.points.len() >= newest.len(), "{}", f.points.len());

    // Time: a cell not seen for longer than the horizon is forgotten.
    let mut m: FusionMap<u32> = FusionMap::new(params).unwrap();
    let old = roof([0.0; 3]);
    let classes = vec![ROOFTOP; old.len()];
    m.insert(scan(0.0, &old, &classes));
    let new = roof([12.0, 0.0, 0.0]);
    for k in 1..=30 {
        m.insert(scan(f64::from(k) * 0.1, &new, &classes));
    }
    assert_eq!(m.cells(), new.len());
}

#[test]
fn keep_out_memory_spreads_frames_over_the_approach() {
    let params = FusionParams {
        keep_out_frames: 4,
        keep_out_interval_s: 0.5,
        ..FusionParams::default()
    };
    let mut m: FusionMap<u32> = FusionMap::new(params).unwrap();
    let pts = roof([0.0; 3]);
    for k in 0..30u32 {
        let s = Scan {
            time_s: f64::from(k) * 0.1,
            points: &pts,
            keep_out: Some(k),
            ..Scan::new("d")
        };
        m.insert(s);
        let kept: Vec<u32> = m.keep_outs().copied().collect();
        assert_eq!(kept.last(), Some(&k), "the current frame is always kept");
        assert!(kept.len() <= 4);
        // Every kept frame but the newest is at least 0.5 s after the one before it.
        for w in kept[..kept.len() - 1].windows(2) {
            assert!(w[1] - w[0] >= 5, "{kept:?}");
        }
    }
    assert_eq!(m.keep_outs().len(), 4);
}

#[test]
fn bad_parameters_name_their_field() {
    let err = FusionMap::<u32>::new(FusionParams {
        cell_size_m: 0.0,
        ..FusionParams::default()
    })
    .unwrap_err();
    assert!(err.to_string().contains("cell_size_m"), "{err}");
    let err = FusionMap::<u32>::new(FusionParams {
        max_jump_m: f64::NAN,
        ..FusionParams::default()
    })
    .unwrap_err();
    assert!(err.to_string().contains("max_jump_m"), "{err}");
    let err = FusionMap::<u32>::new(FusionParams {
        max_pixel_footprint_m: -0.1,
        ..FusionParams::default()
    })
    .unwrap_err();
    assert_eq!(err.field(), "max_pixel_footprint_m");
}

proptest! {
    /// Wherever the world origin is (up to the API's 1e7 m), the map gives the same points,
    /// moved by the offset, and the same classes.
    #[test]
    fn results_do_not_depend_on_the_world_origin(
        ox in -1.0e7..1.0e7f64, oy in -1.0e7..1.0e7f64, oz in -1.0e3..1.0e3f64, frames in 1usize..6,
    ) {
        let run = |offset: [f64; 3]| {
            let mut m = map();
            for k in 0..frames {
                let pts = roof([offset[0] + k as f64 * 0.07, offset[1], offset[2]]);
                let mut classes = vec![ROOFTOP; pts.len()];
                classes[k * 13] = AC_UNIT;
                let s = Scan {
                    sensor: [offset[0] + 5.0, offset[1] - 20.0, offset[2] + 60.0],
                    ..scan(k as f64 * 0.1, &pts, &classes)
                };
                m.insert(s);
            }
            let b = [[offset[0] - 1.0, offset[1] - 1.0], [offset[0] + 12.0, offset[1] + 12.0]];
            m.fused(b, landable)
        };
        let here = run([0.0; 3]);
        let there = run([ox, oy, oz]);
        prop_assert_eq!(&here.classes, &there.classes);
        prop_assert_eq!(here.points.len(), there.points.len());
        for (a, b) in here.points.iter().zip(&there.points) {
            prop_assert!((a[0] + ox - b[0]).abs() < 1e-3);
            prop_assert!((a[1] + oy - b[1]).abs() < 1e-3);
            prop_assert!((a[2] + oz - b[2]).abs() < 1e-3);
        }
    }

    /// Arbitrary scans, classes and times never break the bounds, and answers stay in bounds.
    #[test]
    fn arbitrary_scans_keep_the_invariants(
        scans in prop::collection::vec(
            (prop::collection::vec((-50.0..50.0f64, -50.0..50.0f64, 0.0..40.0f64, 0u8..20), 0..300),
             0.0..0.3f64, any::<bool>()),
            1..12),
    ) {
        let params = FusionParams { max_cells: 1_000, ..FusionParams::default() };
        let mut m: FusionMap<u32> = FusionMap::new(params).unwrap();
        let mut t = 0.0;
        for (points, dt, reset) in &scans {
            t += dt;
            let pts: Vec<[f64; 3]> = points.iter().map(|p| [p.0, p.1, p.2]).collect();
            let classes: Vec<u8> = points.iter().map(|p| p.3).collect();
            m.insert(Scan { reset: *reset, ..scan(t, &pts, &classes) });
            prop_assert!(m.cells() <= 1_000);
            let f = m.fused([[-10.0, -10.0], [10.0, 10.0]], landable);
            prop_assert!(f.points.iter().all(|p| p[0].abs() <= 10.0 && p[1].abs() <= 10.0));
            prop_assert!(f.classes.as_ref().is_none_or(|c| c.len() == f.points.len()));
            prop_assert!(f.classes.as_ref().is_none_or(|c| c.iter().all(|&k| k < 16)));
        }
    }

    /// Placing a scan, then voting, is inserting it; the surface is final once the scan is
    /// placed (votes and views do not move it), so a caller can triangulate it meanwhile.
    #[test]
    fn placing_then_voting_is_inserting(
        scans in prop::collection::vec(
            (prop::collection::vec((-20.0..20.0f64, -20.0..20.0f64, 0.0..40.0f64, 0u8..20), 0..300),
             0.0..0.3f64, any::<bool>(), any::<bool>(), 0u8..3),
            1..10),
    ) {
        let params = FusionParams { max_cells: 1_000, ..FusionParams::default() };
        let mut inserted: FusionMap<u32> = FusionMap::new(params).unwrap();
        let mut split: FusionMap<u32> = FusionMap::new(params).unwrap();
        let fine = |p: &[f64; 3]| (p[0] < 0.0).then_some(0.1);
        let coarse = |p: &[f64; 3]| (p[1] < 5.0).then_some(0.5);
        let everything = [[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]];
        let mut t = 0.0;
        for (k, (points, dt, reset, classified, view)) in scans.iter().enumerate() {
            t += dt;
            let pts: Vec<[f64; 3]> = points.iter().map(|p| [p.0, p.1, p.2]).collect();
            let classes: Vec<u8> = points.iter().map(|p| p.3).collect();
            let s = Scan {
                reset: *reset,
                classes: classified.then_some(&classes[..]),
                view: match view {
                    0 => None,
                    1 => Some(View(&fine)),
                    _ => Some(View(&coarse)),
                },
                keep_out: Some(k as u32),
                ..scan(t, &pts, &classes)
            };
            let expected = inserted.insert(s.clone());
            let placed = split.place(&s);
            prop_assert_eq!(placed.reset(), expected.as_ref());
            let surface = split.surface(everything);
            prop_assert_eq!(split.vote(placed, s), expected);
            let want = inserted.fused(everything, landable);
            prop_assert_eq!(&surface.points, &want.points);
            let (classes, unresolved) = split.classes_of(&surface, landable);
            prop_assert_eq!(classes, want.classes);
            prop_assert_eq!(unresolved, want.unresolved);
            prop_assert!(split.keep_outs().eq(inserted.keep_outs()));
        }
    }
}

#[test]
fn the_origin_lies_among_the_first_scans_points_and_holds_until_a_reset() {
    // A cloud in world coordinates far from the world origin, with the sensor reported at 0.
    let far = roof([4.0e6, -3.0e6, 100.0]);
    let classes = vec![ROOFTOP; far.len()];
    let first = Scan {
        sensor: [0.0; 3],
        ..scan(0.0, &far, &classes)
    };
    let mut m = map();
    let origin = m.origin_for(&first);
    let centre = landing_fusion::centre(&far, [0.0; 3]);
    let cell = FusionParams::default().cell_size_m;
    assert!(
        (0..3).all(|i| (origin[i] - centre[i]).abs() <= cell / 2.0 + 1e-6),
        "{origin:?}"
    );
    m.insert(first.clone());
    let next = Scan {
        time_s: 0.1,
        ..first.clone()
    };
    assert_eq!(m.origin_for(&next), origin, "the map keeps its origin");
    let near = roof([0.0; 3]);
    let restart = Scan {
        reset: true,
        points: &near,
        ..next
    };
    let moved = m.origin_for(&restart);
    assert!(moved[0].abs() < 20.0 && moved[1].abs() < 20.0, "{moved:?}");
    assert!(landing_fusion::centre(&[], [1.0, 2.0, 3.0]) == [1.0, 2.0, 3.0]);
}

/// The meshed surface's points, sorted by position, against the surface's: the same columns.
fn sorted(points: &[[f64; 3]]) -> Vec<[u64; 3]> {
    let mut v: Vec<[u64; 3]> = points.iter().map(|p| p.map(f64::to_bits)).collect();
    v.sort_unstable();
    v
}

/// Checks a map's meshed surface against its surface and a fresh triangulation of its points.
fn check_meshed(m: &mut FusionMap<u32>, what: &str) -> Result<(), TestCaseError> {
    let everything = [[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]];
    let meshed = m.meshed_surface();
    let surface = m.surface(everything);
    prop_assert_eq!(
        sorted(&meshed.surface.points),
        sorted(&surface.points),
        "{}",
        what
    );
    prop_assert_eq!(meshed.points.len(), meshed.surface.points.len());
    let tri = meshed.triangulation.clone().unwrap();
    let xy: Vec<[f64; 2]> = meshed
        .points
        .iter()
        .map(|p| [f64::from(p[0]), f64::from(p[1])])
        .collect();
    if let Err(e) = tri.check_invariants(&xy, true) {
        return Err(TestCaseError::fail(format!("{what}: {e}")));
    }
    let fresh = landing_geometry::triangulate_points(&meshed.points).unwrap();
    prop_assert_eq!(tri.len(), fresh.len(), "{}: triangles", what);
    // The same classes as the surface's, point for point; and the kept ones the same, in order.
    let (classes, unresolved) = m.classes_of(&meshed.surface, landable);
    let kept = m.meshed_classes(landable);
    prop_assert_eq!(
        (&kept.0, &kept.1),
        (&classes, &unresolved),
        "{}: kept classes",
        what
    );
    let want = m.fused(everything, landable);
    let by_point = |pts: &[[f64; 3]], c: &Option<Vec<u8>>, u: &[bool]| {
        let mut v: Vec<([u64; 3], u8, bool)> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| (p.map(f64::to_bits), c.as_ref().map_or(0, |c| c[i]), u[i]))
            .collect();
        v.sort_unstable();
        v
    };
    prop_assert_eq!(
        by_point(&meshed.surface.points, &classes, &unresolved),
        by_point(&want.points, &want.classes, &want.unresolved)
    );
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The surface kept between scans is the surface read afresh, its kept triangulation a
    /// Delaunay triangulation of its points with the fresh one's triangle count, and its kept
    /// classes the ones read afresh, after every scan of random approaches (classes and views
    /// that change): the same roof scanned again and again (means moving, new
    /// columns at its edges, new tops on it), resets, time gaps past the horizon and a small
    /// cell bound that forgets cells.
    #[test]
    fn the_kept_surface_and_mesh_are_the_fresh_ones(
        seed in any::<u64>(),
        scans in prop::collection::vec((0.0..0.6f64, 0u8..20, 0.0..1.0f64), 1..25),
        max_cells in prop::sample::select(vec![1_000usize, 250_000]),
    ) {
        let params = FusionParams { max_cells, horizon_s: 2.0, ..FusionParams::default() };
        let mut m: FusionMap<u32> = FusionMap::new(params).unwrap();
        let mut g = landing_geometry::synthetic::Pcg32::new(seed);
        let mut t = 0.0;
        for (k, (dt, event, reach)) in scans.iter().enumerate() {
            t += dt;
            // A 12 m roof at 30 m with an AC unit, sampled anew each scan, reaching a little
            // farther or less far; sometimes a box on it (new tops) or ground around it.
            let n = 300 + (g.next_u32() % 700) as usize;
            let half = 3.0 + 3.0 * reach;
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|_| {
                    let (x, y) = (g.range(-half, half), g.range(-half, half));
                    let z = if x.abs() < 1.0 && y.abs() < 1.0 && *event % 3 == 0 {
                        31.2
                    } else if x.abs() > 5.0 {
                        0.02 * g.normal()
                    } else {
                        30.0 + 0.01 * g.normal()
                    };
                    [x, y, z]
                })
                .collect();
            // Votes that change cells' classes now and then, and views that resolve part of the
            // roof, finer or coarser than the rule.
            let classes: Vec<u8> = (0..n)
                .map(|_| if g.next_u32().is_multiple_of(5) { AC_UNIT } else { ROOFTOP })
                .collect();
            let max = FusionParams::default().max_pixel_footprint_m;
            let (edge, fine) = (g.range(-6.0, 6.0), *event % 2 == 0);
            let view = move |p: &[f64; 3]| (p[0] < edge).then_some(if fine { max } else { 2.0 * max });
            m.insert(Scan {
                reset: *event == 19,
                view: (*event % 4 != 3).then_some(View(&view)),
                ..scan(t, &pts, &classes)
            });
            check_meshed(&mut m, &format!("scan {k}"))?;
        }
    }
}

#[test]
fn the_kept_mesh_is_repaired_in_place_on_an_approach() {
    // A roof scanned at 10 Hz: after the first scan, updates are repaired in place, not
    // triangulated again (the speed of a fused frame rests on it).
    let mut m = map();
    let mut g = landing_geometry::synthetic::Pcg32::new(3);
    for k in 0..20 {
        let pts: Vec<[f64; 3]> = (0..1500)
            .map(|_| {
                [
                    g.range(-6.0, 6.0),
                    g.range(-6.0, 6.0),
                    30.0 + 0.01 * g.normal(),
                ]
            })
            .collect();
        let classes = vec![ROOFTOP; pts.len()];
        m.insert(scan(f64::from(k) * 0.1, &pts, &classes));
        let meshed = m.meshed_surface();
        assert!(meshed.triangulation.is_ok());
    }
    let stats = m.mesh_stats();
    assert_eq!(stats.rebuilt, 1, "{stats:?}");
    assert_eq!(stats.repaired, 19, "{stats:?}");
    assert!(stats.moved > 10_000, "{stats:?}");
}

#[test]
fn a_large_surface_gets_the_classes_its_parts_get() {
    // 12,100 columns, past the size whose cells are looked up on two threads, with classes and
    // fine views that vary from cell to cell; each quarter alone stays below that size.
    let side = 110;
    let points: Vec<[f64; 3]> = (0..side * side)
        .map(|i| {
            let (x, y) = (f64::from(i % side), f64::from(i / side));
            [x * 0.5 - 27.4, y * 0.5 - 27.3, 30.037]
        })
        .collect();
    let classes: Vec<u8> = (0..side * side)
        .map(|i| [ROOFTOP, AC_UNIT, 0, ROOFTOP, 11][(i as usize * 7 / 3) % 5])
        .collect();
    let fine = |p: &[f64; 3]| (p[0] < p[1]).then_some(0.1);
    let mut m = map();
    m.insert(Scan {
        view: Some(View(&fine)),
        ..scan(0.0, &points, &classes)
    });
    let by_point = |pts: &[[f64; 3]], classes: &[u8], unresolved: &[bool]| {
        let mut v: Vec<([u64; 3], u8, bool)> = (pts.iter().zip(classes).zip(unresolved))
            .map(|((p, &c), &u)| (p.map(f64::to_bits), c, u))
            .collect();
        v.sort_unstable();
        v
    };
    let everything = [[f64::NEG_INFINITY; 2], [f64::INFINITY; 2]];
    let whole = m.fused(everything, landable);
    assert_eq!(whole.points.len(), points.len());
    let mut parts = Vec::new();
    let (low, high) = ([-100.0, 0.0], [0.0, 100.0]);
    for (x, y) in [(low, low), (low, high), (high, low), (high, high)] {
        let bounds = [[x[0], y[0]], [x[1], y[1]]];
        let part = m.fused(bounds, landable);
        assert!(part.points.len() < 4000, "{} points", part.points.len());
        parts.extend(by_point(
            &part.points,
            &part.classes.unwrap(),
            &part.unresolved,
        ));
    }
    parts.sort_unstable();
    let whole = by_point(&whole.points, &whole.classes.unwrap(), &whole.unresolved);
    assert_eq!(whole, parts);
    assert!(whole.iter().any(|w| w.2) && whole.iter().any(|w| !w.2));
    assert!(
        whole
            .iter()
            .map(|w| w.1)
            .collect::<std::collections::HashSet<_>>()
            .len()
            >= 3
    );
}
