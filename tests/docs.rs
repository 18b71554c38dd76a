//! The documentation is tested: its command-line examples run, and its links lead somewhere.
//!
//! **Examples.** Every ```` ```console ```` block of `README.md` and of every `docs/*.md` (a new
//! page is picked up without being listed) is a script: each `$ vltm …` line (a trailing `\`
//! continues it on the next line) runs the `vltm` binary ([`support::vltm_bin`], the one the
//! command-line tests build), and the lines under it, up to the next `$` line, are its expected
//! output, stdout then stderr, compared line by line after trimming trailing blanks:
//!
//! * `...` on a line of its own matches any number of lines (none included);
//! * `[..]` within a line matches any text on that line;
//! * a last line `? N` expects exit status N (`? failed`: any failure); without it the command
//!   must succeed;
//! * a command with no line under it has only its exit status checked.
//!
//! Words are split like a shell does for simple words: blanks separate them, `'…'` and `"…"`
//! quote. No shell runs: no variables, globs, pipes or redirections. Only `vltm` commands may
//! appear in `console` blocks; examples that cannot run here (hardware, long runs, downloads,
//! Python, other programs) belong in ```` ```sh ```` blocks, which are not run.
//!
//! The commands of one page run in order in one scratch directory laid out like the clone's
//! root: `<tmp>/repo/{fixtures,benches,docs,examples,kernel}` link to the repository's, so
//! `fixtures/…` resolves as in the documentation, and what a command writes stays in the
//! scratch directory, never in the repository. Nothing outside the repository is linked: an
//! example that reads a file the repository does not hold fails. Every example runs; none is
//! skipped.
//!
//! **Links.** Every relative link and image (`[text](path)`, `![alt](path)`, `src="path"`) of
//! `README.md`, `docs/*.md` and every other `README.md` of the repository (the crates', the
//! fixtures', the fuzz targets'; outside `target/` and hidden folders) must name an existing
//! file or folder, and a `#fragment` into a Markdown file must name one of its headings
//! (GitHub's anchors). Code blocks and code spans are not links.

