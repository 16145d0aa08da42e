//! Tables: Markdown, LaTeX (booktabs, as the paper) and CSV.

use std::collections::BTreeSet;
use std::fmt::Write;

use a2perf_core::LearningCurve;

pub use super::format::{format_ratio, format_value};
use super::model::{
    Category, FindingCheck, GroupReport, GroupTimeSplit, MetricValue, PaperCell, PaperComparison,
    RATIO_METRICS, Report, TableSettings, Verdict,
};

/// Text from the results (names, notes, reasons) made inert in Markdown: HTML's `&`, `<` and
/// `>` become entities, so a name holding markup is shown, never run, and `|` is escaped so that
/// it cannot split a table cell.
///
/// ```
/// use a2perf_pipeline::report::render::md_text;
/// assert_eq!(md_text("<img src=x>|a&b"), "&lt;img src=x&gt;\\|a&amp;b");
/// ```
pub fn md_text(t: &str) -> String {
    let mut out = String::with_capacity(t.len());
    for c in t.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '|' => out.push_str("\\|"),
            _ => out.push(c),
        }
    }
    out
}

/// A code span of `t` outside tables; inside one nothing is markup, so only a backtick (which
/// would end the span early) makes it fall back to [`md_text`].
fn md_code(t: &str) -> String {
    if t.contains('`') || t.contains('\n') {
        md_text(t)
    } else {
        format!("`{t}`")
    }
}

fn cell(m: &MetricValue, latex: bool) -> String {
    match m.mean {
        None => {
            if latex {
                "--".into()
            } else {
                "—".into()
            }
        }
        Some(mean) => {
            let pm = if latex { " \\pm " } else { " ± " };
            let mut s = format_value(mean);
            if let Some(sd) = m.std {
                s.push_str(pm);
                s.push_str(&format_value(sd));
            }
            if latex {
                s = format!("${s}$");
            } else if let Some([lo, hi]) = m.ci95
                && m.per_seed.len() > 1
            {
                let _ = write!(s, " [{}, {}]", format_value(lo), format_value(hi));
            }
            s
        }
    }
}

fn paper_cell(c: Option<&PaperCell>, latex: bool) -> String {
    let missing = if latex { "--" } else { "—" };
    match c.and_then(|c| c.mean.map(|m| (m, c.std))) {
        None => missing.into(),
        Some((mean, std)) => {
            let pm = if latex { " \\pm " } else { " ± " };
            let mut s = format_value(mean);
            if let Some(sd) = std {
                s.push_str(pm);
                s.push_str(&format_value(sd));
            }
            if latex {
                s = format!("${s}$");
            }
            if let Some(v) = c.and_then(verdict_text) {
                let _ = write!(s, " ({v})");
            }
            s
        }
    }
}

/// `beats`, `within`, or `trails by GAP`: where our mean stands against the paper's.
///
/// ```
/// use a2perf_pipeline::report::paper::{PaperCell, Verdict};
/// use a2perf_pipeline::report::render::verdict_text;
/// let (verdict, gap) = Verdict::judge(0.25, 1.0, Some(0.5));
/// let cell = PaperCell {
///     key: "returns".into(), mean: Some(1.0), std: Some(0.5), unit: "100 eps.".into(),
///     published: None, conversion: None, ratio: None, source: None, note: None,
///     verdict: Some(verdict), gap, paper_metric: None, phase: None, out_of_reach: None,
/// };
/// assert_eq!(verdict_text(&cell).as_deref(), Some("trails by 0.75"));
/// let cell = PaperCell { out_of_reach: Some("out of reach here: ...".into()), ..cell };
/// assert_eq!(verdict_text(&cell).as_deref(), Some("trails by 0.75, out of reach here"));
/// ```
pub fn verdict_text(c: &PaperCell) -> Option<String> {
    let reach = if c.out_of_reach.is_some() {
        ", out of reach here"
    } else {
        ""
    };
    c.verdict.map(|v| match (v, c.gap) {
        (Verdict::Trails, Some(gap)) => format!("trails by {}{reach}", format_value(gap)),
        _ => v.as_str().to_string(),
    })
}

