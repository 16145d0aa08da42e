//! A fixed-capacity ring buffer of transitions for off-policy algorithms.

use a2perf_core::{Observation, PolicyError, RngStream};

use crate::batch::{ObsBatch, ObsLayout};

/// Uniform replay of `(obs, action, reward, next_obs, terminated)`.
///
/// Observations are stored as packed rows (not `Observation` values), so memory is
/// `capacity × 2 × observation size` floats; once full, the oldest transition is overwritten.
#[derive(Clone, Debug)]
pub struct ReplayBuffer {
    obs: ObsBatch,
    next: ObsBatch,
    act_d: Vec<usize>,
    act_c: Vec<f32>,
    act_dim: usize,
    rewards: Vec<f32>,
    terminated: Vec<bool>,
    capacity: usize,
    pos: usize,
    size: usize,
}

/// A sampled minibatch.
#[derive(Clone, Debug)]
pub struct ReplaySample {
    /// Observations.
    pub obs: ObsBatch,
    /// Next observations.
    pub next: ObsBatch,
    /// Discrete actions.
    pub act_d: Vec<usize>,
    /// Continuous actions `[B, act_dim]`.
    pub act_c: Vec<f32>,
    /// Rewards.
    pub rewards: Vec<f32>,
    /// Whether the next state is terminal (no bootstrap).
    pub terminated: Vec<bool>,
}

impl ReplaySample {
    /// Empty sample storage for `layout`.
    pub fn new(layout: &ObsLayout) -> Self {
        Self {
            obs: ObsBatch::new(layout),
            next: ObsBatch::new(layout),
            act_d: Vec::new(),
            act_c: Vec::new(),
            rewards: Vec::new(),
            terminated: Vec::new(),
        }
    }
}

impl ReplayBuffer {
    /// A buffer of `capacity` transitions (`act_dim` = 0 for discrete actions).
    pub fn new(layout: &ObsLayout, capacity: usize, act_dim: usize) -> Self {
        let capacity = capacity.max(1);
        Self {
            obs: ObsBatch::new(layout),
            next: ObsBatch::new(layout),
            act_d: vec![0; capacity],
            act_c: vec![0.0; capacity * act_dim],
            act_dim,
            rewards: vec![0.0; capacity],
            terminated: vec![false; capacity],
            capacity,
            pos: 0,
            size: 0,
        }
    }

    /// Stored transitions.
    pub fn len(&self) -> usize {
        self.size
    }

    /// Whether nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.size == 0
    }

    /// Adds a transition whose observations are row `row` of `obs` / `next` batches.
    #[allow(clippy::too_many_arguments)]
    pub fn push_rows(
        &mut self,
        obs: &ObsBatch,
        row: usize,
        next: &Observation,
        act_d: usize,
        act_c: &[f32],
        reward: f32,
        terminated: bool,
    ) -> Result<(), PolicyError> {
        let i = self.pos;
        if self.obs.len() <= i {
            self.obs.resize(i + 1);
            self.next.resize(i + 1);
        }
        self.obs.copy_row(i, obs, row);
        self.next.write_row(i, next)?;
        self.act_d[i] = act_d;
        self.act_c[i * self.act_dim..(i + 1) * self.act_dim].copy_from_slice(act_c);
        self.rewards[i] = reward;
        self.terminated[i] = terminated;
        self.pos = (self.pos + 1) % self.capacity;
        self.size = (self.size + 1).min(self.capacity);
        Ok(())
    }

    /// Draws `n` transitions uniformly (with replacement) into `out`.
    pub fn sample(
        &self,
        n: usize,
        rng: &mut RngStream,
        idx: &mut Vec<usize>,
        out: &mut ReplaySample,
    ) {
        idx.clear();
        idx.extend((0..n).map(|_| rng.index(self.size)));
        out.obs.gather(&self.obs, idx);
        out.next.gather(&self.next, idx);
        out.act_d.clear();
        out.act_c.clear();
        out.rewards.clear();
        out.terminated.clear();
        for &i in idx.iter() {
            out.act_d.push(self.act_d[i]);
            out.act_c
                .extend_from_slice(&self.act_c[i * self.act_dim..(i + 1) * self.act_dim]);
            out.rewards.push(self.rewards[i]);
            out.terminated.push(self.terminated[i]);
        }
    }
}
