//! a2perf-web (under construction).
