//! Aggregate performance with uncertainty, after rliable (Agarwal et al., NeurIPS 2021;
//! google-research/rliable v1.2.0).
//!
//! - [`iqm`]: `scipy.stats.trim_mean(x, 0.25)` over all runs × tasks: drop `int(0.25·n)` from
//!   each end (integer truncation, no fractional weights).
//! - [`mean`], [`median`] (over tasks of the per-task means), [`optimality_gap`].
//! - [`probability_of_improvement`]: Mann–Whitney `U₁/(n_x·n_y)` per task (ties ½; identical
//!   columns exactly ½), averaged over tasks; run counts may differ.
//! - [`bootstrap_ci`]: stratified bootstrap (runs resampled with replacement independently
//!   within each task; optionally tasks too), percentile intervals with NumPy's linear rule.
//! - [`score_distribution`] / [`average_score_distribution`]: performance profiles.
//!
//! Randomness: rliable draws from NumPy's *global* legacy generator (its `random_state` argument
//! is ignored), so its intervals cannot be reproduced digit for digit; ours come from
//! [`RngStream`] and are bit-identical for a given seed on every machine and thread count
//! (replicates are drawn in fixed chunks, each from its own `derive_index(chunk)` stream).

use a2perf_core::RngStream;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::numeric;

/// Errors of the rliable statistics.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum RliableError {
    /// A score matrix has no entries or ragged rows.
    #[error("invalid score matrix: {0}")]
    Shape(String),
    /// A parameter is outside its domain.
    #[error("invalid parameter: {0}")]
    Param(String),
}

/// A `num_runs × num_tasks` score matrix (rliable's layout), stored row-major.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    runs: usize,
    tasks: usize,
    data: Vec<f64>,
}

impl Scores {
    /// Scores from rows (one row per run, one column per task).
    ///
    /// ```
    /// let s = a2perf_metrics::rliable::Scores::from_rows(&[vec![1.0, 2.0], vec![3.0, 4.0]]).unwrap();
    /// assert_eq!((s.runs(), s.tasks()), (2, 2));
    /// assert_eq!(s.get(1, 0), 3.0);
    /// ```
    pub fn from_rows(rows: &[Vec<f64>]) -> Result<Self, RliableError> {
        let tasks = rows.first().map_or(0, Vec::len);
        if rows.is_empty() || tasks == 0 {
            return Err(RliableError::Shape("no runs or no tasks".into()));
        }
        if let Some(r) = rows.iter().position(|r| r.len() != tasks) {
            return Err(RliableError::Shape(format!(
                "run {r} has {} tasks, expected {tasks}",
                rows[r].len()
            )));
        }
        Ok(Self {
            runs: rows.len(),
            tasks,
            data: rows.iter().flatten().copied().collect(),
        })
    }

    /// Scores from a row-major buffer.
    pub fn new(runs: usize, tasks: usize, data: Vec<f64>) -> Result<Self, RliableError> {
        if runs == 0 || tasks == 0 || data.len() != runs * tasks {
            return Err(RliableError::Shape(format!(
                "{} values for {runs} runs × {tasks} tasks",
                data.len()
            )));
        }
        Ok(Self { runs, tasks, data })
    }

    /// Number of runs.
    pub fn runs(&self) -> usize {
        self.runs
    }

    /// Number of tasks.
    pub fn tasks(&self) -> usize {
        self.tasks
    }

    /// Score of `run` on `task`.
    pub fn get(&self, run: usize, task: usize) -> f64 {
        self.data[run * self.tasks + task]
    }

    /// All scores, row-major.
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }

    /// The scores of one task over its runs.
    pub fn task_column(&self, task: usize) -> Vec<f64> {
        (0..self.runs).map(|r| self.get(r, task)).collect()
    }

    fn task_means(&self) -> Vec<f64> {
        // np.mean(axis=0) reduces along rows sequentially.
        let mut sums = vec![0.0; self.tasks];
        for row in self.data.chunks_exact(self.tasks) {
            for (s, v) in sums.iter_mut().zip(row) {
                *s += v;
            }
        }
        sums.iter().map(|s| s / self.runs as f64).collect()
    }
}

