//! The shipped `docs/paper/tables.json` against the paper's figures as transcribed in the
//! project's shared data (`../shared/data/paper/a2perf-tables.json`): every cell both ways, and
//! every finding's definition on the paper's own figures.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use a2perf_pipeline::report::paper::{PaperTables, PaperValue};

fn shipped() -> PaperTables {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/paper/tables.json");
    PaperTables::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// The shared transcription, or `None` (with the reason printed) when the shared data is not
/// there; `A2PERF_REQUIRE_SHARED=1` makes its absence a failure.
fn shared() -> Option<serde_json::Value> {
    let path = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/paper/a2perf-tables.json"
    ));
    if !path.exists() {
        if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
            panic!("A2PERF_REQUIRE_SHARED=1 but {} is missing", path.display());
        }
        eprintln!("skipping: {} not present", path.display());
        return None;
    }
    let text = std::fs::read_to_string(&path).unwrap();
    Some(serde_json::from_str(&text).unwrap())
}

/// (task, phase, metric as printed, algorithm).
type CellKey = (String, String, String, String);

#[test]
fn every_paper_value_equals_the_shared_transcription_and_none_is_extra() {
    let Some(shared) = shared() else { return };
    let tables = shipped();
    let mut theirs = BTreeSet::new();
    for st in shared["tasks"].as_array().unwrap() {
        let id = st["id"].as_str().unwrap();
        let task = tables
            .tasks
            .iter()
            .find(|t| t.id == id)
            .unwrap_or_else(|| panic!("task `{id}` is not in tables.json"));
        // `WebNavigation-Difficulty-01-v0 (5 websites)`: the id, then the website count.
        let env = st["env"].as_str().unwrap();
        let mut words = env.split_whitespace();
        assert_eq!(words.next(), Some(task.env_id.as_str()), "{id}");
        let websites = words
            .next()
            .map(|w| w.trim_start_matches('(').parse::<i64>().unwrap());
        assert_eq!(
            task.params.get("num_websites").and_then(|v| v.as_i64()),
            websites,
            "{id}"
        );
        assert_eq!(task.table.as_deref(), st["paper_label"].as_str(), "{id}");
        for phase in ["training", "inference"] {
            for (metric, row) in st[phase].as_object().unwrap() {
                let unit = row["unit"].as_str().unwrap();
                for (algo, cell) in row.as_object().unwrap() {
                    if ["category", "metric", "unit"].contains(&algo.as_str()) {
                        continue;
                    }
                    let at = format!("{id} / {phase} / {metric} / {algo}");
                    let ours: Vec<&PaperValue> = task
                        .algorithms
                        .get(algo)
                        .unwrap_or_else(|| panic!("{at}: no algorithm {algo}"))
                        .values()
                        .filter(|v| {
                            v.paper_metric.as_deref() == Some(metric.as_str())
                                && v.phase.map(|p| p.as_str()) == Some(phase)
                        })
                        .collect();
                    let [v] = ours.as_slice() else {
                        panic!("{at}: {} cells in tables.json, want 1", ours.len())
                    };
                    assert_eq!(v.unit, unit, "{at}");
                    assert_eq!(v.mean, cell["mean"].as_f64(), "{at}: mean");
                    assert_eq!(v.std, cell["std"].as_f64(), "{at}: std");
                    let source = v.source.as_deref().unwrap_or_default();
                    assert!(
                        source.contains(st["paper_label"].as_str().unwrap())
                            && source.contains(&format!("'{metric} ({unit})'"))
                            && source.ends_with(phase),
                        "{at}: source `{source}`"
                    );
                    theirs.insert((id.to_string(), phase.into(), metric.clone(), algo.clone()));
                }
            }
        }
    }
    let ours: BTreeSet<CellKey> = tables
        .tasks
        .iter()
        .flat_map(|t| {
            t.algorithms.iter().flat_map(move |(algo, metrics)| {
                metrics.values().map(move |v| {
                    (
                        t.id.clone(),
                        v.phase.map(|p| p.as_str().to_string()).unwrap_or_default(),
                        v.paper_metric.clone().unwrap_or_default(),
                        algo.clone(),
                    )
                })
            })
        })
        .collect();
    let extra: Vec<&CellKey> = ours.difference(&theirs).collect();
    assert!(extra.is_empty(), "cells not in the paper: {extra:?}");
    assert_eq!(ours.len(), theirs.len());
    assert_eq!(
        tables.tasks.len(),
        shared["tasks"].as_array().unwrap().len()
    );
}

#[test]
fn every_finding_holds_on_the_papers_own_figures_with_the_papers_numbers() {
    let tables = shipped();
    let ids: Vec<&str> = tables.findings.iter().map(|f| f.id.as_str()).collect();
    assert_eq!(ids, ["F1", "F2", "F3", "F4", "F5", "F6", "F7", "F8", "F9"]);
    let paper = a2perf_pipeline::report::paper::PaperSide(&tables);
    // The numbers docs/paper-findings.md quotes for each claim, as the evaluation prints them.
    let quoted: [(&str, &[&str]); 9] = [
        ("F1", &["48.28 + 0.11 = 48.39 < 108.20", "48.39 < 120.53"]),
        ("F2", &["0.11 / 48.28"]),
        ("F3", &["-1.10 ± 0.04 vs -1.13 ± 0.04"]),
        ("F4", &["2305.57 / 2.19"]),
        (
            "F5",
            &["120.00 + 68.00 = 188.00 < 273.00", "110.00 + 68.00"],
        ),
        (
            "F6",
            &["0.01 < 0.05", "(×5.00)", "-1.01 > -1.25", "(×1.24)"],
        ),
        ("F7", &["9.94 ± 15.59 vs 6.96 ± 6.72"]),
        ("F8", &["5.81 < 10.19", "13.00 < 25.82"]),
        ("F9", &["1.69 > 0.46", "(×3.67)", "4.80 < 8.76"]),
    ];
    for (f, (id, numbers)) in tables.findings.iter().zip(quoted) {
        assert_eq!(f.id, id);
        let e = f.evaluate(&paper);
        assert_eq!(e.holds, Some(true), "{id}: {} ({:?})", e.text, e.missing);
        for n in numbers {
            assert!(e.text.contains(n), "{id}: `{n}` not in `{}`", e.text);
        }
    }
}
