//! The host library's error type: every message names the file or argument, the field and
//! what was expected.

use std::path::PathBuf;

/// Errors of the vltm host library.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{}: {err}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error (part of the message, not a separate cause, so it prints once).
        err: std::io::Error,
    },
    /// A file's content is not what vltm expects.
    #[error("{}: field `{field}`: expected {expected}, found {found}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// The field (dataset, key, record).
        field: String,
        /// What was expected.
        expected: String,
        /// What was found.
        found: String,
    },
    /// A user argument is malformed or out of range (the CLI exits with code 2).
    #[error("argument `{arg}`: {msg}")]
    Argument {
        /// The argument (flag or parameter name).
        arg: String,
        /// What is wrong and what was expected.
        msg: String,
    },
    /// An allocation would exceed the memory budget (`vltm::budget`).
    #[error(
        "{what}: needs {} > {} memory budget (set it with --max-memory)",
        human(*need),
        human(u128::from(*budget))
    )]
    Memory {
        /// What the memory is for.
        what: String,
        /// Bytes it needs.
        need: u128,
        /// The budget in bytes.
        budget: u64,
    },
    /// The kernel rejected the wave/gate configuration.
    #[error("kernel configuration: {0}")]
    Config(#[from] vltm_kernel::ConfigError),
    /// The kernel rejected a buffer or a position.
    #[error("kernel: {0}")]
    Kernel(#[from] vltm_kernel::Error),
}

impl Error {
    /// A [`Error::Format`] error.
    pub fn format(
        path: impl Into<PathBuf>,
        field: &str,
        expected: impl ToString,
        found: impl ToString,
    ) -> Self {
        Self::Format {
            path: path.into(),
            field: field.into(),
            expected: expected.to_string(),
            found: found.to_string(),
        }
    }
    /// An [`Error::Argument`] error.
    pub fn arg(arg: &str, msg: impl ToString) -> Self {
        Self::Argument {
            arg: arg.into(),
            msg: msg.to_string(),
        }
    }
    /// An [`Error::Io`] error.
    pub fn io(path: impl Into<PathBuf>, err: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            err,
        }
    }
    /// Whether the error is the user's arguments (CLI exit code 2) rather than the data (1).
    pub fn is_usage(&self) -> bool {
        matches!(self, Self::Argument { .. } | Self::Config(_))
    }
}

/// Result with the host [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// A byte count for people: `4.0 TB`, `12 GB`, `640 kB`, `17 B` (powers of 1000).
pub fn human(bytes: u128) -> String {
    const UNITS: [&str; 7] = ["B", "kB", "MB", "GB", "TB", "PB", "EB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1000.0 && u + 1 < UNITS.len() {
        v /= 1000.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else if v < 10.0 {
        format!("{v:.1} {}", UNITS[u])
    } else {
        format!("{v:.0} {}", UNITS[u])
    }
}
