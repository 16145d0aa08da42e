//! Profiles, configurable generalization suites and the paper's tables beside a report, on the
//! example crate's corridor with tiny budgets: what run.json records, what `generalize` rolls
//! out on, what the report prints under each table, and the shipped `docs/paper/tables.json`.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::Value;
use a2perf_pipeline::report::paper::PaperTables;
use a2perf_pipeline::report::{self, ReportOptions};
use a2perf_pipeline::{
    ExperimentPlan, GeneralizationResults, InferOptions, LoadedRun, ProfileRecord, ProfileSwitch,
    SuiteSource, TrainOptions,
};

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const CORRIDOR: &str = r#"env: (id: "Corridor-v0"), algorithm: (name: "random_search"),
    training: (total_env_steps: 400, eval_interval: 100, eval_episodes: 2),
    inference: (rollouts: 3)"#;

fn plans(files: &[PathBuf], sets: &[&str], reg: &a2perf_core::Registry) -> Vec<ExperimentPlan> {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    a2perf_pipeline::load_plans(files, &sets, None, reg)
        .unwrap()
        .plans
}

/// Trains, infers and generalizes every run of `plans`.
fn run_all(plans: &[ExperimentPlan], reg: &a2perf_core::Registry) {
    let opts = TrainOptions {
        meters: common::test_meters(),
        ..Default::default()
    };
    a2perf_pipeline::train(reg, &a2perf_pipeline::grid(plans, None), &opts).unwrap();
    for plan in plans {
        for &seed in &plan.seeds {
            let dir = plan.run_dir(seed);
            a2perf_pipeline::infer_run(
                reg,
                &dir,
                &InferOptions {
                    meters: common::test_meters(),
                    ..Default::default()
                },
            )
            .unwrap();
            a2perf_pipeline::generalize_run(reg, &dir, None, false).unwrap();
        }
    }
}

fn generalization(dir: &Path) -> GeneralizationResults {
    serde_json::from_str(&std::fs::read_to_string(dir.join("generalization.json")).unwrap())
        .unwrap()
}

fn names(g: &GeneralizationResults) -> Vec<&str> {
    g.tasks.iter().map(|t| t.name.as_str()).collect()
}

