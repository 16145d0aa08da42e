//! Offline data for behavioural cloning: an in-memory [`Dataset`] of (observation, action) pairs
//! and the [`DatasetLoader`] trait through which pipelines feed it.

use std::path::{Path, PathBuf};

use a2perf_core::{ActMode, Action, Env, EnvSpec, Observation, Policy, RunError, rollout};
use serde::{Deserialize, Serialize};

/// One demonstration step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// What the demonstrator saw.
    pub observation: Observation,
    /// What it did.
    pub action: Action,
}

/// Demonstrations in memory.
///
/// ```
/// use a2perf_baselines::dataset::{Dataset, Sample};
/// use a2perf_core::{Action, Observation};
/// let mut d = Dataset::default();
/// d.samples.push(Sample { observation: Observation::flat(vec![0.0]), action: Action::Discrete(1) });
/// assert_eq!(d.len(), 1);
/// ```
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Dataset {
    /// Environment id the data was collected on, when known.
    pub env_id: Option<String>,
    /// The samples.
    pub samples: Vec<Sample>,
}

impl Dataset {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Records `episodes` episodes of `policy` (in `mode`) on `env`, seeds `seed, seed+1, …`.
    pub fn collect(
        env: &mut dyn Env,
        policy: &mut dyn Policy,
        episodes: usize,
        seed: u64,
        mode: ActMode,
    ) -> Result<Self, RunError> {
        let mut samples = Vec::new();
        for e in 0..episodes {
            let ep = rollout(env, policy, seed.wrapping_add(e as u64), mode, true)?;
            samples.extend(ep.transitions.into_iter().map(|t| Sample {
                observation: t.observation,
                action: t.action,
            }));
        }
        Ok(Self {
            env_id: Some(env.spec().id.clone()),
            samples,
        })
    }

    /// Reads a dataset written by [`save_json`](Self::save_json).
    pub fn load_json(path: &Path) -> Result<Self, DatasetError> {
        let bytes = std::fs::read(path).map_err(|e| DatasetError::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        serde_json::from_slice(&bytes).map_err(|e| DatasetError::Malformed {
            path: path.to_path_buf(),
            reason: format!("line {}, column {}: {e}", e.line(), e.column()),
        })
    }

    /// Writes the dataset as JSON (atomically).
    pub fn save_json(&self, path: &Path) -> Result<(), DatasetError> {
        a2perf_core::write_json_atomic(path, self).map_err(|e| DatasetError::Malformed {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })
    }
}

/// Errors reading datasets.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// The file is not a dataset.
    #[error("{}: {reason}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The data does not fit the environment.
    #[error("dataset does not fit environment `{env}`: {reason}")]
    Mismatch {
        /// Environment id.
        env: String,
        /// What is wrong.
        reason: String,
    },
}

/// Supplies a dataset for an environment (pipelines implement it to feed offline data, e.g.
/// from a Minari-style collection).
pub trait DatasetLoader: Send + Sync {
    /// The dataset for `spec`.
    fn load(&self, spec: &EnvSpec) -> Result<Dataset, DatasetError>;
}

impl DatasetLoader for Dataset {
    fn load(&self, _spec: &EnvSpec) -> Result<Dataset, DatasetError> {
        Ok(self.clone())
    }
}

/// Loads a JSON dataset file (see [`Dataset::save_json`]).
#[derive(Clone, Debug)]
pub struct JsonDatasetFile(pub PathBuf);

impl DatasetLoader for JsonDatasetFile {
    fn load(&self, _spec: &EnvSpec) -> Result<Dataset, DatasetError> {
        Dataset::load_json(&self.0)
    }
}
