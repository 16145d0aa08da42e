//! What to run: experiments (task × algorithm × seeds), the run grid and its shards.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;

use a2perf_core::{Registry, TrainingSettings, Value};
use serde::{Deserialize, Serialize};

use crate::dataset::{self, CollectOptions, CostRule, DatasetProvenance, Level};
use crate::error::{PipelineError, Result, io_err};
use crate::phase::MetricSettings;
use crate::run_dir::{ExternalAgent, PlannedRun, RUN_FILE, RUN_FORMAT_VERSION, RunRecord};
pub use crate::run_dir::{path_safe, run_dir_name};
pub use crate::spec::{
    AlgorithmSpec, GeneralizationSettings, GeneralizationSuite, GeneralizationTask,
    InferenceSettings, ObservationSource, OperativeWriter, ProfileRecord, ProfileSwitch,
    SuiteSource, TaskSpec,
};

/// One experiment: a task, an algorithm, its seeds and settings.
#[derive(Clone)]
pub struct ExperimentPlan {
    /// Experiment name (the directory under `output`).
    pub name: String,
    /// Output root.
    pub output: PathBuf,
    /// The task.
    pub task: TaskSpec,
    /// The algorithm.
    pub algorithm: AlgorithmSpec,
    /// Seeds, one run each.
    pub seeds: Vec<u64>,
    /// Budgets.
    pub training: TrainingSettings,
    /// Inference settings.
    pub inference: InferenceSettings,
    /// Generalization settings.
    pub generalization: GeneralizationSettings,
    /// Meter and statistics settings.
    pub metrics: MetricSettings,
    /// For offline algorithms: where the dataset came from and its sample cost.
    pub dataset: Option<DatasetProvenance>,
    /// For an offline experiment of a suite whose dataset is collected from other experiments of
    /// the same suite (a suite entry's `dataset`): what to collect, from which runs, and where.
    /// [`crate::run_experiments`] collects it after training those runs.
    pub dataset_from: Option<DatasetSource>,
    /// Writes `operative_config.ron` (absent when the plan was not built from a config file).
    pub operative: Option<OperativeWriter>,
}

impl std::fmt::Debug for ExperimentPlan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExperimentPlan")
            .field("name", &self.name)
            .field("output", &self.output)
            .field("task", &self.task)
            .field("algorithm", &self.algorithm)
            .field("seeds", &self.seeds)
            .field("training", &self.training)
            .finish_non_exhaustive()
    }
}

impl ExperimentPlan {
    /// A plan with default inference and generalization settings.
    pub fn new(
        name: &str,
        output: impl Into<PathBuf>,
        task: TaskSpec,
        algorithm: AlgorithmSpec,
        seeds: Vec<u64>,
        training: TrainingSettings,
    ) -> Self {
        Self {
            name: name.into(),
            output: output.into(),
            task,
            algorithm,
            seeds,
            training,
            inference: InferenceSettings::default(),
            generalization: GeneralizationSettings::default(),
            metrics: MetricSettings::default(),
            dataset: None,
            dataset_from: None,
            operative: None,
        }
    }

    /// `OUTPUT/NAME`.
    pub fn experiment_dir(&self) -> PathBuf {
        self.output.join(&self.name)
    }

    /// Directory of the run with `seed`.
    pub fn run_dir(&self, seed: u64) -> PathBuf {
        self.experiment_dir()
            .join(run_dir_name(&self.task.name, &self.algorithm.name, seed))
    }
}

