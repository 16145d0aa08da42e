//! `configs/paper/`: the A2Perf-compatible profile, the paper's eight tasks × three algorithms and
//! the paper suites. Every file loads and plans; the profile turns on every switch docs/differences.md's
//! tables name (read from that file itself, so a switch
//! added to the table without the profile fails here); the profile's generalization lists are the
//! paper's; the suites plan 8 × 3 experiments × 3 seeds with every BC dataset collected inside
//! the suite.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::{Experiment, Registry, Value};
use a2perf_pipeline::load_plans;
use a2perf_pipeline::plan::{ExperimentPlan, SuiteSource};
use a2perf_pipeline::registry::full_registry;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The paper's tasks: (domain directory, task directory, environment id, `num_websites`).
const TASKS: [(&str, &str, &str, Option<i64>); 8] = [
    (
        "circuit_training",
        "toy_macro_stdcell",
        "CircuitTraining-ToyMacro-v0",
        None,
    ),
    (
        "circuit_training",
        "ariane",
        "CircuitTraining-Ariane-v0",
        None,
    ),
    (
        "quadruped_locomotion",
        "dog_pace",
        "QuadrupedLocomotion-DogPace-v0",
        None,
    ),
    (
        "quadruped_locomotion",
        "dog_trot",
        "QuadrupedLocomotion-DogTrot-v0",
        None,
    ),
    (
        "quadruped_locomotion",
        "dog_spin",
        "QuadrupedLocomotion-DogSpin-v0",
        None,
    ),
    (
        "web_navigation",
        "difficulty_level_1_num_websites_1",
        "WebNavigation-Difficulty-01-v0",
        Some(1),
    ),
    (
        "web_navigation",
        "difficulty_level_1_num_websites_5",
        "WebNavigation-Difficulty-01-v0",
        Some(5),
    ),
    (
        "web_navigation",
        "difficulty_level_1_num_websites_10",
        "WebNavigation-Difficulty-01-v0",
        Some(10),
    ),
];

/// The paper's algorithms per domain.
fn algorithms(domain: &str) -> [&'static str; 3] {
    match domain {
        "quadruped_locomotion" => ["bc", "ppo", "sac"],
        _ => ["bc", "ddqn", "ppo"],
    }
}

/// The paper's generalization lists (A2Perf's generalization.gin files), per domain.
fn paper_generalization(domain: &str) -> Vec<&'static str> {
    match domain {
        "circuit_training" => vec!["toy_macro_stdcell", "ariane"],
        "quadruped_locomotion" => vec!["dog_pace", "dog_trot", "dog_spin"],
        _ => vec![
            "difficulty_level_1_num_websites_1",
            "difficulty_level_1_num_websites_5",
            "difficulty_level_1_num_websites_10",
        ],
    }
}

fn plan_of(file: &Path, registry: &Registry) -> ExperimentPlan {
    let mut loaded = load_plans(&[file.to_path_buf()], &[], None, registry)
        .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    assert_eq!(loaded.plans.len(), 1, "{}", file.display());
    loaded.plans.remove(0)
}

/// The profile as written in configs/paper/profile.ron.
fn profile(registry: &Registry) -> a2perf_core::config::Profile {
    let file = root().join("configs/paper/profile.ron");
    let none: [&str; 0] = [];
    Experiment::load(&file, &none, registry)
        .unwrap_or_else(|e| panic!("{}: {e}", file.display()))
        .profile
        .expect("profile.ron names a profile")
}

