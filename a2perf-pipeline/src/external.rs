//! Runs trained outside the benchmark's algorithms — a participant's Python agent, driven by
//! `a2perf_rs.TrainingRun` — recorded exactly as `a2perf train` records a built-in one, so that
//! `infer`, `generalize`, `collect` and `report` treat both alike.
//!
//! The front end plans the run with [`external_plan`] (the same planning as a config file: the
//! task's name and directory, the generalization suite, the profile, the operative config) and
//! drives an [`ExternalRun`] through the agent's own training loop:
//!
//! 1. [`ExternalRun::begin`] creates the run directory as [`train`](crate::train()) does
//!    (`status.json`, `run.json` with an [`ExternalAgent`], `operative_config.ron`,
//!    `system_info.json`, `train_segments.json`) and starts the same system meters;
//! 2. the agent trains in environments seeded by [`episode_seed`] (the derivation the built-in
//!    algorithms' environments use), reports evaluations ([`ExternalRun::log_evaluation`], or
//!    [`ExternalRun::evaluate`] for the built-in protocol) and registers its own checkpoint files
//!    ([`ExternalRun::save_checkpoint`]);
//! 3. [`ExternalRun::finish`] stops the meters and marks the run `complete` (writing
//!    `train_system.json` and `train_emissions.csv` like a built-in run), `failed` or
//!    `interrupted`, keeping everything written before.
//!
//! An external run has no resume points and no `policy.ckpt` (its checkpoints are in the agent's
//! own format): a rerun starts it again, and its policies are rolled out through a
//! [`PolicySource`](crate::PolicySource) the front end gives.
//!
//! ```
//! use a2perf_pipeline::external::{ExternalOutcome, ExternalRun, ExternalRunSpec, external_plan};
//! use a2perf_pipeline::{ExternalAgent, train::no_meters};
//! let reg = a2perf_pipeline::registry::full_registry();
//! let out = tempfile::tempdir().unwrap();
//! let spec = ExternalRunSpec {
//!     env_id: Some("WebNavigation-Difficulty-01-v0".into()),
//!     ..ExternalRunSpec::new(out.path(), "my-agent", 0)
//! };
//! let plan = external_plan(&reg, &spec).unwrap();
//! let agent = ExternalAgent { harness: "doc test".into(), runtime: "Rust".into() };
//! let mut run = ExternalRun::begin(&reg, plan, 0, agent, &no_meters()).unwrap();
//! run.log_evaluation(100, -1.5, 0.5).unwrap();
//! let dir = run.dir().to_path_buf();
//! run.finish(ExternalOutcome::Completed).unwrap();
//! assert!(a2perf_pipeline::LoadedRun::open(&dir).unwrap().is_complete().unwrap());
//! assert!(dir.ends_with("my-agent/WebNavigation-Difficulty-01-v0__my-agent__seed0"));
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

use a2perf_core::config::{self, AlgorithmConfig, EnvConfig};
use a2perf_core::{
    CancelToken, CurvePoint, DiscardCheckpoints, Env, EnvEntry, LearningCurve, ParamKind,
    ParamSpec, Params, Policy, Registry, RngStream, RunDir, RunState, TrainingContext, Value,
    write_atomic, write_json_atomic,
};

use crate::error::{PipelineError, Result, io_err};
use crate::phase::{MeterFactory, MeteredPhase, Phase};
use crate::plan::{ExperimentPlan, RunJob, check_dir_name, from_experiment, path_safe};
use crate::run_dir::{
    CHECKPOINT_DIR, ExternalAgent, PlannedRun, RunRecord, SegmentOutcome, Start,
    TRAIN_SEGMENTS_FILE, TrainSegment, TrainSegments, prepare, wipe, write_curve, write_run_files,
    write_train_system,
};
use crate::run_lock::TrainingLock;