/// The plan of a loaded experiment config. The task is named after the environment id, with
/// the parameters that differ from the registry's defaults appended (`Id[k=v,...]`), so two
/// experiments on differently parameterised copies of one environment stay apart in reports.
pub fn from_experiment(
    exp: &a2perf_core::Experiment,
    registry: &a2perf_core::Registry,
) -> Result<ExperimentPlan> {
    use a2perf_core::config::ObservationSource as Source;
    let invalid = |e: a2perf_core::ConfigError| PipelineError::Invalid(e.to_string());
    // The name becomes `output.dir/<name>`: refused here, before anything is written.
    check_dir_name("experiment", &exp.name)?;
    let env = exp.require_env().map_err(invalid)?;
    let algo = exp.require_algorithm().map_err(invalid)?;
    let defaults = registry.env_params(&env.id, &BTreeMap::new())?;
    // The profile's switches in force are summed up as `profile=NAME`; parameters that differ
    // from the defaults with the switches applied are listed (an overridden switch too, even
    // when overridden back to the registry's default).
    let mut changed: Vec<String> = exp
        .profile
        .iter()
        .map(|p| format!("profile={}", p.name))
        .collect();
    changed.extend(
        env.params
            .values()
            .iter()
            .filter(|(k, v)| {
                env.profile_switches
                    .get(*k)
                    .or_else(|| defaults.values().get(*k))
                    != Some(*v)
            })
            .map(|(k, v)| format!("{k}={v}")),
    );
    let task_name = if changed.is_empty() {
        env.id.clone()
    } else {
        format!("{}[{}]", env.id, changed.join(","))
    };
    let profile = exp.profile.as_ref().map(|p| ProfileRecord {
        name: p.name.clone(),
        switches: env
            .profile_switches
            .iter()
            .map(|(param, value)| ProfileSwitch {
                param: param.clone(),
                value: value.clone(),
                overridden: env.params.get(param).filter(|v| *v != value).cloned(),
            })
            .collect(),
    });
    let suite = generalization_suite(exp, &env.id, registry)?;
    if exp.seeds.is_empty() {
        return Err(PipelineError::Invalid(format!(
            "experiment {}: no seeds",
            exp.name
        )));
    }
    use a2perf_core::config::{EnergyMethod, ReliabilityDefinition};
    let metrics = MetricSettings {
        ram_sample_interval_s: exp.metrics.ram_sample_interval_s,
        carbon_intensity_g_per_kwh: exp.metrics.carbon_intensity_g_per_kwh,
        energy_method: match exp.metrics.energy_method {
            EnergyMethod::Auto => "auto",
            EnergyMethod::Rapl => "rapl",
            EnergyMethod::Estimate => "estimate",
        }
        .into(),
        reliability_definition: match exp.metrics.reliability_definition {
            ReliabilityDefinition::A2Perf => "a2perf",
            ReliabilityDefinition::Chan2019 => "chan2019",
        }
        .into(),
        bootstrap_reps: exp.metrics.bootstrap_reps,
    };
    let operative = exp.clone();
    let mut plan = ExperimentPlan::new(
        &exp.name,
        exp.output.dir.clone(),
        TaskSpec {
            name: task_name,
            env_id: env.id.clone(),
            env_params: env.params.values().clone(),
            profile,
        },
        AlgorithmSpec {
            name: algo.name.clone(),
            params: algo.params.values().clone(),
        },
        exp.seeds.clone(),
        exp.training.clone(),
    );
    plan.inference = InferenceSettings {
        episodes: exp.inference.rollouts,
        timing_samples: exp.inference.timing_samples,
        observation_source: match exp.inference.observation_source {
            Source::Rollouts => ObservationSource::Rollouts,
            Source::Random => ObservationSource::Random,
        },
    };
    plan.generalization = GeneralizationSettings {
        episodes: exp.generalization.episodes,
        suite,
    };
    plan.metrics = metrics;
    if let Some(path) = algo.params.get("dataset").and_then(Value::as_str) {
        plan.dataset = dataset::dataset_info_for(std::path::Path::new(path))?
            .map(|info| DatasetProvenance::from_info(&info, path));
    }
    plan.operative = Some(Arc::new(move |dir: &std::path::Path| {
        operative
            .write_operative(dir)
            .map(|_| ())
            .map_err(|e| e.to_string())
    }));
    Ok(plan)
}

