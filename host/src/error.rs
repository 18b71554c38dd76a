//! The host library's error type: every message names the file or parameter, the field and
//! what was expected.
//!
//! # Parameters, not flags
//!
//! The library is used from several front ends that spell the same parameter differently:
//! the command line as a flag (`--max-memory`), Python as a keyword argument
//! (`max_memory=`). Library messages therefore never name a flag. They name the
//! *parameter*, in `snake_case`, written `$name` inside message text
//! (`"raise $epsilon"`); [`Error::Argument`] carries the parameter it is about.
//! [`Error::render`] writes an error with a front end's own spelling of each parameter
//! ([`respell`] does the same for any library text, such as the conventions of
//! [`crate::io::Capture`] readers); `Display` writes the bare name (`epsilon`).

use std::path::PathBuf;

/// Errors of the vltm host library.
#[derive(Debug)]
#[non_exhaustive]
pub enum Error {
    /// Reading or writing a file failed.
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error (part of the message, not a separate cause, so it prints once).
        err: std::io::Error,
    },
    /// A file's content is not what vltm expects.
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
    Argument {
        /// The parameter, in `snake_case` (`epsilon`, `max_memory`), never a front end's
        /// spelling (a flag, a keyword): a front end spells it its own way
        /// ([`Error::render`]).
        arg: String,
        /// What is wrong and what was expected; other parameters it names are written
        /// `$name`.
        msg: String,
    },
    /// An allocation would exceed the memory budget (`vltm::budget`).
    Memory {
        /// What the memory is for.
        what: String,
        /// Bytes it needs.
        need: u128,
        /// The budget in bytes.
        budget: u64,
    },
    /// The kernel rejected the wave/gate configuration.
    Config(vltm_kernel::ConfigError),
    /// The kernel rejected a buffer or a position.
    Kernel(vltm_kernel::ArgumentError),
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
    /// An [`Error::Argument`] error about parameter `param` (`snake_case`, no flag
    /// spelling); other parameters named in `msg` are written `$name`.
    pub fn arg(param: &str, msg: impl ToString) -> Self {
        debug_assert!(
            is_param_name(param),
            "`{param}` is not a parameter name (snake_case, no flag spelling)"
        );
        Self::Argument {
            arg: param.into(),
            msg: msg.to_string(),
        }
    }
    /// The message with every parameter spelled by `spell` (given the `snake_case` name):
    /// the command line passes `|p| format!("--{}", p.replace('_', "-"))`, the Python
    /// package `|p| format!("{p}=")`. `Display` is `render` with the bare name.
    ///
    /// ```
    /// let e = vltm::Error::arg("epsilon", "Γ is too large; raise $epsilon");
    /// assert_eq!(e.to_string(), "argument `epsilon`: Γ is too large; raise epsilon");
    /// let cli = e.render(|p| format!("--{}", p.replace('_', "-")));
    /// assert_eq!(cli, "argument `--epsilon`: Γ is too large; raise --epsilon");
    /// ```
    pub fn render(&self, spell: impl Fn(&str) -> String) -> String {
        let raw = match self {
            Self::Io { path, err } => format!("{}: {err}", path.display()),
            Self::Format {
                path,
                field,
                expected,
                found,
            } => format!(
                "{}: field `{field}`: expected {expected}, found {found}",
                path.display()
            ),
            // The parameter spelled directly (a name that is not `snake_case` must not
            // reach the user as a `$NAME` marker), the message's markers respelled.
            Self::Argument { arg, msg } => {
                return format!("argument `{}`: {}", spell(arg), respell(msg, &spell));
            }
            Self::Memory { what, need, budget } => format!(
                "{what}: needs {} > {} memory budget (set it with $max_memory)",
                human(*need),
                human(u128::from(*budget))
            ),
            Self::Config(e) => format!("kernel configuration: {e}"),
            Self::Kernel(e) => format!("kernel: {e}"),
        };
        respell(&raw, spell)
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

impl std::fmt::Display for Error {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render(str::to_string))
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Config(e) => Some(e),
            Self::Kernel(e) => Some(e),
            _ => None,
        }
    }
}

impl From<vltm_kernel::ConfigError> for Error {
    fn from(e: vltm_kernel::ConfigError) -> Self {
        Self::Config(e)
    }
}

impl From<vltm_kernel::ArgumentError> for Error {
    fn from(e: vltm_kernel::ArgumentError) -> Self {
        Self::Kernel(e)
    }
}

/// Whether `s` is a parameter name: `snake_case` ASCII, starting with a letter.
fn is_param_name(s: &str) -> bool {
    s.starts_with(|c: char| c.is_ascii_lowercase())
        && s.bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'_')
}

/// `text` with every parameter marker `$name` (`name` in `snake_case`, after the start, a
/// space, a backtick, `(`, `/` or `,`) replaced by `spell(name)`; other `$` are kept.
///
/// ```
/// let t = "widen $t_min/$t_max or give $background VALUE (cost: $5)";
/// let cli = vltm::error::respell(t, |p| format!("--{}", p.replace('_', "-")));
/// assert_eq!(cli, "widen --t-min/--t-max or give --background VALUE (cost: $5)");
/// ```
pub fn respell(text: &str, spell: impl Fn(&str) -> String) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    let mut prev: Option<char> = None;
    while let Some(at) = rest.find('$') {
        let before = &rest[..at];
        out.push_str(before);
        let p = before.chars().next_back().or(prev);
        let after = &rest[at + 1..];
        let len = after
            .find(|c: char| !(c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'))
            .unwrap_or(after.len());
        let name = &after[..len];
        let opens = matches!(p, None | Some(' ' | '`' | '(' | '/' | ','));
        if opens && is_param_name(name) {
            out.push_str(&spell(name));
            rest = &after[len..];
            prev = name.chars().next_back();
        } else {
            out.push('$');
            rest = after;
            prev = Some('$');
        }
    }
    out.push_str(rest);
    out
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An argument's name reaches the user spelled by the front end even when it is not a
    /// `snake_case` parameter name (no `$NAME` marker is left).
    #[test]
    fn argument_names_are_always_spelled() {
        let e = Error::Argument {
            arg: "CAPTURE".into(),
            msg: "x.nzp: unknown; see $max_memory".into(),
        };
        let r = e.render(|p| format!("<{p}>"));
        assert_eq!(r, "argument `<CAPTURE>`: x.nzp: unknown; see <max_memory>");
        assert!(!e.to_string().contains('$'), "{e}");
    }
}
