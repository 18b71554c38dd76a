//! The workspace's house rules (`host/README.md`), checked against the tree:
//!
//! * every source file of every crate ([`CRATES`]: the library `host/src`, the command line
//!   `host/cli/src`, the kernel `kernel/src`, the Python package `host/python/src` and the
//!   firmware `kernel/firmware/src`), and every module of the Python package
//!   (`host/python/vltm`), has at most [`MAX_LINES`] lines before its tests, every line
//!   counted (comments and blank lines too);
//! * the file-level import graph of each crate has no circle;
//! * no module imports its crate's root `lib.rs`/`main.rs` where the crate root is an entry
//!   point or a table of contents (the library, the command line): items are imported from
//!   the module that defines them, so the root is never a helper store;
//! * the library's data flows one way through its stages ([`STAGES`]: `io`/`sim` → `probe`
//!   → `export`): no module imports a later stage;
//! * the module map in `host/README.md`: every row names a module of the library, and every
//!   import of a module with a row goes to a module its row allows (a module without a row
//!   is held to the general rules above only, so new modules that follow them pass);
//! * the library depends on no front-end crate (`clap`, `indicatif`, `anyhow`).
//!
//! Imports are the `crate::…`, `super::…` and `self::…` paths in code (comments and test
//! modules excluded), resolved to the file that defines the longest module prefix of the path
//! (through the root's `pub use` re-exports where a crate imports through them, as the
//! kernel does). Module declarations (`mod x;`) are containment, not imports; re-exports
//! (`pub use`) are imports.

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The most lines a file may hold before its tests (every line counted).
const MAX_LINES: usize = 800;

/// A crate the rules cover.
struct Crate {
    /// Its source folder, relative to the workspace root.
    src: &'static str,
    /// Whether its module graph is checked (circles, the crate root): `false` for the
    /// firmware, whose folder holds several crate roots (`lib.rs`, `main.rs`, `bin/`).
    graph: bool,
    /// Whether a module may import the crate root (`crate::Name` through its re-exports).
    root_imports: bool,
}

/// Every crate of the workspace (and the two outside it, the Python package and the
/// firmware).
const CRATES: [Crate; 5] = [
    Crate {
        src: "host/src",
        graph: true,
        root_imports: false,
    },
    Crate {
        src: "host/cli/src",
        graph: true,
        root_imports: false,
    },
    Crate {
        src: "kernel/src",
        graph: true,
        root_imports: true,
    },
    Crate {
        src: "host/python/src",
        graph: true,
        root_imports: true,
    },
    Crate {
        src: "kernel/firmware/src",
        graph: false,
        root_imports: true,
    },
];

/// The library's stages, in the order data flows through them: a module of one stage never
/// imports a module of a later one.
const STAGES: [&[&str]; 3] = [&["io", "sim"], &["probe"], &["export"]];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn src_dir() -> PathBuf {
    root().join("host/src")
}

