//! # a2perf-metrics
//!
//! The metrics of the A2Perf benchmark, usable on their own to score your own training logs.
//!
//! - [`a2perf`]: the seven reliability metrics exactly as A2Perf computed its paper tables
//!   (dispersion across/within runs, short/long-term risk, risk across runs, dispersion and risk
//!   across rollouts), each with the direction that is better.
//! - [`chan2019`]: the `rl-reliability-metrics` library definitions (windows in timepoint units,
//!   detrending, normalisation, IQR/MAD/std, CVaR variants, median performance, rollout metrics)
//!   and [`chan2019_stats`]: per-task rankings, permutation tests, bootstrap intervals on mean
//!   ranks, Benjamini–Yekutieli and Bonferroni thresholds.
//! - [`rliable`]: IQM, mean, median, optimality gap, probability of improvement, stratified
//!   bootstrap confidence intervals and performance profiles.
//! - [`filter`]: SciPy-compatible Butterworth design and `filtfilt`.
//! - [`numeric`]: NumPy-compatible percentiles, IQR, CVaR, ranks.
//! - [`bootstrap`]: the percentile bootstrap of `a2perf report` (one sequential stream).
//! - [`application`]: returns summaries, generalization, training sample cost, expertise levels.
//! - [`system`]: meters for RAM, CPU/RAM energy (RAPL or CodeCarbon-style estimates), emissions,
//!   `emissions.csv` and inference time, implementing [`a2perf_core::Meter`]; [`gpu`]: GPU
//!   energy through NVML with the optional `nvml` cargo feature, otherwise reported absent.
//! - [`csv`]: reading your own curves, rollouts and scores with line-numbered errors.
//!
//! ```
//! use a2perf_metrics::{a2perf, Curve};
//! let runs: Vec<Curve> = (0..5)
//!     .map(|j| Curve::from_values((0..50).map(|t| 0.02 * t as f64 + 0.1 * ((t + j) % 3) as f64).collect()).unwrap())
//!     .collect();
//! let r = a2perf::training_reliability(&runs).unwrap();
//! assert!(r.long_term_risk >= 0.0);
//! let iqm = a2perf_metrics::rliable::iqm_of(&[1.0, 2.0, 3.0, 4.0]);
//! assert_eq!(iqm, 2.5);
//! ```
//!
//! It deliberately does not run environments, train agents or plot: it only turns curves, returns
//! and scores into numbers. It depends on `a2perf-core` and small crates only (no physics,
//! browsers, networks or numeric frameworks).

#![warn(missing_docs)]

pub mod a2perf;
pub mod application;
pub mod bootstrap;
pub mod chan2019;
pub mod chan2019_stats;
pub mod csv;
pub mod curve;
pub mod filter;
pub mod gpu;
pub mod numeric;
pub mod rliable;
pub mod system;

pub use curve::{Curve, CurveError};
pub use numeric::{Direction, Tail};
