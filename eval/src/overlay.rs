//! A top-down picture of one frame's answer over its ground truth, to explain a verdict: roofs in
//! grey, the true landable area in green (pale olive where the sensor could not see it), obstacle
//! footprints in red, returned landing polygons in blue, safe circles in dark blue and unsafe ones
//! in magenta.

use image::Rgb;

use crate::geom::{Grid, Mask, P2, bounds_of};
use crate::metrics::{RoofTruth, Site, SiteEval, hidden_mask, landable_mask};
use crate::plot::Canvas;

const MARGIN: i64 = 20;
const LEGEND: i64 = 40;

/// Draws the frame; `None` when there is nothing to draw.
pub fn draw_overlay(
    title: &str,
    roofs: &[RoofTruth],
    sites: &[Site],
    evals: &[SiteEval],
) -> Option<Canvas> {
    let view = View::framing(roofs, sites)?;
    let mut c = Canvas::new(
        (view.w as i64 + 2 * MARGIN) as u32,
        (view.h as i64 + 2 * MARGIN + LEGEND) as u32,
    );
    for (mask, col) in &truth_layers(view.grid(), roofs) {
        view.paint(&mut c, mask, *col);
    }
    let blue = Rgb([40, 90, 200]);
    for s in sites {
        for ring in s.polygon.rings() {
            for k in 0..ring.len() {
                let (a, b) = (view.to_px(ring[k]), view.to_px(ring[(k + 1) % ring.len()]));
                c.line(a.0, a.1, b.0, b.1, blue);
            }
        }
    }
    for (s, e) in sites.iter().zip(evals) {
        let col = if !e.verdict.is_unsafe() {
            Rgb([20, 30, 110])
        } else {
            Rgb([220, 0, 200])
        };
        draw_safe_circle(&mut c, &view, s, col);
    }
    let y = view.h as i64 + 2 * MARGIN;
    c.text(MARGIN, y, title, Rgb([20, 20, 20]));
    Some(c)
}

/// The drawn area: the bounds of the roofs and sites, `ppm` pixels per metre, `w` × `h` pixels
/// inside the margin.
struct View {
    lo: P2,
    hi: P2,
    ppm: f64,
    w: usize,
    h: usize,
}

impl View {
    /// The view of every roof outline and site shell, at most 900 pixels a side and 25 pixels
    /// per metre; `None` when there are none.
    fn framing(roofs: &[RoofTruth], sites: &[Site]) -> Option<Self> {
        let mut pts: Vec<P2> = roofs
            .iter()
            .flat_map(|r| r.outline.shell.iter().copied())
            .collect();
        pts.extend(sites.iter().flat_map(|s| s.polygon.shell.iter().copied()));
        let (lo, hi) = bounds_of(&pts)?;
        let (w_m, h_m) = ((hi[0] - lo[0]).max(1.0), (hi[1] - lo[1]).max(1.0));
        let ppm = (900.0 / w_m).min(900.0 / h_m).min(25.0);
        let (w, h) = ((w_m * ppm).ceil() as usize, (h_m * ppm).ceil() as usize);
        Some(Self { lo, hi, ppm, w, h })
    }

    /// One cell per pixel.
    fn grid(&self) -> Grid {
        Grid {
            x0: self.lo[0],
            y0: self.lo[1],
            cell_m: 1.0 / self.ppm,
            nx: self.w,
            ny: self.h,
        }
    }

    /// The canvas pixel of a point, north up.
    fn to_px(&self, p: P2) -> (i64, i64) {
        (
            MARGIN + ((p[0] - self.lo[0]) * self.ppm).round() as i64,
            MARGIN + ((self.hi[1] - p[1]) * self.ppm).round() as i64,
        )
    }

