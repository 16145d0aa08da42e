//! `a2perf metrics`: score your own training curves, rollouts and scores.

use std::path::PathBuf;

use a2perf_metrics::a2perf::{self as a2, A2PerfMetric};
use a2perf_metrics::chan2019::{Baseline, Dispersion, Metric, MetricValues};
use a2perf_metrics::csv;
use a2perf_metrics::rliable::{self, Aggregate, Aggregates, BootstrapConfig};
use anyhow::{Context, Result};
use clap::{Args, Subcommand, ValueEnum};
use serde_json::{Map, Value, json};

/// Arguments of `a2perf metrics`.
#[derive(Args, Debug)]
pub struct MetricsArgs {
    #[command(subcommand)]
    command: MetricsCommand,
}

#[derive(Subcommand, Debug)]
enum MetricsCommand {
    /// Reliability metrics of training curves (`run,step,value`) and rollout returns (`return`).
    Reliability(ReliabilityArgs),
    /// Interquartile mean with a stratified-bootstrap 95% interval, per algorithm
    /// (`algorithm,task,run,score`).
    Iqm(IqmArgs),
}

/// Which definitions to use.
#[derive(Clone, Copy, Debug, ValueEnum)]
enum Definition {
    /// A2Perf's `reliability.py` (the paper's tables).
    A2perf,
    /// The rl-reliability-metrics library defaults (Chan et al. 2019).
    Chan2019,
}