mod support;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// `README.md` and `docs/*.md`, sorted.
fn doc_pages() -> Vec<PathBuf> {
    let mut pages = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .expect("docs/")
        .map(|e| e.expect("docs/ entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.sort();
    pages.extend(docs);
    pages
}

/// Every `README.md` of the repository outside `target/`, hidden folders and fuzzing corpora.
fn readmes(dir: &Path, depth: usize, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if p.is_dir() {
            let skip = name.starts_with('.')
                || ["target", "node_modules", "corpus", "seeds", "artifacts"].contains(&name);
            if !skip && depth > 0 {
                readmes(&p, depth - 1, out);
            }
        } else if name == "README.md" {
            out.push(p);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Markdown scanning

/// The lines of `text` outside fenced code blocks, with their line numbers (1-based).
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut fence: Option<&str> = None;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        let marker = if t.starts_with("```") {
            Some("```")
        } else if t.starts_with("~~~") {
            Some("~~~")
        } else {
            None
        };
        match (fence, marker) {
            (None, Some(m)) => fence = Some(m),
            (Some(f), Some(m)) if f == m && t.trim_end().trim_start_matches(m).is_empty() => {
                fence = None;
            }
            (None, None) => out.push((i + 1, line)),
            _ => {}
        }
    }
    out
}

/// `line` with its code spans blanked out.
fn without_code_spans(line: &str) -> String {
    let mut out = String::with_capacity(line.len());
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        if c != '`' {
            out.push(c);
            continue;
        }
        let mut ticks = 1;
        while chars.peek() == Some(&'`') {
            chars.next();
            ticks += 1;
        }
        // Skip to the closing run of the same length (or to the end of the line).
        let mut run = 0;
        for d in chars.by_ref() {
            if d == '`' {
                run += 1;
                if run == ticks {
                    break;
                }
            } else {
                run = 0;
            }
        }
        out.push(' ');
    }
    out
}

/// Link targets of one prose line: `](target)` and `src="target"`.
fn link_targets(line: &str) -> Vec<String> {
    let line = without_code_spans(line);
    let mut out = Vec::new();
    let mut rest = line.as_str();
    while let Some(i) = rest.find("](") {
        rest = &rest[i + 2..];
        if let Some(end) = rest.find(')') {
            let target = rest[..end].split_whitespace().next().unwrap_or("");
            out.push(target.trim_matches(['<', '>']).to_string());
            rest = &rest[end..];
        }
    }
    let mut rest = line.as_str();
    while let Some(i) = rest.find("src=\"") {
        rest = &rest[i + 5..];
        if let Some(end) = rest.find('"') {
            out.push(rest[..end].to_string());
            rest = &rest[end..];
        }
    }
    out
}

/// GitHub's anchors of the headings of a Markdown text (duplicates get `-1`, `-2`, …), and the
/// explicit anchors `<a id="NAME"></a>` of its prose (the glossary's entries).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen = BTreeSet::new();
    for (_, line) in prose_lines(text) {
        let mut rest = line;
        while let Some(i) = rest.find("<a id=\"") {
            rest = &rest[i + 7..];
            if let Some(end) = rest.find('"') {
                seen.insert(rest[..end].to_string());
                rest = &rest[end..];
            }
        }
        let t = line.trim_start();
        if !t.starts_with('#') {
            continue;
        }
        let title = t.trim_start_matches('#');
        if !title.starts_with(' ') {
            continue;
        }
        let base: String = without_code_spans_keep(title.trim())
            .chars()
            .filter_map(|c| {
                if c == ' ' {
                    Some('-')
                } else if c.is_alphanumeric() || c == '-' || c == '_' {
                    Some(c.to_lowercase().next().unwrap_or(c))
                } else {
                    None
                }
            })
            .collect();
        let mut a = base.clone();
        let mut k = 0;
        while seen.contains(&a) {
            k += 1;
            a = format!("{base}-{k}");
        }
        seen.insert(a);
    }
    seen
}

/// A heading's text with the backticks of its code spans dropped (their text is kept, as
/// GitHub keeps it in the anchor).
fn without_code_spans_keep(s: &str) -> String {
    s.replace('`', "")
}

#[test]
fn anchors_follow_github() {
    let a = anchors(
        "# Real data: the Stanford captures\n## Views, as seen (here)\n## Views, as seen (here)\n```\n# not a heading\n```\n## The `vltm` CLI\n",
    );
    let want: BTreeSet<String> = [
        "real-data-the-stanford-captures",
        "views-as-seen-here",
        "views-as-seen-here-1",
        "the-vltm-cli",
    ]
    .iter()
    .map(ToString::to_string)
    .collect();
    assert_eq!(a, want);
    let g = anchors("* <a id=\"t3\"></a><a id=\"ptu\"></a>**T3**\n`<a id=\"no\"></a>`\n");
    assert!(g.contains("t3") && g.contains("ptu"), "{g:?}");
    assert_eq!(
        link_targets("see [a](b.md#c), `[no](x)` and ![i](d.png) <img src=\"e.png\">"),
        ["b.md#c", "d.png", "e.png"]
    );
}

