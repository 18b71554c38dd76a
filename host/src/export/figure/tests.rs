//! Unit tests of the figures.

use super::*;

fn top_colour() -> Rgb<u8> {
    Rgb(colorous::INFERNO.eval_continuous(1.0).into_array())
}

fn tmp(name: &str) -> crate::scratch::Scratch {
    crate::scratch::Scratch::file("figure-test", name)
}

/// Pixels of `img` equal to `c`, outside `exclude`.
fn pixels_of(img: &RgbImage, c: Rgb<u8>, exclude: Rect) -> Vec<(i32, i32)> {
    img.enumerate_pixels()
        .filter(|(x, y, p)| **p == c && !exclude.contains(*x as i32, *y as i32))
        .map(|(x, y, _)| (x as i32, y as i32))
        .collect()
}

fn block_of(panel: &Panel, col: usize, row: usize, block: usize) -> Rect {
    let b = block as i32;
    Rect::new(
        panel.rect.x + col as i32 * b,
        panel.rect.y + row as i32 * b,
        b,
        b,
    )
}

#[test]
fn bright_voxel_appears_at_its_place_in_both_panels() {
    let shape = [10, 8, 6];
    let (ix, iy, iz) = (3, 5, 2);
    let mut data = vec![0.0f32; 10 * 8 * 6];
    data[(ix * 8 + iy) * 6 + iz] = 7.0e4;
    data[(8 * 8 + 1) * 6 + 4] = 2.0e4; // a dimmer voxel elsewhere
    data[(8 * 8 + 2) * 6 + 5] = f32::NAN;
    let fig = Figure {
        title: "one bright voxel".into(),
        ..Figure::new(&data, shape, [-0.5, 0.5], [-0.4, 0.3], [0.5, 1.0])
    };
    let img = fig.render();
    let layout = Layout::new(&fig, 7.0e4);
    assert_eq!(
        img.dimensions(),
        (layout.width as u32, layout.height as u32)
    );
    // Each voxel is a 32×32 block (320 / nx); columns go to the left (x increasing to the
    // left: the view from the wall), front rows and top rows go up (z away from the wall).
    let block = 32;
    assert_eq!((layout.front.rect.w, layout.front.rect.h), (320, 8 * 32));
    assert_eq!((layout.top.rect.w, layout.top.rect.h), (320, 6 * 32));
    let front = block_of(&layout.front, 10 - 1 - ix, 8 - 1 - iy, block);
    let top = block_of(&layout.top, 10 - 1 - ix, 6 - 1 - iz, block);
    let hot = pixels_of(&img, top_colour(), layout.cbar);
    assert_eq!(hot.len(), 2 * block * block, "exactly the two blocks");
    assert!(
        hot.iter()
            .all(|&(x, y)| front.contains(x, y) || top.contains(x, y))
    );
    for r in [front, top] {
        assert_eq!(
            *img.get_pixel((r.x + 16) as u32, (r.y + 16) as u32),
            top_colour()
        );
    }
    // The colour bar's top row is the same colour; its bottom row is the colormap's 0.
    let bar = layout.cbar;
    assert_eq!(*img.get_pixel(bar.x as u32 + 2, bar.y as u32), top_colour());
    let zero = Rgb(colorous::INFERNO.eval_continuous(0.0).into_array());
    assert_eq!(
        *img.get_pixel(bar.x as u32 + 2, (bar.bottom() - 1) as u32),
        zero
    );
    // The NaN voxel is drawn as 0, the dimmer one at 2/7 of the scale.
    let dim = block_of(&layout.front, 10 - 1 - 8, 8 - 1 - 1, block);
    let expect = Rgb(colorous::INFERNO
        .eval_rational((255.0f32 * 2.0 / 7.0).round() as usize, 256)
        .into_array());
    assert_eq!(*img.get_pixel(dim.x as u32 + 5, dim.y as u32 + 5), expect);
    let nan = block_of(&layout.front, 10 - 1 - 8, 8 - 1 - 2, block);
    assert_eq!(*img.get_pixel(nan.x as u32 + 5, nan.y as u32 + 5), zero);
}

#[test]
fn decreasing_coordinates_are_drawn_in_the_same_direction() {
    let mut data = vec![0.0f32; 16 * 4 * 4];
    // ix = 0 is x = +0.5: the largest x, drawn at the LEFT edge (x grows to the left);
    // iy = 0 is y = 0, the bottom; iz = 0 is z = 0.5, nearest the wall: the top view's bottom.
    data[0] = 1.0;
    let fig = Figure::new(&data, [16, 4, 4], [0.5, -0.5], [0.0, 0.3], [0.5, 0.8]);
    let img = fig.render();
    let layout = Layout::new(&fig, 1.0);
    let hot = pixels_of(&img, top_colour(), layout.cbar);
    let front = block_of(&layout.front, 0, 3, 20);
    let top = block_of(&layout.top, 0, 3, 20);
    assert_eq!(hot.len(), 2 * 20 * 20);
    assert!(
        hot.iter()
            .all(|&(x, y)| front.contains(x, y) || top.contains(x, y))
    );
}

