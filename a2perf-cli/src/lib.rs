//! # a2perf-cli
//!
//! The benchmark pipelines behind the `a2perf` command, usable as a library so that a participant's
//! own binary (or a test) can run them with its own [`Registry`](a2perf_core::Registry):
//!
//! - [`pipeline::train`]: one run per (task, algorithm, seed), resumable, shardable;
//! - [`pipeline::infer`]: rollouts and per-call inference time of a trained policy;
//! - [`pipeline::generalize`]: returns on every task of the domain's generalization suite;
//! - [`pipeline::collect`]: checkpoint evaluation, expertise levels and offline datasets;
//! - [`pipeline::report`]: the paper's four-category tables, plots and a leaderboard entry.
//!
//! ```
//! use a2perf_cli::pipeline::Shard;
//! let shard: Shard = "1/4".parse().unwrap();
//! assert!(shard.contains(5) && !shard.contains(4));
//! ```
//!
//! It deliberately does not schedule work across machines: `--shard i/N` lets an existing batch
//! system (Slurm job arrays, Kubernetes indexed jobs) spread a sweep, and `report` merges the
//! result directories.

#![warn(missing_docs)]

pub mod pipeline;
pub mod registry;
