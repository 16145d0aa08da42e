//! Application: the returns of the inference rollouts and the generalization sum over the
//! suite's tasks.

use crate::report::load::RunData;
use crate::report::model::{Category::Application, MetricValue};
use crate::report::statistics::Seeds;

/// `returns` (the mean rollout return of each seed) and `generalization` (each seed's sum of
/// mean returns over the generalization tasks).
pub(crate) fn metrics(runs: &[RunData], seeds: &mut Seeds) -> Vec<MetricValue> {
    // Runs not yet inferred or generalized take the episode counts their config asks for.
    let first = &runs[0].run.record;
    let returns: Vec<Option<f64>> = runs
        .iter()
        .map(|r| r.inference.as_ref().map(|i| i.returns.mean))
        .collect();
    let episodes = runs
        .iter()
        .find_map(|r| r.inference.as_ref().map(|i| i.episodes))
        .unwrap_or(first.inference.episodes);
    let returns = seeds.metric(
        MetricValue::new(
            Application,
            "returns",
            "Returns",
            &format!("{episodes} eps."),
            true,
        ),
        returns,
        "run `a2perf infer` first",
        Vec::new(),
    );
    let gen_sum: Vec<Option<f64>> = runs
        .iter()
        .map(|r| {
            r.generalization
                .as_ref()
                .and_then(|g| g.sum_of_mean_returns)
        })
        .collect();
    let gen_eps = runs
        .iter()
        .find_map(|r| r.generalization.as_ref().map(|g| g.episodes))
        .unwrap_or(first.generalization.episodes);
    let failed_task = runs.iter().find_map(|r| {
        r.generalization.as_ref().and_then(|g| {
            g.tasks.iter().find_map(|t| {
                t.error
                    .as_ref()
                    .map(|e| format!("task {} failed: {e}", t.name))
            })
        })
    });
    let generalization = seeds.metric(
        MetricValue::new(
            Application,
            "generalization",
            "Generalization",
            &format!("{gen_eps} eps. [all tasks]"),
            true,
        ),
        gen_sum,
        failed_task
            .as_deref()
            .unwrap_or("run `a2perf generalize` first"),
        Vec::new(),
    );
    vec![returns, generalization]
}