/// Interquartile mean over all runs and tasks (25 % trimmed mean, integer truncation).
///
/// ```
/// // n = 4: drop one from each end, mean of the middle two.
/// assert_eq!(a2perf_metrics::rliable::iqm_of(&[0.0, 3.1, 2.2, 1.3]), 1.75);
/// ```
pub fn iqm(scores: &Scores) -> f64 {
    iqm_of(scores.as_slice())
}

/// [`iqm`] of a flat sample.
pub fn iqm_of(x: &[f64]) -> f64 {
    let mut s = x.to_vec();
    iqm_in_place(&mut s)
}

/// [`iqm_of`] with the middle half summed left to right ([`numeric::mean_sequential`]) rather
/// than pairwise as NumPy: the same for fewer than 16 values, up to the sign of a zero mean.
/// The IQMs of `a2perf report` use it, so its files keep their bytes.
///
/// ```
/// assert_eq!(a2perf_metrics::rliable::iqm_of_sequential(&[0.0, 3.1, 2.2, 1.3]), 1.75);
/// ```
pub fn iqm_of_sequential(x: &[f64]) -> f64 {
    let mut s = x.to_vec();
    numeric::mean_sequential(middle_half(&mut s))
}

fn iqm_in_place(s: &mut [f64]) -> f64 {
    numeric::mean(middle_half(s))
}

/// Sorts `s` and returns its middle half: `int(0.25·n)` dropped from each end (as
/// `scipy.stats.trim_mean(x, 0.25)`).
fn middle_half(s: &mut [f64]) -> &[f64] {
    let n = s.len();
    let cut = n / 4;
    s.sort_unstable_by(f64::total_cmp);
    &s[cut..n - cut]
}

/// Mean over tasks of the per-task mean over runs.
pub fn mean(scores: &Scores) -> f64 {
    numeric::mean(&scores.task_means())
}

/// Median over tasks of the per-task mean over runs.
pub fn median(scores: &Scores) -> f64 {
    numeric::median(&scores.task_means())
}

/// Optimality gap `γ − mean(min(x, γ))` over all entries (rliable's default γ = 1).
///
/// ```
/// let s = a2perf_metrics::rliable::Scores::from_rows(&[vec![0.5, 2.0]]).unwrap();
/// assert_eq!(a2perf_metrics::rliable::optimality_gap(&s, 1.0), 0.25);
/// ```
pub fn optimality_gap(scores: &Scores, gamma: f64) -> f64 {
    let clipped: Vec<f64> = scores.as_slice().iter().map(|v| v.min(gamma)).collect();
    gamma - numeric::mean(&clipped)
}

/// Mann–Whitney `P(X > Y)` for one task: `U₁/(n_x·n_y)` with ties counted ½.
pub fn prob_greater(x: &[f64], y: &[f64]) -> f64 {
    if x == y {
        return 0.5;
    }
    let mut u = 0.0;
    for a in x {
        for b in y {
            if a > b {
                u += 1.0;
            } else if a == b {
                u += 0.5;
            }
        }
    }
    u / (x.len() * y.len()) as f64
}

/// Probability of improvement of X over Y: per-task Mann–Whitney, averaged over tasks.
///
/// ```
/// use a2perf_metrics::rliable::{probability_of_improvement, Scores};
/// let x = Scores::from_rows(&[vec![2.0], vec![3.0]]).unwrap();
/// let y = Scores::from_rows(&[vec![1.0], vec![2.0], vec![4.0]]).unwrap();
/// // pairs: 2>1, 2=2 (½), 3>1, 3>2 → 3.5 of 6.
/// assert!((probability_of_improvement(&x, &y).unwrap() - 3.5 / 6.0).abs() < 1e-15);
/// ```
pub fn probability_of_improvement(x: &Scores, y: &Scores) -> Result<f64, RliableError> {
    if x.tasks != y.tasks {
        return Err(RliableError::Shape(format!(
            "X has {} tasks but Y has {}",
            x.tasks, y.tasks
        )));
    }
    let per_task: Vec<f64> = (0..x.tasks)
        .map(|t| prob_greater(&x.task_column(t), &y.task_column(t)))
        .collect();
    Ok(numeric::mean(&per_task))
}

