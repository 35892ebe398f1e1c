//! End-to-end `detect`: named regression scenes, degenerate input, and seeded property tests on
//! random roofs with obstacles, ground and walls.

use landing_geometry::synthetic::{Pcg32, Scene, SceneParams, SecondRoof, fuzz_detect_input};
use landing_geometry::triangulation::{self, EMPTY, Triangulation};
use landing_geometry::validation::{Location, check_detection, locate_in_ring};
use landing_geometry::{
    Cloud, CloudKind, Detection, Disk, GeometryError, KeepClear, KeepOut, Params, Polygon,
    SemanticClass, boundary, detect, filter, ranking, regions,
};

#[path = "support/spade.rs"]
mod spade;

/// `d` with its timings zeroed, for comparing detections.
fn without_timings(mut d: Detection) -> Detection {
    d.timings = Default::default();
    d
}

/// Runs `detect` and checks every invariant of the result.
fn run(points: &[[f32; 3]], classes: Option<&[u8]>, params: &Params) -> Detection {
    let d = detect(&Cloud::new(points, classes), params).expect("detect");
    check_detection(&d).expect("valid detection");
    d
}

/// Runs `detect` on a fused map's cells of `cell_size_m` and checks every invariant of the result.
fn run_fused(
    points: &[[f32; 3]],
    classes: Option<&[u8]>,
    cell_size_m: f64,
    params: &Params,
) -> Detection {
    let cloud = Cloud::new(points, classes).with_kind(CloudKind::FusedMap { cell_size_m });
    let d = detect(&cloud, params).expect("detect");
    check_detection(&d).expect("valid detection");
    d
}

fn scene(params: &SceneParams, seed: u64) -> (Scene, Detection) {
    let s = Scene::generate(params, seed);
    let d = run(&s.points, Some(&s.classes), &Params::default());
    (s, d)
}

fn strictly_inside(p: &Polygon, q: [f64; 2]) -> bool {
    locate_in_ring(&p.shell, q) == Location::Inside
        && p.holes
            .iter()
            .all(|h| locate_in_ring(h, q) == Location::Outside)
}

/// A triangular lattice (unique Delaunay triangulation: no four points are cocircular) of flat
/// roof points; `obstacles` are (column, row) of points classed as AC units.
fn lattice(cols: usize, rows: usize, obstacles: &[(usize, usize)]) -> (Vec<[f32; 3]>, Vec<u8>) {
    let h = 3f64.sqrt() / 2.0;
    let mut pts = Vec::new();
    let mut classes = Vec::new();
    for j in 0..rows {
        for i in 0..cols {
            let x = i as f64 + 0.5 * (j % 2) as f64;
            pts.push([x as f32, (j as f64 * h) as f32, 10.0]);
            let c = if obstacles.contains(&(i, j)) {
                SemanticClass::AcUnit
            } else {
                SemanticClass::BuildingRooftop
            };
            classes.push(c as u8);
        }
    }
    (pts, classes)
}

fn lattice_xy(i: usize, j: usize) -> [f64; 2] {
    let h = 3f64.sqrt() / 2.0;
    [
        f64::from((i as f64 + 0.5 * (j % 2) as f64) as f32),
        f64::from((j as f64 * h) as f32),
    ]
}

#[test]
fn hole_touching_the_shell_at_one_vertex() {
    // (5, 1) cuts a notch into the bottom edge; (6, 3) makes a hole whose corner (6, 2) is also a
    // corner of the notch.
    let (pts, classes) = lattice(12, 12, &[(5, 1), (6, 3)]);
    let d = run(&pts, Some(&classes), &Params::default());
    assert_eq!(d.sites.len(), 1);
    let p = &d.sites[0].polygon;
    assert_eq!(p.holes.len(), 1, "{p:?}");
    let touch = lattice_xy(6, 2);
    assert!(p.shell.contains(&touch) && p.holes[0].contains(&touch));
    assert_eq!(p.holes[0].len(), 6);
}

#[test]
fn two_holes_touching() {
    let (pts, classes) = lattice(12, 12, &[(3, 5), (5, 5)]);
    let d = run(&pts, Some(&classes), &Params::default());
    assert_eq!(d.sites.len(), 1);
    let p = &d.sites[0].polygon;
    assert_eq!(p.holes.len(), 2, "{p:?}");
    let touch = lattice_xy(4, 5);
    assert!(p.holes.iter().all(|h| h.contains(&touch) && h.len() == 6));
    assert!(!p.shell.contains(&touch));
}

#[test]
fn two_roofs_at_different_heights_side_by_side() {
    for gap in [0.0, 3.0] {
        let params = SceneParams {
            point_count: 3000,
            second_roof: Some(SecondRoof {
                size_m: [15.0, 20.0],
                height_m: 14.0,
                gap_m: gap,
            }),
            obstacles: 0,
            ..SceneParams::default()
        };
        let (_, d) = scene(&params, 5);
        assert_eq!(d.sites.len(), 2, "gap {gap}");
        let mut heights: Vec<f64> = d.sites.iter().map(|s| s.plane_height_m).collect();
        heights.sort_by(f64::total_cmp);
        assert!(
            (heights[0] - 10.0).abs() < 0.05 && (heights[1] - 14.0).abs() < 0.05,
            "{heights:?}"
        );
        // The wider roof ranks first.
        assert!((d.sites[0].plane_height_m - 10.0).abs() < 0.05);
    }
}