#[test]
fn every_paper_task_config_loads_plans_and_runs_under_the_profile() {
    let registry = full_registry();
    let profile = profile(&registry);
    assert_eq!(profile.name, "a2perf");
    let dir = root().join("configs/paper");
    let mut files = 0;
    for (domain, task, env_id, websites) in TASKS {
        for algo in algorithms(domain) {
            let file = dir.join(domain).join(task).join(format!("{algo}.ron"));
            let plan = plan_of(&file, &registry);
            let short = domain.split('_').next().unwrap_or(domain);
            let short = if short == "quadruped" {
                "locomotion"
            } else {
                short
            };
            assert_eq!(plan.name, format!("paper_{short}_{task}_{algo}"));
            assert_eq!(plan.task.env_id, env_id, "{}", file.display());
            assert_eq!(plan.algorithm.name, algo, "{}", file.display());
            if let Some(n) = websites {
                assert_eq!(plan.task.env_params["num_websites"], Value::Int(n));
            }
            // Every switch the profile gives this environment is recorded and in force, with
            // the profile's value.
            let record = plan.task.profile.as_ref().expect("profile recorded");
            assert_eq!(record.name, "a2perf");
            let expected = profile.switches_for(registry.env(env_id).unwrap());
            assert!(!expected.is_empty(), "{env_id}: the profile sets nothing");
            for (param, value) in &expected {
                let switch = record
                    .switches
                    .iter()
                    .find(|s| &s.param == param)
                    .unwrap_or_else(|| panic!("{}: `{param}` not recorded", file.display()));
                assert_eq!(&switch.value, value, "{}: {param}", file.display());
                assert!(
                    switch.overridden.is_none(),
                    "{}: {param} overridden",
                    file.display()
                );
                assert_eq!(&plan.task.env_params[param], value, "{}", file.display());
            }
            // The paper's generalization list, from the profile, each task under the profile.
            let suite = plan.generalization.suite.as_ref().expect("suite planned");
            assert_eq!(suite.source, SuiteSource::Profile, "{}", file.display());
            let names: Vec<&str> = suite.tasks.iter().map(|t| t.name.as_str()).collect();
            assert_eq!(names, paper_generalization(domain), "{}", file.display());
            for t in &suite.tasks {
                for (param, value) in profile.switches_for(registry.env(&t.env_id).unwrap()) {
                    assert_eq!(t.params[&param], value, "{}: {}", file.display(), t.name);
                }
            }
            // The original harness's settings.
            assert_eq!(plan.inference.episodes, 100);
            assert_eq!(plan.inference.timing_samples, 10_000);
            assert_eq!(plan.generalization.episodes, 100);
            files += 1;
        }
    }
    assert_eq!(files, 24);
    // Nothing else in configs/paper/ but the profile, the suites and these 24.
    let mut all = Vec::new();
    for entry in walk(&dir) {
        all.push(entry.strip_prefix(&dir).unwrap().display().to_string());
    }
    all.retain(|f| f.ends_with(".ron") && f.contains('/'));
    assert_eq!(all.len(), 24, "{all:?}");
}

/// The plans of the suite file `configs/paper/<file>`.
fn suite_plans(file: &str, registry: &Registry) -> Vec<ExperimentPlan> {
    load_plans(
        &[root().join("configs/paper").join(file)],
        &[],
        None,
        registry,
    )
    .unwrap_or_else(|e| panic!("{file}: {e}"))
    .plans
}

fn walk(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}

