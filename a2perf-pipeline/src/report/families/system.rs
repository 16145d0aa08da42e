//! System: energy, power, GPU power, RAM and wall-clock time of training, and inference time,
//! power, energy and RAM of inference, from the meters' measurements (`train_system.json`,
//! `inference.json`), with their provenance (measured, estimated, absent) in the notes.

use a2perf_core::{MeterReport, Provenance};

use crate::report::load::RunData;
use crate::report::model::{Category, ENERGY_NAMES, MetricValue, PEAK_RAM_NAMES, meter_value};
use crate::report::statistics::Seeds;
use crate::spec::ObservationSource;
use crate::train::PhaseSystem;

const GPU_POWER_NAMES: &[&str] = &["gpu_power_w"];
const MEAN_RAM_NAMES: &[&str] = &["mean_ram_gb", "ram_mean_gb"];

/// Where a system metric comes from.
#[derive(Clone, Copy)]
enum Source {
    /// A meter's measurement, under any of these names.
    Meter(&'static [&'static str]),
    /// The phase's energy over its wall-clock time.
    Power,
}

/// The metrics of one phase measured by the meters: (key, label, unit, source), in table
/// order.
type Specs = [(&'static str, &'static str, &'static str, Source)];

/// The training half: `energy`, `power`, `gpu_power`, `mean_ram`, `peak_ram`, `wall_clock`.
pub(crate) fn training(runs: &[RunData], seeds: &mut Seeds) -> Vec<MetricValue> {
    use Source::*;
    let cat = Category::SystemTraining;
    let train: Vec<Option<&PhaseSystem>> = runs.iter().map(|r| r.train_system.as_ref()).collect();
    let specs: &Specs = &[
        ("energy", "Energy consumed", "kWh", Meter(ENERGY_NAMES)),
        ("power", "Mean power", "W", Power),
        ("gpu_power", "GPU power", "W", Meter(GPU_POWER_NAMES)),
        ("mean_ram", "Mean RAM usage", "GB", Meter(MEAN_RAM_NAMES)),
        ("peak_ram", "Peak RAM usage", "GB", Meter(PEAK_RAM_NAMES)),
    ];
    let mut out = measured(cat, &train, specs, seeds);
    out.push(
        seeds.metric(
            MetricValue::new(cat, "wall_clock", "Wall-clock time", "Hours", false),
            train
                .iter()
                .map(|s| s.map(|s| s.wall_clock_s / 3600.0))
                .collect(),
            "no train_system.json",
            Vec::new(),
        ),
    );
    out
}

/// The inference half: `inference_time`, `inference_power`, `inference_gpu_power`,
/// `inference_energy`, `inference_mean_ram`, `inference_peak_ram`.
pub(crate) fn inference(runs: &[RunData], seeds: &mut Seeds) -> Vec<MetricValue> {
    use Source::*;
    let cat = Category::SystemInference;
    let inf: Vec<Option<&PhaseSystem>> = runs
        .iter()
        .map(|r| r.inference.as_ref().map(|i| &i.system))
        .collect();
    let times = runs
        .iter()
        .map(|r| {
            r.inference
                .as_ref()
                .map(|i| i.inference_time_ms.mean)
                .filter(|v| v.is_finite())
        })
        .collect();
    let mut out = vec![seeds.metric(
        MetricValue::new(cat, "inference_time", "Inference time", "ms", false),
        times,
        "run `a2perf infer` first",
        vec![inference_time_note(runs)],
    )];
    let specs: &Specs = &[
        ("inference_power", "Mean power", "W", Power),
        (
            "inference_gpu_power",
            "GPU power",
            "W",
            Meter(GPU_POWER_NAMES),
        ),
        (
            "inference_energy",
            "Energy consumed",
            "kWh",
            Meter(ENERGY_NAMES),
        ),
        (
            "inference_mean_ram",
            "Mean RAM usage",
            "GB",
            Meter(MEAN_RAM_NAMES),
        ),
        (
            "inference_peak_ram",
            "Peak RAM usage",
            "GB",
            Meter(PEAK_RAM_NAMES),
        ),
    ];
    out.extend(measured(cat, &inf, specs, seeds));
    out
}

/// The metrics `specs` of one phase (lower is better for all of them).
fn measured(
    cat: Category,
    systems: &[Option<&PhaseSystem>],
    specs: &Specs,
    seeds: &mut Seeds,
) -> Vec<MetricValue> {
    specs
        .iter()
        .map(|&(key, label, unit, source)| {
            let m = MetricValue::new(cat, key, label, unit, false);
            match source {
                Source::Meter(names) => meter(m, systems, names, seeds),
                Source::Power => power(m, systems, seeds),
            }
        })
        .collect()
}

/// Which observations the seeds' inference times were measured on (the profile times random
/// observation-space samples, as the original harness did; the default, the rollouts').
fn inference_time_note(runs: &[RunData]) -> String {
    let sources: Vec<ObservationSource> = runs
        .iter()
        .filter_map(|r| r.inference.as_ref().map(|i| i.observation_source))
        .collect();
    let all = |s: ObservationSource| !sources.is_empty() && sources.iter().all(|x| *x == s);
    if all(ObservationSource::Random) {
        "per call, on random observation-space samples (the original harness's method)".into()
    } else if sources.is_empty() || all(ObservationSource::Rollouts) {
        "per call, on the observations met in the rollouts".into()
    } else {
        "per call; the seeds differ in what was timed (rollout observations or random samples)"
            .into()
    }
}

/// A meter's measurement across the runs of a group, with provenance notes; missing, with the
/// meter's reason, when any run's meter reports it absent.
fn meter(
    metric: MetricValue,
    systems: &[Option<&PhaseSystem>],
    names: &[&str],
    seeds: &mut Seeds,
) -> MetricValue {
    let mut values = Vec::new();
    let mut notes = Vec::new();
    let mut absent = None;
    for s in systems {
        match s.and_then(|s| meter_value(&s.meters, names)) {
            Some((Some(v), prov)) => {
                values.push(Some(v));
                if let Provenance::Estimated(how) = prov {
                    notes.push(format!("estimated: {how}"));
                }
                if let Some(s) = s
                    && s.concurrent_runs > 1
                {
                    notes.push(format!(
                        "process-wide while {} runs shared the process",
                        s.concurrent_runs
                    ));
                }
            }
            Some((None, Provenance::Absent(why))) => {
                absent = Some(why);
                values.push(None);
            }
            _ => values.push(None),
        }
    }
    if let Some(why) = absent {
        return metric.missing(format!("absent: {why}"));
    }
    seeds.metric(metric, values, "not measured", notes)
}

/// Mean total power of a phase: its energy over its wall-clock time.
fn power(metric: MetricValue, systems: &[Option<&PhaseSystem>], seeds: &mut Seeds) -> MetricValue {
    let mut derived = Vec::with_capacity(systems.len());
    for s in systems {
        derived.push(s.map(|s| {
            let mut meters = MeterReport::default();
            if let Some((Some(e), prov)) = meter_value(&s.meters, ENERGY_NAMES) {
                meters.measurements.push(a2perf_core::Measurement {
                    name: "derived_power_w".into(),
                    value: Some(e * 3.6e6 / s.wall_clock_s.max(1e-9)),
                    unit: "W".into(),
                    provenance: prov,
                });
            }
            PhaseSystem {
                meters,
                ..s.clone()
            }
        }));
    }
    let refs: Vec<Option<&PhaseSystem>> = derived.iter().map(Option::as_ref).collect();
    let mut m = meter(metric, &refs, &["derived_power_w"], seeds);
    if m.mean.is_some() {
        let note = m.note.take().map(|n| format!("; {n}")).unwrap_or_default();
        m.note = Some(format!("energy / wall-clock time{note}"));
    }
    m
}
