//! Where a training run's wall time goes: stepping the environments, choosing actions,
//! learning, evaluation and checkpoint I/O (issue 38). The training context times evaluation
//! and I/O itself; an algorithm times its own acting, stepping and learning with
//! [`TimeSplit::time`]. What no part claims (setup, bookkeeping) is the rest of the phase's
//! wall clock.
//!
//! ```
//! use a2perf_core::time_split::{TimePart, TimeSplit};
//! let mut split = TimeSplit::default();
//! let x = split.time(TimePart::Learn, || (0..1000u64).sum::<u64>());
//! assert_eq!(x, 499_500);
//! assert!(split.learn_s >= 0.0 && split.total() == split.learn_s);
//! split.add(TimePart::Env, 0.5);
//! assert_eq!(split.env_s, 0.5);
//! ```

use std::time::Instant;

use serde::{Deserialize, Serialize};

/// One part of a training run's time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimePart {
    /// Stepping the training environments (and resetting them).
    Env,
    /// The policy's forward passes that choose the training actions.
    Act,
    /// Learning: batching, forward and backward passes, the optimiser (replay sampling included).
    Learn,
    /// Greedy evaluation episodes (the learning curve's points).
    Evaluation,
    /// Writing checkpoints and resume points.
    Io,
}

/// Wall seconds per [`TimePart`] over one training segment.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TimeSplit {
    /// [`TimePart::Env`].
    pub env_s: f64,
    /// [`TimePart::Act`].
    pub act_s: f64,
    /// [`TimePart::Learn`].
    pub learn_s: f64,
    /// [`TimePart::Evaluation`].
    pub evaluation_s: f64,
    /// [`TimePart::Io`].
    pub io_s: f64,
}

impl TimeSplit {
    /// Adds `seconds` to `part`.
    pub fn add(&mut self, part: TimePart, seconds: f64) {
        *self.slot(part) += seconds;
    }

    /// Runs `f`, adding its wall time to `part`.
    pub fn time<T>(&mut self, part: TimePart, f: impl FnOnce() -> T) -> T {
        let t = Instant::now();
        let out = f();
        self.add(part, t.elapsed().as_secs_f64());
        out
    }

    /// Seconds claimed by every part.
    pub fn total(&self) -> f64 {
        self.env_s + self.act_s + self.learn_s + self.evaluation_s + self.io_s
    }

    /// The parts with their names, in table order.
    pub fn parts(&self) -> [(&'static str, f64); 5] {
        [
            ("env", self.env_s),
            ("act", self.act_s),
            ("learn", self.learn_s),
            ("evaluation", self.evaluation_s),
            ("io", self.io_s),
        ]
    }

    /// The sum of two splits (segments of one run, or runs of one group).
    pub fn plus(&self, other: &TimeSplit) -> TimeSplit {
        TimeSplit {
            env_s: self.env_s + other.env_s,
            act_s: self.act_s + other.act_s,
            learn_s: self.learn_s + other.learn_s,
            evaluation_s: self.evaluation_s + other.evaluation_s,
            io_s: self.io_s + other.io_s,
        }
    }

    fn slot(&mut self, part: TimePart) -> &mut f64 {
        match part {
            TimePart::Env => &mut self.env_s,
            TimePart::Act => &mut self.act_s,
            TimePart::Learn => &mut self.learn_s,
            TimePart::Evaluation => &mut self.evaluation_s,
            TimePart::Io => &mut self.io_s,
        }
    }
}