#[test]
fn sloped_roof_is_rejected_by_dot_min() {
    // dz/dx = 0.5: |n·k| = 0.89 < 0.96.
    let params = SceneParams {
        roof_slope: 0.5,
        obstacles: 0,
        ..SceneParams::default()
    };
    let (_, d) = scene(&params, 2);
    assert!(
        d.sites.is_empty(),
        "{:?}",
        d.sites.iter().map(|s| s.plane_height_m).collect::<Vec<_>>()
    );
    // A gentle slope (dz/dx = 0.1, |n·k| = 0.995) is landable.
    let params = SceneParams {
        roof_slope: 0.1,
        obstacles: 0,
        ..SceneParams::default()
    };
    let (_, d) = scene(&params, 2);
    assert_eq!(d.sites.len(), 1);
    let n = d.sites[0].normal;
    assert!((n[0] + 0.1 / 1.01f64.sqrt()).abs() < 0.01, "{n:?}");
}

#[test]
fn courtyard_becomes_a_hole() {
    let params = SceneParams {
        roof_size_m: [24.0, 24.0],
        courtyard_m: Some([8.0, 8.0]),
        obstacles: 0,
        point_count: 3000,
        ..SceneParams::default()
    };
    let (_, d) = scene(&params, 11);
    assert_eq!(d.sites.len(), 1);
    let site = &d.sites[0];
    assert_eq!(site.polygon.holes.len(), 1);
    assert_eq!(
        locate_in_ring(&site.polygon.holes[0], [12.0, 12.0]),
        Location::Inside
    );
    // The best circle sits in a corner strip: about (24 - 8) / 4 = 4 m from the walls.
    assert!(
        site.safe_radius_m > 3.0 && site.safe_radius_m < 5.5,
        "{}",
        site.safe_radius_m
    );
    assert!(site.area_m2 > 0.8 * (24.0 * 24.0 - 64.0) && site.area_m2 < 24.0 * 24.0 - 64.0);
}

#[test]
fn without_classes_obstacle_tops_are_their_own_sites() {
    let params = SceneParams {
        obstacles: 2,
        obstacle_side_m: [2.5, 3.0],
        ..SceneParams::default()
    };
    let s = Scene::generate(&params, 4);
    let d = run(&s.points, None, &Params::default());
    // Ground, roof and the flat tops are all candidates; the roof has the largest circle.
    assert!((d.sites[0].plane_height_m - 10.0).abs() < 0.05);
    for o in &s.truth.obstacles {
        let c = [(o.min[0] + o.max[0]) / 2.0, (o.min[1] + o.max[1]) / 2.0];
        assert!(
            !strictly_inside(&d.sites[0].polygon, c),
            "obstacle {o:?} inside the roof site"
        );
    }
}

#[test]
fn degenerate_inputs_give_empty_results_or_typed_errors() {
    let p = Params::default();
    assert!(run(&[], None, &p).sites.is_empty());
    assert!(run(&[[0.0, 0.0, 0.0]], None, &p).sites.is_empty());
    assert!(
        run(&[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]], None, &p)
            .sites
            .is_empty()
    );
    let line: Vec<[f32; 3]> = (0..100).map(|i| [i as f32, 0.5 * i as f32, 0.0]).collect();
    let d = run(&line, None, &p);
    assert!(d.sites.is_empty() && d.triangle_count == 0 && d.point_count == 100);
    assert!(run(&vec![[1.0, 2.0, 3.0]; 1000], None, &p).sites.is_empty());

    let mut bad = vec![[0.0f32, 0.0, 0.0]; 10];
    bad[7][2] = f32::NAN;
    assert!(matches!(
        detect(&Cloud::new(&bad, None), &p),
        Err(GeometryError::InvalidPoint { index: 7, .. })
    ));
    bad[7] = [f32::INFINITY, 0.0, 0.0];
    assert!(matches!(
        detect(&Cloud::new(&bad, None), &p),
        Err(GeometryError::InvalidPoint { index: 7, .. })
    ));
    bad[7] = [0.0, -2e7, 0.0];
    assert!(matches!(
        detect(&Cloud::new(&bad, None), &p),
        Err(GeometryError::InvalidPoint { index: 7, .. })
    ));
    bad[7] = [0.0, 0.0, 0.0];
    assert!(matches!(
        detect(&Cloud::new(&bad, Some(&[4; 9])), &p),
        Err(GeometryError::ClassCountMismatch {
            points: 10,
            classes: 9
        })
    ));
}

#[test]
fn parameters_are_validated_with_field_names() {
    let cases: Vec<(&str, Params)> = vec![
        (
            "max_triangle_edge_m",
            Params {
                max_triangle_edge_m: 0.0,
                ..Params::default()
            },
        ),
        (
            "max_triangle_edge_m",
            Params {
                max_triangle_edge_m: f64::NAN,
                ..Params::default()
            },
        ),
        (
            "min_normal_dot",
            Params {
                min_normal_dot: 1.0,
                ..Params::default()
            },
        ),
        (
            "min_normal_dot",
            Params {
                min_normal_dot: -0.1,
                ..Params::default()
            },
        ),
        (
            "max_triangle_height_m",
            Params {
                max_triangle_height_m: -1.0,
                ..Params::default()
            },
        ),
        (
            "landable_classes",
            Params {
                landable_classes: vec![4, 15],
                ..Params::default()
            },
        ),
        (
            "polylabel_precision_m",
            Params {
                polylabel_precision_m: 0.0,
                ..Params::default()
            },
        ),
        (
            "polylabel_precision_m",
            Params {
                polylabel_precision_m: 1e-9,
                ..Params::default()
            },
        ),
        (
            "min_safe_radius_m",
            Params {
                min_safe_radius_m: f64::INFINITY,
                ..Params::default()
            },
        ),
        (
            "min_area_m2",
            Params {
                min_area_m2: -1.0,
                ..Params::default()
            },
        ),
        (
            "min_hole_area_m2",
            Params {
                min_hole_area_m2: f64::NAN,
                ..Params::default()
            },
        ),
        (
            "max_sites",
            Params {
                max_sites: 0,
                ..Params::default()
            },
        ),
    ];
    for (field, params) in cases {
        match detect(&Cloud::new(&[], None), &params) {
            Err(GeometryError::InvalidParameter { field: f, .. }) => {
                assert_eq!(f, field);
            }
            other => panic!("{field}: {other:?}"),
        }
    }
    Params::default().validate().unwrap();
}

