//! # a2perf-baselines
//!
//! The A2Perf baselines — PPO, DDQN, SAC and behavioural cloning — on small, allocation-free
//! neural networks built on faer. Algorithms implement [`a2perf_core::Algorithm`] and know the
//! domains only through their observation tensors: [`model`] picks a web DOM–profile encoder, a
//! circuit per-cell scoring network, or a flat MLP from the spaces and tensor names.
//!
//! ```
//! use a2perf_core::Registry;
//! let mut reg = Registry::new();
//! a2perf_baselines::register(&mut reg);
//! assert!(reg.algorithm("ppo").is_ok());
//! assert!(reg.algorithm("sac").is_ok());
//! ```
//!
//! It deliberately does not use GPUs, autodiff or recurrent networks (the paper's web encoder has
//! an LSTM; ours scores DOM elements independently, see [`model`]), and it does not depend on
//! any domain crate.

#![warn(missing_docs)]

pub mod batch;
pub mod bc;
mod common;
pub mod dataset;
pub mod ddqn;
pub mod model;
pub mod nn;
mod obs_store;
pub mod policy;
pub mod ppo;
pub mod replay;
mod resume;
pub mod sac;

use std::sync::Arc;

use a2perf_core::{AlgorithmEntry, Checkpoint, EnvSpec, Policy, PolicyError, Registry};

pub use batch::{ObsBatch, ObsLayout};
pub use bc::Bc;
pub use dataset::{Dataset, DatasetLoader, Sample};
pub use ddqn::Ddqn;
pub use model::{DiscreteNet, NetOptions};
pub use policy::{Head, NetPolicy};
pub use ppo::Ppo;
pub use sac::Sac;

fn loader_for(name: &'static str) -> a2perf_core::PolicyLoader {
    match name {
        "ppo" => |c: &Checkpoint, s: &EnvSpec| -> Result<Box<dyn Policy>, PolicyError> {
            Ok(Box::new(NetPolicy::from_checkpoint(c, s, "ppo")?))
        },
        "ddqn" => |c: &Checkpoint, s: &EnvSpec| -> Result<Box<dyn Policy>, PolicyError> {
            Ok(Box::new(NetPolicy::from_checkpoint(c, s, "ddqn")?))
        },
        "sac" => |c: &Checkpoint, s: &EnvSpec| -> Result<Box<dyn Policy>, PolicyError> {
            Ok(Box::new(NetPolicy::from_checkpoint(c, s, "sac")?))
        },
        _ => |c: &Checkpoint, s: &EnvSpec| -> Result<Box<dyn Policy>, PolicyError> {
            Ok(Box::new(NetPolicy::from_checkpoint(c, s, "bc")?))
        },
    }
}

/// Registers PPO, DDQN, SAC and BC with their documented hyperparameters and checkpoint loaders.
pub fn register(reg: &mut Registry) {
    reg.register_algorithm(AlgorithmEntry {
        name: "ppo".into(),
        summary: "Proximal Policy Optimisation (clipped), masked discrete or Gaussian actions"
            .into(),
        params: Ppo::params(),
        make: Arc::new(|p| Ok(Box::new(Ppo::from_params(p)?))),
        load_policy: loader_for("ppo"),
    });
    reg.register_algorithm(AlgorithmEntry {
        name: "ddqn".into(),
        summary: "Double DQN with replay, target network and masked epsilon-greedy".into(),
        params: Ddqn::params(),
        make: Arc::new(|p| Ok(Box::new(Ddqn::from_params(p)?))),
        load_policy: loader_for("ddqn"),
    });
    reg.register_algorithm(AlgorithmEntry {
        name: "sac".into(),
        summary: "Soft Actor-Critic, twin Q, automatic entropy tuning (box actions)".into(),
        params: Sac::params(),
        make: Arc::new(|p| Ok(Box::new(Sac::from_params(p)?))),
        load_policy: loader_for("sac"),
    });
    reg.register_algorithm(AlgorithmEntry {
        name: "bc".into(),
        summary: "Behavioural cloning from a dataset of (observation, action) pairs".into(),
        params: Bc::params(),
        make: Arc::new(|p| Ok(Box::new(Bc::from_params(p)?))),
        load_policy: loader_for("bc"),
    });
}
