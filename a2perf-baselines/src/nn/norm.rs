//! Running statistics for observation and reward normalisation.

use serde::{Deserialize, Serialize};

/// Per-feature running mean and variance (parallel Welford), used to normalise observations to
/// zero mean and unit variance, clipped to `±clip`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningNorm {
    /// Running means.
    pub mean: Vec<f64>,
    /// Running variances.
    pub var: Vec<f64>,
    /// Effective sample count.
    pub count: f64,
    /// Normalised values are clipped to `±clip`.
    pub clip: f32,
}

impl RunningNorm {
    /// Statistics for `dim` features.
    pub fn new(dim: usize) -> Self {
        Self {
            mean: vec![0.0; dim],
            var: vec![1.0; dim],
            count: 1e-4,
            clip: 10.0,
        }
    }

    /// Adds a batch of rows `[n, dim]`.
    pub fn update(&mut self, rows: &[f32], n: usize) {
        let dim = self.mean.len();
        if n == 0 || dim == 0 {
            return;
        }
        for j in 0..dim {
            let mut m = 0.0;
            for i in 0..n {
                m += f64::from(rows[i * dim + j]);
            }
            m /= n as f64;
            let mut v = 0.0;
            for i in 0..n {
                let d = f64::from(rows[i * dim + j]) - m;
                v += d * d;
            }
            v /= n as f64;
            let total = self.count + n as f64;
            let delta = m - self.mean[j];
            self.mean[j] += delta * n as f64 / total;
            let m2 = self.var[j] * self.count
                + v * n as f64
                + delta * delta * self.count * n as f64 / total;
            self.var[j] = m2 / total;
        }
        self.count += n as f64;
    }

    /// Writes the statistics (for resumable training).
    pub(crate) fn save(&self, w: &mut crate::resume::StateWriter) {
        w.f64s(&self.mean);
        w.f64s(&self.var);
        w.f64(self.count);
        w.f32(self.clip);
    }

    /// Restores what [`save`](Self::save) wrote; the dimension must match.
    pub(crate) fn load(
        &mut self,
        r: &mut crate::resume::StateReader<'_>,
    ) -> Result<(), a2perf_core::RunError> {
        r.f64s_into("normalisation means", &mut self.mean)?;
        r.f64s_into("normalisation variances", &mut self.var)?;
        self.count = r.f64()?;
        self.clip = r.f32()?;
        Ok(())
    }

    /// Normalises `row` (length `dim`) in place.
    pub fn apply(&self, row: &mut [f32]) {
        for ((x, m), v) in row.iter_mut().zip(&self.mean).zip(&self.var) {
            let z = (f64::from(*x) - m) / (v + 1e-8).sqrt();
            *x = (z as f32).clamp(-self.clip, self.clip);
        }
    }
}

/// Reward scaling by the running standard deviation of the discounted return (as in TF-Agents'
/// `normalize_rewards` and SB3's `VecNormalize`): rewards are divided, not shifted, so the sign
/// of a reward and the optimal policy are unchanged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RewardScaler {
    returns: Vec<f64>,
    gamma: f64,
    stats: RunningNorm,
}

impl RewardScaler {
    /// A scaler for `num_envs` parallel streams with discount `gamma`.
    pub fn new(num_envs: usize, gamma: f64) -> Self {
        Self {
            returns: vec![0.0; num_envs],
            gamma,
            stats: RunningNorm::new(1),
        }
    }

    /// Writes the running returns and statistics (for resumable training).
    pub(crate) fn save(&self, w: &mut crate::resume::StateWriter) {
        w.f64s(&self.returns);
        w.f64(self.gamma);
        self.stats.save(w);
    }

    /// Restores what [`save`](Self::save) wrote; the number of streams must match.
    pub(crate) fn load(
        &mut self,
        r: &mut crate::resume::StateReader<'_>,
    ) -> Result<(), a2perf_core::RunError> {
        r.f64s_into("reward scaler returns", &mut self.returns)?;
        self.gamma = r.f64()?;
        self.stats.load(r)
    }

    /// Updates the return of stream `env` with `reward` and returns the scaled reward.
    pub fn scale(&mut self, env: usize, reward: f64, done: bool) -> f64 {
        self.returns[env] = self.returns[env] * self.gamma + reward;
        self.stats.update(&[self.returns[env] as f32], 1);
        if done {
            self.returns[env] = 0.0;
        }
        reward / (self.stats.var[0] + 1e-8).sqrt().max(1e-4)
    }
}