#[test]
fn links_and_images_resolve() {
    let mut files = doc_pages();
    let mut others = Vec::new();
    readmes(&root(), 4, &mut others);
    for p in others {
        if !files.contains(&p) {
            files.push(p);
        }
    }
    assert!(files.len() >= 8, "{files:?}");
    let mut broken = Vec::new();
    let mut checked = 0;
    for file in &files {
        let text = std::fs::read_to_string(file).expect("read page");
        let dir = file.parent().expect("page in a folder");
        for (n, line) in prose_lines(&text) {
            for target in link_targets(line) {
                if target.is_empty()
                    || target.contains("://")
                    || target.starts_with("mailto:")
                    || target.starts_with('{')
                {
                    continue;
                }
                checked += 1;
                let (path, fragment) = match target.split_once('#') {
                    Some((p, f)) => (p, Some(f)),
                    None => (target.as_str(), None),
                };
                let dest = if path.is_empty() {
                    file.clone()
                } else {
                    dir.join(path)
                };
                let at = format!(
                    "{}:{n}: {target}",
                    file.strip_prefix(root()).unwrap_or(file).display()
                );
                if !dest.exists() {
                    broken.push(format!("{at}: no such file"));
                    continue;
                }
                if let Some(f) = fragment
                    && dest.extension().is_some_and(|e| e == "md")
                {
                    let text = std::fs::read_to_string(&dest).expect("read link target");
                    if !anchors(&text).contains(f) {
                        broken.push(format!("{at}: no heading with anchor #{f}"));
                    }
                }
            }
        }
    }
    assert!(
        checked > 20,
        "only {checked} links found: the scanner is broken"
    );
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}

// ---------------------------------------------------------------------------------------
// Console examples

/// One `$ vltm …` command of a console block, and what it must print.
#[derive(Debug)]
struct Example {
    line: usize,
    args: Vec<String>,
    expected: Vec<String>,
    status: Status,
}

#[derive(Debug, PartialEq)]
enum Status {
    Success,
    Code(i32),
    Failed,
}

/// The console blocks of a page, as commands.
fn examples(text: &str) -> Result<Vec<Example>, String> {
    let mut out: Vec<Example> = Vec::new();
    let mut in_console = false;
    let mut in_other = false;
    let mut pending: Option<(usize, String)> = None;
    // The fence's indentation (a block inside a list item), removed from its lines.
    let mut indent = 0;
    for (i, raw) in text.lines().enumerate() {
        let n = i + 1;
        let t = raw.trim();
        if !in_console && !in_other {
            if t.starts_with("```") {
                let info = t.trim_start_matches('`').trim();
                indent = raw.len() - raw.trim_start().len();
                if info.split([' ', ',']).next() == Some("console") {
                    in_console = true;
                } else {
                    in_other = true;
                }
            }
            continue;
        }
        if t.starts_with("```") {
            if in_console && pending.is_some() {
                return Err(format!(
                    "line {n}: the block ends inside a continued command"
                ));
            }
            in_console = false;
            in_other = false;
            continue;
        }
        if in_other {
            continue;
        }
        let blank = raw.len() - raw.trim_start().len();
        let line = &raw[blank.min(indent)..];
        if let Some((start, mut cmd)) = pending.take() {
            let (part, more) = continued(line);
            cmd.push(' ');
            cmd.push_str(part);
            if more {
                pending = Some((start, cmd));
            } else {
                out.push(new_example(start, &cmd)?);
            }
            continue;
        }
        if let Some(cmd) = line.strip_prefix("$ ") {
            let (part, more) = continued(cmd);
            if more {
                pending = Some((n, part.to_string()));
            } else {
                out.push(new_example(n, part)?);
            }
            continue;
        }
        let Some(ex) = out.last_mut() else {
            return Err(format!("line {n}: output before any `$ vltm` command"));
        };
        if ex.status != Status::Success {
            return Err(format!("line {n}: output after the exit status line"));
        }
        match t.strip_prefix("? ") {
            Some("failed") => ex.status = Status::Failed,
            Some(code) => {
                ex.status = Status::Code(
                    code.parse()
                        .map_err(|_| format!("line {n}: bad exit status {code:?}"))?,
                );
            }
            None => ex.expected.push(line.trim_end().to_string()),
        }
    }
    // Blank lines at the end of an expected output are layout, not output.
    for ex in &mut out {
        while ex.expected.last().is_some_and(|l| l.is_empty()) {
            ex.expected.pop();
        }
    }
    Ok(out)
}

/// A command line without its continuation backslash, and whether one was there.
fn continued(line: &str) -> (&str, bool) {
    let t = line.trim_end();
    match t.strip_suffix('\\') {
        Some(head) => (head.trim(), true),
        None => (t.trim(), false),
    }
}

