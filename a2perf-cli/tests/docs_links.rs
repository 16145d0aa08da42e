//! Every relative link of `README.md` and of the pages under `docs/` points at a file that
//! exists, and every `#anchor` at a heading of its target (GitHub's heading ids). Links to other
//! sites are not fetched (no network in tests); they are only counted. Every markdown table of
//! those pages renders as one on GitHub: its delimiter row has the header's cell count, and so
//! does every body row.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The markdown pages checked: the README and every `.md` below `docs/`.
fn pages() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        let mut entries: Vec<_> = entries.flatten().map(|e| e.path()).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "md") {
                out.push(p);
            }
        }
    }
    let mut out = vec![root().join("README.md")];
    walk(&root().join("docs"), &mut out);
    out
}

/// The page's lines outside fenced code blocks, numbered from 1.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut in_fence = false;
    let mut out = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            in_fence = !in_fence;
        } else if !in_fence {
            out.push((n + 1, line));
        }
    }
    out
}

/// A line without its inline code spans (where `](` is text, not a link).
fn without_code_spans(line: &str) -> String {
    line.split('`').step_by(2).collect()
}

/// `[text](target)` and `![alt](target)` targets of a line.
fn link_targets(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = line;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        let target = after[..end].split_whitespace().next().unwrap_or("");
        if !target.is_empty() {
            out.push(target.to_string());
        }
        rest = &after[end..];
    }
    out
}

/// GitHub's id of a heading: markup dropped, lower case, punctuation removed, spaces to `-`.
fn slug(heading: &str) -> String {
    // A link in a heading contributes its text only.
    let mut text = String::new();
    let mut rest = heading;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let Some(end) = after.find(')') else { break };
        text.push_str(&rest[..i]);
        rest = &after[end + 1..];
    }
    text.push_str(rest);
    text.to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | ' '))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The heading ids of a markdown page (a repeated heading gets `-1`, `-2`, … as on GitHub).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|c| *c == '#').count();
        if hashes == 0 || hashes > 6 || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = slug(line[hashes..].trim());
        let mut id = base.clone();
        let mut n = 0;
        while out.contains(&id) {
            n += 1;
            id = format!("{base}-{n}");
        }
        out.insert(id);
    }
    out
}

/// Where a code span starting at `start` (a run of backticks) ends: the byte after its closing
/// run of the same length, or `None` when it has none (then the backticks are literal text).
fn code_span_end(line: &str, start: usize) -> Option<usize> {
    let run = line[start..].bytes().take_while(|b| *b == b'`').count();
    let mut i = start + run;
    while let Some(off) = line[i..].find('`') {
        let at = i + off;
        let len = line[at..].bytes().take_while(|b| *b == b'`').count();
        if len == run {
            return Some(at + len);
        }
        i = at + len;
    }
    None
}

/// The cells of a table row, as GitHub splits them: at every `|` that is neither escaped (`\|`)
/// nor inside an inline code span; a leading and a trailing pipe are optional.
fn table_cells(row: &str) -> Vec<String> {
    let row = row.trim();
    let mut cells = Vec::new();
    let (mut cell_start, mut i) = (0, 0);
    let mut ends_with_pipe = false;
    while i < row.len() {
        ends_with_pipe = false;
        match row.as_bytes()[i] {
            // An escaped character, whatever its width, is text.
            b'\\' => i += 1 + row[i + 1..].chars().next().map_or(0, char::len_utf8),
            b'`' => match code_span_end(row, i) {
                Some(end) => i = end,
                None => i += row[i..].bytes().take_while(|b| *b == b'`').count(),
            },
            b'|' => {
                cells.push(row[cell_start..i].trim().to_string());
                i += 1;
                cell_start = i;
                ends_with_pipe = true;
            }
            _ => i += row[i..].chars().next().map_or(1, char::len_utf8),
        }
    }
    if !ends_with_pipe {
        cells.push(row[cell_start..].trim().to_string());
    }
    if row.starts_with('|') {
        cells.remove(0);
    }
    cells
}

