//! The shape of the crate's source, measured from its imports (issue 35).
//!
//! The measurement reads every `src/**/*.rs` file of a crate and builds a graph of files:
//!
//! - **Files** are the nodes (`lib.rs`, `plan.rs`, `report/mod.rs`, …).
//! - **An import** is an ordered pair of distinct files (A, B) such that A's code names an item of
//!   B through a `use crate::…`, `use super::…`, `use self::…` declaration (groups expanded), a
//!   `use child::…` of one of A's own submodules, or a path written in the code (`crate::x::f`,
//!   `super::x::f`, `child::f`). Comments and strings are not code, so intra-doc links are not
//!   imports; each pair counts once however many names it carries.
//! - **Re-exports lead to the definition**: a path naming a re-exported item counts as an
//!   import of the file that defines the item, so `use crate::RunRecord` imports the module
//!   where `RunRecord` lives. The crate root's own `pub use` lines are its facade, not imports
//!   (or the root would import everything); a `pub use` anywhere else is an import.
//! - **Levels** are the longest-path layering of the graph with cycles condensed: a file that
//!   imports nothing is on level 1; any other file sits one level above the highest file it
//!   imports; the files of one cycle share a level.
//! - **Imports running back up** are the imports of items that a parent module defines: the
//!   crate root (`lib.rs`) for every file, `report/mod.rs` for `report/*`, `report/paper.rs`
//!   for `report/paper/*`. A parent declares its modules, so it sits above them; a module that
//!   takes an error type or a file name from it runs up (these imports are left out of the
//!   layering, or every such module would be in one cycle with its parent). Every import
//!   between two files of one cycle runs back up too (one of them runs against any layering).
//! - **Cycles** are the strongly connected components of more than one file.
//!
//! Measured this way on the code before issue 35 (`main` at 9603bb3), `a2perf-pipeline/src`
//! had 26 files on 7 levels, 79 imports, 30 running back up (20 into a parent, 10 inside
//! cycles) and 2 cycles: `collect, isolate, plan, train` and
//! `report/paper, report/paper/findings, report/render` (the issue's own count, 18 files on 8
//! levels, 51 imports, 11 back up, came from a coarser reading of the same imports; the cycles
//! are the same). The targets: no cycle, at most 3 imports running back up, at most 6 levels.
//! After issue 35: 46 files on 6 levels, 136 imports, none running back up, no cycle.
//!
//! The same scan finds functions over 150 lines (a function is its `fn` line through the
//! brace that closes its body) in the pipeline, the baselines and the web generator.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// Files whose cycles and long functions are printed but not yet held against the targets
/// (empty: every file of the crate is held to them).
const PENDING: &[&str] = &[];

const MAX_LEVELS: usize = 6;
const MAX_BACK_UP: usize = 3;
const MAX_FN_LINES: usize = 150;

fn is_pending(file: &str) -> bool {
    PENDING.iter().any(|p| file.starts_with(p))
}

/// A token of the stripped source: an identifier or keyword, `::`, or one punctuation char.
#[derive(Clone, Debug, PartialEq)]
enum Tok {
    Ident(String),
    PathSep,
    Punct(char),
}

