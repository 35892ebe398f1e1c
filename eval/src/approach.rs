//! Approaches: the frames of one recording are one drone's descent onto a roof, in sequence
//! order. What `landing eval --stream` needs beyond single frames, as pure functions: where a
//! frame stands in its approach ([`ApproachFrame`]), the truth a fused answer is judged against
//! ([`fused_roofs`]: the scans so far), and the rows of the approach breakdown ([`breakdown`]:
//! the last quarter, time since the start, altitude bands).

use serde::Serialize;

use crate::geom::{Grid, Mask, P2, Polygon2, convex_hull};
use crate::metrics::RoofTruth;

/// Where a frame stands in its approach.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ApproachFrame {
    /// The approach: the recording's file name.
    pub approach: String,
    /// Index of the frame in its approach, in sequence order (0 is the first frame).
    pub index: usize,
    /// Frames of the approach in the recording (with ground truth).
    pub approach_frames: usize,
    /// Time since the approach's first frame, seconds, from the frames' timestamps (`None` when
    /// a frame has no timestamp).
    pub time_s: Option<f64>,
    /// Height of the true camera above the target roof, metres, from the ground truth.
    pub camera_above_roof_m: Option<f64>,
}

impl ApproachFrame {
    /// Whether the frame is in the last quarter of its approach ([`in_last_quarter`]).
    pub fn in_last_quarter(&self) -> bool {
        in_last_quarter(self.index, self.approach_frames)
    }
}

/// Whether frame `index` of an approach of `frames` frames is in its last quarter: `index >=
/// 0.75 * (frames - 1)`, so the last frame always is (computed in integers, so that no rounding
/// moves a frame across the boundary).
pub fn in_last_quarter(index: usize, frames: usize) -> bool {
    frames > 0 && 4 * index >= 3 * (frames - 1)
}

/// The quarter (0 to 3) of an approach of `frames` frames that frame `index` is in, by its
/// position `index / (frames - 1)`; quarter 3 is exactly [`in_last_quarter`]. A one-frame
/// approach is all last quarter.
pub fn quarter_of(index: usize, frames: usize) -> usize {
    if frames <= 1 {
        return 3;
    }
    (4 * index.min(frames - 1) / (frames - 1)).min(3)
}

/// Time bands are whole seconds since the approach started; this many, the last open-ended.
pub const TIME_BANDS: u32 = 10;

/// The time band of `time_s` seconds since the start: `k` for `k <= t < k + 1` (band 0 is the
/// first second), at most [`TIME_BANDS`]` - 1` (that band and everything later).
pub fn time_band(time_s: f64) -> u32 {
    // A microsecond of slack, so that a frame stamped at exactly 1 s is not in the first second
    // because its timestamp difference came out as 0.999999999.
    let k = (time_s.max(0.0) + 1e-6).floor();
    (k.min(f64::from(TIME_BANDS - 1))) as u32
}

/// The label of [`time_band`] `k`.
pub fn time_band_label(k: u32) -> String {
    if k + 1 >= TIME_BANDS {
        format!("time >= {k} s")
    } else if k == 0 {
        "time 0-1 s (first second)".to_string()
    } else {
        format!("time {k}-{} s", k + 1)
    }
}

/// Altitude bands are 10 m thick: band `k` holds heights above the roof in `(10(k-1), 10k]`
/// metres, so an approach from 40 m down to 10 m has its frames at 40, 30, 20 and 10 m in bands
/// "40-30", "30-20", "20-10" and "10-0" (a millimetre of slack keeps 30.0000001 m in "30-20").
pub fn altitude_band(height_m: f64) -> u32 {
    ((height_m - 1e-3) / 10.0).ceil().clamp(0.0, 99.0) as u32
}

/// The label of [`altitude_band`] `k`.
pub fn altitude_band_label(k: u32) -> String {
    if k == 0 {
        "altitude <= 0 m".to_string()
    } else {
        format!("altitude {}-{} m", 10 * k, 10 * (k - 1))
    }
}