#[test]
fn profiles_and_suites_are_recorded_and_generalize_runs_the_listed_tasks() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let out = format!(
        "output: (dir: {:?})",
        d.join("results").display().to_string()
    );
    let plain = write(
        d,
        "plain.ron",
        &format!("(name: \"plain\", seeds: [0], {CORRIDOR}, {out}, generalization: (episodes: 2))"),
    );
    let listed = write(
        d,
        "listed.ron",
        &format!(
            r#"(name: "listed", seeds: [0], {CORRIDOR}, {out},
                generalization: (episodes: 2, tasks: [
                    (env: "Corridor-v0", name: "short", params: (length: 4)),
                    (env: "Corridor-v0", name: "long", params: (length: 14)),
                ]))"#
        ),
    );
    write(
        d,
        "profile.ron",
        r#"(profile: (
            name: "orig",
            env: {"example": (length: 6)},
            generalization: {"example": [(env: "Corridor-v0", name: "profiled")]},
        ))"#,
    );
    let profiled = write(
        d,
        "profiled.ron",
        &format!(
            r#"(include: ["profile.ron"], name: "profiled", seeds: [0], {CORRIDOR}, {out},
                generalization: (episodes: 2))"#
        ),
    );
    let reg = common::registry();
    let all = plans(&[plain, listed, profiled.clone()], &[], &reg);
    run_all(&all, &reg);
    let [plain, listed, profiled_plan] = [&all[0], &all[1], &all[2]];

    // No profile, no list: the registry's suite, recorded with its source.
    let run = LoadedRun::open(&plain.run_dir(0)).unwrap();
    assert_eq!(run.record.task.name, "Corridor-v0");
    assert_eq!(run.record.task.profile, None);
    let suite = run.record.generalization.suite.as_ref().unwrap();
    assert_eq!(suite.source, SuiteSource::Registry);
    let g_plain = generalization(&plain.run_dir(0));
    assert_eq!(names(&g_plain), ["corridor_6", "corridor_8", "corridor_12"]);
    assert_eq!(g_plain.source, Some(SuiteSource::Registry));

    // The config's list is exactly what is rolled out, and the sum is over those tasks.
    let run = LoadedRun::open(&listed.run_dir(0)).unwrap();
    let suite = run.record.generalization.suite.as_ref().unwrap();
    assert_eq!(suite.source, SuiteSource::Config);
    let g = generalization(&listed.run_dir(0));
    assert_eq!(names(&g), ["short", "long"]);
    assert_eq!(g.source, Some(SuiteSource::Config));
    assert_eq!(g.tasks[0].params["length"], Value::Int(4));
    assert_eq!(g.tasks[1].params["length"], Value::Int(14));
    let sum: f64 = g.tasks.iter().map(|t| t.mean_return.unwrap()).sum();
    assert_eq!(g.sum_of_mean_returns, Some(sum));
    let plain_sum: f64 = g_plain.tasks.iter().map(|t| t.mean_return.unwrap()).sum();
    assert_eq!(g_plain.sum_of_mean_returns, Some(plain_sum));
    assert_eq!(g.tasks.len() + 1, g_plain.tasks.len());

    // The profile: its switch fills the unset parameter, is recorded, names the task, and is
    // filled into its suite's tasks too.
    let run = LoadedRun::open(&profiled_plan.run_dir(0)).unwrap();
    assert_eq!(run.record.task.name, "Corridor-v0[profile=orig]");
    assert_eq!(run.record.task.env_params["length"], Value::Int(6));
    assert_eq!(
        run.record.task.profile,
        Some(ProfileRecord {
            name: "orig".into(),
            switches: vec![ProfileSwitch {
                param: "length".into(),
                value: Value::Int(6),
                overridden: None,
            }],
        })
    );
    let g = generalization(&profiled_plan.run_dir(0));
    assert_eq!(g.source, Some(SuiteSource::Profile));
    assert_eq!(names(&g), ["profiled"]);
    assert_eq!(g.tasks[0].params["length"], Value::Int(6));

    // Overriding a switch, even back to the registry default, shows in the record and the name.
    let over = plans(&[profiled], &["env.length=8"], &reg);
    let task = &over[0].task;
    assert_eq!(task.name, "Corridor-v0[profile=orig,length=8]");
    let switch = &task.profile.as_ref().unwrap().switches[0];
    assert_eq!(switch.overridden, Some(Value::Int(8)));
    assert_eq!(
        switch.to_string(),
        "env.length = 8 (overrides the profile's 6)"
    );

    // The report says under each table which profile and suite its runs used.
    let out = d.join("report");
    let dirs: Vec<PathBuf> = all.iter().map(ExperimentPlan::experiment_dir).collect();
    report::write_report(
        &dirs,
        &out,
        &ReportOptions {
            bootstrap_reps: 100,
            seed: 0,
        },
    )
    .unwrap();
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    let table = section(&md, "## Corridor-v0[profile=orig] (");
    assert!(
        table.contains("\nProfile: orig — env.length = 6\n"),
        "{table}"
    );
    assert!(table.contains("\nGeneralization suite: from the profile: profiled\n"));
    let table = section(&md, "## Corridor-v0 (");
    assert!(
        table.contains("**Mixed generalization suites in this table**"),
        "plain and listed share the task: {table}"
    );
    assert!(table.contains("RANDOM_SEARCH:LISTED: from the config: short, long"));
    assert!(
        table.contains(
            "RANDOM_SEARCH:PLAIN: from the registry: corridor_6, corridor_8, corridor_12"
        )
    );
    assert!(table.contains("\nProfile: none (corrected defaults)\n"));

    // run.json files written before profiles and suites existed still load, and generalize
    // falls back to the registry's suite.
    for plan in [plain, profiled_plan] {
        let path = plan.run_dir(0).join("run.json");
        let mut json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        json["task"].as_object_mut().unwrap().remove("profile");
        json["generalization"]
            .as_object_mut()
            .unwrap()
            .remove("suite");
        std::fs::write(&path, serde_json::to_string_pretty(&json).unwrap()).unwrap();
        let run = LoadedRun::open(&plan.run_dir(0)).unwrap();
        assert_eq!(run.record.task.profile, None);
        assert_eq!(run.record.generalization.suite, None);
        let g = a2perf_pipeline::generalize_run(&reg, &plan.run_dir(0), Some(1), false).unwrap();
        assert_eq!(names(&g), ["corridor_6", "corridor_8", "corridor_12"]);
    }
}