/// What a front end knows about an external run before it starts.
#[derive(Clone, Debug, PartialEq)]
pub struct ExternalRunSpec {
    /// Output root: the run goes to `output/<experiment>/<task>__<algorithm>__seed<k>`.
    pub output: PathBuf,
    /// Experiment name (default: the algorithm's name).
    pub experiment: Option<String>,
    /// An experiment config whose task and settings the run takes (its algorithm is replaced by
    /// the agent), so that the agent is scored on exactly the task and suite of a built-in run.
    pub config: Option<PathBuf>,
    /// `dotted.path=value` overrides, as `a2perf train --set` (e.g. `training.total_env_steps=
    /// 50000`, `inference.rollouts=20`).
    pub set: Vec<String>,
    /// Environment id (default: the config's).
    pub env_id: Option<String>,
    /// Environment parameters (over the config's when it names the same environment).
    pub env_params: BTreeMap<String, Value>,
    /// The agent's name: the report's column. It must not be a registered algorithm's.
    pub algorithm: String,
    /// The agent's hyperparameters, recorded in `run.json`, the operative config and the
    /// leaderboard: numbers, booleans, strings, lists of numbers, or `None`.
    pub hyperparameters: BTreeMap<String, Value>,
    /// The run's seed.
    pub seed: u64,
}

impl ExternalRunSpec {
    /// A spec with no config, environment, parameters or overrides yet.
    pub fn new(output: impl Into<PathBuf>, algorithm: &str, seed: u64) -> Self {
        Self {
            output: output.into(),
            experiment: None,
            config: None,
            set: Vec::new(),
            env_id: None,
            env_params: BTreeMap::new(),
            algorithm: algorithm.into(),
            hyperparameters: BTreeMap::new(),
            seed,
        }
    }
}

/// Hyperparameter names for [`ParamSpec`]s, which hold `&'static str`: each distinct name is
/// leaked once for the life of the process.
fn interned(name: &str) -> &'static str {
    static NAMES: OnceLock<Mutex<BTreeSet<&'static str>>> = OnceLock::new();
    let mut names = NAMES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(n) = names.get(name) {
        return n;
    }
    let leaked: &'static str = Box::leak(name.to_owned().into_boxed_str());
    names.insert(leaked);
    leaked
}

