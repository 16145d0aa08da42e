//! Adam with bias correction and learning-rate schedules.

use serde::{Deserialize, Serialize};

/// Adam (Kingma & Ba) with the paper baselines' `eps = 1e-5`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    /// First-moment decay.
    pub beta1: f32,
    /// Second-moment decay.
    pub beta2: f32,
    /// Denominator fuzz (TF-Agents baselines use 1e-5).
    pub eps: f32,
    m: Vec<f32>,
    v: Vec<f32>,
    t: u64,
}

impl Adam {
    /// Optimiser state for `n` parameters.
    pub fn new(n: usize) -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-5,
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// Number of updates applied.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// Writes the moments and step count (for resumable training).
    pub(crate) fn save(&self, w: &mut crate::resume::StateWriter) {
        w.f32(self.beta1);
        w.f32(self.beta2);
        w.f32(self.eps);
        w.f32s(&self.m);
        w.f32s(&self.v);
        w.u64(self.t);
    }

    /// Restores what [`save`](Self::save) wrote; the parameter count must match.
    pub(crate) fn load(
        &mut self,
        what: &str,
        r: &mut crate::resume::StateReader<'_>,
    ) -> Result<(), a2perf_core::RunError> {
        self.beta1 = r.f32()?;
        self.beta2 = r.f32()?;
        self.eps = r.f32()?;
        r.f32s_into(&format!("{what} Adam first moments"), &mut self.m)?;
        r.f32s_into(&format!("{what} Adam second moments"), &mut self.v)?;
        self.t = r.u64()?;
        Ok(())
    }

    /// One descent step `params −= lr · m̂ / (√v̂ + eps)`.
    ///
    /// ```
    /// use a2perf_baselines::nn::optim::Adam;
    /// let mut p = vec![1.0f32];
    /// let mut adam = Adam::new(1);
    /// for _ in 0..500 { let g = vec![2.0 * p[0]]; adam.step(&mut p, &g, 0.05); }
    /// assert!(p[0].abs() < 0.25); // from 1.0: Adam hovers near the minimum at a fixed step
    /// ```
    ///
    /// Every parameter's update is its own, so on a thread of rayon's pool (where handing work
    /// to the other thread costs no wake-up) a large vector is updated in two halves side by
    /// side, with the same values.
    pub fn step(&mut self, params: &mut [f32], grads: &[f32], lr: f32) {
        self.t += 1;
        let t = self.t as i32;
        let c1 = 1.0 - self.beta1.powi(t);
        let c2 = 1.0 - self.beta2.powi(t);
        let k = AdamStep {
            beta1: self.beta1,
            beta2: self.beta2,
            step: lr * c2.sqrt() / c1,
            eps: self.eps * c2.sqrt(),
        };
        let n = params.len().min(grads.len());
        if n >= PARALLEL_STEP && rayon::current_thread_index().is_some() {
            let h = n / 2;
            let (p0, p1) = params[..n].split_at_mut(h);
            let (m0, m1) = self.m[..n].split_at_mut(h);
            let (v0, v1) = self.v[..n].split_at_mut(h);
            let (g0, g1) = grads[..n].split_at(h);
            rayon::join(|| k.apply(p0, g0, m0, v0), || k.apply(p1, g1, m1, v1));
        } else {
            k.apply(params, grads, &mut self.m, &mut self.v);
        }
    }
}

/// Parameters from which [`Adam::step`] splits its update between two threads (the locomotion
/// PPO networks at the paper's size have 431,000; below ~30,000 the hand-off costs more than
/// half the update).
const PARALLEL_STEP: usize = 1 << 15;

/// The constants of one Adam step.
#[derive(Clone, Copy)]
struct AdamStep {
    beta1: f32,
    beta2: f32,
    step: f32,
    eps: f32,
}

impl AdamStep {
    fn apply(self, params: &mut [f32], grads: &[f32], m: &mut [f32], v: &mut [f32]) {
        for (((p, g), m), v) in params.iter_mut().zip(grads).zip(m).zip(v) {
            *m = self.beta1 * *m + (1.0 - self.beta1) * g;
            *v = self.beta2 * *v + (1.0 - self.beta2) * g * g;
            *p -= self.step * *m / (v.sqrt() + self.eps);
        }
    }
}

/// Learning rate as a function of training progress.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum LrSchedule {
    /// Fixed learning rate.
    Constant(f32),
    /// Cosine decay from `initial` to `initial · final_fraction` (TF `CosineDecay(alpha)`, used by
    /// the circuit-training PPO baseline with `alpha = 0.1`).
    Cosine {
        /// Initial learning rate.
        initial: f32,
        /// Final learning rate as a fraction of the initial one.
        final_fraction: f32,
    },
}

impl LrSchedule {
    /// Learning rate at `progress ∈ [0, 1]`.
    ///
    /// ```
    /// use a2perf_baselines::nn::optim::LrSchedule;
    /// let s = LrSchedule::Cosine { initial: 1.0, final_fraction: 0.1 };
    /// assert_eq!(s.at(0.0), 1.0);
    /// assert!((s.at(1.0) - 0.1).abs() < 1e-6);
    /// ```
    pub fn at(&self, progress: f64) -> f32 {
        match *self {
            LrSchedule::Constant(lr) => lr,
            LrSchedule::Cosine {
                initial,
                final_fraction,
            } => {
                let p = progress.clamp(0.0, 1.0);
                let cos = 0.5 * (1.0 + (std::f64::consts::PI * p).cos());
                (f64::from(initial)
                    * (f64::from(final_fraction) + (1.0 - f64::from(final_fraction)) * cos))
                    as f32
            }
        }
    }
}