/// A tables.json for the corridor: one task matching the default length, one matching none of
/// the runs. The figures are test data, not the paper's.
const TABLES: &str = r#"{
  "schema": "a2perf-paper-tables/1",
  "paper": {"title": "Corridor paper", "version": "test fixture v1"},
  "tasks": [
    {
      "id": "corridor8", "title": "Corridor, length 8", "domain": "example", "table": "Table 1",
      "env_id": "Corridor-v0", "params": {"length": 8.0},
      "algorithms": {
        "random_search": {
          "returns": {"mean": 1.5, "std": 0.5, "unit": "100 eps.", "source": "Table 1, row 'Returns'"},
          "energy": {"mean": 2e-6, "std": 1e-7, "unit": "kWh", "source": "Table 1, row 'Energy'"},
          "peak_ram": {"mean": 0.25, "std": null, "unit": "GiB", "source": "Table 1, row 'Peak RAM (GiB)'"},
          "wall_clock": {"mean": 0.5, "std": null, "unit": "min", "source": "Table 1, row 'Wall clock (min)'"},
          "inference_time": {"mean": 0.001, "std": null, "unit": "ms", "measured_unit": "s",
                             "source": "Table 1, row 'Inference time (ms)'"},
          "mean_ram": {"mean": null, "std": null, "unit": "GB", "source": null,
                       "note": "not printed in Table 1"}
        },
        "toy_bc": {
          "returns": {"mean": 1.0, "std": null, "unit": "100 eps.", "source": "Table 1, row 'Returns'"}
        }
      }
    },
    {
      "id": "corridor12", "title": "Corridor, length 12", "domain": "example", "table": null,
      "env_id": "Corridor-v0", "params": {"length": 12},
      "algorithms": {
        "random_search": {"returns": {"mean": 2.0, "std": null, "unit": "100 eps.", "source": "Table 2"}}
      }
    }
  ]
}"#;

fn section<'a>(md: &'a str, heading: &str) -> &'a str {
    let start = md
        .find(heading)
        .unwrap_or_else(|| panic!("no `{heading}` in\n{md}"));
    let rest = &md[start + heading.len()..];
    &rest[..rest.find("\n## ").unwrap_or(rest.len())]
}

