//! Action distributions and the gradients of their log-likelihoods.
//!
//! - [`masked`]: categorical over a large discrete space with illegal actions masked out (their
//!   probability is exactly zero and they never receive gradient);
//! - [`gaussian`]: diagonal Gaussian with a state-independent log-std (PPO, BC);
//! - [`tanh_gaussian`]: reparameterised Gaussian squashed by `tanh` (SAC).

/// Masked categorical distribution over one row of logits.
pub mod masked {
    use a2perf_core::RngStream;

    fn legal(mask: Option<&[bool]>, i: usize) -> bool {
        mask.is_none_or(|m| m.get(i).copied().unwrap_or(false))
    }

    /// Writes masked log-probabilities into `logp` (illegal entries get `-inf`). Returns `false`
    /// when no action is legal.
    pub fn log_softmax(logits: &[f32], mask: Option<&[bool]>, logp: &mut [f32]) -> bool {
        let mut max = f32::NEG_INFINITY;
        for (i, &z) in logits.iter().enumerate() {
            if legal(mask, i) && z > max {
                max = z;
            }
        }
        if max == f32::NEG_INFINITY {
            logp.fill(f32::NEG_INFINITY);
            return false;
        }
        let mut sum = 0.0f64;
        for (i, &z) in logits.iter().enumerate() {
            if legal(mask, i) {
                sum += f64::from((z - max).exp());
            }
        }
        let lse = max + sum.ln() as f32;
        for (i, (&z, l)) in logits.iter().zip(logp.iter_mut()).enumerate() {
            *l = if legal(mask, i) {
                z - lse
            } else {
                f32::NEG_INFINITY
            };
        }
        true
    }

    /// Index of the largest legal logit (ties: lowest index); `None` when nothing is legal.
    ///
    /// ```
    /// use a2perf_baselines::nn::dist::masked;
    /// assert_eq!(masked::argmax(&[5.0, 1.0, 2.0], Some(&[false, true, true])), Some(2));
    /// ```
    pub fn argmax(logits: &[f32], mask: Option<&[bool]>) -> Option<usize> {
        let mut best: Option<(usize, f32)> = None;
        for (i, &z) in logits.iter().enumerate() {
            if legal(mask, i) && best.is_none_or(|(_, b)| z > b) {
                best = Some((i, z));
            }
        }
        best.map(|(i, _)| i)
    }

    /// [`argmax`] over a subset of the actions: `logits[j]` is the logit of action
    /// `actions[j]`, whose legality `mask[actions[j]]` says. Returns the column `j` of the
    /// largest legal logit (ties: lowest column); `None` when none is legal. With `actions` in
    /// increasing order and every other action illegal, it picks the action [`argmax`] picks
    /// over all of them.
    ///
    /// ```
    /// use a2perf_baselines::nn::dist::masked;
    /// let mask = [false, true, false, true, true];
    /// assert_eq!(masked::argmax_at(&[9.0, 2.0, 2.0], &[0, 3, 4], Some(&mask)), Some(1));
    /// assert_eq!(masked::argmax_at(&[9.0], &[2], Some(&mask)), None);
    /// ```
    pub fn argmax_at(logits: &[f32], actions: &[usize], mask: Option<&[bool]>) -> Option<usize> {
        let mut best: Option<(usize, f32)> = None;
        for (j, (&z, &a)) in logits.iter().zip(actions).enumerate() {
            if legal(mask, a) && best.is_none_or(|(_, b)| z > b) {
                best = Some((j, z));
            }
        }
        best.map(|(j, _)| j)
    }

    /// Draws an index from masked log-probabilities (inverse CDF).
    pub fn sample(logp: &[f32], rng: &mut RngStream) -> Option<usize> {
        let u = rng.uniform();
        let mut acc = 0.0f64;
        let mut last = None;
        for (i, &l) in logp.iter().enumerate() {
            if l > f32::NEG_INFINITY {
                acc += f64::from(l.exp());
                last = Some(i);
                if u < acc {
                    return Some(i);
                }
            }
        }
        last
    }

    /// Entropy `−Σ p log p` over legal actions.
    pub fn entropy(logp: &[f32]) -> f32 {
        logp.iter()
            .filter(|l| **l > f32::NEG_INFINITY)
            .map(|&l| -l.exp() * l)
            .sum()
    }

    /// [`log_softmax`] over the legal actions `legal` (in increasing order) followed by
    /// [`grad_logp`], touching only the legal entries: `dlogits[i] += coef · (onehot(action) −
    /// p_i)` for each legal `i`, the same values bit for bit (the sums run in the same order),
    /// without a pass over the illegal ones. Returns `false`, leaving `dlogits` as it was, when
    /// nothing is legal.
    ///
    /// ```
    /// use a2perf_baselines::nn::dist::masked;
    /// let (z, mask) = ([0.5, 3.0, -1.0, 2.0], [true, false, true, true]);
    /// let mut lp = [0.0; 4];
    /// masked::log_softmax(&z, Some(&mask), &mut lp);
    /// let mut full = [0.0; 4];
    /// masked::grad_logp(&lp, 3, -0.5, &mut full);
    /// let legal: Vec<usize> = (0..4).filter(|&i| mask[i]).collect();
    /// let mut fast = [0.0; 4];
    /// assert!(masked::grad_logp_legal(&z, &legal, 3, -0.5, &mut fast));
    /// assert_eq!(fast, full);
    /// ```
    pub fn grad_logp_legal(
        logits: &[f32],
        legal: &[usize],
        action: usize,
        coef: f32,
        dlogits: &mut [f32],
    ) -> bool {
        let mut max = f32::NEG_INFINITY;
        for &i in legal {
            let z = logits[i];
            if z > max {
                max = z;
            }
        }
        if max == f32::NEG_INFINITY {
            return false;
        }
        let mut sum = 0.0f64;
        for &i in legal {
            sum += f64::from((logits[i] - max).exp());
        }
        let lse = max + sum.ln() as f32;
        for &i in legal {
            let l = logits[i] - lse;
            if l > f32::NEG_INFINITY {
                let onehot = if i == action { 1.0 } else { 0.0 };
                dlogits[i] += coef * (onehot - l.exp());
            }
        }
        true
    }

