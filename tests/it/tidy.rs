//! The layering rule of ARCHITECTURE.md, checked on the source (after rust-analyzer's tidy
//! tests): numerics know no files and no pipeline, and the top-level modules form no cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The pure numerics: they take slices and structs and return values.
const NUMERICS: [&str; 5] = ["signal", "physics", "vision", "diagnose", "stats"];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The non-test code of a file: test-only files are skipped, and a file's `#[cfg(test)]` module
/// (by convention its last item) is cut off.
fn production_code(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?;
    if name == "tests.rs" || name == "test_support.rs" {
        return None;
    }
    let text = std::fs::read_to_string(path).ok()?;
    let code = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => &text,
    };
    // Comments may name any module: only code counts.
    Some(code.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n"))
}

/// Top-level module of `src` → the top-level modules its production code names (`crate::x`,
/// `shakeflow::x`), and the files that name each.
fn module_graph() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    for file in files {
        let relative = file.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
        let module = relative.split('/').next().unwrap().trim_end_matches(".rs").to_string();
        let Some(code) = production_code(&file) else { continue };
        for (i, _) in code.match_indices("crate::") {
            let used: String = code[i + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            if !used.is_empty() && used != module {
                graph.entry(module.clone()).or_default().entry(used).or_default().insert(relative.clone());
            }
        }
    }
    graph
}

#[test]
fn numerics_know_no_files_and_no_pipeline() {
    let graph = module_graph();
    let forbidden = ["io", "pipeline", "stages", "validate", "cli", "demo", "plot", "inspect", "table"];
    let mut problems = Vec::new();
    for layer in NUMERICS {
        for (used, files) in graph.get(layer).into_iter().flatten() {
            if forbidden.contains(&used.as_str()) {
                problems.push(format!("{layer} uses crate::{used} in {files:?}"));
            }
        }
    }
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    for layer in NUMERICS {
        let mut files = Vec::new();
        rust_files(&src.join(layer), &mut files);
        for file in files {
            let Some(code) = production_code(&file) else { continue };
            if code.contains("std::fs") || code.contains("File::open") || code.contains("File::create") {
                problems.push(format!("{} touches the file system", file.display()));
            }
        }
    }
    assert!(problems.is_empty(), "the layering rule (ARCHITECTURE.md) is broken:\n{}", problems.join("\n"));
}

/// Whether `to` can be reached from `from` following uses.
fn reaches(graph: &BTreeMap<String, BTreeMap<String, BTreeSet<String>>>, from: &str, to: &str) -> bool {
    let mut seen = BTreeSet::new();
    let mut stack = vec![from.to_string()];
    while let Some(m) = stack.pop() {
        for next in graph.get(&m).into_iter().flat_map(|u| u.keys()) {
            if next == to {
                return true;
            }
            if seen.insert(next.clone()) {
                stack.push(next.clone());
            }
        }
    }
    false
}

#[test]
fn top_level_modules_form_no_cycle() {
    let graph = module_graph();
    let modules: Vec<String> = graph.keys().cloned().collect();
    let mut cycles = Vec::new();
    for a in &modules {
        for (b, files) in &graph[a] {
            if reaches(&graph, b, a) {
                cycles.push(format!("{a} → {b} ({files:?}) and back"));
            }
        }
    }
    assert!(cycles.is_empty(), "import cycles between top-level modules:\n{}", cycles.join("\n"));
}

/// The crate's root folder.
fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The top-level modules a production file or folder below `src/` names, outside its own.
fn uses_of(path: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let src = root().join("src");
    let mut files = Vec::new();
    if path.is_dir() {
        rust_files(path, &mut files);
    } else {
        files.push(path.to_path_buf());
    }
    let mut uses: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files {
        let relative = file.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
        let own = relative.split('/').next().unwrap().trim_end_matches(".rs").to_string();
        let Some(code) = production_code(&file) else { continue };
        for (i, _) in code.match_indices("crate::") {
            let used: String = code[i + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            if !used.is_empty() && used != own {
                uses.entry(used).or_default().insert(relative.clone());
            }
        }
    }
    uses
}

/// The backticked words of a Markdown table cell.
fn backticked(cell: &str) -> Vec<String> {
    cell.split('`').skip(1).step_by(2).map(str::to_string).collect()
}

#[test]
fn every_module_is_on_the_map_and_keeps_out_of_what_it_may_not_import() {
    let text = std::fs::read_to_string(root().join("ARCHITECTURE.md")).unwrap();
    let map = &text[text.find("## Code map").expect("ARCHITECTURE.md has a code map")..];
    let map = &map[..map[3..].find("\n## ").map_or(map.len(), |i| i + 3)];
    let mut problems = Vec::new();
    let mut mapped = BTreeSet::new();
    for row in map.lines().filter(|l| l.starts_with("| `")) {
        let cells: Vec<&str> = row.split(" | ").collect();
        let forbidden: Vec<String> = cells
            .get(2)
            .map(|c| c.trim_end_matches('|').trim())
            .into_iter()
            .flat_map(|c| {
                let mut words = backticked(c);
                if c.starts_with("numerics") || c.contains(", numerics") {
                    words.extend(NUMERICS.iter().map(|s| s.to_string()));
                }
                words
            })
            .collect();
        for path in backticked(cells[0].trim_start_matches("| ")) {
            let full = root().join(&path);
            if !full.exists() {
                problems.push(format!("the code map names {path}, which does not exist"));
                continue;
            }
            if let Some(module) = path.strip_prefix("src/") {
                mapped.insert(module.split('/').next().unwrap().trim_end_matches(".rs").to_string());
                for (used, files) in uses_of(&full) {
                    if forbidden.contains(&used) {
                        problems.push(format!("{path} may not import {used}, but {files:?} do"));
                    }
                }
            }
        }
    }
    for entry in std::fs::read_dir(root().join("src")).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().trim_end_matches(".rs").to_string();
        if name != "lib" && !mapped.contains(&name) {
            problems.push(format!("src/{name} is not on the code map of ARCHITECTURE.md"));
        }
    }
    assert!(problems.is_empty(), "ARCHITECTURE.md's code map is out of date:\n{}", problems.join("\n"));
}