#[test]
fn the_paper_column_and_ratios_appear_under_matching_tables_only() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let matching = common::plan(tmp.path(), "matching", vec![0, 1]);
    let mut other = common::plan(tmp.path(), "other", vec![0]);
    other.task.name = "Corridor-v0[length=6]".into();
    other.task.env_params.insert("length".into(), Value::Int(6));
    run_all(&[matching.clone(), other.clone()], &reg);
    let tables = PaperTables::from_json(TABLES, Path::new("tables.json")).unwrap();

    let out = tmp.path().join("report");
    let rep = report::write_report_with_paper(
        &[matching.experiment_dir(), other.experiment_dir()],
        &out,
        &ReportOptions {
            bootstrap_reps: 100,
            seed: 0,
        },
        Some(&tables),
    )
    .unwrap();

    assert_eq!(rep.paper.len(), 1, "only the length-8 table matches");
    let cmp = &rep.paper[0];
    assert_eq!(
        (cmp.task.as_str(), cmp.paper_task.as_str()),
        ("Corridor-v0", "corridor8")
    );
    assert_eq!(cmp.not_run, ["toy_bc"]);
    let col = &cmp.columns[0];
    assert!(col.in_paper);
    let ours = rep.groups.iter().find(|g| g.task == "Corridor-v0").unwrap();
    let ours_of = |key: &str| ours.metric(key).unwrap().mean.unwrap();

    // GiB → GB, minutes → hours, seconds (labelled ms) → ms; each labelled.
    let peak = col.cell("peak_ram").unwrap();
    assert_eq!(peak.mean, Some(0.25 * 1_073_741_824.0 / 1e9));
    assert_eq!(peak.unit, "GB");
    assert_eq!(peak.conversion.as_deref(), Some("GiB → GB (×1.073742)"));
    assert_eq!(peak.published.as_deref(), Some("0.25 GiB"));
    assert_eq!(peak.ratio, Some(ours_of("peak_ram") / peak.mean.unwrap()));
    let energy = col.cell("energy").unwrap();
    assert_eq!(
        (energy.mean, energy.std, &energy.conversion),
        (Some(2e-6), Some(1e-7), &None)
    );
    assert_eq!(energy.ratio, Some(ours_of("energy") / 2e-6));
    let wall = col.cell("wall_clock").unwrap();
    assert_eq!(wall.mean, Some(0.5 * 60.0 / 3600.0));
    assert_eq!(wall.ratio, Some(ours_of("wall_clock") / wall.mean.unwrap()));
    let inference = col.cell("inference_time").unwrap();
    assert_eq!(inference.mean, Some(1.0));
    assert!(
        inference
            .conversion
            .as_deref()
            .unwrap()
            .contains("measured in s")
    );
    assert_eq!(inference.ratio, None, "no ratio for inference time");
    let returns = col.cell("returns").unwrap();
    assert_eq!((returns.mean, returns.ratio), (Some(1.5), None));
    let missing = col.cell("mean_ram").unwrap();
    assert_eq!(missing.mean, None);
    assert_eq!(missing.note.as_deref(), Some("not printed in Table 1"));

    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    // For eyeballing: A2PERF_KEEP_REPORT=DIR keeps a copy of the report.
    if let Ok(keep) = std::env::var("A2PERF_KEEP_REPORT") {
        std::fs::create_dir_all(&keep).unwrap();
        for f in ["report.md", "report.tex", "paper_comparison.csv"] {
            std::fs::copy(out.join(f), Path::new(&keep).join(f)).unwrap();
        }
    }
    let matched = section(&md, "## Corridor-v0 (");
    assert!(matched.contains("| RANDOM_SEARCH (paper) |"), "{matched}");
    assert!(
        matched.contains("Paper columns: Corridor, length 8, Table 1 (test fixture v1"),
        "{matched}"
    );
    assert!(matched.contains("Ours / paper"), "{matched}");
    let ratio = report::render::format_ratio(peak.ratio.unwrap());
    assert!(
        matched.contains(&format!(
            "| System (training) | Peak RAM usage (GB) | {ratio} |"
        )),
        "{matched}"
    );
    assert!(matched.contains("GiB → GB (×1.073742)"));
    assert!(matched.contains("the paper also reports TOY_BC on this task (not run here)"));
    assert!(matched.contains("Profile: none (corrected defaults)"));
    let unmatched = section(&md, "## Corridor-v0[length=6] (");
    assert!(!unmatched.contains("(paper)") && !unmatched.contains("Ours / paper"));

    let tex = std::fs::read_to_string(out.join("report.tex")).unwrap();
    assert!(tex.contains("\\textbf{RANDOM\\_SEARCH} (paper)") && tex.contains("Ours / paper"));
    let csv = std::fs::read_to_string(out.join("paper_comparison.csv")).unwrap();
    assert!(csv.starts_with("task,paper_task,algorithm,metric,unit,ours_mean,paper_mean"));
    assert_eq!(csv.lines().count(), 1 + 6, "{csv}");
    assert!(csv.lines().all(|l| !l.starts_with("Corridor-v0[length=6]")));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["paper"][0]["paper_task"], "corridor8");

    // Without --paper nothing of the paper appears.
    let plain_out = tmp.path().join("plain-report");
    let rep = report::write_report(
        &[matching.experiment_dir()],
        &plain_out,
        &ReportOptions {
            bootstrap_reps: 100,
            seed: 0,
        },
    )
    .unwrap();
    assert!(rep.paper.is_empty());
    assert!(!plain_out.join("paper_comparison.csv").exists());
    let md = std::fs::read_to_string(plain_out.join("report.md")).unwrap();
    assert!(!md.contains("(paper)"));
}

