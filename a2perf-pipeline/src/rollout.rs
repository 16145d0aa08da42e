//! Rollouts whose errors say where they failed: the run, the episode and the step.

use a2perf_core::{Checkpoint, Env, Policy};

use crate::error::{PipelineError, Result};

/// A policy that counts its calls, so that a failed rollout can say at which step it failed.
struct CountedPolicy<'a> {
    inner: &'a mut dyn Policy,
    calls: usize,
}

impl Policy for CountedPolicy<'_> {
    fn act(
        &mut self,
        obs: &a2perf_core::Observation,
        mode: a2perf_core::ActMode,
    ) -> std::result::Result<a2perf_core::Action, a2perf_core::PolicyError> {
        self.calls += 1;
        self.inner.act(obs, mode)
    }
    fn checkpoint(&self) -> std::result::Result<Checkpoint, a2perf_core::PolicyError> {
        self.inner.checkpoint()
    }
}

/// [`a2perf_core::rollout`] whose error names the run (`run()`), the episode and the step.
pub(crate) fn located_rollout(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    seed: u64,
    mode: a2perf_core::ActMode,
    record: bool,
    episode: usize,
    run: impl FnOnce() -> String,
) -> Result<a2perf_core::Episode> {
    let mut counted = CountedPolicy {
        inner: policy,
        calls: 0,
    };
    a2perf_core::rollout(env, &mut counted, seed, mode, record).map_err(|source| {
        PipelineError::Rollout {
            run: run(),
            episode,
            step: counted.calls.saturating_sub(1),
            source,
        }
    })
}