/// Functions of a file longer than `limit` lines, as rustfmt lays them out (a `fn` line and the
/// first `}` at its indentation).
fn long_functions(path: &Path, limit: usize) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let mut long = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let body = line.trim_start();
        let indent = &line[..line.len() - body.len()];
        let signature = ["fn ", "pub fn ", "pub(super) fn ", "pub(crate) fn "].iter().any(|p| body.starts_with(p));
        if !signature || line.trim_end().ends_with(';') {
            continue;
        }
        let close = format!("{indent}}}");
        if line.trim_end().ends_with('}') {
            continue;
        }
        if let Some(end) = lines[i..].iter().position(|l| *l == close) {
            if end + 1 > limit {
                long.push(format!("{}:{} ({} lines)", path.display(), i + 1, end + 1));
            }
        }
    }
    long
}

/// The production files below `dir`: each file's path, its name relative to `dir` and its code.
fn production_files(dir: &Path) -> Vec<(PathBuf, String, String)> {
    let mut files = Vec::new();
    rust_files(dir, &mut files);
    files
        .into_iter()
        .filter_map(|file| {
            let name = file.strip_prefix(dir).unwrap().to_string_lossy().replace('\\', "/");
            let code = production_code(&file)?;
            Some((file, name, code))
        })
        .collect()
}

