//! Maximum-intensity-projection (MIP) figures of voxel volumes, as PNG.
//!
//! A [`Figure`] shows a volume `(nx, ny, nz)` as a person standing at the relay wall sees the
//! hidden scene, looking in: a title, the FRONT view (maximum over z) drawn as a camera on the
//! wall looking into the scene would see it, and the TOP view (maximum over y) seen from above
//! with the wall at the bottom and depth z increasing upward, away from the wall. In vltm's
//! right-handed frame (x, y on the wall, y up, z > 0 into the hidden scene) that viewer has
//! **x increasing to the left**, so both panels draw x reversed, and their x axes say so
//! (`x [m], increasing <-`; the tick labels decrease from left to right). A sign that faces
//! the wall therefore reads correctly, not mirrored. Only the drawing is mirrored: the
//! volumes, their axes and their files keep vltm's frame. Both views share the horizontal x
//! direction, so a voxel's column is at the same place in the two panels.
//!
//! Frames, ticks and tick labels are in metres, with a vertical colour bar. Both panels share
//! one linear scale from 0 to the volume's maximum, mapped through the perceptual `inferno`
//! colormap. Small volumes are upscaled with nearest-neighbour blocks (each panel at least
//! [`PANEL_MIN_W`] pixels wide); very large ones are max-pooled.
//!
//! Text uses an embedded 5×7 bitmap font drawn at 2× scale: no system fonts, no font crates.
//! Cost: one pass over the volume for the projections, then one pass over the pixels; memory:
//! the two projections and the RGB image.

use std::ops::Range;
use std::path::Path;

use image::{Rgb, RgbImage};

use crate::atomic::Transaction;
use crate::error::{Error, Result};

/// Minimum width of a panel in pixels (small volumes are upscaled in whole blocks).
pub const PANEL_MIN_W: usize = 320;
/// Minimum height of a panel in pixels.
const PANEL_MIN_H: usize = 80;
/// Largest panel width; wider volumes are max-pooled.
const PANEL_MAX_W: usize = 1024;
/// Largest panel height; taller volumes are max-pooled.
const PANEL_MAX_H: usize = 800;

/// Line pitch of the title.
const LINE_H: i32 = GLYPH_H + 4;

const MARGIN: i32 = 16;
const TICK: i32 = 5;
/// Gap between a tick and its label.
const TICK_GAP: i32 = 4;
/// Gap between the tick labels and the axis label.
const LABEL_GAP: i32 = 6;
/// Horizontal gap between the front panel's frame and the top panel's axis label.
const PANEL_GAP: i32 = 36;
const CBAR_GAP: i32 = 24;
const CBAR_W: i32 = 18;
/// Longest title, in lines (the rest is cut with "...").
const MAX_TITLE_LINES: usize = 4;

const ERROR_RED: Rgb<u8> = Rgb([180, 0, 0]);
/// Marks: a cyan that stands out against every inferno colour.
const MARK: Rgb<u8> = Rgb([0, 230, 255]);

/// Subtitle of the front panel.
const FRONT_TITLE: &str = "front view from the wall";
/// Subtitle of the top panel.
const TOP_TITLE: &str = "top view, wall at bottom";
/// Label of both panels' horizontal axis: x grows to the left (the view from the wall).
const X_LABEL: &str = "x [m], increasing <-";

/// A maximum-intensity-projection figure of a voxel volume.
///
/// Build it with a struct literal or [`Figure::new`], then [`Figure::write_png`] or
/// [`Figure::render`]. NaN and infinite voxel values are drawn as 0; negative values clamp
/// to the bottom of the colour scale.
#[derive(Debug, Clone)]
pub struct Figure<'a> {
    /// Voxel values, shape `(nx, ny, nz)` in C order: `data[(ix * ny + iy) * nz + iz]`.
    pub data: &'a [f32],
    /// `[nx, ny, nz]`.
    pub shape: [usize; 3],
    /// x of the first and the last sample, in metres.
    pub x: [f32; 2],
    /// y of the first and the last sample, in metres.
    pub y: [f32; 2],
    /// z (depth from the wall) of the first and the last sample, in metres.
    pub z: [f32; 2],
    /// Title drawn above the panels (wrapped to the figure's width; may be empty).
    pub title: String,
    /// Points `[x, y, z]` in metres drawn as small rings with a label on both panels
    /// (e.g. focus points).
    pub marks: Vec<([f32; 3], String)>,
}