/// Whether `s` can name a hyperparameter (and a Python keyword argument): ASCII letters,
/// digits and `_`, not starting with a digit.
///
/// ```
/// use a2perf_pipeline::external::is_identifier;
/// assert!(is_identifier("learning_rate") && !is_identifier("1st") && !is_identifier(""));
/// ```
pub fn is_identifier(s: &str) -> bool {
    let mut chars = s.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// The agent's hyperparameters as resolved parameters (every one declared with its own value
/// as the default), so that they render in the operative config like a built-in algorithm's.
fn hyperparameters(given: &BTreeMap<String, Value>) -> Result<Params> {
    let mut specs = Vec::with_capacity(given.len());
    for (name, value) in given {
        if !is_identifier(name) {
            return Err(PipelineError::Invalid(format!(
                "hyperparameter `{name}`: names must be identifiers (letters, digits and `_`, \
                 not starting with a digit), as in a config file"
            )));
        }
        let kind = match value {
            Value::Bool(_) => ParamKind::Bool,
            Value::Int(_) => ParamKind::Int,
            Value::Float(_) => ParamKind::Float,
            Value::Str(_) | Value::Null => ParamKind::Str,
            Value::List(items) if items.iter().all(|v| matches!(v, Value::Int(_))) => {
                ParamKind::IntList
            }
            Value::List(items) if items.iter().all(|v| v.as_f64().is_some()) => {
                ParamKind::FloatList
            }
            other => {
                return Err(PipelineError::Invalid(format!(
                    "hyperparameter `{name}`: a {} cannot be recorded; use numbers, booleans, \
                     strings, lists of numbers or None (e.g. one key per entry of a dict)",
                    other.type_name()
                )));
            }
        };
        specs.push(ParamSpec::new(interned(name), kind, value.clone(), ""));
    }
    Params::resolve(&specs, &BTreeMap::new()).map_err(|e| PipelineError::Invalid(e.to_string()))
}

/// Plans an external run the way a config file plans a built-in one ([`from_experiment`]): the
/// experiment is `spec.config` (or the config schema's defaults) with `spec.set` applied, the
/// environment from `spec.env_id` / `spec.env_params` (the profile's switches filled in), the
/// algorithm replaced by the agent and its hyperparameters, one seed, and `spec.output`.
pub fn external_plan(registry: &Registry, spec: &ExternalRunSpec) -> Result<ExperimentPlan> {
    let name = spec.algorithm.trim();
    if name.is_empty() {
        return Err(PipelineError::Invalid(
            "algorithm: give the agent a name (it labels the agent's column in reports)".into(),
        ));
    }
    if registry.algorithm(name).is_ok() {
        return Err(PipelineError::Invalid(format!(
            "algorithm `{name}` is the name of a built-in algorithm; name the agent differently \
             (e.g. `my-{name}`) so that reports keep the two apart"
        )));
    }
    let experiment = spec.experiment.clone().unwrap_or_else(|| path_safe(name));
    check_dir_name("experiment", &experiment)?;
    let invalid = |e: config::ConfigError| PipelineError::Invalid(e.to_string());
    let mut exp = match &spec.config {
        Some(path) => a2perf_core::Experiment::load(path, &spec.set, registry).map_err(invalid)?,
        None => {
            let overrides = spec
                .set
                .iter()
                .map(|o| config::Override::parse(o))
                .collect::<std::result::Result<Vec<_>, _>>()
                .map_err(invalid)?;
            config::load_str(
                "()",
                Path::new(&format!("{experiment}.ron")),
                &overrides,
                registry,
            )
            .map_err(invalid)?
        }
    };
    let base_env = exp.env.take();
    let env_id = match (&spec.env_id, &base_env) {
        (Some(id), _) => id.clone(),
        (None, Some(env)) => env.id.clone(),
        (None, None) => {
            return Err(PipelineError::Invalid(
                "env_id: name the environment (or give a config that names one)".into(),
            ));
        }
    };
    let entry: &EnvEntry = registry.env(&env_id)?;
    // A config's parameters stay under the agent's when it names the same environment (the
    // config merge rule: another environment replaces the section).
    let mut given: BTreeMap<String, Value> = match &base_env {
        Some(env) if env.id == env_id => env.params.values().clone(),
        _ => BTreeMap::new(),
    };
    given.extend(spec.env_params.clone());
    let profile_switches = match &exp.profile {
        Some(p) => p.switches_for(entry),
        None => BTreeMap::new(),
    };
    for (k, v) in &profile_switches {
        given.entry(k.clone()).or_insert_with(|| v.clone());
    }
    let params = registry.env_params(&env_id, &given)?;
    exp.env = Some(EnvConfig {
        id: env_id,
        params,
        profile_switches,
    });
    exp.algorithm = Some(AlgorithmConfig {
        name: name.to_string(),
        params: hyperparameters(&spec.hyperparameters)?,
    });
    exp.name = experiment;
    exp.seeds = vec![spec.seed];
    exp.output.dir = spec.output.clone();
    from_experiment(&exp, registry)
}

/// The reset seed of episode `episode` (counted from 0) of training environment `index` in a
/// run with `seed`: the derivation of [`a2perf_core::VecEnv`], which the built-in algorithms'
/// training environments use, so that an external agent's environments draw the same episodes.
///
/// ```
/// use a2perf_pipeline::external::episode_seed;
/// assert_eq!(episode_seed(0, 1, 2), episode_seed(0, 1, 2));
/// assert_ne!(episode_seed(0, 1, 2), episode_seed(0, 2, 1));
/// ```
pub fn episode_seed(seed: u64, index: usize, episode: u64) -> u64 {
    RngStream::new(seed, "vec-env/reset")
        .derive_index(index as u64)
        .derive_index(episode)
        .next_u64()
}

/// How the agent's training ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ExternalOutcome {
    /// It finished: the run is marked complete (it must have logged at least one evaluation).
    Completed,
    /// It raised an error (the note says which): the run is marked failed.
    Failed(String),
    /// It was stopped (Ctrl-C): the run is marked interrupted.
    Interrupted(String),
}

/// An external agent's run in progress (see the [module documentation](self)).
pub struct ExternalRun {
    run: RunDir,
    record: RunRecord,
    env: EnvEntry,
    env_params: Params,
    phase: MeteredPhase,
    segments: TrainSegments,
    curve: LearningCurve,
    checkpoints: BTreeMap<u64, PathBuf>,
    warnings: Vec<String>,
    /// Held from `begin` to `finish` (or drop): no other trainer takes the directory meanwhile.
    lock: TrainingLock,
}

impl std::fmt::Debug for ExternalRun {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExternalRun")
            .field("dir", &self.run.path())
            .field("curve_points", &self.curve.points.len())
            .finish_non_exhaustive()
    }
}

