//! What the command line prints: `say!` (stdout, quiet on a closed pipe), and errors as one
//! line with their exit code ([`Failure`]), every library parameter spelled as its flag
//! ([`flag`]: `max_memory` → `--max-memory`).

use std::process::ExitCode;

/// `println!` that ignores a closed stdout (`vltm info CAPTURE | head` must not panic).
macro_rules! say {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($t)*);
    }};
}
pub(crate) use say;

/// `eprintln!` that ignores a closed stderr (`vltm … 2>&1 | head -1` must not panic; the
/// exit code stays the one the run would have had).
macro_rules! tell {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}
pub(crate) use tell;

/// The command line's spelling of a library parameter: `--` and the name with dashes
/// (`t_min` → `--t-min`), the flags being named after the parameters.
pub(crate) fn flag(param: &str) -> String {
    match param {
        // Already a flag (the command line's own errors).
        p if p.starts_with('-') => p.to_string(),
        // The positional arguments, as `--help` names them.
        "capture" | "scene" | "source" | "parts" => param.to_ascii_uppercase(),
        _ => format!("--{}", param.replace('_', "-")),
    }
}

/// Escapes control characters (terminal escapes, newlines from a file's strings) so that an
/// error stays one printable line.
pub(crate) fn printable(msg: &str) -> String {
    msg.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// An error with its exit code.
pub(crate) struct Failure {
    code: u8,
    err: anyhow::Error,
}

impl From<vltm::Error> for Failure {
    fn from(e: vltm::Error) -> Self {
        Self {
            code: if e.is_usage() { 2 } else { 1 },
            err: e.into(),
        }
    }
}

impl From<anyhow::Error> for Failure {
    fn from(err: anyhow::Error) -> Self {
        let code = match err.downcast_ref::<vltm::Error>() {
            Some(e) if e.is_usage() => 2,
            _ => 1,
        };
        Self { code, err }
    }
}

impl Failure {
    /// Prints the error as one line (`vltm: …`, parameters as flags, a context chain as
    /// `context: cause`) and returns its exit code.
    pub(crate) fn report(&self) -> ExitCode {
        // A library error renders its own cause: the chain ends there (else a kernel
        // configuration error would be printed twice).
        let mut parts = Vec::new();
        for e in self.err.chain() {
            if let Some(v) = e.downcast_ref::<vltm::Error>() {
                parts.push(v.render(flag));
                break;
            }
            parts.push(e.to_string());
        }
        let msg = parts.join(": ");
        // Markers in a context's text are respelled too: no `$name` reaches the user.
        let msg = vltm::error::respell(&msg, flag);
        tell!("vltm: {}", printable(&msg.replace('\n', " ")));
        ExitCode::from(self.code)
    }
}