impl<'a> Figure<'a> {
    /// A figure of `data` (shape `(nx, ny, nz)`, C order) on the given sample coordinates,
    /// without title or marks.
    pub fn new(data: &'a [f32], shape: [usize; 3], x: [f32; 2], y: [f32; 2], z: [f32; 2]) -> Self {
        Self {
            data,
            shape,
            x,
            y,
            z,
            title: String::new(),
            marks: Vec::new(),
        }
    }

    /// Checks that the shape has no zero dimension and matches `data.len()`, and that the
    /// coordinates are finite.
    ///
    /// # Errors
    ///
    /// [`Error::Argument`] `volume`, saying what is wrong.
    pub fn validate(&self) -> Result<()> {
        let [nx, ny, nz] = self.shape;
        let shape = format!("{nx}x{ny}x{nz}");
        if self.shape.contains(&0) {
            return Err(Error::arg(
                "volume",
                format!("shape {shape} has an empty dimension"),
            ));
        }
        match nx.checked_mul(ny).and_then(|n| n.checked_mul(nz)) {
            Some(n) if n == self.data.len() => {}
            _ => {
                return Err(Error::arg(
                    "volume",
                    format!(
                        "shape {shape} does not match the data ({} values)",
                        self.data.len()
                    ),
                ));
            }
        }
        for (name, c) in [("x", self.x), ("y", self.y), ("z", self.z)] {
            if !c.iter().all(|v| v.is_finite()) {
                return Err(Error::arg(
                    "volume",
                    format!("{name} range {}..{} is not finite", c[0], c[1]),
                ));
            }
        }
        Ok(())
    }

    /// Renders the figure and writes it as a PNG.
    ///
    /// # Errors
    ///
    /// An invalid volume ([`Figure::validate`]); the file cannot be written ([`Error::Io`]).
    pub fn write_png(&self, path: &Path) -> Result<()> {
        let mut t = Transaction::new();
        self.stage_png(&mut t, path)?;
        t.commit()
    }

    /// [`Figure::write_png`] as one file of a [`Transaction`] (written on its commit).
    ///
    /// # Errors
    ///
    /// As [`Figure::write_png`].
    pub fn stage_png(&self, t: &mut Transaction, path: &Path) -> Result<()> {
        self.validate()?;
        let mut png = std::io::Cursor::new(Vec::new());
        self.render()
            .write_to(&mut png, image::ImageFormat::Png)
            .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
        let bytes = png.into_inner();
        t.stage(path, |f| {
            std::io::Write::write_all(f, &bytes).map_err(|e| Error::io(path, e))
        })
    }

    /// Renders the figure. An invalid volume (see [`Figure::validate`]) renders as a small
    /// image stating the error instead of panicking.
    pub fn render(&self) -> RgbImage {
        match self.validate() {
            Ok(()) => self.render_valid(),
            Err(e) => error_image(&e.to_string()),
        }
    }

    fn render_valid(&self) -> RgbImage {
        let (front, top) = projections(self.data, self.shape);
        let vmax = front.iter().fold(0.0f32, |m, &v| m.max(v));
        let layout = Layout::new(self, vmax);
        let mut cv = Canvas::new(layout.width, layout.height);
        let full = cv.bounds();
        for (i, line) in layout.title.iter().enumerate() {
            let x = (layout.width - text_width(line)) / 2;
            cv.text(x.max(MARGIN), MARGIN + i as i32 * LINE_H, line, BLACK, full);
        }
        let cmap = Colormap::inferno();
        let [_, ny, nz] = self.shape;
        for (panel, proj, stride) in [(&layout.front, &front, ny), (&layout.top, &top, nz)] {
            panel.draw_image(&mut cv, &cmap, vmax, |i, j| proj[i * stride + j]);
            panel.draw_axes(&mut cv);
        }
        draw_colorbar(&mut cv, &cmap, layout.cbar, &layout.cbar_labels);
        for (p, label) in &self.marks {
            layout.front.draw_mark(&mut cv, p[0], p[1], label);
            layout.top.draw_mark(&mut cv, p[0], p[2], label);
        }
        cv.img
    }
}

