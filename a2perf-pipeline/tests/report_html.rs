//! The report page (`index.html`) against `report.json`: every number on the page is the number
//! in the file and every figure of the file is on the page; names from results files are shown
//! as text, never as markup, on the page and in `report.md`.

mod html_fixture;

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use a2perf_pipeline::report::html::{self, RunView};
use a2perf_pipeline::report::paper::{FindingCheck, PaperTables};
use a2perf_pipeline::report::render::{format_ratio, format_value};
use a2perf_pipeline::report::{self, Report, ReportOptions};
use html_fixture::{
    SynthRun, SynthTask, count_verdicts, paper_tables, tasks, write_failed_run, write_tree,
};
use serde_json::Value as Json;

/// A number on the page: its JSON pointer, exact value, format and displayed text.
#[derive(Debug)]
struct PageNumber {
    at: String,
    value: String,
    fmt: String,
    text: String,
}

fn attr(tag: &str, name: &str) -> String {
    let key = format!("{name}=\"");
    let start = tag
        .find(&key)
        .unwrap_or_else(|| panic!("no {name} in {tag}"))
        + key.len();
    let end = start + tag[start..].find('"').expect("closing quote");
    tag[start..end].to_string()
}

/// Every `<span class="num" …>` of the page.
fn page_numbers(page: &str) -> Vec<PageNumber> {
    let open = "<span class=\"num\"";
    let mut out = Vec::new();
    let mut rest = page;
    while let Some(i) = rest.find(open) {
        let tag_end = i + rest[i..].find('>').expect("end of tag");
        let tag = &rest[i..tag_end];
        let text_end = tag_end + rest[tag_end..].find("</span>").expect("</span>");
        out.push(PageNumber {
            at: attr(tag, "data-ref"),
            value: attr(tag, "data-value"),
            fmt: attr(tag, "data-fmt"),
            text: rest[tag_end + 1..text_end].to_string(),
        });
        rest = &rest[text_end..];
    }
    out
}

/// Checks both ways that the page's numbers are `report.json`'s; returns how many it checked.
fn check_numbers(page: &str, json: &Json) -> usize {
    let numbers = page_numbers(page);
    assert!(!numbers.is_empty(), "no numbers on the page");
    for n in &numbers {
        let in_file = json
            .pointer(&n.at)
            .and_then(Json::as_f64)
            .unwrap_or_else(|| panic!("{} is not a number in report.json", n.at));
        let on_page: f64 = n.value.parse().expect("data-value parses");
        assert_eq!(
            on_page.to_bits(),
            in_file.to_bits(),
            "{}: page {} vs file {in_file}",
            n.at,
            n.value
        );
        let expected = match n.fmt.as_str() {
            "value" => format_value(in_file),
            "ratio" => format_ratio(in_file),
            "p3" => format!("{in_file:.3}"),
            other => panic!("unknown format {other}"),
        };
        assert_eq!(n.text, expected, "{}: displayed text", n.at);
    }
    // The other way: every figure of the file is on the page.
    let shown: BTreeSet<&str> = numbers.iter().map(|n| n.at.as_str()).collect();
    let mut wanted = Vec::new();
    let arr = |v: &Json, k: &str| v[k].as_array().cloned().unwrap_or_default();
    for (gi, g) in arr(json, "groups").iter().enumerate() {
        for (mi, m) in arr(g, "metrics").iter().enumerate() {
            let at = format!("/groups/{gi}/metrics/{mi}");
            if m["mean"].is_number() {
                wanted.push(format!("{at}/mean"));
                if m["std"].is_number() {
                    wanted.push(format!("{at}/std"));
                }
                if m["ci95"].is_array() && arr(m, "per_seed").len() > 1 {
                    wanted.push(format!("{at}/ci95/0"));
                    wanted.push(format!("{at}/ci95/1"));
                }
            }
        }
    }
    for (pi, p) in arr(json, "paper").iter().enumerate() {
        for (ci, c) in arr(p, "columns").iter().enumerate() {
            for (ki, cell) in arr(c, "cells").iter().enumerate() {
                let at = format!("/paper/{pi}/columns/{ci}/cells/{ki}");
                for field in ["mean", "std", "ratio"] {
                    if cell[field].is_number() && (field != "std" || cell["mean"].is_number()) {
                        wanted.push(format!("{at}/{field}"));
                    }
                }
                if cell["gap"].is_number() && cell["verdict"] == "trails" {
                    wanted.push(format!("{at}/gap"));
                }
            }
        }
    }
    for (i, _) in arr(json, "iqm").iter().enumerate() {
        for f in ["iqm", "ci95/0", "ci95/1"] {
            wanted.push(format!("/iqm/{i}/{f}"));
        }
    }
    for (i, _) in arr(json, "probability_of_improvement").iter().enumerate() {
        for f in ["probability", "ci95/0", "ci95/1"] {
            wanted.push(format!("/probability_of_improvement/{i}/{f}"));
        }
    }
    let missing: Vec<&String> = wanted
        .iter()
        .filter(|w| !shown.contains(w.as_str()))
        .collect();
    assert!(
        missing.is_empty(),
        "figures of report.json not on the page: {missing:?}"
    );
    numbers.len()
}