/// A sign facing the wall, drawn into a volume as a person at the wall reads it (their right
/// is −x), must come out of the front view reading the same, not mirrored: the front panel,
/// sampled once per voxel block, equals the glyph, and differs from its mirror image.
#[test]
fn a_sign_facing_the_wall_reads_as_seen_from_the_wall() {
    // 'R' is not mirror-symmetric: its mirror image differs from it.
    let rows = glyph('R');
    let (nx, ny, nz) = (5, 7, 2);
    let on = |col: usize, row: usize| rows[row] >> (4 - col) & 1 == 1;
    assert!((0..7).any(|r| (0..5).any(|c| on(c, r) != on(4 - c, r))));
    let mut data = vec![0.0f32; nx * ny * nz];
    for ix in 0..nx {
        for iy in 0..ny {
            // Seen from the wall: column 0 (the viewer's left) is the largest x; row 0 (top)
            // the largest y.
            if on(nx - 1 - ix, ny - 1 - iy) {
                data[(ix * ny + iy) * nz + 1] = 1.0;
            }
        }
    }
    let fig = Figure::new(&data, [nx, ny, nz], [-0.2, 0.2], [-0.3, 0.3], [0.7, 0.8]);
    let img = fig.render();
    let layout = Layout::new(&fig, 1.0);
    let block = layout.front.rect.w as usize / nx;
    let drawn = |col: usize, row: usize| {
        let r = block_of(&layout.front, col, row, block);
        *img.get_pixel((r.x + r.w / 2) as u32, (r.y + r.h / 2) as u32) == top_colour()
    };
    let mut mirrored = false;
    for row in 0..ny {
        for col in 0..nx {
            assert_eq!(
                drawn(col, row),
                on(col, row),
                "pixel ({col}, {row}) of the R"
            );
            mirrored |= drawn(col, row) != on(nx - 1 - col, row);
        }
    }
    assert!(mirrored, "the glyph is not told from its mirror image");
    // The tick labels say so: x decreases from left to right, y and z increase upward.
    for (panel, v) in [(&layout.front, 0.0), (&layout.top, 0.75)] {
        let xs: Vec<(f32, f32)> = panel
            .h_ticks
            .iter()
            .map(|(c, _)| (panel.screen(*c, v).0, *c))
            .collect();
        assert!(xs.len() >= 2, "{xs:?}");
        for w in xs.windows(2) {
            assert!(w[0].1 < w[1].1 && w[0].0 > w[1].0, "x ticks {xs:?}");
        }
        let ys: Vec<(f32, f32)> = panel
            .v_ticks
            .iter()
            .map(|(c, _)| (panel.screen(0.0, *c).1, *c))
            .collect();
        for w in ys.windows(2) {
            assert!(w[0].1 < w[1].1 && w[0].0 > w[1].0, "vertical ticks {ys:?}");
        }
    }
    assert_eq!(layout.front.labels[0], X_LABEL);
    assert_eq!(layout.top.labels[0], X_LABEL);
}

#[test]
fn shape_mismatch_and_bad_coordinates_are_argument_errors() {
    let data = [1.0f32; 5];
    let path = tmp("never-written.png");
    for fig in [
        Figure::new(&data, [2, 2, 2], [0.0, 1.0], [0.0, 1.0], [0.0, 1.0]),
        Figure::new(&data, [5, 0, 1], [0.0, 1.0], [0.0, 1.0], [0.0, 1.0]),
        Figure::new(
            &data,
            [usize::MAX, 2, 3],
            [0.0, 1.0],
            [0.0, 1.0],
            [0.0, 1.0],
        ),
        Figure::new(&data, [5, 1, 1], [0.0, f32::NAN], [0.0, 1.0], [0.0, 1.0]),
    ] {
        let err = fig.write_png(&path).unwrap_err();
        assert!(
            matches!(err, Error::Argument { ref arg, .. } if arg == "volume"),
            "{err}"
        );
        // render() does not panic either: it shows the error.
        let img = fig.render();
        assert!(img.width() > 100 && img.height() > 20);
    }
    assert!(!path.exists());
}

#[test]
fn degenerate_volumes_do_not_panic() {
    let nan = [f32::NAN];
    let cases: Vec<(Vec<f32>, [usize; 3])> = vec![
        (vec![f32::NAN], [1, 1, 1]),
        (vec![3.0], [1, 1, 1]),
        (vec![0.0; 7], [1, 7, 1]),
        (vec![f32::NAN; 12], [3, 1, 4]),
        (vec![f32::INFINITY, -1.0, f32::NEG_INFINITY, 2.0], [4, 1, 1]),
        (vec![-5.0; 8], [2, 2, 2]),
        (vec![1.0e-40; 8], [2, 2, 2]),
        ((0..3000).map(|i| i as f32).collect(), [1500, 2, 1]),
        ((0..2000).map(|i| i as f32).collect(), [1, 1000, 2]),
    ];
    for (data, shape) in &cases {
        for coords in [[0.0, 1.0], [0.3, 0.3], [1.0e-7, 2.0e-7], [-1.0e30, 1.0e30]] {
            let mut fig = Figure::new(data, *shape, coords, coords, coords);
            fig.title = "a title that is long enough to need wrapping over more than a single line of the figure, \
                         with λ = 5 cm, σ, μ and unknown glyphs ☃"
                .repeat(3);
            fig.marks = vec![
                ([0.5, 0.5, 0.5], "A".into()),
                ([f32::NAN, 0.0, 0.0], "nan".into()),
                ([9.0, -9.0, 9.0], "far".into()),
                ([0.1, 0.1, 0.1], "x".repeat(100_000)),
            ];
            let img = fig.render();
            assert!(
                img.width() >= PANEL_MIN_W as u32 && img.width() < 4000,
                "{shape:?}: {}",
                img.width()
            );
            assert!(
                img.height() >= PANEL_MIN_H as u32 && img.height() < 1200,
                "{shape:?}: {}",
                img.height()
            );
        }
    }
    let _ = Figure::new(&nan, [1, 1, 1], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]).render();
}

