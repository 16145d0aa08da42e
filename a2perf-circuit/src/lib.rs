//! a2perf-circuit (under construction).
