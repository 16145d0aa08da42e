//! # a2perf-pipeline
//!
//! The benchmark pipelines as a library: plan, train, infer, generalize, collect and report,
//! plus the registry of every built-in environment and algorithm. The `a2perf` command
//! (`a2perf-cli`) and the Python package (`python/`) are two front ends over it; a participant's
//! own binary or test can call it with its own [`Registry`](a2perf_core::Registry):
//!
//! - [`train()`]: one run per (task, algorithm, seed), resumable, shardable;
//! - [`infer_run`]: rollouts and per-call inference time of a trained policy;
//! - [`generalize_run`]: returns on every task of the domain's generalization suite;
//! - [`collect`]: checkpoint evaluation, expertise levels and offline datasets;
//! - [`report`]: the paper's four-category tables, plots and a leaderboard entry;
//! - [`run_experiments`]: all of the above in order, skipping what is already on disk;
//! - [`external`]: runs trained outside the benchmark's algorithms (a Python agent), recorded
//!   like built-in ones and rolled out through a [`PolicySource`].
//!
//! ```
//! use a2perf_pipeline::Shard;
//! let shard: Shard = "1/4".parse().unwrap();
//! assert!(shard.contains(5) && !shard.contains(4));
//! ```
//!
//! It deliberately does not schedule work across machines: a shard (`--shard i/N`) lets an
//! existing batch system (Slurm job arrays, Kubernetes indexed jobs) spread a sweep, and
//! [`report`] merges the result directories. It prints nothing but progress bars (when asked):
//! messages are the front ends' business.
//!
//! Every pipeline works on plain directories. An experiment directory
//! `OUTPUT/EXPERIMENT_NAME/` holds one run directory per (task, algorithm, seed), named
//! `<task>__<algorithm>__seed<k>`, with these files (all written atomically), whose names,
//! models, readers and writers [`run_dir`] owns:
//!
//! | file | written by | contents |
//! |---|---|---|
//! | `status.json` | train | `running`, `interrupted`, `failed` or `complete` (reruns skip complete runs and continue the others) |
//! | `run.json` | train | [`RunRecord`]: task, resolved parameters, seed, settings |
//! | `operative_config.ron` | train | every config value in force (when a config file was used) |
//! | `system_info.json` | train | [`SystemInfo`] of the machine |
//! | `curve.csv`, `curve.json` | train | evaluation return against environment steps |
//! | `train_system.json` | train | system meters over the whole training (all segments) |
//! | `train_segments.json` | train | each training segment (process): start step, outcome, meters, resume points written |
//! | `checkpoints/step_*.ckpt` | train | checkpoints at the configured interval |
//! | `resume/step_*.resume` | train | the newest two resume points, while the run is unfinished |
//! | `policy.ckpt` | train | the final policy |
//! | `inference.json` | infer | rollout returns, per-call inference time, meters |
//! | `generalization.json` | generalize | per-task mean returns and their sum |
//! | `collect/` | collect | checkpoint evaluations, expertise levels, datasets |
//! | `train.lock` | train | the training lock ([`run_lock`]): the pid and host of the process training the run, empty when none does |

#![warn(missing_docs)]

// The README's Rust example runs as a doc test of this crate (the one that depends on every
// domain), so the front page cannot drift from the API.
#[cfg(doctest)]
#[doc = include_str!("../../README.md")]
struct ReadmeExamples;

pub use a2perf_core::CancelToken;

pub mod arrow;
pub mod bench;
pub mod bundle;
pub mod collect;
pub mod dataset;
mod error;
pub mod external;
pub mod generalize;
pub mod infer;
pub mod isolate;
pub mod meters;
pub mod minari;
mod outcome;
pub mod phase;
pub mod plan;
mod pool;
pub mod progress;
pub mod registry;
pub mod report;
mod rollout;
pub mod run;
pub mod run_dir;
pub mod run_lock;
pub mod spec;
pub mod stats;
pub mod sysinfo;
pub mod train;

pub use dataset::DatasetProvenance;
pub(crate) use error::io_err;
pub use error::{PipelineError, Result};
pub use generalize::{GeneralizationResults, generalize_run, generalize_run_with};
pub use infer::{InferOptions, InferenceResults, infer_run, infer_run_with};
pub use phase::{MeterFactory, MetricSettings};
pub use plan::{
    AlgorithmSpec, ExperimentPlan, GeneralizationSettings, GeneralizationSuite, GeneralizationTask,
    InferenceSettings, LoadedPlans, ObservationSource, ProfileRecord, ProfileSwitch, RunJob, Shard,
    Suite, SuiteSource, TaskSpec, check_dir_name, from_experiment, grid, load_plans, parse_seeds,
};
pub use pool::for_each;
pub use run::{RunEvent, RunOptions, TrainTask, expand_runs, run_experiments};
pub use run_dir::{
    CHECKPOINT_DIR, CURVE_CSV, CURVE_JSON, ExternalAgent, GENERALIZATION_FILE, INFERENCE_FILE,
    LoadedRun, OPERATIVE_FILE, POLICY_FILE, PolicySource, RESUME_DIR, RUN_FILE, RUN_FORMAT_VERSION,
    RegistryPolicies, RunRecord, SUBMISSION_CODE_DIR, SUBMISSION_FILES_DIR, SYSTEM_INFO_FILE,
    TRAIN_SEGMENTS_FILE, TRAIN_SYSTEM_FILE, find_runs, load_checkpoint_policy,
};
pub use sysinfo::SystemInfo;
pub use train::{RunOutcome, RunReport, TrainOptions, TrainSummary, train, train_one, train_run};