#[test]
fn hybrid_models_share_one_driver() {
    let mut problems = Vec::new();
    for (file, name, code) in production_files(&root().join("src/physics")) {
        // Only the driver (and the integrators themselves) step an integrator.
        if name != "hybrid.rs" && name != "ode.rs" && code.contains(".advance(") {
            problems.push(format!("physics/{name} steps an integrator itself: go through physics::hybrid::drive"));
        }
        if code.contains("match index") {
            problems.push(format!("physics/{name} matches event indices: map them to transitions"));
        }
        problems.extend(long_functions(&file, 120).into_iter().map(|f| format!("over 120 lines: {f}")));
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The text of every Rust file below `dir`, joined.
fn all_source(dir: &Path) -> String {
    let mut files = Vec::new();
    rust_files(dir, &mut files);
    files.iter().map(|f| std::fs::read_to_string(f).unwrap()).collect::<Vec<_>>().join("\n")
}

fn defines_fn(source: &str, name: &str) -> bool {
    source.match_indices(&format!("fn {name}")).any(|(i, m)| {
        let next = source[i + m.len()..].chars().next();
        matches!(next, Some('(' | '<'))
    })
}

fn has_word(source: &str, word: &str) -> bool {
    source.match_indices(word).any(|(i, _)| {
        let before = source[..i].chars().next_back();
        let after = source[i + word.len()..].chars().next();
        let ident = |c: Option<char>| c.is_some_and(|c| c.is_ascii_alphanumeric() || c == '_');
        !ident(before) && !ident(after)
    })
}

/// CONTRIBUTING.md's walkthroughs name files, functions, types and tests: each must exist.
#[test]
fn contributing_names_what_exists() {
    let text = std::fs::read_to_string(root().join("CONTRIBUTING.md")).unwrap();
    let code = all_source(&root().join("src")) + &all_source(&root().join("tests"));
    let mut problems = Vec::new();
    let mut checked = 0;
    for token in text.split('`').skip(1).step_by(2) {
        if token.contains('<') || token.contains(' ') {
            continue;
        }
        if ["src/", "tests/", "schemas/"].iter().any(|p| token.starts_with(p)) {
            checked += 1;
            if !root().join(token).exists() {
                problems.push(format!("{token} does not exist"));
            }
            continue;
        }
        let is_ident = |s: &str| s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == ':');
        if let Some(name) = token.strip_suffix("()").filter(|s| is_ident(s)) {
            let name = name.rsplit([':', '.']).next().unwrap();
            checked += 1;
            if !defines_fn(&code, name) {
                problems.push(format!("no function `{name}` (named as `{token}`)"));
            }
        } else if is_ident(token) && token.starts_with(|c: char| c.is_ascii_uppercase()) {
            checked += 1;
            for segment in token.split("::") {
                if !has_word(&code, segment) {
                    problems.push(format!("no `{segment}` in the source (named as `{token}`)"));
                }
            }
        } else if is_ident(token) && token.rsplit("::").next().unwrap().matches('_').count() >= 2 {
            let name = token.rsplit("::").next().unwrap();
            checked += 1;
            if !defines_fn(&code, name) {
                problems.push(format!("no test or function `{name}` (named as `{token}`)"));
            }
        }
    }
    assert!(checked > 40, "only {checked} names checked: has CONTRIBUTING.md lost its walkthroughs?");
    assert!(problems.is_empty(), "CONTRIBUTING.md names what is gone:\n{}", problems.join("\n"));
}

/// The module path of a source file (`pipeline/executor/mod.rs` → `pipeline::executor`).
fn module_path(relative: &str) -> Vec<String> {
    let mut parts: Vec<String> = relative.split('/').map(str::to_string).collect();
    let file = parts.pop().unwrap();
    if file != "mod.rs" {
        parts.push(file.trim_end_matches(".rs").to_string());
    }
    parts
}

/// Inside each top-level module, its submodules → the sibling submodules their production code
/// names (`super::x`, `super::super::x`, `self::x` resolved from the file's own module, or
/// `crate::<module>::x`), and the files that name each. A grandchild's uses count for its child.
fn submodule_graph() -> BTreeMap<String, BTreeMap<String, BTreeSet<String>>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut graph: BTreeMap<String, BTreeMap<String, BTreeSet<String>>> = BTreeMap::new();
    let ident = |s: &str| s.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect::<String>();
    for file in files {
        let relative = file.strip_prefix(&src).unwrap().to_string_lossy().replace('\\', "/");
        let module = module_path(&relative);
        if module.len() < 2 {
            continue;
        }
        let Some(code) = production_code(&file) else { continue };
        let (top, child) = (&module[0], &module[1]);
        let mut named: Vec<Vec<String>> = Vec::new();
        for (i, _) in code.match_indices("crate::") {
            let path: Vec<String> = code[i + 7..].split("::").take(2).map(ident).collect();
            named.push(path);
        }
        for start in ["super::", "self::"] {
            for (i, _) in code.match_indices(start) {
                // Only where a path starts (not `super::super::` counted twice, not `itself::`).
                if code[..i].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_' || c == ':') {
                    continue;
                }
                let mut base = module.clone();
                let mut rest = &code[i..];
                while let Some(after) = rest.strip_prefix("super::") {
                    base.pop();
                    rest = after;
                }
                if let Some(after) = rest.strip_prefix("self::") {
                    rest = after;
                }
                base.push(ident(rest));
                named.push(base);
            }
        }
        for path in named {
            if path.len() >= 2 && path[0] == *top && path[1] != *child && !path[1].is_empty() {
                let (from, to) = (format!("{top}::{child}"), format!("{top}::{}", path[1]));
                graph.entry(from).or_default().entry(to).or_default().insert(relative.clone());
            }
        }
    }
    graph
}

/// After rust-analyzer's and cargo's own tidy rules: inside a module too (the engine's lockfile,
/// sink, ownership checks, plan and stage contract once imported each other in a ring), a
/// submodule that names another is not named back, directly or not.
#[test]
fn submodules_form_no_cycle() {
    let graph = submodule_graph();
    assert!(graph.contains_key("pipeline::executor") && graph.contains_key("pipeline::sink"), "{graph:?}");
    let mut cycles = Vec::new();
    for (a, uses) in &graph {
        for (b, files) in uses {
            if reaches(&graph, b, a) {
                cycles.push(format!("{a} → {b} ({files:?}) and back"));
            }
        }
    }
    assert!(cycles.is_empty(), "import cycles inside a module:\n{}", cycles.join("\n"));
}

/// The output folder's ownership checks run before anything is written: the engine makes them
/// under its lease, and outside it only `validate::ownership` calls them (for `validate`,
/// `shakeflow stage` and `shakeflow diagnose`), so no command keeps a copy that could drift.
#[test]
fn the_ownership_checks_have_one_call_site_outside_the_engine() {
    let mut callers = Vec::new();
    for (_, relative, code) in production_files(&root().join("src")) {
        if relative.starts_with("pipeline/") {
            continue;
        }
        for check in ["check_output_dir(", "check_pipeline(", "check_stage_folders("] {
            if code.contains(check) {
                callers.push(format!("{relative}: {check}"));
            }
        }
    }
    let one = ["validate.rs: check_output_dir(", "validate.rs: check_pipeline(", "validate.rs: check_stage_folders("];
    assert_eq!(callers, one, "call `validate::ownership` instead of the checks themselves");
}