/// A finite value, or 0.
fn clean(v: f32) -> f32 {
    if v.is_finite() { v } else { 0.0 }
}

/// The front `(nx, ny)` (max over z) and top `(nx, nz)` (max over y) projections, C order,
/// of a validated volume. Values below 0 (and non-finite ones) become 0.
fn projections(data: &[f32], [_, ny, nz]: [usize; 3]) -> (Vec<f32>, Vec<f32>) {
    let front = data
        .chunks_exact(nz)
        .map(|line| line.iter().fold(0.0f32, |m, &v| m.max(clean(v))))
        .collect();
    let mut top = vec![0.0f32; data.len() / ny];
    for (i, &v) in data.iter().enumerate() {
        let (ix, iz) = (i / (ny * nz), i % nz);
        let t = &mut top[ix * nz + iz];
        *t = t.max(clean(v));
    }
    (front, top)
}

/// "0", or `v` in scientific notation with 2 significant digits ("1.3e5", "2.0e-3").
fn format_sci(v: f32) -> String {
    if v == 0.0 {
        "0".to_string()
    } else {
        format!("{v:.1e}")
    }
}

/// Greedy word wrap to `max_chars` per line, at most [`MAX_TITLE_LINES`] lines.
fn wrap(text: &str, max_chars: usize) -> Vec<String> {
    let max_chars = max_chars.max(4);
    let mut lines = Vec::new();
    for paragraph in text.lines() {
        let mut line = String::new();
        for word in paragraph.split_whitespace() {
            let chars: Vec<char> = word.chars().collect();
            for piece in chars.chunks(max_chars) {
                let piece: String = piece.iter().collect();
                if !line.is_empty() && line.chars().count() + 1 + piece.chars().count() > max_chars
                {
                    lines.push(std::mem::take(&mut line));
                }
                if !line.is_empty() {
                    line.push(' ');
                }
                line.push_str(&piece);
            }
        }
        if !line.is_empty() {
            lines.push(line);
        }
    }
    if lines.len() > MAX_TITLE_LINES {
        lines.truncate(MAX_TITLE_LINES);
        let last: String = lines[MAX_TITLE_LINES - 1]
            .chars()
            .take(max_chars - 3)
            .collect();
        lines[MAX_TITLE_LINES - 1] = last + "...";
    }
    lines
}

/// A white image with `msg` in red (what [`Figure::render`] shows for an invalid volume).
fn error_image(msg: &str) -> RgbImage {
    let lines = wrap(msg, 80);
    let width = lines.iter().map(|l| text_width(l)).max().unwrap_or(0) + 2 * MARGIN;
    let height = lines.len() as i32 * LINE_H + 2 * MARGIN;
    let mut cv = Canvas::new(width, height);
    let full = cv.bounds();
    for (i, line) in lines.iter().enumerate() {
        cv.text(MARGIN, MARGIN + i as i32 * LINE_H, line, ERROR_RED, full);
    }
    cv.img
}

// ---------------------------------------------------------------------------------------
// Layout

/// Where everything goes.
struct Layout {
    width: i32,
    height: i32,
    title: Vec<String>,
    front: Panel,
    top: Panel,
    cbar: Rect,
    /// Bottom and top labels of the colour bar.
    cbar_labels: [String; 2],
}

impl Layout {
    fn new(fig: &Figure<'_>, vmax: f32) -> Self {
        let [nx, ny, nz] = fig.shape;
        let block = PANEL_MIN_W.div_ceil(nx);
        let ax = Axis::new(nx, fig.x, block, PANEL_MIN_W, PANEL_MAX_W);
        let ay = Axis::new(ny, fig.y, block, PANEL_MIN_H, PANEL_MAX_H);
        let az = Axis::new(nz, fig.z, block, PANEL_MIN_H, PANEL_MAX_H);
        let mut front = Panel::new(FRONT_TITLE, ax.clone(), ay, [X_LABEL, "y [m]"]);
        let mut top = Panel::new(TOP_TITLE, ax, az, [X_LABEL, "z [m]"]);

        front.rect.x = MARGIN + front.gutter();
        top.rect.x = front.rect.right() + PANEL_GAP + top.gutter();
        let cbar_labels = ["0".to_string(), format_sci(vmax)];
        let cbar_label_w = cbar_labels.iter().map(|l| text_width(l)).max().unwrap_or(0);
        let cbar_x = top.rect.right() + CBAR_GAP;
        let width = cbar_x + CBAR_W + TICK + TICK_GAP + cbar_label_w + MARGIN;

        let title = wrap(&fig.title, ((width - 2 * MARGIN) / ADV) as usize);
        let title_h = if title.is_empty() {
            0
        } else {
            title.len() as i32 * LINE_H + 10
        };
        let panel_top = MARGIN + title_h + GLYPH_H + 12;
        front.rect.y = panel_top;
        top.rect.y = panel_top;
        let panels_h = front.rect.h.max(top.rect.h);
        let cbar = Rect::new(cbar_x, panel_top, CBAR_W, panels_h);
        let height =
            panel_top + panels_h + TICK + TICK_GAP + GLYPH_H + LABEL_GAP + GLYPH_H + MARGIN;
        Self {
            width,
            height,
            title,
            front,
            top,
            cbar,
            cbar_labels,
        }
    }
}