/// Every `.rs` file below `dir`, sorted.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("read {}: {e}", dir.display()))
        .map(|e| e.expect("dir entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The module path of a file below a crate's source folder (`io/tal/mod.rs` → `io::tal`,
/// `lib.rs` or `main.rs` → ``), or `None` for the further crate roots of `bin/`.
fn module_of(rel: &Path) -> Option<String> {
    let parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    let mut segs: Vec<String> = parts[..parts.len() - 1].to_vec();
    let stem = parts[parts.len() - 1].trim_end_matches(".rs").to_string();
    if stem != "mod" && stem != "lib" && stem != "main" {
        segs.push(stem);
    }
    Some(segs.join("::"))
}

/// Whether a file is test code as a whole (`tests.rs` submodules).
fn is_test_file(rel: &Path) -> bool {
    rel.file_name().is_some_and(|n| n == "tests.rs")
}

/// The non-test code of a file: every line before a top-level `#[cfg(test)]`, comment lines
/// dropped.
fn code_lines(text: &str) -> Vec<&str> {
    text.lines()
        .take_while(|l| !l.starts_with("#[cfg(test)]"))
        .filter(|l| {
            let t = l.trim_start();
            !t.is_empty() && !t.starts_with("//")
        })
        .collect()
}

/// The `crate`/`super`/`self` paths used in `code`, each as its segments after the keyword,
/// with the keyword first; `{a::B, c}` groups expanded one level.
fn paths(code: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let b = code.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut i = 0;
    while i < b.len() {
        if !code.is_char_boundary(i) {
            i += 1;
            continue;
        }
        let kw = ["crate::", "super::", "self::"]
            .into_iter()
            .find(|k| code[i..].starts_with(k) && (i == 0 || !ident(b[i - 1])));
        let Some(kw) = kw else {
            i += 1;
            continue;
        };
        let mut head = vec![kw.trim_end_matches("::").to_string()];
        let mut j = i + kw.len();
        // Further `super::` hops.
        while code[j..].starts_with("super::") {
            head.push("super".into());
            j += "super::".len();
        }
        if b.get(j) == Some(&b'{') {
            let end = code[j..].find('}').map_or(b.len(), |e| j + e);
            for item in code[j + 1..end].split(',') {
                let mut p = head.clone();
                p.extend(
                    item.trim()
                        .split("::")
                        .map(|s| s.split_whitespace().next().unwrap_or("").to_string())
                        .filter(|s| !s.is_empty() && s != "*"),
                );
                out.push(p);
            }
            i = end;
            continue;
        }
        let mut p = head;
        loop {
            let s = j;
            while j < b.len() && ident(b[j]) {
                j += 1;
            }
            if s == j {
                break;
            }
            p.push(code[s..j].to_string());
            if code[j..].starts_with("::") && b.get(j + 2).is_some_and(|&c| ident(c)) {
                j += 2;
            } else {
                break;
            }
        }
        out.push(p);
        i = j.max(i + 1);
    }
    out
}

/// Resolves a path used in module `from` to the longest module prefix that exists; a name the
/// crate root re-exports (`crate::Point`) resolves to the module it comes from when
/// `reexports` has it.
fn resolve(from: &str, path: &[String], modules: &BTreeSet<String>) -> Option<String> {
    resolve_via(from, path, modules, &BTreeMap::new())
}

fn resolve_via(
    from: &str,
    path: &[String],
    modules: &BTreeSet<String>,
    reexports: &BTreeMap<String, String>,
) -> Option<String> {
    let mut base: Vec<String> = if from.is_empty() {
        Vec::new()
    } else {
        from.split("::").map(String::from).collect()
    };
    let mut rest = path;
    match rest.first().map(String::as_str) {
        Some("crate") => base.clear(),
        Some("self") => {}
        Some("super") => {
            base.pop();
        }
        _ => return None,
    }
    rest = &rest[1..];
    while rest.first().is_some_and(|s| s == "super") {
        base.pop();
        rest = &rest[1..];
    }
    if base.is_empty()
        && let Some(m) = rest.first().and_then(|n| reexports.get(n))
    {
        return Some(m.clone());
    }
    let mut best = base.join("::");
    let mut cur = base;
    for seg in rest {
        cur.push(seg.clone());
        let m = cur.join("::");
        if modules.contains(&m) {
            best = m;
        } else {
            break;
        }
    }
    Some(best)
}

/// The module map of `host/README.md`: row module → modules it may import (entries ending
/// in `::*` allow a whole subtree).
fn module_map() -> BTreeMap<String, Vec<String>> {
    let readme = fs::read_to_string(root().join("host/README.md")).expect("host/README.md");
    let mut map = BTreeMap::new();
    for line in readme.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 5 || !cells[1].starts_with('`') {
            continue;
        }
        let module = cells[1].trim_matches('`').to_string();
        let allowed = cells[3]
            .split(',')
            .map(|s| s.trim().trim_matches('`').to_string())
            .filter(|s| !s.is_empty() && s != "—")
            .collect();
        map.insert(module, allowed);
    }
    assert!(map.len() > 5, "host/README.md has no module map table");
    map
}

/// The map row a module belongs to: the longest row that is it or contains it.
fn row_of<'m>(module: &str, map: &'m BTreeMap<String, Vec<String>>) -> Option<&'m str> {
    map.keys()
        .filter(|r| module == r.as_str() || module.starts_with(&format!("{r}::")))
        .max_by_key(|r| r.len())
        .map(String::as_str)
}

fn allows(allowed: &[String], target_row: &str) -> bool {
    allowed.iter().any(|a| match a.strip_suffix("::*") {
        Some(tree) => target_row == tree || target_row.starts_with(&format!("{tree}::")),
        None => a == target_row,
    })
}

struct Tree {
    /// Module path → file (relative to the source folder), test files excluded.
    files: BTreeMap<String, PathBuf>,
    /// Module path → modules it imports.
    edges: BTreeMap<String, BTreeSet<String>>,
}

