//! What a live run shows: [`View`] (a volume with its figure and peak, made by [`view`]), the
//! views of every probe from the rows folded so far, and the summed transient's plot.

use super::run::LiveRun;
use crate::error::{Error, Result};
use crate::export::figure::Figure;
use crate::export::figure::plot::Transient;
use crate::probe::partial::Task;
use crate::volume::Volume;
use vltm_kernel::Point;

/// One volume to show and write: a probe's preview (or final) volume.
#[derive(Clone, Debug)]
pub struct View {
    /// `direct`, `column0`, …, `indirect`.
    pub tag: String,
    /// Figure title.
    pub title: String,
    /// One value per voxel.
    pub values: Vec<f32>,
    /// The figure (front and top views, axes, colour bar) as PNG bytes (empty for a point
    /// list volume).
    pub png: Vec<u8>,
    /// Focus marks drawn on the figure.
    pub marks: Vec<(Point, String)>,
    /// Peak value and its voxel.
    pub peak: (f32, Point),
}

fn encode_png(img: &image::RgbImage) -> Result<Vec<u8>> {
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| Error::io("png", std::io::Error::other(e)))?;
    Ok(png.into_inner())
}

/// A view of `values` over `volume` with its figure.
///
/// # Errors
/// PNG encoding errors.
pub fn view(
    tag: &str,
    title: &str,
    values: Vec<f32>,
    volume: &Volume,
    marks: Vec<(Point, String)>,
) -> Result<View> {
    let png = match volume.axes {
        Some([x, y, z]) => encode_png(
            &Figure {
                data: &values,
                shape: volume.shape,
                x,
                y,
                z,
                title: title.to_string(),
                marks: marks.clone(),
            }
            .render(),
        )?,
        None => Vec::new(),
    };
    let (i, m) =
        values.iter().enumerate().fold(
            (0, f32::NEG_INFINITY),
            |a, (i, &x)| if x > a.1 { (i, x) } else { a },
        );
    let p = volume.points.get(i).copied().unwrap_or_default();
    Ok(View {
        tag: tag.to_string(),
        title: title.to_string(),
        values,
        png,
        marks,
        peak: (m, p),
    })
}

impl LiveRun {
    /// The views of every probe from the rows folded so far (titles say how many).
    ///
    /// # Errors
    /// As [`LiveRun::preview`].
    pub fn views(&self) -> Result<Vec<View>> {
        let mut out = Vec::new();
        for (i, p) in self.probes.iter().enumerate() {
            let f = self.preview(i)?;
            let marks = match p.task {
                Task::Column { focus, .. } => vec![(focus, "x_a".to_string())],
                _ => Vec::new(),
            };
            let title = if self.complete() {
                p.title.clone()
            } else if self.held.iter().all(|h| h.start == 0) {
                format!(
                    "{} (rows 0:{} of {})",
                    p.title,
                    self.folded,
                    self.total_rows()
                )
            } else {
                format!(
                    "{} ({} of {} rows)",
                    p.title,
                    self.folded,
                    self.total_rows()
                )
            };
            out.push(view(&p.tag, &title, f.output.values, &f.volume, marks)?);
        }
        Ok(out)
    }

    /// The summed transient's plot (log counts against path length) as PNG bytes; `None`
    /// while no count is positive.
    pub fn transient_png(&self) -> Option<Vec<u8>> {
        let g = &self.capture.geometry;
        let t = Transient {
            counts: &self.transient,
            t0: g.t0,
            dt: g.dt,
            title: format!(
                "summed transient, rows 0:{} of {}",
                self.received,
                self.total_rows()
            ),
            shade: None,
        };
        encode_png(&t.render().ok()?).ok()
    }
}