/// Performance profile over runs: for each τ, the fraction of all scores **strictly** above τ.
pub fn score_distribution(scores: &Scores, taus: &[f64]) -> Vec<f64> {
    let n = scores.as_slice().len() as f64;
    taus.iter()
        .map(|&t| scores.as_slice().iter().filter(|v| **v > t).count() as f64 / n)
        .collect()
}

/// Performance profile over tasks: for each τ, the fraction of per-task mean scores above τ.
pub fn average_score_distribution(scores: &Scores, taus: &[f64]) -> Vec<f64> {
    let means = scores.task_means();
    let n = means.len() as f64;
    taus.iter()
        .map(|&t| means.iter().filter(|v| **v > t).count() as f64 / n)
        .collect()
}

/// A statistic of one score matrix, evaluated many times by the bootstrap.
pub trait Statistic: Sync {
    /// Number of values it produces.
    fn len(&self) -> usize;
    /// `true` when it produces no values.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Writes its values for `scores` into `out` (`out.len() == self.len()`); `scratch` is a
    /// reusable buffer.
    fn eval(&self, scores: &Scores, scratch: &mut Vec<f64>, out: &mut [f64]);
    /// `true` when the values depend only on the multiset of scores, not on which run and task
    /// each score sits in (up to floating-point summation order). The bootstrap then hands
    /// [`Statistic::eval`] each resample already sorted, which makes order statistics cheap.
    fn order_free(&self) -> bool {
        false
    }
}

/// The standard aggregates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Aggregate {
    /// [`iqm`].
    Iqm,
    /// [`mean`].
    Mean,
    /// [`median`].
    Median,
    /// [`optimality_gap`] with this γ.
    OptimalityGap(f64),
}

impl Aggregate {
    /// The aggregate of `scores`.
    pub fn compute(self, scores: &Scores) -> f64 {
        match self {
            Aggregate::Iqm => iqm(scores),
            Aggregate::Mean => mean(scores),
            Aggregate::Median => median(scores),
            Aggregate::OptimalityGap(g) => optimality_gap(scores, g),
        }
    }
}

/// Several aggregates as one statistic (rliable's `lambda x: np.array([median, iqm, …])`).
#[derive(Clone, Debug, PartialEq)]
pub struct Aggregates(pub Vec<Aggregate>);

impl Statistic for Aggregates {
    fn len(&self) -> usize {
        self.0.len()
    }
    fn order_free(&self) -> bool {
        // IQM, optimality gap and the mean (every task has the same number of runs) are
        // functions of the pooled scores; the median is taken over per-task means.
        self.0.iter().all(|a| !matches!(a, Aggregate::Median))
    }
    fn eval(&self, scores: &Scores, scratch: &mut Vec<f64>, out: &mut [f64]) {
        for (o, a) in out.iter_mut().zip(&self.0) {
            *o = match a {
                Aggregate::Iqm => {
                    scratch.clear();
                    scratch.extend_from_slice(scores.as_slice());
                    iqm_in_place(scratch)
                }
                other => other.compute(scores),
            };
        }
    }
}

/// A performance profile as a statistic (one value per τ).
#[derive(Clone, Debug, PartialEq)]
pub struct Profile {
    /// Thresholds.
    pub taus: Vec<f64>,
    /// `true`: [`score_distribution`]; `false`: [`average_score_distribution`].
    pub over_runs: bool,
}

impl Statistic for Profile {
    fn len(&self) -> usize {
        self.taus.len()
    }
    fn eval(&self, scores: &Scores, _scratch: &mut Vec<f64>, out: &mut [f64]) {
        let v = if self.over_runs {
            score_distribution(scores, &self.taus)
        } else {
            average_score_distribution(scores, &self.taus)
        };
        out.copy_from_slice(&v);
    }
}

/// Bootstrap settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BootstrapConfig {
    /// Number of replicates (rliable default 50,000).
    pub reps: usize,
    /// Interval coverage (default 0.95).
    pub confidence: f64,
    /// Also resample tasks (rliable's `task_bootstrap`).
    pub task_bootstrap: bool,
    /// Experiment seed of the [`RngStream`].
    pub seed: u64,
}

