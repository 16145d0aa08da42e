//! Application and data-cost metrics (A2Perf `metrics_lib.py`, `evaluation.py`, `expertise.py`,
//! `data/combine.py`).

use serde::{Deserialize, Serialize};

use crate::numeric;

/// Summary of episode returns (A2Perf's `rollout_returns`, 100 episodes by default).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReturnsSummary {
    /// Mean return.
    pub mean: f64,
    /// Population standard deviation (`np.std`, ddof 0), as A2Perf reports it.
    pub std: f64,
    /// Median return.
    pub median: f64,
    /// Smallest return.
    pub min: f64,
    /// Largest return.
    pub max: f64,
    /// Number of episodes.
    pub count: usize,
}

/// Summarises episode returns; `None` for an empty slice. Higher is better.
///
/// ```
/// let s = a2perf_metrics::application::returns_summary(&[1.0, 2.0, 3.0]).unwrap();
/// assert_eq!((s.mean, s.median, s.min, s.max, s.count), (2.0, 2.0, 1.0, 3.0, 3));
/// ```
pub fn returns_summary(returns: &[f64]) -> Option<ReturnsSummary> {
    if returns.is_empty() {
        return None;
    }
    let s = numeric::sorted(returns);
    Some(ReturnsSummary {
        mean: numeric::mean(returns),
        std: numeric::std(returns, 0),
        median: numeric::median_sorted(&s),
        min: s[0],
        max: s[s.len() - 1],
        count: returns.len(),
    })
}

/// Generalization: per-task mean returns and their sum (A2Perf's
/// `generalization_rollout_returns`, unit "100 eps. [all tasks]").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Generalization {
    /// `(task, mean return)` in the order given.
    pub per_task: Vec<(String, f64)>,
    /// Sum of the per-task means (higher is better).
    pub total: f64,
}

/// Per-task means over each task's rollouts, averaged over seeds when a task has several return
/// lists, and their sum. Tasks with no returns are skipped.
///
/// ```
/// use a2perf_metrics::application::generalization;
/// let g = generalization(&[("a".into(), vec![vec![1.0, 3.0]]), ("b".into(), vec![vec![2.0], vec![4.0]])]);
/// assert_eq!(g.total, 2.0 + 3.0);
/// ```
pub fn generalization(tasks: &[(String, Vec<Vec<f64>>)]) -> Generalization {
    let per_task: Vec<(String, f64)> = tasks
        .iter()
        .filter_map(|(name, seeds)| {
            let means: Vec<f64> = seeds
                .iter()
                .filter(|r| !r.is_empty())
                .map(|r| r.iter().sum::<f64>() / r.len() as f64)
                .collect();
            (!means.is_empty()).then(|| (name.clone(), numeric::mean(&means)))
        })
        .collect();
    let total = per_task.iter().map(|(_, m)| m).sum();
    Generalization { per_task, total }
}

/// Training energy attributed to a checkpoint: `total × checkpoint / max_checkpoint` (A2Perf's
/// `evaluation.py` assumes energy grows linearly with checkpoint number).
///
/// ```
/// assert_eq!(a2perf_metrics::application::checkpoint_training_energy_kwh(10.0, 25, 100), 2.5);
/// ```
pub fn checkpoint_training_energy_kwh(total_kwh: f64, checkpoint: u64, max_checkpoint: u64) -> f64 {
    if max_checkpoint == 0 {
        return 0.0;
    }
    total_kwh * checkpoint as f64 / max_checkpoint as f64
}

/// Training sample cost of a dataset (kWh): the mean training energy of the policies that
/// generated it (`data/combine.py`'s `training_sample_cost.txt`). `None` if there are none.
///
/// ```
/// assert_eq!(a2perf_metrics::application::training_sample_cost_kwh(&[1.0, 3.0]), Some(2.0));
/// ```
pub fn training_sample_cost_kwh(policy_training_energy_kwh: &[f64]) -> Option<f64> {
    (!policy_training_energy_kwh.is_empty()).then(|| numeric::mean(policy_training_energy_kwh))
}

/// Total energy of an offline-trained agent: the data's sample cost plus its own training energy.
pub fn total_energy_kwh(sample_cost_kwh: f64, training_energy_kwh: f64) -> f64 {
    sample_cost_kwh + training_energy_kwh
}