/// A fused map's cell size is checked too, by name.
#[test]
fn fused_map_cell_sizes_out_of_range_are_refused_by_name() {
    for cell_size_m in [f64::INFINITY, f64::NAN, -0.3, 0.0] {
        let cloud = Cloud::new(&[], None).with_kind(CloudKind::FusedMap { cell_size_m });
        match detect(&cloud, &Params::default()) {
            Err(GeometryError::InvalidParameter { field: f, .. }) => assert_eq!(f, "cell_size_m"),
            other => panic!("{cell_size_m}: {other:?}"),
        }
    }
}

#[test]
fn filters_and_limits() {
    let params = SceneParams {
        second_roof: Some(SecondRoof {
            size_m: [8.0, 8.0],
            height_m: 13.0,
            gap_m: 2.0,
        }),
        point_count: 3000,
        ..SceneParams::default()
    };
    let s = Scene::generate(&params, 8);
    let all = run(&s.points, Some(&s.classes), &Params::default());
    assert!(all.sites.len() >= 2);
    let one = run(
        &s.points,
        Some(&s.classes),
        &Params {
            max_sites: 1,
            ..Params::default()
        },
    );
    assert_eq!(one.sites.len(), 1);
    assert_eq!(one.sites[0], all.sites[0]);
    let r = all.sites[1].safe_radius_m;
    let big = run(
        &s.points,
        Some(&s.classes),
        &Params {
            min_safe_radius_m: r + 0.01,
            ..Params::default()
        },
    );
    assert_eq!(big.sites.len(), 1);
    let a = all.sites[0].area_m2;
    let none = run(
        &s.points,
        Some(&s.classes),
        &Params {
            min_area_m2: a + 1.0,
            ..Params::default()
        },
    );
    assert!(none.sites.is_empty());
    // Dropping every hole gives a polygon without holes and a radius at least as large.
    let no_holes = run(
        &s.points,
        Some(&s.classes),
        &Params {
            min_hole_area_m2: 1e6,
            ..Params::default()
        },
    );
    assert!(no_holes.sites.iter().all(|s| s.polygon.holes.is_empty()));
    assert!(no_holes.sites[0].safe_radius_m >= all.sites[0].safe_radius_m - 0.5);
}

#[test]
fn results_are_deterministic_and_triangulator_independent() {
    let params = SceneParams {
        obstacles: 5,
        point_count: 4000,
        ..SceneParams::default()
    };
    let s = Scene::generate(&params, 21);
    let a = without_timings(
        detect(&Cloud::new(&s.points, Some(&s.classes)), &Params::default()).unwrap(),
    );
    let b = without_timings(
        detect(&Cloud::new(&s.points, Some(&s.classes)), &Params::default()).unwrap(),
    );
    assert_eq!(a, b);
    let pts: Vec<[f64; 3]> = s.points.iter().map(|p| p.map(f64::from)).collect();
    let spade = spade::triangulate_spade(&pts);
    let cloud = Cloud::new(&s.points, Some(&s.classes)).with_triangulation(&spade);
    let c = without_timings(detect(&cloud, &Params::default()).unwrap());
    // Jittered points are in general position: the same Delaunay triangulation, so the same
    // polygons (canonical rings) and radii, whatever the triangle numbering.
    assert_eq!(a.triangle_count, c.triangle_count);
    assert_eq!(a.sites.len(), c.sites.len());
    for (x, y) in a.sites.iter().zip(&c.sites) {
        assert_eq!(x.polygon, y.polygon);
        assert_eq!(x.safe_radius_m, y.safe_radius_m);
    }
}

#[test]
fn a_triangulation_made_beforehand_gives_the_same_detection() {
    let params = SceneParams {
        obstacles: 5,
        point_count: 4000,
        ..SceneParams::default()
    };
    let s = Scene::generate(&params, 22);
    let vent = |point: [f64; 3], _normal: [f64; 3], _bounds: [f64; 4]| {
        vec![Disk {
            center: [point[0] + 1.0, point[1]],
            radius: 0.4,
        }]
    };
    let flags: Vec<bool> = (0..s.points.len()).map(|i| i % 97 == 0).collect();
    let keep_clear = || KeepClear {
        disks: Some(&vent),
        points: Some(&flags),
    };
    let params = Params::default();
    let made = without_timings(
        detect(
            &Cloud::new(&s.points, Some(&s.classes)).with_keep_clear(keep_clear()),
            &params,
        )
        .unwrap(),
    );
    let tri = landing_geometry::triangulate_points(&s.points).unwrap();
    let cloud = Cloud::new(&s.points, Some(&s.classes))
        .with_keep_clear(keep_clear())
        .with_triangulation(&tri);
    let given = without_timings(detect(&cloud, &params).unwrap());
    assert!(!made.sites.is_empty());
    assert_eq!(made, given);
    // A triangulation of other points is refused, not indexed out of bounds.
    let few = &s.points[..s.points.len() / 2];
    let err = detect(&Cloud::new(few, None).with_triangulation(&tri), &params);
    assert!(
        matches!(err, Err(GeometryError::InvalidMesh { .. })),
        "{err:?}"
    );
}