/// `report` (whose paper comparison gave verdicts) with a finding whose claim holds markup.
fn with_verdicts(mut report: Report) -> Report {
    assert!(count_verdicts(&report) > 0);
    report.findings.push(FindingCheck {
        id: "F1".into(),
        claim: "PPO <b>beats</b> DDQN on returns".into(),
        paper: "30 vs 50".into(),
        ours: "see table".into(),
        holds: Some(false),
        note: None,
        paper_holds: Some(true),
    });
    report
}

/// Writes a tree of `tasks` × `algorithms` × 3 seeds and the paper's tables for them.
fn tree(root: &Path, tasks: &[SynthTask], algorithms: &[&str]) -> PaperTables {
    write_tree(&root.join("results"), tasks, algorithms, 3, 30);
    let text = paper_tables(&tasks[0].env_id, algorithms);
    PaperTables::from_json(&text, Path::new("tables.json")).unwrap()
}

fn opts() -> ReportOptions {
    ReportOptions {
        bootstrap_reps: 200,
        seed: 0,
    }
}

#[test]
fn every_number_on_the_page_is_the_number_in_report_json() {
    let tmp = tempfile::tempdir().unwrap();
    let algorithms = ["ppo", "ddqn", "sac"];
    let tables = tree(tmp.path(), &tasks(2), &algorithms);
    let dirs = vec![tmp.path().join("results")];
    let out = tmp.path().join("report");

    // As `a2perf report --paper` writes them.
    report::write_report_with_paper(&dirs, &out, &opts(), Some(&tables)).unwrap();
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    let json: Json =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let checked = check_numbers(&page, &json);
    assert!(checked > 100, "only {checked} numbers on the page");

    // With verdicts and findings filled in.
    let (report, groups) = report::build_report_with_paper(&dirs, &opts(), Some(&tables)).unwrap();
    let report = with_verdicts(report);
    let page = html::page(&report, &RunView::of_groups(&groups, &out));
    let json = serde_json::to_value(&report).unwrap();
    check_numbers(&page, &json);
    for v in ["verdict-beats", "verdict-trails"] {
        assert!(page.contains(v), "{v} missing");
    }
    assert!(page.contains("✗ does not hold"));

    // Run links are relative to the page and reach the files.
    let first = &groups[0].runs[0].run.dir;
    let rel = format!(
        "../results/{}/{}/run.json",
        first
            .parent()
            .unwrap()
            .file_name()
            .unwrap()
            .to_string_lossy(),
        first.file_name().unwrap().to_string_lossy()
    );
    let href = rel
        .replace('[', "%5B")
        .replace(']', "%5D")
        .replace('=', "%3D");
    assert!(
        page.contains(&format!("href=\"{href}\"")),
        "{href} not linked"
    );
    assert!(out.join(&rel).is_file());
}

/// `<img src=x onerror=…>` with quotes and a closing script tag, in names, notes and reasons.
pub const PAYLOAD: &str = "<img src=x onerror=window.__xss=1>\"'";

