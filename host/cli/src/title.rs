//! Figure titles: the command line's words (`column --focus … --gate two-bounce`) and the
//! parameters that decide the picture (λ, σ, the leak correction), so that a PNG says how it
//! was made.

use clap::ValueEnum;
use vltm_kernel::{Config, Point};

use crate::leak::Used;

/// A point as typed on the command line: `X,Y,Z` with the shortest decimals.
fn point(p: Point) -> String {
    format!("{},{},{}", p[0], p[1], p[2])
}

/// The spelling of a value-enum argument on the command line (`two-bounce`).
pub(crate) fn arg<T: ValueEnum>(v: &T) -> String {
    v.to_possible_value()
        .map_or_else(String::new, |p| p.get_name().to_string())
}

/// ` (λ = … m, σ = … m)` of a probe's configuration, with `extra` after a `;`.
fn wave(cfg: &Config, extra: &str) -> String {
    let sep = if extra.is_empty() { "" } else { "; " };
    format!(
        " (λ = {:.3} m, σ = {:.3} m{sep}{extra})",
        cfg.wavelength(),
        cfg.sigma()
    )
}

/// What the column's options were, beyond the focus and the gate.
pub(crate) struct ColumnWords<'a> {
    /// `--gate` as typed.
    pub(crate) gate: String,
    /// `--shell R0:R1` when given.
    pub(crate) shell: Option<&'a str>,
    /// `--mask-epsilon E` when given.
    pub(crate) mask_epsilon: Option<f32>,
    /// How the capture's direct light was removed first (`None`: it was not).
    pub(crate) leak: Option<Used>,
}

/// `column --focus X,Y,Z --gate G [--shell ..] [--mask-epsilon ..] (λ, σ; correction)`.
pub(crate) fn column(focus: Point, w: &ColumnWords<'_>, cfg: &Config) -> String {
    let mut t = format!("column --focus {} --gate {}", point(focus), w.gate);
    if let Some(s) = w.shell {
        t += &format!(" --shell {s}");
    }
    if let Some(e) = w.mask_epsilon {
        t += &format!(" --mask-epsilon {e}");
    }
    t + &wave(cfg, correction(w.leak))
}

/// A column merged from partial states (`vltm merge`): parts are never leak-corrected.
pub(crate) fn merged_column(focus: Point, cfg: &Config) -> String {
    format!(
        "column --focus {} --no-leak-correct, merged parts",
        point(focus)
    ) + &wave(cfg, "")
}

/// The words of the leak correction: `leak-corrected` (the windows), `surface model
/// subtracted`, or the flag that turned it off.
fn correction(leak: Option<Used>) -> &'static str {
    match leak {
        Some(Used::Gate) => "leak-corrected",
        Some(Used::Model) => "surface model subtracted",
        None => "--no-leak-correct",
    }
}

/// `row --focus X,Y,Z (λ, σ; two-bounce gate, correction)`.
pub(crate) fn row(focus: Point, leak: Option<Used>, cfg: &Config) -> String {
    let extra = format!("two-bounce gate, {}", correction(leak));
    format!("row --focus {}", point(focus)) + &wave(cfg, &extra)
}

/// `relight --pattern: N foci (λ, σ; two-bounce gate, correction)`.
pub(crate) fn relight(foci: usize, leak: Option<Used>, cfg: &Config) -> String {
    let extra = format!("two-bounce gate, {}", correction(leak));
    format!("relight --pattern: {foci} foci") + &wave(cfg, &extra)
}

/// `direct --gate G (λ, σ)`.
pub(crate) fn direct(gate: &str, cfg: &Config) -> String {
    format!("direct --gate {gate}") + &wave(cfg, "")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::args::{DiagGateArg, GateArg};
    use vltm_kernel::Params;

    /// λ = 0.4 m, σ = 2λ/3 (the defaults on a wall of 0.2 m pitch).
    fn cfg() -> Config {
        Config::try_new(&Params::new(0.4, 300, 0.01)).expect("config")
    }

    #[test]
    fn column_title_uses_the_command_lines_words() {
        let w = ColumnWords {
            gate: arg(&GateArg::TwoBounce),
            shell: None,
            mask_epsilon: None,
            leak: Some(Used::Gate),
        };
        let t = column([-0.5, 0.0, 0.75], &w, &cfg());
        assert_eq!(
            t,
            "column --focus -0.5,0,0.75 --gate two-bounce (λ = 0.400 m, σ = 0.267 m; leak-corrected)"
        );
        assert!(!t.contains("TwoBounce"), "{t}");
        let w = ColumnWords {
            gate: arg(&GateArg::HigherOrder),
            shell: Some("0.3:2"),
            mask_epsilon: Some(0.2),
            leak: None,
        };
        assert_eq!(
            column([0.1, 0.0, 0.8], &w, &cfg()),
            "column --focus 0.1,0,0.8 --gate higher-order --shell 0.3:2 --mask-epsilon 0.2 (λ = 0.400 m, σ = 0.267 m; --no-leak-correct)"
        );
    }

    #[test]
    fn other_titles_carry_focus_and_wave() {
        assert_eq!(
            row([0.25, 0.0, 0.9], Some(Used::Gate), &cfg()),
            "row --focus 0.25,0,0.9 (λ = 0.400 m, σ = 0.267 m; two-bounce gate, leak-corrected)"
        );
        assert_eq!(
            relight(3, None, &cfg()),
            "relight --pattern: 3 foci (λ = 0.400 m, σ = 0.267 m; two-bounce gate, --no-leak-correct)"
        );
        assert_eq!(
            row([0.25, 0.0, 0.9], Some(Used::Model), &cfg()),
            "row --focus 0.25,0,0.9 (λ = 0.400 m, σ = 0.267 m; two-bounce gate, surface model subtracted)"
        );
        assert_eq!(
            merged_column([0.1, 0.0, 0.8], &cfg()),
            "column --focus 0.1,0,0.8 --no-leak-correct, merged parts (λ = 0.400 m, σ = 0.267 m)"
        );
        assert_eq!(
            direct(&arg(&DiagGateArg::Gaussian), &cfg()),
            "direct --gate gaussian (λ = 0.400 m, σ = 0.267 m)"
        );
    }
}
