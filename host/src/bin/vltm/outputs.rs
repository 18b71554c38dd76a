//! Writing a probe's outputs: one volume and its figure, or several parts of one run (the
//! near, middle and far shells; Γ and `I_d` beside `I_i`) named `F.<part>.npy` /
//! `F.<part>.png` after `--out F.npy` / `--png F.png`, all in one transaction (all or
//! nothing).

use std::path::{Path, PathBuf};

use anyhow::Context;
use vltm::atomic::Transaction;
use vltm::io;
use vltm::out::figure::Figure;
use vltm::out::h5::Provenance;
use vltm::volume::Volume;
use vltm_kernel::Point;

use crate::Failure;

/// One output volume of a run: its name part (`None` for the main output), values, title.
pub(crate) struct Part<'a> {
    /// Inserted before the extension: `F.npy` → `F.<tag>.npy`.
    pub(crate) tag: Option<&'a str>,
    /// One value per voxel.
    pub(crate) values: &'a [f32],
    /// The figure's title.
    pub(crate) title: String,
}

/// `F.npy` → `F.<tag>.npy` (the tag before the last extension).
pub(crate) fn tagged(p: &Path, tag: Option<&str>) -> PathBuf {
    let Some(tag) = tag else {
        return p.to_path_buf();
    };
    match (p.file_stem(), p.extension()) {
        (Some(stem), Some(ext)) => p.with_file_name(format!(
            "{}.{tag}.{}",
            stem.to_string_lossy(),
            ext.to_string_lossy()
        )),
        _ => p.with_file_name(format!(
            "{}.{tag}",
            p.file_name().unwrap_or_default().to_string_lossy()
        )),
    }
}

/// Writes the volume (`c`: `--out` and `--png`; `--out`: `.npy`, or HDF5 for `.h5`/`.hdf5`) and the figure (`--png`);
/// with neither, `<probe>.npy` and `<probe>.png`.
pub(crate) fn write_outputs(
    c: (&Option<PathBuf>, &Option<PathBuf>),
    meta: &Provenance<'_>,
    v: &[f32],
    volume: &Volume,
    title: &str,
    marks: &[(Point, String)],
) -> Result<(), Failure> {
    let part = Part {
        tag: None,
        values: v,
        title: title.to_string(),
    };
    write_parts(c, meta, &[part], volume, marks)
}

/// Writes every part (see [`Part`]) in one transaction.
pub(crate) fn write_parts(
    (c_out, c_png): (&Option<PathBuf>, &Option<PathBuf>),
    meta: &Provenance<'_>,
    parts: &[Part<'_>],
    volume: &Volume,
    marks: &[(Point, String)],
) -> Result<(), Failure> {
    let stem = meta.probe;
    let (out, png) = match (c_out, c_png) {
        (None, None) => (
            Some(PathBuf::from(format!("{stem}.npy"))),
            Some(PathBuf::from(format!("{stem}.png"))),
        ),
        (a, b) => (a.clone(), b.clone()),
    };
    // The volumes and their figures: all or nothing.
    let mut t = Transaction::new();
    let mut wrote = Vec::new();
    for part in parts {
        let v = part.values;
        if let Some(p) = out.as_deref().map(|p| tagged(p, part.tag)) {
            if io::is_hdf5(&p) {
                vltm::out::h5::stage_volume(&mut t, &p, v, volume, meta)
            } else {
                vltm::out::npy::stage_f32(&mut t, &p, v, &volume.shape)
            }
            .with_context(|| format!("writing {}", p.display()))?;
            wrote.push(p);
        }
        if let Some(p) = png.as_deref().map(|p| tagged(p, part.tag)) {
            match volume.axes {
                Some([x, y, z]) => {
                    let fig = Figure {
                        data: v,
                        shape: volume.shape,
                        x,
                        y,
                        z,
                        title: part.title.clone(),
                        marks: marks.to_vec(),
                    };
                    fig.stage_png(&mut t, &p)
                        .with_context(|| format!("writing {}", p.display()))?;
                    wrote.push(p);
                }
                None if part.tag.is_none() => {
                    tell!("vltm: note: no figure for a point list (only for grid volumes)");
                }
                None => {}
            }
        }
    }
    t.commit()?;
    for p in &wrote {
        say!("wrote {}", p.display());
    }
    Ok(())
}
