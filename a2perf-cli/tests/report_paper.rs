//! `a2perf report --paper` on a synthetic results tree: one real run of the binary (a few dozen
//! steps) copied into five runs of three algorithms whose returns, energy, RAM and inference
//! times are set by hand, and a small `tables.json` with the figures to compare them with. The
//! report must show the paper columns with a verdict of each kind, the ratios, a metric
//! published in another unit converted and labelled, and the findings: one that holds, one that
//! does not, one that cannot be checked; `comparison.json` must say the same.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};

fn a2perf(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_a2perf"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(out: &std::process::Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn read(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn write(path: &Path, v: &Value) {
    std::fs::write(path, serde_json::to_string_pretty(v).unwrap()).unwrap();
}

/// Trains and infers one tiny PPO run on the smallest synthetic netlist; returns its directory.
fn real_run(dir: &Path) -> PathBuf {
    let out = dir.join("real");
    let config = dir.join("tiny.ron");
    std::fs::write(
        &config,
        format!(
            r#"(
    name: "tiny",
    env: (id: "CircuitTraining-Synthetic-Small-v0"),
    algorithm: (name: "ppo", num_steps: 32, minibatch_size: 32, latent_dim: 8, hidden_sizes: [8]),
    seeds: [0],
    training: (total_env_steps: 64, eval_interval: 32, eval_episodes: 1, num_envs: 1),
    inference: (rollouts: 2, timing_samples: 10),
    metrics: (energy_method: "estimate", ram_sample_interval_s: 0.2),
    output: (dir: {:?}),
)"#,
            out.display().to_string()
        ),
    )
    .unwrap();
    ok(&a2perf(&["train", config.to_str().unwrap(), "--quiet"]));
    let run = out.join("tiny/CircuitTraining-Synthetic-Small-v0__ppo__seed0");
    ok(&a2perf(&["infer", run.to_str().unwrap(), "--quiet"]));
    run
}

fn set_meter(system: &mut Value, name: &str, value: f64) {
    let ms = system["meters"]["measurements"].as_array_mut().unwrap();
    let m = ms
        .iter_mut()
        .find(|m| m["name"] == name)
        .unwrap_or_else(|| panic!("no meter {name}"));
    m["value"] = json!(value);
}

/// What one synthetic run reports.
struct Fake {
    algorithm: &'static str,
    seed: u64,
    returns: f64,
    train_peak_ram_gb: f64,
    inference_ms: f64,
}

/// A copy of `real` as run `fake`: training 1 h and 2 kWh, inference 0.1 h, 0.5 kWh and
/// 0.25 GB peak RAM, the rest as `fake` says.
fn fake_run(real: &Path, tree: &Path, fake: &Fake) {
    let experiment = format!("exp_{}", fake.algorithm);
    let dir = tree.join(&experiment).join(format!(
        "CircuitTraining-Synthetic-Small-v0__{}__seed{}",
        fake.algorithm, fake.seed
    ));
    std::fs::create_dir_all(&dir).unwrap();
    for f in [
        "status.json",
        "curve.json",
        "curve.csv",
        "system_info.json",
        "operative_config.ron",
    ] {
        std::fs::copy(real.join(f), dir.join(f)).unwrap();
    }
    let mut run = read(&real.join("run.json"));
    run["experiment"] = json!(experiment);
    run["algorithm"]["name"] = json!(fake.algorithm);
    run["seed"] = json!(fake.seed);
    write(&dir.join("run.json"), &run);

    let mut train = read(&real.join("train_system.json"));
    train["wall_clock_s"] = json!(3600.0);
    set_meter(&mut train, "energy_kwh", 2.0);
    set_meter(&mut train, "peak_ram_gb", fake.train_peak_ram_gb);
    write(&dir.join("train_system.json"), &train);

    let mut inference = read(&real.join("inference.json"));
    inference["returns"]["mean"] = json!(fake.returns);
    inference["rollout_returns"] = json!([fake.returns, fake.returns]);
    inference["inference_time_ms"]["mean"] = json!(fake.inference_ms);
    inference["system"]["wall_clock_s"] = json!(360.0);
    set_meter(&mut inference["system"], "energy_kwh", 0.5);
    set_meter(&mut inference["system"], "peak_ram_gb", 0.25);
    write(&dir.join("inference.json"), &inference);
}

