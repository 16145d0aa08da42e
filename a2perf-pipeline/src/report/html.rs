//! `index.html`: the whole report as one self-contained page to look at.
//!
//! Styles, script, data and plots are inline: the page makes no network request, opens from
//! `file://` and needs no server. It is rendered from the same [`Report`] as `report.json`, plus
//! the runs' curves and inference-time summaries ([`RunView`]).
//!
//! Everything on the page comes from result files, which are untrusted input: every string is
//! HTML-escaped ([`escape`]), in text and in attributes; the data the script reads sits in a
//! `<script type="application/json">` block escaped by [`json_for_script`]; the script builds
//! no markup from strings (no `innerHTML`). Every number drawn from `report.json` carries its
//! exact value and its JSON pointer (`data-value`, `data-ref`) beside the formatted text, so a
//! test can check the page against the file.
//!
//! ```
//! use a2perf_pipeline::report::html::escape;
//! assert_eq!(escape(r#"<img src=x onerror="a('b')">"#),
//!            "&lt;img src=x onerror=&quot;a(&#39;b&#39;)&quot;&gt;");
//! ```

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::{Path, PathBuf};

use a2perf_metrics::numeric;
use serde::Serialize;

use super::format::{format_ratio, format_value};
use super::load::Group;
use super::model::{Category, FindingCheck, GroupReport, MetricValue, PaperCell, Report, Verdict};
use super::svg::{PALETTE, frame, nice_ticks, plot_ranges, tick_label};
use crate::stats::Summary;
use crate::{
    CURVE_CSV, GENERALIZATION_FILE, INFERENCE_FILE, OPERATIVE_FILE, RUN_FILE, TRAIN_SYSTEM_FILE,
};
use crate::{PipelineError, Result};

const STYLE: &str = include_str!("html/report.css");
const SCRIPT: &str = include_str!("html/report.js");

/// Points of a curve drawn per algorithm; the figures in tables come from the full curves.
const CURVE_POINTS: usize = 160;

/// The leaderboard's columns: the headline metric of each family (key, column title).
pub const LEADERBOARD_METRICS: &[(&str, &str)] = &[
    ("returns", "Return"),
    ("generalization", "Generalization"),
    ("energy", "Training energy"),
    ("peak_ram", "Peak RAM"),
    ("wall_clock", "Wall clock"),
    ("inference_time", "Inference time"),
    ("dispersion_across_runs", "Dispersion across runs"),
    ("risk_across_runs", "Risk across runs"),
];

/// Files of a run directory the page links to, when present.
const RUN_FILES: &[&str] = &[
    RUN_FILE,
    CURVE_CSV,
    OPERATIVE_FILE,
    INFERENCE_FILE,
    GENERALIZATION_FILE,
    TRAIN_SYSTEM_FILE,
];

/// `t` safe in HTML text and in quoted attribute values: `&`, `<`, `>`, `"` and `'` become
/// character references.
pub fn escape(t: &str) -> String {
    let mut out = String::with_capacity(t.len() + 8);
    for c in t.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

/// `value` as JSON that can sit inside `<script type="application/json">`: `<`, `>` and `&`
/// (which could close the element or open a comment) and U+2028/U+2029 are written as `\u`
/// escapes, which JSON reads back as the same characters.
///
/// ```
/// use a2perf_pipeline::report::html::json_for_script;
/// let j = json_for_script(&serde_json::json!({"name": "</script><b>&\u{2028}"}));
/// assert_eq!(j, r#"{"name":"\u003c/script\u003e\u003cb\u003e\u0026\u2028"}"#);
/// ```
pub fn json_for_script<T: Serialize>(value: &T) -> String {
    // Serializing plain data (strings, numbers, vectors, maps with string keys) cannot fail.
    let text = serde_json::to_string(value).unwrap_or_else(|_| "null".into());
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '<' => out.push_str("\\u003c"),
            '>' => out.push_str("\\u003e"),
            '&' => out.push_str("\\u0026"),
            '\u{2028}' => out.push_str("\\u2028"),
            '\u{2029}' => out.push_str("\\u2029"),
            _ => out.push(c),
        }
    }
    out
}

/// A path for an `href`: each component percent-encoded (all but letters, digits, `-`, `_`,
/// `.`, `~`), joined by `/`.
fn href(path: &Path) -> String {
    use std::path::Component;
    let parts: Vec<String> = path
        .components()
        .filter(|c| matches!(c, Component::Normal(_) | Component::ParentDir))
        .map(|c| {
            let s = c.as_os_str().to_string_lossy();
            let mut out = String::new();
            for b in s.bytes() {
                if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~') {
                    out.push(b as char);
                } else {
                    let _ = write!(out, "%{b:02X}");
                }
            }
            out
        })
        .collect();
    let joined = parts.join("/");
    if path.is_absolute() {
        format!("file:///{joined}")
    } else if joined.is_empty() {
        ".".into()
    } else {
        joined
    }
}

/// `target` relative to `base` (both resolved), e.g. `../results/x/run0`; `None` when either
/// cannot be resolved.
fn relative_to(target: &Path, base: &Path) -> Option<PathBuf> {
    let t = target.canonicalize().ok()?;
    let b = base.canonicalize().ok()?;
    let tc: Vec<_> = t.components().collect();
    let bc: Vec<_> = b.components().collect();
    let common = tc.iter().zip(&bc).take_while(|(x, y)| x == y).count();
    let mut p = PathBuf::new();
    for _ in common..bc.len() {
        p.push("..");
    }
    for c in &tc[common..] {
        p.push(c);
    }
    Some(p)
}

/// One run as the page shows it.
#[derive(Clone, Debug, PartialEq)]
pub struct RunView {
    /// Task (report table).
    pub task: String,
    /// Algorithm label (as in the report's groups).
    pub algorithm: String,
    /// Seed.
    pub seed: u64,
    /// The run directory relative to the page (`None` when the page is rendered without the
    /// runs, e.g. from a committed report).
    pub dir: Option<PathBuf>,
    /// Files of `RUN_FILES` present in the directory.
    pub files: Vec<String>,
    /// Training curve: (environment steps, evaluation return).
    pub curve: Vec<(f64, f64)>,
    /// Per-call inference time (ms), when `infer` ran.
    pub inference_time_ms: Option<Summary>,
}