/// Source with comments, strings and character literals blanked (newlines kept, so line
/// numbers survive), so that braces and `crate::` inside them are not read as code.
fn strip(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
        } else if (c == 'r' || c == 'b')
            && !prev_is_ident(&b, i)
            && raw_string_hashes(&b, i).is_some()
        {
            let (start, hashes) = raw_string_hashes(&b, i).unwrap_or((i, 0));
            for _ in i..=start {
                out.push(' ');
            }
            i = start + 1;
            while i < b.len() {
                if b[i] == '"' && (1..=hashes).all(|k| b.get(i + k) == Some(&'#')) {
                    for _ in 0..=hashes {
                        out.push(' ');
                    }
                    i += hashes + 1;
                    break;
                }
                out.push(blank(b[i]));
                i += 1;
            }
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < b.len() {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' && is_char_literal(&b, i) {
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != '\'' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                out.push(' ');
                i += 1;
            }
            out.push(' ');
            i += 1;
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn prev_is_ident(b: &[char], i: usize) -> bool {
    i > 0 && (b[i - 1].is_alphanumeric() || b[i - 1] == '_')
}

/// For `r"`, `r#"`, `br#"` at `i`: the index of the opening quote and the number of hashes.
fn raw_string_hashes(b: &[char], i: usize) -> Option<(usize, usize)> {
    let mut j = i;
    if b[j] == 'b' {
        j += 1;
    }
    if b.get(j) != Some(&'r') {
        return None;
    }
    j += 1;
    let mut hashes = 0;
    while b.get(j) == Some(&'#') {
        hashes += 1;
        j += 1;
    }
    (b.get(j) == Some(&'"')).then_some((j, hashes))
}

/// `'x'` or `'\n'` rather than a lifetime `'a`.
fn is_char_literal(b: &[char], i: usize) -> bool {
    matches!(
        (b.get(i + 1), b.get(i + 2)),
        (Some('\\'), _) | (Some(_), Some('\''))
    )
}

/// Tokens with the line each starts on.
fn tokens(code: &str) -> Vec<(Tok, usize)> {
    let b: Vec<char> = code.chars().collect();
    let mut out = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == '\n' {
            line += 1;
            i += 1;
        } else if c.is_whitespace() {
            i += 1;
        } else if c.is_alphanumeric() || c == '_' {
            let start = i;
            while i < b.len() && (b[i].is_alphanumeric() || b[i] == '_') {
                i += 1;
            }
            let word: String = b[start..i].iter().collect();
            let word = word.strip_prefix("r#").unwrap_or(&word).to_string();
            out.push((Tok::Ident(word), line));
        } else if c == ':' && b.get(i + 1) == Some(&':') {
            out.push((Tok::PathSep, line));
            i += 2;
        } else {
            out.push((Tok::Punct(c), line));
            i += 1;
        }
    }
    out
}

fn ident(t: Option<&(Tok, usize)>) -> Option<&str> {
    match t {
        Some((Tok::Ident(s), _)) => Some(s),
        _ => None,
    }
}

fn punct(t: Option<&(Tok, usize)>, c: char) -> bool {
    matches!(t, Some((Tok::Punct(p), _)) if *p == c)
}

/// The paths a use tree starting at `toks[i]` names, as (segments, alias); returns the index
/// after the tree. `self` in a group names the group's prefix.
fn use_tree(toks: &[(Tok, usize)], mut i: usize, prefix: &[String]) -> (Vec<Vec<String>>, usize) {
    let mut path = prefix.to_vec();
    let mut out = Vec::new();
    loop {
        match toks.get(i) {
            Some((Tok::Ident(s), _)) if s == "as" => {
                i += 2;
            }
            Some((Tok::Ident(s), _)) => {
                if s != "self" || path.is_empty() {
                    path.push(s.clone());
                }
                i += 1;
            }
            Some((Tok::PathSep, _)) => i += 1,
            Some((Tok::Punct('*'), _)) => {
                i += 1;
            }
            Some((Tok::Punct('{'), _)) => {
                i += 1;
                loop {
                    if punct(toks.get(i), '}') {
                        i += 1;
                        break;
                    }
                    if punct(toks.get(i), ',') {
                        i += 1;
                        continue;
                    }
                    let (paths, next) = use_tree(toks, i, &path);
                    out.extend(paths);
                    if next == i {
                        i += 1;
                    } else {
                        i = next;
                    }
                }
                return (out, i);
            }
            _ => {
                out.push(path);
                return (out, i);
            }
        }
    }
}

