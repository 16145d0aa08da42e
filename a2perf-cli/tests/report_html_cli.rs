//! `a2perf report --paper` writes the results page beside the other outputs, and names that
//! become directories are refused before anything is written.

#[path = "../../a2perf-pipeline/tests/html_fixture/mod.rs"]
mod html_fixture;

use std::path::{Path, PathBuf};
use std::process::Command;

fn config(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../configs")
        .join(rel)
}

/// Every path below `dir` (empty when it does not exist).
fn tree(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir(dir) {
        for e in entries.flatten() {
            out.push(e.path());
            out.extend(tree(&e.path()));
        }
    }
    out
}

#[test]
fn names_that_would_leave_the_output_dir_are_refused_before_anything_is_written() {
    let tmp = tempfile::tempdir().unwrap();
    let work = tmp.path().join("work");
    std::fs::create_dir_all(&work).unwrap();
    for (sub, name) in [
        ("train", "../../escaped_here"),
        ("train", "a/b"),
        ("run", ".hidden"),
        ("train", ".."),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
            .current_dir(&work)
            .arg(sub)
            .arg(config("circuit_training/ppo.ron"))
            .args([
                "--set",
                &format!("name={name:?}"),
                "--set",
                "output.dir=out/x",
            ])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{sub} {name}: {err}");
        // The same words as Python's `TrainingRun` (one shared check).
        assert!(
            err.contains(&format!(
                "experiment `{name}`: use letters, digits, `-`, `_` and `.` only (it names a \
                 directory), not starting with `.`"
            )),
            "{sub} {name}: {err}"
        );
        assert!(!err.contains("panicked"), "{err}");
        assert_eq!(
            tree(tmp.path()),
            vec![work.clone()],
            "{sub} {name} wrote files"
        );
    }

    let suite = tmp.path().join("suite.ron");
    std::fs::write(
        &suite,
        format!(
            "(name: \"../up\", set: [\"output.dir=out\"], experiments: [(config: {:?})])",
            config("circuit_training/ppo.ron").display().to_string()
        ),
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .current_dir(&work)
        .arg("run")
        .arg(&suite)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("suite.ron: suite `../up`: use letters, digits"),
        "{err}"
    );
    assert!(tree(&work).is_empty());
}

#[test]
fn report_with_paper_writes_the_page() {
    let tmp = tempfile::tempdir().unwrap();
    let results = tmp.path().join("results");
    let tasks = html_fixture::tasks(2);
    html_fixture::write_tree(&results, &tasks, &["ppo", "ddqn"], 3, 20);
    let tables = tmp.path().join("tables.json");
    std::fs::write(
        &tables,
        html_fixture::paper_tables(&tasks[0].env_id, &["ppo", "ddqn"]),
    )
    .unwrap();
    let out_dir = tmp.path().join("report");
    let out = Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .arg("report")
        .arg(&results)
        .arg("--paper")
        .arg(&tables)
        .args(["--bootstrap-reps", "200", "-o"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let page = std::fs::read_to_string(out_dir.join("index.html")).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("report.json")).unwrap())
            .unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"));
    assert!(page.contains("id=\"leaderboard\""));
    // One row per group, a paper column per algorithm of the matching table.
    assert_eq!(page.matches("<tr data-domain=").count(), 4);
    assert_eq!(
        page.matches("<span class=\"sub\">(paper)</span>").count(),
        2
    );
    assert!(page.contains("<div class=\"paper\""));
    // Verdicts are drawn exactly where report.json has them.
    let verdicts = json["paper"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|p| p["columns"].as_array().unwrap())
        .flat_map(|c| c["cells"].as_array().unwrap())
        .filter(|c| c["verdict"].is_string())
        .count();
    // Each verdict shows in the leaderboard (returns, generalization) and in the task table.
    assert_eq!(page.matches("<span class=\"verdict ").count(), 2 * verdicts);
    // Nothing to fetch: no external reference (the SVG namespace is a name, not a request).
    assert!(!page.contains("href=\"http") && !page.contains("src=\""));
}

#[test]
fn from_reports_merges_report_directories_into_one_page() {
    let results = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/results");
    let dirs = [
        results.join("circuit_training_ppo"),
        results.join("circuit_training_ddqn"),
    ];
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("page");
    let run = |args: &[&std::ffi::OsStr]| {
        Command::new(env!("CARGO_BIN_EXE_a2perf"))
            .arg("report")
            .arg("--from-reports")
            .args(args)
            .output()
            .unwrap()
    };
    let o = run(&[
        dirs[0].as_os_str(),
        dirs[1].as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("2 (task, algorithm) groups from 2 reports"),
        "{stdout}"
    );
    let page = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"), "{}", &page[..40]);
    let merged: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(merged["groups"].as_array().unwrap().len(), 2);
    // PPO and DDQN were reported apart; merged, each is compared with the other.
    assert_eq!(
        merged["probability_of_improvement"]
            .as_array()
            .unwrap()
            .len(),
        2
    );

    // The output may not be an input (its report.json would be replaced); -o is required; and
    // --paper needs the runs, not reports.
    let before = std::fs::read(dirs[0].join("report.json")).unwrap();
    let o = run(&[dirs[0].as_os_str(), "-o".as_ref(), dirs[0].as_os_str()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("is one of the report directories read"),
        "{err}"
    );
    assert_eq!(std::fs::read(dirs[0].join("report.json")).unwrap(), before);
    let o = run(&[dirs[0].as_os_str()]);
    assert_eq!(o.status.code(), Some(2));
    let o = run(&[
        dirs[0].as_os_str(),
        "-o".as_ref(),
        out.as_os_str(),
        "--paper".as_ref(),
        "x.json".as_ref(),
    ]);
    assert_eq!(o.status.code(), Some(2));
}