    /// Paints the cells of `mask` (on [`View::grid`]) in `col`.
    fn paint(&self, c: &mut Canvas, mask: &Mask, col: Rgb<u8>) {
        for j in 0..self.h {
            for i in 0..self.w {
                if mask.get(i, j) {
                    c.pixel(MARGIN + i as i64, MARGIN + (self.h - 1 - j) as i64, col);
                }
            }
        }
    }
}

/// The truth as masks on `grid`, bottom layer first: roofs, the landable area, the part of it
/// the sensor could not see, obstacle footprints.
fn truth_layers(grid: Grid, roofs: &[RoofTruth]) -> [(Mask, Rgb<u8>); 4] {
    let mut roof = Mask::empty(grid);
    let mut landable = Mask::empty(grid);
    let mut hidden = Mask::empty(grid);
    let mut obstacles = Mask::empty(grid);
    for r in roofs {
        roof.add_polygon(&r.outline);
        if r.scored {
            let m = landable_mask(grid, r);
            let mut unseen = hidden_mask(grid, r);
            unseen.and(&m);
            landable.or(&m);
            hidden.or(&unseen);
        }
        for o in &r.obstacles {
            obstacles.add_polygon(&o.footprint);
        }
    }
    [
        (roof, Rgb([205, 205, 205])),
        (landable, Rgb([170, 225, 160])),
        (hidden, Rgb([205, 215, 165])),
        (obstacles, Rgb([225, 80, 70])),
    ]
}

/// The safe circle of `s` (two pixels wide), a cross at its centre and its rank.
fn draw_safe_circle(c: &mut Canvas, view: &View, s: &Site, col: Rgb<u8>) {
    let n = 96;
    for k in 0..n {
        let (t0, t1) = (
            k as f64 / n as f64 * std::f64::consts::TAU,
            (k + 1) as f64 / n as f64 * std::f64::consts::TAU,
        );
        let a = view.to_px([
            s.center[0] + s.radius_m * t0.cos(),
            s.center[1] + s.radius_m * t0.sin(),
        ]);
        let b = view.to_px([
            s.center[0] + s.radius_m * t1.cos(),
            s.center[1] + s.radius_m * t1.sin(),
        ]);
        c.line(a.0, a.1, b.0, b.1, col);
        c.line(a.0 + 1, a.1, b.0 + 1, b.1, col);
    }
    let p = view.to_px(s.center);
    c.rect(p.0 - 3, p.1, p.0 + 3, p.1, col);
    c.rect(p.0, p.1 - 3, p.0, p.1 + 3, col);
    c.text(p.0 + 5, p.1 + 4, &s.rank.to_string(), col);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Polygon2;
    use crate::metrics::{MetricsParams, Obstacle, judge_site};

    #[test]
    fn overlay_shows_truth_and_an_unsafe_circle() {
        let roof = RoofTruth {
            id: 1,
            outline: Polygon2::rect([0.0, 0.0], [20.0, 10.0]),
            interior: Polygon2::rect([0.3, 0.3], [19.7, 9.7]),
            height_m: 30.0,
            obstacles: vec![Obstacle {
                class: 13,
                footprint: Polygon2::rect([4.0, 4.0], [6.0, 6.0]),
                seen: true,
            }],
            scanned: None,
            hidden: vec![],
            in_sight: None,
            stated_best_radius_m: None,
            scored: true,
            target: true,
        };
        let site = Site {
            rank: 1,
            polygon: roof.interior.clone(),
            center: [5.0, 5.0],
            plane_height_m: 30.0,
            radius_m: 3.0,
        };
        let e = judge_site(
            &site,
            std::slice::from_ref(&roof),
            &MetricsParams::default(),
        );
        let c = draw_overlay("T", &[roof], &[site], &[e]).unwrap();
        let count = |rgb: [u8; 3]| c.image().pixels().filter(|p| p.0 == rgb).count();
        assert!(count([170, 225, 160]) > 1000, "landable drawn");
        assert!(count([225, 80, 70]) > 100, "obstacle drawn");
        assert!(count([220, 0, 200]) > 50, "unsafe circle drawn");
    }
}