pub fn injected_tree(root: &Path) -> (Vec<PathBuf>, PaperTables) {
    let evil_task = SynthTask {
        name: format!("</script>{PAYLOAD}"),
        env_id: "CircuitTraining-Ariane-v0".into(),
        domain: format!("{PAYLOAD}domain"),
    };
    let results = root.join("results");
    for algo in [format!("ppo{PAYLOAD}</script>"), "ddqn".to_string()] {
        for seed in 0..3 {
            let mut run = SynthRun::new(&format!("exp{PAYLOAD}"), &evil_task, &algo, seed);
            run.energy_note = format!("meter note {PAYLOAD}</script>");
            run.write(&results);
        }
    }
    let mut failed = SynthRun::new("failed", &evil_task, "ddqn", 9);
    failed.curve_points = 3;
    write_failed_run(&failed, &results, &format!("failed: reason {PAYLOAD}"));
    let text = paper_tables("CircuitTraining-Ariane-v0", &["ddqn"]);
    (
        vec![results],
        PaperTables::from_json(&text, Path::new("tables.json")).unwrap(),
    )
}

#[test]
fn names_and_notes_from_results_are_text_not_markup() {
    let tmp = tempfile::tempdir().unwrap();
    let (dirs, tables) = injected_tree(tmp.path());
    let out = tmp.path().join("report");
    let r = report::write_report_with_paper(&dirs, &out, &opts(), Some(&tables)).unwrap();
    assert_eq!(r.skipped_runs.len(), 1);
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    let lower = page.to_lowercase();
    assert!(!lower.contains("<img"), "raw <img in index.html");
    // Exactly the page's own two script elements.
    assert_eq!(lower.matches("<script").count(), 2);
    assert_eq!(lower.matches("</script").count(), 2);
    assert!(!page.contains("onerror=window.__xss=1>\""));
    for shown in [
        "&lt;img src=x onerror=window.__xss=1&gt;&quot;&#39;",
        "meter note &lt;img",
        "reason &lt;img",
        "&lt;/script&gt;",
    ] {
        assert!(page.contains(shown), "{shown} not on the page");
    }
    // The script's data block: the names are there, as JSON escapes.
    let data_start = page.find("id=\"report-data\">").unwrap();
    let data = &page[data_start..data_start + page[data_start..].find("</script>").unwrap()];
    assert!(data.contains("\\u003c/script\\u003e\\u003cimg src=x"));
    let script = page.rsplit("<script>").next().unwrap();
    assert!(!script.contains("innerHTML") && !script.contains("insertAdjacentHTML"));

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(!md.to_lowercase().contains("<img"), "raw <img in report.md");
    assert!(!md.contains("</script>"));
    assert!(md.contains("&lt;img src=x onerror=window.__xss=1&gt;"));
    // A pipe in a name cannot split a table row.
    assert_eq!(
        report::render::md_text("a|b<c"),
        "a\\|b&lt;c",
        "markdown escaping"
    );
}

#[test]
fn committed_report_directories_render_without_their_runs() {
    let results = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results");
    let mut rendered = 0;
    for entry in std::fs::read_dir(&results).unwrap() {
        let dir = entry.unwrap().path();
        if !dir.join("report.json").is_file() || !dir.join("curves.csv").is_file() {
            continue;
        }
        let page = html::page_from_report_dir(&dir).unwrap();
        let json: Json =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap())
                .unwrap();
        check_numbers(&page, &json);
        // Curves drawn from curves.csv; no run links without run directories.
        assert!(page.contains("<g class=\"series\""), "{}", dir.display());
        assert!(page.contains("(not included)"));
        rendered += 1;
    }
    assert!(
        rendered > 0,
        "no report directories in {}",
        results.display()
    );

    let tmp = tempfile::tempdir().unwrap();
    let some = std::fs::read_dir(&results)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|d| d.join("report.json").is_file())
        .unwrap();
    std::fs::copy(some.join("report.json"), tmp.path().join("report.json")).unwrap();
    std::fs::write(
        tmp.path().join("curves.csv"),
        "run,step,value\nnobody/x/seed0,1,2\n",
    )
    .unwrap();
    let err = html::page_from_report_dir(tmp.path())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("curves.csv")
            && err.contains("line 2: run `nobody/x/seed0` is not in report.json"),
        "{err}"
    );
}