#[test]
fn the_paper_suites_plan_eight_tasks_three_algorithms_three_seeds_with_their_datasets() {
    let registry = full_registry();
    for suite in ["suite.ron", "suite.long.ron"] {
        let file = root().join("configs/paper").join(suite);
        let loaded = load_plans(std::slice::from_ref(&file), &[], None, &registry)
            .unwrap_or_else(|e| panic!("{suite}: {e}"));
        assert_eq!(loaded.plans.len(), 24, "{suite}");
        let mut per_task: BTreeMap<String, Vec<&ExperimentPlan>> = BTreeMap::new();
        for plan in &loaded.plans {
            assert_eq!(plan.seeds, [0, 1, 2], "{suite}: {}", plan.name);
            assert_eq!(
                plan.task.profile.as_ref().map(|p| p.name.as_str()),
                Some("a2perf"),
                "{suite}: {}",
                plan.name
            );
            per_task
                .entry(plan.task.name.clone())
                .or_default()
                .push(plan);
        }
        assert_eq!(per_task.len(), 8, "{suite}: {:?}", per_task.keys());
        for (task, plans) in &per_task {
            let mut algos: Vec<&str> = plans.iter().map(|p| p.algorithm.name.as_str()).collect();
            algos.sort();
            assert!(
                algos == ["bc", "ddqn", "ppo"] || algos == ["bc", "ppo", "sac"],
                "{suite}: {task}: {algos:?}"
            );
            // BC's dataset is collected inside the suite from the task's online experiments
            // (both, or the one a suite chose as the demonstrator), all three seeds of each.
            let bc = plans.iter().find(|p| p.algorithm.name == "bc").unwrap();
            let source = bc
                .dataset_from
                .as_ref()
                .unwrap_or_else(|| panic!("{suite}: {task}: BC has no dataset step"));
            let demonstrators: Vec<&&ExperimentPlan> = plans
                .iter()
                .filter(|p| p.algorithm.name != "bc")
                .filter(|p| source.runs.contains(&p.run_dir(p.seeds[0])))
                .collect();
            assert!(!demonstrators.is_empty(), "{suite}: {task}");
            let mut runs = source.runs.clone();
            runs.sort();
            let mut want: Vec<PathBuf> = demonstrators
                .iter()
                .flat_map(|p| p.seeds.iter().map(|s| p.run_dir(*s)))
                .collect();
            want.sort();
            assert_eq!(runs, want, "{suite}: {task}");
            assert_eq!(
                bc.algorithm.params["dataset"],
                Value::Str(source.samples.display().to_string())
            );
            for p in plans.iter().filter(|p| p.algorithm.name != "bc") {
                assert!(p.dataset_from.is_none());
                assert!(
                    p.training.checkpoint_interval > 0
                        && p.training.checkpoint_interval < p.training.total_env_steps,
                    "{suite}: {}: the levels need several checkpoints per run",
                    p.name
                );
            }
        }
    }
    // The long variant trains longer than the short one, experiment by experiment.
    let (short, long) = (
        suite_plans("suite.ron", &registry),
        suite_plans("suite.long.ron", &registry),
    );
    // Both evaluate every run 20 times, so the reliability metrics have curves to work on.
    for p in short.iter().chain(&long) {
        let t = &p.training;
        assert!(
            t.eval_interval > 0 && t.total_env_steps / t.eval_interval >= 20,
            "{}: {} evaluations",
            p.name,
            t.total_env_steps / t.eval_interval.max(1)
        );
    }
    for (s, l) in short.iter().zip(&long) {
        assert_eq!(s.name, l.name);
        assert!(
            l.training.total_env_steps > s.training.total_env_steps,
            "{}: {} vs {}",
            s.name,
            l.training.total_env_steps,
            s.training.total_env_steps
        );
    }
}

/// One row of a differences table (`docs/differences.md`): its domain and the "reproduce the
/// original" cell.
struct Row {
    domain: &'static str,
    what: String,
    reproduce: String,
}

/// The rows of the tables of `docs/differences.md`, "Differences from the original A2Perf".
fn difference_rows() -> Vec<Row> {
    let path = root().join("docs/differences.md");
    let doc = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut domain = None;
    let mut rows = Vec::new();
    for line in doc.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            domain = Some(match h.trim() {
                "Chip placement" => "circuit_training",
                "Quadruped locomotion" => "quadruped_locomotion",
                "Web navigation" => "web_navigation",
                other => panic!("docs/differences.md: unknown section `{other}`"),
            });
            continue;
        }
        if !line.starts_with('|') || line.starts_with("|---") {
            continue;
        }
        let cells: Vec<&str> = line.trim_matches('|').split(" | ").collect();
        if cells[0].trim() == "what" {
            continue;
        }
        rows.push(Row {
            domain: domain.expect("a table row before any domain subsection"),
            what: cells[0].trim().to_string(),
            reproduce: cells.last().unwrap().trim().to_string(),
        });
    }
    rows
}

/// `name = value` switches written in backticks in a "reproduce" cell (`env.` prefix optional).
fn switches_in(cell: &str) -> Vec<(String, String)> {
    cell.split('`')
        .skip(1)
        .step_by(2)
        .filter_map(|code| {
            let (name, value) = code.split_once(" = ")?;
            let name = name.trim().trim_start_matches("env.");
            name.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_')
                .then(|| (name.to_string(), value.trim().replace('−', "-")))
        })
        .collect()
}

/// Switches of the table the profile leaves out on purpose (profile.ron says why, and the
/// differences row says when to set it).
const NOT_IN_PROFILE: [(&str, &str); 1] = [("quadruped_locomotion", "mode")];