impl ExternalRun {
    /// Creates the run directory of `plan` and `seed` exactly as [`train`](crate::train())
    /// would (an unfinished run of the same or another configuration is started again, with a
    /// warning in the second case; a complete one is refused), and starts the training meters.
    /// The run holds the directory's training lock until it finishes or is dropped; a
    /// directory another trainer holds is refused with [`PipelineError::Locked`] (see
    /// [`run_lock`](crate::run_lock)).
    pub fn begin(
        registry: &Registry,
        plan: ExperimentPlan,
        seed: u64,
        agent: ExternalAgent,
        meters: &MeterFactory,
    ) -> Result<Self> {
        let job = RunJob {
            index: 0,
            plan,
            seed,
        };
        let dir = job.plan.run_dir(seed);
        let run = RunDir::new(&dir);
        let complete = || {
            PipelineError::Invalid(format!(
                "{}: this run is already complete (complete runs are never redone); delete the \
                 directory, or choose another seed or output directory",
                dir.display()
            ))
        };
        let planned = PlannedRun::new(registry, &job, job.plan.algorithm.clone(), Some(agent))?;
        let lock = TrainingLock::acquire(&dir)?;
        let mut warnings = Vec::new();
        match prepare(&run, &planned.record_json, &mut warnings)? {
            Start::Skip => return Err(complete()),
            Start::Fresh => {}
            // External runs write no resume points; one found here is not theirs.
            Start::Resume(..) => {
                wipe(&run)?;
                run.begin()?;
            }
        }
        write_run_files(&run, &planned.record_json, job.plan.operative.as_ref())?;
        run.set_status(
            RunState::Running,
            "training by an external agent (a2perf_rs.TrainingRun)",
        )?;
        let segments = TrainSegments {
            segments: vec![TrainSegment {
                started_at_step: 0,
                outcome: SegmentOutcome::Running,
                system: None,
                resume_points: Vec::new(),
                warnings: warnings.clone(),
                time_split: None,
            }],
        };
        write_json_atomic(&run.file(TRAIN_SEGMENTS_FILE), &segments)?;
        let phase = MeteredPhase::start(meters(Phase::Train, &dir, &job.plan.metrics));
        Ok(Self {
            run,
            record: planned.record,
            env: planned.env,
            env_params: planned.env_params,
            phase,
            segments,
            curve: LearningCurve::default(),
            checkpoints: BTreeMap::new(),
            warnings,
            lock,
        })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        self.run.path()
    }

    /// The run's `run.json` record.
    pub fn record(&self) -> &RunRecord {
        &self.record
    }

    /// Things the user should know (e.g. an earlier run of another configuration was replaced).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Seconds since the run began (the curve's clock).
    pub fn clock(&self) -> f64 {
        self.phase.elapsed_s()
    }

    /// The curve logged so far.
    pub fn curve(&self) -> &LearningCurve {
        &self.curve
    }

    /// The checkpoints registered so far, by step.
    pub fn checkpoints(&self) -> &BTreeMap<u64, PathBuf> {
        &self.checkpoints
    }

    /// A new instance of the run's environment (its parameters resolved as in `run.json`).
    pub fn make_env(&self) -> Result<Box<dyn Env>> {
        (self.env.make)(&self.env_params).map_err(|source| {
            a2perf_core::RegistryError::Env {
                id: self.record.task.env_id.clone(),
                source,
            }
            .into()
        })
    }

    /// Records an evaluation point, as the built-in curve does (its wall-clock second is the
    /// run's clock now), and rewrites `curve.csv` and `curve.json` so that a run that dies
    /// keeps its curve. Steps must increase from one point to the next; returns must be finite.
    pub fn log_evaluation(
        &mut self,
        env_steps: u64,
        mean_return: f64,
        std_return: f64,
    ) -> Result<()> {
        if let Some(last) = self.curve.points.last()
            && env_steps <= last.env_steps
        {
            return Err(PipelineError::Invalid(format!(
                "log_evaluation: env_steps {env_steps} does not increase (the last point was at \
                 {})",
                last.env_steps
            )));
        }
        if !mean_return.is_finite() || !std_return.is_finite() || std_return < 0.0 {
            return Err(PipelineError::Invalid(format!(
                "log_evaluation: mean_return {mean_return} and std_return {std_return} must be \
                 finite, std_return non-negative"
            )));
        }
        self.curve.points.push(CurvePoint {
            env_steps,
            mean_return,
            std_return,
            wall_seconds: self.clock(),
        });
        write_curve(&self.run, &self.curve)
    }