/// One source file: its module path and what its code names.
struct File {
    rel: String,
    lines: usize,
    /// Paths the file imports, each with the module it was written in.
    imports: Vec<(Vec<String>, Vec<String>)>,
    /// `pub use` re-exports: visible name -> (full path, module it was written in).
    reexports: BTreeMap<String, (Vec<String>, Vec<String>)>,
    /// Functions: (name, first line, lines).
    fns: Vec<(String, usize, usize)>,
}

fn module_path(rel: &str) -> Vec<String> {
    let stem = rel.trim_end_matches(".rs");
    let mut parts: Vec<String> = stem.split('/').map(str::to_string).collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("lib" | "mod" | "main")
    ) {
        parts.pop();
    }
    parts
}

fn read_file(root: &Path, rel: &str, modules: &BTreeSet<Vec<String>>) -> File {
    let src = std::fs::read_to_string(root.join(rel)).unwrap_or_default();
    let toks = tokens(&strip(&src));
    let file_mod = module_path(rel);
    let mut imports = Vec::new();
    let mut reexports = BTreeMap::new();
    let mut fns = Vec::new();
    // Inline modules (`mod tests { … }`) with the brace depth they close at.
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < toks.len() {
        let here: Vec<String> = file_mod
            .iter()
            .cloned()
            .chain(inline.iter().map(|(n, _)| n.clone()))
            .collect();
        match &toks[i].0 {
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                depth = depth.saturating_sub(1);
                if inline.last().is_some_and(|(_, d)| *d == depth) {
                    inline.pop();
                }
            }
            Tok::Ident(w) if w == "mod" => {
                if let (Some(name), true) = (ident(toks.get(i + 1)), punct(toks.get(i + 2), '{')) {
                    inline.push((name.to_string(), depth));
                }
            }
            Tok::Ident(w) if w == "fn" => {
                if let Some(f) = function(&toks, i) {
                    fns.push(f);
                }
            }
            Tok::Ident(w) if w == "use" => {
                let public = is_pub_before(&toks, i);
                let (paths, next) = use_tree(&toks, i + 1, &[]);
                for p in paths {
                    if !is_local(&p, &here, modules) {
                        continue;
                    }
                    if public {
                        let name = reexport_name(&toks, i, next, &p);
                        reexports.insert(name, (p.clone(), here.clone()));
                    }
                    if !(public && here.is_empty()) {
                        imports.push((p, here.clone()));
                    }
                }
                i = next;
                continue;
            }
            Tok::Ident(w) => {
                let after_sep = i > 0 && matches!(toks[i - 1].0, Tok::PathSep | Tok::Punct('.'));
                let starts = matches!(w.as_str(), "crate" | "super" | "self")
                    || modules.contains(&[here.clone(), vec![w.clone()]].concat());
                if !after_sep && starts && matches!(toks.get(i + 1), Some((Tok::PathSep, _))) {
                    let mut path = vec![w.clone()];
                    let mut j = i + 1;
                    while matches!(toks.get(j), Some((Tok::PathSep, _))) {
                        match ident(toks.get(j + 1)) {
                            Some(s) => path.push(s.to_string()),
                            None => break,
                        }
                        j += 2;
                    }
                    imports.push((path, here.clone()));
                    i = j;
                    continue;
                }
            }
            _ => {}
        }
        i += 1;
    }
    File {
        rel: rel.to_string(),
        lines: src.lines().count(),
        imports,
        reexports,
        fns,
    }
}

/// Whether the `use` at `i` is preceded by `pub` or `pub(…)`.
fn is_pub_before(toks: &[(Tok, usize)], i: usize) -> bool {
    if i >= 1 && ident(toks.get(i - 1)) == Some("pub") {
        return true;
    }
    // pub(crate) use / pub(super) use
    i >= 4 && punct(toks.get(i - 1), ')') && ident(toks.get(i - 4)) == Some("pub")
}