/// `holds`, `does not hold` or `not checked`.
fn holds_text(h: Option<bool>) -> &'static str {
    match h {
        Some(true) => "holds",
        Some(false) => "does not hold",
        None => "not checked",
    }
}

/// The findings section of `report.md`.
fn findings_md(s: &mut String, findings: &[FindingCheck]) {
    // The claims come from a tables file someone else wrote: escaped like every other string.
    let esc = md_text;
    let _ = writeln!(s, "## The paper's findings\n");
    let _ = writeln!(
        s,
        "Each claim of the paper's evaluation, checked on these runs with the same definition \
         as on the paper's figures (in `tables.json`).\n"
    );
    let _ = writeln!(
        s,
        "| Id | Claim | Paper | Ours | On our runs |\n|---|---|---|---|---|"
    );
    for f in findings {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | **{}** |",
            esc(&f.id),
            esc(&f.claim),
            esc(&f.paper),
            esc(&f.ours),
            holds_text(f.holds)
        );
    }
    let notes: Vec<String> = findings
        .iter()
        .filter_map(|f| {
            f.note
                .as_ref()
                .map(|n| format!("- {}: {}", md_text(&f.id), md_text(n)))
        })
        .collect();
    let _ = writeln!(s);
    if !notes.is_empty() {
        let _ = writeln!(
            s,
            "<details><summary>Notes</summary>\n\n{}\n\n</details>\n",
            notes.join("\n")
        );
    }
}

/// Text for LaTeX: escaped, with the symbols of the findings' numbers in math mode.
fn tex_text(t: &str) -> String {
    tex_escape(t)
        .replace('±', "$\\pm$")
        .replace('≤', "$\\le$")
        .replace('≥', "$\\ge$")
        .replace('×', "$\\times$")
        .replace('≈', "$\\approx$")
        .replace('—', "--")
}

/// The findings as a LaTeX table.
fn findings_latex(s: &mut String, findings: &[FindingCheck]) {
    let _ = writeln!(
        s,
        "\\begin{{table}}[t]\n\\centering\n\\small\n\\begin{{tabular}}{{lp{{5cm}}p{{3.5cm}}p{{3.5cm}}l}}\n\\toprule\nId & Claim & Paper & Ours & On our runs \\\\\n\\midrule"
    );
    for f in findings {
        let _ = writeln!(
            s,
            "{} & {} & {} & {} & {} \\\\",
            tex_text(&f.id),
            tex_text(&f.claim),
            tex_text(&f.paper),
            tex_text(&f.ours),
            holds_text(f.holds)
        );
    }
    let _ = writeln!(
        s,
        "\\bottomrule\n\\end{{tabular}}\n\\caption{{The paper's findings, checked on these runs.}}\n\\label{{tab:paper-findings}}\n\\end{{table}}\n"
    );
}