/// One axis of a panel: `n` samples from `c[0]` to `c[1]` drawn over `len` pixels.
///
/// The drawing direction always has the coordinate increasing (a decreasing grid is
/// flipped). `len` is a whole number of blocks of the same voxel when upscaling, and fewer
/// pixels than voxels (max-pooled) only for volumes larger than the maximum panel.
#[derive(Debug, Clone)]
struct Axis {
    n: usize,
    c: [f32; 2],
    len: usize,
}

impl Axis {
    /// `block` pixels per voxel, adjusted into `[min_px, max_px]`.
    fn new(n: usize, c: [f32; 2], block: usize, min_px: usize, max_px: usize) -> Self {
        let mut block = block.max(1);
        if n * block < min_px {
            block = min_px.div_ceil(n);
        }
        if n * block > max_px {
            block = (max_px / n).max(1);
        }
        Self {
            n,
            c,
            len: (n * block).min(max_px),
        }
    }

    fn flipped(&self) -> bool {
        self.c[1] < self.c[0]
    }

    /// A single sample, or all samples at one coordinate.
    fn degenerate(&self) -> bool {
        self.n == 1 || self.c[0] == self.c[1]
    }

    /// The coordinate range `(lo, hi)` of the sample centres.
    fn range(&self) -> (f32, f32) {
        (self.c[0].min(self.c[1]), self.c[0].max(self.c[1]))
    }

    /// Voxel indices drawn at pixel `d` (counted in the direction of increasing coordinate).
    fn voxels(&self, d: usize) -> Range<usize> {
        let k = if self.flipped() { self.len - 1 - d } else { d };
        let a = k * self.n / self.len;
        let b = ((k + 1) * self.n / self.len).max(a + 1);
        a..b
    }

    /// Pixel position (continuous, in the direction of increasing coordinate) of the centre
    /// of coordinate `c`; the panel centre on a degenerate axis.
    fn offset(&self, c: f32) -> f32 {
        let len = self.len as f32;
        if self.degenerate() {
            return len / 2.0;
        }
        let index = (c - self.c[0]) / (self.c[1] - self.c[0]) * (self.n - 1) as f32;
        let k = (index + 0.5) * len / self.n as f32;
        if self.flipped() { len - k } else { k }
    }

    /// Pixel distance between two coordinates `step` apart.
    fn pixels_per(&self, step: f32) -> f32 {
        let (lo, hi) = self.range();
        step / (hi - lo) * (self.n - 1) as f32 / self.n as f32 * self.len as f32
    }
}

/// An image panel with its two axes. The horizontal coordinate (x) increases to the LEFT and
/// the vertical one (y or z) upward: the view from the wall (module documentation).
struct Panel {
    subtitle: &'static str,
    rect: Rect,
    h: Axis,
    v: Axis,
    labels: [&'static str; 2],
    h_ticks: Vec<(f32, String)>,
    v_ticks: Vec<(f32, String)>,
}

impl Panel {
    fn new(subtitle: &'static str, h: Axis, v: Axis, labels: [&'static str; 2]) -> Self {
        let rect = Rect::new(0, 0, h.len as i32, v.len as i32);
        let h_ticks = ticks(&h, true);
        let v_ticks = ticks(&v, false);
        Self {
            subtitle,
            rect,
            h,
            v,
            labels,
            h_ticks,
            v_ticks,
        }
    }

