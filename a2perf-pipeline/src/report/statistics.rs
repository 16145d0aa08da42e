//! Statistics: the summary of a metric over a group's seeds, and the comparisons between
//! algorithms (IQM of the per-seed returns per task, probability of improvement between every
//! ordered pair of algorithms), each with a 95% percentile-bootstrap interval.
//!
//! The arithmetic is `a2perf_metrics`'s (`numeric`, `rliable`, `bootstrap`); this module only
//! says which runs are compared and which random stream each interval draws from, so that a
//! report is the same on every machine.

use std::collections::{BTreeMap, BTreeSet};

use a2perf_core::RngStream;
use a2perf_metrics::{bootstrap, numeric, rliable};

use super::model::{
    GroupReport, ImprovementEntry, IqmEntry, MetricValue, NOT_FINITE, ReportOptions,
};

/// Mean, sample standard deviation and 95% bootstrap interval of the mean of one metric over
/// a group's seeds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OverSeeds {
    /// Mean over the seeds.
    pub mean: f64,
    /// Sample standard deviation (ddof 1); 0 for a single seed, which has no spread to show.
    pub std: f64,
    /// Percentile-bootstrap 95% interval of the mean (`None` when a value is not finite or no
    /// repetitions were asked for).
    pub ci95: Option<[f64; 2]>,
}

impl OverSeeds {
    /// The statistics of `values` (one per seed, at least one), the interval drawn from `rng`.
    ///
    /// ```
    /// use a2perf_core::RngStream;
    /// use a2perf_pipeline::report::statistics::OverSeeds;
    /// let s = OverSeeds::of(&[1.0, 3.0], 100, &mut RngStream::new(0, "doc"));
    /// assert_eq!((s.mean, s.std), (2.0, 2f64.sqrt()));
    /// assert_eq!(OverSeeds::of(&[5.0], 100, &mut RngStream::new(0, "doc")).std, 0.0);
    /// ```
    pub fn of(values: &[f64], reps: usize, rng: &mut RngStream) -> Self {
        Self {
            mean: numeric::mean_sequential(values),
            std: if values.len() == 1 {
                0.0
            } else {
                numeric::std_sequential(values, 1)
            },
            ci95: bootstrap::mean_ci(values, reps, rng),
        }
    }
}

/// The IQMs and probabilities of improvement of the groups' per-seed returns (groups without
/// returns are left out). Every interval has its own stream, named after what it compares, so
/// adding a group changes no other group's interval.
pub fn comparisons(
    groups: &[GroupReport],
    opts: &ReportOptions,
) -> (Vec<IqmEntry>, Vec<ImprovementEntry>) {
    let scores: BTreeMap<(String, String), Vec<f64>> = groups
        .iter()
        .filter_map(|g| {
            let m = g.metric("returns")?;
            (m.mean.is_some() && !m.per_seed.is_empty())
                .then(|| ((g.algorithm.clone(), g.task.clone()), m.per_seed.clone()))
        })
        .collect();
    (iqms(&scores, opts), improvements(&scores, opts))
}

/// Per-seed returns keyed by (algorithm, task).
type Scores = BTreeMap<(String, String), Vec<f64>>;

fn iqms(scores: &Scores, opts: &ReportOptions) -> Vec<IqmEntry> {
    let mut out: Vec<IqmEntry> = scores
        .iter()
        .map(|((algo, task), s)| {
            let mut rng = RngStream::new(opts.seed, &format!("report/iqm/{task}/{algo}"));
            let mut buf = Vec::with_capacity(s.len());
            let ci95 = bootstrap::interval95_of(opts.bootstrap_reps, || {
                bootstrap::resample(s, &mut buf, &mut rng);
                rliable::iqm_of_sequential(&buf)
            });
            IqmEntry {
                task: task.clone(),
                algorithm: algo.clone(),
                iqm: rliable::iqm_of_sequential(s),
                ci95,
                runs: s.len(),
            }
        })
        .collect();
    out.sort_by(|a, b| (&a.task, &a.algorithm).cmp(&(&b.task, &b.algorithm)));
    out
}