/// One line naming a profile and every switch it gives the task's environment.
fn describe_profile(p: Option<&crate::spec::ProfileRecord>) -> String {
    match p {
        None => "none (corrected defaults)".into(),
        Some(p) if p.switches.is_empty() => {
            format!("{} (no environment switches for this task)", p.name)
        }
        Some(p) => format!(
            "{} — {}",
            p.name,
            p.switches
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// `from <source>: <tasks>`.
fn describe_suite(u: &super::model::SuiteUse) -> String {
    match u.source {
        None => "the domain's registry default (not recorded by these runs)".into(),
        Some(source) => format!("from {}: {}", source.label(), u.tasks.join(", ")),
    }
}

fn upper(algos: &[String]) -> String {
    algos
        .iter()
        .map(|a| a.to_uppercase())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The profile and generalization-suite lines printed under a table's heading.
pub(super) fn settings_lines(t: &TableSettings) -> Vec<String> {
    let mut out = Vec::new();
    if t.mixed_profiles() {
        let parts: Vec<String> = t
            .profiles
            .iter()
            .map(|u| {
                format!(
                    "{}: {}",
                    upper(&u.algorithms),
                    describe_profile(u.profile.as_ref())
                )
            })
            .collect();
        out.push(format!(
            "**Mixed profiles in this table** (its columns ran under different environment \
             semantics): {}",
            parts.join("; ")
        ));
    } else if let Some(u) = t.profiles.first() {
        out.push(format!("Profile: {}", describe_profile(u.profile.as_ref())));
    }
    if t.mixed_suites() {
        let parts: Vec<String> = t
            .suites
            .iter()
            .map(|u| format!("{}: {}", upper(&u.algorithms), describe_suite(u)))
            .collect();
        out.push(format!(
            "**Mixed generalization suites in this table** (its generalization sums are over \
             different tasks): {}",
            parts.join("; ")
        ));
    } else if let Some(u) = t.suites.first() {
        out.push(format!("Generalization suite: {}", describe_suite(u)));
    }
    out
}

/// Where the paper's column of a table comes from.
pub(super) fn paper_heading(p: &PaperComparison) -> String {
    format!(
        "{}{} ({}; paper task `{}`)",
        p.paper_title,
        p.table
            .as_ref()
            .map(|t| format!(", {t}"))
            .unwrap_or_default(),
        p.version,
        p.paper_task
    )
}

/// Notes on the paper's column: sources, conversions and missing values.
fn paper_notes(p: &PaperComparison) -> Vec<String> {
    let mut notes = Vec::new();
    for col in &p.columns {
        if !col.in_paper {
            notes.push(format!(
                "{} (paper): the paper does not report this algorithm on this task",
                col.algorithm
            ));
        }
        for c in &col.cells {
            let mut parts = Vec::new();
            match (c.mean, &c.source) {
                (Some(_), Some(src)) => parts.push(src.clone()),
                (None, _) => parts.push("no paper value".into()),
                _ => {}
            }
            if let Some(p) = &c.published {
                parts.push(format!("published {p}"));
            }
            if let Some(conv) = &c.conversion {
                parts.push(conv.clone());
            }
            if let Some(n) = &c.note {
                parts.push(n.clone());
            }
            if let Some(r) = &c.out_of_reach {
                parts.push(r.clone());
            }
            notes.push(format!(
                "{} (paper) / {}: {}",
                col.algorithm,
                c.key,
                parts.join("; ")
            ));
        }
    }
    if !p.not_run.is_empty() {
        notes.push(format!(
            "the paper also reports {} on this task (not run here)",
            upper(&p.not_run)
        ));
    }
    if let Some(n) = &p.note {
        notes.push(format!("paper task: {n}"));
    }
    notes
}

fn tasks(report: &Report) -> Vec<&str> {
    let set: BTreeSet<&str> = report.groups.iter().map(|g| g.task.as_str()).collect();
    set.into_iter().collect()
}

fn rows<'a>(groups: &[&'a GroupReport]) -> Vec<(Category, &'a str, &'a str, &'a str, bool)> {
    let mut out = Vec::new();
    if let Some(g) = groups.first() {
        for m in &g.metrics {
            out.push((
                m.category,
                m.key.as_str(),
                m.label.as_str(),
                m.unit.as_str(),
                m.higher_is_better,
            ));
        }
    }
    out
}

/// The report as Markdown: one table per task (metrics × algorithms), then IQM and probability
/// of improvement, then notes on missing or estimated values.
pub fn markdown(report: &Report) -> String {
    let mut s = String::from("# A2Perf report\n\n");
    let _ = writeln!(
        s,
        "Values are mean ± std over seeds (sample std) with a 95% percentile-bootstrap interval \
         of the mean ({} resamples) in brackets; reliability metrics are computed across the \
         seeds of each group (± their own spread where they have one). ↑ higher is better, ↓ lower \
         is better; — missing (see notes).\n",
        report.bootstrap_reps
    );
    for task in tasks(report) {
        task_md(&mut s, report, task);
    }
    if !report.findings.is_empty() {
        findings_md(&mut s, &report.findings);
    }
    comparisons_md(&mut s, report);
    time_split_md(&mut s, report);
    if !report.skipped_runs.is_empty() {
        let _ = writeln!(s, "## Runs left out\n");
        for (dir, why) in &report.skipped_runs {
            let _ = writeln!(s, "- {}: {}", md_code(dir), md_text(why));
        }
    }
    s
}

/// "Where training time went": per group, its training wall time and each part's share of it
/// (only for groups whose runs recorded it; nothing for a report without any).
fn time_split_md(s: &mut String, report: &Report) {
    let rows: Vec<(&GroupReport, &GroupTimeSplit)> = report
        .groups
        .iter()
        .filter_map(|g| g.time_split.as_ref().map(|t| (g, t)))
        .collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "## Where training time went\n\nTraining wall time summed over each group's seeds, and \
         the share of it each part took (timed by the training loop; `other` is what no part \
         claims: setup, batching outside learning, bookkeeping).\n"
    );
    let _ = writeln!(
        s,
        "| task | algorithm | wall (h) | env | act | learn | evaluation | io | other |\n\
         |---|---|---|---|---|---|---|---|---|"
    );
    for (g, t) in rows {
        let share = |x: f64| {
            if t.wall_s > 0.0 {
                format!("{:.0}%", 100.0 * x / t.wall_s)
            } else {
                "—".to_string()
            }
        };
        let parts: Vec<String> = t.parts.parts().iter().map(|&(_, x)| share(x)).collect();
        let _ = writeln!(
            s,
            "| {} | {} | {:.3} | {} | {} |",
            md_text(&g.task),
            md_text(&g.algorithm),
            t.wall_s / 3600.0,
            parts.join(" | "),
            share((t.wall_s - t.parts.total()).max(0.0))
        );
    }
    let _ = writeln!(s);
}

/// The table of one task in Markdown: settings, our columns (and the paper's), the ratio
/// table and the notes.
fn task_md(s: &mut String, report: &Report, task: &str) {
    let groups: Vec<&GroupReport> = report.groups.iter().filter(|g| g.task == task).collect();
    let first = groups[0];
    let paper = report.paper_of(task);
    let _ = writeln!(
        s,
        "## {} ({}, {})\n",
        md_text(task),
        md_code(&first.env_id),
        md_text(&first.domain)
    );
    if let Some(t) = report.settings_of(task) {
        for line in settings_lines(t) {
            let _ = writeln!(s, "{}\n", md_text(&line));
        }
    }
    if let Some(p) = paper {
        let _ = writeln!(
            s,
            "Paper columns: {}, in our units (conversions in the notes).\n",
            md_text(&paper_heading(p))
        );
    }
    let _ = write!(s, "| Category | Metric | ");
    for g in &groups {
        let algorithm = md_text(&g.algorithm.to_uppercase());
        let verified = if g.verified { ", **verified**" } else { "" };
        let _ = write!(s, "{algorithm} (seeds {}{verified}) | ", g.seeds.len());
        if paper.is_some() {
            let _ = write!(s, "{algorithm} (paper) | ");
        }
    }
    let _ = writeln!(s);
    let columns = groups.len() * if paper.is_some() { 2 } else { 1 };
    let _ = writeln!(s, "|---|---|{}", "---|".repeat(columns));
    for (cat, key, label, unit, higher) in rows(&groups) {
        let arrow = if higher { "↑" } else { "↓" };
        let _ = write!(
            s,
            "| {} | {} ({}) {arrow} | ",
            cat.label(),
            md_text(label),
            md_text(unit)
        );
        for c in row_cells(&groups, paper, key, false) {
            let _ = write!(s, "{c} | ");
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s);
    if let Some(p) = paper {
        ratio_table_md(s, &groups, p);
    }
    let mut notes = Vec::new();
    for g in &groups {
        for m in &g.metrics {
            if let Some(n) = &m.note {
                notes.push(format!(
                    "- {} / {}: {}",
                    md_text(&g.algorithm),
                    m.key,
                    md_text(n)
                ));
            }
        }
    }
    if let Some(p) = paper {
        notes.extend(
            paper_notes(p)
                .into_iter()
                .map(|n| format!("- {}", md_text(&n))),
        );
    }
    if !notes.is_empty() {
        let _ = writeln!(
            s,
            "<details><summary>Notes</summary>\n\n{}\n\n</details>\n",
            notes.join("\n")
        );
    }
}

/// The IQM and probability-of-improvement tables in Markdown.
fn comparisons_md(s: &mut String, report: &Report) {
    if !report.iqm.is_empty() {
        let _ = writeln!(s, "## Interquartile mean of returns (95% bootstrap CI)\n");
        let _ = writeln!(
            s,
            "| Task | Algorithm | Runs | IQM | 95% CI |\n|---|---|---|---|---|"
        );
        for e in &report.iqm {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | [{}, {}] |",
                md_text(&e.task),
                md_text(&e.algorithm),
                e.runs,
                format_value(e.iqm),
                format_value(e.ci95[0]),
                format_value(e.ci95[1])
            );
        }
        let _ = writeln!(s);
    }
    if !report.probability_of_improvement.is_empty() {
        let _ = writeln!(s, "## Probability of improvement P(X > Y) on returns\n");
        let _ = writeln!(
            s,
            "| X | Y | Tasks | P(X > Y) | 95% CI |\n|---|---|---|---|---|"
        );
        for e in &report.probability_of_improvement {
            let _ = writeln!(
                s,
                "| {} | {} | {} | {:.3} | [{:.3}, {:.3}] |",
                md_text(&e.x),
                md_text(&e.y),
                e.tasks.len(),
                e.probability,
                e.ci95[0],
                e.ci95[1]
            );
        }
        let _ = writeln!(s);
    }
}

/// The cells of metric `key`'s row, one per group and, beside each, the paper's when the
/// table has a paper column (missing: a dash).
fn row_cells(
    groups: &[&GroupReport],
    paper: Option<&PaperComparison>,
    key: &str,
    latex: bool,
) -> Vec<String> {
    let dash = if latex { "--" } else { "—" };
    let mut out = Vec::new();
    for g in groups {
        out.push(
            g.metric(key)
                .map_or_else(|| dash.into(), |m| cell(m, latex)),
        );
        if let Some(p) = paper {
            let pc = p
                .columns
                .iter()
                .find(|c| c.algorithm == g.algorithm)
                .and_then(|c| c.cell(key));
            out.push(paper_cell(pc, latex));
        }
    }
    out
}

/// The ratio rows (energy, RAM, wall-clock time) of a table with a paper column.
fn ratio_rows<'a>(
    groups: &[&'a GroupReport],
    p: &PaperComparison,
) -> Vec<(&'a MetricValue, Vec<Option<f64>>)> {
    let Some(first) = groups.first() else {
        return Vec::new();
    };
    first
        .metrics
        .iter()
        .filter(|m| RATIO_METRICS.contains(&m.key.as_str()))
        .map(|m| {
            let ratios = groups
                .iter()
                .map(|g| {
                    p.columns
                        .iter()
                        .find(|c| c.algorithm == g.algorithm)
                        .and_then(|c| c.cell(&m.key))
                        .and_then(|c| c.ratio)
                })
                .collect();
            (m, ratios)
        })
        .collect()
}

fn ratio_table_md(s: &mut String, groups: &[&GroupReport], p: &PaperComparison) {
    let _ = writeln!(
        s,
        "Ours / paper (energy, RAM, wall-clock; 1 = the same, below 1 = less):\n"
    );
    let _ = write!(s, "| Category | Metric | ");
    for g in groups {
        let _ = write!(s, "{} | ", md_text(&g.algorithm.to_uppercase()));
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "|---|---|{}", "---|".repeat(groups.len()));
    for (m, ratios) in ratio_rows(groups, p) {
        let _ = write!(
            s,
            "| {} | {} ({}) | ",
            m.category.label(),
            md_text(&m.label),
            md_text(&m.unit)
        );
        for r in ratios {
            let _ = write!(s, "{} | ", r.map_or_else(|| "—".into(), format_ratio));
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s);
}

fn tex_escape(t: &str) -> String {
    let mut out = String::with_capacity(t.len());
    for c in t.chars() {
        match c {
            '_' | '%' | '&' | '#' | '$' | '{' | '}' => {
                out.push('\\');
                out.push(c);
            }
            '~' => out.push_str("\\textasciitilde{}"),
            '^' => out.push_str("\\textasciicircum{}"),
            '\\' => out.push_str("\\textbackslash{}"),
            _ => out.push(c),
        }
    }
    out
}

/// The report as LaTeX tables (booktabs), one per task, in the paper's layout: rows
/// (category, metric (unit)), columns the algorithms in bold upper case.
pub fn latex(report: &Report) -> String {
    let mut s = String::from("% Generated by `a2perf report`. Requires \\usepackage{booktabs}.\n");
    for task in tasks(report) {
        let groups: Vec<&GroupReport> = report.groups.iter().filter(|g| g.task == task).collect();
        let paper = report.paper_of(task);
        let per_group = if paper.is_some() { 2 } else { 1 };
        let _ = writeln!(s, "\\begin{{table}}[t]\n\\centering\n\\small");
        let _ = writeln!(
            s,
            "\\begin{{tabular}}{{ll{}}}\n\\toprule",
            "c".repeat(groups.len() * per_group)
        );
        let _ = write!(s, "Category & Metric (unit)");
        for g in &groups {
            let _ = write!(
                s,
                " & \\textbf{{{}}}",
                tex_escape(&g.algorithm.to_uppercase())
            );
            if paper.is_some() {
                let _ = write!(
                    s,
                    " & \\textbf{{{}}} (paper)",
                    tex_escape(&g.algorithm.to_uppercase())
                );
            }
        }
        let _ = writeln!(s, " \\\\\n\\midrule");
        let mut last = None;
        for (cat, key, label, unit, _) in rows(&groups) {
            if last.is_some() && last != Some(cat) {
                let _ = writeln!(s, "\\midrule");
            }
            let cat_cell = if last == Some(cat) {
                String::new()
            } else {
                cat.label().into()
            };
            last = Some(cat);
            let _ = write!(
                s,
                "{} & {} ({})",
                tex_escape(&cat_cell),
                tex_escape(label),
                tex_escape(unit)
            );
            for c in row_cells(&groups, paper, key, true) {
                let _ = write!(s, " & {c}");
            }
            let _ = writeln!(s, " \\\\");
        }
        if let Some(p) = paper {
            let _ = writeln!(
                s,
                "\\midrule\n\\multicolumn{{{}}}{{l}}{{Ours / paper}} \\\\",
                2 + groups.len() * per_group
            );
            for (m, ratios) in ratio_rows(&groups, p) {
                let _ = write!(
                    s,
                    "{} & {} ({})",
                    tex_escape(m.category.label()),
                    tex_escape(&m.label),
                    tex_escape(&m.unit)
                );
                for r in ratios {
                    let v = r.map_or_else(|| "--".into(), |r| format!("${}$", format_ratio(r)));
                    // The ratio sits in the paper column of its algorithm.
                    let _ = write!(s, " & & {v}");
                }
                let _ = writeln!(s, " \\\\");
            }
        }
        let _ = writeln!(s, "\\bottomrule\n\\end{{tabular}}");
        let mut caption = format!(
            "Metrics for {} (mean $\\pm$ std over seeds).",
            tex_escape(task)
        );
        if let Some(t) = report.settings_of(task) {
            for line in settings_lines(t) {
                let _ = write!(caption, " {}.", tex_escape(&line.replace("**", "")));
            }
        }
        if let Some(p) = paper {
            let _ = write!(
                caption,
                " Paper columns: {}, in our units.",
                tex_escape(&paper_heading(p))
            );
        }
        let _ = writeln!(
            s,
            "\\caption{{{caption}}}\n\\label{{tab:metrics-{}}}\n\\end{{table}}\n",
            crate::run_dir::path_safe(task)
        );
    }
    if !report.findings.is_empty() {
        findings_latex(&mut s, &report.findings);
    }
    s
}

/// The paper comparison, one row per (task, algorithm, metric) the paper gives:
/// `paper_comparison.csv`.
pub fn paper_csv(report: &Report) -> String {
    let mut s = String::from(
        "task,paper_task,algorithm,metric,unit,ours_mean,paper_mean,paper_std,ratio_ours_over_paper,verdict,gap,published,conversion,source,note\n",
    );
    for p in &report.paper {
        for col in &p.columns {
            let ours = report
                .groups
                .iter()
                .find(|g| g.task == p.task && g.algorithm == col.algorithm);
            for c in &col.cells {
                let mean = ours.and_then(|g| g.metric(&c.key)).and_then(|m| m.mean);
                let _ = writeln!(
                    s,
                    "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
                    csv_field(&p.task),
                    csv_field(&p.paper_task),
                    csv_field(&col.algorithm),
                    c.key,
                    csv_field(&c.unit),
                    opt(mean),
                    opt(c.mean),
                    opt(c.std),
                    opt(c.ratio),
                    c.verdict.map(Verdict::as_str).unwrap_or_default(),
                    opt(c.gap),
                    csv_field(c.published.as_deref().unwrap_or("")),
                    csv_field(c.conversion.as_deref().unwrap_or("")),
                    csv_field(c.source.as_deref().unwrap_or("")),
                    csv_field(c.note.as_deref().unwrap_or("")),
                );
            }
        }
    }
    s
}

fn csv_field(t: &str) -> String {
    if t.contains([',', '"', '\n']) {
        format!("\"{}\"", t.replace('"', "\"\""))
    } else {
        t.to_string()
    }
}

fn opt(v: Option<f64>) -> String {
    v.map(|x| x.to_string()).unwrap_or_default()
}

/// One row per (task, algorithm, metric): long format for spreadsheets and pandas.
pub fn csv(report: &Report) -> String {
    let mut s = String::from(
        "task,env_id,domain,algorithm,category,metric,unit,higher_is_better,n_seeds,mean,std,ci95_low,ci95_high,per_seed,note\n",
    );
    for g in &report.groups {
        for m in &g.metrics {
            let per_seed = m
                .per_seed
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(";");
            let _ = writeln!(
                s,
                "{},{},{},{},{:?},{},{},{},{},{},{},{},{},{},{}",
                csv_field(&g.task),
                csv_field(&g.env_id),
                csv_field(&g.domain),
                csv_field(&g.algorithm),
                m.category,
                m.key,
                csv_field(&m.unit),
                m.higher_is_better,
                g.seeds.len(),
                opt(m.mean),
                opt(m.std),
                opt(m.ci95.map(|c| c[0])),
                opt(m.ci95.map(|c| c[1])),
                per_seed,
                csv_field(m.note.as_deref().unwrap_or("")),
            );
        }
    }
    s
}

/// Every training curve as `run,step,value` (the input of `a2perf metrics reliability`), with
/// the run named `<task>/<algorithm>/seed<k>`. `runs` are `(task, algorithm, seed, curve)`.
pub fn curves_csv<'a>(
    runs: impl IntoIterator<Item = (&'a str, &'a str, u64, &'a LearningCurve)>,
) -> String {
    let mut s = String::from("run,step,value\n");
    for (task, algorithm, seed, curve) in runs {
        let name = csv_field(&format!("{task}/{algorithm}/seed{seed}"));
        for p in &curve.points {
            let _ = writeln!(s, "{name},{},{}", p.env_steps, p.mean_return);
        }
    }
    s
}

/// Per-seed mean returns as `algorithm,task,run,score` (the input of `a2perf metrics iqm`).
pub fn scores_csv(report: &Report) -> String {
    let mut s = String::from("algorithm,task,run,score\n");
    for g in &report.groups {
        if let Some(m) = g.metric("returns") {
            for (seed, v) in g.seeds.iter().zip(&m.per_seed) {
                let _ = writeln!(
                    s,
                    "{},{},{seed},{v}",
                    csv_field(&g.algorithm),
                    csv_field(&g.task)
                );
            }
        }
    }
    s
}
