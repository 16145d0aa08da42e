//! Minari interoperability: datasets written by `collect` load with `minari.load_dataset`.
//!
//! Needs a Python with `minari` and `pyarrow` (`pip install "minari[arrow]"`): taken from
//! `A2PERF_MINARI_PYTHON`, else `A2PERF_PYTHON` if it has both, else a venv at `~/.cache/a2perf-rs/minari-arrow-venv` (created with
//! pip when missing). Skips with a printed reason when that is impossible, unless
//! `A2PERF_REQUIRE_INTEROP=1`, which turns the skip into a failure.

mod common;

use std::path::PathBuf;
use std::process::Command;

use a2perf_pipeline::collect::CollectOptions;

fn has_minari(python: &PathBuf) -> bool {
    Command::new(python)
        .args(["-c", "import minari, pyarrow, PIL"])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn python() -> Result<PathBuf, String> {
    if let Ok(p) = std::env::var("A2PERF_MINARI_PYTHON") {
        let p = PathBuf::from(p);
        return if has_minari(&p) {
            Ok(p)
        } else {
            Err(format!(
                "{} cannot import minari, pyarrow and PIL (minari's arrow storage imports it)",
                p.display()
            ))
        };
    }
    // CI's interop venv, when it has the arrow extra.
    if let Ok(p) = std::env::var("A2PERF_PYTHON") {
        let p = PathBuf::from(p);
        if has_minari(&p) {
            return Ok(p);
        }
    }
    let home = std::env::var("HOME").map_err(|_| "HOME is not set".to_string())?;
    let venv = PathBuf::from(home).join(".cache/a2perf-rs/minari-arrow-venv");
    let py = venv.join("bin/python");
    if has_minari(&py) {
        return Ok(py);
    }
    let made = Command::new("python3")
        .args(["-m", "venv"])
        .arg(&venv)
        .status()
        .map_err(|e| format!("python3 not runnable: {e}"))?;
    if !made.success() {
        return Err("python3 -m venv failed".into());
    }
    let pip = Command::new(venv.join("bin/pip"))
        .args(["install", "-q", "minari[arrow]", "pillow"])
        .status()
        .map_err(|e| format!("pip not runnable: {e}"))?;
    if !pip.success() || !has_minari(&py) {
        return Err("pip install \"minari[arrow]\" failed (offline?)".into());
    }
    Ok(py)
}

#[test]
fn collected_datasets_load_with_minari() {
    let py = match python() {
        Ok(p) => p,
        Err(why) => {
            if std::env::var("A2PERF_REQUIRE_INTEROP").as_deref() == Ok("1") {
                panic!("Minari interop required but unavailable: {why}");
            }
            eprintln!("SKIPPED collected_datasets_load_with_minari: {why}");
            return;
        }
    };
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let plan = common::trained_plan(&reg, tmp.path(), "exp", vec![0, 1]);
    let out = tmp.path().join("datasets");
    let runs = [plan.run_dir(0), plan.run_dir(1)];
    let summary = a2perf_pipeline::collect::collect(
        &reg,
        &runs,
        &out,
        &CollectOptions {
            eval_episodes: 3,
            dataset_episodes: 4,
            one_sigma: true,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(!summary.datasets.is_empty());
    for d in &summary.datasets {
        let episodes: Vec<serde_json::Value> =
            serde_json::from_slice(&std::fs::read(d.path.join("episodes.json")).unwrap()).unwrap();
        let returns: Vec<String> = episodes.iter().map(|e| e["return"].to_string()).collect();
        let script = format!(
            r#"
import minari, numpy as np
ds = minari.load_dataset("{id}")
assert ds.total_episodes == {n}, ds.total_episodes
assert ds.total_steps == {steps}, ds.total_steps
expected = [{returns}]
for ep, r in zip(ds.iterate_episodes(), expected):
    assert ep.observations.shape == (len(ep.actions) + 1, 2), ep.observations.shape
    assert ep.actions.dtype == np.int64 and set(np.unique(ep.actions)) <= {{0, 1}}
    assert abs(float(np.sum(ep.rewards)) - r) < 1e-9, (np.sum(ep.rewards), r)
    assert ep.terminations[-1] or ep.truncations[-1]
print("ok", ds.total_episodes, ds.total_steps)
"#,
            id = d.dataset_id,
            n = d.episodes,
            steps = d.steps,
            returns = returns.join(", "),
        );
        let o = Command::new(&py)
            .args(["-c", &script])
            .env("MINARI_DATASETS_PATH", &out)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{}: {}\n{}",
            d.dataset_id,
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        eprintln!(
            "{}: {}",
            d.dataset_id,
            String::from_utf8_lossy(&o.stdout).trim()
        );
    }
}
