//! Data cost: the training sample cost of an offline dataset, and that cost plus the training
//! energy.

use crate::report::load::RunData;
use crate::report::model::{Category::DataCost, ENERGY_NAMES, MetricValue, meter_value};
use crate::report::statistics::Seeds;

/// `training_sample_cost` and `total_energy`, not applicable when no run learned from a
/// dataset.
pub(crate) fn metrics(runs: &[RunData], seeds: &mut Seeds) -> Vec<MetricValue> {
    let sample_cost = MetricValue::new(
        DataCost,
        "training_sample_cost",
        "Training sample cost",
        "kWh",
        false,
    );
    let total = MetricValue::new(
        DataCost,
        "total_energy",
        "Sample cost + training energy",
        "kWh",
        false,
    );
    if runs.iter().all(|r| r.run.record.dataset.is_none()) {
        let why = "not applicable: trained online, no dataset";
        return vec![sample_cost.missing(why), total.missing(why)];
    }
    let cost: Vec<Option<f64>> = runs
        .iter()
        .map(|r| {
            r.run
                .record
                .dataset
                .as_ref()
                .and_then(|d| d.training_sample_cost_kwh)
        })
        .collect();
    let train_energy: Vec<Option<f64>> = runs
        .iter()
        .map(|r| {
            r.train_system
                .as_ref()
                .and_then(|s| meter_value(&s.meters, ENERGY_NAMES))
                .and_then(|(v, _)| v)
        })
        .collect();
    let methods: Vec<String> = runs
        .iter()
        .filter_map(|r| {
            r.run
                .record
                .dataset
                .as_ref()
                .map(|d| format!("cost method: {}", d.cost_method))
        })
        .collect();
    let totals: Vec<Option<f64>> = cost
        .iter()
        .zip(&train_energy)
        .map(|(c, e)| Some((*c)? + (*e)?))
        .collect();
    vec![
        seeds.metric(sample_cost, cost, "no sample cost recorded", methods),
        seeds.metric(
            total,
            totals,
            "sample cost or training energy missing",
            Vec::new(),
        ),
    ]
}
