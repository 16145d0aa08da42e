//! # a2perf-core
//!
//! The traits and plumbing of the A2Perf benchmark, with no domain knowledge:
//!
//! - [`Env`] / [`EnvSpec`] / [`Step`]: environments with Gymnasium semantics, stepped in place
//!   without allocation; [`VecEnv`] steps many of them over the machine's cores; [`render`]:
//!   the [`Frame`]s of [`Env::render`] and the small rasterizer that draws them.
//! - [`Space`], [`Observation`], [`Action`]: discrete (with action masks), box and dict spaces;
//!   [`Tensor`]s hold their values in the box's [`DType`] (`int32` ids, `float32` features).
//! - [`Policy`], [`Algorithm`], [`TrainingContext`]: how algorithms train and report their curves
//!   and checkpoints; [`rollout()`](crate::rollout::rollout) runs one episode; [`Checkpoint`]:
//!   a serialised policy in its self-checking container ([`checkpoint`]); [`CancelToken`]: Ctrl-C
//!   and SIGTERM reaching the training runs.
//! - [`Meter`]: anything that measures a phase, composable with [`MeterSet`].
//! - [`Registry`]: environment ids and algorithm names mapped to typed constructors.
//! - [`RngStream`]: every random number, keyed by (seed, purpose); [`hash`]: FNV-1a, the one
//!   stable hash of provenance records, checksums and purpose keys.
//! - [`config`]: RON experiment files with includes, overrides and precise errors.
//! - [`results`]: atomic result files and resumable run directories.
//! - [`resume`]: resume points, so that an interrupted training run continues exactly where it
//!   stopped ([`TrainingContext::take_resume_state`], [`TrainingContext::progress_resumable`]).
//! - [`alloc_count`]: a counting global allocator, to check that hot paths allocate nothing.
//! - [`copy`]: slice copies that avoid the C library's slow `rep movsb` case.
//! - [`crew`]: worker threads for lockstep jobs (each part pinned to one thread, spin-then-sleep
//!   between jobs), which the Python package's vector environments step with.
//!
//! ```
//! use a2perf_core::{RngStream, Space};
//! let mut rng = RngStream::new(0, "example");
//! let action = Space::Discrete { n: 4 }.sample(&mut rng, Some(&[false, true, false, false]));
//! assert_eq!(action, Some(a2perf_core::Action::Discrete(1)));
//! ```
//!
//! It deliberately does not contain environments, metrics or learning code: those live in the
//! domain, metrics and baselines crates, which depend on this one.

#![warn(missing_docs)]

pub mod alloc_count;
pub mod bytes;
pub mod cancel;
pub mod checkpoint;
pub mod config;
pub mod copy;
pub mod crew;
pub mod curve;
pub mod env;
pub mod error;
pub mod hash;
pub mod meter;
pub mod policy;
pub mod registry;
pub mod render;
pub mod replay;
pub mod results;
pub mod resume;
pub mod rng;
pub mod rollout;
pub mod space;
pub mod tensor;
pub mod time_split;
pub mod training;
pub mod value;
pub mod vec_env;

pub use cancel::CancelToken;
pub use checkpoint::Checkpoint;
pub use config::{ConfigError, Experiment, Override};
pub use curve::{CurvePoint, LearningCurve};
pub use env::{Env, EnvError, EnvSpec, Info, Step};
pub use error::{PolicyError, RunError};
pub use meter::{Measurement, Meter, MeterError, MeterReport, MeterSet, Provenance};
pub use policy::{ActMode, Policy, PolicyLoader, RandomPolicy};
pub use registry::{
    AlgorithmConstructor, AlgorithmEntry, EnvConstructor, EnvEntry, Registry, RegistryError,
    TaskRef,
};
pub use render::Frame;
pub use results::{
    RunDir, RunState, RunStatus, write_atomic, write_json_atomic, write_json_compact_atomic,
};
pub use resume::{NewestResume, ResumeDir, ResumePoint, ResumeWrite, TrainingProgress};
pub use rng::{RngState, RngStream};
pub use rollout::{Episode, Transition, rollout};
pub use space::{Action, Observation, Space};
pub use tensor::{DType, Tensor, TensorData};
pub use time_split::{TimePart, TimeSplit};
pub use training::{
    Algorithm, CheckpointSink, Control, DirectoryCheckpoints, DiscardCheckpoints, EnvFactory,
    TrainingContext, TrainingSettings,
};
pub use value::{ParamError, ParamKind, ParamSpec, Params, Value, did_you_mean};
pub use vec_env::{EpisodeSnapshot, VecEnv, VecEnvSnapshot, VecStep, observation_hash};