#[test]
fn the_profile_turns_on_every_switch_of_the_readme_differences_table() {
    let registry = full_registry();
    let profile = profile(&registry);
    let profile_text = std::fs::read_to_string(root().join("configs/paper/profile.ron")).unwrap();
    let rows = difference_rows();
    assert!(rows.len() >= 30, "only {} differences rows", rows.len());
    let mut checked = 0;
    let mut exceptions_seen = Vec::new();
    for row in &rows {
        let cell = row.reproduce.as_str();
        let lower = cell.to_lowercase();
        let domain_envs: Vec<_> = registry.envs().filter(|e| e.domain == row.domain).collect();
        // Faithful rows (`default; `x = v` gives our earlier behaviour`): the profile pins the
        // default.
        if lower.starts_with("default") {
            for (param, value) in switches_in(cell) {
                for entry in domain_envs
                    .iter()
                    .filter(|e| e.params.iter().any(|p| p.name == param))
                {
                    let spec = entry.params.iter().find(|p| p.name == param).unwrap();
                    assert_ne!(
                        spec.kind.check(&Value::parse_literal(&value)),
                        Ok(spec.default.clone())
                    );
                    assert_eq!(
                        profile.switches_for(entry).get(&param),
                        Some(&spec.default),
                        "differences row `{}`: the profile does not pin `{param}` at its faithful \
                         default for {}",
                        row.what,
                        entry.id
                    );
                }
                checked += 1;
            }
            continue;
        }
        // Rows without a switch (`none`, `—`).
        if lower.starts_with("none") || cell.starts_with('—') {
            continue;
        }
        if lower.contains("generalization suite is configurable")
            || lower.contains("configured suite")
        {
            let names: Vec<&str> = profile.generalization[row.domain]
                .iter()
                .map(|t| t.name.as_str())
                .collect();
            assert_eq!(names, paper_generalization(row.domain), "{}", row.what);
            checked += 1;
        }
        for (param, value) in switches_in(cell) {
            if NOT_IN_PROFILE.contains(&(row.domain, param.as_str())) {
                assert!(
                    profile_text.contains(&format!("`{param} = ")),
                    "profile.ron should say why `{param}` is left out"
                );
                exceptions_seen.push(param);
                continue;
            }
            let declaring: Vec<_> = domain_envs
                .iter()
                .filter(|e| e.params.iter().any(|p| p.name == param))
                .collect();
            assert!(
                !declaring.is_empty(),
                "differences row `{}`: no {} environment has a parameter `{param}`",
                row.what,
                row.domain
            );
            // A path (`<path>`, `.../01.json`): the profile gives every environment that the
            // paper's tasks use one.
            let is_path = value.contains('<') || value.contains("...");
            for entry in declaring {
                let switches = profile.switches_for(entry);
                let paper_env = TASKS.iter().any(|t| t.2 == entry.id)
                    || profile.generalization[row.domain]
                        .iter()
                        .any(|t| t.env_id == entry.id);
                if is_path {
                    if paper_env {
                        assert!(
                            matches!(switches.get(&param), Some(Value::Str(s)) if !s.is_empty()),
                            "differences row `{}`: the profile gives {} no `{param}`",
                            row.what,
                            entry.id
                        );
                    }
                    continue;
                }
                let spec = entry.params.iter().find(|p| p.name == param).unwrap();
                let want = spec
                    .kind
                    .check(&Value::parse_literal(&value))
                    .unwrap_or_else(|e| panic!("differences `{param} = {value}`: {e}"));
                assert_eq!(
                    switches.get(&param),
                    Some(&want),
                    "differences row `{}`: the profile does not set `{param} = {value}` for {}",
                    row.what,
                    entry.id
                );
            }
            checked += 1;
        }
    }
    // The switches known today (a lower bound: the table may grow, and must keep the profile in
    // step): circuit 4 + netlist + 2 pinned defaults, locomotion 1 + motion, web 6 + designs, and
    // the suites.
    assert!(checked >= 19, "only {checked} switches checked");
    for (domain, param) in NOT_IN_PROFILE {
        assert!(
            exceptions_seen.iter().any(|p| p == param),
            "{domain}.{param} is listed as left out of the profile but no differences row names it"
        );
    }
}

