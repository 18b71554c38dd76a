//! The host crate's house rules (`host/README.md`), checked against the tree:
//!
//! * every source file of `host/src` has at most [`MAX_LINES`] lines of non-test code;
//! * the module map in `host/README.md` names every module of the tree and nothing else;
//! * the file-level import graph of the library has no circle, and every import goes to a
//!   module that the importing module's row of the map allows.
//!
//! Imports are the `crate::…`, `super::…` and `self::…` paths in code (comments and test
//! modules excluded), resolved to the file that defines the longest module prefix of the path.
//! Module declarations (`mod x;`) are containment, not imports; re-exports (`pub use`) are
//! imports.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

/// The most lines of non-test code a file may hold.
const MAX_LINES: usize = 800;

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("host/src")
}

/// Every `.rs` file below `dir`, sorted.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = fs::read_dir(dir)
        .expect("read host/src")
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

/// The library's module path of a file below `host/src` (`io/tal/mod.rs` → `io::tal`,
/// `lib.rs` → ``), or `None` for the command line (`bin/`).
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
    if stem != "mod" && stem != "lib" {
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

/// Resolves a path used in module `from` to the longest module prefix that exists.
fn resolve(from: &str, path: &[String], modules: &BTreeSet<String>) -> Option<String> {
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
    let readme = fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("host/README.md"))
        .expect("host/README.md");
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
    /// Module path → file (relative to host/src), library files only, test files excluded.
    files: BTreeMap<String, PathBuf>,
    /// Module path → modules it imports.
    edges: BTreeMap<String, BTreeSet<String>>,
}

fn tree() -> Tree {
    let root = src_dir();
    let mut all = Vec::new();
    rust_files(&root, &mut all);
    let mut files = BTreeMap::new();
    for p in &all {
        let rel = p.strip_prefix(&root).expect("below src").to_path_buf();
        if let Some(m) = module_of(&rel)
            && !is_test_file(&rel)
        {
            files.insert(m, rel);
        }
    }
    let modules: BTreeSet<String> = files.keys().cloned().collect();
    let mut edges = BTreeMap::new();
    for (m, rel) in &files {
        let text = fs::read_to_string(root.join(rel)).expect("read source");
        let code: String = code_lines(&text)
            .into_iter()
            .filter(|l| !l.trim_start().starts_with("mod ") && !l.contains(" mod "))
            .collect::<Vec<_>>()
            .join("\n");
        let mut targets: BTreeSet<String> = paths(&code)
            .iter()
            .filter_map(|p| resolve(m, p, &modules))
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

#[test]
fn no_file_is_over_the_line_limit() {
    let root = src_dir();
    let mut all = Vec::new();
    rust_files(&root, &mut all);
    assert!(all.len() > 20, "host/src has {} files", all.len());
    let over: Vec<String> = all
        .iter()
        .filter(|p| !is_test_file(p))
        .filter_map(|p| {
            let n = code_lines(&fs::read_to_string(p).expect("read")).len();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", p.display()))
        })
        .collect();
    assert!(over.is_empty(), "over {MAX_LINES} lines of code: {over:?}");
}

#[test]
fn module_map_matches_the_tree() {
    let map = module_map();
    let t = tree();
    // Every row names a module of the tree (or the command line).
    for row in map.keys() {
        assert!(
            row.starts_with("bin/") || t.files.contains_key(row),
            "host/README.md names `{row}`, which is not a module of host/src"
        );
    }
    // Every top-level module, and every module of `io`, has its row.
    for m in t.files.keys().filter(|m| !m.is_empty()) {
        let depth = m.matches("::").count();
        if depth == 0 || (m.starts_with("io::") && depth == 1) {
            assert!(
                map.contains_key(m),
                "module `{m}` has no row in host/README.md"
            );
        }
        assert!(row_of(m, &map).is_some(), "module `{m}` is in no row");
    }
}

#[test]
fn imports_flow_one_way() {
    let map = module_map();
    let t = tree();
    let mut bad = Vec::new();
    for (m, targets) in &t.edges {
        if m.is_empty() {
            continue; // lib.rs: the crate root re-exports
        }
        let from = row_of(m, &map).expect("mapped");
        for target in targets {
            if target.is_empty() {
                bad.push(format!(
                    "{m} → the crate root (import from the defining module)"
                ));
                continue;
            }
            let to = row_of(target, &map).expect("mapped");
            if to != from && !allows(&map[from], to) {
                bad.push(format!("{m} → {target} (`{from}` may not import `{to}`)"));
            }
        }
    }
    assert!(
        bad.is_empty(),
        "imports against host/README.md:\n{}",
        bad.join("\n")
    );
}

#[test]
fn import_graph_has_no_circle() {
    let t = tree();
    // Depth-first search with colours; report the first circle found.
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
    let mut state = BTreeMap::new();
    for m in t.edges.keys() {
        if state.get(m).copied().unwrap_or(0) == 0
            && let Some(c) = visit(m, &t.edges, &mut state, &mut Vec::new())
        {
            panic!("import circle: {}", c.join(" → "));
        }
    }
    // The graph is not trivially empty: the readers import the capture model.
    assert!(t.edges["io::tal"].contains("io::capture"));
}

/// The checks can fail: a circle and a forbidden import in made-up code are found.
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
}