/// The rows of the approach breakdown, in report order, each with the items that belong to it:
/// all answers, the last quarter of each approach, all answers after the first second, then one
/// row per time band, per quarter of the approach and per altitude band (highest first) that
/// holds an item. `at` says where an item stands.
pub fn breakdown<'a, T>(
    items: &[&'a T],
    at: impl Fn(&T) -> &ApproachFrame,
) -> Vec<(String, Vec<&'a T>)> {
    let pick = |f: &dyn Fn(&ApproachFrame) -> bool| -> Vec<&'a T> {
        items.iter().copied().filter(|x| f(at(x))).collect()
    };
    let mut rows = vec![
        ("all answers".to_string(), items.to_vec()),
        (
            "last quarter of each approach".to_string(),
            pick(&ApproachFrame::in_last_quarter),
        ),
        (
            "after the first second".to_string(),
            pick(&|a| a.time_s.is_some_and(|t| time_band(t) > 0)),
        ),
    ];
    let mut times: Vec<u32> = items
        .iter()
        .filter_map(|x| at(x).time_s.map(time_band))
        .collect();
    times.sort_unstable();
    times.dedup();
    for k in times {
        rows.push((
            time_band_label(k),
            pick(&|a| a.time_s.is_some_and(|t| time_band(t) == k)),
        ));
    }
    for q in 0..4 {
        let of_q = pick(&|a| quarter_of(a.index, a.approach_frames) == q);
        if !of_q.is_empty() {
            rows.push((format!("quarter {}/4 of the approach", q + 1), of_q));
        }
    }
    let mut heights: Vec<u32> = items
        .iter()
        .filter_map(|x| at(x).camera_above_roof_m.map(altitude_band))
        .collect();
    heights.sort_unstable_by(|a, b| b.cmp(a));
    heights.dedup();
    for k in heights {
        rows.push((
            altitude_band_label(k),
            pick(&|a| a.camera_above_roof_m.is_some_and(|h| altitude_band(h) == k)),
        ));
    }
    rows
}

/// The truth each fused answer of an approach is judged against: for frame `k` (the slices of
/// `frames` in approach order, each frame's roofs with their scanned regions filled), that
/// frame's roofs with
///
/// - the scanned region grown to the **convex hull of the union of the scanned regions of frames
///   `0..=k`** on that roof (each frame's region is the convex hull of its LiDAR returns on the
///   roof surface, or the simulator's clip of it to the walkable roof, so this is the convex
///   hull of the union of the returns of every frame so far, within the walkable roof); a roof
///   one frame saw whole (`scanned: None`) stays whole from then on;
/// - an obstacle counted as seen by the LiDAR when any frame so far saw it.
///
/// A roof's first scan stays exactly the frame's own region, so that the first answer of an
/// approach is judged as the single-frame one is.
///
/// The line-of-sight scores of a later answer leave out what no frame so far had in sight
/// ([`RoofTruth::in_sight`], on a grid of `cell_m`): each frame sees its scanned region less its
/// shadows, and an answer draws on every frame's. (The scanned region alone is a convex hull,
/// which spans the shadow behind a tall obstacle that no scan line reached.)
///
/// A roof is the same across frames when its building id, height and outline are. The regions
/// only grow, even where the server's map forgets old cells (its horizon): the answer is judged
/// against what the approach has scanned, not what the server kept.
pub fn fused_roofs(frames: &[&[RoofTruth]], cell_m: f64) -> Vec<Vec<RoofTruth>> {
    let mut seen: Vec<SeenRoof> = Vec::new();
    let mut out = Vec::with_capacity(frames.len());
    for roofs in frames {
        let mut fused = roofs.to_vec();
        for roof in &mut fused {
            let k = match seen.iter().position(|s| s.is(roof)) {
                Some(k) => k,
                None => {
                    seen.push(SeenRoof {
                        id: roof.id,
                        height_m: roof.height_m,
                        outline: roof.outline.clone(),
                        scans: 0,
                        whole: false,
                        hull: Vec::new(),
                        seen_obstacles: Vec::new(),
                        in_sight: None,
                    });
                    seen.len() - 1
                }
            };
            let s = &mut seen[k];
            let first = s.scans == 0;
            s.scans += 1;
            s.add_sight(roof, cell_m);
            match &roof.scanned {
                None => s.whole = true,
                Some(region) => s.hull = grow_scanned(&s.hull, region),
            }
            // A roof's first scan is the frame's own region, as it is (the hull of a region may
            // start at another vertex): that answer is judged exactly as a single frame's.
            if s.whole {
                roof.scanned = None;
            } else if !first {
                roof.scanned = Some(if s.hull.len() >= 3 {
                    Polygon2::simple(s.hull.clone())
                } else {
                    Polygon2::default()
                });
            }
            if !first {
                roof.in_sight.clone_from(&s.in_sight);
            }
            for o in &mut roof.obstacles {
                if o.seen {
                    if !s.seen_obstacles.contains(&o.footprint) {
                        s.seen_obstacles.push(o.footprint.clone());
                    }
                } else {
                    o.seen = s.seen_obstacles.contains(&o.footprint);
                }
            }
        }
        out.push(fused);
    }
    out
}