impl RunView {
    /// The runs of `groups`, with directories relative to `out` (the page's directory).
    pub fn of_groups(groups: &[Group], out: &Path) -> Vec<RunView> {
        let mut views = Vec::new();
        for g in groups {
            for r in &g.runs {
                let dir = &r.run.dir;
                views.push(RunView {
                    task: g.task.clone(),
                    algorithm: g.algorithm.clone(),
                    seed: r.run.record.seed,
                    dir: relative_to(dir, out).or_else(|| Some(dir.clone())),
                    files: RUN_FILES
                        .iter()
                        .filter(|f| dir.join(f).is_file())
                        .map(|f| f.to_string())
                        .collect(),
                    curve: r
                        .curve
                        .points
                        .iter()
                        .map(|p| (p.env_steps as f64, p.mean_return))
                        .collect(),
                    inference_time_ms: r.inference.as_ref().map(|i| i.inference_time_ms.clone()),
                });
            }
        }
        views
    }
}

/// The page of a report directory alone (`report.json` and `curves.csv`, as committed under
/// `docs/results/`): curves come from `curves.csv`; run links and inference-time distributions,
/// which need the run directories, are left out (and the page says so).
pub fn page_from_report_dir(dir: &Path) -> Result<String> {
    let report: Report = a2perf_core::results::read_json(&dir.join("report.json"))?;
    let runs = runs_of_report_dir(dir, &report)?;
    Ok(page(&report, &runs))
}

/// The runs of a report directory's `report.json`, with their curves from its `curves.csv`.
pub(super) fn runs_of_report_dir(dir: &Path, report: &Report) -> Result<Vec<RunView>> {
    let curves_path = dir.join("curves.csv");
    let text = std::fs::read_to_string(&curves_path).map_err(crate::io_err(&curves_path))?;
    runs_from_curves_csv(report, &text).map_err(|reason| PipelineError::Corrupt {
        path: curves_path.clone(),
        reason,
    })
}

/// One field list of a CSV line (RFC 4180 quotes, as `render::curves_csv` writes them).
fn csv_fields(line: &str) -> Vec<String> {
    let mut fields = vec![String::new()];
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match (c, quoted) {
            ('"', true) if chars.peek() == Some(&'"') => {
                chars.next();
                if let Some(f) = fields.last_mut() {
                    f.push('"');
                }
            }
            ('"', _) => quoted = !quoted,
            (',', false) => fields.push(String::new()),
            _ => {
                if let Some(f) = fields.last_mut() {
                    f.push(c);
                }
            }
        }
    }
    fields
}

/// The runs of `report` with their curves from `curves.csv` text (`run,step,value`, the run
/// named `<task>/<algorithm>/seed<k>`).
fn runs_from_curves_csv(report: &Report, text: &str) -> std::result::Result<Vec<RunView>, String> {
    let mut by_name: BTreeMap<String, usize> = BTreeMap::new();
    let mut runs = Vec::new();
    for g in &report.groups {
        for &seed in &g.seeds {
            by_name.insert(format!("{}/{}/seed{seed}", g.task, g.algorithm), runs.len());
            runs.push(RunView {
                task: g.task.clone(),
                algorithm: g.algorithm.clone(),
                seed,
                dir: None,
                files: Vec::new(),
                curve: Vec::new(),
                inference_time_ms: None,
            });
        }
    }
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, "run,step,value")) => {}
        other => {
            return Err(format!(
                "expected the header `run,step,value`, found `{}`",
                other.map_or("", |(_, l)| l)
            ));
        }
    }
    for (i, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f = csv_fields(line);
        let [run, step, value] = f.as_slice() else {
            return Err(format!(
                "line {}: expected 3 fields, found {}",
                i + 1,
                f.len()
            ));
        };
        let number = |t: &str| {
            t.parse::<f64>()
                .map_err(|e| format!("line {}: `{t}`: {e}", i + 1))
        };
        let (step, value) = (number(step)?, number(value)?);
        match by_name.get(run.as_str()) {
            Some(&k) => runs[k].curve.push((step, value)),
            None => return Err(format!("line {}: run `{run}` is not in report.json", i + 1)),
        }
    }
    Ok(runs)
}

/// How a number is printed (the checker re-formats `data-value` the same way).
#[derive(Clone, Copy)]
enum Fmt {
    /// [`format_value`].
    Value,
    /// [`format_ratio`].
    Ratio,
    /// Three decimals (probabilities).
    P3,
}

/// A number from `report.json` at JSON pointer `at`: formatted text with its exact value.
fn num(v: f64, at: &str, fmt: Fmt) -> String {
    let (text, tag) = match fmt {
        Fmt::Value => (format_value(v), "value"),
        Fmt::Ratio => (format_ratio(v), "ratio"),
        Fmt::P3 => (format!("{v:.3}"), "p3"),
    };
    format!(
        r#"<span class="num" data-value="{v}" data-ref="{}" data-fmt="{tag}">{text}</span>"#,
        escape(at)
    )
}

/// `mean ± std [lo, hi]` of a metric, as in `report.md`.
fn metric_cell(m: &MetricValue, at: &str, with_std: bool) -> String {
    let Some(mean) = m.mean else {
        return r#"<span class="missing">—</span>"#.into();
    };
    let mut s = num(mean, &format!("{at}/mean"), Fmt::Value);
    if with_std && let Some(sd) = m.std {
        let _ = write!(s, " ± {}", num(sd, &format!("{at}/std"), Fmt::Value));
    }
    if let Some([lo, hi]) = m.ci95
        && m.per_seed.len() > 1
    {
        let _ = write!(
            s,
            r#" <span class="ci">[{}, {}]</span>"#,
            num(lo, &format!("{at}/ci95/0"), Fmt::Value),
            num(hi, &format!("{at}/ci95/1"), Fmt::Value)
        );
    }
    s
}