/// The paper of this test (its figures are test data). PPO's peak RAM is published in GiB and
/// its inference time in seconds; SAC was not run here.
fn tables() -> Value {
    let cell = |mean: f64, std: Option<f64>, unit: &str, name: &str, phase: &str| {
        json!({"mean": mean, "std": std, "unit": unit, "paper_metric": name, "phase": phase,
               "source": format!("Table 1, row '{name} ({unit})', {phase}")})
    };
    let returns = |mean: f64, std: f64| cell(mean, Some(std), "100 eps.", "Returns", "training");
    let energy = |kwh: f64| cell(kwh, None, "kWh", "Energy Consumed", "training");
    json!({
        "schema": "a2perf-paper-tables/2",
        "paper": {"title": "Test paper", "version": "test v1"},
        "tasks": [
            {
                "id": "small_macro", "title": "Synthetic small netlist", "domain": "circuit_training",
                "table": "Table 1", "env_id": "CircuitTraining-Synthetic-Small-v0",
                "params": {"netlist_seed": 0},
                // Ours: the best return measured as reachable. BC's paper cell (-1.0 ± 0.1) is
                // above it, so BC's trailing verdict says it is out of reach.
                "ceilings": {"returns": {"value": -1.5, "how": "the test's best placement"}},
                "algorithms": {
                    "ppo": {
                        "returns": returns(-1.2, 0.1),
                        "energy": energy(1.0),
                        "peak_ram": cell(0.5, Some(0.25), "GiB", "Peak RAM Usage", "training"),
                        "inference_time": cell(1e-4, None, "s", "Inference Time", "inference"),
                    },
                    "ddqn": {"returns": returns(-1.0, 0.5), "energy": energy(4.0)},
                    "bc": {"returns": returns(-1.0, 0.1)},
                    "sac": {"returns": returns(-0.5, 0.1)},
                }
            },
            {
                "id": "other_netlist", "title": "Another netlist", "domain": "circuit_training",
                "table": "Table 2", "env_id": "CircuitTraining-Synthetic-Small-v0",
                "params": {"netlist_seed": 7},
                "algorithms": {"ppo": {"returns": returns(3.0, 1.0)}}
            }
        ],
        "findings": [
            {"id": "H1", "claim": "PPO answers within a millisecond",
             "holds_when": {"less": [{"cell": "small_macro/ppo/inference_time"}, {"const": 1.0}]}},
            {"id": "H2", "claim": "BC's returns overlap DDQN's",
             "holds_when": {"overlap": [{"cell": "small_macro/bc/returns"},
                                        {"cell": "small_macro/ddqn/returns"}]}},
            {"id": "H3", "claim": "SAC beats PPO",
             "holds_when": {"greater": [{"cell": "small_macro/sac/returns"},
                                        {"cell": "small_macro/ppo/returns"}]},
             "note": "judged on the direction"}
        ]
    })
}

fn section<'a>(md: &'a str, heading: &str) -> &'a str {
    let start = md
        .find(heading)
        .unwrap_or_else(|| panic!("no `{heading}` in\n{md}"));
    let rest = &md[start + heading.len()..];
    &rest[..rest.find("\n## ").unwrap_or(rest.len())]
}

