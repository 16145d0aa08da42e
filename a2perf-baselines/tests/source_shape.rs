//! Two shape rules of the sources, checked by a small scan (issue 35): no function in the
//! baselines is longer than 150 lines (a training loop is written as named steps), and the
//! modules of `a2perf-core` import each other without a cycle. The scan blanks comments and
//! literals, then matches braces; it knows enough Rust for these sources, not all of Rust.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_FUNCTION_LINES: usize = 150;

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).expect("readable source directory") {
            let path = entry.expect("directory entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// `src` with comments, strings and character literals replaced by spaces (newlines kept, so
/// line numbers stay right).
fn blank(src: &str) -> String {
    let c: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let keep = |ch: char| if ch == '\n' { '\n' } else { ' ' };
    // The character `k` places after `i` (NUL past the end).
    let at = |i: usize, k: usize| c.get(i + k).copied().unwrap_or('\0');
    let mut i = 0;
    while i < c.len() {
        if c[i] == '/' && at(i, 1) == '/' {
            while i < c.len() && c[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c[i] == '/' && at(i, 1) == '*' {
            let mut depth = 0;
            loop {
                if i >= c.len() {
                    break;
                }
                if c[i] == '/' && at(i, 1) == '*' {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if c[i] == '*' && at(i, 1) == '/' {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(keep(c[i]));
                    i += 1;
                }
            }
        } else if c[i] == 'r'
            && (i == 0 || !is_ident(c[i - 1]) || c[i - 1] == 'b')
            && (at(i, 1) == '"' || (at(i, 1) == '#' && matches!(at(i, 2), '"' | '#')))
        {
            // Raw string: r"…", r#"…"#, br"…", …
            let mut hashes = 0;
            i += 1;
            out.push(' ');
            while at(i, 0) == '#' {
                hashes += 1;
                i += 1;
                out.push(' ');
            }
            i += 1;
            out.push(' ');
            while i < c.len() {
                if c[i] == '"' && (1..=hashes).all(|k| at(i, k) == '#') {
                    for _ in 0..=hashes {
                        out.push(' ');
                    }
                    i += hashes + 1;
                    break;
                }
                out.push(keep(c[i]));
                i += 1;
            }
        } else if c[i] == '"' {
            out.push(' ');
            i += 1;
            while i < c.len() && c[i] != '"' {
                if c[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < c.len() {
                    out.push(keep(c[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c[i] == '\'' && (at(i, 2) == '\'' || at(i, 1) == '\\') {
            // A character literal ('x', '\n', '\u{..}'), not a lifetime.
            out.push(' ');
            i += 1;
            while i < c.len() && c[i] != '\'' {
                if c[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                out.push(' ');
                i += 1;
            }
            out.push(' ');
            i += 1;
        } else {
            out.push(c[i]);
            i += 1;
        }
    }
    out
}

fn is_ident(ch: char) -> bool {
    ch.is_alphanumeric() || ch == '_'
}

/// `(name, first line, number of lines)` of every function with a body in `src` (blanked).
fn functions(src: &str) -> Vec<(String, usize, usize)> {
    let c: Vec<char> = src.chars().collect();
    let line_of = |i: usize| c[..i].iter().filter(|ch| **ch == '\n').count() + 1;
    let mut out = Vec::new();
    let mut i = 0;
    while i + 2 < c.len() {
        let word_start = i == 0 || !is_ident(c[i - 1]);
        if !(word_start && c[i] == 'f' && c[i + 1] == 'n' && c[i + 2].is_whitespace()) {
            i += 1;
            continue;
        }
        let mut j = i + 2;
        while j < c.len() && c[j].is_whitespace() {
            j += 1;
        }
        let name: String = c[j..].iter().take_while(|ch| is_ident(**ch)).collect();
        if name.is_empty() {
            // `fn(…)`: a function pointer type.
            i = j;
            continue;
        }
        // The body opens at the first `{` outside the signature's brackets; a `;` first
        // means a declaration without a body.
        let mut depth = 0i32;
        let mut open = None;
        while j < c.len() {
            match c[j] {
                '(' | '[' | '<' => depth += 1,
                ')' | ']' => depth -= 1,
                '>' if c[j - 1] != '-' => depth -= 1,
                '{' if depth <= 0 => {
                    open = Some(j);
                    break;
                }
                ';' if depth <= 0 => break,
                _ => {}
            }
            j += 1;
        }
        let Some(open) = open else {
            i = j;
            continue;
        };
        let mut braces = 0;
        let mut close = open;
        for (k, ch) in c.iter().enumerate().skip(open) {
            match ch {
                '{' => braces += 1,
                '}' => {
                    braces -= 1;
                    if braces == 0 {
                        close = k;
                        break;
                    }
                }
                _ => {}
            }
        }
        let first = line_of(i);
        out.push((name, first, line_of(close) - first + 1));
        i += 2;
    }
    out
}

#[test]
fn the_scan_measures_functions() {
    let src = blank(
        "/// fn not_me() {\nfn a(x: Vec<u8>) -> u8 {\n    let s = \"}\";\n    let c = '}';\n    x[0]\n}\n\
         trait T { fn decl(&self) -> fn(u8) -> u8; }\nfn b<'a>(s: &'a str) { let _ = r#\"{\"#; }\n",
    );
    assert_eq!(
        functions(&src),
        vec![("a".to_string(), 2, 5), ("b".to_string(), 8, 1)]
    );
}

#[test]
fn no_function_in_the_baselines_exceeds_150_lines() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut long = Vec::new();
    let mut count = 0;
    for path in rust_files(&src) {
        let text = std::fs::read_to_string(&path).expect("readable source");
        for (name, line, lines) in functions(&blank(&text)) {
            count += 1;
            if lines > MAX_FUNCTION_LINES {
                long.push(format!("{}:{line} `{name}`: {lines} lines", path.display()));
            }
        }
    }
    assert!(count > 100, "the scan found only {count} functions");
    assert!(
        long.is_empty(),
        "functions over {MAX_FUNCTION_LINES} lines:\n{}",
        long.join("\n")
    );
}

/// The modules (top level of `src`) that each module of the crate at `src` names through
/// `crate::…` paths; names that the root re-exports are resolved to their module.
fn module_imports(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let files = rust_files(src);
    let module_of = |path: &Path| -> String {
        let rel = path.strip_prefix(src).expect("under src");
        let first = rel.components().next().expect("a component");
        first
            .as_os_str()
            .to_string_lossy()
            .trim_end_matches(".rs")
            .to_string()
    };
    let modules: BTreeSet<String> = files.iter().map(|p| module_of(p)).collect();
    // `pub use module::{A, B};` and `pub use module::A;` in lib.rs.
    let lib = blank(&std::fs::read_to_string(src.join("lib.rs")).expect("lib.rs"));
    let mut reexports: BTreeMap<String, String> = BTreeMap::new();
    for item in lib.split(';') {
        let Some(path) = item.trim().strip_prefix("pub use ") else {
            continue;
        };
        let Some((module, names)) = path.split_once("::") else {
            continue;
        };
        for name in names
            .trim_matches(|c| c == '{' || c == '}' || char::is_whitespace(c))
            .split(',')
        {
            let name = name.trim();
            if !name.is_empty() {
                reexports.insert(name.to_string(), module.trim().to_string());
            }
        }
    }
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for path in &files {
        let from = module_of(path);
        if from == "lib" {
            continue;
        }
        let text = blank(&std::fs::read_to_string(path).expect("readable source"));
        let mut named = Vec::new();
        for (at, _) in text.match_indices("crate::") {
            if at > 0 && is_ident(text[..at].chars().last().unwrap_or(' ')) {
                continue;
            }
            let rest = &text[at + "crate::".len()..];
            if let Some(group) = rest.strip_prefix('{') {
                // The first segment of each top-level item of `{a::{b, c}, d}`.
                let mut depth = 0;
                let mut item_start = true;
                for (k, ch) in group.char_indices() {
                    match ch {
                        '{' => depth += 1,
                        '}' if depth == 0 => break,
                        '}' => depth -= 1,
                        ',' if depth == 0 => item_start = true,
                        c if item_start && is_ident(c) => {
                            item_start = false;
                            named.push(group[k..].chars().take_while(|c| is_ident(*c)).collect());
                        }
                        _ => {}
                    }
                }
            } else {
                named.push(rest.chars().take_while(|c| is_ident(*c)).collect());
            }
        }
        for name in named {
            let to = if modules.contains(&name) {
                Some(name)
            } else {
                reexports.get(&name).cloned()
            };
            if let Some(to) = to.filter(|t| *t != from && t != "lib") {
                graph.entry(from.clone()).or_default().insert(to);
            }
        }
    }
    graph
}

/// A cycle of `graph`, if it has one.
fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(at) = path.iter().position(|p| p == node) {
            let mut cycle = path[at..].to_vec();
            cycle.push(node.to_string());
            return Some(cycle);
        }
        if done.contains(node) {
            return None;
        }
        path.push(node.to_string());
        for next in graph.get(node).into_iter().flatten() {
            if let Some(c) = visit(next, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(node.to_string());
        None
    }
    let mut done = BTreeSet::new();
    graph
        .keys()
        .find_map(|n| visit(n, graph, &mut Vec::new(), &mut done))
}

#[test]
fn the_scan_finds_cycles() {
    let g = |edges: &[(&str, &str)]| {
        let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
        for (a, b) in edges {
            g.entry(a.to_string()).or_default().insert(b.to_string());
        }
        g
    };
    assert_eq!(find_cycle(&g(&[("a", "b"), ("b", "c"), ("a", "c")])), None);
    assert_eq!(
        find_cycle(&g(&[("a", "b"), ("b", "c"), ("c", "a")])),
        Some(vec!["a".into(), "b".into(), "c".into(), "a".into()])
    );
}

#[test]
fn the_core_modules_import_each_other_without_a_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../a2perf-core/src");
    let graph = module_imports(&src);
    // The scan does see the imports: training uses the policy, rollout and resume modules.
    let training = graph.get("training").cloned().unwrap_or_default();
    for m in ["policy", "rollout", "resume", "checkpoint"] {
        assert!(training.contains(m), "training -> {m} not found: {graph:?}");
    }
    assert_eq!(find_cycle(&graph), None, "{graph:#?}");
}