fn new_example(line: usize, cmd: &str) -> Result<Example, String> {
    let args = split_words(cmd).map_err(|e| format!("line {line}: {e}"))?;
    if args.first().map(String::as_str) != Some("vltm") {
        return Err(format!(
            "line {line}: only `$ vltm …` commands run in console blocks (use a sh block): {cmd}"
        ));
    }
    Ok(Example {
        line,
        args: args[1..].to_vec(),
        expected: Vec::new(),
        status: Status::Success,
    })
}

/// Splits like a shell for simple words; refuses what would need a shell.
fn split_words(cmd: &str) -> Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word = String::new();
    let mut has_word = false;
    let mut chars = cmd.chars();
    while let Some(c) = chars.next() {
        match c {
            ' ' | '\t' => {
                if has_word {
                    words.push(std::mem::take(&mut word));
                    has_word = false;
                }
            }
            '\'' | '"' => {
                has_word = true;
                loop {
                    match chars.next() {
                        Some(d) if d == c => break,
                        Some(d) => word.push(d),
                        None => return Err(format!("unclosed quote in {cmd}")),
                    }
                }
            }
            '|' | '>' | '<' | ';' | '&' | '$' | '*' | '`' | '#' => {
                return Err(format!(
                    "{c:?} needs a shell, which console examples do not have: {cmd}"
                ));
            }
            _ => {
                has_word = true;
                word.push(c);
            }
        }
    }
    if has_word {
        words.push(word);
    }
    Ok(words)
}

/// Whether `actual` matches the pattern line `expected` (`[..]`: any text).
fn line_matches(expected: &str, actual: &str) -> bool {
    let parts: Vec<&str> = expected.split("[..]").collect();
    if parts.len() == 1 {
        return expected == actual;
    }
    let (first, last) = (parts[0], parts[parts.len() - 1]);
    if !actual.starts_with(first) || actual.len() < first.len() + last.len() {
        return false;
    }
    let mut rest = &actual[first.len()..];
    for mid in &parts[1..parts.len() - 1] {
        match rest.find(mid) {
            Some(i) => rest = &rest[i + mid.len()..],
            None => return false,
        }
    }
    rest.ends_with(last)
}

/// Whether the lines `actual` match the pattern lines `expected` (`...`: any lines).
fn lines_match(expected: &[String], actual: &[&str]) -> bool {
    match expected.split_first() {
        None => actual.is_empty(),
        Some((e, rest)) if e.trim() == "..." => {
            (0..=actual.len()).any(|k| lines_match(rest, &actual[k..]))
        }
        Some((e, rest)) => actual
            .split_first()
            .is_some_and(|(a, more)| line_matches(e, a) && lines_match(rest, more)),
    }
}

#[test]
fn the_matcher_has_teeth() {
    let p = |s: &[&str]| s.iter().map(ToString::to_string).collect::<Vec<_>>();
    assert!(lines_match(&p(&["a [..] c", "..."]), &["a b c", "x", "y"]));
    assert!(lines_match(&p(&["...", "z"]), &["z"]));
    assert!(!lines_match(&p(&["a [..] c"]), &["a b d"]));
    assert!(!lines_match(&p(&["a"]), &["a", "b"]));
    assert!(!lines_match(&p(&["[..]ab[..]ab"]), &["xab"]));
    assert!(line_matches("[..]", ""));
    assert_eq!(
        split_words("vltm direct 'a b' \"c\" --x=1").unwrap(),
        ["vltm", "direct", "a b", "c", "--x=1"]
    );
    assert!(split_words("vltm info x > y").is_err());
    let ex = examples(
        "```console\n$ vltm info a \\\n    --png b.png\nline [..]\n...\n? 2\n```\n```sh\n$ rm -rf /\n```\n\
         * item\n\n  ```console\n  $ vltm info c\n    two\n  ```\n",
    )
    .unwrap();
    assert_eq!(ex.len(), 2);
    assert_eq!(ex[1].args, ["info", "c"]);
    assert_eq!(ex[1].expected, ["  two"]);
    assert_eq!(ex[0].args, ["info", "a", "--png", "b.png"]);
    assert_eq!(ex[0].expected, ["line [..]", "..."]);
    assert_eq!(ex[0].status, Status::Code(2));
    assert!(examples("```console\n$ ls\n```\n").is_err());
}