/// The name a `pub use` makes visible: its alias or its last segment.
fn reexport_name(toks: &[(Tok, usize)], start: usize, end: usize, path: &[String]) -> String {
    let last = path.last().cloned().unwrap_or_default();
    for k in start..end.saturating_sub(1) {
        if ident(toks.get(k)) == Some(&last)
            && ident(toks.get(k + 1)) == Some("as")
            && let Some(alias) = ident(toks.get(k + 2))
        {
            return alias.to_string();
        }
    }
    last
}

/// Whether a path starts inside the crate (`crate`, `super`, `self` or a submodule).
fn is_local(path: &[String], here: &[String], modules: &BTreeSet<Vec<String>>) -> bool {
    match path.first().map(String::as_str) {
        Some("crate" | "super" | "self") => true,
        Some(first) => modules.contains(&[here.to_vec(), vec![first.to_string()]].concat()),
        None => false,
    }
}

/// The function whose `fn` keyword is at `i`: its name, first line and length in lines.
fn function(toks: &[(Tok, usize)], i: usize) -> Option<(String, usize, usize)> {
    let name = ident(toks.get(i + 1))?.to_string();
    let mut j = i + 2;
    // The body opens at the first `{` outside parentheses; a `;` first means no body.
    let mut parens = 0i32;
    loop {
        match toks.get(j)? {
            (Tok::Punct('(' | '['), _) => parens += 1,
            (Tok::Punct(')' | ']'), _) => parens -= 1,
            (Tok::Punct(';'), _) if parens == 0 => return None,
            (Tok::Punct('{'), _) if parens == 0 => break,
            _ => {}
        }
        j += 1;
    }
    let mut depth = 0;
    for (t, line) in &toks[j..] {
        match t {
            Tok::Punct('{') => depth += 1,
            Tok::Punct('}') => {
                depth -= 1;
                if depth == 0 {
                    return Some((name, toks[i].1, line - toks[i].1 + 1));
                }
            }
            _ => {}
        }
    }
    None
}

/// The import graph of one crate's `src/`.
struct Graph {
    files: Vec<File>,
    /// Imports as (importer, imported) file indices.
    edges: BTreeSet<(usize, usize)>,
}

fn rust_files(dir: &Path, base: &Path, out: &mut Vec<String>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut paths: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    paths.sort();
    for p in paths {
        if p.is_dir() {
            rust_files(&p, base, out);
        } else if p.extension().is_some_and(|e| e == "rs")
            && let Ok(rel) = p.strip_prefix(base)
        {
            out.push(rel.to_string_lossy().replace('\\', "/"));
        }
    }
}

impl Graph {
    fn of(src: &Path) -> Graph {
        let mut rels = Vec::new();
        rust_files(src, src, &mut rels);
        let modules: BTreeSet<Vec<String>> = rels.iter().map(|r| module_path(r)).collect();
        let files: Vec<File> = rels.iter().map(|r| read_file(src, r, &modules)).collect();
        let by_module: BTreeMap<Vec<String>, usize> = files
            .iter()
            .enumerate()
            .map(|(k, f)| (module_path(&f.rel), k))
            .collect();
        let mut edges = BTreeSet::new();
        for (k, f) in files.iter().enumerate() {
            for (path, here) in &f.imports {
                if let Some(target) = resolve(path, here, &by_module, &files, 0)
                    && target != k
                {
                    edges.insert((k, target));
                }
            }
        }
        Graph { files, edges }
    }

    /// Whether `a` imports an item that one of its parent modules (`lib.rs` above every file,
    /// `report/mod.rs` above `report/*`) defines.
    fn runs_up(&self, a: usize, b: usize) -> bool {
        let (ma, mb) = (
            module_path(&self.files[a].rel),
            module_path(&self.files[b].rel),
        );
        mb.len() < ma.len() && ma.starts_with(&mb)
    }

    fn name(&self, k: usize) -> &str {
        &self.files[k].rel
    }

