//! Synthetic results trees for the report page's tests: complete run directories written from
//! the pipeline's own types, with values drawn from seeded streams, so that any number of tasks,
//! algorithms and seeds can be reported without training. Used by the pipeline's report-page
//! tests and (through `#[path]`) by the CLI's.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_core::{
    CurvePoint, LearningCurve, Measurement, MeterReport, Provenance, RngStream, RunDir, RunState,
    TrainingSettings,
};
use a2perf_pipeline::generalize::TaskResult;
use a2perf_pipeline::report::Report;
use a2perf_pipeline::stats::Summary;
use a2perf_pipeline::train::PhaseSystem;
use a2perf_pipeline::{
    AlgorithmSpec, GeneralizationResults, GeneralizationSettings, InferenceResults,
    InferenceSettings, MetricSettings, ObservationSource, RunRecord, TaskSpec,
};

/// A task of a synthetic tree.
#[derive(Clone, Debug)]
pub struct SynthTask {
    /// Task name (the report's table).
    pub name: String,
    /// Environment id.
    pub env_id: String,
    /// Domain.
    pub domain: String,
}

/// One run to write.
#[derive(Clone, Debug)]
pub struct SynthRun {
    /// Experiment name (a directory under the root).
    pub experiment: String,
    /// The task.
    pub task: SynthTask,
    /// Algorithm name.
    pub algorithm: String,
    /// Seed.
    pub seed: u64,
    /// Evaluation points of the curve.
    pub curve_points: usize,
    /// How the training energy was obtained (written as the meter's estimate note).
    pub energy_note: String,
    /// Parameters recorded in `env_params` (e.g. a name that must be escaped).
    pub env_params: BTreeMap<String, a2perf_core::Value>,
}

impl SynthRun {
    /// A run with plain names and 50 curve points.
    pub fn new(experiment: &str, task: &SynthTask, algorithm: &str, seed: u64) -> Self {
        Self {
            experiment: experiment.into(),
            task: task.clone(),
            algorithm: algorithm.into(),
            seed,
            curve_points: 50,
            energy_note: "TDP × utilisation".into(),
            env_params: BTreeMap::new(),
        }
    }

    /// Its directory below `root`.
    pub fn dir(&self, root: &Path) -> PathBuf {
        root.join(&self.experiment).join(format!(
            "{}__{}__seed{}",
            a2perf_pipeline::plan::path_safe(&self.task.name),
            a2perf_pipeline::plan::path_safe(&self.algorithm),
            self.seed
        ))
    }

    /// Writes the run, complete (trained, inferred, generalized), below `root`; returns its
    /// directory.
    pub fn write(&self, root: &Path) -> PathBuf {
        let dir = self.dir(root);
        std::fs::create_dir_all(&dir).unwrap();
        let mut rng = RngStream::new(
            self.seed,
            &format!("synthetic/{}/{}", self.task.name, self.algorithm),
        );
        // Algorithms differ in level so that sorting has something to sort.
        let level = self.algorithm.bytes().map(f64::from).sum::<f64>() % 97.0;
        let record = RunRecord {
            format_version: a2perf_pipeline::RUN_FORMAT_VERSION,
            experiment: self.experiment.clone(),
            task: TaskSpec {
                name: self.task.name.clone(),
                env_id: self.task.env_id.clone(),
                env_params: self.env_params.clone(),
                profile: None,
            },
            domain: self.task.domain.clone(),
            algorithm: AlgorithmSpec {
                name: self.algorithm.clone(),
                params: BTreeMap::new(),
            },
            seed: self.seed,
            training: TrainingSettings {
                total_env_steps: 1000 * self.curve_points as u64,
                eval_interval: 1000,
                eval_episodes: 5,
                checkpoint_interval: 0,
                num_envs: 1,
            },
            inference: InferenceSettings {
                episodes: 20,
                timing_samples: 100,
                observation_source: ObservationSource::Rollouts,
            },
            generalization: GeneralizationSettings {
                episodes: 5,
                suite: None,
            },
            metrics: MetricSettings::default(),
            env_metadata: BTreeMap::new(),
            dataset: None,
            external: None,
        };
        a2perf_core::write_json_atomic(&dir.join("run.json"), &record).unwrap();
        let points: Vec<CurvePoint> = (1..=self.curve_points)
            .map(|i| {
                let t = i as f64 / self.curve_points as f64;
                CurvePoint {
                    env_steps: 1000 * i as u64,
                    mean_return: level * t + rng.range(-3.0, 3.0),
                    std_return: 1.0,
                    wall_seconds: i as f64,
                }
            })
            .collect();
        let mut csv = String::from("env_steps,mean_return\n");
        for p in &points {
            csv.push_str(&format!("{},{}\n", p.env_steps, p.mean_return));
        }
        std::fs::write(dir.join("curve.csv"), csv).unwrap();
        a2perf_core::write_json_atomic(&dir.join("curve.json"), &LearningCurve { points }).unwrap();
        std::fs::write(
            dir.join("operative_config.ron"),
            format!("(name: {:?}, seeds: [{}])\n", self.experiment, self.seed),
        )
        .unwrap();
        let system = |energy: f64, ram: f64, wall: f64, note: &str| PhaseSystem {
            wall_clock_s: wall,
            concurrent_runs: 1,
            pid: None,
            meters: MeterReport {
                measurements: vec![
                    Measurement {
                        name: "energy_kwh".into(),
                        value: Some(energy),
                        unit: "kWh".into(),
                        provenance: Provenance::Estimated(note.into()),
                    },
                    Measurement::measured("peak_ram_gb", ram, "GB"),
                    Measurement::measured("mean_ram_gb", ram * 0.8, "GB"),
                ],
            },
            meter_errors: Vec::new(),
            segments: 1,
            note: None,
        };
        a2perf_core::write_json_atomic(
            &dir.join("train_system.json"),
            &system(
                rng.range(0.01, 0.5),
                rng.range(0.2, 2.0),
                rng.range(600.0, 7200.0),
                &self.energy_note,
            ),
        )
        .unwrap();
        let returns: Vec<f64> = (0..20).map(|_| level + rng.range(-5.0, 5.0)).collect();
        let base_ms = 0.05 + level / 200.0;
        let times: Vec<f64> = (0..100)
            .map(|_| base_ms * (1.0 + rng.uniform().powi(4) * 30.0))
            .collect();
        let inference = InferenceResults {
            episodes: returns.len(),
            returns: Summary::of(&returns),
            rollout_returns: returns,
            episode_lengths: vec![100; 20],
            inference_time_ms: Summary::of(&times),
            observation_source: ObservationSource::Rollouts,
            rollout_call_time_ms: Summary::of(&times),
            random_observation_time_ms: None,
            random_observation_failures: 0,
            system: system(1e-5, 0.3, 20.0, "TDP × utilisation"),
        };
        a2perf_core::write_json_atomic(&dir.join("inference.json"), &inference).unwrap();
        let gen_tasks: Vec<TaskResult> = (0..3)
            .map(|k| {
                let r: Vec<f64> = (0..5).map(|_| level / 3.0 + rng.range(-2.0, 2.0)).collect();
                TaskResult {
                    name: format!("variant_{k}"),
                    env_id: self.task.env_id.clone(),
                    params: BTreeMap::new(),
                    mean_return: Some(r.iter().sum::<f64>() / r.len() as f64),
                    returns: r,
                    error: None,
                }
            })
            .collect();
        let generalization = GeneralizationResults {
            domain: self.task.domain.clone(),
            source: None,
            episodes: 5,
            sum_of_mean_returns: Some(gen_tasks.iter().filter_map(|t| t.mean_return).sum()),
            tasks: gen_tasks,
        };
        a2perf_core::write_json_atomic(&dir.join("generalization.json"), &generalization).unwrap();
        RunDir::new(&dir)
            .set_status(RunState::Complete, "")
            .unwrap();
        dir
    }
}

