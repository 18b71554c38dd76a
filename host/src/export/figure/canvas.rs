//! Drawing on an RGB image: the colormap lookup table, rectangles and the canvas with lines,
//! fills and text in the embedded font. Pixel coordinates, origin top left.

use super::font::*;

/// Background.
pub(super) const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
/// Frames, ticks and text.
pub(super) const BLACK: Rgb<u8> = Rgb([0, 0, 0]);
use image::{Rgb, RgbImage};

/// A 256-entry lookup table of a colormap.
pub(super) struct Colormap([Rgb<u8>; 256]);

impl Colormap {
    pub(super) fn inferno() -> Self {
        Self(std::array::from_fn(|i| {
            Rgb(colorous::INFERNO.eval_rational(i, 256).into_array())
        }))
    }

    /// The colour of `t` in `[0, 1]` (clamped; NaN is 0).
    pub(super) fn at(&self, t: f32) -> Rgb<u8> {
        let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
        self.0[(t * 255.0).round() as usize]
    }
}

/// A rectangle of pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Rect {
    pub(super) x: i32,
    pub(super) y: i32,
    pub(super) w: i32,
    pub(super) h: i32,
}

impl Rect {
    pub(super) const fn new(x: i32, y: i32, w: i32, h: i32) -> Self {
        Self { x, y, w, h }
    }

    /// One past the last column.
    pub(super) fn right(self) -> i32 {
        self.x + self.w
    }

    /// One past the last row.
    pub(super) fn bottom(self) -> i32 {
        self.y + self.h
    }

    pub(super) fn contains(self, x: i32, y: i32) -> bool {
        x >= self.x && x < self.right() && y >= self.y && y < self.bottom()
    }

    /// The overlap of two rectangles (possibly empty).
    pub(super) fn intersect(self, o: Self) -> Self {
        let (x, y) = (self.x.max(o.x), self.y.max(o.y));
        let (right, bottom) = (self.right().min(o.right()), self.bottom().min(o.bottom()));
        Self::new(x, y, (right - x).max(0), (bottom - y).max(0))
    }

    /// `self` grown by `d` pixels on every side.
    pub(super) fn grow(self, d: i32) -> Self {
        Self::new(self.x - d, self.y - d, self.w + 2 * d, self.h + 2 * d)
    }
}

/// An image with clipped drawing primitives.
pub(super) struct Canvas {
    pub(super) img: RgbImage,
}

impl Canvas {
    /// A white canvas.
    pub(super) fn new(width: i32, height: i32) -> Self {
        Self {
            img: RgbImage::from_pixel(width.max(1) as u32, height.max(1) as u32, WHITE),
        }
    }

    pub(super) fn bounds(&self) -> Rect {
        Rect::new(0, 0, self.img.width() as i32, self.img.height() as i32)
    }

    pub(super) fn put(&mut self, x: i32, y: i32, c: Rgb<u8>) {
        self.put_clipped(x, y, c, self.bounds());
    }

    pub(super) fn put_clipped(&mut self, x: i32, y: i32, c: Rgb<u8>, clip: Rect) {
        if clip.contains(x, y) && self.bounds().contains(x, y) {
            self.img.put_pixel(x as u32, y as u32, c);
        }
    }

    pub(super) fn fill(&mut self, r: Rect, c: Rgb<u8>) {
        self.fill_clipped(r, c, self.bounds());
    }

    pub(super) fn fill_clipped(&mut self, r: Rect, c: Rgb<u8>, clip: Rect) {
        let r = r.intersect(clip).intersect(self.bounds());
        for y in r.y..r.bottom() {
            for x in r.x..r.right() {
                self.img.put_pixel(x as u32, y as u32, c);
            }
        }
    }

    /// A one-pixel frame just outside `r`.
    pub(super) fn frame(&mut self, r: Rect, c: Rgb<u8>) {
        let (x0, y0, x1, y1) = (r.x - 1, r.y - 1, r.right(), r.bottom());
        self.fill(Rect::new(x0, y0, x1 - x0 + 1, 1), c);
        self.fill(Rect::new(x0, y1, x1 - x0 + 1, 1), c);
        self.fill(Rect::new(x0, y0, 1, y1 - y0 + 1), c);
        self.fill(Rect::new(x1, y0, 1, y1 - y0 + 1), c);
    }

    /// Text with its top-left corner at `(x, y)`.
    pub(super) fn text(&mut self, x: i32, y: i32, s: &str, c: Rgb<u8>, clip: Rect) {
        // Characters entirely left of the clip are skipped without drawing.
        let hidden = usize::try_from((clip.x - x) / ADV - 1).unwrap_or(0);
        let mut left = x.saturating_add(
            i32::try_from(hidden)
                .unwrap_or(i32::MAX)
                .saturating_mul(ADV),
        );
        for ch in s.chars().skip(hidden) {
            if left >= clip.right() {
                break;
            }
            for (col, row) in glyph_pixels(ch) {
                let r = Rect::new(left + col * SCALE, y + row * SCALE, SCALE, SCALE);
                self.fill_clipped(r, c, clip);
            }
            left = left.saturating_add(ADV);
        }
    }

    /// Text reading upward, its baseline side at the right: the first character's bottom-left
    /// corner (top of the glyphs facing left) at `(x, bottom)`.
    pub(super) fn text_up(&mut self, x: i32, bottom: i32, s: &str, c: Rgb<u8>, clip: Rect) {
        // Characters entirely below the clip are skipped without drawing.
        let hidden = usize::try_from((bottom - clip.bottom()) / ADV - 1).unwrap_or(0);
        let mut start = bottom.saturating_sub(
            i32::try_from(hidden)
                .unwrap_or(i32::MAX)
                .saturating_mul(ADV),
        );
        for ch in s.chars().skip(hidden) {
            if start <= clip.y {
                break;
            }
            for (col, row) in glyph_pixels(ch) {
                let r = Rect::new(x + row * SCALE, start - col * SCALE - SCALE, SCALE, SCALE);
                self.fill_clipped(r, c, clip);
            }
            start = start.saturating_sub(ADV);
        }
    }

    /// Text in `c` with a one-pixel black outline (legible on any colour).
    pub(super) fn text_outlined(&mut self, x: i32, y: i32, s: &str, c: Rgb<u8>, clip: Rect) {
        for (dx, dy) in [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ] {
            self.text(x + dx, y + dy, s, BLACK, clip);
        }
        self.text(x, y, s, c, clip);
    }
}
