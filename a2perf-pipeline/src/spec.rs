//! What a run's plan says, as `run.json` records it: the task, the algorithm, the profile in
//! force, and the inference and generalization settings. The planner ([`crate::plan`]) fills
//! these in; the run directory ([`crate::run_dir`]) stores them; the phases and the report read
//! them back.

use std::collections::BTreeMap;
use std::sync::Arc;

use a2perf_core::Value;
use serde::{Deserialize, Serialize};

/// A task: an environment id with its parameters, under a short name used in run directories.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskSpec {
    /// Short name (`dog_pace`, or the environment id when the config gives none).
    pub name: String,
    /// Registered environment id.
    pub env_id: String,
    /// Environment parameters (resolved in `run.json`).
    pub env_params: BTreeMap<String, Value>,
    /// The profile the config named, with the switches it gives this environment (absent in
    /// runs without a profile and in `run.json` files written before profiles existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub profile: Option<ProfileRecord>,
}

/// A profile as recorded with a run: its name and every switch it gives the run's environment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileRecord {
    /// Profile name (`a2perf`).
    pub name: String,
    /// The switches, sorted by parameter.
    pub switches: Vec<ProfileSwitch>,
}

impl ProfileRecord {
    /// The switches in force (not overridden by a config layer).
    pub fn in_force(&self) -> impl Iterator<Item = &ProfileSwitch> {
        self.switches.iter().filter(|s| s.overridden.is_none())
    }
}

/// One environment parameter a profile sets.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfileSwitch {
    /// Environment parameter (`infeasible_reward`).
    pub param: String,
    /// The profile's value.
    pub value: Value,
    /// The value in force instead, when a config layer or `--set` overrode the switch.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub overridden: Option<Value>,
}

impl std::fmt::Display for ProfileSwitch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match &self.overridden {
            None => write!(f, "env.{} = {}", self.param, self.value),
            Some(v) => write!(
                f,
                "env.{} = {v} (overrides the profile's {})",
                self.param, self.value
            ),
        }
    }
}

/// An algorithm and its hyperparameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AlgorithmSpec {
    /// Registered name.
    pub name: String,
    /// Hyperparameters (resolved in `run.json`).
    pub params: BTreeMap<String, Value>,
}

/// Which observations the inference timer uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObservationSource {
    /// Every `act` call made during the rollouts is timed (what a deployed policy sees).
    Rollouts,
    /// `timing_samples` observations drawn uniformly from the observation space, as the original
    /// harness did (the rollout calls are timed too, for comparison).
    Random,
}

/// How `infer` measures a policy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InferenceSettings {
    /// Greedy rollouts (the paper: 100).
    pub episodes: usize,
    /// Calls timed on random observations when `observation_source` is `random`.
    pub timing_samples: usize,
    /// Which observations the reported inference time is measured on.
    pub observation_source: ObservationSource,
}

impl Default for InferenceSettings {
    fn default() -> Self {
        Self {
            episodes: 100,
            timing_samples: 1000,
            observation_source: ObservationSource::Rollouts,
        }
    }
}

/// How `generalize` measures a policy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneralizationSettings {
    /// Greedy rollouts per task (the paper: 100).
    pub episodes: usize,
    /// The tasks to roll out on, resolved when the run was planned. `None` (plans built without a
    /// config, and `run.json` files written before suites were configurable): the registry's
    /// suite for the run's domain at `generalize` time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub suite: Option<GeneralizationSuite>,
}

impl Default for GeneralizationSettings {
    fn default() -> Self {
        Self {
            episodes: 100,
            suite: None,
        }
    }
}

/// A generalization suite and where it came from. The generalization score is a sum over its
/// tasks, so two scores are comparable only over the same suite.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneralizationSuite {
    /// Where the list came from.
    pub source: SuiteSource,
    /// The tasks, in order.
    pub tasks: Vec<GeneralizationTask>,
}

/// Where a run's generalization suite came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SuiteSource {
    /// The experiment config's `generalization.tasks`.
    Config,
    /// The profile's suite for the domain.
    Profile,
    /// The registry's suite for the domain.
    Registry,
}

impl SuiteSource {
    /// Display name.
    pub fn label(self) -> &'static str {
        match self {
            SuiteSource::Config => "the config",
            SuiteSource::Profile => "the profile",
            SuiteSource::Registry => "the registry",
        }
    }
}

/// One task of a generalization suite.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GeneralizationTask {
    /// Task name (`difficulty_level_1_num_websites_5`).
    pub name: String,
    /// Environment id.
    pub env_id: String,
    /// Parameters the task sets, the profile's switches included (the others take the
    /// environment's defaults).
    pub params: BTreeMap<String, Value>,
}

impl From<&a2perf_core::TaskRef> for GeneralizationTask {
    fn from(t: &a2perf_core::TaskRef) -> Self {
        Self {
            name: t.name.clone(),
            env_id: t.env_id.clone(),
            params: t.params.clone(),
        }
    }
}

/// Writes the operative config of an experiment into a run directory (given as argument).
pub type OperativeWriter =
    Arc<dyn Fn(&std::path::Path) -> std::result::Result<(), String> + Send + Sync>;