impl Default for BootstrapConfig {
    fn default() -> Self {
        Self {
            reps: 50_000,
            confidence: 0.95,
            task_bootstrap: false,
            seed: 0,
        }
    }
}

/// Point estimates with percentile confidence intervals.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IntervalEstimate {
    /// The statistic on the original scores.
    pub point: Vec<f64>,
    /// Lower bounds.
    pub lower: Vec<f64>,
    /// Upper bounds.
    pub upper: Vec<f64>,
}

/// Replicates drawn per RNG stream; fixed so results do not depend on the thread count.
const CHUNK: usize = 1024;

fn check_config(cfg: &BootstrapConfig) -> Result<(), RliableError> {
    if cfg.reps == 0 {
        return Err(RliableError::Param("reps must be positive".into()));
    }
    if !(cfg.confidence > 0.0 && cfg.confidence < 1.0) {
        return Err(RliableError::Param(format!(
            "confidence {} must be in (0, 1)",
            cfg.confidence
        )));
    }
    Ok(())
}

fn resample_into(src: &Scores, dst: &mut Scores, rng: &mut RngStream, task_bootstrap: bool) {
    let tasks = src.tasks;
    for t in 0..tasks {
        let from_task = if task_bootstrap { rng.index(tasks) } else { t };
        for r in 0..src.runs {
            let from_run = rng.index(src.runs);
            dst.data[r * tasks + t] = src.data[from_run * tasks + from_task];
        }
    }
}

/// Stratified resampling that writes each resample in ascending order: a draw only counts how
/// often each source score was picked, and the sample is then laid out by walking the source
/// scores in sorted order — a counting sort, with the same draws as [`resample_into`].
struct SortedResampler {
    /// Flat source index → position of that score in ascending order.
    rank: Vec<usize>,
    /// The source scores in ascending order.
    sorted: Vec<f64>,
    /// How often each sorted position was drawn (scratch).
    counts: Vec<u32>,
}

impl SortedResampler {
    fn new(src: &Scores) -> Self {
        let mut order: Vec<usize> = (0..src.data.len()).collect();
        order.sort_by(|&a, &b| src.data[a].total_cmp(&src.data[b]).then(a.cmp(&b)));
        let mut rank = vec![0; order.len()];
        for (pos, &flat) in order.iter().enumerate() {
            rank[flat] = pos;
        }
        Self {
            rank,
            sorted: order.iter().map(|&i| src.data[i]).collect(),
            counts: vec![0; order.len()],
        }
    }

    fn resample(
        &mut self,
        src: &Scores,
        dst: &mut Scores,
        rng: &mut RngStream,
        task_bootstrap: bool,
    ) {
        self.counts.fill(0);
        let tasks = src.tasks;
        for t in 0..tasks {
            let from_task = if task_bootstrap { rng.index(tasks) } else { t };
            for _ in 0..src.runs {
                let from_run = rng.index(src.runs);
                self.counts[self.rank[from_run * tasks + from_task]] += 1;
            }
        }
        let mut out = dst.data.iter_mut();
        for (&v, &c) in self.sorted.iter().zip(&self.counts) {
            for slot in out.by_ref().take(c as usize) {
                *slot = v;
            }
        }
    }
}

fn percentile_intervals(reps: &[f64], k: usize, confidence: f64) -> (Vec<f64>, Vec<f64>) {
    let n = reps.len() / k;
    let lo_q = 100.0 * (1.0 - confidence) / 2.0;
    let hi_q = 100.0 * (1.0 - (1.0 - confidence) / 2.0);
    let mut col = vec![0.0; n];
    let mut lower = Vec::with_capacity(k);
    let mut upper = Vec::with_capacity(k);
    for j in 0..k {
        for (i, c) in col.iter_mut().enumerate() {
            *c = reps[i * k + j];
        }
        col.sort_unstable_by(f64::total_cmp);
        lower.push(numeric::percentile_sorted(&col, lo_q));
        upper.push(numeric::percentile_sorted(&col, hi_q));
    }
    (lower, upper)
}

