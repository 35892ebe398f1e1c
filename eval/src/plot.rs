//! PNG charts drawn pixel by pixel with the `image` crate and a built-in 5×7 bitmap font: grouped
//! bars with confidence whiskers on a log axis (the paper's Fig. 5 layout) and box plots.

use std::path::Path;

use image::{Rgb, RgbImage};

use crate::EvalError;
use crate::stats::{MeanCi, quantile};

/// Colours given to series in order.
pub const PALETTE: [[u8; 3]; 4] = [[214, 96, 77], [67, 147, 195], [77, 175, 74], [152, 78, 163]];

const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const BLACK: Rgb<u8> = Rgb([20, 20, 20]);
const GRID: Rgb<u8> = Rgb([225, 225, 225]);
const SCALE: u32 = 2;

/// A chart under construction.
pub struct Canvas {
    img: RgbImage,
}

impl Canvas {
    /// A white canvas.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            img: RgbImage::from_pixel(width, height, WHITE),
        }
    }

    fn put(&mut self, x: i64, y: i64, c: Rgb<u8>) {
        if x >= 0 && y >= 0 && (x as u32) < self.img.width() && (y as u32) < self.img.height() {
            self.img.put_pixel(x as u32, y as u32, c);
        }
    }

    /// Fills the rectangle with corners `(x0, y0)` and `(x1, y1)` (inclusive, any order).
    pub fn rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb<u8>) {
        for y in y0.min(y1)..=y0.max(y1) {
            for x in x0.min(x1)..=x0.max(x1) {
                self.put(x, y, c);
            }
        }
    }

    /// Outlines the rectangle.
    pub fn frame(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb<u8>) {
        self.rect(x0, y0, x1, y0, c);
        self.rect(x0, y1, x1, y1, c);
        self.rect(x0, y0, x0, y1, c);
        self.rect(x1, y0, x1, y1, c);
    }

    /// Draws a one-pixel line from `(x0, y0)` to `(x1, y1)` (Bresenham).
    pub fn line(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb<u8>) {
        let (dx, dy) = ((x1 - x0).abs(), -(y1 - y0).abs());
        let (sx, sy) = (if x0 < x1 { 1 } else { -1 }, if y0 < y1 { 1 } else { -1 });
        let (mut x, mut y, mut err) = (x0, y0, dx + dy);
        // Bounded: each step moves x or y one pixel towards the end.
        for _ in 0..=(dx - dy) {
            self.put(x, y, c);
            if x == x1 && y == y1 {
                break;
            }
            let e2 = 2 * err;
            if e2 >= dy {
                err += dy;
                x += sx;
            }
            if e2 <= dx {
                err += dx;
                y += sy;
            }
        }
    }

    /// Sets one pixel (outside the canvas: nothing).
    pub fn pixel(&mut self, x: i64, y: i64, c: Rgb<u8>) {
        self.put(x, y, c);
    }

    /// Writes `text` with its top-left corner at `(x, y)`; returns the width drawn.
    pub fn text(&mut self, x: i64, y: i64, text: &str, c: Rgb<u8>) -> i64 {
        let mut cx = x;
        for ch in text.chars() {
            let rows = glyph(ch);
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        let (px, py) =
                            (cx + col * i64::from(SCALE), y + r as i64 * i64::from(SCALE));
                        self.rect(
                            px,
                            py,
                            px + i64::from(SCALE) - 1,
                            py + i64::from(SCALE) - 1,
                            c,
                        );
                    }
                }
            }
            cx += 6 * i64::from(SCALE);
        }
        cx - x
    }

    /// Width in pixels that [`Canvas::text`] would draw.
    pub fn text_width(text: &str) -> i64 {
        text.chars().count() as i64 * 6 * i64::from(SCALE)
    }

    /// Writes the PNG.
    pub fn save(&self, path: &Path) -> Result<(), EvalError> {
        self.img
            .save_with_format(path, image::ImageFormat::Png)
            .map_err(|e| EvalError::Image {
                path: path.display().to_string(),
                reason: e.to_string(),
            })
    }

    /// The pixels.
    pub fn image(&self) -> &RgbImage {
        &self.img
    }
}

/// One group of bars (one pipeline step): a mean with its interval per series, `None` where the
/// series has no value for this step.
#[derive(Debug, Clone)]
pub struct BarGroup {
    pub label: String,
    pub values: Vec<Option<MeanCi>>,
}

const LEFT: i64 = 90;
const RIGHT: i64 = 20;
const TOP: i64 = 64;
const BOTTOM: i64 = 90;