/// The generalization suite of an experiment on `env_id`: the config's `generalization.tasks`,
/// else its profile's suite for the domain, else the registry's (`None` when the domain has
/// none). A profile's switches are filled into every task's unset parameters, so the suite runs
/// under the same semantics as the training task, and so is the run's value of every simulator
/// setting (`ParamSpec::follows_run`, e.g. locomotion's physics engine) the list leaves unset.
pub fn generalization_suite(
    exp: &a2perf_core::Experiment,
    env_id: &str,
    registry: &a2perf_core::Registry,
) -> Result<Option<GeneralizationSuite>> {
    let domain = &registry.env(env_id)?.domain;
    let (source, tasks) = if let Some(tasks) = &exp.generalization.tasks {
        (SuiteSource::Config, tasks.as_slice())
    } else if let Some(tasks) = exp
        .profile
        .as_ref()
        .and_then(|p| p.generalization.get(domain))
    {
        (SuiteSource::Profile, tasks.as_slice())
    } else {
        (SuiteSource::Registry, registry.generalization(domain))
    };
    if tasks.is_empty() {
        return Ok(None);
    }
    let run = exp.env.as_ref().map(|e| e.params.values());
    let tasks = tasks
        .iter()
        .map(|t| {
            let mut task = match &exp.profile {
                Some(p) => GeneralizationTask::from(&p.apply_to_task(t, registry)),
                None => GeneralizationTask::from(t),
            };
            if let Some(run) = run {
                follow_run_settings(&mut task, &t.params, run, registry);
            }
            task
        })
        .collect();
    Ok(Some(GeneralizationSuite { source, tasks }))
}

/// Gives `task` the run's value of each simulator setting
/// ([`a2perf_core::ParamSpec::follows_run`]) its environment declares, where the task's value
/// (a profile switch or the default) differs and the suite's list (`listed`) does not set it:
/// a policy trained on one physics engine is generalized on the same one.
fn follow_run_settings(
    task: &mut GeneralizationTask,
    listed: &BTreeMap<String, Value>,
    run: &BTreeMap<String, Value>,
    registry: &a2perf_core::Registry,
) {
    let Ok(entry) = registry.env(&task.env_id) else {
        return;
    };
    for spec in entry.params.iter().filter(|s| s.follows_run) {
        let Some(value) = run.get(spec.name) else {
            continue;
        };
        let current = task.params.get(spec.name).unwrap_or(&spec.default);
        if current != value && !listed.contains_key(spec.name) {
            task.params.insert(spec.name.to_string(), value.clone());
        }
    }
}

/// Checks a name that becomes a directory (an experiment, a suite): letters, digits, `-`, `_`
/// and `.` only, not starting with `.`, so that it can neither leave the output directory
/// (`../x`, `a/b`) nor hide in it. `what` names the kind of name in the error.
///
/// ```
/// use a2perf_pipeline::check_dir_name;
/// assert!(check_dir_name("experiment", "web_ppo-2.1").is_ok());
/// let err = check_dir_name("experiment", "../escaped").unwrap_err().to_string();
/// assert!(err.contains("experiment `../escaped`: use letters, digits"), "{err}");
/// assert!(check_dir_name("suite", ".hidden").is_err());
/// assert!(check_dir_name("suite", "").is_err());
/// ```
pub fn check_dir_name(what: &str, name: &str) -> Result<()> {
    if name.is_empty() || path_safe(name) != name || name.starts_with('.') {
        return Err(PipelineError::Invalid(format!(
            "{what} `{name}`: use letters, digits, `-`, `_` and `.` only (it names a \
             directory), not starting with `.`"
        )));
    }
    Ok(())
}

/// One cell of the grid: an experiment and one of its seeds.
#[derive(Clone, Debug)]
pub struct RunJob {
    /// Position in the full grid (what shards split on).
    pub index: usize,
    /// The experiment.
    pub plan: ExperimentPlan,
    /// The seed.
    pub seed: u64,
}

