//! `a2perf metrics …` on small CSV files, through the built binary.

use std::path::Path;
use std::process::Command;

fn a2perf(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(args)
        .output()
        .expect("the a2perf binary runs")
}

/// Runs `a2perf args`, asserts success and parses its standard output as JSON.
fn a2perf_json(args: &[&str]) -> serde_json::Value {
    let out = a2perf(args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on stdout")
}

fn write_curves(path: &Path, runs: usize, points: usize) {
    let mut s = String::from("run,step,value\n");
    for r in 0..runs {
        for t in 0..points {
            let v = 0.02 * t as f64 + 0.3 * (0.7 * t as f64 + r as f64).sin();
            s.push_str(&format!("seed{r},{},{v}\n", t * 10));
        }
    }
    std::fs::write(path, s).unwrap();
}

#[test]
fn reliability_json_has_exactly_the_a2perf_keys() {
    let dir = tempfile::tempdir().unwrap();
    let curves = dir.path().join("curves.csv");
    let rollouts = dir.path().join("rollouts.csv");
    write_curves(&curves, 4, 60);
    std::fs::write(&rollouts, "return\n1.0\n2.5\n-0.5\n3.0\n2.0\n").unwrap();

    let v = a2perf_json(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
        "--json",
    ]);
    let mut keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "dispersion_across_runs",
            "dispersion_within_runs",
            "long_term_risk",
            "risk_across_runs",
            "short_term_risk"
        ]
    );
    assert!(v["dispersion_within_runs"]["mean"].as_f64().unwrap() >= 0.0);
    assert!(v["dispersion_within_runs"]["std"].is_number());
    assert!(v["short_term_risk"].is_number());

    let v = a2perf_json(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
        "--rollouts",
        rollouts.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(v.as_object().unwrap().len(), 7);
    // IQR of [-0.5, 1, 2, 2.5, 3] = 2.5 - 1 = 1.5; CVaR_0.05 = the minimum.
    assert_eq!(v["dispersion_across_rollouts"].as_f64(), Some(1.5));
    assert_eq!(v["risk_across_rollouts"].as_f64(), Some(-0.5));
}

#[test]
fn reliability_chan2019_and_table_output() {
    let dir = tempfile::tempdir().unwrap();
    let curves = dir.path().join("curves.csv");
    write_curves(&curves, 3, 40);
    let v = a2perf_json(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
        "--definition",
        "chan2019",
        "--json",
    ]);
    assert_eq!(v["LowerCVaROnDiffs"]["bigger_is_better"], true);
    assert_eq!(v["LowerCVaROnDiffs"]["values"].as_array().unwrap().len(), 3);
    assert_eq!(v["IqrWithinRuns"]["bigger_is_better"], false);

    let out = a2perf(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
    ]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("risk_across_runs") && text.contains("higher"),
        "{text}"
    );
}

#[test]
fn bad_files_give_line_numbered_errors() {
    let dir = tempfile::tempdir().unwrap();
    let curves = dir.path().join("bad.csv");
    std::fs::write(&curves, "run,step,value\na,0,1\na,1,oops\n").unwrap();
    let out = a2perf(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.csv:3:") && err.contains("oops"), "{err}");

    std::fs::write(&curves, "step,value\n").unwrap();
    let out = a2perf(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("bad.csv:1:") && err.contains("run,step,value"),
        "{err}"
    );

    std::fs::write(
        &curves,
        "run,step,value\nfirst,0,1\nfirst,1,2\nlonely,0,1\n",
    )
    .unwrap();
    let out = a2perf(&[
        "metrics",
        "reliability",
        "--curves",
        curves.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("run `lonely`"),
        "{err}"
    );

    let missing = dir.path().join("missing.csv");
    let out = a2perf(&["metrics", "iqm", "--scores", missing.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.csv"));
}

#[test]
fn iqm_reports_point_and_interval_per_algorithm() {
    let dir = tempfile::tempdir().unwrap();
    let scores = dir.path().join("scores.csv");
    let mut s = String::from("algorithm,task,run,score\n");
    for (a, offset) in [("ppo", 0.0), ("sac", 0.5)] {
        for t in 0..3 {
            for r in 0..10 {
                s.push_str(&format!(
                    "{a},task{t},{r},{}\n",
                    offset + (r * 7 % 10) as f64 / 10.0 + t as f64 * 0.01
                ));
            }
        }
    }
    std::fs::write(&scores, s).unwrap();
    let v = a2perf_json(&[
        "metrics",
        "iqm",
        "--scores",
        scores.to_str().unwrap(),
        "--reps",
        "2000",
        "--json",
    ]);
    let ppo = &v["algorithms"]["ppo"];
    let sac = &v["algorithms"]["sac"];
    let (p, lo, hi) = (
        ppo["iqm"].as_f64().unwrap(),
        ppo["ci_lower"].as_f64().unwrap(),
        ppo["ci_upper"].as_f64().unwrap(),
    );
    assert!(lo <= p && p <= hi, "{lo} {p} {hi}");
    assert!((sac["iqm"].as_f64().unwrap() - p - 0.5).abs() < 1e-12);
    assert_eq!(ppo["runs"], 10);
    assert_eq!(ppo["tasks"], 3);
}