fn improvements(scores: &Scores, opts: &ReportOptions) -> Vec<ImprovementEntry> {
    let algos: BTreeSet<&String> = scores.keys().map(|(a, _)| a).collect();
    let mut out = Vec::new();
    for x in &algos {
        for y in &algos {
            if x == y {
                continue;
            }
            let tasks: Vec<&String> = scores
                .keys()
                .filter(|(a, t)| a == *x && scores.contains_key(&((*y).clone(), t.clone())))
                .map(|(_, t)| t)
                .collect();
            if tasks.is_empty() {
                continue;
            }
            let pairs: Vec<(&[f64], &[f64])> = tasks
                .iter()
                .map(|t| {
                    (
                        scores[&((*x).clone(), (*t).clone())].as_slice(),
                        scores[&((*y).clone(), (*t).clone())].as_slice(),
                    )
                })
                .collect();
            out.push(ImprovementEntry {
                x: (*x).clone(),
                y: (*y).clone(),
                tasks: tasks.iter().map(|t| (*t).clone()).collect(),
                probability: numeric::mean_sequential(
                    &pairs
                        .iter()
                        .map(|(a, b)| rliable::prob_greater(a, b))
                        .collect::<Vec<_>>(),
                ),
                ci95: improvement_interval(&pairs, &format!("report/poi/{x}/{y}"), opts),
            });
        }
    }
    out
}

/// Stratified bootstrap of the probability of improvement: runs are resampled within each
/// task and algorithm, X's then Y's, task after task.
fn improvement_interval(
    pairs: &[(&[f64], &[f64])],
    stream: &str,
    opts: &ReportOptions,
) -> [f64; 2] {
    let mut rng = RngStream::new(opts.seed, stream);
    let (mut ba, mut bb) = (Vec::new(), Vec::new());
    bootstrap::interval95_of(opts.bootstrap_reps, || {
        let mut acc = 0.0;
        for (a, b) in pairs {
            bootstrap::resample(a, &mut ba, &mut rng);
            bootstrap::resample(b, &mut bb, &mut rng);
            acc += rliable::prob_greater(&ba, &bb);
        }
        acc / pairs.len() as f64
    })
}

/// The bootstrap settings and stream of a column's per-seed metrics.
pub(super) struct Seeds {
    pub(super) reps: usize,
    pub(super) rng: RngStream,
}

impl Seeds {
    /// A metric with one value per run: its statistics over the seeds, or missing (saying how
    /// many runs have it) when any run lacks it or has it not finite (a NaN reward). `notes`
    /// (deduplicated) say how it was obtained.
    pub(super) fn metric(
        &mut self,
        metric: MetricValue,
        values: Vec<Option<f64>>,
        missing_why: &str,
        mut notes: Vec<String>,
    ) -> MetricValue {
        let mut m = metric;
        if values.is_empty() || values.iter().any(Option::is_none) {
            let have = values.iter().filter(|v| v.is_some()).count();
            return m.missing(format!("{missing_why} ({have} of {} runs)", values.len()));
        }
        let v: Vec<f64> = values.into_iter().flatten().collect();
        let not_finite = v.iter().filter(|x| !x.is_finite()).count();
        if not_finite > 0 {
            return m.missing(format!("{NOT_FINITE} ({not_finite} of {} runs)", v.len()));
        }
        let stats = OverSeeds::of(&v, self.reps, &mut self.rng);
        m.mean = Some(stats.mean);
        m.std = Some(stats.std);
        m.ci95 = stats.ci95;
        m.per_seed = v;
        notes.sort();
        notes.dedup();
        if !notes.is_empty() {
            m.note = Some(notes.join("; "));
        }
        m
    }
}