/// A delimiter row (`|---|:--:|`): at least one pipe, and every cell dashes with optional colons.
fn is_delimiter_row(line: &str) -> bool {
    let cells = table_cells(line);
    line.contains('|')
        && !cells.is_empty()
        && cells.iter().all(|c| {
            let dashes = c.strip_prefix(':').unwrap_or(c);
            let dashes = dashes.strip_suffix(':').unwrap_or(dashes);
            !dashes.is_empty() && dashes.bytes().all(|b| b == b'-')
        })
}

/// The tables of a page and what would break each on GitHub: a delimiter row whose cell count is
/// not the header's (then no table renders at all), a body row with another count, and a row
/// cut off from its table (by a blank line or a paragraph). Returns the number of tables and
/// one message per problem.
fn table_problems(text: &str) -> (usize, Vec<String>) {
    let lines = prose_lines(text);
    let mut problems = Vec::new();
    let mut tables = 0;
    let mut k = 0;
    while k < lines.len() {
        let (n, line) = lines[k];
        let next = lines.get(k + 1).filter(|(m, _)| *m == n + 1);
        match next {
            Some(&(_, delimiter)) if line.contains('|') && is_delimiter_row(delimiter) => {
                tables += 1;
                let columns = table_cells(line).len();
                let found = table_cells(delimiter).len();
                if found != columns {
                    problems.push(format!(
                        "line {n}: header has {columns} cells, its delimiter row {found}"
                    ));
                }
                k += 2;
                // The body: every following line up to a blank one (a fence ends it too).
                while let Some(&(m, row)) = lines.get(k) {
                    if m != lines[k - 1].0 + 1 || row.trim().is_empty() {
                        break;
                    }
                    let found = table_cells(row).len();
                    if found != columns {
                        problems.push(format!(
                            "line {m}: row has {found} cells, the header {columns}"
                        ));
                    }
                    k += 1;
                }
            }
            _ => {
                if is_delimiter_row(line) {
                    problems.push(format!("line {n}: delimiter row without a header row"));
                } else if line.trim_start().starts_with('|') {
                    problems.push(format!("line {n}: table row outside any table"));
                }
                k += 1;
            }
        }
    }
    (tables, problems)
}

#[test]
fn every_relative_link_and_anchor_resolves() {
    let pages = pages();
    assert!(pages.len() > 10, "only {} pages found", pages.len());
    let mut broken = Vec::new();
    let (mut checked, mut external) = (0, 0);
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        let shown = page
            .strip_prefix(root())
            .unwrap_or(page)
            .display()
            .to_string();
        for (n, line) in prose_lines(&text) {
            for target in link_targets(&without_code_spans(line)) {
                if target.contains("://") || target.starts_with("mailto:") {
                    external += 1;
                    continue;
                }
                checked += 1;
                let (path, anchor) = match target.split_once('#') {
                    Some((p, a)) => (p, Some(a)),
                    None => (target.as_str(), None),
                };
                let file = if path.is_empty() {
                    page.clone()
                } else {
                    page.parent().unwrap().join(path)
                };
                if !file.exists() {
                    broken.push(format!("{shown}:{n}: `{target}`: no such file"));
                    continue;
                }
                let Some(anchor) = anchor else { continue };
                if file.extension().is_none_or(|e| e != "md") {
                    continue;
                }
                let target_text = std::fs::read_to_string(&file).unwrap();
                if !anchors(&target_text).contains(anchor) {
                    broken.push(format!("{shown}:{n}: `{target}`: no heading `#{anchor}`"));
                }
            }
        }
    }
    println!("{checked} relative links checked, {external} links to other sites not fetched");
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    assert!(checked > 50, "only {checked} relative links found");
}