/// Where a metric's figure comes from, for its `title`.
fn provenance(g: &GroupReport, m: &MetricValue, reps: usize) -> String {
    let seeds = g
        .seeds
        .iter()
        .map(u64::to_string)
        .collect::<Vec<_>>()
        .join(", ");
    let mut s = format!(
        "{} ({}) of {} on {}: ",
        m.label,
        m.unit,
        g.algorithm.to_uppercase(),
        g.task
    );
    if m.mean.is_none() {
        let _ = write!(s, "missing");
    } else if m.per_seed.is_empty() {
        let _ = write!(
            s,
            "computed across the curves or rollouts of {} seeds ({seeds})",
            g.seeds.len()
        );
    } else {
        let _ = write!(
            s,
            "mean ± sample std over {} seeds ({seeds}), 95% bootstrap interval of the mean \
             ({reps} resamples)",
            m.per_seed.len()
        );
    }
    if m.mean.is_some() {
        let estimated = m.note.as_deref().is_some_and(|n| n.contains("estimated"));
        s.push_str(if estimated {
            "; estimated, not measured"
        } else {
            "; measured"
        });
    }
    if let Some(n) = &m.note {
        let _ = write!(s, "; note: {n}");
    }
    let _ = write!(s, "; runs: see Runs of {}", g.task);
    s
}

/// The paper's cell of (`task`, `algorithm`, `key`) with its JSON pointer.
fn paper_cell<'a>(
    report: &'a Report,
    task: &str,
    algorithm: &str,
    key: &str,
) -> Option<(&'a PaperCell, String)> {
    let (pi, p) = report
        .paper
        .iter()
        .enumerate()
        .find(|(_, p)| p.task == task)?;
    let (ci, col) = p
        .columns
        .iter()
        .enumerate()
        .find(|(_, c)| c.algorithm == algorithm)?;
    let (ki, cell) = col.cells.iter().enumerate().find(|(_, c)| c.key == key)?;
    Some((cell, format!("/paper/{pi}/columns/{ci}/cells/{ki}")))
}

/// The verdict as a symbol and a word (readable without colour), with the gap when it trails.
fn verdict_badge(c: &PaperCell, at: &str) -> String {
    let Some(v) = c.verdict else {
        return String::new();
    };
    let (class, text, why) = match v {
        Verdict::Beats => ("beats", "▲ beats", "our mean is above the paper's mean"),
        Verdict::Within => (
            "within",
            "≈ within",
            "our mean is at or below the paper's, within its ± std",
        ),
        Verdict::Trails => (
            "trails",
            "▼ trails",
            "our mean is below the paper's mean minus its std",
        ),
    };
    let gap = match (v, c.gap) {
        (Verdict::Trails, Some(g)) => format!(" by {}", num(g, &format!("{at}/gap"), Fmt::Value)),
        _ => String::new(),
    };
    let (why, reach) = match &c.out_of_reach {
        Some(r) => (format!("{why}; {r}"), " (out of reach here)"),
        None => (why.to_string(), ""),
    };
    format!(
        r#" <span class="verdict verdict-{class}" title="{}">{text}{gap}{reach}</span>"#,
        escape(&why)
    )
}

/// The paper's `mean ± std` and verdict.
fn paper_cell_html(c: Option<&(&PaperCell, String)>) -> String {
    match c {
        Some((c, at)) if c.mean.is_some() => {
            let mut s = String::new();
            if let Some(m) = c.mean {
                s.push_str(&num(m, &format!("{at}/mean"), Fmt::Value));
            }
            if let Some(sd) = c.std {
                let _ = write!(s, " ± {}", num(sd, &format!("{at}/std"), Fmt::Value));
            }
            s.push_str(&verdict_badge(c, at));
            s
        }
        _ => r#"<span class="missing">—</span>"#.into(),
    }
}

/// Where a paper figure comes from, for its `title`.
fn paper_provenance(c: &PaperCell) -> String {
    let mut parts = vec![format!("paper, in {}", c.unit)];
    parts.extend(c.source.clone());
    parts.extend(c.published.as_ref().map(|p| format!("published {p}")));
    parts.extend(c.conversion.clone());
    parts.extend(c.note.clone());
    parts.join("; ")
}

/// The data the script reads.
#[derive(Serialize)]
struct PageData<'a> {
    facets: BTreeMap<&'static str, Vec<&'a str>>,
}

