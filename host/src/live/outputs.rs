//! The files of a live run ([`Outputs`]): volumes, figures, states and the transient's plot,
//! named from `--out` and written all or nothing.

use std::path::{Path, PathBuf};

use super::run::LiveRun;
use super::view::View;
use crate::atomic::Transaction;
use crate::error::{Error, Result};

/// Output paths of a live run, from `--out F.npy` (or `F.h5`): probe `tag` is written to
/// `F.npy` for the direct light and `F.<tag>.npy` otherwise, its figure beside it as `.png`,
/// its state as `F.<tag>.part`; the summed transient as `F.transient.png`.
#[derive(Clone, Debug)]
pub struct Outputs {
    /// `--out`.
    pub out: PathBuf,
}

impl Outputs {
    fn tagged(&self, tag: Option<&str>, ext: &str) -> PathBuf {
        let stem = self.out.file_stem().unwrap_or_default().to_string_lossy();
        let name = match tag {
            Some(t) => format!("{stem}.{t}.{ext}"),
            None => format!("{stem}.{ext}"),
        };
        self.out.with_file_name(name)
    }

    fn main_tag(tag: &str) -> Option<&str> {
        (tag != "direct").then_some(tag)
    }

    /// The volume file of probe `tag`.
    pub fn volume(&self, tag: &str) -> PathBuf {
        let ext = self
            .out
            .extension()
            .map_or_else(|| "npy".to_string(), |e| e.to_string_lossy().into_owned());
        self.tagged(Self::main_tag(tag), &ext)
    }

    /// The figure of probe `tag`.
    pub fn png(&self, tag: &str) -> PathBuf {
        self.tagged(Self::main_tag(tag), "png")
    }

    /// The partial state of probe `tag`.
    pub fn state(&self, tag: &str) -> PathBuf {
        self.tagged(Some(tag), "part")
    }

    /// The summed transient's plot.
    pub fn transient(&self) -> PathBuf {
        self.tagged(Some("transient"), "png")
    }

    /// Every file the run writes for `tags`.
    pub fn all(&self, tags: &[&str]) -> Vec<PathBuf> {
        let mut v = vec![self.transient()];
        for t in tags {
            v.extend([self.volume(t), self.png(t), self.state(t)]);
        }
        v
    }

    /// Writes `views` (volumes and figures), the states of `run` and the transient, all or
    /// nothing.
    ///
    /// # Errors
    /// [`Error::Io`] and encoder errors; nothing is replaced then.
    pub fn write(&self, run: &LiveRun, views: &[View], capture: &Path) -> Result<Vec<PathBuf>> {
        let mut t = Transaction::new();
        let mut wrote = Vec::new();
        let volume = &run.opts.volume;
        for v in views {
            let p = self.volume(&v.tag);
            if crate::io::is_hdf5(&p) {
                let probe = run.probes.iter().find(|q| q.tag == v.tag);
                let cfg = match probe {
                    Some(q) => q.state.preview()?.output.config,
                    None => run.opts.wave.config(run.geometry())?,
                };
                let focus = probe.and_then(|q| q.state.focus());
                let meta = crate::export::h5::Provenance {
                    probe: &v.tag,
                    config: &cfg,
                    focus,
                    capture,
                };
                crate::export::h5::stage_volume(&mut t, &p, &v.values, volume, &meta)?;
            } else {
                crate::export::npy::stage_f32(&mut t, &p, &v.values, &volume.shape)?;
            }
            wrote.push(p);
            if !v.png.is_empty() {
                let p = self.png(&v.tag);
                t.stage(&p, |f| {
                    std::io::Write::write_all(f, &v.png).map_err(|e| Error::io(&p, e))
                })?;
                wrote.push(p);
            }
        }
        for q in &run.probes {
            let p = self.state(&q.tag);
            let bytes = q.state.to_bytes();
            t.stage(&p, |f| {
                std::io::Write::write_all(f, &bytes).map_err(|e| Error::io(&p, e))
            })?;
            wrote.push(p);
        }
        if let Some(png) = run.transient_png() {
            let p = self.transient();
            t.stage(&p, |f| {
                std::io::Write::write_all(f, &png).map_err(|e| Error::io(&p, e))
            })?;
            wrote.push(p);
        }
        t.commit()?;
        Ok(wrote)
    }
}