#[test]
fn the_readme_table_parser_finds_switches_and_skips_prose() {
    assert_eq!(
        switches_in("`env.infeasible_reward = −1.0`"),
        [("infeasible_reward".to_string(), "-1.0".to_string())]
    );
    assert_eq!(
        switches_in(r#"`pool = "a2perf"`, `designs = "<path>/0N.json"` (no data)"#),
        [
            ("pool".to_string(), "\"a2perf\"".to_string()),
            ("designs".to_string(), "\"<path>/0N.json\"".to_string())
        ]
    );
    assert!(switches_in("`WebNavEnv::a2perf_action` maps one onto the other").is_empty());
    assert!(switches_in("none").is_empty());
}

/// `suite.circuit.ron` re-runs the circuit cells of `suite.ron` after a change to the circuit
/// environment, so its experiments must be `suite.ron`'s circuit experiments exactly: same tasks,
/// algorithms, seeds, budgets, inference, generalization, metrics and dataset steps. Only the
/// output directory differs.
#[test]
fn the_circuit_suite_is_the_paper_suites_circuit_half() {
    let registry = full_registry();
    // Everything a run's results depend on, with the output directory written as `<out>`.
    let key = |p: &ExperimentPlan| {
        let out = p.output.display().to_string();
        format!(
            "{} {:?} {:?} {:?} {:?} {:?} {:?} {:?} {:?}",
            p.name,
            p.task,
            p.algorithm,
            p.seeds,
            p.training,
            p.inference,
            p.generalization,
            p.metrics,
            p.dataset_from
        )
        .replace(&out, "<out>")
    };
    let circuit = suite_plans("suite.circuit.ron", &registry);
    let paper: Vec<ExperimentPlan> = suite_plans("suite.ron", &registry)
        .into_iter()
        .filter(|p| p.task.env_id.starts_with("CircuitTraining"))
        .collect();
    assert_eq!(circuit.len(), 6);
    assert_eq!(paper.len(), 6);
    assert_ne!(circuit[0].output, paper[0].output);
    for (c, p) in circuit.iter().zip(&paper) {
        assert_eq!(key(c), key(p));
    }
}

/// A run's physics engine goes with it to its generalization tasks (`ParamSpec::follows_run`):
/// set on the training task (`--set env.physics=...`), through the profile, or back to the
/// default against a profile switch; a task whose list sets the engine keeps it; and a run on
/// the default engine leaves its tasks' parameters as they were.
#[test]
fn generalization_tasks_follow_the_runs_physics_engine() {
    let registry = full_registry();
    let file = root().join("configs/paper/quadruped_locomotion/dog_pace/sac.ron");
    let engines = |sets: &[&str]| -> Vec<Option<Value>> {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        let mut loaded = load_plans(std::slice::from_ref(&file), &sets, None, &registry).unwrap();
        let plan = loaded.plans.remove(0);
        let suite = plan.generalization.suite.expect("suite planned");
        assert_eq!(suite.tasks.len(), 3);
        suite
            .tasks
            .iter()
            .map(|t| t.params.get("physics").cloned())
            .collect()
    };
    let art = Some(Value::Str("articulated".into()));
    let rapier = Some(Value::Str("rapier".into()));
    assert_eq!(engines(&[]), vec![None, None, None]);
    assert_eq!(
        engines(&["env.physics=\"articulated\""]),
        vec![art.clone(); 3]
    );
    let profile = "profile.env.quadruped_locomotion.physics=\"articulated\"";
    assert_eq!(engines(&[profile]), vec![art.clone(); 3]);
    assert_eq!(
        engines(&[profile, "env.physics=\"rapier\""]),
        vec![rapier.clone(); 3]
    );
    // A suite that lists the engine of a task keeps it.
    let listed = "generalization.tasks=[(env: \"QuadrupedLocomotion-DogPace-v0\", name: \"pace_on_rapier\", params: (physics: \"rapier\")), (env: \"QuadrupedLocomotion-DogTrot-v0\", name: \"trot\"), (env: \"QuadrupedLocomotion-DogSpin-v0\", name: \"spin\")]";
    assert_eq!(
        engines(&[listed, "env.physics=\"articulated\""]),
        vec![rapier, art.clone(), art]
    );
}
