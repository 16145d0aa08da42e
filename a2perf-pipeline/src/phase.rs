//! One phase's system measurement: the meters a phase runs ([`MeterFactory`]), what they
//! measured ([`PhaseSystem`]) and how the figures of a run's training segments combine.

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use a2perf_core::{Measurement, Meter, MeterReport, MeterSet, Provenance};
use serde::{Deserialize, Serialize};

/// The phase a meter measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Phase {
    /// The whole of training.
    Train,
    /// Inference rollouts.
    Inference,
}

/// Builds the system meters of a phase; the path is the run directory (for `emissions.csv`-style
/// outputs).
pub type MeterFactory =
    Arc<dyn Fn(Phase, &Path, &MetricSettings) -> Vec<Box<dyn Meter>> + Send + Sync>;

/// A factory that builds no meters (only wall-clock time is then recorded).
pub fn no_meters() -> MeterFactory {
    Arc::new(|_, _, _| Vec::new())
}

/// Settings of the system meters and of the statistics (from the config's `metrics` section).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MetricSettings {
    /// Seconds between RAM samples.
    pub ram_sample_interval_s: f64,
    /// Grid carbon intensity, g CO2-eq per kWh.
    pub carbon_intensity_g_per_kwh: f64,
    /// `auto`, `rapl` or `estimate`.
    pub energy_method: String,
    /// `a2perf` or `chan2019`.
    pub reliability_definition: String,
    /// Bootstrap resamples for confidence intervals.
    pub bootstrap_reps: usize,
}

impl Default for MetricSettings {
    fn default() -> Self {
        Self {
            ram_sample_interval_s: 1.0,
            carbon_intensity_g_per_kwh: 475.0,
            energy_method: "auto".into(),
            reliability_definition: "a2perf".into(),
            bootstrap_reps: 50_000,
        }
    }
}

/// System measurements of one phase (`train_system.json`, and the `system` part of
/// `inference.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhaseSystem {
    /// Wall-clock time of the phase in seconds.
    pub wall_clock_s: f64,
    /// Most runs that shared this process while the phase ran. Meters measure the whole
    /// process, so with more than one the RAM and energy figures cover all of them.
    pub concurrent_runs: usize,
    /// The process that measured the phase (absent in records written before it was kept, and
    /// for segments of several processes combined).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pid: Option<u32>,
    /// What the meters reported.
    pub meters: MeterReport,
    /// Meters that failed, and why (their values are then missing, never zero).
    pub meter_errors: Vec<String>,
    /// Training segments (processes) these figures combine: more than one when the run was
    /// interrupted and resumed (see [`combine_segments`]).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub segments: usize,
    /// How the figures were combined, and what they miss.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