#[test]
fn tables_mixing_profiles_or_suites_are_flagged() {
    let tmp = tempfile::tempdir().unwrap();
    let reg = common::registry();
    let plain = common::plan(tmp.path(), "plain", vec![0]);
    let mut profiled = common::plan(tmp.path(), "profiled", vec![0]);
    profiled.task.profile = Some(ProfileRecord {
        name: "orig".into(),
        switches: vec![ProfileSwitch {
            param: "length".into(),
            value: Value::Int(8),
            overridden: None,
        }],
    });
    let opts = TrainOptions {
        meters: common::test_meters(),
        ..Default::default()
    };
    let both = [plain.clone(), profiled.clone()];
    a2perf_pipeline::train(&reg, &a2perf_pipeline::grid(&both, None), &opts).unwrap();
    let out = tmp.path().join("report");
    let rep = report::write_report(
        &[plain.experiment_dir(), profiled.experiment_dir()],
        &out,
        &ReportOptions {
            bootstrap_reps: 100,
            seed: 0,
        },
    )
    .unwrap();
    let settings = rep.settings_of("Corridor-v0").unwrap();
    assert!(settings.mixed_profiles());
    assert!(!settings.mixed_suites(), "neither recorded a suite");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        md.contains(
            "**Mixed profiles in this table** (its columns ran under different environment \
             semantics): RANDOM_SEARCH:PLAIN: none (corrected defaults); \
             RANDOM_SEARCH:PROFILED: orig — env.length = 8"
        ),
        "{md}"
    );
    assert!(md.contains(
        "Generalization suite: the domain's registry default (not recorded by these runs)"
    ));
    let tex = std::fs::read_to_string(out.join("report.tex")).unwrap();
    assert!(tex.contains("Mixed profiles in this table"));

    // One profile for the whole table: a single line with its switches.
    let out = tmp.path().join("one");
    report::write_report(
        &[profiled.experiment_dir()],
        &out,
        &ReportOptions {
            bootstrap_reps: 100,
            seed: 0,
        },
    )
    .unwrap();
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("Profile: orig — env.length = 8\n"), "{md}");
}