    /// Strongly connected components (Tarjan), as a component index per file, over the imports
    /// that do not run up into a parent.
    fn components(&self) -> Vec<usize> {
        struct State<'a> {
            adj: &'a [Vec<usize>],
            index: Vec<Option<usize>>,
            low: Vec<usize>,
            on_stack: Vec<bool>,
            stack: Vec<usize>,
            next: usize,
            comp: Vec<usize>,
            comps: usize,
        }
        fn visit(s: &mut State, v: usize) {
            s.index[v] = Some(s.next);
            s.low[v] = s.next;
            s.next += 1;
            s.stack.push(v);
            s.on_stack[v] = true;
            for &w in &s.adj[v] {
                match s.index[w] {
                    None => {
                        visit(s, w);
                        s.low[v] = s.low[v].min(s.low[w]);
                    }
                    Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                    Some(_) => {}
                }
            }
            if Some(s.low[v]) == s.index[v] {
                while let Some(w) = s.stack.pop() {
                    s.on_stack[w] = false;
                    s.comp[w] = s.comps;
                    if w == v {
                        break;
                    }
                }
                s.comps += 1;
            }
        }
        let n = self.files.len();
        let mut adj = vec![Vec::new(); n];
        for &(a, b) in &self.edges {
            if !self.runs_up(a, b) {
                adj[a].push(b);
            }
        }
        let mut s = State {
            adj: &adj,
            index: vec![None; n],
            low: vec![0; n],
            on_stack: vec![false; n],
            stack: Vec::new(),
            next: 0,
            comp: vec![0; n],
            comps: 0,
        };
        for v in 0..n {
            if s.index[v].is_none() {
                visit(&mut s, v);
            }
        }
        s.comp
    }

    fn measure(&self) -> Measure {
        let comp = self.components();
        let mut members: BTreeMap<usize, Vec<usize>> = BTreeMap::new();
        for (k, c) in comp.iter().enumerate() {
            members.entry(*c).or_default().push(k);
        }
        let cycles: Vec<Vec<String>> = members
            .values()
            .filter(|m| m.len() > 1)
            .map(|m| m.iter().map(|&k| self.name(k).to_string()).collect())
            .collect();
        // Tarjan numbers components so that a component's imports come first.
        let mut comp_level = vec![1usize; members.len()];
        for c in 0..members.len() {
            for &(a, b) in &self.edges {
                if comp[a] == c && comp[b] != c && !self.runs_up(a, b) {
                    comp_level[c] = comp_level[c].max(comp_level[comp[b]] + 1);
                }
            }
        }
        let level: Vec<usize> = comp.iter().map(|&c| comp_level[c]).collect();
        let into_parent: Vec<(usize, usize)> = self
            .edges
            .iter()
            .copied()
            .filter(|&(a, b)| self.runs_up(a, b))
            .collect();
        let in_cycle: Vec<(usize, usize)> = self
            .edges
            .iter()
            .copied()
            .filter(|&(a, b)| !self.runs_up(a, b) && comp[a] == comp[b])
            .collect();
        Measure {
            files: self.files.len(),
            levels: level.iter().copied().max().unwrap_or(0),
            imports: self.edges.len(),
            into_parent,
            in_cycle,
            cycles,
            level,
        }
    }

    fn print(&self, title: &str, m: &Measure) {
        println!(
            "{title}: {} files on {} levels, {} imports, {} running back up ({} into a parent, {} inside cycles), {} cycles",
            m.files,
            m.levels,
            m.imports,
            m.into_parent.len() + m.in_cycle.len(),
            m.into_parent.len(),
            m.in_cycle.len(),
            m.cycles.len()
        );
        for c in &m.cycles {
            println!("  cycle: {}", c.join(" <-> "));
        }
        for &(a, b) in m.into_parent.iter().chain(&m.in_cycle) {
            println!("  back up: {} -> {}", self.name(a), self.name(b));
        }
        let mut order: Vec<usize> = (0..self.files.len()).collect();
        order.sort_by_key(|&k| (std::cmp::Reverse(m.level[k]), self.name(k).to_string()));
        for k in order {
            let imports: Vec<&str> = self
                .edges
                .iter()
                .filter(|&&(a, _)| a == k)
                .map(|&(_, b)| self.name(b))
                .collect();
            println!(
                "  level {:>2} {:>5} lines  {:<28} -> {}",
                m.level[k],
                self.files[k].lines,
                self.name(k),
                imports.join(", ")
            );
        }
    }
}