    /// `dlogits += coef · ∂ log p(a) / ∂ logits` = `coef·(onehot(a) − p)` on legal entries.
    pub fn grad_logp(logp: &[f32], action: usize, coef: f32, dlogits: &mut [f32]) {
        for (i, (&l, d)) in logp.iter().zip(dlogits.iter_mut()).enumerate() {
            if l > f32::NEG_INFINITY {
                let onehot = if i == action { 1.0 } else { 0.0 };
                *d += coef * (onehot - l.exp());
            }
        }
    }

    /// `dlogits += coef · ∂H/∂logits` = `−coef·p_i (log p_i + H)` on legal entries.
    pub fn grad_entropy(logp: &[f32], coef: f32, dlogits: &mut [f32]) {
        let h = entropy(logp);
        for (&l, d) in logp.iter().zip(dlogits.iter_mut()) {
            if l > f32::NEG_INFINITY {
                *d -= coef * l.exp() * (l + h);
            }
        }
    }
}

/// Diagonal Gaussian `N(mean, exp(log_std)²)`.
pub mod gaussian {
    const HALF_LN_2PI: f32 = 0.918_938_5;

    /// `log N(a; mean, exp(log_std)²)` summed over dimensions.
    pub fn log_prob(mean: &[f32], log_std: &[f32], a: &[f32]) -> f32 {
        mean.iter()
            .zip(log_std)
            .zip(a)
            .map(|((&m, &s), &x)| {
                let z = (x - m) * (-s).exp();
                -0.5 * z * z - s - HALF_LN_2PI
            })
            .sum()
    }

    /// Accumulates `coef · ∂ log p / ∂mean` and `coef · ∂ log p / ∂log_std`.
    pub fn grad_log_prob(
        mean: &[f32],
        log_std: &[f32],
        a: &[f32],
        coef: f32,
        dmean: &mut [f32],
        dlog_std: &mut [f32],
    ) {
        for i in 0..mean.len() {
            let inv = (-log_std[i]).exp();
            let z = (a[i] - mean[i]) * inv;
            dmean[i] += coef * z * inv;
            dlog_std[i] += coef * (z * z - 1.0);
        }
    }

    /// Entropy summed over dimensions (`Σ log_std + ½(1 + ln 2π)`); its gradient w.r.t. each
    /// `log_std` is 1.
    pub fn entropy(log_std: &[f32]) -> f32 {
        log_std.iter().map(|s| s + 0.5 + HALF_LN_2PI).sum()
    }
}

/// Reparameterised `tanh(N(mean, σ²))` with a bounded log-std, as in SAC.
pub mod tanh_gaussian {
    use crate::nn::tanh::tanh;

    /// Lower bound of `log σ`.
    pub const LOG_STD_MIN: f32 = -5.0;
    /// Upper bound of `log σ`.
    pub const LOG_STD_MAX: f32 = 2.0;
    const HALF_LN_2PI: f32 = 0.918_938_5;
    const EPS: f32 = 1e-6;

    /// Maps an unbounded network output to `log σ ∈ [LOG_STD_MIN, LOG_STD_MAX]` smoothly.
    pub fn log_std(raw: f32) -> f32 {
        LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (tanh(raw) + 1.0)
    }

    fn dlog_std_draw(raw: f32) -> f32 {
        let t = tanh(raw);
        0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (1.0 - t * t)
    }

    /// Squashed action `a = tanh(mean + σ ε)` and its log-density; writes `a` and returns `log p(a)`.
    pub fn sample(mean: &[f32], raw_log_std: &[f32], eps: &[f32], a: &mut [f32]) -> f32 {
        let mut logp = 0.0;
        for i in 0..mean.len() {
            let s = log_std(raw_log_std[i]);
            let u = mean[i] + s.exp() * eps[i];
            let t = tanh(u);
            a[i] = t;
            logp += -0.5 * eps[i] * eps[i] - s - HALF_LN_2PI - (1.0 - t * t + EPS).ln();
        }
        logp
    }

    /// Backpropagates `dL/da` and `dL/dlogp` (with ε fixed) to the mean and raw log-std,
    /// accumulating into `dmean` and `draw`.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        mean: &[f32],
        raw_log_std: &[f32],
        eps: &[f32],
        da: &[f32],
        dlogp: f32,
        dmean: &mut [f32],
        draw: &mut [f32],
    ) {
        for i in 0..mean.len() {
            let s = log_std(raw_log_std[i]);
            let sigma = s.exp();
            let u = mean[i] + sigma * eps[i];
            let t = tanh(u);
            let dtdu = 1.0 - t * t;
            // ∂ log p / ∂u through the −ln(1 − tanh²u + ε) correction.
            let dlogp_du = 2.0 * t * dtdu / (dtdu + EPS);
            let du = da[i] * dtdu + dlogp * dlogp_du;
            dmean[i] += du;
            let ds = du * sigma * eps[i] - dlogp;
            draw[i] += ds * dlog_std_draw(raw_log_std[i]);
        }
    }
}