/// Largest signed distance on a grid of step `step` over the polygon's bounding box.
fn grid_optimum(p: &Polygon, step: f64) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for q in &p.shell {
        lo = [lo[0].min(q[0]), lo[1].min(q[1])];
        hi = [hi[0].max(q[0]), hi[1].max(q[1])];
    }
    let mut best = f64::NEG_INFINITY;
    let mut x = lo[0];
    while x <= hi[0] {
        let mut y = lo[1];
        while y <= hi[1] {
            best = best.max(p.signed_distance([x, y]));
            y += step;
        }
        x += step;
    }
    best
}

#[test]
fn property_random_roofs_with_obstacles() {
    let mut g = Pcg32::new(2024);
    for case in 0..24u64 {
        let params = SceneParams {
            point_count: 800 + (g.next_u32() % 2500) as usize,
            roof_size_m: [g.range(10.0, 30.0), g.range(10.0, 30.0)],
            roof_height_m: g.range(3.0, 40.0),
            obstacles: (g.next_u32() % 7) as usize,
            courtyard_m: (case % 5 == 0).then_some([4.0, 3.0]),
            second_roof: (case % 4 == 1).then_some(SecondRoof {
                size_m: [g.range(6.0, 15.0), g.range(6.0, 15.0)],
                height_m: g.range(3.0, 40.0),
                gap_m: g.range(0.0, 4.0),
            }),
            noise_m: g.range(0.0, 0.02),
            ..SceneParams::default()
        };
        let (s, d) = scene(&params, case);
        assert!(!d.sites.is_empty(), "case {case}: no site on {params:?}");
        let precision = Params::default().polylabel_precision_m;
        let obstacle_points: Vec<[f64; 2]> = s
            .obstacle_points()
            .map(|i| [f64::from(s.points[i][0]), f64::from(s.points[i][1])])
            .collect();
        for site in &d.sites {
            let p = &site.polygon;
            let c = [site.center[0], site.center[1]];
            for &q in &obstacle_points {
                assert!(
                    !strictly_inside(p, q),
                    "case {case}: obstacle point {q:?} inside a site"
                );
                let dist = (q[0] - c[0]).hypot(q[1] - c[1]);
                assert!(
                    dist >= site.safe_radius_m - 1e-9,
                    "case {case}: obstacle point in circle"
                );
            }
            // The sampled boundary lies between roof and obstacle samples, so the true box edge
            // can be up to one point spacing inside the circle; never more.
            for o in &s.truth.obstacles {
                let dist = o.distance(c[0], c[1]);
                assert!(
                    dist >= site.safe_radius_m - s.spacing_m,
                    "case {case}: box {o:?}"
                );
            }
            let step = 0.2;
            let best = grid_optimum(p, step);
            assert!(
                site.safe_radius_m >= best - precision - 1e-9,
                "case {case}: {} vs grid {best}",
                site.safe_radius_m
            );
            assert!(
                site.safe_radius_m <= best + step * 0.7072,
                "case {case}: {} vs grid {best}",
                site.safe_radius_m
            );
        }
    }
}

#[test]
fn keep_out_disks_move_the_safe_circle_off_obstacles_the_points_missed() {
    // A flat 20 m roof at 10 m with no obstacle point: the best circle is central.
    let (pts, classes) = lattice(21, 24, &[]);
    let plain = run(&pts, Some(&classes), &Params::default());
    let c = plain.sites[0].center;
    // The camera saw a 1 m vent right there: a keep-out disk on the roof plane.
    let vent = Disk {
        center: [c[0], c[1]],
        radius: 0.5,
    };
    let planes = std::cell::RefCell::new(Vec::new());
    let keep_out = |point: [f64; 3], normal: [f64; 3], _bounds: [f64; 4]| {
        planes.borrow_mut().push((point, normal));
        vec![vent]
    };
    let keep_clear = KeepClear {
        disks: Some(&keep_out),
        points: None,
    };
    let d = detect(
        &Cloud::new(&pts, Some(&classes)).with_keep_clear(keep_clear),
        &Params::default(),
    )
    .expect("detect");
    check_detection(&d).expect("valid detection");
    let (point, normal) = planes.borrow()[0];
    assert!(
        (point[2] - 10.0).abs() < 1e-6 && normal[2] > 0.999,
        "the roof's plane"
    );
    let s = &d.sites[0];
    let clear = (s.center[0] - c[0]).hypot(s.center[1] - c[1]) - vent.radius;
    assert!(
        clear >= s.safe_radius_m - 1e-9,
        "the circle reaches into the vent: {s:?}"
    );
    assert!(s.safe_radius_m < plain.sites[0].safe_radius_m);
    assert!(
        s.polygon.signed_distance([s.center[0], s.center[1]]) >= s.safe_radius_m - 1e-9,
        "and stays inside the polygon"
    );
}