/// A run directory whose training failed with `note` (the report lists it as left out).
pub fn write_failed_run(run: &SynthRun, root: &Path, note: &str) -> PathBuf {
    let dir = run.write(root);
    RunDir::new(&dir)
        .set_status(RunState::Failed, note)
        .unwrap();
    dir
}

/// `tasks` × `algorithms` × `seeds` complete runs below `root`, one experiment per
/// (task, algorithm).
pub fn write_tree(
    root: &Path,
    tasks: &[SynthTask],
    algorithms: &[&str],
    seeds: u64,
    curve_points: usize,
) {
    for (ti, task) in tasks.iter().enumerate() {
        for algo in algorithms {
            for seed in 0..seeds {
                let mut run = SynthRun::new(&format!("exp{ti}_{algo}"), task, algo, seed);
                run.curve_points = curve_points;
                run.write(root);
            }
        }
    }
}

/// `n` tasks over the three domains.
pub fn tasks(n: usize) -> Vec<SynthTask> {
    let domains = [
        ("circuit_training", "CircuitTraining-Ariane-v0"),
        ("web_navigation", "WebNavigation-Difficulty-01-v0"),
        ("quadruped_locomotion", "QuadrupedLocomotion-DogPace-v0"),
    ];
    (0..n)
        .map(|i| {
            let (domain, env_id) = domains[i % domains.len()];
            SynthTask {
                name: format!("{env_id}[variant={i}]"),
                env_id: env_id.into(),
                domain: domain.into(),
            }
        })
        .collect()
}

/// A `tables.json` with a paper entry for `algorithms` on the first task's environment:
/// returns, generalization and training energy and peak RAM.
pub fn paper_tables(env_id: &str, algorithms: &[&str]) -> String {
    let algos: Vec<String> = algorithms
        .iter()
        .enumerate()
        .map(|(i, a)| {
            format!(
                r#""{a}": {{
                  "returns": {{"mean": {}, "std": 4.0, "unit": "100 eps.", "source": "Table 9, row 'Returns'"}},
                  "generalization": {{"mean": {}, "std": null, "unit": "100 eps.", "source": "Table 9, row 'Generalization'"}},
                  "energy": {{"mean": 0.2, "std": 0.01, "unit": "kWh", "source": "Table 9, row 'Energy'"}},
                  "peak_ram": {{"mean": 1.5, "std": 0.1, "unit": "GiB", "source": "Table 9, row 'Peak RAM'"}}
                }}"#,
                30.0 + 20.0 * i as f64,
                10.0 + 5.0 * i as f64
            )
        })
        .collect();
    format!(
        r#"{{"schema": "a2perf-paper-tables/1",
            "paper": {{"title": "A2Perf", "version": "arXiv 2503.03056v1"}},
            "tasks": [{{"id": "synthetic", "title": "Synthetic task", "domain": "d",
                        "table": "Table 9", "env_id": "{env_id}", "params": {{}},
                        "algorithms": {{ {} }} }}]}}"#,
        algos.join(",\n")
    )
}

/// How many return and generalization cells of `report`'s paper columns carry a verdict (the
/// paper comparison computes them; the page's tests need some of each kind to render).
pub fn count_verdicts(report: &Report) -> usize {
    report
        .paper
        .iter()
        .flat_map(|p| &p.columns)
        .flat_map(|c| &c.cells)
        .filter(|c| c.verdict.is_some())
        .count()
}