    fn v_tick_label_w(&self) -> i32 {
        self.v_ticks
            .iter()
            .map(|(_, l)| text_width(l))
            .max()
            .unwrap_or(0)
    }

    /// Width left of the frame: vertical axis label, tick labels, ticks.
    fn gutter(&self) -> i32 {
        GLYPH_H + LABEL_GAP + self.v_tick_label_w() + TICK_GAP + TICK + 1
    }

    /// Screen pixel (continuous) of the coordinates `(hc, vc)`: both axes are counted from
    /// the panel's right and bottom edges (x grows to the left, the vertical one upward).
    fn screen(&self, hc: f32, vc: f32) -> (f32, f32) {
        let x = self.rect.x as f32 + self.h.len as f32 - self.h.offset(hc);
        let y = self.rect.y as f32 + self.v.len as f32 - self.v.offset(vc);
        (x, y)
    }

    /// Fills the panel: `value(i, j)` is the projection at horizontal voxel `i`, vertical `j`.
    fn draw_image(
        &self,
        cv: &mut Canvas,
        cmap: &Colormap,
        vmax: f32,
        value: impl Fn(usize, usize) -> f32,
    ) {
        let columns: Vec<Range<usize>> = (0..self.h.len)
            .map(|col| self.h.voxels(self.h.len - 1 - col))
            .collect();
        for row in 0..self.v.len {
            let rows = self.v.voxels(self.v.len - 1 - row);
            for (col, cols) in columns.iter().enumerate() {
                let v = cols
                    .clone()
                    .flat_map(|i| rows.clone().map(move |j| (i, j)))
                    .fold(0.0f32, |m, (i, j)| m.max(value(i, j)));
                let (x, y) = (self.rect.x + col as i32, self.rect.y + row as i32);
                let t = if vmax > 0.0 { v / vmax } else { 0.0 };
                cv.put(x, y, cmap.at(t));
            }
        }
    }

    /// Frame, subtitle, ticks, tick labels and axis labels.
    fn draw_axes(&self, cv: &mut Canvas) {
        let r = self.rect;
        let full = cv.bounds();
        cv.frame(r, BLACK);
        let sub_x = r.x + (r.w - text_width(self.subtitle)) / 2;
        cv.text(sub_x, r.y - GLYPH_H - 10, self.subtitle, BLACK, full);

        let below = r.bottom() + 1;
        for (c, label) in &self.h_ticks {
            let x = self.screen(*c, 0.0).0.floor() as i32;
            cv.fill(Rect::new(x, below, 1, TICK), BLACK);
            cv.text(
                x - text_width(label) / 2,
                below + TICK + TICK_GAP,
                label,
                BLACK,
                full,
            );
        }
        let h_label_y = below + TICK + TICK_GAP + GLYPH_H + LABEL_GAP;
        cv.text(
            r.x + (r.w - text_width(self.labels[0])) / 2,
            h_label_y,
            self.labels[0],
            BLACK,
            full,
        );

        let left = r.x - 1;
        for (c, label) in &self.v_ticks {
            let y = self.screen(0.0, *c).1.floor() as i32;
            cv.fill(Rect::new(left - TICK, y, TICK, 1), BLACK);
            cv.text(
                left - TICK - TICK_GAP - text_width(label),
                y - CAP_H / 2,
                label,
                BLACK,
                full,
            );
        }
        let v_label_x = left - TICK - TICK_GAP - self.v_tick_label_w() - LABEL_GAP - GLYPH_H;
        let v_label_bottom = r.y + (r.h + text_width(self.labels[1])) / 2;
        cv.text_up(v_label_x, v_label_bottom, self.labels[1], BLACK, full);
    }