/// Renders the page of `report`, whose runs are `runs`.
pub fn page(report: &Report, runs: &[RunView]) -> String {
    let mut s = String::with_capacity(64 * 1024);
    let tasks = task_names(report);
    s.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n");
    s.push_str(
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; \
         style-src 'unsafe-inline'; script-src 'unsafe-inline'; img-src data:\">\n",
    );
    s.push_str("<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n");
    s.push_str("<title>A2Perf report</title>\n<style>\n");
    s.push_str(STYLE);
    s.push_str("</style>\n</head>\n<body>\n<header>\n<h1>A2Perf report</h1>\n");
    let _ = writeln!(
        s,
        "<p class=\"summary\">{} (task, algorithm) groups on {} tasks from {} runs; runs left \
         out: {}. Values are mean ± std over seeds (sample std) with a 95% percentile-bootstrap \
         interval of the mean ({} resamples) in brackets; ↑ higher is better, ↓ lower is better; \
         — missing (hover for the reason). Hover any number to see where it came from.</p>",
        report.groups.len(),
        tasks.len(),
        runs.len(),
        report.skipped_runs.len(),
        report.bootstrap_reps
    );
    s.push_str("<nav aria-label=\"Sections\"><ul>\n<li><a href=\"#leaderboard-section\">Leaderboard</a></li>\n");
    if !report.findings.is_empty() {
        s.push_str("<li><a href=\"#findings\">Paper findings</a></li>\n");
    }
    for (ti, task) in tasks.iter().enumerate() {
        let _ = writeln!(s, "<li><a href=\"#task-{ti}\">{}</a></li>", escape(task));
    }
    s.push_str("<li><a href=\"#statistics\">IQM and P(X&gt;Y)</a></li>\n");
    if !report.skipped_runs.is_empty() {
        s.push_str("<li><a href=\"#skipped\">Runs left out</a></li>\n");
    }
    s.push_str("</ul></nav>\n</header>\n<main>\n");
    leaderboard(&mut s, report);
    if !report.findings.is_empty() {
        findings(&mut s, &report.findings);
    }
    for (ti, task) in tasks.iter().enumerate() {
        task_section(&mut s, report, runs, ti, task);
    }
    statistics(&mut s, report);
    skipped(&mut s, report);
    s.push_str("</main>\n");
    let facet = |f: fn(&GroupReport) -> &str| {
        let mut v: Vec<&str> = report.groups.iter().map(f).collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    let data = PageData {
        facets: BTreeMap::from([
            ("domain", facet(|g| g.domain.as_str())),
            ("task", facet(|g| g.task.as_str())),
            ("algorithm", facet(|g| g.algorithm.as_str())),
        ]),
    };
    let _ = writeln!(
        s,
        "<script type=\"application/json\" id=\"report-data\">{}</script>",
        json_for_script(&data)
    );
    s.push_str("<script>\n");
    s.push_str(SCRIPT);
    s.push_str("</script>\n</body>\n</html>\n");
    s
}

fn task_names(report: &Report) -> Vec<&str> {
    let set: std::collections::BTreeSet<&str> =
        report.groups.iter().map(|g| g.task.as_str()).collect();
    set.into_iter().collect()
}

fn leaderboard(s: &mut String, report: &Report) {
    let with_paper = !report.paper.is_empty();
    s.push_str("<section id=\"leaderboard-section\">\n<h2>Leaderboard</h2>\n");
    s.push_str(
        "<form class=\"controls\" aria-label=\"Filter the leaderboard\">\n\
         <label>Domain <select id=\"filter-domain\" data-facet=\"domain\"><option value=\"\">all</option></select></label>\n\
         <label>Task <select id=\"filter-task\" data-facet=\"task\"><option value=\"\">all</option></select></label>\n\
         <label>Algorithm <select id=\"filter-algorithm\" data-facet=\"algorithm\"><option value=\"\">all</option></select></label>\n\
         </form>\n",
    );
    if with_paper {
        s.push_str(
            "<p>Under our value: the paper's, with a verdict for returns and generalization \
             (▲ beats: above the paper's mean; ≈ within: at or below it, within its ± std; \
             ▼ trails: below its mean minus its std).</p>\n",
        );
    }
    s.push_str("<div class=\"scroll\"><table id=\"leaderboard\">\n<caption>One row per (task, algorithm); click a column header to sort.</caption>\n<thead><tr>");
    let header = |s: &mut String, label: &str, kind: &str| {
        let _ = write!(
            s,
            "<th scope=\"col\" aria-sort=\"none\" data-type=\"{kind}\"><button type=\"button\">{label}</button></th>"
        );
    };
    header(s, "Domain", "text");
    header(s, "Task", "text");
    header(s, "Algorithm", "text");
    header(s, "Seeds", "number");
    for (key, title) in LEADERBOARD_METRICS {
        let unit = report
            .groups
            .iter()
            .find_map(|g| g.metric(key))
            .map(|m| {
                let arrow = if m.higher_is_better { "↑" } else { "↓" };
                format!(" <span class=\"unit\">({}) {arrow}</span>", escape(&m.unit))
            })
            .unwrap_or_default();
        header(s, &format!("{}{unit}", escape(title)), "number");
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    let tasks = task_names(report);
    for (gi, g) in report.groups.iter().enumerate() {
        let ti = tasks.iter().position(|t| *t == g.task).unwrap_or(0);
        let _ = write!(
            s,
            "<tr data-domain=\"{}\" data-task=\"{}\" data-algorithm=\"{}\">",
            escape(&g.domain),
            escape(&g.task),
            escape(&g.algorithm)
        );
        let _ = write!(
            s,
            "<td data-sort=\"{0}\">{0}</td><th scope=\"row\" data-sort=\"{1}\"><a href=\"#task-{ti}\">{1}</a></th><td data-sort=\"{2}\">{3}{5}</td><td data-sort=\"{4}\">{4}</td>",
            escape(&g.domain),
            escape(&g.task),
            escape(&g.algorithm),
            escape(&g.algorithm.to_uppercase()),
            g.seeds.len(),
            verified_badge(g)
        );
        for (key, _) in LEADERBOARD_METRICS {
            let Some((mi, m)) = g.metrics.iter().enumerate().find(|(_, m)| m.key == *key) else {
                s.push_str("<td data-sort=\"\"><span class=\"missing\">—</span></td>");
                continue;
            };
            let at = format!("/groups/{gi}/metrics/{mi}");
            let sort = m.mean.map(|v| v.to_string()).unwrap_or_default();
            let _ = write!(
                s,
                "<td data-sort=\"{sort}\" title=\"{}\">{}",
                escape(&provenance(g, m, report.bootstrap_reps)),
                metric_cell(m, &at, false)
            );
            if with_paper && let Some(pc) = paper_cell(report, &g.task, &g.algorithm, key) {
                let _ = write!(
                    s,
                    "<div class=\"paper\" title=\"{}\">paper {}</div>",
                    escape(&paper_provenance(pc.0)),
                    paper_cell_html(Some(&pc))
                );
            }
            s.push_str("</td>");
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table></div>\n</section>\n");
}

fn findings(s: &mut String, findings: &[FindingCheck]) {
    s.push_str("<section id=\"findings\">\n<h2>The paper's findings, checked on these runs</h2>\n");
    s.push_str("<div class=\"scroll\"><table>\n<thead><tr><th scope=\"col\">Finding</th><th scope=\"col\">Claim</th><th scope=\"col\">Paper</th><th scope=\"col\">Ours</th><th scope=\"col\">Holds here</th><th scope=\"col\">Note</th></tr></thead>\n<tbody>\n");
    for f in findings {
        let (class, text) = match f.holds {
            Some(true) => ("holds", "✓ holds"),
            Some(false) => ("fails", "✗ does not hold"),
            None => ("unchecked", "? not checked"),
        };
        let _ = writeln!(
            s,
            "<tr><th scope=\"row\">{}</th><td>{}</td><td>{}</td><td>{}</td><td><span class=\"finding finding-{class}\">{text}</span></td><td>{}</td></tr>",
            escape(&f.id),
            escape(&f.claim),
            escape(&f.paper),
            escape(&f.ours),
            escape(f.note.as_deref().unwrap_or(""))
        );
    }
    s.push_str("</tbody>\n</table></div>\n</section>\n");
}

fn task_section(s: &mut String, report: &Report, runs: &[RunView], ti: usize, task: &str) {
    let groups: Vec<(usize, &GroupReport)> = report
        .groups
        .iter()
        .enumerate()
        .filter(|(_, g)| g.task == task)
        .collect();
    let Some((_, first)) = groups.first() else {
        return;
    };
    let paper = report.paper_of(task);
    let _ = writeln!(
        s,
        "<section class=\"task\" id=\"task-{ti}\">\n<h2>{} <span class=\"sub\">{}, {}</span></h2>",
        escape(task),
        escape(&first.env_id),
        escape(&first.domain)
    );
    if let Some(t) = report.settings_of(task) {
        for line in super::render::settings_lines(t) {
            let _ = writeln!(s, "<p>{}</p>", escape(&line.replace("**", "")));
        }
    }
    if let Some(p) = paper {
        let _ = writeln!(
            s,
            "<p>Paper columns: {}, in our units (conversions on hover).</p>",
            escape(&super::render::paper_heading(p))
        );
    }
    // The full metric table.
    let _ = write!(
        s,
        "<div class=\"scroll\"><table class=\"metrics\">\n<caption>All metrics of {}</caption>\n<thead><tr><th scope=\"col\">Category</th><th scope=\"col\">Metric</th>",
        escape(task)
    );
    for (_, g) in &groups {
        let _ = write!(
            s,
            "<th scope=\"col\">{}{} <span class=\"sub\">({} seeds)</span></th>",
            escape(&g.algorithm.to_uppercase()),
            verified_badge(g),
            g.seeds.len()
        );
        if paper.is_some() {
            let _ = write!(
                s,
                "<th scope=\"col\">{} <span class=\"sub\">(paper)</span></th>",
                escape(&g.algorithm.to_uppercase())
            );
        }
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    let mut last: Option<Category> = None;
    for m in &first.metrics {
        let arrow = if m.higher_is_better { "↑" } else { "↓" };
        let cat = if last == Some(m.category) {
            String::new()
        } else {
            m.category.label().to_string()
        };
        last = Some(m.category);
        let _ = write!(
            s,
            "<tr><td>{}</td><th scope=\"row\">{} <span class=\"unit\">({}) {arrow}</span></th>",
            escape(&cat),
            escape(&m.label),
            escape(&m.unit)
        );
        for (gi, g) in &groups {
            // Groups of one table share the metric order; look up by key all the same.
            match g.metrics.iter().enumerate().find(|(_, x)| x.key == m.key) {
                Some((k, gm)) => {
                    let at = format!("/groups/{gi}/metrics/{k}");
                    let _ = write!(
                        s,
                        "<td title=\"{}\">{}</td>",
                        escape(&provenance(g, gm, report.bootstrap_reps)),
                        metric_cell(gm, &at, true)
                    );
                }
                None => s.push_str("<td><span class=\"missing\">—</span></td>"),
            }
            if paper.is_some() {
                let pc = paper_cell(report, task, &g.algorithm, &m.key);
                let title = pc
                    .as_ref()
                    .map(|(c, _)| paper_provenance(c))
                    .unwrap_or_else(|| "the paper gives no value".into());
                let _ = write!(
                    s,
                    "<td class=\"paper\" title=\"{}\">{}</td>",
                    escape(&title),
                    paper_cell_html(pc.as_ref())
                );
            }
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table></div>\n");
    if paper.is_some() {
        ratio_table(s, report, &groups, first);
    }
    notes(s, &groups);
    // Plots.
    s.push_str("<div class=\"plots\">\n<figure class=\"radar\">\n");
    let in_task: Vec<&GroupReport> = groups.iter().map(|(_, g)| *g).collect();
    s.push_str(&super::svg::radar(task, &in_task));
    s.push_str("</figure>\n");
    curves(s, runs, &in_task, ti);
    s.push_str("</div>\n");
    inference_times(s, runs, &in_task, ti);
    runs_table(s, runs, &in_task);
    s.push_str("</section>\n");
}

fn ratio_table(
    s: &mut String,
    report: &Report,
    groups: &[(usize, &GroupReport)],
    first: &GroupReport,
) {
    s.push_str("<div class=\"scroll\"><table class=\"ratios\">\n<caption>Ours / paper (energy, RAM, wall-clock; 1 = the same, below 1 = less)</caption>\n<thead><tr><th scope=\"col\">Category</th><th scope=\"col\">Metric</th>");
    for (_, g) in groups {
        let _ = write!(
            s,
            "<th scope=\"col\">{}</th>",
            escape(&g.algorithm.to_uppercase())
        );
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for m in first
        .metrics
        .iter()
        .filter(|m| super::model::RATIO_METRICS.contains(&m.key.as_str()))
    {
        let _ = write!(
            s,
            "<tr><td>{}</td><th scope=\"row\">{} <span class=\"unit\">({})</span></th>",
            escape(m.category.label()),
            escape(&m.label),
            escape(&m.unit)
        );
        for (_, g) in groups {
            match paper_cell(report, &g.task, &g.algorithm, &m.key) {
                Some((c, at)) if c.ratio.is_some() => {
                    let r = c.ratio.unwrap_or(f64::NAN);
                    let _ = write!(
                        s,
                        "<td title=\"{}\">{}</td>",
                        escape(&format!(
                            "our mean / the paper's, both in {}; {}",
                            c.unit,
                            paper_provenance(c)
                        )),
                        num(r, &format!("{at}/ratio"), Fmt::Ratio)
                    );
                }
                _ => s.push_str("<td><span class=\"missing\">—</span></td>"),
            }
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</tbody>\n</table></div>\n");
}

fn notes(s: &mut String, groups: &[(usize, &GroupReport)]) {
    let mut items = Vec::new();
    for (_, g) in groups {
        for m in &g.metrics {
            if let Some(n) = &m.note {
                items.push(format!(
                    "<li>{} / {}: {}</li>",
                    escape(&g.algorithm.to_uppercase()),
                    escape(&m.label),
                    escape(n)
                ));
            }
        }
    }
    if !items.is_empty() {
        let _ = writeln!(
            s,
            "<details class=\"notes\"><summary>Notes ({})</summary>\n<ul>\n{}\n</ul></details>",
            items.len(),
            items.join("\n")
        );
    }
}

/// Per evaluation step over the seeds: (step, mean, lower, upper) of a 95% t-interval of the
/// mean (the band collapses to the mean with one seed).
fn mean_band(curves: &[&[(f64, f64)]]) -> Vec<(f64, f64, f64, f64)> {
    let mut at: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    for c in curves {
        for &(x, y) in *c {
            if x.is_finite() && y.is_finite() {
                at.entry(x.to_bits()).or_default().push(y);
            }
        }
    }
    let mut pts: Vec<(f64, f64, f64, f64)> = at
        .into_iter()
        .map(|(bits, v)| {
            let n = v.len() as f64;
            let mean = numeric::mean_sequential(&v);
            let half = if v.len() > 1 {
                let var = numeric::var_sequential(&v, 1);
                numeric::student_t975(v.len() - 1) * (var / n).sqrt()
            } else {
                0.0
            };
            (f64::from_bits(bits), mean, mean - half, mean + half)
        })
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    downsample(pts, CURVE_POINTS)
}

/// At most `n` evenly spaced points, the first and last kept.
fn downsample<T: Copy>(pts: Vec<T>, n: usize) -> Vec<T> {
    if pts.len() <= n || n < 2 {
        return pts;
    }
    let last = pts.len() - 1;
    (0..n).map(|i| pts[i * last / (n - 1)]).collect()
}

fn curves(s: &mut String, runs: &[RunView], groups: &[&GroupReport], ti: usize) {
    let (w, h) = (640.0, 380.0);
    let (l, r, t, b) = (64.0, 32.0, 16.0, 44.0);
    let (pw, ph) = (w - l - r, h - t - b);
    let series: Vec<Vec<(f64, f64, f64, f64)>> = groups
        .iter()
        .map(|g| {
            let cs: Vec<&[(f64, f64)]> = runs
                .iter()
                .filter(|r| r.task == g.task && r.algorithm == g.algorithm)
                .map(|r| r.curve.as_slice())
                .collect();
            mean_band(&cs)
        })
        .collect();
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for &(x, _, lo, hi) in series.iter().flatten() {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(lo);
        y1 = y1.max(hi);
    }
    s.push_str("<figure class=\"curves\">\n");
    let _ = write!(
        s,
        "<fieldset class=\"series-toggle\" data-plot=\"curves-{ti}\"><legend>Show</legend>"
    );
    for (i, g) in groups.iter().enumerate() {
        let _ = write!(
            s,
            "<label><input type=\"checkbox\" checked data-series=\"{i}\"> <svg class=\"key\" width=\"28\" height=\"10\" aria-hidden=\"true\"><line x1=\"0\" y1=\"5\" x2=\"28\" y2=\"5\" stroke=\"{}\" stroke-width=\"2.5\" stroke-dasharray=\"{}\"/></svg> {}</label> ",
            PALETTE[i % PALETTE.len()],
            DASHES[i % DASHES.len()],
            escape(&g.algorithm.to_uppercase())
        );
    }
    s.push_str("</fieldset>\n");
    let _ = writeln!(
        s,
        "<svg id=\"curves-{ti}\" class=\"plot\" viewBox=\"0 0 {w} {h}\" width=\"{w}\" height=\"{h}\" role=\"img\" aria-label=\"Training curves\">"
    );
    if !x0.is_finite() || !y0.is_finite() {
        let _ = writeln!(
            s,
            "<text x=\"{}\" y=\"{}\" text-anchor=\"middle\">No curve points.</text></svg>",
            w / 2.0,
            h / 2.0
        );
    } else {
        let ((x0, x1), (y0, y1)) = plot_ranges((x0, x1), (y0, y1));
        let px = |x: f64| l + (x - x0) / (x1 - x0) * pw;
        let py = |y: f64| t + ph - (y - y0) / (y1 - y0) * ph;
        frame(s, (l, t, pw, ph), (x0, x1), (y0, y1), &px, &py);
        let _ = writeln!(
            s,
            "<text x=\"{:.0}\" y=\"{:.0}\" text-anchor=\"middle\">environment steps</text><text transform=\"translate(14,{:.0}) rotate(-90)\" text-anchor=\"middle\">evaluation return</text>",
            l + pw / 2.0,
            h - 8.0,
            t + ph / 2.0
        );
        for (i, (pts, g)) in series.iter().zip(groups).enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let upper = pts.iter().map(|p| format!("{:.1},{:.1}", px(p.0), py(p.3)));
            let lower = pts
                .iter()
                .rev()
                .map(|p| format!("{:.1},{:.1}", px(p.0), py(p.2)));
            let band: Vec<String> = upper.chain(lower).collect();
            let line: Vec<String> = pts
                .iter()
                .map(|p| format!("{:.1},{:.1}", px(p.0), py(p.1)))
                .collect();
            let _ = writeln!(
                s,
                "<g class=\"series\" data-series=\"{i}\"><title>{}: mean evaluation return over seeds, 95% t-interval of the mean shaded</title><polygon points=\"{}\" fill=\"{color}\" fill-opacity=\"0.18\" stroke=\"none\"/><polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"2\" stroke-dasharray=\"{}\"/></g>",
                escape(&g.algorithm.to_uppercase()),
                band.join(" "),
                line.join(" "),
                DASHES[i % DASHES.len()]
            );
        }
        s.push_str("</svg>\n");
    }
    s.push_str("<figcaption>Evaluation return during training: mean over seeds with the 95% t-interval of the mean shaded (drawn with at most 160 points per algorithm; the tables use every point). Line styles tell the algorithms apart without colour.</figcaption>\n</figure>\n");
}

/// Dash patterns, one per series, so that curves differ without colour.
const DASHES: [&str; 4] = ["none", "6 3", "2 3", "8 3 2 3"];

fn inference_times(s: &mut String, runs: &[RunView], groups: &[&GroupReport], ti: usize) {
    let rows: Vec<(usize, &RunView, &Summary)> = groups
        .iter()
        .enumerate()
        .flat_map(|(i, g)| {
            runs.iter()
                .filter(move |r| r.task == g.task && r.algorithm == g.algorithm)
                .filter_map(move |r| r.inference_time_ms.as_ref().map(|t| (i, r, t)))
        })
        .filter(|(_, _, t)| t.count > 0 && t.min.is_finite() && t.max.is_finite())
        .collect();
    s.push_str("<figure class=\"inference\">\n");
    if rows.is_empty() {
        let without_runs = runs.iter().all(|r| r.dir.is_none());
        s.push_str(if without_runs {
            "<p>Inference-time distributions need the run directories (this page was rendered \
             from a report directory alone).</p>\n</figure>\n"
        } else {
            "<p>No inference times: run <code>a2perf infer</code> first.</p>\n</figure>\n"
        });
        return;
    }
    let lo = rows.iter().map(|r| r.2.min).fold(f64::INFINITY, f64::min);
    let hi = rows
        .iter()
        .map(|r| r.2.max)
        .fold(f64::NEG_INFINITY, f64::max);
    // A long tail (max far above the median) squeezes the boxes on a linear axis.
    let log = lo > 0.0 && hi / lo > 20.0;
    let tx = |v: f64| if log { v.log10() } else { v };
    let (a, mut bnd) = (tx(lo), tx(hi));
    if bnd <= a {
        bnd = a + 1.0;
    }
    let (l, r, t, row) = (120.0, 20.0, 10.0, 16.0);
    let w = 640.0;
    let h = t + row * rows.len() as f64 + 40.0;
    let pw = w - l - r;
    let px = |v: f64| l + (tx(v) - a) / (bnd - a) * pw;
    let _ = writeln!(
        s,
        "<svg id=\"inference-{ti}\" class=\"plot\" viewBox=\"0 0 {w} {h:.0}\" width=\"{w}\" height=\"{h:.0}\" role=\"img\" aria-label=\"Inference time per call\">"
    );
    let axis_y = t + row * rows.len() as f64 + 4.0;
    let _ = writeln!(
        s,
        "<line x1=\"{l}\" y1=\"{axis_y:.1}\" x2=\"{:.1}\" y2=\"{axis_y:.1}\" stroke=\"#444\"/>",
        l + pw
    );
    let ticks: Vec<f64> = if log {
        let (e0, e1) = (a.floor() as i32, bnd.ceil() as i32);
        // 1, 2, 5 per decade: a narrow range still gets a few labels.
        (e0..=e1)
            .flat_map(|e| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(e)))
            .filter(|v| tx(*v) >= a - 1e-9 && tx(*v) <= bnd + 1e-9)
            .collect()
    } else {
        nice_ticks(lo, hi)
    };
    for v in ticks {
        let x = px(v);
        let _ = writeln!(
            s,
            "<line x1=\"{x:.1}\" y1=\"{t}\" x2=\"{x:.1}\" y2=\"{:.1}\" stroke=\"#e4e4e4\"/><text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>",
            axis_y + 4.0,
            axis_y + 16.0,
            tick_label(v)
        );
    }
    let _ = writeln!(
        s,
        "<text x=\"{:.0}\" y=\"{:.0}\" text-anchor=\"middle\">ms per call{}</text>",
        l + pw / 2.0,
        h - 4.0,
        if log { " (log scale)" } else { "" }
    );
    for (k, (i, run, sm)) in rows.iter().enumerate() {
        let y = t + row * k as f64 + row / 2.0;
        let color = PALETTE[i % PALETTE.len()];
        let label = format!("{} seed {}", run.algorithm.to_uppercase(), run.seed);
        let title = format!(
            "{label}: {} calls; min {}, median {}, mean {}, p90 {}, p99 {}, max {} ms (from the run's {INFERENCE_FILE})",
            sm.count,
            format_value(sm.min),
            format_value(sm.median),
            format_value(sm.mean),
            format_value(sm.p90),
            format_value(sm.p99),
            format_value(sm.max)
        );
        let _ = writeln!(
            s,
            "<g><title>{}</title><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{}</text><line x1=\"{:.1}\" y1=\"{y:.1}\" x2=\"{:.1}\" y2=\"{y:.1}\" stroke=\"{color}\"/><rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"8\" fill=\"{color}\" fill-opacity=\"0.35\" stroke=\"{color}\"/><circle cx=\"{:.1}\" cy=\"{y:.1}\" r=\"2.5\" fill=\"#000\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" font-size=\"9\">×</text></g>",
            escape(&title),
            l - 6.0,
            y + 4.0,
            escape(&label),
            px(sm.min),
            px(sm.p99),
            px(sm.median),
            y - 4.0,
            (px(sm.p90) - px(sm.median)).max(1.0),
            px(sm.mean),
            px(sm.max),
            y + 3.0
        );
    }
    s.push_str("</svg>\n<figcaption>Inference time per call, per seed: line from the fastest call to the 99th percentile, box from the median to the 90th percentile, ● mean, × slowest call (hover a row for its figures).</figcaption>\n</figure>\n");
}

fn runs_table(s: &mut String, runs: &[RunView], groups: &[&GroupReport]) {
    s.push_str("<details class=\"runs\"><summary>Runs</summary>\n<div class=\"scroll\"><table>\n<thead><tr><th scope=\"col\">Algorithm</th><th scope=\"col\">Seed</th><th scope=\"col\">Directory</th><th scope=\"col\">Files</th></tr></thead>\n<tbody>\n");
    for g in groups {
        for r in runs
            .iter()
            .filter(|r| r.task == g.task && r.algorithm == g.algorithm)
        {
            let (dir, files) = match &r.dir {
                Some(d) => {
                    let link = format!(
                        "<a href=\"{}\">{}</a>",
                        escape(&href(d)),
                        escape(&d.display().to_string())
                    );
                    let files: Vec<String> = r
                        .files
                        .iter()
                        .map(|f| {
                            format!(
                                "<a href=\"{}\">{}</a>",
                                escape(&href(&d.join(f))),
                                escape(f)
                            )
                        })
                        .collect();
                    (link, files.join(" "))
                }
                None => ("(not included)".into(), String::new()),
            };
            let _ = writeln!(
                s,
                "<tr><td>{}</td><td>{}</td><td>{dir}</td><td>{files}</td></tr>",
                escape(&r.algorithm.to_uppercase()),
                r.seed
            );
        }
    }
    s.push_str("</tbody>\n</table></div></details>\n");
}

fn statistics(s: &mut String, report: &Report) {
    s.push_str("<section id=\"statistics\">\n<h2>Interquartile mean of returns and probability of improvement</h2>\n");
    if report.iqm.is_empty() {
        s.push_str("<p>No returns: run <code>a2perf infer</code> first.</p>\n");
    } else {
        s.push_str("<div class=\"scroll\"><table>\n<caption>IQM of the per-seed mean returns, with its 95% bootstrap interval</caption>\n<thead><tr><th scope=\"col\">Task</th><th scope=\"col\">Algorithm</th><th scope=\"col\">Runs</th><th scope=\"col\">IQM</th><th scope=\"col\">95% CI</th></tr></thead>\n<tbody>\n");
        for (i, e) in report.iqm.iter().enumerate() {
            let _ = writeln!(
                s,
                "<tr><th scope=\"row\">{}</th><td>{}</td><td>{}</td><td>{}</td><td>[{}, {}]</td></tr>",
                escape(&e.task),
                escape(&e.algorithm.to_uppercase()),
                e.runs,
                num(e.iqm, &format!("/iqm/{i}/iqm"), Fmt::Value),
                num(e.ci95[0], &format!("/iqm/{i}/ci95/0"), Fmt::Value),
                num(e.ci95[1], &format!("/iqm/{i}/ci95/1"), Fmt::Value)
            );
        }
        s.push_str("</tbody>\n</table></div>\n");
    }
    if !report.probability_of_improvement.is_empty() {
        s.push_str("<div class=\"scroll\"><table>\n<caption>P(X &gt; Y): the probability that a run of X beats a run of Y on returns, averaged over the tasks both ran</caption>\n<thead><tr><th scope=\"col\">X</th><th scope=\"col\">Y</th><th scope=\"col\">Tasks</th><th scope=\"col\">P(X &gt; Y)</th><th scope=\"col\">95% CI</th></tr></thead>\n<tbody>\n");
        for (i, e) in report.probability_of_improvement.iter().enumerate() {
            let at = format!("/probability_of_improvement/{i}");
            let _ = writeln!(
                s,
                "<tr><th scope=\"row\">{}</th><td>{}</td><td title=\"{}\">{}</td><td>{}</td><td>[{}, {}]</td></tr>",
                escape(&e.x.to_uppercase()),
                escape(&e.y.to_uppercase()),
                escape(&e.tasks.join(", ")),
                e.tasks.len(),
                num(e.probability, &format!("{at}/probability"), Fmt::P3),
                num(e.ci95[0], &format!("{at}/ci95/0"), Fmt::P3),
                num(e.ci95[1], &format!("{at}/ci95/1"), Fmt::P3)
            );
        }
        s.push_str("</tbody>\n</table></div>\n");
    }
    s.push_str("</section>\n");
}

fn skipped(s: &mut String, report: &Report) {
    if report.skipped_runs.is_empty() {
        return;
    }
    s.push_str("<section id=\"skipped\">\n<h2>Runs left out</h2>\n<div class=\"scroll\"><table>\n<thead><tr><th scope=\"col\">Directory</th><th scope=\"col\">Why</th></tr></thead>\n<tbody>\n");
    for (dir, why) in &report.skipped_runs {
        let _ = writeln!(
            s,
            "<tr><td>{}</td><td>{}</td></tr>",
            escape(dir),
            escape(why)
        );
    }
    s.push_str("</tbody>\n</table></div>\n</section>\n");
}

/// The mark of a group whose runs all came from verified bundles (nothing otherwise, so pages
/// made without bundles are unchanged).
fn verified_badge(g: &GroupReport) -> &'static str {
    if g.verified {
        " <span class=\"verified\" title=\"every run of this column came from a bundle that \
         verified: its episodes replayed to the stated returns\">&#10003; verified</span>"
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_lines_split_on_unquoted_commas() {
        assert_eq!(csv_fields("a,\"b,\"\"c\"\"\",3"), ["a", "b,\"c\"", "3"]);
        assert_eq!(csv_fields(""), [""]);
    }

    #[test]
    fn hrefs_encode_every_component() {
        assert_eq!(
            href(Path::new("../a b/x#y?/run.json")),
            "../a%20b/x%23y%3F/run.json"
        );
        assert_eq!(href(Path::new("")), ".");
        assert_eq!(href(Path::new("/tmp/x")), "file:///tmp/x");
    }

    #[test]
    fn relative_paths_climb_to_the_common_ancestor() {
        let tmp = tempfile::tempdir().unwrap();
        let run = tmp.path().join("results/exp/run0");
        let out = tmp.path().join("report");
        std::fs::create_dir_all(&run).unwrap();
        std::fs::create_dir_all(&out).unwrap();
        assert_eq!(
            relative_to(&run, &out).unwrap(),
            Path::new("../results/exp/run0")
        );
        assert!(relative_to(&tmp.path().join("missing"), &out).is_none());
    }

    #[test]
    fn bands_are_t_intervals_and_downsampling_keeps_the_ends() {
        let a = [(0.0, 1.0), (10.0, 2.0)];
        let b = [(0.0, 3.0), (10.0, 2.0)];
        let band = mean_band(&[&a, &b]);
        assert_eq!(band.len(), 2);
        let (x, m, lo, hi) = band[0];
        assert_eq!((x, m), (0.0, 2.0));
        // sd = sqrt(2), se = 1, t(1) = 12.706.
        assert!((hi - 2.0 - 12.706).abs() < 1e-9 && (2.0 - lo - 12.706).abs() < 1e-9);
        assert_eq!(band[1].2, band[1].3);
        let pts: Vec<usize> = (0..1000).collect();
        let d = downsample(pts, 160);
        assert_eq!((d.len(), d[0], d[159]), (160, 0, 999));
    }
}
