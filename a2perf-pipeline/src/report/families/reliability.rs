//! Reliability: A2Perf's seven metrics, five over the training curves and two over the pooled
//! inference rollouts (`a2perf_metrics::a2perf`).

use crate::CURVE_JSON;
use crate::report::load::RunData;
use crate::report::model::{Category, MetricValue};

/// The seven reliability metrics; each says why when it cannot be computed. A config asking
/// for the chan2019 definitions gets A2Perf's here, with a note saying how to score the other.
pub(crate) fn metrics(runs: &[RunData]) -> Vec<MetricValue> {
    let mut rel = computed(runs);
    if runs
        .iter()
        .any(|r| r.run.record.metrics.reliability_definition != "a2perf")
    {
        for m in &mut rel {
            let why = "the config asks for the chan2019 definitions; this table uses A2Perf's \
                       (score curves.csv with `a2perf metrics reliability --definition chan2019`)";
            m.note = Some(match m.note.take() {
                Some(n) => format!("{n}; {why}"),
                None => why.into(),
            });
        }
    }
    rel
}

fn computed(runs: &[RunData]) -> Vec<MetricValue> {
    use Category::Reliability;
    use a2perf_metrics::a2perf as rel;
    let curves: std::result::Result<Vec<a2perf_metrics::Curve>, String> = runs
        .iter()
        .map(|r| {
            let (steps, values): (Vec<f64>, Vec<f64>) = r
                .curve
                .points
                .iter()
                .map(|p| (p.env_steps as f64, p.mean_return))
                .unzip();
            a2perf_metrics::Curve::new(steps, values)
                .map_err(|e| format!("{}: {e}", r.run.dir.join(CURVE_JSON).display()))
        })
        .collect();
    let mk = |key: &str, label: &str, unit: &str, higher: bool| {
        MetricValue::new(Reliability, key, label, unit, higher)
    };
    let mut out = Vec::new();
    let spread =
        |m: MetricValue, r: std::result::Result<rel::Spread, rel::ReliabilityError>| match r {
            Ok(s) => m.scalar(s.mean, Some(s.std)),
            Err(e) => m.missing(e.to_string()),
        };
    let scalar = |m: MetricValue, r: std::result::Result<f64, rel::ReliabilityError>| match r {
        Ok(v) => m.scalar(v, None),
        Err(e) => m.missing(e.to_string()),
    };
    let specs = [
        (
            "dispersion_across_runs",
            "Dispersion across runs",
            "IQR",
            false,
        ),
        (
            "dispersion_within_runs",
            "Dispersion within runs",
            "IQR",
            false,
        ),
        ("short_term_risk", "Short-term risk", "CVaR", false),
        ("long_term_risk", "Long-term risk", "CVaR", false),
        ("risk_across_runs", "Risk across runs", "CVaR", true),
    ];
    match &curves {
        Ok(curves) => {
            let across = if curves.len() < 3 {
                Err(format!("needs at least 3 runs, have {}", curves.len()))
            } else {
                Ok(())
            };
            for (key, label, unit, higher) in specs {
                let m = mk(key, label, unit, higher);
                out.push(match key {
                    "dispersion_across_runs" => match &across {
                        Err(why) => m.missing(why.clone()),
                        Ok(()) => spread(m, rel::dispersion_across_runs(curves)),
                    },
                    "dispersion_within_runs" => spread(m, rel::dispersion_within_runs(curves)),
                    "short_term_risk" => scalar(m, rel::short_term_risk(curves)),
                    "long_term_risk" => scalar(m, rel::long_term_risk(curves)),
                    _ => scalar(m, rel::risk_across_runs(curves)),
                });
            }
        }
        Err(why) => {
            for (key, label, unit, higher) in specs {
                out.push(mk(key, label, unit, higher).missing(why.clone()));
            }
        }
    }
    let pooled: Option<Vec<f64>> = runs
        .iter()
        .map(|r| r.inference.as_ref().map(|i| i.rollout_returns.clone()))
        .collect::<Option<Vec<_>>>()
        .map(|v| v.concat());
    let rollouts = [
        (
            "dispersion_across_rollouts",
            "Dispersion across rollouts",
            "IQR",
            false,
        ),
        ("risk_across_rollouts", "Risk across rollouts", "CVaR", true),
    ];
    for (key, label, unit, higher) in rollouts {
        let m = mk(key, label, unit, higher);
        out.push(match &pooled {
            None => m.missing("run `a2perf infer` first"),
            Some(p) if key == "dispersion_across_rollouts" => {
                scalar(m, rel::dispersion_across_rollouts(p))
            }
            Some(p) => scalar(m, rel::risk_across_rollouts(p)),
        });
    }
    out
}