/// The committed per-domain report directories under `docs/results/`.
fn committed_report_dirs() -> Vec<PathBuf> {
    let results = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results");
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&results)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|d| d.join("report.json").is_file() && d.join("curves.csv").is_file())
        .collect();
    dirs.sort();
    dirs
}

#[test]
fn a_report_merged_alone_is_the_same_report() {
    // The IQMs and probabilities of improvement are computed again on merging, with the
    // streams `a2perf report` uses: one report merged alone must come back unchanged.
    for dir in committed_report_dirs() {
        let path = dir.join("report.json");
        let alone: Report = a2perf_core::results::read_json(&path).unwrap();
        let merged = report::merge_reports(vec![(path.clone(), alone.clone())]).unwrap();
        assert_eq!(merged, alone, "{}", dir.display());
    }
}

#[test]
fn report_directories_merge_into_one_page_whose_numbers_are_the_merged_report_json() {
    let dirs = committed_report_dirs();
    assert!(dirs.len() >= 2, "{dirs:?}");
    let (merged, page) = a2perf_pipeline::report::page_from_report_dirs(&dirs).unwrap();
    let parts: Vec<Report> = dirs
        .iter()
        .map(|d| a2perf_core::results::read_json(&d.join("report.json")).unwrap())
        .collect();
    assert_eq!(
        merged.groups.len(),
        parts.iter().map(|r| r.groups.len()).sum::<usize>()
    );
    // Algorithms reported apart on one task are now compared: every ordered pair of the
    // algorithms that share a task has a probability of improvement.
    let on = |task: &str| -> BTreeSet<&str> {
        merged
            .groups
            .iter()
            .filter(|g| g.task == task)
            .map(|g| g.algorithm.as_str())
            .collect()
    };
    let shared = merged
        .groups
        .iter()
        .find(|g| on(&g.task).len() > 1)
        .expect("two algorithms on one task");
    let algos = on(&shared.task);
    for x in &algos {
        for y in algos.iter().filter(|y| y != &x) {
            assert!(
                merged
                    .probability_of_improvement
                    .iter()
                    .any(|p| p.x == *x && p.y == *y && p.tasks.contains(&shared.task)),
                "{x} over {y} on {}",
                shared.task
            );
        }
    }
    // One settings entry per task, naming every algorithm of that task.
    for s in &merged.settings {
        assert_eq!(
            merged.settings.iter().filter(|t| t.task == s.task).count(),
            1
        );
        let named: BTreeSet<&str> = s
            .profiles
            .iter()
            .flat_map(|p| p.algorithms.iter().map(String::as_str))
            .collect();
        assert_eq!(named, on(&s.task), "{}", s.task);
    }
    let json: Json = serde_json::to_value(&merged).unwrap();
    check_numbers(&page, &json);
    for g in &merged.groups {
        assert!(page.contains(&html::escape(&g.task)), "{}", g.task);
    }

    // A group in two reports, and reports with different bootstrap repetitions, are refused
    // with the file named.
    let err = a2perf_pipeline::report::page_from_report_dirs(&[dirs[0].clone(), dirs[0].clone()])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("report.json") && err.contains("from one report only"),
        "{err}"
    );
    let tmp = tempfile::tempdir().unwrap();
    let mut other: Report = parts[1].clone();
    other.bootstrap_reps += 1;
    std::fs::write(
        tmp.path().join("report.json"),
        serde_json::to_string(&other).unwrap(),
    )
    .unwrap();
    std::fs::copy(dirs[1].join("curves.csv"), tmp.path().join("curves.csv")).unwrap();
    let err = a2perf_pipeline::report::page_from_report_dirs(&[
        dirs[0].clone(),
        tmp.path().to_path_buf(),
    ])
    .unwrap_err()
    .to_string();
    assert!(
        err.contains(&tmp.path().join("report.json").display().to_string())
            && err.contains("bootstrap repetitions"),
        "{err}"
    );
}