/// The names the crate root re-exports (`pub use module::{A, B}`) → their module.
fn reexports(root_code: &str, modules: &BTreeSet<String>) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for p in paths(root_code) {
        if p.len() < 3 {
            continue;
        }
        let name = p[p.len() - 1].clone();
        if let Some(m) = resolve("", &p, modules)
            && !m.is_empty()
            && name.starts_with(|c: char| c.is_ascii_uppercase() || c.is_ascii_lowercase())
        {
            out.entry(name).or_insert(m);
        }
    }
    // `pub use module::Name;` without a `crate::`/`self::` prefix.
    for line in root_code.lines() {
        let Some(rest) = line.trim().strip_prefix("pub use ") else {
            continue;
        };
        let (first, tail) = rest.split_once("::").unwrap_or((rest, ""));
        if !modules.contains(first) {
            continue;
        }
        let tail = tail.trim_end_matches(';');
        let names: Vec<&str> = match tail.strip_prefix('{') {
            Some(g) => g.trim_end_matches('}').split(',').collect(),
            None => vec![tail],
        };
        for n in names {
            let n = n.trim().rsplit("::").next().unwrap_or("").trim();
            if !n.is_empty() {
                out.entry(n.to_string()).or_insert(first.to_string());
            }
        }
    }
    out
}

