//! Experiment configs: the gin analogue, in RON.
//!
//! An experiment file names the environment (id and parameters), the algorithm and its
//! hyperparameters, the seeds, the budgets and the metric settings:
//!
//! ```ron
//! (
//!     include: ["../base.ron"],
//!     name: "web_ppo",
//!     env: (id: "WebNavigation-Difficulty-01-v0", num_websites: 1),
//!     algorithm: (name: "ppo", learning_rate: 3e-4),
//!     seeds: [0, 1, 2],
//!     training: (total_env_steps: 100000),
//! )
//! ```
//!
//! Loading one ([`load`]) parses the file and its includes with a small RON parser that keeps the
//! line and column of every key and value ([`parse_str`], [`Node`]), merges the layers (includes in
//! order, then the file, then the `--set` [`Override`]s; see the merge rule below), and checks the
//! result against the fixed schema ([`section_schema`]) and the [`Registry`]'s parameter specs for
//! the chosen environment and algorithm. The outcome is an [`Experiment`] holding every value in
//! force, defaults included: the *operative config*, rendered by [`Experiment::to_ron_string`] and
//! written next to results by [`Experiment::write_operative`]. Every problem is a [`ConfigError`]
//! naming the file, line and column (or the `--set` argument) and the key, with a did-you-mean
//! suggestion for typos.
//!
//! ## Merge rule
//!
//! 1. A file's `include`s (paths relative to the including file) are merged in the order listed:
//!    a later include overrides an earlier one, and the including file overrides all of them.
//! 2. `--set` overrides form one last layer; when the same key is set twice, the last one wins.
//! 3. Structs merge key by key, recursively; lists and scalars replace what is below them.
//! 4. Exception: the `env` and `algorithm` sections are replaced wholesale when the upper layer
//!    names a different `id` / `name` than the layer below, because one environment's parameters
//!    (or one algorithm's hyperparameters) mean nothing to another.
//!
//! ```
//! use a2perf_core::{Registry, config::{self, Override}};
//! let dir = tempfile::tempdir().unwrap();
//! std::fs::write(dir.path().join("base.ron"), "(seeds: [0, 1], training: (num_envs: 4))").unwrap();
//! std::fs::write(
//!     dir.path().join("exp.ron"),
//!     "(include: [\"base.ron\"], training: (total_env_steps: 5000))",
//! ).unwrap();
//! let set = [Override::parse("seeds=[7]").unwrap()];
//! let exp = config::load(&dir.path().join("exp.ron"), &set, &Registry::new()).unwrap();
//! assert_eq!((exp.seeds.as_slice(), exp.training.num_envs, exp.training.total_env_steps), (&[7][..], 4, 5000));
//! assert_eq!(exp.name, "exp");
//!
//! let err = config::load(&dir.path().join("exp.ron"), &[Override::parse("trainig.num_envs=2").unwrap()], &Registry::new())
//!     .unwrap_err();
//! assert_eq!(err.to_string(), "--set trainig.num_envs=2: unknown key `trainig` (did you mean `training`?)");
//! ```

mod error;
mod expand;
mod experiment;
mod layers;
mod profile;
mod schema;
mod syntax;

#[cfg(test)]
mod tests;

use std::path::Path;

pub use error::{ConfigError, Location};
pub use experiment::{
    AlgorithmConfig, EnergyMethod, EnvConfig, Experiment, GeneralizationSettings,
    InferenceSettings, MetricSettings, OPERATIVE_CONFIG_FILE, ObservationSource, OutputSettings,
    ReliabilityDefinition, section_schema,
};
pub use layers::Override;
pub use profile::Profile;
pub use syntax::{Field, Node, NodeValue, parse_str};

use crate::registry::Registry;

fn default_name(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "experiment".to_string())
}

/// Loads the experiment file `path` with its includes, applies `overrides` and checks the result
/// against the schema and `registry`.
pub fn load(
    path: &Path,
    overrides: &[Override],
    registry: &Registry,
) -> Result<Experiment, ConfigError> {
    let tree = load_tree(path, overrides)?;
    Experiment::from_tree(&tree, &default_name(path), registry)
}

/// Like [`load`], for text that is not (or not yet) in a file: `path` names it in messages, gives
/// the default experiment name, and is what its includes are relative to.
///
/// ```
/// use a2perf_core::{Registry, config};
/// let exp = config::load_str("(seeds: [3])", "inline.ron".as_ref(), &[], &Registry::new()).unwrap();
/// assert_eq!(exp.seeds, [3]);
/// let err = config::load_str("(seeds: [3],\n seed: 1)", "inline.ron".as_ref(), &[], &Registry::new()).unwrap_err();
/// assert_eq!(err.to_string(), "inline.ron:2:2: unknown key `seed` (did you mean `seeds`?)");
/// ```
pub fn load_str(
    text: &str,
    path: &Path,
    overrides: &[Override],
    registry: &Registry,
) -> Result<Experiment, ConfigError> {
    let mut tree = layers::load_text_tree(text, path)?;
    layers::apply_overrides(&mut tree, overrides);
    Experiment::from_tree(&tree, &default_name(path), registry)
}

/// The merged tree of `path`, its includes and `overrides`, before schema checks (what [`load`]
/// validates). Each node keeps the location of the layer that set it.
pub fn load_tree(path: &Path, overrides: &[Override]) -> Result<Node, ConfigError> {
    let mut tree = layers::load_file_tree(path)?;
    layers::apply_overrides(&mut tree, overrides);
    Ok(tree)
}

impl Experiment {
    /// [`load`] with overrides given as `dotted.path=value` strings (as on the command line).
    pub fn load(
        path: &Path,
        overrides: &[impl AsRef<str>],
        registry: &Registry,
    ) -> Result<Self, ConfigError> {
        let overrides = overrides
            .iter()
            .map(|o| Override::parse(o.as_ref()))
            .collect::<Result<Vec<_>, _>>()?;
        load(path, &overrides, registry)
    }
}