/// The full seed × task grid, in a deterministic order (experiments in the order given, then
/// seeds), optionally restricted to one shard.
///
/// ```
/// use a2perf_pipeline::{grid, AlgorithmSpec, ExperimentPlan, Shard, TaskSpec};
/// let task = TaskSpec { name: "t".into(), env_id: "T-v0".into(), env_params: Default::default(), profile: None };
/// let algo = AlgorithmSpec { name: "a".into(), params: Default::default() };
/// let plan = ExperimentPlan::new("e", "/tmp/out", task, algo, vec![0, 1, 2], Default::default());
/// assert_eq!(grid(&[plan.clone()], None).len(), 3);
/// let shard = Shard::new(1, 2).unwrap();
/// let jobs = grid(&[plan], Some(shard));
/// assert_eq!(jobs.iter().map(|j| j.seed).collect::<Vec<_>>(), vec![1]);
/// ```
pub fn grid(plans: &[ExperimentPlan], shard: Option<Shard>) -> Vec<RunJob> {
    let mut out = Vec::new();
    let mut index = 0;
    for plan in plans {
        for &seed in &plan.seeds {
            if shard.is_none_or(|s| s.contains(index)) {
                out.push(RunJob {
                    index,
                    plan: plan.clone(),
                    seed,
                });
            }
            index += 1;
        }
    }
    out
}

/// Shard `index` of `count` (0-based, as `SLURM_ARRAY_TASK_ID` with `--array=0-(N-1)` and
/// Kubernetes' `JOB_COMPLETION_INDEX`): grid cells whose position modulo `count` is `index`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    index: usize,
    count: usize,
}

impl Shard {
    /// Shard `index` of `count`.
    pub fn new(index: usize, count: usize) -> Result<Self> {
        if count == 0 || index >= count {
            return Err(PipelineError::Invalid(format!(
                "shard {index}/{count}: expected i/N with 0 <= i < N"
            )));
        }
        Ok(Self { index, count })
    }

    /// Whether grid cell `position` belongs to this shard.
    pub fn contains(&self, position: usize) -> bool {
        position % self.count == self.index
    }
}

impl FromStr for Shard {
    type Err = PipelineError;

    fn from_str(s: &str) -> Result<Self> {
        let bad = || PipelineError::Invalid(format!("--shard `{s}`: expected i/N, e.g. 0/4"));
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let i = i.trim().parse().map_err(|_| bad())?;
        let n = n.trim().parse().map_err(|_| bad())?;
        Shard::new(i, n)
    }
}

/// Parses a seed list: `0..10` (exclusive), `0..=9`, `3`, or a comma list of those.
///
/// ```
/// use a2perf_pipeline::parse_seeds;
/// assert_eq!(parse_seeds("0..3").unwrap(), vec![0, 1, 2]);
/// assert_eq!(parse_seeds("1,4..=5").unwrap(), vec![1, 4, 5]);
/// assert!(parse_seeds("3..1").is_err());
/// ```
pub fn parse_seeds(text: &str) -> Result<Vec<u64>> {
    let bad = |why: &str| PipelineError::Invalid(format!("--seeds `{text}`: {why}"));
    let num = |s: &str| -> Result<u64> {
        s.trim()
            .parse()
            .map_err(|_| bad(&format!("`{}` is not a non-negative integer", s.trim())))
    };
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        if let Some((a, b)) = part.split_once("..=") {
            let (a, b) = (num(a)?, num(b)?);
            if a > b {
                return Err(bad("empty range"));
            }
            out.extend(a..=b);
        } else if let Some((a, b)) = part.split_once("..") {
            let (a, b) = (num(a)?, num(b)?);
            if a >= b {
                return Err(bad("empty range"));
            }
            out.extend(a..b);
        } else {
            out.push(num(part)?);
        }
        if out.len() > 1_000_000 {
            return Err(bad("too many seeds"));
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    out.retain(|s| seen.insert(*s));
    if out.is_empty() {
        return Err(bad("no seeds"));
    }
    Ok(out)
}

/// One entry of a suite file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SuiteEntry {
    /// Experiment config, relative to the suite file.
    pub config: String,
    /// `dotted.path=value` overrides for this experiment (after the suite's own).
    #[serde(default)]
    pub set: Vec<String>,
    /// For an offline algorithm (`bc`): the dataset it trains on is collected from other
    /// experiments of this suite as soon as their runs are trained (`a2perf run` does it in its
    /// `--jobs` pool, beside the other runs, and trains this experiment right after).
    #[serde(default)]
    pub dataset: Option<DatasetStep>,
}

