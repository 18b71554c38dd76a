//! `vltm._native`: the Rust side of the Python package. Thin typed entry points over the
//! vltm library; argument normalisation, docstrings of the public API and the Dask layer live
//! in the Python package (`vltm/`: its modules are listed in `host/python/README.md`).
//!
//! Probes: direct light (and the un-gated and higher-order diagonals), columns (with their
//! near/middle/far shells, Γ masks, leak correction and complex amplitudes on request),
//! in-focus indirect light, the matrix between two voxel sets, relighting and rows; each over
//! all rows, or over a row range as a partial state; every one through the preprocessing of
//! raw counts (time window, rebinning, background) and the SPAD/laser role swap where the
//! command line offers them.
//!
//! Every call that runs a probe or reads a capture releases the GIL (`Python::detach`) while
//! Rust works; inputs are copied out of NumPy before, outputs handed to NumPy after. Errors
//! become `vltm.ArgumentError` (a `ValueError`: bad arguments, the CLI's exit code 2) or
//! `vltm.DataError` (an `OSError`: unreadable or bad data, exit code 1) carrying the
//! library's one-line message, with the command line's flags spelled as Python keyword
//! arguments (`--t-min` → `t_min`).

use pyo3::exceptions::PyException;
use pyo3::prelude::*;

mod capture;
mod job;
mod leak;
mod options;
mod partial;
mod run;
mod volume;

/// The Python exception for a library error: `vltm.ArgumentError` or `vltm.DataError`.
pub(crate) fn py_err(e: vltm::Error) -> PyErr {
    let usage = e.is_usage();
    let msg = python_message(&e);
    Python::attach(|py| {
        let class = if usage { "ArgumentError" } else { "DataError" };
        match py
            .import("vltm._errors")
            .and_then(|m| m.getattr(class))
            .and_then(|c| c.call1((msg.clone(),)))
        {
            Ok(obj) => PyErr::from_value(obj),
            Err(_) => PyException::new_err(msg),
        }
    })
}

/// An `ArgumentError` naming the keyword argument `name`.
pub(crate) fn arg(name: &str, msg: impl ToString) -> PyErr {
    py_err(vltm::Error::arg(name, msg))
}

/// The library's one-line message with every command-line flag spelled as the Python
/// keyword argument it stands for.
pub(crate) fn python_message(e: &vltm::Error) -> String {
    let text = match e {
        // The library marks parameter names in its messages (`$epsilon`): spelled as they
        // are, the keyword's own name.
        vltm::Error::Argument { arg, msg } => format!(
            "argument `{}`: {}",
            keyword(arg),
            vltm::error::respell(msg, param)
        ),
        e => e.render(param),
    };
    respell(&text.replace('\n', " "))
}

/// A library parameter name (`max_memory`) as Python spells it (`vltm.set_max_memory()`; most
/// keep their name).
pub(crate) fn param(name: &str) -> String {
    keyword(&format!("--{}", name.replace('_', "-")))
}

/// A flag (`--t-min`, `--from`, `CAPTURE`, `--t-min/--t-max`) as a keyword (`t_min`, `from_`,
/// `capture`, `t_min/t_max`); a name without dashes is kept.
fn keyword(flag: &str) -> String {
    if flag.contains('/') {
        return flag.split('/').map(keyword).collect::<Vec<_>>().join("/");
    }
    let Some(name) = flag.strip_prefix("--") else {
        // A parameter name already (`threads`), or a positional (`CAPTURE`).
        return if flag.chars().all(|c| c.is_ascii_uppercase()) {
            flag.to_ascii_lowercase()
        } else {
            flag.to_string()
        };
    };
    match name {
        "from" => "from_".into(),
        "no-leak-correct" => "leak_correct".into(),
        "max-memory" => "vltm.set_max_memory()".into(),
        "threads" => "vltm.set_threads()".into(),
        "partial" => "rows".into(),
        n => n.replace('-', "_"),
    }
}

/// Replaces every `--flag` word of a message by its keyword.
fn respell(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(i) = rest.find("--") {
        let before = &rest[..i];
        let after = &rest[i + 2..];
        let word_start = before
            .chars()
            .next_back()
            .is_none_or(|c| !c.is_alphanumeric() && c != '-');
        let len = after
            .find(|c: char| !(c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-'))
            .unwrap_or(after.len());
        out.push_str(before);
        if word_start && len > 0 && after.as_bytes()[0].is_ascii_lowercase() {
            out.push_str(&keyword(&format!("--{}", &after[..len])));
            rest = &after[len..];
        } else {
            out.push_str("--");
            rest = after;
        }
    }
    out.push_str(rest);
    out
}

/// Γ = {v : I_d(v) > ε·max I_d}, as vltm computes it.
#[pyfunction]
fn gamma_mask(direct: numpy::PyReadonlyArray1<'_, f32>, epsilon: f32) -> PyResult<Vec<bool>> {
    let d = direct.as_slice().map_err(|e| arg("direct", e))?;
    Ok(vltm::probe::gamma_mask(d, epsilon))
}

/// Checks buffers the Python side is about to make (`(name, bytes)` pairs, held at once)
/// against the memory budget, as the library checks its own: the one-line error names
/// `what`, the largest buffer and the budget.
#[pyfunction]
fn check_memory(what: &str, buffers: Vec<(String, u64)>) -> PyResult<()> {
    let mut plan = vltm::budget::Plan::new();
    for (name, bytes) in buffers {
        plan.add(name, u128::from(bytes));
    }
    plan.check(|| what.to_string()).map_err(py_err)
}

/// Sets the number of worker threads (once per process, before the first probe): 1 to 4
/// per core, as `--threads`.
#[pyfunction]
fn set_threads(n: i64) -> PyResult<()> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let most = 4 * cores;
    if n < 1 || n as usize > most {
        return Err(arg(
            "threads",
            format!("expected 1 to {most} threads (4 per core, {cores} cores), found {n}"),
        ));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(n as usize)
        .build_global()
        .map_err(|e| {
            arg(
                "threads",
                format!("the thread pool is already running ({e})"),
            )
        })
}

/// Sets the memory budget from a size (`12G`, `500M`) as `--max-memory`; returns the bytes.
#[pyfunction]
fn set_max_memory(size: &str) -> PyResult<u64> {
    let b = vltm::budget::parse_size(size).map_err(|e| match e {
        vltm::Error::Argument { msg, .. } => arg("size", msg),
        e => py_err(e),
    })?;
    vltm::budget::set(b);
    Ok(b)
}

/// The memory budget in bytes.
#[pyfunction]
fn max_memory() -> u64 {
    vltm::budget::get()
}

/// The extension module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    capture::register(m)?;
    volume::register(m)?;
    partial::register(m)?;
    run::register(m)?;
    m.add_function(wrap_pyfunction!(gamma_mask, m)?)?;
    m.add_function(wrap_pyfunction!(check_memory, m)?)?;
    m.add_function(wrap_pyfunction!(set_threads, m)?)?;
    m.add_function(wrap_pyfunction!(set_max_memory, m)?)?;
    m.add_function(wrap_pyfunction!(max_memory, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