/// The file that defines the item `path` names, written in module `here`; `None` outside the
/// crate. Follows `pub use` re-exports to the defining file.
fn resolve(
    path: &[String],
    here: &[String],
    by_module: &BTreeMap<Vec<String>, usize>,
    files: &[File],
    hops: usize,
) -> Option<usize> {
    let mut base: Vec<String> = here.to_vec();
    let mut rest = path;
    match rest.first().map(String::as_str) {
        Some("crate") => {
            base.clear();
            rest = &rest[1..];
        }
        Some("self") => rest = &rest[1..],
        _ => {}
    }
    while rest.first().map(String::as_str) == Some("super") {
        base.pop();
        rest = &rest[1..];
    }
    // Descend through module files.
    while let Some(seg) = rest.first() {
        let mut next = base.clone();
        next.push(seg.clone());
        if by_module.contains_key(&next) {
            base = next;
            rest = &rest[1..];
        } else {
            break;
        }
    }
    // An inline module (`mod tests`) belongs to the file that holds it.
    while !by_module.contains_key(&base) {
        base.pop();
    }
    let file = *by_module.get(&base)?;
    if let Some(name) = rest.first()
        && let Some((target, written_in)) = files[file].reexports.get(name)
        && hops < 8
    {
        return resolve(target, written_in, by_module, files, hops + 1);
    }
    Some(file)
}

struct Measure {
    files: usize,
    levels: usize,
    imports: usize,
    into_parent: Vec<(usize, usize)>,
    in_cycle: Vec<(usize, usize)>,
    cycles: Vec<Vec<String>>,
    level: Vec<usize>,
}

fn crate_src(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(name)
        .join("src")
}

#[test]
fn pipeline_imports_are_layered() {
    let g = Graph::of(&crate_src("a2perf-pipeline"));
    let m = g.measure();
    g.print("a2perf-pipeline/src", &m);
    assert!(m.files > 10, "the scan found the crate's files");
    let cycles: Vec<&Vec<String>> = m
        .cycles
        .iter()
        .filter(|c| !c.iter().all(|f| is_pending(f)))
        .collect();
    assert!(cycles.is_empty(), "import cycles: {cycles:?}");
    let back_up = m
        .into_parent
        .iter()
        .chain(&m.in_cycle)
        .filter(|&&(a, b)| !(is_pending(g.name(a)) && is_pending(g.name(b))))
        .count();
    assert!(
        back_up <= MAX_BACK_UP,
        "{back_up} imports run back up (at most {MAX_BACK_UP})"
    );
    assert!(
        m.levels <= MAX_LEVELS,
        "{} levels (at most {MAX_LEVELS})",
        m.levels
    );
}

#[test]
fn core_imports_have_no_cycle() {
    let g = Graph::of(&crate_src("a2perf-core"));
    let m = g.measure();
    g.print("a2perf-core/src", &m);
    assert!(m.files > 10, "the scan found the crate's files");
    // The scan does see the imports: training uses the policy, rollout and resume modules.
    let training: Vec<&str> = g
        .edges
        .iter()
        .filter(|&&(a, _)| g.name(a) == "training.rs")
        .map(|&(_, b)| g.name(b))
        .collect();
    for m in ["policy.rs", "rollout.rs", "resume.rs", "checkpoint.rs"] {
        assert!(
            training.contains(&m),
            "training.rs -> {m} not found: {training:?}"
        );
    }
    assert!(m.cycles.is_empty(), "import cycles: {:?}", m.cycles);
}