/// A scratch directory laid out like a checkout (module documentation), removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(tag: &str) -> Self {
        let base = std::env::temp_dir().join(format!("vltm-docs-{}-{tag}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        let repo = base.join("repo");
        std::fs::create_dir_all(&repo).expect("scratch dir");
        for d in ["fixtures", "benches", "docs", "examples", "kernel"] {
            symlink(&root().join(d), &repo.join(d));
        }
        Self(base)
    }
    fn repo(&self) -> PathBuf {
        self.0.join("repo")
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[cfg(unix)]
fn symlink(from: &Path, to: &Path) {
    std::os::unix::fs::symlink(from, to).expect("symlink");
}

#[cfg(not(unix))]
fn symlink(_from: &Path, _to: &Path) {
    panic!("the documentation examples need symbolic links (unix)");
}

#[test]
fn console_examples_run() {
    let mut failures = Vec::new();
    let mut ran = 0;
    for page in doc_pages() {
        let name = page
            .strip_prefix(root())
            .unwrap_or(&page)
            .display()
            .to_string();
        let text = std::fs::read_to_string(&page).expect("read page");
        let exs = match examples(&text) {
            Ok(e) => e,
            Err(e) => {
                failures.push(format!("{name}: {e}"));
                continue;
            }
        };
        if exs.is_empty() {
            continue;
        }
        let scratch = Scratch::new(&name.replace(['/', '.'], "_"));
        for ex in &exs {
            ran += 1;
            let out = Command::new(support::vltm_bin())
                .args(&ex.args)
                .current_dir(scratch.repo())
                .output()
                .expect("run vltm");
            let text = format!(
                "{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            let actual: Vec<&str> = text.lines().map(str::trim_end).collect();
            let code = out.status.code();
            let status_ok = match ex.status {
                Status::Success => out.status.success(),
                Status::Code(c) => code == Some(c),
                Status::Failed => !out.status.success(),
            };
            let output_ok = ex.expected.is_empty() || lines_match(&ex.expected, &actual);
            if !(status_ok && output_ok) {
                failures.push(format!(
                    "{name}:{}: `vltm {}`: exit {code:?} (expected {:?}){}\n--- expected\n{}\n--- actual\n{}",
                    ex.line,
                    ex.args.join(" "),
                    ex.status,
                    if output_ok { "" } else { ", output differs" },
                    ex.expected.join("\n"),
                    text
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
    assert!(ran >= 5, "only {ran} console examples ran");
}

/// The README's front picture is made by `vltm`: the `console` example whose `--png` names the
/// picture's file (`docs/NAME.png` made as `NAME.png`) runs in a scratch directory, and the
/// PNG it writes equals the committed one up to rounding (mean absolute difference of the
/// 8-bit channels below 1 %, the same size). Regenerate the picture with that command.
#[test]
fn readme_front_picture_is_made_by_its_caption_command() {
    let text = std::fs::read_to_string(root().join("README.md")).expect("README.md");
    // The first image of the page (a line of its own).
    let rest = text
        .lines()
        .find(|l| l.starts_with("!["))
        .expect("README.md has no image");
    let open = rest.find("](").expect("image link") + 2;
    let picture = &rest[open..open + rest[open..].find(')').expect("image link end")];
    let name = Path::new(picture)
        .file_name()
        .and_then(|n| n.to_str())
        .expect("picture file name")
        .to_string();
    let exs = examples(&text).expect("README examples");
    let ex = exs
        .iter()
        .find(|e| e.args.windows(2).any(|w| w[0] == "--png" && w[1] == name))
        .unwrap_or_else(|| {
            panic!("no console example of README.md writes its front picture (--png {name})")
        });
    let scratch = Scratch::new("front_picture");
    let out = Command::new(support::vltm_bin())
        .args(&ex.args)
        .current_dir(scratch.repo())
        .output()
        .expect("run vltm");
    assert!(
        out.status.success(),
        "vltm {}: {}",
        ex.args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    let made = image::open(scratch.repo().join(&name))
        .expect("the command's picture")
        .to_rgb8();
    let committed = image::open(root().join(picture))
        .expect("the README's picture")
        .to_rgb8();
    assert_eq!(made.dimensions(), committed.dimensions(), "{picture}: size");
    let diff: f64 = made
        .as_raw()
        .iter()
        .zip(committed.as_raw())
        .map(|(&a, &b)| f64::from(a.abs_diff(b)))
        .sum::<f64>()
        / made.as_raw().len() as f64
        / 255.0;
    assert!(
        diff < 0.01,
        "{picture} differs from what `vltm {}` makes (mean difference {:.2} %): regenerate it \
         with that command",
        ex.args.join(" "),
        100.0 * diff
    );
}

// ---------------------------------------------------------------------------------------
// The guide is guidance, not a log

/// Phrases of development history or references to files outside the repository that the
/// guide must not hold: section marks of the development design notes (`§B.…`, a file that
/// is not in the repository),
/// `this morning`, `the range first asked for`, and `was <number> ms` / `was <number> s`
/// (a time the reader cannot reproduce). Returns `line: phrase` for each.
fn history_phrases(text: &str) -> Vec<String> {
    const FIXED: [&str; 4] = [
        concat!("DESI", "GN §"),
        "§B.",
        "this morning",
        "first asked for",
    ];
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let lower = line.to_lowercase();
        for p in FIXED {
            if lower.contains(&p.to_lowercase()) {
                out.push(format!("{}: `{p}`", n + 1));
            }
        }
        let mut rest = lower.as_str();
        while let Some(i) = rest.find("was ") {
            rest = &rest[i + 4..];
            let num = rest
                .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == ','))
                .unwrap_or(rest.len());
            if num == 0 || !rest.starts_with(|c: char| c.is_ascii_digit()) {
                continue;
            }
            let unit = rest[num..].trim_start();
            let word = unit
                .find(|c: char| !c.is_alphabetic())
                .map_or(unit, |e| &unit[..e]);
            if word == "ms" || word == "s" {
                out.push(format!("{}: `was {} {word}`", n + 1, &rest[..num]));
            }
        }
    }
    out
}

/// README.md and docs/*.md hold no development history ([`history_phrases`]).
#[test]
fn guide_holds_no_history() {
    let mut found = Vec::new();
    for page in doc_pages() {
        let text = std::fs::read_to_string(&page).expect("read page");
        let name = page
            .strip_prefix(root())
            .unwrap_or(&page)
            .display()
            .to_string();
        found.extend(
            history_phrases(&text)
                .into_iter()
                .map(|h| format!("{name}:{h}")),
        );
    }
    assert!(
        found.is_empty(),
        "development history in the guide (say what a reader should do, and keep \
         measurements in tables with their machine and date):\n{}",
        found.join("\n")
    );
}

/// The history check has teeth: each phrase is found, and ordinary text is not.
#[test]
fn history_check_has_teeth() {
    for bad in [
        concat!("see DESI", "GN §3"),
        "as in §B.0",
        "2.00 s This morning",
        "20.5 ms (was 177 ms)",
        "0.18 s (was 118 s)",
        "was 1,234.5ms",
        "the range first asked for",
    ] {
        assert_eq!(history_phrases(bad).len(), 1, "{bad}");
    }
    for good in [
        "it was 3 slices deep",
        "was 12 seconds long in total", // `seconds` is not the unit word `s`
        "the bound was stated",
        "takes 20.5 ms per row",
    ] {
        assert!(history_phrases(good).is_empty(), "{good}");
    }
}
