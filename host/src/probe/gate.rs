//! The time gate of a column ([`ColumnGate`]): two-bounce, higher-order or none. Its own
//! module because the column, the diagonal and the empty-window rule all take it (and the
//! column imports the other two).

/// The time gate of a column (the CLI's `--gate`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColumnGate {
    /// 4-vertex Gaussian gate (Eq. 14): first-order indirect light from `x_a`.
    TwoBounce,
    /// The late gate (Eq. 18): higher-order indirect light.
    HigherOrder,
    /// No gate (the paper's Fig. 6 control).
    None,
}
