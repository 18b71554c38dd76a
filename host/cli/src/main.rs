//! `vltm`: virtual light transport matrices of hidden scenes from NLOS captures.
//!
//! A thin layer over the `vltm` library: `args` parses the command line (clap), `commands`
//! and `ltm` run the commands, `split` writes the several outputs of one run (Γ masks,
//! shells, `indirect`), `outputs` writes volumes, figures and matrices, `summary` prints the
//! summary lines, `partial` runs parts of a scan and `vltm merge`, `open` opens a command's
//! capture, `input` holds its reading and preprocessing options, `info` is `vltm info` (`demo`
//! is the library's `vltm::demo`), `console` prints errors (library parameters spelled as
//! flags) and `progress` draws the progress bars (indicatif). This file is the entry point
//! only.
//!
//! Exit codes: 0 success, 2 bad arguments, 1 bad or unreadable input data.

use clap::Parser;
use std::process::ExitCode;

mod args;
mod commands;
mod console;
mod info;
mod input;
mod leak;
mod live;
mod ltm;
mod open;
mod outputs;
mod partial;
mod progress;
mod split;
mod summary;
mod surface;
mod title;

use args::Cli;
use console::{flag, printable, tell};

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) if !e.use_stderr() => {
            // --help and --version.
            let _ = e.print();
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            // One line, like every other error: clap's message up to its first blank line
            // (the argument it names, the values it expects) and its tips ("a similar
            // argument exists: '--volume'"), without "error: " and the usage block.
            let text = e.render().to_string();
            let mut lines = text.lines().map(str::trim);
            let mut parts: Vec<&str> = lines.by_ref().take_while(|l| !l.is_empty()).collect();
            parts.extend(lines.filter(|l| l.starts_with("tip:")));
            let msg = parts.join(" ").replace(" tip: ", "; ");
            let msg = msg.trim_start_matches("error: ");
            let msg = if msg.is_empty() { "bad arguments" } else { msg };
            tell!("vltm: {msg} (see --help)");
            return ExitCode::from(2);
        }
    };
    if let Some(n) = cli.threads {
        // More threads than 4 per core only add start-up time and memory.
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        let most = 4 * cores;
        if n == 0 || n > most {
            tell!(
                "vltm: argument `--threads`: expected 1 to {most} threads (4 per core, {cores} cores), found {n}"
            );
            return ExitCode::from(2);
        }
        if rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .is_err()
        {
            tell!("vltm: argument `--threads`: the thread pool could not be started");
            return ExitCode::from(1);
        }
    }
    if let Some(m) = &cli.max_memory {
        match vltm::budget::parse_size(m) {
            Ok(b) => vltm::budget::set(b),
            Err(e) => {
                tell!("vltm: {}", printable(&e.render(flag)));
                return ExitCode::from(2);
            }
        }
    }
    progress::BARS.set_mode(cli.progress);
    vltm::timings::start();
    let done = commands::run(cli.command);
    if let Some(t) = vltm::timings::report() {
        tell!("{t}");
    }
    match done {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => f.report(),
    }
}
