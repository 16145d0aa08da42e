//! Shared fixtures of the pipeline tests: a registry with the example crate's corridor and
//! random-search algorithm, a toy offline learner, and a meter test double.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use a2perf_core::{
    ActMode, Action, Algorithm, AlgorithmEntry, Checkpoint, Measurement, Meter, MeterError,
    MeterReport, Observation, ParamKind, ParamSpec, Params, Policy, PolicyError, Registry,
    RunError, TrainingContext, TrainingSettings, Value,
};
use a2perf_pipeline::{AlgorithmSpec, ExperimentPlan, TaskSpec, train::MeterFactory, train::Phase};

/// The example crate's environment and algorithm plus `toy_bc`.
pub fn registry() -> Registry {
    let mut reg = Registry::new();
    a2perf_example_custom::register(&mut reg);
    reg.register_algorithm(AlgorithmEntry {
        name: "toy_bc".into(),
        summary: "test: majority action per observation bucket from a samples.json".into(),
        params: vec![ParamSpec::new(
            "dataset",
            ParamKind::Path,
            Value::Null,
            "samples.json",
        )],
        make: Arc::new(|p: &Params| {
            let path = p
                .opt_str("dataset")
                .ok()
                .flatten()
                .ok_or_else(|| RunError::InvalidHyperparameter {
                    name: "dataset".into(),
                    reason: "required".into(),
                })?
                .to_string();
            Ok(Box::new(ToyBc { path }) as Box<dyn Algorithm>)
        }),
        load_policy: load_table,
    });
    reg
}

/// Writes `text` to `dir/name`.
pub fn write(dir: &Path, name: &str, text: &str) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A suite file in `dir` whose experiments are `entries` (`(config: …)` items) over
/// `online.ron` (random search on the corridor, seeds 0 and 1, tiny budgets) and `offline.ron`
/// (the same with `toy_bc`, for an entry with a `dataset` step); results go to `dir/results`.
pub fn dataset_suite(dir: &Path, entries: &[&str]) -> std::path::PathBuf {
    write(
        dir,
        "online.ron",
        r#"(env: (id: "Corridor-v0"), algorithm: (name: "random_search"), seeds: [0, 1],
            training: (total_env_steps: 600, eval_interval: 200, eval_episodes: 2,
                       checkpoint_interval: 200),
            inference: (rollouts: 3, timing_samples: 5), generalization: (episodes: 2))"#,
    );
    write(
        dir,
        "offline.ron",
        r#"(include: ["online.ron"], name: "offline", algorithm: (name: "toy_bc"))"#,
    );
    let out = dir.join("results").display().to_string();
    write(
        dir,
        "suite.ron",
        &format!(
            r#"(name: "s", set: ["output.dir={out}"], experiments: [{}])"#,
            entries.join(",\n")
        ),
    )
}

/// [`plan`], trained to the end with the default options.
pub fn trained_plan(reg: &Registry, out: &Path, name: &str, seeds: Vec<u64>) -> ExperimentPlan {
    let plan = plan(out, name, seeds);
    a2perf_pipeline::train(
        reg,
        &a2perf_pipeline::grid(std::slice::from_ref(&plan), None),
        &a2perf_pipeline::TrainOptions::default(),
    )
    .unwrap();
    plan
}

/// A small plan on the corridor.
pub fn plan(out: &Path, name: &str, seeds: Vec<u64>) -> ExperimentPlan {
    ExperimentPlan::new(
        name,
        out,
        TaskSpec {
            name: "Corridor-v0".into(),
            env_id: "Corridor-v0".into(),
            env_params: BTreeMap::new(),
            profile: None,
        },
        AlgorithmSpec {
            name: "random_search".into(),
            params: BTreeMap::new(),
        },
        seeds,
        TrainingSettings {
            total_env_steps: 1_200,
            eval_interval: 100,
            eval_episodes: 3,
            checkpoint_interval: 300,
            num_envs: 1,
        },
    )
}

/// Test double of a power meter: a constant 10 W over the measured wall-clock time, reported
/// as an estimate, plus a RAM figure. It exercises the plumbing, not the measurement.
pub struct ConstantPower {
    started: Option<Instant>,
}

impl Meter for ConstantPower {
    fn name(&self) -> &str {
        "constant_power"
    }
    fn start(&mut self) -> Result<(), MeterError> {
        self.started = Some(Instant::now());
        Ok(())
    }
    fn finish(&mut self) -> Result<MeterReport, MeterError> {
        let t = self
            .started
            .ok_or_else(|| MeterError::NotStarted("constant_power".into()))?
            .elapsed()
            .as_secs_f64();
        let how = "test double: 10 W constant";
        Ok(MeterReport {
            measurements: vec![
                Measurement::estimated("energy_total_kwh", 10.0 * t / 3.6e6, "kWh", how),
                Measurement::absent("gpu_power_w", "W", "test double: no GPU"),
                Measurement::measured("mean_ram_gb", 0.1, "GB"),
                Measurement::measured("peak_ram_gb", 0.2, "GB"),
            ],
        })
    }
}

/// Meters for tests.
pub fn test_meters() -> MeterFactory {
    Arc::new(|_phase: Phase, _dir: &Path, _s: &_| {
        vec![Box::new(ConstantPower { started: None }) as Box<dyn Meter>]
    })
}

/// Offline learner for tests: the majority action of the dataset per observation bucket.
struct ToyBc {
    path: String,
}

#[derive(serde::Serialize, serde::Deserialize, Clone)]
struct Table {
    buckets: Vec<usize>,
}

impl Policy for Table {
    fn act(&mut self, obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        let x = obs.flat_values().first().copied().unwrap_or(0.0);
        let b = ((x * 16.0) as usize).min(self.buckets.len() - 1);
        Ok(Action::Discrete(self.buckets[b]))
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: "toy_bc".into(),
            format_version: 1,
            payload: serde_json::to_vec(self)
                .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?,
        })
    }
}

fn load_table(
    c: &Checkpoint,
    _spec: &a2perf_core::EnvSpec,
) -> Result<Box<dyn Policy>, PolicyError> {
    let t: Table = serde_json::from_slice(&c.payload)
        .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?;
    Ok(Box::new(t))
}

#[derive(serde::Deserialize)]
struct Samples {
    samples: Vec<Sample>,
}
#[derive(serde::Deserialize)]
struct Sample {
    observation: Observation,
    action: Action,
}

impl Algorithm for ToyBc {
    fn name(&self) -> &str {
        "toy_bc"
    }
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        let bytes = std::fs::read(&self.path)?;
        let data: Samples =
            serde_json::from_slice(&bytes).map_err(|e| RunError::Unsupported(e.to_string()))?;
        let mut votes = vec![[0usize; 2]; 17];
        for s in &data.samples {
            let x = s.observation.flat_values()[0];
            if let Action::Discrete(a) = s.action {
                votes[((x * 16.0) as usize).min(16)][a.min(1)] += 1;
            }
        }
        let mut table = Table {
            buckets: votes.iter().map(|v| usize::from(v[1] >= v[0])).collect(),
        };
        // Offline: "steps" count dataset passes; progress is reported so the curve has points.
        let steps = ctx.settings().total_env_steps;
        for i in 1..4 {
            ctx.progress(i * steps / 4, &mut table)?;
        }
        ctx.finish(steps, &mut table)?;
        Ok(Box::new(table))
    }
}