#[test]
fn keep_out_disks_bound_circles_only_over_gaps_in_dense_points() {
    // A flat roof on a unit lattice (edges 1 m), with a gap of radius 1.6 m where an obstacle
    // stands that no point hit: the triangles across it have edges over 2 m.
    let (cols, rows) = (21, 24);
    let (full_pts, full_classes) = lattice(cols, rows, &[]);
    let gap = lattice_xy(6, 12);
    let keep: Vec<bool> = (0..full_pts.len())
        .map(|k| {
            let v = lattice_xy(k % cols, k / cols);
            (v[0] - gap[0]).hypot(v[1] - gap[1]) > 1.6
        })
        .collect();
    let pick = |all: &[[f32; 3]]| -> Vec<[f32; 3]> {
        all.iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(p, _)| *p)
            .collect()
    };
    let pts = pick(&full_pts);
    let classes: Vec<u8> = full_classes
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(c, _)| *c)
        .collect();
    // The camera saw the obstacle in the gap, and something at the centre of dense points.
    let in_gap = Disk {
        center: gap,
        radius: 0.8,
    };
    let plain = run(&pts, Some(&classes), &Params::default());
    let c = plain.sites[0].center;
    let on_points = Disk {
        center: [c[0], c[1]],
        radius: 0.5,
    };
    // The lattice's points are all roof, and no triangle of it is steep: a fused map's pinholes
    // and midpoint edges change nothing here, only which disks count.
    let with = |disks: Vec<Disk>, kind: CloudKind| {
        let keep_out = move |_: [f64; 3], _: [f64; 3], _: [f64; 4]| disks.clone();
        let keep_clear = KeepClear {
            disks: Some(&keep_out),
            points: None,
        };
        let cloud = Cloud::new(&pts, Some(&classes))
            .with_keep_clear(keep_clear)
            .with_kind(kind);
        let d = detect(&cloud, &Params::default()).expect("detect");
        check_detection(&d).expect("valid detection");
        d
    };
    let clear_of = |d: &Detection, disk: &Disk| {
        let s = &d.sites[0];
        (s.center[0] - disk.center[0]).hypot(s.center[1] - disk.center[1]) - disk.radius
            >= s.safe_radius_m - 1e-9
    };
    // Every disk counts in a scan: the circle leaves the centre.
    let scan = CloudKind::Scan;
    let every = with(vec![in_gap, on_points], scan);
    assert!(clear_of(&every, &on_points) && clear_of(&every, &in_gap));
    assert!(every.sites[0].safe_radius_m < plain.sites[0].safe_radius_m);
    // Trusting edges of up to 1.5 m (two cells of 0.75 m), the disk on dense points bounds
    // nothing; the one in the gap still does.
    let trusted = with(
        vec![in_gap, on_points],
        CloudKind::FusedMap { cell_size_m: 0.75 },
    );
    assert_eq!(trusted.sites, with(vec![in_gap], scan).sites);
    assert!(clear_of(&trusted, &in_gap));
    assert!(trusted.sites[0].safe_radius_m > every.sites[0].safe_radius_m);
    // Trusting edges as long as the gap's, no disk bounds anything: the limit must stay below
    // the gaps an obstacle leaves.
    let wide = CloudKind::FusedMap { cell_size_m: 2.0 };
    assert_eq!(with(vec![in_gap, on_points], wide).sites, plain.sites);
}

#[test]
fn safe_circles_keep_off_the_triangles_of_flagged_points() {
    // A flat roof of about 20 x 20 m on a unit triangular lattice: each point's triangles cover
    // the disk of the triangles' height around it.
    let (cols, rows) = (21, 24);
    let star = 3f64.sqrt() / 2.0;
    let (pts, classes) = lattice(cols, rows, &[]);
    let plain = run(&pts, Some(&classes), &Params::default());
    let with = |flagged: &dyn Fn(usize, usize) -> bool| {
        let flags: Vec<bool> = (0..rows)
            .flat_map(|j| (0..cols).map(move |i| (i, j)))
            .map(|(i, j)| flagged(i, j))
            .collect();
        let keep_clear = KeepClear {
            disks: None,
            points: Some(&flags),
        };
        let d = detect(
            &Cloud::new(&pts, Some(&classes)).with_keep_clear(keep_clear),
            &Params::default(),
        )
        .expect("detect");
        check_detection(&d).expect("valid detection");
        for s in &d.sites {
            assert_eq!(
                s.polygon, plain.sites[0].polygon,
                "the polygon keeps every triangle"
            );
            for (k, _) in flags.iter().enumerate().filter(|(_, f)| **f) {
                let v = lattice_xy(k % cols, k / cols);
                let dist = (s.center[0] - v[0]).hypot(s.center[1] - v[1]);
                assert!(
                    dist >= s.safe_radius_m + star - 1e-6,
                    "the circle {s:?} reaches the triangles of {v:?}"
                );
            }
        }
        d
    };
    let full = plain.sites[0].safe_radius_m;
    // One flagged point at the centre, where the plain circle sits.
    let one = with(&|i, j| (i, j) == (10, 12));
    assert!(one.sites[0].safe_radius_m < full);
    // The left 8 columns flagged: the circle fits in the other 12 m.
    let left = with(&|i, _| i < 8);
    let r = left.sites[0].safe_radius_m;
    assert!(r < full && r > 4.5, "{r} against {full}");
    // A band across the middle cuts the roof in two parts; the circle is in one of them.
    let band = with(&|_, j| (10..=13).contains(&j));
    let r = band.sites[0].safe_radius_m;
    assert!(r > 3.0 && r < left.sites[0].safe_radius_m, "{r}");
    // Everything flagged: no site; nothing flagged: as without flags.
    assert!(with(&|_, _| true).sites.is_empty());
    assert_eq!(with(&|_, _| false).sites, plain.sites);
    // One flag per point, or an error that says so.
    let short = vec![false; pts.len() - 1];
    let keep_clear = KeepClear {
        disks: None,
        points: Some(&short),
    };
    assert_eq!(
        detect(
            &Cloud::new(&pts, Some(&classes)).with_keep_clear(keep_clear),
            &Params::default()
        )
        .unwrap_err(),
        GeometryError::FlagCountMismatch {
            points: pts.len(),
            flags: pts.len() - 1
        }
    );
}

/// Distance from `p` to the triangle `t` (0 inside).
fn triangle_distance(p: [f64; 2], t: [[f64; 2]; 3]) -> f64 {
    let triangle = Polygon {
        shell: t.to_vec(),
        holes: Vec::new(),
    };
    (-triangle.signed_distance(p)).max(0.0)
}