/// A suite entry's `dataset`: an offline dataset collected, as `a2perf collect` does, from the
/// checkpoints of other experiments of the same suite.
///
/// ```ron
/// (config: "bc.ron", dataset: (from: ["toy_ppo", "toy_ddqn"], level: "intermediate",
///                              eval_episodes: 10, episodes: 20))
/// ```
///
/// ```
/// use a2perf_pipeline::plan::DatasetStep;
/// let step: DatasetStep = ron::from_str(r#"(from: ["toy_ppo"], level: "expert")"#).unwrap();
/// assert_eq!(step.level().unwrap().name(), "expert");
/// assert_eq!(step.collect_options().unwrap().dataset_episodes, 100);
/// let bad: DatasetStep = ron::from_str(r#"(from: ["toy_ppo"], level: "guru")"#).unwrap();
/// assert!(bad.level().unwrap_err().to_string().contains("dataset.level `guru`"));
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetStep {
    /// Names of the experiments (their `name`, as loaded) whose runs' checkpoints make the
    /// dataset; they must run on the same task as each other and as the offline experiment.
    pub from: Vec<String>,
    /// Expertise level of the checkpoints drawn: `novice`, `intermediate` or `expert`.
    #[serde(default = "default_level")]
    pub level: String,
    /// Level rule: the paper's one-σ wording instead of the original code's rule.
    #[serde(default)]
    pub one_sigma: bool,
    /// Greedy episodes per checkpoint evaluation (the original: 100).
    #[serde(default = "default_episodes")]
    pub eval_episodes: usize,
    /// Episodes in the dataset.
    #[serde(default = "default_episodes")]
    pub episodes: usize,
    /// Training sample cost rule: `measured` or `pro_rata` (the original's).
    #[serde(default = "default_cost")]
    pub cost: String,
}

fn default_level() -> String {
    "intermediate".into()
}

fn default_episodes() -> usize {
    100
}

fn default_cost() -> String {
    "measured".into()
}

impl DatasetStep {
    /// The level, checked.
    pub fn level(&self) -> Result<Level> {
        match self.level.as_str() {
            "novice" => Ok(Level::Novice),
            "intermediate" => Ok(Level::Intermediate),
            "expert" => Ok(Level::Expert),
            other => Err(PipelineError::Invalid(format!(
                "dataset.level `{other}`: expected `novice`, `intermediate` or `expert`"
            ))),
        }
    }

    /// The options `collect` runs with.
    pub fn collect_options(&self) -> Result<CollectOptions> {
        let cost = match self.cost.as_str() {
            "measured" => CostRule::Measured,
            "pro_rata" => CostRule::ProRata,
            other => {
                return Err(PipelineError::Invalid(format!(
                    "dataset.cost `{other}`: expected `measured` or `pro_rata`"
                )));
            }
        };
        if self.eval_episodes == 0 || self.episodes == 0 {
            return Err(PipelineError::Invalid(
                "dataset: `eval_episodes` and `episodes` must be at least 1".into(),
            ));
        }
        Ok(CollectOptions {
            eval_episodes: self.eval_episodes,
            dataset_episodes: self.episodes,
            cost,
            one_sigma: self.one_sigma,
            show_progress: false,
            cancel: Default::default(),
        })
    }
}

/// Where an offline experiment's dataset comes from, resolved when the suite is loaded.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetSource {
    /// The suite entry's step.
    pub step: DatasetStep,
    /// Run directories of the source experiments (every seed), in suite order.
    pub runs: Vec<PathBuf>,
    /// Directory `collect` writes into (`<experiment dir>/datasets`).
    pub out: PathBuf,
    /// The dataset's `samples.json`: the experiment's `algorithm.dataset`.
    pub samples: PathBuf,
}

/// A suite file: several experiment configs run and reported together (e.g.
/// `configs/quickstart.ron`). Recognised by its top-level `experiments` key.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Suite {
    /// Name (informational).
    #[serde(default)]
    pub name: String,
    /// Overrides applied to every experiment (before each entry's own).
    #[serde(default)]
    pub set: Vec<String>,
    /// The experiments.
    pub experiments: Vec<SuiteEntry>,
    /// Where `a2perf run` writes the report (relative to the working directory; empty = in the
    /// first experiment's directory).
    #[serde(default)]
    pub report_dir: String,
}

