//! A line plot of a capture's summed transient: counts against path length (m), log scale
//! (`vltm info --png`), so that a user can see where the wall's return ends and pick a time
//! window. Each pixel column draws the range of the bins it covers (no bin is lost however
//! many bins share a column). Non-positive and non-finite counts are not drawn (no log).
//! Cost O(bins + pixels); the image is 900×420 pixels.

use super::canvas::*;
use super::font::*;
use super::{MARGIN, TICK, TICK_GAP, format_coord, nice_values};
use crate::atomic::Transaction;
use crate::error::{Error, Result};
use image::{Rgb, RgbImage};
use std::path::Path;

const W: i32 = 900;
const H: i32 = 420;
const LINE: Rgb<u8> = Rgb([20, 60, 160]);
const GRID: Rgb<u8> = Rgb([225, 225, 225]);
const WINDOW: Rgb<u8> = Rgb([255, 236, 200]);

/// The summed transient of a capture.
#[derive(Clone, Debug)]
pub struct Transient<'a> {
    /// Counts per bin.
    pub counts: &'a [f64],
    /// Path length of bin 0 (m).
    pub t0: f64,
    /// Bin width (m of path).
    pub dt: f64,
    /// Title above the plot.
    pub title: String,
    /// A path interval (m) shaded behind the curve (e.g. the kept window), if any.
    pub shade: Option<[f64; 2]>,
}

impl Transient<'_> {
    /// Renders the plot and stages it as a PNG in `t`.
    ///
    /// # Errors
    /// [`Error::Argument`] when no count is positive (nothing to draw on a log scale) or the
    /// axis is not finite; [`Error::Io`] on encoding.
    pub fn stage_png(&self, t: &mut Transaction, path: &Path) -> Result<()> {
        let img = self.render()?;
        let mut png = std::io::Cursor::new(Vec::new());
        img.write_to(&mut png, image::ImageFormat::Png)
            .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
        let bytes = png.into_inner();
        t.stage(path, |f| {
            std::io::Write::write_all(f, &bytes).map_err(|e| Error::io(path, e))
        })
    }

    /// Renders the plot.
    ///
    /// # Errors
    /// As [`Transient::stage_png`].
    pub fn render(&self) -> Result<RgbImage> {
        let pos: Vec<f64> = self
            .counts
            .iter()
            .copied()
            .filter(|c| c.is_finite() && *c > 0.0)
            .collect();
        let n = self.counts.len();
        if pos.is_empty() || !(self.t0.is_finite() && self.dt.is_finite() && self.dt > 0.0) {
            return Err(Error::arg(
                "png",
                "the transient has no positive count to plot on a log scale",
            ));
        }
        let lo = pos.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let hi = pos.iter().fold(0.0f64, |a, &b| a.max(b));
        let (d0, d1) = (
            lo.log10().floor(),
            hi.log10().ceil().max(lo.log10().floor() + 1.0),
        );
        let (x0, x1) = (self.t0, self.t0 + (n.max(2) - 1) as f64 * self.dt);
        let mut cv = Canvas::new(W, H);
        let full = cv.bounds();
        cv.text(MARGIN, MARGIN, &self.title, BLACK, full);
        let left = MARGIN + 8 * ADV;
        let plot = Rect::new(
            left,
            MARGIN + 2 * GLYPH_H,
            W - left - MARGIN - 2 * ADV,
            H - MARGIN * 2 - 5 * GLYPH_H,
        );
        let px = |x: f64| plot.x as f64 + (x - x0) / (x1 - x0) * f64::from(plot.w - 1);
        let py = |c: f64| {
            f64::from(plot.bottom() - 1) - (c.log10() - d0) / (d1 - d0) * f64::from(plot.h - 1)
        };
        if let Some([a, b]) = self.shade {
            let (a, b) = (px(a.max(x0)).round() as i32, px(b.min(x1)).round() as i32);
            cv.fill_clipped(Rect::new(a, plot.y, b - a + 1, plot.h), WINDOW, plot);
        }
        // Decades: grid lines and labels.
        let mut k = d0;
        while k <= d1 {
            let y = py(10f64.powf(k)).round() as i32;
            cv.fill_clipped(Rect::new(plot.x, y, plot.w, 1), GRID, plot);
            cv.fill(Rect::new(plot.x - TICK, y, TICK, 1), BLACK);
            let s = format!("1e{k:.0}");
            cv.text(
                plot.x - TICK - TICK_GAP - text_width(&s),
                y - CAP_H / 2,
                &s,
                BLACK,
                full,
            );
            k += 1.0;
        }
        // Path ticks.
        let (vals, step) = nice_values(x0 as f32, x1 as f32, 8);
        let dec = super::decimals(step);
        for v in vals {
            let x = px(f64::from(v)).round() as i32;
            cv.fill_clipped(Rect::new(x, plot.y, 1, plot.h), GRID, plot);
            cv.fill(Rect::new(x, plot.bottom(), 1, TICK), BLACK);
            let s = format_coord(v, dec);
            cv.text(
                x - text_width(&s) / 2,
                plot.bottom() + TICK + TICK_GAP,
                &s,
                BLACK,
                full,
            );
        }
        let xl = "optical path (m); counts summed over all histograms (log)";
        cv.text(
            plot.x + (plot.w - text_width(xl)) / 2,
            plot.bottom() + TICK + 2 * TICK_GAP + GLYPH_H,
            xl,
            BLACK,
            full,
        );
        // The curve: per pixel column, the range of its bins joined to the previous column.
        let mut prev: Option<(f64, f64)> = None;
        let per = f64::from(plot.w - 1) / (n.max(2) - 1) as f64;
        for col in 0..plot.w {
            let a = ((f64::from(col) - 0.5) / per).ceil().max(0.0) as usize;
            let b = (((f64::from(col) + 0.5) / per).floor() as usize).min(n - 1);
            let vals: Vec<f64> = (a..=b.max(a))
                .filter_map(|i| self.counts.get(i).copied())
                .filter(|c| c.is_finite() && *c > 0.0)
                .map(&py)
                .collect();
            if vals.is_empty() {
                prev = None;
                continue;
            }
            let (mut top, mut bot) = vals
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |m, &v| {
                    (m.0.min(v), m.1.max(v))
                });
            if let Some((pt, pb)) = prev {
                top = top.min(pb);
                bot = bot.max(pt);
            }
            prev = Some((
                vals[0].min(vals[vals.len() - 1]),
                vals[0].max(vals[vals.len() - 1]),
            ));
            let (t, b) = (top.round() as i32, bot.round() as i32);
            cv.fill_clipped(Rect::new(plot.x + col, t, 2, b - t + 1), LINE, plot);
        }
        cv.frame(plot, BLACK);
        Ok(cv.img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curve_follows_the_counts() {
        // A decaying transient: 1e6 at path 0, 1e1 at the end.
        let counts: Vec<f64> = (0..1000)
            .map(|n| 10f64.powf(6.0 - 5.0 * n as f64 / 999.0))
            .collect();
        let t = Transient {
            counts: &counts,
            t0: 0.0,
            dt: 0.001,
            title: "t".into(),
            shade: None,
        };
        let img = t.render().unwrap();
        // The curve's pixels: high on the left, low on the right.
        let row_of = |x: u32| (0..img.height()).find(|&y| img.get_pixel(x, y) == &LINE);
        let (l, r) = (row_of(120).unwrap(), row_of(800).unwrap());
        assert!(l + 200 < r, "left {l}, right {r}");
        let zeros = vec![0.0; 10];
        let t = Transient {
            counts: &zeros,
            ..t
        };
        assert!(t.render().is_err());
    }
}