/// On random roofs, with scattered flags, flagged patches and flagged bands: every safe circle
/// stays off every triangle with a flagged vertex, and every site's polygon is one the same
/// roof gives without flags.
#[test]
fn property_flagged_points_keep_circles_off_their_triangles() {
    let mut g = Pcg32::new(77);
    let (mut sites, mut cut) = (0, 0);
    for case in 0..24u64 {
        let params = SceneParams {
            point_count: 800 + (g.next_u32() % 2500) as usize,
            roof_size_m: [g.range(10.0, 30.0), g.range(10.0, 30.0)],
            obstacles: (g.next_u32() % 5) as usize,
            second_roof: (case % 3 == 1).then_some(SecondRoof {
                size_m: [g.range(6.0, 15.0), g.range(6.0, 15.0)],
                height_m: g.range(3.0, 40.0),
                gap_m: g.range(0.0, 4.0),
            }),
            ..SceneParams::default()
        };
        let (s, plain) = scene(&params, case);
        let xy = |i: usize| [f64::from(s.points[i][0]), f64::from(s.points[i][1])];
        let (cx, cy, r) = (
            g.range(-10.0, 10.0),
            g.range(-10.0, 10.0),
            g.range(1.0, 6.0),
        );
        let rate = g.range(0.0, 0.05);
        let flags: Vec<bool> = (0..s.points.len())
            .map(|i| match case % 3 {
                0 => g.unit() < rate,
                1 => (xy(i)[0] - cx).hypot(xy(i)[1] - cy) < r,
                _ => (xy(i)[1] - cy).abs() < r / 4.0,
            })
            .collect();
        let keep_clear = KeepClear {
            disks: None,
            points: Some(&flags),
        };
        let d = detect(
            &Cloud::new(&s.points, Some(&s.classes)).with_keep_clear(keep_clear),
            &Params::default(),
        )
        .expect("detect");
        check_detection(&d).expect("valid detection");
        let pts: Vec<[f64; 3]> = s.points.iter().map(|p| p.map(f64::from)).collect();
        let tri = landing_geometry::triangulation::triangulate(&pts).expect("triangulate");
        let flagged: Vec<[[f64; 2]; 3]> = tri
            .triangles
            .chunks_exact(3)
            .filter(|t| t.iter().any(|&v| flags[v as usize]))
            .map(|t| [xy(t[0] as usize), xy(t[1] as usize), xy(t[2] as usize)])
            .collect();
        for site in &d.sites {
            assert!(
                plain.sites.iter().any(|p| p.polygon == site.polygon),
                "case {case}: a polygon the roof does not give without flags"
            );
            let c = [site.center[0], site.center[1]];
            for t in &flagged {
                assert!(
                    triangle_distance(c, *t) >= site.safe_radius_m - 1e-9,
                    "case {case}: the circle {site:?} reaches the flagged triangle {t:?}"
                );
            }
        }
        sites += d.sites.len();
        cut += usize::from(
            d.sites.len() < plain.sites.len()
                || d.sites
                    .iter()
                    .zip(&plain.sites)
                    .any(|(a, b)| a.safe_radius_m < b.safe_radius_m),
        );
    }
    assert!(
        sites > 10 && cut > 10,
        "{sites} sites, {cut} cases where flags cut a circle"
    );
}

/// Found by the `detect` fuzz target (RELIABILITY.md): a real hole of about 1e-31 m² whose
/// vertices mix x of 1e-41 and 1e-23 m. Its shoelace area rounds to 0, and the validity check
/// used to call it a zero-area ring; the check is exact now.
#[test]
fn fuzz_regression_tiny_hole_is_valid() {
    let input = fuzz_detect_input(include_bytes!("data/fuzz-detect-zero-area-hole.bin"), 512)
        .expect("parameter bytes");
    let d = run(&input.points, input.classes.as_deref(), &input.params);
    assert_eq!(d.sites.len(), 1);
    assert_eq!(d.sites[0].polygon.holes.len(), 2, "both holes kept");
}

/// Dense, noisy roofs, as a fused map's cells are (points about 0.18 m apart, 2.5 cm of range
/// noise): the noise tilts short triangles past `min_normal_dot`, and the pinholes it punches hold no
/// point. As a fused map (pinholes closed, `regions::close_pinholes`) every hole left holds a point
/// of the cloud, and no obstacle point is inside a site; as a single scan some of the pinholes
/// stay.
#[test]
fn property_dense_noisy_roofs_lose_their_pinholes_not_their_obstacles() {
    let mut g = Pcg32::new(77);
    let mut pinholes_left_open = 0;
    for case in 0..6u64 {
        let params = SceneParams {
            point_count: 12_000,
            roof_size_m: [12.0, 12.0],
            roof_height_m: g.range(3.0, 40.0),
            obstacles: 1 + (g.next_u32() % 4) as usize,
            noise_m: 0.025,
            ..SceneParams::default()
        };
        let s = Scene::generate(&params, case);
        let xy = |i: usize| [f64::from(s.points[i][0]), f64::from(s.points[i][1])];
        let empty_holes = |d: &Detection| {
            d.sites
                .iter()
                .flat_map(|site| &site.polygon.holes)
                .filter(|hole| {
                    !(0..s.points.len()).any(|i| locate_in_ring(hole, xy(i)) == Location::Inside)
                })
                .count()
        };
        pinholes_left_open += empty_holes(&run(&s.points, Some(&s.classes), &Params::default()));
        let d = run_fused(&s.points, Some(&s.classes), s.spacing_m, &Params::default());
        assert!(!d.sites.is_empty(), "case {case}");
        assert_eq!(empty_holes(&d), 0, "case {case}: a hole holds no point");
        for site in &d.sites {
            for i in s.obstacle_points() {
                assert!(!strictly_inside(&site.polygon, xy(i)), "case {case}");
            }
        }
    }
    assert!(pinholes_left_open > 0, "the scenes have pinholes to close");
}