/// Whether RON text is a suite (an `experiments` key) rather than one experiment.
fn looks_like_suite(text: &str) -> bool {
    let code: String = text
        .lines()
        .map(|l| l.split("//").next().unwrap_or(""))
        .collect::<Vec<_>>()
        .join("\n");
    code.match_indices("experiments").any(|(i, _)| {
        let before = code[..i].chars().next_back();
        let after = code[i + "experiments".len()..].trim_start();
        before.is_none_or(|c| c == '(' || c == ',' || c.is_whitespace()) && after.starts_with(':')
    })
}

/// Plans loaded from config files, plus the report directory a suite asks for.
#[derive(Debug, Default)]
pub struct LoadedPlans {
    /// One plan per experiment, in file order.
    pub plans: Vec<ExperimentPlan>,
    /// A suite's `report_dir`, if any.
    pub report_dir: Option<PathBuf>,
    /// A suite's name, if any.
    pub suite_name: Option<String>,
}

/// Loads experiment configs or suite files, applying `sets` (`dotted.path=value`) to every
/// experiment last and replacing the seeds with `seeds` when given.
pub fn load_plans(
    paths: &[PathBuf],
    sets: &[String],
    seeds: Option<&[u64]>,
    registry: &a2perf_core::Registry,
) -> Result<LoadedPlans> {
    let mut out = LoadedPlans::default();
    let load_exp =
        |path: &std::path::Path, overrides: &[String]| -> Result<a2perf_core::Experiment> {
            a2perf_core::Experiment::load(path, overrides, registry)
                .map_err(|e| PipelineError::Invalid(e.to_string()))
        };
    let plan_of = |exp: &a2perf_core::Experiment| -> Result<ExperimentPlan> {
        let mut plan = from_experiment(exp, registry)?;
        if let Some(seeds) = seeds {
            plan.seeds = seeds.to_vec();
        }
        Ok(plan)
    };
    for path in paths {
        let text = std::fs::read_to_string(path).map_err(io_err(path))?;
        if looks_like_suite(&text) {
            let suite: Suite = ron::Options::default()
                .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
                .from_str(&text)
                .map_err(|e| {
                    PipelineError::Invalid(format!(
                        "{}:{}:{}: {}",
                        path.display(),
                        e.span.start.line,
                        e.span.start.col,
                        e.code
                    ))
                })?;
            if !suite.name.is_empty() {
                check_dir_name("suite", &suite.name)
                    .map_err(|e| PipelineError::Invalid(format!("{}: {e}", path.display())))?;
            }
            let base = path.parent().unwrap_or(std::path::Path::new("."));
            let overrides_of = |entry: &SuiteEntry| {
                let mut overrides = suite.set.clone();
                overrides.extend(entry.set.iter().cloned());
                overrides.extend(sets.iter().cloned());
                overrides
            };
            // Experiments that train from a dataset of the suite are planned after the others,
            // whose runs they draw from; the plans keep the file's order.
            let mut planned: Vec<Option<ExperimentPlan>> = vec![None; suite.experiments.len()];
            for (i, entry) in suite.experiments.iter().enumerate() {
                if entry.dataset.is_none() {
                    let exp = load_exp(&base.join(&entry.config), &overrides_of(entry))?;
                    planned[i] = Some(plan_of(&exp)?);
                }
            }
            let sources: Vec<ExperimentPlan> = planned.iter().flatten().cloned().collect();
            for (i, entry) in suite.experiments.iter().enumerate() {
                let Some(step) = &entry.dataset else {
                    continue;
                };
                let config = base.join(&entry.config);
                let mut exp = load_exp(&config, &overrides_of(entry))?;
                let context = format!(
                    "{}: experiment `{}` ({})",
                    path.display(),
                    exp.name,
                    entry.config
                );
                // The task as planned (profile switches and defaults resolved), to compare with
                // the sources'.
                let task = plan_of(&exp)?.task;
                let source = dataset_source(&exp, &task, step, &sources, registry)
                    .map_err(|e| PipelineError::Invalid(format!("{context}: {e}")))?;
                set_dataset(&mut exp, &source.samples, registry)
                    .map_err(|e| PipelineError::Invalid(format!("{context}: {e}")))?;
                let mut plan = plan_of(&exp)?;
                plan.dataset_from = Some(source);
                planned[i] = Some(plan);
            }
            out.plans.extend(planned.into_iter().flatten());
            if out.report_dir.is_none() && !suite.report_dir.is_empty() {
                out.report_dir = Some(PathBuf::from(&suite.report_dir));
            }
            if out.suite_name.is_none() && !suite.name.is_empty() {
                out.suite_name = Some(suite.name.clone());
            }
        } else {
            out.plans.push(plan_of(&load_exp(path, sets)?)?);
        }
    }
    let mut dirs = std::collections::BTreeSet::new();
    for p in &out.plans {
        for s in &p.seeds {
            if !dirs.insert(p.run_dir(*s)) {
                return Err(PipelineError::Invalid(format!(
                    "two experiments write to {}; give them different `name`s",
                    p.run_dir(*s).display()
                )));
            }
        }
    }
    Ok(out)
}

