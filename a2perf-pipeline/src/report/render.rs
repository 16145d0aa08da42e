//! Tables: Markdown, LaTeX (booktabs, as the paper) and CSV.

use std::collections::BTreeSet;
use std::fmt::Write;

use super::{Category, Group, GroupReport, MetricValue, Report};

/// The original's number format: two decimals, or scientific notation below 0.01.
///
/// ```
/// use a2perf_pipeline::report::render::format_value;
/// assert_eq!(format_value(12.345), "12.35");
/// assert_eq!(format_value(0.00123), "1.23e-3");
/// assert_eq!(format_value(0.0), "0.00");
/// assert_eq!(format_value(-0.0), "0.00");
/// ```
pub fn format_value(v: f64) -> String {
    if v != 0.0 && v.abs() < 1e-2 {
        format!("{v:.2e}")
    } else {
        // `-0.00` would suggest a sign the value does not have.
        format!("{:.2}", if v == 0.0 { 0.0 } else { v })
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
        let groups: Vec<&GroupReport> = report.groups.iter().filter(|g| g.task == task).collect();
        let first = groups[0];
        let _ = writeln!(s, "## {task} (`{}`, {})\n", first.env_id, first.domain);
        let _ = write!(s, "| Category | Metric | ");
        for g in &groups {
            let _ = write!(
                s,
                "{} (seeds {}) | ",
                g.algorithm.to_uppercase(),
                g.seeds.len()
            );
        }
        let _ = writeln!(s);
        let _ = writeln!(s, "|---|---|{}", "---|".repeat(groups.len()));
        for (cat, key, label, unit, higher) in rows(&groups) {
            let arrow = if higher { "↑" } else { "↓" };
            let _ = write!(s, "| {} | {label} ({unit}) {arrow} | ", cat.label());
            for g in &groups {
                let c = g.metric(key).map_or_else(|| "—".into(), |m| cell(m, false));
                let _ = write!(s, "{c} | ");
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(s);
        let mut notes = Vec::new();
        for g in &groups {
            for m in &g.metrics {
                if let Some(n) = &m.note {
                    notes.push(format!("- {} / {}: {}", g.algorithm, m.key, n));
                }
            }
        }
        if !notes.is_empty() {
            let _ = writeln!(
                s,
                "<details><summary>Notes</summary>\n\n{}\n\n</details>\n",
                notes.join("\n")
            );
        }
    }
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
                e.task,
                e.algorithm,
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
                e.x,
                e.y,
                e.tasks.len(),
                e.probability,
                e.ci95[0],
                e.ci95[1]
            );
        }
        let _ = writeln!(s);
    }
    if !report.skipped_runs.is_empty() {
        let _ = writeln!(s, "## Runs left out\n");
        for (dir, why) in &report.skipped_runs {
            let _ = writeln!(s, "- `{dir}`: {why}");
        }
    }
    s
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
        let _ = writeln!(s, "\\begin{{table}}[t]\n\\centering\n\\small");
        let _ = writeln!(
            s,
            "\\begin{{tabular}}{{ll{}}}\n\\toprule",
            "c".repeat(groups.len())
        );
        let _ = write!(s, "Category & Metric (unit)");
        for g in &groups {
            let _ = write!(
                s,
                " & \\textbf{{{}}}",
                tex_escape(&g.algorithm.to_uppercase())
            );
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
            for g in &groups {
                let c = g.metric(key).map_or_else(|| "--".into(), |m| cell(m, true));
                let _ = write!(s, " & {c}");
            }
            let _ = writeln!(s, " \\\\");
        }
        let _ = writeln!(s, "\\bottomrule\n\\end{{tabular}}");
        let _ = writeln!(
            s,
            "\\caption{{Metrics for {} (mean $\\pm$ std over seeds).}}\n\\label{{tab:metrics-{}}}\n\\end{{table}}\n",
            tex_escape(task),
            super::super::plan::path_safe(task)
        );
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
/// the run named `<task>/<algorithm>/seed<k>`.
pub fn curves_csv(groups: &[Group]) -> String {
    let mut s = String::from("run,step,value\n");
    for g in groups {
        for r in &g.runs {
            let name = csv_field(&format!(
                "{}/{}/seed{}",
                g.task, g.algorithm, r.run.record.seed
            ));
            for p in &r.curve.points {
                let _ = writeln!(s, "{name},{},{}", p.env_steps, p.mean_return);
            }
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
