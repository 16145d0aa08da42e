//! a2perf-baselines (under construction).