/// A lone obstacle point in a lattice roof: its hole is the hexagon of its six neighbours, the
/// triangles that touch it. As a fused map's cells (midpoint edges of two cells; the lattice has
/// no pinhole) the hole runs through the midpoints between the obstacle and each neighbour
/// instead (the two detours of each pair of neighbouring triangles meet there), and the safe
/// circle does not move.
#[test]
fn an_obstacle_hole_ends_halfway_to_the_obstacle_and_the_circle_stays() {
    let (pts, classes) = lattice(12, 12, &[(5, 5)]);
    let plain = run(&pts, Some(&classes), &Params::default());
    let grown = run_fused(&pts, Some(&classes), 0.75, &Params::default());
    assert_eq!(plain.sites.len(), 1);
    assert_eq!(grown.sites.len(), 1);
    let (p, g) = (&plain.sites[0], &grown.sites[0]);
    assert_eq!((p.center, p.safe_radius_m), (g.center, g.safe_radius_m));
    // The lattice's hull has no triangle outside it: the shell stays.
    assert_eq!(p.polygon.shell, g.polygon.shell);
    assert_eq!(p.polygon.holes[0].len(), 6);
    assert_eq!(g.polygon.holes.len(), 1);
    let hole = &g.polygon.holes[0];
    assert_eq!(hole.len(), 6, "{hole:?}");
    let o = lattice_xy(5, 5);
    for v in hole {
        let d = (v[0] - o[0]).hypot(v[1] - o[1]);
        assert!((d - 0.5).abs() < 1e-6, "{v:?} is {d} m from the obstacle");
    }
    // The hexagon of side 1 becomes the hexagon of side 0.5: a quarter of its area.
    let hexagon = 3.0 * 3f64.sqrt() / 2.0;
    assert!((g.area_m2 - (p.area_m2 + 0.75 * hexagon)).abs() < 1e-4);
    // Beyond the limit nothing moves.
    let short = run_fused(&pts, Some(&classes), 0.45, &Params::default());
    assert_eq!(short.sites[0].polygon, p.polygon);
}

/// Dense, noisy roofs with obstacles and walls, as a fused map's cells are: with midpoint edges
/// every site keeps its circle, its polygon stays valid and holds the polygon of its own points,
/// reaches at most half the limit beyond it, and holds no obstacle point. Without them (the same
/// steps by hand, pinholes closed) the polygons are smaller (so the test can fail).
#[test]
fn property_midpoint_edges_grow_polygons_not_circles() {
    let mut g = Pcg32::new(91);
    let max_edge = 0.5;
    let geometry = Params::default();
    let mut grown_by = 0.0;
    for case in 0..6u64 {
        let params = SceneParams {
            point_count: 10_000,
            roof_size_m: [12.0, 12.0],
            roof_height_m: g.range(3.0, 40.0),
            obstacles: 1 + (g.next_u32() % 4) as usize,
            noise_m: 0.01,
            ..SceneParams::default()
        };
        let s = Scene::generate(&params, case);
        let xy = |i: usize| [f64::from(s.points[i][0]), f64::from(s.points[i][1])];
        let plain = sites_with_pinholes_closed(&s.points, Some(&s.classes), &geometry, None);
        let grown = run_fused(&s.points, Some(&s.classes), max_edge / 2.0, &geometry);
        assert!(!plain.sites.is_empty(), "case {case}");
        // Every region's grown polygon is valid as built: `detect`'s fallback to the polygon of
        // the region's own points is never needed here.
        let (tri, pts, regions) =
            regions_with_pinholes_closed(&s.points, Some(&s.classes), &geometry);
        let grow = boundary::BoundaryParams {
            midpoint_max_edge_m: max_edge,
        };
        for (r, polygon) in boundary::region_polygons(&tri, &pts, &regions, &grow)
            .unwrap()
            .iter()
            .enumerate()
        {
            polygon
                .validate()
                .unwrap_or_else(|e| panic!("case {case}, region {r}: {e}"));
        }
        assert_eq!(plain.sites.len(), grown.sites.len(), "case {case}");
        for (p, q) in plain.sites.iter().zip(&grown.sites) {
            assert_eq!(
                (p.center, p.safe_radius_m),
                (q.center, q.safe_radius_m),
                "case {case}"
            );
            for v in p
                .polygon
                .shell
                .iter()
                .chain(p.polygon.holes.iter().flatten())
            {
                assert!(
                    q.polygon.signed_distance(*v) > -1e-9,
                    "case {case}: {v:?} left out"
                );
            }
            for v in q
                .polygon
                .shell
                .iter()
                .chain(q.polygon.holes.iter().flatten())
            {
                assert!(
                    p.polygon.signed_distance(*v) > -max_edge / 2.0 - 1e-9,
                    "case {case}: {v:?} reaches too far"
                );
            }
            for i in s.obstacle_points() {
                assert!(!strictly_inside(&q.polygon, xy(i)), "case {case}");
            }
            assert!(q.area_m2 >= p.area_m2, "case {case}");
            grown_by += q.area_m2 - p.area_m2;
        }
    }
    assert!(grown_by > 1.0, "the polygons grew by {grown_by} m²");
}