#[test]
fn malformed_paper_tables_are_refused_naming_the_file_and_the_problem() {
    let tmp = tempfile::tempdir().unwrap();
    let cases: [(&str, String, &str); 8] = [
        (
            "syntax.json",
            "{\"schema\": ".into(),
            "EOF while parsing a value at line 1",
        ),
        (
            "schema.json",
            TABLES.replace("a2perf-paper-tables/1", "v0"),
            "schema `v0` is not supported (expected one of `a2perf-paper-tables/1`, `a2perf-paper-tables/2`)",
        ),
        (
            "unit.json",
            TABLES.replace("\"GiB\"", "\"furlongs\""),
            "task `corridor8`, random_search / peak_ram: unit `furlongs` is not a unit of this metric (expected one of GB, GiB",
        ),
        (
            "metric.json",
            TABLES.replace("\"peak_ram\"", "\"peak_rma\""),
            "task `corridor8`, random_search / peak_rma: unknown metric (did you mean `peak_ram`?)",
        ),
        (
            "source.json",
            TABLES.replace("\"source\": \"Table 1, row 'Energy'\"", "\"source\": null"),
            "task `corridor8`, random_search / energy: a published value needs its `source`",
        ),
        (
            "note.json",
            TABLES.replace("\"note\": \"not printed in Table 1\"", "\"note\": null"),
            "random_search / mean_ram: a missing value (`mean: null`) needs a `note` saying why",
        ),
        (
            "twice.json",
            TABLES.replace("\"length\": 12", "\"length\": 8.0"),
            "tasks `corridor8` and `corridor12` match the same runs",
        ),
        (
            "field.json",
            TABLES.replace("\"table\": null", "\"tabel\": null"),
            "unknown field `tabel`",
        ),
    ];
    for (name, text, want) in cases {
        let path = write(tmp.path(), name, &text);
        let err = PaperTables::load(&path).unwrap_err().to_string();
        let prefix = format!("{}: ", path.display());
        assert!(err.starts_with(&prefix), "{err}");
        assert!(err.contains(want), "{name}:\n got: {err}\nwant: {want}");
    }
    let missing = tmp.path().join("nope.json");
    let err = PaperTables::load(&missing).unwrap_err().to_string();
    assert!(err.starts_with(&missing.display().to_string()), "{err}");
}