/// Stratified bootstrap percentile confidence intervals of `stat` (rliable's
/// `get_interval_estimates` for one algorithm).
///
/// ```
/// use a2perf_metrics::rliable::{bootstrap_ci, Aggregate, Aggregates, BootstrapConfig, Scores};
/// let s = Scores::from_rows(&(0..10).map(|r| vec![r as f64, 2.0 * r as f64]).collect::<Vec<_>>()).unwrap();
/// let cfg = BootstrapConfig { reps: 2000, ..BootstrapConfig::default() };
/// let ci = bootstrap_ci(&s, &Aggregates(vec![Aggregate::Mean]), &cfg).unwrap();
/// assert!(ci.lower[0] < ci.point[0] && ci.point[0] < ci.upper[0]);
/// ```
pub fn bootstrap_ci(
    scores: &Scores,
    stat: &dyn Statistic,
    cfg: &BootstrapConfig,
) -> Result<IntervalEstimate, RliableError> {
    check_config(cfg)?;
    let k = stat.len();
    let mut scratch = Vec::new();
    let mut point = vec![0.0; k];
    stat.eval(scores, &mut scratch, &mut point);
    let root = RngStream::new(cfg.seed, "rliable/stratified-bootstrap");
    let mut reps = vec![0.0; cfg.reps * k];
    reps.par_chunks_mut(CHUNK * k)
        .enumerate()
        .for_each(|(chunk, out)| {
            let mut rng = root.derive_index(chunk as u64);
            let mut sample = scores.clone();
            let mut scratch = Vec::with_capacity(scores.data.len());
            let mut sorter = stat.order_free().then(|| SortedResampler::new(scores));
            for rep_out in out.chunks_exact_mut(k) {
                match sorter.as_mut() {
                    Some(s) => s.resample(scores, &mut sample, &mut rng, cfg.task_bootstrap),
                    None => resample_into(scores, &mut sample, &mut rng, cfg.task_bootstrap),
                }
                stat.eval(&sample, &mut scratch, rep_out);
            }
        });
    let (lower, upper) = percentile_intervals(&reps, k, cfg.confidence);
    Ok(IntervalEstimate {
        point,
        lower,
        upper,
    })
}

/// Probability of improvement with an interval: X and Y are resampled independently, each
/// stratified by task (rliable's `StratifiedIndependentBootstrap`).
pub fn probability_of_improvement_ci(
    x: &Scores,
    y: &Scores,
    cfg: &BootstrapConfig,
) -> Result<IntervalEstimate, RliableError> {
    check_config(cfg)?;
    let point = probability_of_improvement(x, y)?;
    let root = RngStream::new(cfg.seed, "rliable/independent-bootstrap");
    let mut reps = vec![0.0; cfg.reps];
    reps.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(chunk, out)| {
            let mut rng = root.derive_index(chunk as u64);
            let (mut xs, mut ys) = (x.clone(), y.clone());
            for o in out.iter_mut() {
                resample_into(x, &mut xs, &mut rng, false);
                resample_into(y, &mut ys, &mut rng, false);
                *o = probability_of_improvement(&xs, &ys).unwrap_or(f64::NAN);
            }
        });
    let (lower, upper) = percentile_intervals(&reps, 1, cfg.confidence);
    Ok(IntervalEstimate {
        point: vec![point],
        lower,
        upper,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The counting-sort resample is the plain resample, sorted: same draws, same multiset.
    #[test]
    fn sorted_resample_is_the_plain_resample_sorted() {
        let rows: Vec<Vec<f64>> = (0..7)
            .map(|r| {
                (0..4)
                    .map(|t| ((r * 5 + t * 3) % 6) as f64 - 0.5 * t as f64)
                    .collect()
            })
            .collect();
        let src = Scores::from_rows(&rows).unwrap();
        for task_bootstrap in [false, true] {
            let mut sorter = SortedResampler::new(&src);
            let (mut a, mut b) = (src.clone(), src.clone());
            let mut rng_a = RngStream::new(3, "test");
            let mut rng_b = RngStream::new(3, "test");
            for _ in 0..200 {
                resample_into(&src, &mut a, &mut rng_a, task_bootstrap);
                sorter.resample(&src, &mut b, &mut rng_b, task_bootstrap);
                let mut want = a.data.clone();
                want.sort_by(f64::total_cmp);
                assert_eq!(want, b.data);
            }
        }
    }
}