    /// A ring around `(hc, vc)` and its label, clipped to the panel.
    fn draw_mark(&self, cv: &mut Canvas, hc: f32, vc: f32, label: &str) {
        if !(hc.is_finite() && vc.is_finite()) {
            return;
        }
        let clip = self.rect;
        let (x, y) = self.screen(hc, vc);
        // Far outside the panel (this also keeps the pixel arithmetic below in range).
        let near = clip.grow(10);
        if !(x >= near.x as f32
            && x < near.right() as f32
            && y >= near.y as f32
            && y < near.bottom() as f32)
        {
            return;
        }
        let (cx, cy) = (x.floor() as i32, y.floor() as i32);
        for dy in -9..=9 {
            for dx in -9..=9 {
                let d = ((dx * dx + dy * dy) as f32).sqrt();
                if (6.0..8.0).contains(&d) {
                    cv.put_clipped(cx + dx, cy + dy, MARK, clip);
                } else if (5.0..6.0).contains(&d) || (8.0..9.0).contains(&d) {
                    cv.put_clipped(cx + dx, cy + dy, BLACK, clip);
                }
            }
        }
        let w = text_width(label);
        let mut tx = cx + 11;
        if tx.saturating_add(w) > clip.right() {
            tx = (cx - 11).saturating_sub(w);
        }
        let mut ty = cy - 9 - CAP_H;
        if ty < clip.y {
            ty = cy + 10;
        }
        cv.text_outlined(tx, ty, label, MARK, clip);
    }
}

/// Vertical colour bar from 0 (bottom) to the maximum (top), with its two labels.
fn draw_colorbar(cv: &mut Canvas, cmap: &Colormap, r: Rect, labels: &[String; 2]) {
    for row in 0..r.h {
        let t = if r.h > 1 {
            1.0 - row as f32 / (r.h - 1) as f32
        } else {
            1.0
        };
        cv.fill(Rect::new(r.x, r.y + row, r.w, 1), cmap.at(t));
    }
    cv.frame(r, BLACK);
    let full = cv.bounds();
    let x = r.right() + 1;
    for (y, label) in [(r.bottom() - 1, &labels[0]), (r.y, &labels[1])] {
        cv.fill(Rect::new(x, y, TICK, 1), BLACK);
        let ty = (y - CAP_H / 2).min(r.bottom() - CAP_H + 2).max(r.y - 2);
        cv.text(x + TICK + TICK_GAP, ty, label, BLACK, full);
    }
}

// ---------------------------------------------------------------------------------------
// Ticks

/// Tick positions and labels for an axis: "nice" steps (1, 2, 2.5, 5 × 10^k) inside the
/// sample range, as many as fit without the labels touching.
fn ticks(axis: &Axis, horizontal: bool) -> Vec<(f32, String)> {
    let (lo, hi) = axis.range();
    if axis.degenerate() {
        return vec![(axis.c[0], format_coord(axis.c[0], 2))];
    }
    for count in (2..=12).rev() {
        let (values, step) = nice_values(lo, hi, count);
        let decimals = decimals(step);
        let labels: Vec<(f32, String)> = values
            .iter()
            .map(|&v| (v, format_coord(v, decimals)))
            .collect();
        let need = if horizontal {
            labels.iter().map(|(_, l)| text_width(l)).max().unwrap_or(0) + ADV
        } else {
            GLYPH_H + 8
        };
        if labels.len() >= 2 && axis.pixels_per(step) >= need as f32 {
            return labels;
        }
    }
    // Not even two ticks fit: label the first sample only.
    vec![(axis.c[0], format_coord(axis.c[0], 2))]
}

/// About `count` multiples of a nice step inside `[lo, hi]`, and the step.
fn nice_values(lo: f32, hi: f32, count: usize) -> (Vec<f32>, f32) {
    let (lo, hi) = (f64::from(lo), f64::from(hi));
    let raw = (hi - lo) / count as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|&s| s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag);
    let first = (lo / step - 1e-6).ceil();
    let values = (0..=count + 1)
        .map(|k| (first + k as f64) * step)
        .take_while(|&v| v <= hi + 1e-6 * step)
        .map(|v| if v.abs() < 1e-9 * step { 0.0 } else { v as f32 })
        .collect();
    (values, step as f32)
}

/// Decimals (at least 2, the usual centimetre precision) that show multiples of `step`.
fn decimals(step: f32) -> usize {
    let step = f64::from(step);
    (2..=6)
        .find(|&d| {
            let scaled = step * 10f64.powi(d as i32);
            (scaled - scaled.round()).abs() < 1e-3
        })
        .unwrap_or(6)
}

fn format_coord(v: f32, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    // No "-0.00".
    if s.trim_start_matches('-')
        .bytes()
        .all(|b| b == b'0' || b == b'.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

mod canvas;
mod font;
pub mod plot;

use canvas::*;
use font::*;

#[cfg(test)]
mod tests;