/// The convex hull of a hull so far (its vertices) and one more scanned region: the vertices of
/// the grown hull. Holes of the region do not matter (scanned regions have none).
pub fn grow_scanned(hull: &[P2], region: &Polygon2) -> Vec<P2> {
    let mut pts = hull.to_vec();
    pts.extend(region.shell.iter().copied());
    convex_hull(&pts)
}

/// One roof as seen so far in an approach.
struct SeenRoof {
    id: u32,
    height_m: f64,
    outline: Polygon2,
    scans: usize,
    whole: bool,
    hull: Vec<P2>,
    seen_obstacles: Vec<Polygon2>,
    /// What the frames so far had in sight, on a grid over the outline.
    in_sight: Option<Mask>,
}

impl SeenRoof {
    /// Adds what one frame had in sight of the roof: its scanned region (the walkable roof when
    /// it saw all of it) less its shadows.
    fn add_sight(&mut self, roof: &RoofTruth, cell_m: f64) {
        if self.in_sight.is_none() {
            self.in_sight = roof
                .outline
                .bounds()
                .and_then(|(lo, hi)| Grid::covering(lo, hi, cell_m, cell_m))
                .map(Mask::empty);
        }
        let Some(sight) = &mut self.in_sight else {
            return;
        };
        let mut seen = Mask::of_polygon(sight.grid, &roof.interior);
        if let Some(region) = &roof.scanned {
            seen.and(&Mask::of_polygon(sight.grid, region));
        }
        let mut shadows = Mask::empty(sight.grid);
        for h in &roof.hidden {
            shadows.add_polygon(h);
        }
        seen.and_not(&shadows);
        sight.or(&seen);
    }