/// Dense, noisy roofs, as a fused map's cells are, where the LiDAR missed one obstacle (no
/// point on or under it) and a camera saw every obstacle, and also something on open roof that
/// is not there. As a fused map, with the trust limit `L` of two cells, a safe circle reaches at
/// most `L/√3` into the missed obstacle (deeper, its points lie in a triangle with an edge over
/// `L`, whose disks count), and the disks on dense points bound nothing, so the circles grow over
/// those of the same steps with every disk counted (the test fails without it).
#[test]
fn property_keep_out_disks_count_over_gaps_not_over_dense_points() {
    let mut g = Pcg32::new(17);
    let (mut every_total, mut trusted_total) = (0.0, 0.0);
    for case in 0..6u64 {
        let params = SceneParams {
            point_count: 10_000,
            roof_size_m: [12.0, 12.0],
            roof_height_m: g.range(3.0, 40.0),
            obstacles: 1 + (g.next_u32() % 3) as usize,
            noise_m: 0.01,
            ..SceneParams::default()
        };
        let s = Scene::generate(&params, 100 + case);
        // Two point spacings, as the service's two map cells.
        let limit = 2.0 * s.spacing_m;
        let reach = limit / 3f64.sqrt();
        let missed = &s.truth.obstacles[0];
        let (points, classes): (Vec<[f32; 3]>, Vec<u8>) = s
            .points
            .iter()
            .zip(&s.classes)
            .filter(|(p, _)| !missed.contains(f64::from(p[0]), f64::from(p[1])))
            .map(|(p, c)| (*p, *c))
            .unzip();
        // The camera's disks: every obstacle's footprint and 0.2 m around it, and false ones.
        let mut disks = Vec::new();
        for o in &s.truth.obstacles {
            let mut y = o.min[1] - 0.2;
            while y <= o.max[1] + 0.2 {
                let mut x = o.min[0] - 0.2;
                while x <= o.max[0] + 0.2 {
                    disks.push(Disk {
                        center: [x, y],
                        radius: 0.15,
                    });
                    x += 0.1;
                }
                y += 0.1;
            }
        }
        let roof = &s.truth.roofs[0];
        for _ in 0..20 {
            let c = [
                g.range(roof.min[0], roof.max[0]),
                g.range(roof.min[1], roof.max[1]),
            ];
            if s.truth
                .obstacles
                .iter()
                .all(|o| o.distance(c[0], c[1]) > 1.0)
            {
                disks.push(Disk {
                    center: c,
                    radius: g.range(0.1, 0.6),
                });
            }
        }
        let keep_out = |_: [f64; 3], _: [f64; 3], _: [f64; 4]| disks.clone();
        let keep_clear = KeepClear {
            disks: Some(&keep_out),
            points: None,
        };
        let geometry = Params::default();
        let every = sites_with_pinholes_closed(&points, Some(&classes), &geometry, Some(&keep_out));
        let cloud = Cloud::new(&points, Some(&classes))
            .with_keep_clear(keep_clear)
            .with_kind(CloudKind::FusedMap {
                cell_size_m: s.spacing_m,
            });
        let trusted = detect(&cloud, &geometry).expect("detect");
        check_detection(&trusted).expect("valid detection");
        assert!(!trusted.sites.is_empty(), "case {case}");
        for site in &trusted.sites {
            // How deep the circle reaches into the missed obstacle, on a 1 cm grid.
            let mut depth: f64 = 0.0;
            let mut y = missed.min[1];
            while y <= missed.max[1] {
                let mut x = missed.min[0];
                while x <= missed.max[0] {
                    if (x - site.center[0]).hypot(y - site.center[1]) <= site.safe_radius_m {
                        let d = (x - missed.min[0])
                            .min(missed.max[0] - x)
                            .min(y - missed.min[1])
                            .min(missed.max[1] - y);
                        depth = depth.max(d);
                    }
                    x += 0.01;
                }
                y += 0.01;
            }
            assert!(
                depth <= reach + 0.01,
                "case {case}: the circle at {:?} of {} m reaches {depth} m into {missed:?}",
                site.center,
                site.safe_radius_m
            );
        }
        every_total += every.sites.first().map_or(0.0, |s| s.safe_radius_m);
        trusted_total += trusted.sites[0].safe_radius_m;
    }
    assert!(
        trusted_total > every_total + 0.5,
        "{trusted_total} against {every_total} with every disk"
    );
}

/// The steps of `detect` up to the regions, with pinholes closed as for a fused map: the
/// triangulation, the points in double precision and the regions.
fn regions_with_pinholes_closed(
    points: &[[f32; 3]],
    classes: Option<&[u8]>,
    params: &Params,
) -> (Triangulation, Vec<[f64; 3]>, regions::Regions) {
    let pts: Vec<[f64; 3]> = points.iter().map(|p| p.map(f64::from)).collect();
    let tri = triangulation::triangulate(&pts).unwrap();
    let keep = filter::filter_triangles(&tri, &pts, classes, &filter::FilterParams::from(params));
    let region_params = regions::RegionParams {
        min_triangles: params.min_region_triangles,
    };
    let mut regions = regions::extract_regions(&tri, &pts, keep, &region_params).unwrap();
    regions::close_pinholes(
        &tri,
        &pts,
        &mut regions,
        params.max_triangle_edge_m,
        params.max_triangle_height_m,
    );
    (tri, pts, regions)
}

/// The steps of `detect` done by hand, with a fused map's pinholes closed but the paper's
/// polygons and every keep-out disk counted (which no [`CloudKind`] asks for), its invariants
/// checked: to compare the other two mechanisms of a fused map with.
fn sites_with_pinholes_closed(
    points: &[[f32; 3]],
    classes: Option<&[u8]>,
    params: &Params,
    disks: Option<&dyn KeepOut>,
) -> Detection {
    let (tri, pts, regions) = regions_with_pinholes_closed(points, classes, params);
    let polygons =
        boundary::region_polygons(&tri, &pts, &regions, &boundary::BoundaryParams::default())
            .unwrap();
    let ranking = ranking::RankingParams::from(params);
    let sites = ranking::rank_sites(&regions, polygons, None, &ranking, disks).unwrap();
    let d = Detection {
        sites,
        point_count: points.len(),
        triangle_count: tri.len(),
        ..Detection::default()
    };
    check_detection(&d).expect("valid detection");
    d
}