/// The crates whose functions are held to [`MAX_FN_LINES`]: the pipeline, the baselines'
/// algorithms and the web generator (issue 35: a long function becomes named steps).
const SHORT_FUNCTIONS: &[(&str, Option<&str>)] = &[
    ("a2perf-pipeline", None),
    ("a2perf-baselines", None),
    ("a2perf-web", Some("generator")),
];

#[test]
fn functions_are_short() {
    let mut long = Vec::new();
    let mut seen = 0;
    for &(krate, only) in SHORT_FUNCTIONS {
        let g = Graph::of(&crate_src(krate));
        for f in &g.files {
            if only.is_some_and(|prefix| !f.rel.starts_with(prefix)) {
                continue;
            }
            for (name, line, lines) in &f.fns {
                seen += 1;
                if *lines > MAX_FN_LINES {
                    println!("{krate}/src/{}:{line} fn {name}: {lines} lines", f.rel);
                    if !is_pending(&f.rel) {
                        long.push(format!(
                            "{krate}/src/{}:{line} {name} ({lines} lines)",
                            f.rel
                        ));
                    }
                }
            }
        }
    }
    assert!(seen > 500, "the scan found the functions ({seen})");
    assert!(
        long.is_empty(),
        "functions over {MAX_FN_LINES} lines: {long:?}"
    );
}

#[test]
fn the_scan_reads_paths_groups_and_reexports() {
    // A small crate in a temporary directory: lib.rs re-exports `a::Item`; `b` imports it
    // through the root, `c` through a group with `self`, and `a` names `c` in code.
    let dir = std::env::temp_dir().join(format!("a2perf-structure-{}", std::process::id()));
    let src = dir.join("src");
    std::fs::create_dir_all(src.join("d")).unwrap();
    let write = |p: &str, s: &str| std::fs::write(src.join(p), s).unwrap();
    write(
        "lib.rs",
        "pub mod a; pub mod b; pub mod c; pub mod d;\npub use a::Item;\npub struct Root;\n",
    );
    write(
        "a.rs",
        "pub struct Item;\nfn f() { let s = \"crate::b::X {\"; crate::c::g(); }\n",
    );
    write(
        "b.rs",
        "use crate::Item;\n// use crate::d::Y;\nuse super::Root;\n",
    );
    write(
        "c.rs",
        "use crate::{d::{self, E}};\npub fn g() {}\n#[cfg(test)]\nmod tests { use super::*; }\n",
    );
    write("d/mod.rs", "mod e; pub use e::E;\n");
    write("d/e.rs", "pub struct E; use super::super::c::g;\n");
    let g = Graph::of(&src);
    std::fs::remove_dir_all(&dir).unwrap();
    let edges: BTreeSet<(&str, &str)> = g
        .edges
        .iter()
        .map(|&(a, b)| (g.name(a), g.name(b)))
        .collect();
    let expected: BTreeSet<(&str, &str)> = [
        ("a.rs", "c.rs"),
        ("b.rs", "a.rs"),
        ("b.rs", "lib.rs"),
        ("c.rs", "d/mod.rs"),
        ("c.rs", "d/e.rs"),
        ("d/mod.rs", "d/e.rs"),
        ("d/e.rs", "c.rs"),
    ]
    .into_iter()
    .collect();
    assert_eq!(edges, expected);
    let m = g.measure();
    let cycle: Vec<String> = ["c.rs", "d/e.rs", "d/mod.rs"].map(String::from).to_vec();
    assert_eq!(m.cycles, vec![cycle]);
    assert_eq!(m.into_parent.len(), 1, "b imports the root's own item");
    assert_eq!(m.in_cycle.len(), 4);
    // The cycle on level 1, a on 2, b on 3.
    assert_eq!(m.levels, 3);
}