    /// Evaluates `policy` as the built-in algorithms' training context does
    /// ([`TrainingContext::evaluate`]: `training.eval_episodes` greedy episodes on the same
    /// evaluation seeds at every point) and logs the point at `env_steps`; returns the mean and
    /// standard deviation.
    pub fn evaluate(&mut self, env_steps: u64, policy: &mut dyn Policy) -> Result<(f64, f64)> {
        let (make, params) = (self.env.make.clone(), self.env_params.clone());
        let factory = move |_i: usize| make(&params);
        let mut sink = DiscardCheckpoints;
        let mut ctx = TrainingContext::new(
            &factory,
            self.record.seed,
            self.record.training.clone(),
            &mut sink,
            CancelToken::new(),
        );
        let (mean, std) = ctx.evaluate(policy).map_err(|source| PipelineError::Run {
            run: format!("{} (evaluation at step {env_steps})", self.dir().display()),
            source,
        })?;
        self.log_evaluation(env_steps, mean, std)?;
        Ok((mean, std))
    }

    /// Registers the agent's checkpoint file `source`, taken after `env_steps` steps: copied
    /// atomically to `checkpoints/step_<env_steps>.ckpt` (the name the built-in algorithms'
    /// checkpoints get, so that `collect` finds it; the bytes are the agent's own format).
    /// Returns the stored path.
    pub fn save_checkpoint(&mut self, env_steps: u64, source: &Path) -> Result<PathBuf> {
        if !source.is_file() {
            return Err(PipelineError::Invalid(format!(
                "save_checkpoint: {} is not a file (save the agent's checkpoint to a file first)",
                source.display()
            )));
        }
        let bytes = std::fs::read(source).map_err(io_err(source))?;
        let dir = self.run.file(CHECKPOINT_DIR);
        std::fs::create_dir_all(&dir).map_err(io_err(&dir))?;
        let path = a2perf_core::DirectoryCheckpoints::new(&dir).path_for(env_steps);
        write_atomic(&path, &bytes).map_err(io_err(&path))?;
        self.checkpoints.insert(env_steps, path.clone());
        Ok(path)
    }

    /// Stops the meters and closes the run: `Completed` marks it complete (with
    /// `train_system.json`) — or failed, with an error, when no evaluation was logged —;
    /// `Failed` and `Interrupted` mark it so with the note. The segment's meters go to
    /// `train_segments.json` whatever the outcome; nothing written before is removed.
    pub fn finish(self, outcome: ExternalOutcome) -> Result<RunState> {
        let Self {
            run,
            phase,
            mut segments,
            curve,
            lock,
            ..
        } = self;
        let system = phase.finish();
        let no_curve = outcome == ExternalOutcome::Completed && curve.points.is_empty();
        let (segment, state, note) = match &outcome {
            _ if no_curve => (
                SegmentOutcome::Failed,
                RunState::Failed,
                "failed: the agent logged no evaluation (call run.log_evaluation or \
                 run.evaluate at least once)"
                    .to_string(),
            ),
            ExternalOutcome::Completed => (
                SegmentOutcome::Completed,
                RunState::Complete,
                "trained by an external agent (a2perf_rs.TrainingRun)".to_string(),
            ),
            ExternalOutcome::Failed(why) => (
                SegmentOutcome::Failed,
                RunState::Failed,
                format!("failed: {why}"),
            ),
            ExternalOutcome::Interrupted(why) => (
                SegmentOutcome::Interrupted,
                RunState::Interrupted,
                format!("interrupted: {why}; running it again trains it from scratch"),
            ),
        };
        if let Some(seg) = segments.segments.last_mut() {
            seg.outcome = segment;
            seg.system = Some(system);
        }
        write_json_atomic(&run.file(TRAIN_SEGMENTS_FILE), &segments)?;
        if state == RunState::Complete {
            write_train_system(&run, &segments)?;
        }
        run.set_status(state, &note)?;
        drop(lock);
        if no_curve {
            return Err(PipelineError::Invalid(format!(
                "{}: marked failed: the agent logged no evaluation (call run.log_evaluation or \
                 run.evaluate at least once)",
                run.path().display()
            )));
        }
        Ok(state)
    }
}