#[test]
fn the_shipped_tables_hold_the_papers_eight_tasks() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/paper/tables.json");
    let tables = PaperTables::load(&path).unwrap_or_else(|e| panic!("{e}"));
    let expected: [(&str, &str, Option<i64>, [&str; 3]); 8] = [
        (
            "circuit_toy_macro",
            "CircuitTraining-ToyMacro-v0",
            None,
            ["bc", "ddqn", "ppo"],
        ),
        (
            "circuit_ariane",
            "CircuitTraining-Ariane-v0",
            None,
            ["bc", "ddqn", "ppo"],
        ),
        (
            "locomotion_dog_pace",
            "QuadrupedLocomotion-DogPace-v0",
            None,
            ["bc", "ppo", "sac"],
        ),
        (
            "locomotion_dog_trot",
            "QuadrupedLocomotion-DogTrot-v0",
            None,
            ["bc", "ppo", "sac"],
        ),
        (
            "locomotion_dog_spin",
            "QuadrupedLocomotion-DogSpin-v0",
            None,
            ["bc", "ppo", "sac"],
        ),
        (
            "web_difficulty_1_websites_1",
            "WebNavigation-Difficulty-01-v0",
            Some(1),
            ["bc", "ddqn", "ppo"],
        ),
        (
            "web_difficulty_1_websites_5",
            "WebNavigation-Difficulty-01-v0",
            Some(5),
            ["bc", "ddqn", "ppo"],
        ),
        (
            "web_difficulty_1_websites_10",
            "WebNavigation-Difficulty-01-v0",
            Some(10),
            ["bc", "ddqn", "ppo"],
        ),
    ];
    assert_eq!(tables.tasks.len(), 8);
    let registry = a2perf_pipeline::registry::full_registry();
    for ((id, env_id, websites, algos), task) in expected.iter().zip(&tables.tasks) {
        assert_eq!((task.id.as_str(), task.env_id.as_str()), (*id, *env_id));
        // Every task names a registered environment of its domain.
        assert_eq!(registry.env(env_id).unwrap().domain, task.domain);
        assert_eq!(
            task.params.get("num_websites").and_then(Value::as_i64),
            *websites
        );
        assert_eq!(
            task.algorithms
                .keys()
                .map(String::as_str)
                .collect::<Vec<_>>(),
            algos
        );
        assert!(task.table.as_deref().is_some_and(|t| t.starts_with("tab:")));
        for (algo, metrics) in &task.algorithms {
            // The paper prints no generalization row for 10 websites and no training mean RAM
            // for the toy macro; every table has the rest.
            let mut rows = vec![
                ("returns", "100 eps."),
                ("training_sample_cost", "kWh"),
                ("energy", "kWh"),
                ("peak_ram", "GB"),
                ("wall_clock", "Hours"),
                ("inference_time", "ms"),
                ("inference_peak_ram", "GB"),
                ("risk_across_rollouts", "CVaR"),
            ];
            if *id != "web_difficulty_1_websites_10" {
                rows.push(("generalization", "100 eps. [all tasks]"));
            }
            if *id != "circuit_toy_macro" {
                rows.push(("mean_ram", "GB"));
            }
            for (key, unit) in rows {
                let v = metrics
                    .get(key)
                    .unwrap_or_else(|| panic!("{id}/{algo}: no {key}"));
                assert_eq!(v.unit, unit, "{id}/{algo}/{key}");
                assert!(v.mean.is_some(), "{id}/{algo}/{key}");
            }
            for (key, v) in metrics {
                // Every cell names its table and row and keeps the paper's name and phase; a
                // missing figure is the paper's N/A, with the reason.
                assert!(v.source.is_some(), "{id}/{algo}/{key}");
                assert!(
                    v.paper_metric.is_some() && v.phase.is_some(),
                    "{id}/{algo}/{key}"
                );
                assert!(
                    v.mean.is_some() || v.note.as_deref().is_some_and(|n| n.starts_with("N/A"))
                );
            }
        }
    }
    // Runs find their table by environment and parameters (numbers by value).
    let params = |n: Value| {
        BTreeMap::from([
            ("num_websites".to_string(), n),
            ("seed".to_string(), Value::Int(0)),
        ])
    };
    let web = "WebNavigation-Difficulty-01-v0";
    assert_eq!(
        tables.matching(web, &params(Value::Int(5))).unwrap().id,
        "web_difficulty_1_websites_5"
    );
    assert_eq!(
        tables
            .matching(web, &params(Value::Float(10.0)))
            .unwrap()
            .id,
        "web_difficulty_1_websites_10"
    );
    assert!(tables.matching(web, &params(Value::Int(3))).is_none());
    assert!(
        tables
            .matching("WebNavigation-Difficulty-02-v0", &params(Value::Int(5)))
            .is_none()
    );
    assert_eq!(
        tables
            .matching("CircuitTraining-Ariane-v0", &BTreeMap::new())
            .unwrap()
            .id,
        "circuit_ariane"
    );
}