/// Grouped bars on a log axis with 95 % whiskers, like the paper's Fig. 5. Values are in
/// milliseconds; series names go in the legend.
pub fn bars_log(title: &str, unit: &str, series: &[&str], groups: &[BarGroup]) -> Canvas {
    let width =
        (LEFT + RIGHT + groups.len().max(1) as i64 * (series.len().max(1) as i64 * 22 + 30))
            .max(700);
    let height = 480i64;
    let mut c = Canvas::new(width as u32, height as u32);
    let positives: Vec<f64> = groups
        .iter()
        .flat_map(|g| g.values.iter().flatten())
        .flat_map(|m| [m.mean, m.hi])
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    let lo_exp = positives
        .iter()
        .map(|v| v.log10().floor() as i32)
        .min()
        .unwrap_or(-2);
    let hi_exp = positives
        .iter()
        .map(|v| v.log10().ceil() as i32)
        .max()
        .unwrap_or(3)
        .max(lo_exp + 1);
    let (x0, x1, y0, y1) = (LEFT, width - RIGHT, TOP, height - BOTTOM);
    let y_of = |v: f64| {
        let t =
            (v.max(10f64.powi(lo_exp)).log10() - f64::from(lo_exp)) / f64::from(hi_exp - lo_exp);
        y1 - (t.clamp(0.0, 1.0) * (y1 - y0) as f64).round() as i64
    };
    for e in lo_exp..=hi_exp {
        let y = y_of(10f64.powi(e));
        c.rect(x0, y, x1, y, GRID);
        let label = tick_label(e);
        c.text(x0 - 8 - Canvas::text_width(&label), y - 7, &label, BLACK);
        for k in 2..10 {
            let ym = y_of(f64::from(k) * 10f64.powi(e));
            if e < hi_exp {
                c.rect(x0 - 3, ym, x0, ym, BLACK);
            }
        }
    }
    c.frame(x0, y0, x1, y1, BLACK);
    c.text(x0, 12, title, BLACK);
    c.text(8, y0 - 24, unit, BLACK);
    let group_w = (x1 - x0) as f64 / groups.len().max(1) as f64;
    let bar_w = ((group_w * 0.8) / series.len().max(1) as f64).floor() as i64;
    for (gi, g) in groups.iter().enumerate() {
        let gx = x0 as f64 + gi as f64 * group_w + group_w * 0.1;
        for (si, v) in g.values.iter().enumerate() {
            let Some(m) = v else { continue };
            let bx = gx as i64 + si as i64 * bar_w;
            let col = Rgb(PALETTE[si % PALETTE.len()]);
            c.rect(bx + 1, y_of(m.mean), bx + bar_w - 2, y1 - 1, col);
            let mid = bx + bar_w / 2;
            let (wlo, whi) = (y_of(m.lo.max(1e-12)), y_of(m.hi));
            c.rect(mid, whi, mid, wlo, BLACK);
            c.rect(mid - 3, whi, mid + 3, whi, BLACK);
            c.rect(mid - 3, wlo, mid + 3, wlo, BLACK);
        }
        // Labels alternate between two rows so that long step names do not collide.
        let label: String = g
            .label
            .chars()
            .take(((group_w / 12.0) as usize).max(3) * 2)
            .collect();
        let lx = (gx + group_w * 0.4) as i64 - Canvas::text_width(&label) / 2;
        c.text(lx, y1 + 8 + (gi as i64 % 2) * 18, &label, BLACK);
    }
    legend(&mut c, series, x0, height - 30);
    c
}

/// Box plots, one per series: box from the 25th to the 75th percentile, median line, whiskers
/// from the 5th to the 95th percentile, and a black dot at the mean. The y axis is linear over
/// `y_range`.
pub fn box_plot(
    title: &str,
    series: &[(&str, Vec<f64>)],
    y_range: (f64, f64),
    reference: Option<f64>,
) -> Canvas {
    let width = (LEFT + RIGHT + series.len().max(1) as i64 * 250)
        .max(600)
        .max(LEFT + 40 + Canvas::text_width(title));
    let height = 440i64;
    let mut c = Canvas::new(width as u32, height as u32);
    let (x0, x1, y0, y1) = (LEFT, width - RIGHT, TOP, height - BOTTOM + 30);
    let (lo, hi) = y_range;
    let y_of = |v: f64| {
        let t = ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
        y1 - (t * (y1 - y0) as f64).round() as i64
    };
    let ticks = 5;
    for k in 0..=ticks {
        let v = lo + (hi - lo) * f64::from(k) / f64::from(ticks);
        let y = y_of(v);
        c.rect(x0, y, x1, y, GRID);
        let label = format!("{v:.2}");
        c.text(x0 - 8 - Canvas::text_width(&label), y - 7, &label, BLACK);
    }
    if let Some(r) = reference {
        let y = y_of(r);
        let mut x = x0;
        while x < x1 {
            c.rect(x, y, (x + 6).min(x1), y, Rgb([200, 30, 30]));
            x += 12;
        }
    }
    c.frame(x0, y0, x1, y1, BLACK);
    c.text(x0, 12, title, BLACK);
    let slot = (x1 - x0) as f64 / series.len().max(1) as f64;
    for (si, (name, xs)) in series.iter().enumerate() {
        let cx = (x0 as f64 + slot * (si as f64 + 0.5)) as i64;
        let label = format!("{name} (N={})", xs.iter().filter(|x| x.is_finite()).count());
        c.text(cx - Canvas::text_width(&label) / 2, y1 + 10, &label, BLACK);
        let (Some(p5), Some(p25), Some(p50), Some(p75), Some(p95)) = (
            quantile(xs, 0.05),
            quantile(xs, 0.25),
            quantile(xs, 0.5),
            quantile(xs, 0.75),
            quantile(xs, 0.95),
        ) else {
            continue;
        };
        let col = Rgb(PALETTE[si % PALETTE.len()]);
        let half = (slot * 0.25) as i64;
        c.rect(cx, y_of(p95), cx, y_of(p5), BLACK);
        c.rect(cx - half / 2, y_of(p95), cx + half / 2, y_of(p95), BLACK);
        c.rect(cx - half / 2, y_of(p5), cx + half / 2, y_of(p5), BLACK);
        c.rect(cx - half, y_of(p75), cx + half, y_of(p25), col);
        c.frame(cx - half, y_of(p75), cx + half, y_of(p25), BLACK);
        c.rect(cx - half, y_of(p50) - 1, cx + half, y_of(p50) + 1, BLACK);
        let finite: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
        let mean = finite.iter().sum::<f64>() / finite.len() as f64;
        let ym = y_of(mean);
        c.rect(cx - 3, ym - 3, cx + 3, ym + 3, BLACK);
    }
    c
}

