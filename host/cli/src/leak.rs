//! The leak correction of `column`, `row` and `relight` (on by default, as `indirect`'s): Γ
//! over the probe's volume, the capture's direct-return windows of Γ zeroed as the rows
//! stream in (`vltm::probe::leak`), and the line that says how much was removed.

use vltm::io::RowSource;
use vltm::probe::{self, LeakOptions};
use vltm::volume::Volume;

use crate::args::Common;
use crate::console::{Failure, say};

/// Runs `probe` on the rows of `src`, leak-corrected with Γ = direct light above
/// `epsilon`·max over `volume` (an extra diagonal pass), or on `src` as it is when `epsilon`
/// is `None` (`--no-leak-correct`).
pub(crate) fn corrected<T>(
    src: &mut dyn RowSource,
    volume: &Volume,
    epsilon: Option<f32>,
    common: &Common,
    probe: impl FnOnce(&mut dyn RowSource) -> vltm::Result<T>,
) -> Result<T, Failure> {
    let Some(e) = epsilon else {
        return Ok(probe(src)?);
    };
    let model = probe::fit_over_volume(
        src,
        volume,
        e,
        &common.wave(),
        &LeakOptions::default(),
        common.exec(),
    )?;
    say!(
        "leak correction (--no-leak-correct to skip): {:.4} of the capture's energy was in the 3-vertex windows of Γ's {} voxels and removed ({:.2} s)",
        model.explained,
        model.points().len(),
        model.seconds
    );
    let mut lc = probe::LeakCorrected::new(src, &model);
    Ok(probe(&mut lc)?)
}