/// The module tree and import graph of the crate in `src` (relative to the workspace).
fn tree_of(src: &str, via_root: bool) -> Tree {
    let root_dir = root().join(src);
    let mut all = Vec::new();
    rust_files(&root_dir, &mut all);
    let mut files = BTreeMap::new();
    for p in &all {
        let rel = p.strip_prefix(&root_dir).expect("below src").to_path_buf();
        if let Some(m) = module_of(&rel)
            && !is_test_file(&rel)
        {
            files.insert(m, rel);
        }
    }
    let modules: BTreeSet<String> = files.keys().cloned().collect();
    let code_of = |rel: &Path| -> String {
        let text = fs::read_to_string(root_dir.join(rel)).expect("read source");
        code_lines(&text)
            .into_iter()
            .filter(|l| !l.trim_start().starts_with("mod ") && !l.contains(" mod "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    let re = match files.get("") {
        Some(rel) if via_root => reexports(&code_of(rel), &modules),
        _ => BTreeMap::new(),
    };
    let mut edges = BTreeMap::new();
    for (m, rel) in &files {
        let code = code_of(rel);
        let mut targets: BTreeSet<String> = paths(&code)
            .iter()
            .filter_map(|p| resolve_via(m, p, &modules, &re))
            .collect();
        // `use child::…` (a path relative to this module) imports a submodule.
        for line in code.lines() {
            let t = line.trim_start();
            let rest = ["use ", "pub use ", "pub(crate) use ", "pub(super) use "]
                .into_iter()
                .find_map(|k| t.strip_prefix(k));
            if let Some(first) = rest.and_then(|r| r.split("::").next()) {
                let child = if m.is_empty() {
                    first.to_string()
                } else {
                    format!("{m}::{first}")
                };
                if modules.contains(&child) {
                    targets.insert(child);
                }
            }
        }
        targets.remove(m);
        edges.insert(m.clone(), targets);
    }
    Tree { files, edges }
}

/// The library's tree.
fn tree() -> Tree {
    tree_of("host/src", false)
}

/// The lines of a file that count against [`MAX_LINES`]: every line before a top-level
/// `#[cfg(test)]` (Rust) — comments, docs and blank lines included.
fn counted_lines(text: &str) -> usize {
    text.lines()
        .take_while(|l| !l.starts_with("#[cfg(test)]"))
        .count()
}

/// The files over [`MAX_LINES`] counted lines in `src` (relative to the workspace).
fn over_the_limit(src: &str) -> Vec<String> {
    let mut all = Vec::new();
    rust_files(&root().join(src), &mut all);
    assert!(!all.is_empty(), "{src} has no source files");
    all.iter()
        .filter(|p| !is_test_file(p))
        .filter_map(|p| {
            let n = counted_lines(&fs::read_to_string(p).expect("read"));
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", p.display()))
        })
        .collect()
}

/// The Python package's modules over [`MAX_LINES`] lines.
fn python_over_the_limit() -> Vec<String> {
    let dir = root().join("host/python/vltm");
    let mut n_files = 0;
    let over = fs::read_dir(&dir)
        .expect("host/python/vltm")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "py"))
        .filter_map(|p| {
            n_files += 1;
            let n = fs::read_to_string(&p).expect("read").lines().count();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", p.display()))
        })
        .collect();
    assert!(n_files > 3, "host/python/vltm has {n_files} modules");
    over
}

#[test]
fn no_file_is_over_the_line_limit() {
    let mut all = Vec::new();
    rust_files(&src_dir(), &mut all);
    assert!(all.len() > 20, "host/src has {} files", all.len());
    let mut over: Vec<String> = CRATES.iter().flat_map(|c| over_the_limit(c.src)).collect();
    over.extend(python_over_the_limit());
    assert!(over.is_empty(), "over {MAX_LINES} lines: {over:?}");
    // With teeth: comment lines count, and only a top-level `#[cfg(test)]` ends the count.
    let comments = "//! doc\n".repeat(MAX_LINES + 1);
    assert_eq!(counted_lines(&comments), MAX_LINES + 1);
    let with_tests = format!("fn a() {{}}\n\n#[cfg(test)]\nmod tests {{\n{comments}}}\n");
    assert_eq!(counted_lines(&with_tests), 2);
}

/// The library depends on no front-end crate: argument parsing, progress bars and the
/// command line's error chains live in `vltm-cli`, so the Python package does not build them.
#[test]
fn library_has_no_front_end_dependencies() {
    let manifest = fs::read_to_string(root().join("host/Cargo.toml")).expect("host/Cargo.toml");
    let deps = manifest
        .split("\n[")
        .find(|s| s.starts_with("dependencies]"))
        .expect("[dependencies]");
    for front in ["clap", "indicatif", "anyhow"] {
        assert!(
            !deps.lines().any(|l| l.trim_start().starts_with(front)),
            "the library depends on `{front}`, a front end's crate"
        );
    }
}

#[test]
fn module_map_matches_the_tree() {
    let map = module_map();
    let t = tree();
    // Every row names a module of the library.
    for row in map.keys() {
        assert!(
            t.files.contains_key(row),
            "host/README.md names `{row}`, which is not a module of host/src"
        );
    }
    // The map is not trivially small: the stages and the readers have their rows.
    for m in STAGES.iter().flat_map(|s| s.iter()) {
        assert!(map.contains_key(*m), "`{m}` has no row in host/README.md");
    }
}

/// Imports against the module map (rows that exist) and the stages (every module).
fn library_import_errors(t: &Tree, map: &BTreeMap<String, Vec<String>>) -> Vec<String> {
    let stage = |m: &str| {
        STAGES.iter().position(|s| {
            s.iter()
                .any(|r| m == *r || m.starts_with(&format!("{r}::")))
        })
    };
    let mut bad = Vec::new();
    for (m, targets) in &t.edges {
        if m.is_empty() {
            continue; // lib.rs: the crate root re-exports
        }
        for target in targets {
            if target.is_empty() {
                continue; // reported by `no_module_imports_the_crate_root`
            }
            if let (Some(a), Some(b)) = (stage(m), stage(target))
                && b > a
            {
                bad.push(format!(
                    "{m} → {target} (data flows {}: a stage never imports a later one)",
                    STAGES.map(|s| s.join("/")).join(" → ")
                ));
            }
            if let (Some(from), Some(to)) = (row_of(m, map), row_of(target, map))
                && to != from
                && !allows(&map[from], to)
            {
                bad.push(format!("{m} → {target} (`{from}` may not import `{to}`)"));
            }
        }
    }
    bad
}

#[test]
fn imports_flow_one_way() {
    let bad = library_import_errors(&tree(), &module_map());
    assert!(
        bad.is_empty(),
        "imports against host/README.md:\n{}",
        bad.join("\n")
    );
}

#[test]
fn no_module_imports_the_crate_root() {
    let mut bad = Vec::new();
    for c in CRATES.iter().filter(|c| c.graph && !c.root_imports) {
        let t = tree_of(c.src, false);
        for (m, targets) in t.edges.iter().filter(|(m, _)| !m.is_empty()) {
            if targets.contains("") {
                bad.push(format!(
                    "{}: {m} → the crate root (import from the defining module; the root \
                     is an entry point, not a helper store)",
                    c.src
                ));
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// The first circle of the graph (depth-first search with colours), if any. The crate
/// root's own edges are containment and re-exports, not a use of the modules.
fn circle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        m: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(m.to_string(), 1);
        stack.push(m.to_string());
        for n in edges.get(m).into_iter().flatten() {
            match state.get(n).copied().unwrap_or(0) {
                1 => {
                    let at = stack.iter().position(|s| s == n).unwrap_or(0);
                    let mut c = stack[at..].to_vec();
                    c.push(n.clone());
                    return Some(c);
                }
                0 => {
                    if let Some(c) = visit(n, edges, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(m.to_string(), 2);
        None
    }
    let mut edges = edges.clone();
    edges.remove("");
    let mut state = BTreeMap::new();
    for m in edges.keys() {
        if state.get(m).copied().unwrap_or(0) == 0
            && let Some(c) = visit(m, &edges, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

#[test]
fn import_graph_has_no_circle() {
    for c in CRATES.iter().filter(|c| c.graph) {
        let t = tree_of(c.src, c.root_imports);
        if let Some(cycle) = circle(&t.edges) {
            panic!(
                "import circle in {}: {}",
                c.src,
                cycle
                    .iter()
                    .map(|m| if m.is_empty() { "(crate root)" } else { m })
                    .collect::<Vec<_>>()
                    .join(" → ")
            );
        }
    }
    // The graphs are not trivially empty: the readers import the capture model, the command
    // line's commands import its arguments, the kernel's probe its configuration.
    assert!(tree().edges["io::tal"].contains("io::capture"));
    assert!(tree_of("host/cli/src", false).edges["commands"].contains("args"));
    assert!(tree_of("kernel/src", true).edges["band::probe"].contains("config"));
}

/// The checks can fail: a circle, a forbidden import, an import against the data flow and an
/// import of the crate root in made-up code are found.
#[test]
fn checks_have_teeth() {
    let modules: BTreeSet<String> = ["io", "io::tal", "io::capture", "probe", "probe::wave"]
        .into_iter()
        .map(String::from)
        .collect();
    let p = paths("use crate::probe::wave::Wave;\nuse super::{capture::Capture, *};");
    let got: Vec<_> = p
        .iter()
        .filter_map(|p| resolve("io::tal", p, &modules))
        .collect();
    assert_eq!(got, ["probe::wave", "io::capture", "io"]);
    let map = module_map();
    assert!(!allows(
        &map["io::tal"],
        row_of("probe::wave", &map).unwrap_or("")
    ));
    assert!(allows(&map["io::tal"], "io::capture"));
    // A made-up module without a row, importing a later stage, is caught; the same module
    // importing an earlier stage passes.
    let edges = |pairs: &[(&str, &str)]| {
        let mut e: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in pairs {
            e.entry(a.to_string()).or_default().insert(b.to_string());
        }
        e
    };
    let t = Tree {
        files: BTreeMap::new(),
        edges: edges(&[("io::live", "export::npy"), ("export::live", "io::capture")]),
    };
    let bad = library_import_errors(&t, &BTreeMap::new());
    assert_eq!(bad.len(), 1, "{bad:?}");
    assert!(bad[0].starts_with("io::live → export::npy"), "{bad:?}");
    // Circles: the command line's old `ltm` ↔ `partial`, and one through three modules.
    let c = circle(&edges(&[("ltm", "partial"), ("partial", "ltm")])).expect("circle");
    assert_eq!(c, ["ltm", "partial", "ltm"]);
    assert!(circle(&edges(&[("a", "b"), ("b", "c"), ("c", "a")])).is_some());
    assert!(circle(&edges(&[("a", "b"), ("b", "c"), ("a", "c")])).is_none());
    // Re-exports: the kernel's `crate::Point` is `config`'s.
    let kmods: BTreeSet<String> = ["config", "probe"].into_iter().map(String::from).collect();
    let re = reexports("pub use config::{Config, Point};", &kmods);
    let p = paths("use crate::Point;");
    assert_eq!(
        resolve_via("probe", &p[0], &kmods, &re).as_deref(),
        Some("config")
    );
    assert_eq!(resolve("probe", &p[0], &kmods).as_deref(), Some(""));
}

// ---------------------------------------------------------------------------------------
// A stranger's clone is enough: nothing outside the repository, fixtures whole and listed.

/// Text files of the repository that the reference check reads: everything outside
/// `target/`, hidden folders (`.git`) and the fuzzers' corpora, below 4 MB.
fn repo_text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("read {}: {e}", dir.display()))
        .map(|e| e.expect("dir entry").path())
        .collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if p.is_dir() {
            let skip = (name.starts_with('.') && name != ".ci")
                || ["target", "corpus", "artifacts", "__pycache__", "dist"].contains(&name);
            if !skip {
                repo_text_files(&p, out);
            }
        } else if fs::metadata(&p).is_ok_and(|m| m.len() < 4 << 20) {
            out.push(p);
        }
    }
}

/// The places in `files` that name a folder beside the repository (the development data that
/// a clone does not have), as `path:line: text`.
fn outside_references(files: &[PathBuf]) -> Vec<String> {
    // Spelled in pieces, so that this file does not find itself.
    let needles = [
        ["..", "/shared"].concat(),
        ["/work", "/shared"].concat(),
        ["VLTM_", "SHARED"].concat(),
        // The development design notes, which the repository does not hold.
        ["DESIGN", " §"].concat(),
        ["DESIGN", ".md"].concat(),
    ];
    let mut found = Vec::new();
    for p in files {
        let Ok(text) = fs::read_to_string(p) else {
            continue; // binary
        };
        for (i, line) in text.lines().enumerate() {
            if needles.iter().any(|n| line.contains(n.as_str())) {
                let rel = p.strip_prefix(root()).unwrap_or(p);
                found.push(format!("{}:{}: {}", rel.display(), i + 1, line.trim()));
            }
        }
    }
    found
}

/// Nothing in the repository — code, tests, docs, scripts, the CI — refers to a folder beside
/// it: a clone with nothing beside it must build, test and run every example.
#[test]
fn nothing_refers_outside_the_repository() {
    let mut files = Vec::new();
    repo_text_files(root(), &mut files);
    assert!(files.len() > 100, "only {} files found", files.len());
    let found = outside_references(&files);
    assert!(
        found.is_empty(),
        "references to files outside the repository (copy what is needed into fixtures/, \
         with its provenance in fixtures/README.md):\n{}",
        found.join("\n")
    );
    // With teeth: a file that reads the development data beside the repository is found.
    let dir = std::env::temp_dir().join(format!("vltm-layout-{}", std::process::id()));
    fs::create_dir_all(&dir).unwrap();
    let bad = dir.join("bad.rs");
    let text = ["let p = root().join(\"..", "/shared/data/x.hdf5\");\n"].concat();
    fs::write(&bad, text).unwrap();
    assert_eq!(outside_references(std::slice::from_ref(&bad)).len(), 1);
    fs::write(&bad, ["/// The flop model of DESI", "GN §B.8.\n"].concat()).unwrap();
    assert_eq!(outside_references(&[bad]).len(), 1);
    let _ = fs::remove_dir_all(&dir);
}

/// The data files of `fixtures/` (captures, volumes, partial states), relative to it.
fn fixture_data_files() -> Vec<String> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for e in fs::read_dir(dir).unwrap_or_else(|e| panic!("read {}: {e}", dir.display())) {
            let p = e.expect("dir entry").path();
            if p.is_dir() {
                walk(&p, out);
            } else {
                out.push(p);
            }
        }
    }
    let base = root().join("fixtures");
    let mut files = Vec::new();
    walk(&base, &mut files);
    let data = ["hdf5", "h5", "npz", "npy", "mat", "ptu", "vltmpart"];
    let mut out: Vec<String> = files
        .iter()
        .filter(|p| p.extension().is_some_and(|e| data.iter().any(|d| e == *d)))
        .map(|p| {
            p.strip_prefix(&base)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect();
    out.sort();
    out
}

/// The most bytes `fixtures/` may hold: the repository stays lean (32.8 MB with the seed-1
/// render of `pathtraced/seed1/`, the Stage-2 headline of issue 34).
const FIXTURES_MAX_BYTES: u64 = 34_000_000;

/// Every data file of `fixtures/` is listed in `fixtures/SHA256SUMS` with its checksum, every
/// listed file is there and whole, its provenance is in a `fixtures/…/README.md`, and the
/// folder holds at most 30 MB.
#[test]
fn fixtures_are_whole_listed_and_small() {
    let sums = support::fixture_sums();
    let data = fixture_data_files();
    assert!(
        data.len() >= 30,
        "only {} data files in fixtures/",
        data.len()
    );
    let unlisted: Vec<&String> = data.iter().filter(|f| !sums.contains_key(*f)).collect();
    assert!(
        unlisted.is_empty(),
        "fixtures not in fixtures/SHA256SUMS (run `bash fixtures/sums.sh` after adding one, \
         and give its provenance in fixtures/README.md): {unlisted:?}"
    );
    let mut bad = Vec::new();
    for rel in sums.keys() {
        if let Err(e) = support::check_fixture(rel, &root().join("fixtures").join(rel)) {
            bad.push(e);
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    // Provenance: each data file (or its folder) is named by the README of fixtures/ or of a
    // folder above it.
    let mut readmes = String::new();
    for r in [
        "README.md",
        "ytal/README.md",
        "real/README.md",
        "pathtraced/README.md",
        "firmware/README.md",
    ] {
        readmes += &fs::read_to_string(root().join("fixtures").join(r))
            .unwrap_or_else(|e| panic!("fixtures/{r}: {e}"));
    }
    let orphans: Vec<&String> = data
        .iter()
        .filter(|f| {
            let name = f.rsplit('/').next().unwrap();
            let dir = f.rsplit_once('/').map_or("", |(d, _)| d);
            !(readmes.contains(f.as_str())
                || readmes.contains(name)
                || (!dir.is_empty() && readmes.contains(&format!("{dir}/"))))
        })
        .collect();
    assert!(
        orphans.is_empty(),
        "fixtures without provenance in fixtures/README.md: {orphans:?}"
    );
    let total: u64 = {
        fn size(p: &Path) -> u64 {
            if p.is_dir() {
                fs::read_dir(p)
                    .unwrap()
                    .map(|e| size(&e.unwrap().path()))
                    .sum()
            } else {
                fs::metadata(p).map_or(0, |m| m.len())
            }
        }
        size(&root().join("fixtures"))
    };
    assert!(
        total <= FIXTURES_MAX_BYTES,
        "fixtures/ holds {total} bytes, more than {FIXTURES_MAX_BYTES}: use a smaller capture \
         (fewer bins, a crop, a rebin) made by a script kept in fixtures/"
    );
    // With teeth: a damaged copy of a listed fixture is refused, naming it and the way back.
    let rel = "two_patches_single.npz";
    let dir = std::env::temp_dir().join(format!("vltm-fixture-{}", std::process::id()));
    fs::create_dir_all(&dir).unwrap();
    let copy = dir.join("copy.npz");
    let mut bytes = fs::read(root().join("fixtures").join(rel)).unwrap();
    bytes.truncate(bytes.len() / 2);
    fs::write(&copy, &bytes).unwrap();
    let e = support::check_fixture(rel, &copy).unwrap_err();
    assert!(
        e.contains("fixtures/two_patches_single.npz is damaged")
            && e.contains("git checkout -- fixtures/two_patches_single.npz"),
        "{e}"
    );
    let e = support::check_fixture(rel, &dir.join("gone.npz")).unwrap_err();
    assert!(
        e.contains("is missing") && e.contains("git checkout --"),
        "{e}"
    );
    let _ = fs::remove_dir_all(&dir);
}

/// Files the README's tour and the tests write are outputs, never committed: the clone's root
/// holds only the workspace's own files, `.gitignore` names the outputs, and (in a git
/// checkout) no file at the root is tracked or left untracked beyond those.
#[test]
fn no_outputs_at_the_root() {
    let ignore = fs::read_to_string(root().join(".gitignore")).expect(".gitignore");
    for pat in [
        "/*.npy",
        "/*.png",
        "/*.h5",
        "/*.npz",
        "/*.ptu",
        "/vltm-demo/",
        "target/",
    ] {
        assert!(
            ignore.lines().any(|l| l.trim() == pat),
            ".gitignore does not name {pat}"
        );
    }
    let out = std::process::Command::new("git")
        .args(["ls-files", "--cached", "--others", "--exclude-standard"])
        .current_dir(root())
        .output()
        .expect("git (the tests run in a git checkout)");
    assert!(out.status.success(), "git ls-files failed");
    let allowed = [
        ".gitignore",
        "Cargo.toml",
        "Cargo.lock",
        "README.md",
        "rustfmt.toml",
        "clippy.toml",
        "rust-toolchain.toml",
    ];
    let stray: Vec<String> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|f| !f.contains('/') && !allowed.contains(f))
        .map(str::to_string)
        .collect();
    assert!(
        stray.is_empty(),
        "files at the repository's root that are outputs or strays (write outputs elsewhere, \
         or name them in .gitignore): {stray:?}"
    );
}

/// The modules of the library without a row of their own or a mention in their row: a
/// module below a row (`probe::cosine` under `probe`) is named in backticks in that row's
/// "owns" cell; any other module has its own row.
fn unmapped_modules(t: &Tree, readme: &str) -> Vec<String> {
    let owns: BTreeMap<String, String> = readme
        .lines()
        .filter_map(|line| {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            (cells.len() >= 5 && cells[1].starts_with('`'))
                .then(|| (cells[1].trim_matches('`').to_string(), cells[2].to_string()))
        })
        .collect();
    let map: BTreeMap<String, Vec<String>> = owns.keys().map(|k| (k.clone(), Vec::new())).collect();
    let mut bad = Vec::new();
    for m in t.files.keys().filter(|m| !m.is_empty()) {
        match row_of(m, &map) {
            None => bad.push(format!("`{m}` has no row")),
            Some(row) if row != m => {
                let name = m.rsplit("::").next().unwrap_or(m);
                let cell = &owns[row];
                if !cell.contains(&format!("`{name}`")) && !cell.contains(&format!("::{name}`")) {
                    bad.push(format!("`{m}` is not named in the row of `{row}`"));
                }
            }
            Some(_) => {}
        }
    }
    bad
}

/// The map both ways: every module of the library has a row in `host/README.md`, or is
/// named in its parent's row (and every row names a module: `module_map_matches_the_tree`).
#[test]
fn every_module_has_a_row() {
    let readme = fs::read_to_string(root().join("host/README.md")).expect("host/README.md");
    let t = tree();
    let bad = unmapped_modules(&t, &readme);
    assert!(bad.is_empty(), "host/README.md:\n{}", bad.join("\n"));
    // With teeth: a map without the `probe` row leaves its modules unmapped.
    let cut: String = readme
        .lines()
        .filter(|l| !l.starts_with("| `probe` |"))
        .map(|l| format!("{l}\n"))
        .collect();
    assert!(
        unmapped_modules(&t, &cut)
            .iter()
            .any(|b| b.contains("`probe::wave` has no row"))
    );
}

/// The rows of the command line's table in `host/README.md` (the two-column table after
/// "## The command line"): module names.
fn cli_rows(readme: &str) -> BTreeSet<String> {
    readme
        .split("## The command line")
        .nth(1)
        .expect("host/README.md: ## The command line")
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            cells
                .get(1)
                .filter(|c| c.starts_with('`'))
                .map(|c| c.trim_matches('`').to_string())
        })
        .collect()
}

/// The command line's top-level modules (`args.rs` → `args`, `live/mod.rs` → `live`).
fn cli_modules() -> BTreeSet<String> {
    let mut files = Vec::new();
    let src = root().join("host/cli/src");
    rust_files(&src, &mut files);
    files
        .iter()
        .filter_map(|p| {
            let rel = p.strip_prefix(&src).unwrap_or(p);
            module_of(rel)
        })
        .map(|m| {
            let top = m.split("::").next().unwrap_or("").to_string();
            if top.is_empty() {
                "main".to_string()
            } else {
                top
            }
        })
        .collect()
}

/// The command line's table both ways: every module of `host/cli/src` has a row, every row
/// names a module.
#[test]
fn cli_table_matches_the_tree() {
    let readme = fs::read_to_string(root().join("host/README.md")).expect("host/README.md");
    let rows = cli_rows(&readme);
    let modules = cli_modules();
    assert!(
        modules.len() > 10,
        "host/cli/src has {} modules",
        modules.len()
    );
    let missing: Vec<&String> = modules.difference(&rows).collect();
    let extra: Vec<&String> = rows.difference(&modules).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "host/README.md's command-line table: modules without a row {missing:?}, rows without a module {extra:?}"
    );
    // With teeth: a table without `args` misses it.
    let cut = readme.replace("| `args` |", "| args |");
    assert!(!cli_rows(&cut).contains("args"));
}

/// The rows of the module map in `kernel/README.md` (the table after "## Module map"): the
/// module path in the first cell's backticks.
fn kernel_map_rows(readme: &str) -> BTreeSet<String> {
    readme
        .split("## Module map")
        .nth(1)
        .expect("kernel/README.md: ## Module map")
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            cells
                .get(1)
                .filter(|c| c.starts_with('`'))
                .and_then(|c| c.split('`').nth(1))
                .map(str::to_string)
        })
        .collect()
}

/// The kernel's module map both ways: every module of `kernel/src` (`band::scan`,
/// `lookup::kahan`, …) has a row in `kernel/README.md`, and every row names a module.
#[test]
fn kernel_module_map_matches_the_tree() {
    let readme = fs::read_to_string(root().join("kernel/README.md")).expect("kernel/README.md");
    let rows = kernel_map_rows(&readme);
    let modules: BTreeSet<String> = tree_of("kernel/src", true)
        .files
        .into_keys()
        .filter(|m| !m.is_empty())
        .collect();
    assert!(
        modules.len() > 20,
        "kernel/src has {} modules",
        modules.len()
    );
    let missing: Vec<&String> = modules.difference(&rows).collect();
    let extra: Vec<&String> = rows.difference(&modules).collect();
    assert!(
        missing.is_empty() && extra.is_empty(),
        "kernel/README.md's module map: modules without a row {missing:?}, rows without a module {extra:?}"
    );
    // With teeth: a map without `band::row` misses it.
    let cut = readme.replace("| `band::row` |", "| band::row |");
    assert!(!kernel_map_rows(&cut).contains("band::row"));
    assert!(rows.contains("band::row"));
}