#[derive(Args, Debug)]
struct ReliabilityArgs {
    /// CSV with header `run,step,value`.
    #[arg(long, value_name = "CURVES.csv")]
    curves: PathBuf,
    /// CSV with header `return`, one episode return per line.
    #[arg(long, value_name = "ROLLOUTS.csv")]
    rollouts: Option<PathBuf>,
    /// Metric definitions.
    #[arg(long, value_enum, default_value_t = Definition::A2perf)]
    definition: Definition,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

#[derive(Args, Debug)]
struct IqmArgs {
    /// CSV with header `algorithm,task,run,score`.
    #[arg(long, value_name = "SCORES.csv")]
    scores: PathBuf,
    /// Bootstrap replicates.
    #[arg(long, default_value_t = 50_000)]
    reps: usize,
    /// Seed of the bootstrap.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `a2perf metrics …`.
pub fn run(args: &MetricsArgs) -> Result<()> {
    match &args.command {
        MetricsCommand::Reliability(a) => reliability(a),
        MetricsCommand::Iqm(a) => iqm(a),
    }
}

fn reliability(args: &ReliabilityArgs) -> Result<()> {
    let named = csv::read_curves(&args.curves)?;
    let curves = named.curves();
    let rollouts = args
        .rollouts
        .as_deref()
        .map(csv::read_rollouts)
        .transpose()?;
    let out = match args.definition {
        Definition::A2perf => a2perf_json(&curves, rollouts.as_deref()).map_err(|e| {
            // Name the run as the file does, not by its position.
            match e.downcast_ref::<a2::ReliabilityError>() {
                Some(
                    a2::ReliabilityError::TooShort { run, .. }
                    | a2::ReliabilityError::StepSpacing { run, .. },
                ) => {
                    let id = named.runs.get(*run).map_or("?", |(id, _)| id.as_str());
                    e.context(format!("{}: run `{id}`", args.curves.display()))
                }
                _ => e,
            }
        })?,
        Definition::Chan2019 => chan2019_json(&curves, rollouts.as_deref())?,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        print_table(&out, args.definition);
    }
    Ok(())
}

fn a2perf_json(curves: &[a2perf_metrics::Curve], rollouts: Option<&[f64]>) -> Result<Value> {
    let t = a2::training_reliability(curves)?;
    let mut m = Map::new();
    let spread = |s: a2::Spread| json!({"mean": s.mean, "std": s.std});
    m.insert(
        "dispersion_across_runs".into(),
        spread(t.dispersion_across_runs),
    );
    m.insert(
        "dispersion_within_runs".into(),
        spread(t.dispersion_within_runs),
    );
    m.insert("short_term_risk".into(), json!(t.short_term_risk));
    m.insert("long_term_risk".into(), json!(t.long_term_risk));
    m.insert("risk_across_runs".into(), json!(t.risk_across_runs));
    if let Some(r) = rollouts {
        let r = a2::rollout_reliability(r).context("computing the rollout metrics")?;
        m.insert(
            "dispersion_across_rollouts".into(),
            json!(r.dispersion_across_rollouts),
        );
        m.insert("risk_across_rollouts".into(), json!(r.risk_across_rollouts));
    }
    Ok(Value::Object(m))
}

fn chan2019_json(curves: &[a2perf_metrics::Curve], rollouts: Option<&[f64]>) -> Result<Value> {
    let last_common = a2perf_metrics::chan2019::valid_eval_points(curves, 1.0)?
        .last()
        .copied();
    let mut metrics = vec![
        Metric::iqr_within_runs(),
        Metric::iqr_across_runs(),
        Metric::lower_cvar_on_diffs(),
        Metric::upper_cvar_on_drawdown(),
        Metric::lower_cvar_on_across(last_common.map(|s| vec![s])),
        Metric::MedianPerfDuringTraining {
            window_size: None,
            eval_points: None,
            baseline: Baseline::None,
        },
    ];
    if rollouts.is_some() {
        metrics.push(Metric::DispersionAcrossRollouts {
            dispersion: Dispersion::Iqr,
            baseline: Baseline::None,
        });
        metrics.push(Metric::CvarAcrossRollouts {
            tail: a2perf_metrics::Tail::Lower,
            alpha: 0.05,
            baseline: Baseline::None,
        });
    }
    let mut m = Map::new();
    for metric in metrics {
        let values = match (metric.takes_rollouts(), rollouts) {
            (true, Some(r)) => MetricValues::Flat(metric.evaluate_rollouts(&[r.to_vec()])?),
            _ => metric
                .evaluate(curves)
                .with_context(|| format!("computing {}", metric.class_name()))?,
        };
        m.insert(
            metric.class_name(),
            json!({
                "bigger_is_better": metric.direction().bigger_is_better(),
                "dimensions": metric.dimensions(),
                "values": values,
            }),
        );
    }
    Ok(Value::Object(m))
}

fn print_table(out: &Value, definition: Definition) {
    let Some(obj) = out.as_object() else { return };
    match definition {
        Definition::A2perf => {
            println!("{:<28} {:>14} {:>14}  better", "metric", "value", "std");
            for metric in A2PerfMetric::ALL {
                let Some(v) = obj.get(metric.name()) else {
                    continue;
                };
                let better = if metric.direction().bigger_is_better() {
                    "higher"
                } else {
                    "lower"
                };
                let num = |v: &Value| v.as_f64().map_or("n/a".to_string(), |x| format!("{x:.6}"));
                match v {
                    Value::Object(s) => println!(
                        "{:<28} {:>14} {:>14}  {better}",
                        metric.name(),
                        num(&s["mean"]),
                        num(&s["std"])
                    ),
                    other => println!(
                        "{:<28} {:>14} {:>14}  {better}",
                        metric.name(),
                        num(other),
                        ""
                    ),
                }
            }
        }
        Definition::Chan2019 => {
            for (name, v) in obj {
                let better = if v["bigger_is_better"].as_bool() == Some(true) {
                    "higher is better"
                } else {
                    "lower is better"
                };
                println!("{name} ({better}): {}", v["values"]);
            }
        }
    }
}

fn iqm(args: &IqmArgs) -> Result<()> {
    let named = csv::read_scores(&args.scores)?;
    let cfg = BootstrapConfig {
        reps: args.reps,
        seed: args.seed,
        ..BootstrapConfig::default()
    };
    let stat = Aggregates(vec![Aggregate::Iqm]);
    let mut rows = Map::new();
    for (algo, scores) in &named.algorithms {
        let ci = rliable::bootstrap_ci(scores, &stat, &cfg)
            .with_context(|| format!("bootstrapping algorithm `{algo}`"))?;
        rows.insert(
            algo.clone(),
            json!({
                "iqm": ci.point[0],
                "ci_lower": ci.lower[0],
                "ci_upper": ci.upper[0],
                "runs": scores.runs(),
                "tasks": scores.tasks(),
            }),
        );
    }
    if args.json {
        let out = json!({"confidence": cfg.confidence, "reps": cfg.reps, "seed": cfg.seed, "algorithms": rows});
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "{:<24} {:>10} {:>22}  runs×tasks",
            "algorithm", "IQM", "95% CI"
        );
        for (algo, r) in &rows {
            println!(
                "{:<24} {:>10.4} [{:>9.4}, {:>9.4}]  {}×{}",
                algo,
                r["iqm"].as_f64().unwrap_or(f64::NAN),
                r["ci_lower"].as_f64().unwrap_or(f64::NAN),
                r["ci_upper"].as_f64().unwrap_or(f64::NAN),
                r["runs"],
                r["tasks"]
            );
        }
        println!(
            "(stratified bootstrap, {} replicates, seed {})",
            cfg.reps, cfg.seed
        );
    }
    Ok(())
}
