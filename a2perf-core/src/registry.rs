//! Maps environment ids and algorithm names to constructors with typed parameters.
//!
//! Each domain crate exports `register(&mut Registry)`; the CLI composes them. A user's own crate
//! can register its algorithm the same way.

use std::collections::BTreeMap;
use std::sync::Arc;

use crate::env::{Env, EnvError};
use crate::error::RunError;
use crate::policy::PolicyLoader;
use crate::training::Algorithm;
use crate::value::{ParamError, ParamSpec, Params, Value, did_you_mean};

/// Constructor of an environment from resolved parameters.
pub type EnvConstructor = Arc<dyn Fn(&Params) -> Result<Box<dyn Env>, EnvError> + Send + Sync>;

/// Constructor of an algorithm from resolved hyperparameters.
pub type AlgorithmConstructor =
    Arc<dyn Fn(&Params) -> Result<Box<dyn Algorithm>, RunError> + Send + Sync>;

/// A registered environment.
#[derive(Clone)]
pub struct EnvEntry {
    /// Id, e.g. `WebNavigation-Difficulty-01-v0`.
    pub id: String,
    /// Domain name (`circuit_training`, `web_navigation`, `quadruped_locomotion`, …).
    pub domain: String,
    /// One-line description.
    pub summary: String,
    /// Accepted parameters with defaults.
    pub params: Vec<ParamSpec>,
    /// Constructor.
    pub make: EnvConstructor,
}

/// A registered algorithm.
#[derive(Clone)]
pub struct AlgorithmEntry {
    /// Name, e.g. `ppo`.
    pub name: String,
    /// One-line description.
    pub summary: String,
    /// Hyperparameters with defaults.
    pub params: Vec<ParamSpec>,
    /// Constructor.
    pub make: AlgorithmConstructor,
    /// Rebuilds a trained policy from a checkpoint.
    pub load_policy: PolicyLoader,
}

/// A task of a generalization suite: an environment id and parameter overrides.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskRef {
    /// Short task name (`dog_pace`).
    pub name: String,
    /// Environment id.
    pub env_id: String,
    /// Parameters that differ from the id's defaults.
    pub params: BTreeMap<String, Value>,
}

/// Errors looking things up in the registry.
#[derive(Debug, thiserror::Error)]
pub enum RegistryError {
    /// No environment with that id.
    #[error("unknown environment `{id}`{}", hint.as_ref().map(|h| format!(" (did you mean `{h}`?)")).unwrap_or_default())]
    UnknownEnv {
        /// The id asked for.
        id: String,
        /// The closest registered id.
        hint: Option<String>,
    },
    /// No algorithm with that name.
    #[error("unknown algorithm `{name}`{}", hint.as_ref().map(|h| format!(" (did you mean `{h}`?)")).unwrap_or_default())]
    UnknownAlgorithm {
        /// The name asked for.
        name: String,
        /// The closest registered name.
        hint: Option<String>,
    },
    /// Bad parameters.
    #[error("{context}: {source}")]
    Param {
        /// Which environment or algorithm.
        context: String,
        /// The problem.
        source: ParamError,
    },
    /// The environment constructor failed.
    #[error("{id}: {source}")]
    Env {
        /// The environment id.
        id: String,
        /// The error.
        source: EnvError,
    },
    /// The algorithm constructor failed.
    #[error("{name}: {source}")]
    Algorithm {
        /// The algorithm name.
        name: String,
        /// The error.
        source: RunError,
    },
}

/// The registry of environments, algorithms and generalization suites.
///
/// ```
/// use a2perf_core::Registry;
/// let reg = Registry::new();
/// assert!(reg.env("Nope-v0").is_err());
/// ```
#[derive(Clone, Default)]
pub struct Registry {
    envs: BTreeMap<String, EnvEntry>,
    algorithms: BTreeMap<String, AlgorithmEntry>,
    generalization: BTreeMap<String, Vec<TaskRef>>,
}

impl Registry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers (or replaces) an environment.
    pub fn register_env(&mut self, entry: EnvEntry) {
        self.envs.insert(entry.id.clone(), entry);
    }

    /// Registers (or replaces) an algorithm.
    pub fn register_algorithm(&mut self, entry: AlgorithmEntry) {
        self.algorithms.insert(entry.name.clone(), entry);
    }

    /// Sets the generalization suite of `domain`.
    pub fn register_generalization(&mut self, domain: &str, tasks: Vec<TaskRef>) {
        self.generalization.insert(domain.to_string(), tasks);
    }

    /// All environments, sorted by id.
    pub fn envs(&self) -> impl Iterator<Item = &EnvEntry> {
        self.envs.values()
    }

    /// All algorithms, sorted by name.
    pub fn algorithms(&self) -> impl Iterator<Item = &AlgorithmEntry> {
        self.algorithms.values()
    }

    /// The generalization suite of `domain` (empty when none).
    pub fn generalization(&self, domain: &str) -> &[TaskRef] {
        self.generalization.get(domain).map_or(&[], Vec::as_slice)
    }

    /// The environment registered as `id`.
    pub fn env(&self, id: &str) -> Result<&EnvEntry, RegistryError> {
        self.envs.get(id).ok_or_else(|| RegistryError::UnknownEnv {
            id: id.into(),
            hint: did_you_mean(id, self.envs.keys().map(String::as_str)),
        })
    }

    /// The algorithm registered as `name`.
    pub fn algorithm(&self, name: &str) -> Result<&AlgorithmEntry, RegistryError> {
        self.algorithms
            .get(name)
            .ok_or_else(|| RegistryError::UnknownAlgorithm {
                name: name.into(),
                hint: did_you_mean(name, self.algorithms.keys().map(String::as_str)),
            })
    }

    /// Resolves `params` for environment `id` (defaults filled in, types checked).
    pub fn env_params(
        &self,
        id: &str,
        params: &BTreeMap<String, Value>,
    ) -> Result<Params, RegistryError> {
        let entry = self.env(id)?;
        Params::resolve(&entry.params, params).map_err(|source| RegistryError::Param {
            context: format!("environment {id}"),
            source,
        })
    }

    /// Builds environment `id` with `params`.
    pub fn make_env(
        &self,
        id: &str,
        params: &BTreeMap<String, Value>,
    ) -> Result<Box<dyn Env>, RegistryError> {
        let resolved = self.env_params(id, params)?;
        (self.env(id)?.make)(&resolved).map_err(|source| RegistryError::Env {
            id: id.into(),
            source,
        })
    }

    /// Builds algorithm `name` with hyperparameters `params`.
    pub fn make_algorithm(
        &self,
        name: &str,
        params: &BTreeMap<String, Value>,
    ) -> Result<Box<dyn Algorithm>, RegistryError> {
        let entry = self.algorithm(name)?;
        let resolved =
            Params::resolve(&entry.params, params).map_err(|source| RegistryError::Param {
                context: format!("algorithm {name}"),
                source,
            })?;
        (entry.make)(&resolved).map_err(|source| RegistryError::Algorithm {
            name: name.into(),
            source,
        })
    }
}