    fn is(&self, roof: &RoofTruth) -> bool {
        self.id == roof.id
            && (self.height_m - roof.height_m).abs() < 1e-6
            && self.outline == roof.outline
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::Obstacle;

    fn roof(scanned: Option<Polygon2>, seen: bool) -> RoofTruth {
        RoofTruth {
            id: 3,
            outline: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
            interior: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
            height_m: 30.0,
            obstacles: vec![Obstacle {
                class: 13,
                footprint: Polygon2::rect([15.0, 4.0], [17.0, 6.0]),
                seen,
            }],
            scanned,
            hidden: vec![],
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target: true,
        }
    }

    fn at(index: usize, frames: usize, time_s: f64, height: f64) -> ApproachFrame {
        ApproachFrame {
            approach: "a.mcap".into(),
            index,
            approach_frames: frames,
            time_s: Some(time_s),
            camera_above_roof_m: Some(height),
        }
    }

    #[test]
    fn the_union_of_scans_grows_monotonically_and_covers_every_scan() {
        // Three scans sweeping across the roof: left, middle, a sliver on the left again.
        let scans = [
            Polygon2::rect([0.0, 0.0], [6.0, 10.0]),
            Polygon2::rect([5.0, 2.0], [12.0, 8.0]),
            Polygon2::rect([1.0, 1.0], [2.0, 2.0]),
        ];
        let frames: Vec<Vec<RoofTruth>> = scans
            .iter()
            .enumerate()
            .map(|(k, s)| vec![roof(Some(s.clone()), k == 1)])
            .collect();
        let refs: Vec<&[RoofTruth]> = frames.iter().map(Vec::as_slice).collect();
        let fused = fused_roofs(&refs, 0.05);
        assert_eq!(fused.len(), 3);
        let regions: Vec<Polygon2> = fused
            .iter()
            .map(|f| f[0].scanned.clone().expect("a region"))
            .collect();
        // The first frame is judged as a single frame would be.
        assert!((regions[0].area() - scans[0].area()).abs() < 1e-9);
        // Hull of both rectangles: the first one, then a trapezoid from x = 6 (10 m high) to
        // x = 12 (6 m high).
        let both = 60.0 + 6.0 * (10.0 + 6.0) / 2.0;
        assert!(
            (regions[1].area() - both).abs() < 1e-9,
            "{}",
            regions[1].area()
        );
        // The third scan adds nothing: the region stays, it does not shrink to the sliver.
        assert!((regions[2].area() - both).abs() < 1e-9);
        for k in 1..3 {
            assert!(regions[k].area() >= regions[k - 1].area() - 1e-9);
            for p in &regions[k - 1].shell {
                assert!(regions[k].boundary_distance(*p) < 1e-9 || regions[k].contains(*p));
            }
        }
        for (k, s) in scans.iter().enumerate() {
            for p in &s.shell {
                let r = &regions[k];
                assert!(r.contains(*p) || r.boundary_distance(*p) < 1e-9, "{p:?}");
            }
        }
        // The tarp was seen in frame 1: it stays seen in frame 2, not before.
        let seen: Vec<bool> = fused.iter().map(|f| f[0].obstacles[0].seen).collect();
        assert_eq!(seen, [false, true, true]);
    }

    #[test]
    fn line_of_sight_is_what_any_frame_so_far_saw() {
        use crate::geom::Grid;
        use crate::metrics::hidden_mask;
        // Frame 0 scans the left half with a shadow over x 2..4, frame 1 the right half with a
        // shadow over x 12..14, frame 2 the whole roof with shadows over x 2..4, 6..8 and 16..18.
        let frame = |scanned: Option<Polygon2>, shadows: &[[f64; 2]]| {
            let mut r = roof(scanned, false);
            r.hidden = shadows
                .iter()
                .map(|&[a, b]| Polygon2::rect([a, 0.0], [b, 10.0]))
                .collect();
            r
        };
        let frames = [
            vec![frame(
                Some(Polygon2::rect([0.0, 0.0], [10.0, 10.0])),
                &[[2.0, 4.0]],
            )],
            vec![frame(
                Some(Polygon2::rect([10.0, 0.0], [20.0, 10.0])),
                &[[12.0, 14.0]],
            )],
            vec![frame(None, &[[2.0, 4.0], [6.0, 8.0], [16.0, 18.0]])],
        ];
        let refs: Vec<&[RoofTruth]> = frames.iter().map(Vec::as_slice).collect();
        let fused = fused_roofs(&refs, 0.05);
        let grid = Grid::covering([0.0, 0.0], [20.0, 10.0], 0.05, 0.0).unwrap();
        let hidden = |k: usize| {
            let m = hidden_mask(grid, &fused[k][0]);
            move |x: f64| (0..grid.ny).all(|j| m.get((x / 0.05) as usize, j))
        };
        // The first answer is judged as a single frame is: by its own shadows.
        assert_eq!(fused[0][0].in_sight, None);
        assert!(hidden(0)(3.0) && !hidden(0)(7.0) && !hidden(0)(13.0));
        // After frame 1, each half is in sight but for its own frame's shadow.
        let h = hidden(1);
        assert!(h(3.0) && h(13.0));
        assert!(!h(1.0) && !h(7.0) && !h(11.0) && !h(19.0));
        // Frame 2 sees x 12..14 anew; its shadows over 6..8 and 16..18 were in sight of frames
        // 0 and 1. Only 2..4, in every frame's shadow, stays hidden.
        let h = hidden(2);
        assert!(h(3.0));
        assert!(!h(7.0) && !h(13.0) && !h(17.0) && !h(9.0));
    }

    #[test]
    fn roofs_are_told_apart_and_a_whole_roof_stays_whole() {
        let mut other = roof(Some(Polygon2::rect([0.0, 0.0], [1.0, 1.0])), false);
        other.id = 4;
        let frames = [
            vec![
                roof(Some(Polygon2::rect([0.0, 0.0], [2.0, 2.0])), false),
                other.clone(),
            ],
            vec![roof(None, false)],
            vec![
                roof(Some(Polygon2::rect([0.0, 0.0], [1.0, 1.0])), false),
                other,
            ],
        ];
        let refs: Vec<&[RoofTruth]> = frames.iter().map(Vec::as_slice).collect();
        let fused = fused_roofs(&refs, 0.05);
        // Roof 4's region is its own, not roof 3's.
        assert!((fused[2][1].scanned.as_ref().unwrap().area() - 1.0).abs() < 1e-9);
        assert_eq!(fused[1][0].scanned, None);
        assert_eq!(fused[2][0].scanned, None);
    }

    #[test]
    fn last_quarter_is_the_frames_from_three_quarters_of_the_way() {
        let last = |n: usize| {
            (0..n)
                .filter(|&i| in_last_quarter(i, n))
                .collect::<Vec<_>>()
        };
        assert_eq!(last(4), [3]);
        assert_eq!(last(5), [3, 4]); // 0.75 * 4 = 3 exactly
        assert_eq!(last(20), [15, 16, 17, 18, 19]); // from 14.25
        assert_eq!(last(1), [0]);
        assert!(last(0).is_empty());
        for n in 1..40 {
            for i in 0..n {
                assert_eq!(quarter_of(i, n) == 3, in_last_quarter(i, n), "{i}/{n}");
            }
            assert_eq!(quarter_of(0, n.max(2)), 0);
        }
    }

    #[test]
    fn time_and_altitude_bands() {
        assert_eq!(time_band(0.0), 0);
        assert_eq!(time_band(0.9), 0);
        assert_eq!(time_band(0.999_999_999_9), 1);
        assert_eq!(time_band(1.0), 1);
        assert_eq!(time_band(2.5), 2);
        assert_eq!(time_band(1e6), TIME_BANDS - 1);
        assert_eq!(time_band_label(0), "time 0-1 s (first second)");
        assert_eq!(time_band_label(TIME_BANDS - 1), "time >= 9 s");
        let bands: Vec<String> = [40.0, 35.0, 30.000_000_1, 29.999_999_9, 20.0, 10.0, 4.0]
            .iter()
            .map(|&h| altitude_band_label(altitude_band(h)))
            .collect();
        assert_eq!(
            bands,
            [
                "altitude 40-30 m",
                "altitude 40-30 m",
                "altitude 30-20 m",
                "altitude 30-20 m",
                "altitude 20-10 m",
                "altitude 10-0 m",
                "altitude 10-0 m"
            ]
        );
    }

    #[test]
    fn the_breakdown_has_the_summary_rows_then_the_bands() {
        // Four frames of a 0.3 s approach from 40 m down, and five of a 2 s one.
        let mut items = vec![];
        for i in 0..4 {
            items.push(at(i, 4, 0.1 * i as f64, 40.0 - 10.0 * i as f64));
        }
        for i in 0..5 {
            items.push(at(i, 5, 0.5 * i as f64, 25.0));
        }
        let refs: Vec<&ApproachFrame> = items.iter().collect();
        let rows = breakdown(&refs, |a| a);
        let n = |label: &str| {
            rows.iter()
                .find(|(l, _)| l == label)
                .map(|(_, v)| v.len())
                .unwrap_or_else(|| {
                    panic!(
                        "no row {label}: {:?}",
                        rows.iter().map(|r| &r.0).collect::<Vec<_>>()
                    )
                })
        };
        assert_eq!(rows[0].0, "all answers");
        assert_eq!(rows[1].0, "last quarter of each approach");
        assert_eq!(n("all answers"), 9);
        assert_eq!(n("last quarter of each approach"), 1 + 2);
        assert_eq!(n("after the first second"), 3); // 1.0, 1.5, 2.0 s
        assert_eq!(n("time 0-1 s (first second)"), 6);
        assert_eq!(n("time 1-2 s"), 2);
        assert_eq!(n("time 2-3 s"), 1);
        assert_eq!(n("quarter 4/4 of the approach"), 3);
        assert_eq!(n("altitude 30-20 m"), 5 + 1);
        let alt: Vec<&str> = rows
            .iter()
            .map(|r| r.0.as_str())
            .filter(|l| l.starts_with("altitude"))
            .collect();
        assert_eq!(
            alt,
            [
                "altitude 40-30 m",
                "altitude 30-20 m",
                "altitude 20-10 m",
                "altitude 10-0 m"
            ]
        );
    }
}