#[test]
fn a_paper_style_profile_gives_every_domain_its_suite_and_switches() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    write(
        d,
        "profile.ron",
        r#"(profile: (
            name: "a2perf",
            env: {"circuit_training": (infeasible_reward: -1.0, padded_action: true)},
            generalization: {
                "circuit_training": [
                    (env: "CircuitTraining-ToyMacro-v0", name: "toy_macro_stdcell",
                     params: (netlist_file: "/data/toy_macro_stdcell/netlist.pb.txt")),
                    (env: "CircuitTraining-Ariane-v0", name: "ariane",
                     params: (netlist_file: "/data/ariane/netlist.pb.txt")),
                ],
                "web_navigation": [
                    (env: "WebNavigation-Difficulty-01-v0", name: "difficulty_level_1_num_websites_1", params: (num_websites: 1)),
                    (env: "WebNavigation-Difficulty-01-v0", name: "difficulty_level_1_num_websites_5", params: (num_websites: 5)),
                    (env: "WebNavigation-Difficulty-01-v0", name: "difficulty_level_1_num_websites_10", params: (num_websites: 10)),
                ],
                "quadruped_locomotion": [
                    (env: "QuadrupedLocomotion-DogPace-v0", name: "dog_pace"),
                    (env: "QuadrupedLocomotion-DogTrot-v0", name: "dog_trot"),
                    (env: "QuadrupedLocomotion-DogSpin-v0", name: "dog_spin"),
                ],
            },
        ))"#,
    );
    let exp = |name: &str, env: &str, algo: &str| {
        write(
            d,
            &format!("{name}.ron"),
            &format!(
                r#"(include: ["profile.ron"], name: "{name}", env: {env}, algorithm: (name: "{algo}"))"#
            ),
        )
    };
    let circuit = exp(
        "circuit",
        r#"(id: "CircuitTraining-ToyMacro-v0", netlist_file: "/data/toy_macro_stdcell/netlist.pb.txt")"#,
        "ppo",
    );
    let web = exp(
        "web",
        r#"(id: "WebNavigation-Difficulty-01-v0", num_websites: 5)"#,
        "ddqn",
    );
    let locomotion = exp(
        "locomotion",
        r#"(id: "QuadrupedLocomotion-DogPace-v0")"#,
        "sac",
    );
    let reg = a2perf_pipeline::registry::full_registry();
    let all = plans(&[circuit, web, locomotion], &[], &reg);
    let suite_of = |p: &ExperimentPlan| {
        let s = p.generalization.suite.as_ref().unwrap();
        assert_eq!(s.source, SuiteSource::Profile, "{}", p.name);
        s.tasks.clone()
    };

    let circuit = &all[0];
    assert_eq!(
        circuit.task.name,
        "CircuitTraining-ToyMacro-v0[profile=a2perf,netlist_file=\"/data/toy_macro_stdcell/netlist.pb.txt\"]"
    );
    let profile = circuit.task.profile.as_ref().unwrap();
    assert_eq!(
        profile
            .in_force()
            .map(ToString::to_string)
            .collect::<Vec<_>>(),
        ["env.infeasible_reward = -1.0", "env.padded_action = true"]
    );
    assert_eq!(
        circuit.task.env_params["infeasible_reward"],
        Value::Float(-1.0)
    );
    let tasks = suite_of(circuit);
    assert_eq!(
        tasks.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(),
        ["toy_macro_stdcell", "ariane"]
    );
    for t in &tasks {
        // The suite runs under the profile's switches too.
        assert_eq!(
            t.params["infeasible_reward"],
            Value::Float(-1.0),
            "{}",
            t.name
        );
        assert_eq!(t.params["padded_action"], Value::Bool(true), "{}", t.name);
    }
    assert_eq!(
        tasks[1].params["netlist_file"],
        Value::Str("/data/ariane/netlist.pb.txt".into())
    );

    let web = &all[1];
    assert_eq!(
        web.task.name,
        "WebNavigation-Difficulty-01-v0[profile=a2perf,num_websites=5]"
    );
    assert!(web.task.profile.as_ref().unwrap().switches.is_empty());
    let tasks = suite_of(web);
    assert_eq!(
        tasks
            .iter()
            .map(|t| t.params["num_websites"].clone())
            .collect::<Vec<_>>(),
        [Value::Int(1), Value::Int(5), Value::Int(10)]
    );

    let tasks = suite_of(&all[2]);
    assert_eq!(
        tasks.iter().map(|t| t.env_id.as_str()).collect::<Vec<_>>(),
        [
            "QuadrupedLocomotion-DogPace-v0",
            "QuadrupedLocomotion-DogTrot-v0",
            "QuadrupedLocomotion-DogSpin-v0"
        ]
    );

    // Without the profile the domain's registered suite applies.
    let bare = write(
        d,
        "bare.ron",
        r#"(env: (id: "CircuitTraining-Synthetic-Small-v0"), algorithm: (name: "ppo"))"#,
    );
    let bare = &plans(&[bare], &[], &reg)[0];
    let suite = bare.generalization.suite.as_ref().unwrap();
    assert_eq!(suite.source, SuiteSource::Registry);
    assert_eq!(
        suite.tasks.len(),
        reg.generalization("circuit_training").len()
    );
    assert!(bare.task.profile.is_none());
}