/// Expertise level of a checkpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Expertise {
    /// Low return.
    Novice,
    /// Middling return.
    Intermediate,
    /// High return.
    Expert,
}

/// How returns are cut into expertise levels (μ, σ over all evaluated checkpoints).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ExpertiseRule {
    /// The original code (`expertise.py`): novice ≤ μ−2σ, intermediate in [μ−σ, μ+σ],
    /// expert ≥ μ+2σ; everything else is unassigned.
    #[default]
    OriginalCode,
    /// The paper's wording: novice ≤ μ−σ, intermediate in (μ−σ, μ+σ), expert ≥ μ+σ.
    OneSigma,
}

/// Assigns levels to checkpoint returns; `None` where the rule leaves a gap. σ is the pandas
/// std (ddof 1) of the returns, as the original computes it from a DataFrame column.
///
/// ```
/// use a2perf_metrics::application::{expertise_levels, Expertise, ExpertiseRule};
/// let r = [0.0, 5.0, 5.0, 5.0, 10.0];
/// let one = expertise_levels(&r, ExpertiseRule::OneSigma);
/// assert_eq!(one[0], Some(Expertise::Novice));
/// assert_eq!(one[2], Some(Expertise::Intermediate));
/// assert_eq!(one[4], Some(Expertise::Expert));
/// ```
pub fn expertise_levels(returns: &[f64], rule: ExpertiseRule) -> Vec<Option<Expertise>> {
    let mu = numeric::mean(returns);
    let sigma = numeric::std(returns, 1);
    returns
        .iter()
        .map(|&r| match rule {
            ExpertiseRule::OriginalCode => {
                if r <= mu - 2.0 * sigma {
                    Some(Expertise::Novice)
                } else if r >= mu + 2.0 * sigma {
                    Some(Expertise::Expert)
                } else if r >= mu - sigma && r <= mu + sigma {
                    Some(Expertise::Intermediate)
                } else {
                    None
                }
            }
            ExpertiseRule::OneSigma => {
                if r <= mu - sigma {
                    Some(Expertise::Novice)
                } else if r >= mu + sigma {
                    Some(Expertise::Expert)
                } else if r.is_finite() && sigma.is_finite() {
                    Some(Expertise::Intermediate)
                } else {
                    None
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn original_rule_leaves_gaps_between_one_and_two_sigma() {
        // μ = 0, σ (ddof 1) = 1 for these values scaled below.
        let base = [-2.0, -1.0, 0.0, 1.0, 2.0];
        let sigma = numeric::std(&base, 1);
        let r: Vec<f64> = base.iter().map(|v| v / sigma).collect();
        let lv = expertise_levels(&r, ExpertiseRule::OriginalCode);
        // ±2/σ' = ±1.26σ: beyond one σ but short of two σ → unassigned.
        assert_eq!(lv[0], None);
        assert_eq!(lv[4], None);
        assert_eq!(lv[1], Some(Expertise::Intermediate));
        assert_eq!(lv[2], Some(Expertise::Intermediate));
        let one = expertise_levels(&r, ExpertiseRule::OneSigma);
        assert_eq!(one[0], Some(Expertise::Novice));
        assert_eq!(one[4], Some(Expertise::Expert));
        let wide = [-10.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 10.0];
        let lv = expertise_levels(&wide, ExpertiseRule::OriginalCode);
        assert_eq!(lv[0], Some(Expertise::Novice));
        assert_eq!(lv[9], Some(Expertise::Expert));
    }

    #[test]
    fn costs_and_summaries() {
        assert_eq!(total_energy_kwh(1.5, 2.0), 3.5);
        assert_eq!(training_sample_cost_kwh(&[]), None);
        assert_eq!(checkpoint_training_energy_kwh(1.0, 1, 0), 0.0);
        assert!(returns_summary(&[]).is_none());
        let s = returns_summary(&[1.0, 3.0]).unwrap();
        assert_eq!(s.std, 1.0);
        let g = generalization(&[
            ("empty".into(), vec![vec![]]),
            ("a".into(), vec![vec![2.0]]),
        ]);
        assert_eq!(g.per_task.len(), 1);
        assert_eq!(g.total, 2.0);
    }
}