#[test]
fn report_with_the_paper_shows_columns_ratios_verdicts_findings_and_comparison_json() {
    let tmp = tempfile::tempdir().unwrap();
    let real = real_run(tmp.path());
    let tree = tmp.path().join("tree");
    let gib = 1_073_741_824.0 / 1e9;
    let fakes = [
        // PPO: mean return -0.9, above the paper's -1.2 (beats); peak RAM 1 GiB, twice the
        // paper's 0.5 GiB.
        ("ppo", 0, -1.0, gib, 0.02),
        ("ppo", 1, -0.8, gib, 0.04),
        // DDQN: -1.2, inside the paper's -1.0 ± 0.5 (within).
        ("ddqn", 0, -1.3, 0.5, 0.05),
        ("ddqn", 1, -1.1, 0.5, 0.05),
        // BC: -2.0, below the paper's -1.0 ± 0.1 (trails by 1.0).
        ("bc", 0, -2.0, 0.5, 0.05),
    ];
    for (algorithm, seed, returns, train_peak_ram_gb, inference_ms) in fakes {
        fake_run(
            &real,
            &tree,
            &Fake {
                algorithm,
                seed,
                returns,
                train_peak_ram_gb,
                inference_ms,
            },
        );
    }
    let tables_path = tmp.path().join("tables.json");
    write(&tables_path, &tables());
    let out = tmp.path().join("report");
    let stdout = ok(&a2perf(&[
        "report",
        tree.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--paper",
        tables_path.to_str().unwrap(),
        "--bootstrap-reps",
        "100",
    ]));
    assert!(
        stdout.contains("paper: 1 of the report's tables match"),
        "{stdout}"
    );

    // For eyeballing: A2PERF_KEEP_REPORT=DIR keeps a copy of the report.
    if let Ok(keep) = std::env::var("A2PERF_KEEP_REPORT") {
        std::fs::create_dir_all(&keep).unwrap();
        for f in [
            "report.md",
            "report.tex",
            "comparison.json",
            "paper_comparison.csv",
        ] {
            std::fs::copy(out.join(f), Path::new(&keep).join(f)).unwrap();
        }
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let table = section(&md, "## CircuitTraining-Synthetic-Small-v0 (");
    // The paper columns, with the verdicts.
    assert!(
        table.contains("| PPO (seeds 2) | PPO (paper) |")
            && table.contains("| DDQN (seeds 2) | DDQN (paper) |")
            && table.contains("| BC (seeds 1) | BC (paper) |"),
        "{table}"
    );
    let returns_row = table
        .lines()
        .find(|l| l.starts_with("| Application | Returns"))
        .unwrap();
    for want in [
        "-1.20 ± 0.10 (beats)",
        "-1.00 ± 0.50 (within)",
        "-1.00 ± 0.10 (trails by 1.00, out of reach here)",
    ] {
        assert!(returns_row.contains(want), "`{want}` not in {returns_row}");
    }
    // The ratios (columns BC, DDQN, PPO): energy 2 kWh against 4 and 1; peak RAM 1 GiB
    // against 0.5 GiB.
    assert!(
        table.contains("| System (training) | Energy consumed (kWh) | — | 0.500 | 2.00 |"),
        "{table}"
    );
    assert!(
        table.contains("| System (training) | Peak RAM usage (GB) | — | — | 2.00 |"),
        "{table}"
    );
    // Units that differ are converted and labelled.
    assert!(
        table.contains("0.5 ± 0.25 GiB; GiB → GB (×1.073742)"),
        "{table}"
    );
    assert!(table.contains("s → ms (×1000)"), "{table}");
    let inference_row = table
        .lines()
        .find(|l| l.starts_with("| System (inference) | Inference time (ms)"))
        .unwrap();
    assert!(inference_row.contains("| 0.10 |"), "{inference_row}");
    assert!(table.contains("the paper also reports SAC on this task (not run here)"));
    assert!(
        table.contains(
            "out of reach here: the test's best placement is -1.5, below the paper's mean − \
             std -1.10"
        ),
        "{table}"
    );

    // The findings: one holds, one does not, one cannot be checked.
    let findings = section(&md, "## The paper's findings");
    for (id, outcome) in [
        ("H1", "**holds**"),
        ("H2", "**does not hold**"),
        ("H3", "**not checked**"),
    ] {
        let row = findings
            .lines()
            .find(|l| l.starts_with(&format!("| {id} |")))
            .unwrap_or_else(|| panic!("no {id} in {findings}"));
        assert!(row.ends_with(&format!("| {outcome} |")), "{row}");
    }
    // Markdown text is HTML-escaped (`<` is `&lt;`, which renders as `<`).
    assert!(findings.contains("| 0.10 &lt; 1.00 ms (×10.0) | 0.03 &lt; 1.00 ms (×33.3) |"));
    assert!(findings.contains("-1.00 ± 0.10 vs -1.00 ± 0.50: gap 0.00 ≤ 0.60"));
    assert!(findings.contains("-2.00 ± 0.00 vs -1.20 ± 0.14: gap 0.80 &gt; 0.14"));
    assert!(findings.contains("H3: judged on the direction; missing in our runs: small_macro/sac/returns: no sac runs on this task"));

    let report = read(&out.join("report.json"));
    let holds: Vec<&Value> = report["findings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| &f["holds"])
        .collect();
    assert_eq!(holds, [&json!(true), &json!(false), &Value::Null]);
    let tex = std::fs::read_to_string(out.join("report.tex")).unwrap();
    assert!(
        tex.contains("(trails by 1.00, out of reach here)") && tex.contains("tab:paper-findings")
    );
    let csv = std::fs::read_to_string(out.join("paper_comparison.csv")).unwrap();
    assert!(
        csv.lines()
            .any(|l| l.contains(",bc,returns,") && l.contains(",trails,1,")),
        "{csv}"
    );

    // comparison.json: the paper's names, both means in the paper's unit, the verdicts.
    let cmp = read(&out.join("comparison.json"));
    let cells = cmp["cells"].as_array().unwrap();
    assert_eq!(cells.len(), 9, "every cell of the paper's tables");
    let find = |task: &str, algorithm: &str, metric: &str| {
        cells
            .iter()
            .find(|c| c["task"] == task && c["algorithm"] == algorithm && c["metric"] == metric)
            .unwrap_or_else(|| panic!("no {task}/{algorithm}/{metric}"))
    };
    let ram = find("small_macro", "ppo", "Peak RAM Usage");
    assert_eq!(ram["phase"], "training");
    assert_eq!(ram["unit"], "GiB");
    assert_eq!(ram["paper_mean"], json!(0.5));
    let ours = ram["ours_mean"].as_f64().unwrap();
    assert!((ours - 1.0).abs() < 1e-12, "1 GiB in GiB: {ours}");
    assert!((ram["ratio"].as_f64().unwrap() - 2.0).abs() < 1e-12);
    let time = find("small_macro", "ppo", "Inference Time");
    assert_eq!(
        (&time["phase"], &time["unit"]),
        (&json!("inference"), &json!("s"))
    );
    assert!((time["ours_mean"].as_f64().unwrap() - 3e-5).abs() < 1e-15);
    for (algorithm, verdict) in [("ppo", "beats"), ("ddqn", "within"), ("bc", "trails")] {
        let c = find("small_macro", algorithm, "Returns");
        assert_eq!(c["verdict"], verdict, "{algorithm}");
        // Only the trailing cell the ceiling explains says it is out of reach.
        assert_eq!(
            c["out_of_reach"].as_str().is_some(),
            algorithm == "bc",
            "{algorithm}: {c}"
        );
    }
    let sac = find("small_macro", "sac", "Returns");
    assert_eq!(
        (&sac["ours_mean"], &sac["verdict"]),
        (&Value::Null, &Value::Null)
    );
    assert_eq!(sac["ours_note"], "no sac runs on this task");
    assert_eq!(
        find("other_netlist", "ppo", "Returns")["ours_mean"],
        Value::Null
    );
    let outcomes: Vec<(&Value, &Value)> = cmp["findings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| (&f["id"], &f["holds"]))
        .collect();
    assert_eq!(
        outcomes,
        [
            (&json!("H1"), &json!(true)),
            (&json!("H2"), &json!(false)),
            (&json!("H3"), &Value::Null)
        ]
    );
    let suite = &cmp["suite"];
    assert_eq!((&suite["runs"], &suite["seeds"]), (&json!(5), &json!(2)));
    let close = |key: &str, want: f64| {
        let got = suite[key].as_f64().unwrap();
        assert!((got - want).abs() < 1e-9, "suite.{key}: {got}, want {want}");
    };
    close("wall_hours", 5.0 * 1.1);
    close("energy_kwh", 5.0 * 2.5);
    close("peak_ram_gb", gib);
    // The paper's 1 and 4 kWh per seed for PPO's and DDQN's two seeds each, against our 2 kWh.
    close("paper_energy_kwh_same_runs", 2.0 * 1.0 + 2.0 * 4.0);
    close("ours_energy_kwh_same_runs", 4.0 * 2.0);
    close("energy_ratio_same_runs", 0.8);
}
