//! a2perf-metrics (under construction).