/// Resolves a suite entry's dataset step against the suite's other experiments (`sources`,
/// already planned): the runs to collect from and where the dataset will be.
fn dataset_source(
    exp: &a2perf_core::Experiment,
    task_of_exp: &TaskSpec,
    step: &DatasetStep,
    sources: &[ExperimentPlan],
    registry: &a2perf_core::Registry,
) -> Result<DatasetSource> {
    let level = step.level()?;
    step.collect_options()?;
    if step.from.is_empty() {
        return Err(PipelineError::Invalid(
            "dataset.from names no experiment to collect from".into(),
        ));
    }
    let mut from: Vec<&ExperimentPlan> = Vec::new();
    for name in &step.from {
        let Some(plan) = sources.iter().find(|p| &p.name == name) else {
            let names = sources.iter().map(|p| p.name.as_str());
            let hint = a2perf_core::value::did_you_mean(name, names.clone())
                .map(|h| format!(" (did you mean `{h}`?)"))
                .unwrap_or_default();
            let known: Vec<String> = names.map(|n| format!("`{n}`")).collect();
            return Err(PipelineError::Invalid(format!(
                "dataset.from: no experiment named `{name}` in this suite{hint} (experiments that \
                 do not themselves take a dataset: {})",
                known.join(", ")
            )));
        };
        from.push(plan);
    }
    let task = &from[0].task;
    if let Some(other) = from.iter().find(|p| p.task.name != task.name) {
        return Err(PipelineError::Invalid(format!(
            "dataset.from: `{}` runs task `{}` but `{}` runs `{}`; a dataset is collected from \
             one task",
            from[0].name, task.name, other.name, other.task.name
        )));
    }
    if task_of_exp.env_id != task.env_id || task_of_exp.env_params != task.env_params {
        return Err(PipelineError::Invalid(format!(
            "its task `{}` is not the task of `{}` (`{}`), whose runs make the dataset",
            task_of_exp.name, from[0].name, task.name
        )));
    }
    let algo = exp
        .require_algorithm()
        .map_err(|e| PipelineError::Invalid(e.to_string()))?;
    if !registry
        .algorithm(&algo.name)?
        .params
        .iter()
        .any(|p| p.name == "dataset")
    {
        return Err(PipelineError::Invalid(format!(
            "algorithm `{}` has no `dataset` parameter to train on a collected dataset",
            algo.name
        )));
    }
    let out = exp.output.dir.join(&exp.name).join("datasets");
    let samples = out
        .join(dataset::dataset_id(&task.name, &task.env_id, level))
        .join("samples.json");
    Ok(DatasetSource {
        step: step.clone(),
        runs: from
            .iter()
            .flat_map(|p| p.seeds.iter().map(|s| p.run_dir(*s)))
            .collect(),
        out,
        samples,
    })
}