fn legend(c: &mut Canvas, series: &[&str], x: i64, y: i64) {
    let mut lx = x;
    for (i, name) in series.iter().enumerate() {
        c.rect(lx, y, lx + 14, y + 14, Rgb(PALETTE[i % PALETTE.len()]));
        lx += 22;
        lx += c.text(lx, y, name, BLACK) + 24;
    }
}

fn tick_label(e: i32) -> String {
    if e >= 0 {
        format!("{}", 10u64.pow(e as u32))
    } else {
        format!("{}", 10f64.powi(e))
    }
}

/// The 5×7 glyph of `ch` (rows top to bottom, bit 4 is the leftmost column). Lower case draws as
/// upper case; characters without a glyph draw as a box.
fn glyph(ch: char) -> [u8; 7] {
    match ch.to_ascii_uppercase() {
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        'A' => [0x0E, 0x11, 0x11, 0x11, 0x1F, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '_' => [0, 0, 0, 0, 0, 0, 0x1F],
        '<' => [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        ' ' => [0; 7],
        _ => [0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dark_pixels(c: &Canvas) -> usize {
        c.image()
            .pixels()
            .filter(|p| p.0.iter().all(|&v| v < 60))
            .count()
    }

    #[test]
    fn text_draws_pixels_and_spaces_do_not() {
        let mut c = Canvas::new(100, 30);
        assert_eq!(c.text(0, 0, "   ", BLACK), 36);
        assert_eq!(dark_pixels(&c), 0);
        c.text(0, 0, "IOU 0.9", BLACK);
        assert!(dark_pixels(&c) > 50);
    }

    #[test]
    fn taller_bars_for_larger_means_on_the_log_axis() {
        let m = |v: f64| {
            Some(MeanCi {
                n: 10,
                mean: v,
                lo: v * 0.9,
                hi: v * 1.1,
            })
        };
        let groups = vec![
            BarGroup {
                label: "a".into(),
                values: vec![m(0.1), m(10.0)],
            },
            BarGroup {
                label: "b".into(),
                values: vec![m(100.0), None],
            },
        ];
        let c = bars_log("T", "ms", &["x", "y"], &groups);
        let col = |rgb: [u8; 3]| c.image().pixels().filter(|p| p.0 == rgb).count();
        // Series 0 has one tiny and one tall bar; series 1 one medium bar: both present.
        assert!(col(PALETTE[0]) > 0 && col(PALETTE[1]) > 0);
        let pixels_in_column = |x: u32| {
            (0..c.image().height())
                .filter(|&y| c.image().get_pixel(x, y).0 == PALETTE[0])
                .count()
        };
        let heights: Vec<usize> = (0..c.image().width())
            .map(pixels_in_column)
            .filter(|&n| n > 0)
            .collect();
        assert!(heights.iter().max() > heights.iter().min(), "{heights:?}");
    }

    #[test]
    fn box_plot_draws_each_series() {
        let a: Vec<f64> = (0..50).map(|i| 0.8 + f64::from(i) * 0.004).collect();
        let b: Vec<f64> = (0..50).map(|i| 0.3 + f64::from(i) * 0.01).collect();
        let c = box_plot(
            "IoU",
            &[("geometry", b), ("model", a)],
            (0.0, 1.0),
            Some(0.93),
        );
        for rgb in &PALETTE[..2] {
            assert!(c.image().pixels().any(|p| p.0 == *rgb));
        }
    }
}
