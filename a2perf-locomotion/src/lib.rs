//! a2perf-locomotion (under construction).