/// Points the experiment's `algorithm.dataset` at `samples`, so its operative config and
/// `run.json` name the dataset it trains on.
fn set_dataset(
    exp: &mut a2perf_core::Experiment,
    samples: &std::path::Path,
    registry: &a2perf_core::Registry,
) -> Result<()> {
    let Some(algo) = exp.algorithm.as_mut() else {
        return Err(PipelineError::Invalid("no algorithm".into()));
    };
    let mut given = algo.params.values().clone();
    given.insert(
        "dataset".into(),
        Value::Str(samples.to_string_lossy().into_owned()),
    );
    let specs = &registry.algorithm(&algo.name)?.params;
    algo.params = a2perf_core::Params::resolve(specs, &given).map_err(|source| {
        a2perf_core::RegistryError::Param {
            context: format!("algorithm {}", algo.name),
            source,
        }
    })?;
    Ok(())
}

// A run's record is planned here, from its job; the run directory only stores it.
impl PlannedRun {
    /// The record of `job` trained by `algorithm` (hyperparameters resolved): the task's
    /// parameters resolved and the environment's provenance read from a probe instance.
    /// `external` marks a run trained outside the benchmark's algorithms.
    pub(crate) fn new(
        registry: &Registry,
        job: &RunJob,
        algorithm: AlgorithmSpec,
        external: Option<ExternalAgent>,
    ) -> Result<Self> {
        let plan = &job.plan;
        let env = registry.env(&plan.task.env_id)?.clone();
        let env_params = registry.env_params(&plan.task.env_id, &plan.task.env_params)?;
        let probe = (env.make)(&env_params).map_err(|source| a2perf_core::RegistryError::Env {
            id: plan.task.env_id.clone(),
            source,
        })?;
        let env_metadata = probe.spec().metadata.clone();
        drop(probe);
        let mut task = plan.task.clone();
        task.env_params = env_params.values().clone();
        let record = RunRecord {
            format_version: RUN_FORMAT_VERSION,
            experiment: plan.name.clone(),
            task,
            domain: env.domain.clone(),
            algorithm,
            seed: job.seed,
            training: plan.training.clone(),
            inference: plan.inference.clone(),
            generalization: plan.generalization.clone(),
            metrics: plan.metrics.clone(),
            env_metadata,
            dataset: plan.dataset.clone(),
            external,
        };
        // The exact bytes `write_json_atomic` writes, so that comparing them with the file on
        // disk is exact (no float parsing).
        let record_json =
            serde_json::to_vec_pretty(&record).map_err(|e| PipelineError::Corrupt {
                path: plan.run_dir(job.seed).join(RUN_FILE),
                reason: e.to_string(),
            })?;
        Ok(Self {
            record,
            record_json,
            env,
            env_params,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_the_grid() {
        let task = TaskSpec {
            name: "t".into(),
            env_id: "T-v0".into(),
            env_params: BTreeMap::new(),
            profile: None,
        };
        let algo = AlgorithmSpec {
            name: "a".into(),
            params: BTreeMap::new(),
        };
        let p1 = ExperimentPlan::new(
            "e",
            "/o",
            task.clone(),
            algo.clone(),
            (0..7).collect(),
            TrainingSettings::default(),
        );
        let mut p2 = p1.clone();
        p2.task.name = "u".into();
        let plans = [p1, p2];
        let all: Vec<usize> = grid(&plans, None).iter().map(|j| j.index).collect();
        let mut union = Vec::new();
        for i in 0..3 {
            union.extend(
                grid(&plans, Some(Shard::new(i, 3).unwrap()))
                    .iter()
                    .map(|j| j.index),
            );
        }
        union.sort();
        assert_eq!(union, all);
        assert_eq!(all.len(), 14);
    }

    #[test]
    fn bad_shards_are_errors() {
        for s in ["3/3", "1", "a/b", "0/0", "-1/2"] {
            assert!(s.parse::<Shard>().is_err(), "{s}");
        }
    }

    #[test]
    fn run_dir_names_are_path_safe() {
        assert_eq!(run_dir_name("a/b c", "ppo", 3), "a_b_c__ppo__seed3");
    }
}