fn one() -> usize {
    1
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

/// Combines the system figures of a run's training segments: wall-clock time, energy,
/// emissions and other totals (units `kWh`, `kg`, `h`, `s`) are summed, `peak_*` values take the
/// maximum, and everything else (mean RAM, power) is the mean weighted by each segment's
/// wall-clock time. A value missing in any segment is missing in the result. `killed` segments
/// left no figures: the note says that their time and energy are not included.
///
/// ```
/// use a2perf_core::{Measurement, MeterReport};
/// use a2perf_pipeline::train::{PhaseSystem, combine_segments};
/// let seg = |secs: f64, kwh: f64, peak: f64, mean: f64| PhaseSystem {
///     wall_clock_s: secs,
///     concurrent_runs: 1,
///     pid: None,
///     meters: MeterReport { measurements: vec![
///         Measurement::measured("energy_kwh", kwh, "kWh"),
///         Measurement::measured("peak_ram_gb", peak, "GB"),
///         Measurement::measured("mean_ram_gb", mean, "GB"),
///     ] },
///     meter_errors: vec![],
///     segments: 1,
///     note: None,
/// };
/// let all = combine_segments(&[seg(10.0, 1.0, 2.0, 1.0), seg(30.0, 2.0, 1.5, 2.0)], 0);
/// assert_eq!(all.wall_clock_s, 40.0);
/// assert_eq!(all.segments, 2);
/// assert_eq!(all.meters.value("energy_kwh"), Some(3.0));
/// assert_eq!(all.meters.value("peak_ram_gb"), Some(2.0));
/// assert_eq!(all.meters.value("mean_ram_gb"), Some(1.75));
/// assert!(all.note.unwrap().contains("combined from 2 training segments"));
/// ```
pub fn combine_segments(parts: &[PhaseSystem], killed: usize) -> PhaseSystem {
    let n = parts.len() + killed;
    if let ([only], 0) = (parts, killed) {
        return only.clone();
    }
    let wall: f64 = parts.iter().map(|p| p.wall_clock_s).sum();
    let mut names: Vec<&str> = Vec::new();
    for p in parts {
        for m in &p.meters.measurements {
            if !names.contains(&m.name.as_str()) {
                names.push(&m.name);
            }
        }
    }
    let measurements = names
        .iter()
        .map(|name| {
            let found: Vec<(Option<&Measurement>, f64)> = parts
                .iter()
                .map(|p| (p.meters.get(name), p.wall_clock_s))
                .collect();
            let first = found
                .iter()
                .find_map(|(m, _)| *m)
                .cloned()
                .unwrap_or_else(|| Measurement::absent(name, "", "not reported"));
            let values: Option<Vec<(f64, f64)>> = found
                .iter()
                .map(|(m, w)| m.and_then(|m| m.value).map(|v| (v, *w)))
                .collect();
            let Some(values) = values else {
                let missing = found
                    .iter()
                    .filter(|(m, _)| m.and_then(|m| m.value).is_none())
                    .count();
                return match first.value {
                    None => first,
                    Some(_) => Measurement::absent(
                        name,
                        &first.unit,
                        &format!("missing in {missing} of {} training segments", parts.len()),
                    ),
                };
            };
            let total_like = ["kWh", "kg", "h", "s"].contains(&first.unit.as_str());
            let value = if total_like {
                values.iter().map(|(v, _)| v).sum()
            } else if name.starts_with("peak_") {
                values
                    .iter()
                    .map(|(v, _)| *v)
                    .fold(f64::NEG_INFINITY, f64::max)
            } else {
                let w: f64 = values.iter().map(|(_, w)| w).sum();
                if w > 0.0 {
                    values.iter().map(|(v, w)| v * w).sum::<f64>() / w
                } else {
                    values.iter().map(|(v, _)| v).sum::<f64>() / values.len() as f64
                }
            };
            let estimated = found
                .iter()
                .find_map(|(m, _)| match m.map(|m| &m.provenance) {
                    Some(Provenance::Estimated(how)) => Some(how.clone()),
                    _ => None,
                });
            Measurement {
                name: first.name.clone(),
                value: Some(value),
                unit: first.unit.clone(),
                provenance: match estimated {
                    Some(how) => Provenance::Estimated(format!(
                        "{how} (combined over {} segments)",
                        parts.len()
                    )),
                    None => Provenance::Measured,
                },
            }
        })
        .collect();
    let mut note = format!(
        "combined from {n} training segments (the run was interrupted and resumed): wall-clock \
         time, energy and emissions summed, peak RAM the maximum, mean RAM and power weighted by \
         each segment's wall-clock time"
    );
    if killed > 0 {
        note.push_str(&format!(
            "; {killed} segment(s) killed without a meter report (kill -9): their time and \
             energy are not included"
        ));
    }
    PhaseSystem {
        wall_clock_s: wall,
        concurrent_runs: parts.iter().map(|p| p.concurrent_runs).max().unwrap_or(1),
        pid: parts
            .first()
            .and_then(|p| p.pid)
            .filter(|pid| parts.iter().all(|p| p.pid == Some(*pid))),
        meters: MeterReport { measurements },
        meter_errors: parts
            .iter()
            .enumerate()
            .flat_map(|(i, p)| {
                p.meter_errors
                    .iter()
                    .map(move |e| format!("segment {}: {e}", i + 1))
            })
            .collect(),
        segments: n,
        note: Some(note),
    }
}

static ACTIVE_RUNS: AtomicUsize = AtomicUsize::new(0);

/// Counts this run as active for as long as it lives.
pub(crate) struct ActiveRun {
    max_seen: usize,
}

impl ActiveRun {
    pub(crate) fn enter() -> Self {
        let now = ACTIVE_RUNS.fetch_add(1, Ordering::SeqCst) + 1;
        Self { max_seen: now }
    }
    pub(crate) fn observe(&mut self) -> usize {
        self.max_seen = self.max_seen.max(ACTIVE_RUNS.load(Ordering::SeqCst));
        self.max_seen
    }
}

impl Drop for ActiveRun {
    fn drop(&mut self) {
        ACTIVE_RUNS.fetch_sub(1, Ordering::SeqCst);
    }
}

/// System meters running over a phase that is not one closure call — a front end's block of
/// code, such as Python's `with a2perf_rs.TrainingRun(...)` — from [`start`](Self::start) to
/// [`finish`](Self::finish), with the phase's wall-clock time. Meter failures are recorded, not
/// fatal: a missing figure is reported as missing. The phase counts as an active run of this
/// process while it lasts (see [`PhaseSystem::concurrent_runs`]).
///
/// ```
/// use a2perf_pipeline::train::MeteredPhase;
/// let phase = MeteredPhase::start(Vec::new());
/// let system = phase.finish();
/// assert!(system.wall_clock_s >= 0.0 && system.meter_errors.is_empty());
/// assert!(system.concurrent_runs >= 1);
/// ```
pub struct MeteredPhase {
    set: MeterSet,
    errors: Vec<String>,
    active: ActiveRun,
    started_ok: bool,
    started: Instant,
}

impl MeteredPhase {
    /// Starts `meters` and the clock.
    pub fn start(meters: Vec<Box<dyn Meter>>) -> Self {
        let mut set = MeterSet::new(meters);
        let mut errors = Vec::new();
        let active = ActiveRun::enter();
        let started_ok = match set.start() {
            Ok(()) => true,
            Err(e) => {
                errors.push(e.to_string());
                false
            }
        };
        Self {
            set,
            errors,
            active,
            started_ok,
            started: Instant::now(),
        }
    }

    /// Seconds since [`start`](Self::start).
    pub fn elapsed_s(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Stops the clock and the meters and returns what they measured.
    pub fn finish(mut self) -> PhaseSystem {
        let wall = self.elapsed_s();
        let meters = if self.started_ok {
            self.set.finish().unwrap_or_else(|e| {
                self.errors.push(e.to_string());
                MeterReport::default()
            })
        } else {
            MeterReport::default()
        };
        PhaseSystem {
            wall_clock_s: wall,
            concurrent_runs: self.active.observe(),
            pid: Some(std::process::id()),
            meters,
            meter_errors: self.errors,
            segments: 1,
            note: None,
        }
    }
}

/// Runs `f` between the start and the finish of `meters` (see [`MeteredPhase`]).
pub(crate) fn measured<T>(meters: Vec<Box<dyn Meter>>, f: impl FnOnce() -> T) -> (T, PhaseSystem) {
    let phase = MeteredPhase::start(meters);
    let out = f();
    (out, phase.finish())
}