#[test]
fn write_png_writes_a_readable_png() {
    let data: Vec<f32> = (0..40 * 30 * 20).map(|i| (i % 97) as f32).collect();
    let mut fig = Figure::new(&data, [40, 30, 20], [-0.5, 0.5], [-0.4, 0.4], [0.3, 1.2]);
    fig.title = "test".into();
    fig.marks.push(([0.0, 0.0, 0.8], "A".into()));
    let path = tmp("figure.png");
    fig.write_png(&path).unwrap();
    let png = image::open(&path).unwrap().to_rgb8();
    let rendered = fig.render();
    assert_eq!(png.dimensions(), rendered.dimensions());
    assert_eq!(png, rendered);
    // 320 px panels side by side plus gutters and the colour bar.
    assert!(
        png.width() > 2 * 320 && png.width() < 2 * 320 + 400,
        "{}",
        png.width()
    );
    let err = fig
        .write_png(&tmp("no-such-dir").join("x").join("f.png"))
        .unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err}");
}

#[test]
fn ticks_are_nice_and_fit() {
    let x = Axis::new(40, [-0.5, 0.5], 8, PANEL_MIN_W, PANEL_MAX_W);
    let labels: Vec<String> = ticks(&x, true).into_iter().map(|(_, l)| l).collect();
    assert!(
        labels.contains(&"-0.50".to_string()) && labels.contains(&"0.00".to_string()),
        "{labels:?}"
    );
    assert!(
        labels.contains(&"0.50".to_string()) || labels.contains(&"0.25".to_string()),
        "{labels:?}"
    );
    let z = Axis::new(20, [0.3, 1.2], 8, PANEL_MIN_H, PANEL_MAX_H);
    let t = ticks(&z, false);
    assert!(t.len() >= 3, "{t:?}");
    for w in t.windows(2) {
        assert!(
            z.pixels_per(w[1].0 - w[0].0) >= (GLYPH_H + 8) as f32,
            "{t:?}"
        );
    }
    assert!(
        t.iter()
            .all(|&(v, _)| (0.3 - 1e-6..=1.2 + 1e-6).contains(&v))
    );
    assert_eq!(
        ticks(&Axis::new(1, [0.8, 0.8], 8, 80, 800), false),
        vec![(0.8, "0.80".to_string())]
    );
    let fine = Axis::new(50, [0.0, 0.01], 8, PANEL_MIN_W, PANEL_MAX_W);
    let t = ticks(&fine, true);
    assert!(
        t.len() >= 3 && t.iter().all(|(_, l)| l.len() == 5) && t.iter().any(|(_, l)| l == "0.010"),
        "{t:?}"
    );
}

#[test]
fn number_formats() {
    assert_eq!(format_sci(1.3e5), "1.3e5");
    assert_eq!(format_sci(0.0), "0");
    assert_eq!(format_sci(2.0e-3), "2.0e-3");
    assert_eq!(format_coord(-0.0001, 2), "0.00");
    assert_eq!(format_coord(-0.25, 2), "-0.25");
    assert_eq!(decimals(0.25), 2);
    assert_eq!(decimals(0.025), 3);
}

#[test]
fn wrap_breaks_words_and_limits_lines() {
    assert_eq!(
        wrap("front and top views", 10),
        vec!["front and", "top views"]
    );
    assert_eq!(wrap("", 10), Vec::<String>::new());
    assert_eq!(wrap("abcdefghijkl", 5), vec!["abcde", "fghij", "kl"]);
    let long = wrap(&"word ".repeat(100), 12);
    assert_eq!(long.len(), MAX_TITLE_LINES);
    assert!(
        long[MAX_TITLE_LINES - 1].ends_with("...") && long.iter().all(|l| l.chars().count() <= 12)
    );
}

#[test]
fn glyphs_fit_their_cell() {
    for c in (' '..='~').chain("λσμΓΔ×±°−☃".chars()) {
        assert!(glyph(c).iter().all(|&row| row < 32), "{c}");
    }
    assert_eq!(glyph('☃'), glyph('?'));
    assert_eq!(glyph(' '), [0; 8]);
    assert_ne!(glyph('a'), glyph('A'));
    assert_eq!(text_width("0.50"), 4 * ADV - SCALE);
}
