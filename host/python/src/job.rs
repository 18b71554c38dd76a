//! What each probe of [`crate::run`] needs beyond the options every probe shares.

use vltm::probe::{ColumnGate, IndirectOptions, Pattern, Shell};
use vltm_kernel::Point;

/// What each probe needs beyond the shared options.
pub(crate) enum Job {
    Direct {
        gate: ColumnGate,
    },
    Column {
        focus: Point,
        gate: ColumnGate,
        shell: Shell,
        shells: Option<[Shell; 3]>,
        mask_epsilon: Option<f32>,
        leak_epsilon: Option<f32>,
    },
    Indirect {
        opts: IndirectOptions,
        shells: Option<[Shell; 3]>,
        direct: Option<Vec<f32>>,
    },
    Matrix {
        from: Vec<Point>,
    },
    Relight {
        pattern: Pattern,
        leak_epsilon: Option<f32>,
    },
    Row {
        focus: Point,
        leak_epsilon: Option<f32>,
    },
}

impl Job {
    /// Whether the job removes the capture's direct light first (the windows of Γ).
    pub(crate) fn leaks(&self) -> bool {
        match self {
            Job::Column { leak_epsilon, .. }
            | Job::Relight { leak_epsilon, .. }
            | Job::Row { leak_epsilon, .. } => leak_epsilon.is_some(),
            Job::Indirect { opts, .. } => opts.leak.is_some(),
            Job::Direct { .. } | Job::Matrix { .. } => false,
        }
    }

    /// The job without its windows (it runs on the capture minus the surface model).
    pub(crate) fn without_leak(mut self) -> Self {
        match &mut self {
            Job::Column { leak_epsilon, .. }
            | Job::Relight { leak_epsilon, .. }
            | Job::Row { leak_epsilon, .. } => *leak_epsilon = None,
            Job::Indirect { opts, .. } => opts.leak = None,
            Job::Direct { .. } | Job::Matrix { .. } => {}
        }
        self
    }
}