#[test]
fn slugs_follow_github() {
    assert_eq!(slug("The paper, reproduced"), "the-paper-reproduced");
    assert_eq!(
        slug("Report excerpt (from the quickstart)"),
        "report-excerpt-from-the-quickstart"
    );
    assert_eq!(slug("From Rust: plugging in"), "from-rust-plugging-in");
    assert_eq!(slug("[docs](x.md) and more"), "docs-and-more");
    assert_eq!(slug("The `a2perf_rs` package"), "the-a2perf_rs-package");
    let ids = anchors("# A\n## A\n```\n# not a heading\n```\n## B c\n");
    assert_eq!(
        ids,
        BTreeSet::from(["a".into(), "a-1".into(), "b-c".into()])
    );
}

#[test]
fn the_front_page_stays_a_front_page() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= 300,
        "README.md has {lines} lines; move detail into docs/"
    );
}

#[test]
fn every_table_renders_with_matching_cell_counts() {
    let (mut tables, mut broken) = (0, Vec::new());
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let shown = page
            .strip_prefix(root())
            .unwrap_or(&page)
            .display()
            .to_string();
        let (found, problems) = table_problems(&text);
        tables += found;
        broken.extend(problems.into_iter().map(|p| format!("{shown}: {p}")));
    }
    println!("{tables} tables checked");
    assert!(broken.is_empty(), "broken tables:\n{}", broken.join("\n"));
    assert!(tables > 40, "only {tables} tables found");
}

#[test]
fn cells_split_as_github_splits_them() {
    assert_eq!(table_cells("| a | b |"), ["a", "b"]);
    assert_eq!(table_cells("a | b"), ["a", "b"]);
    assert_eq!(table_cells("| a | |"), ["a", ""]);
    assert_eq!(
        table_cells(r"| `x | y` | a \| b | c |"),
        ["`x | y`", r"a \| b", "c"]
    );
    // A double-backtick span holds single backticks; an unclosed backtick is literal.
    assert_eq!(
        table_cells("| ``a ` | b`` | ` c | d |"),
        ["``a ` | b``", "` c", "d"]
    );
    assert_eq!(table_cells(r"| x → y | \é | é |"), ["x → y", r"\é", "é"]);
    assert!(is_delimiter_row("|---|:--:|--:|"));
    assert!(is_delimiter_row("--- | ---"));
    assert!(!is_delimiter_row("---"));
    assert!(!is_delimiter_row("| a | --- |"));
}

#[test]
fn the_table_check_fails_on_broken_tables() {
    let good = "| a | b |\n|---|---|\n| 1 | `x|y` |\n\ntext\n";
    assert_eq!(table_problems(good), (1, vec![]));

    // The README's old performance table: five header cells over a four-cell delimiter row.
    let header = "| what | original | target | measured | command |\n|---|---|---|---|\n| a | b | c | d | e |\n";
    let (tables, problems) = table_problems(header);
    assert_eq!(tables, 1);
    assert_eq!(
        problems,
        ["line 1: header has 5 cells, its delimiter row 4"]
    );

    let short_row = "| a | b | c |\n|---|---|---|\n| 1 | 2 |\n| 1 | 2 | 3 | 4 |\n";
    assert_eq!(
        table_problems(short_row).1,
        [
            "line 3: row has 2 cells, the header 3",
            "line 4: row has 4 cells, the header 3"
        ]
    );

    // A paragraph inside the table ends it: the rows after it are text on GitHub.
    let split = "| a | b |\n|---|---|\n| 1 | 2 |\n\nA paragraph.\n| 3 | 4 |\n";
    assert_eq!(
        table_problems(split).1,
        ["line 6: table row outside any table"]
    );
    let glued = "| a | b |\n|---|---|\nno pipe here\n";
    assert_eq!(
        table_problems(glued).1,
        ["line 3: row has 1 cells, the header 2"]
    );
    assert_eq!(
        table_problems("text\n\n|---|---|\n").1,
        ["line 3: delimiter row without a header row"]
    );

    // Fenced code is not a table.
    assert_eq!(table_problems("```\n| a |\n|---|---|\n```\n"), (0, vec![]));
}
