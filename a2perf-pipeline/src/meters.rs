//! The system meters the command-line pipelines use: `a2perf-metrics`' [`SystemMeter`] (RAM
//! sampler, CPU energy from RAPL or estimated, RAM power model, GPU through NVML with the `nvml`
//! feature and absent otherwise, emissions), which also appends a CodeCarbon-style row to `train_emissions.csv` /
//! `inference_emissions.csv` in the run directory.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use a2perf_core::{Meter, MeterError, MeterReport};
use a2perf_metrics::system::{SystemMeter, SystemMeterConfig, append_emissions_csv};

use crate::phase::{MeterFactory, MetricSettings, Phase};

pub use crate::run_dir::{INFERENCE_EMISSIONS_FILE, TRAIN_EMISSIONS_FILE};

/// A [`SystemMeter`] that writes its emissions row next to the run's results when it finishes.
pub struct RunSystemMeter {
    inner: SystemMeter,
    csv: PathBuf,
}

impl RunSystemMeter {
    /// Meters `phase` of the run in `dir` with `settings`.
    pub fn new(phase: Phase, dir: &Path, settings: &MetricSettings) -> Self {
        let mut cfg = SystemMeterConfig {
            interval: Duration::from_secs_f64(settings.ram_sample_interval_s.clamp(0.01, 3600.0)),
            carbon_intensity_g_per_kwh: settings.carbon_intensity_g_per_kwh,
            project_name: format!(
                "a2perf_{}",
                match phase {
                    Phase::Train => "train",
                    Phase::Inference => "inference",
                }
            ),
            run_id: dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            experiment_id: dir
                .parent()
                .and_then(Path::file_name)
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            ..Default::default()
        };
        if settings.energy_method == "estimate" {
            // No counters under this root, so the meter falls back to its documented estimate.
            cfg.powercap_root = dir.join(".no-rapl");
        }
        let name = match phase {
            Phase::Train => TRAIN_EMISSIONS_FILE,
            Phase::Inference => INFERENCE_EMISSIONS_FILE,
        };
        Self {
            inner: SystemMeter::new(cfg),
            csv: dir.join(name),
        }
    }
}

impl Meter for RunSystemMeter {
    fn name(&self) -> &str {
        "system"
    }
    fn start(&mut self) -> Result<(), MeterError> {
        self.inner.start()
    }
    fn sample(&mut self) -> Result<(), MeterError> {
        self.inner.sample()
    }
    fn finish(&mut self) -> Result<MeterReport, MeterError> {
        let report = self.inner.finish()?;
        if let Some(row) = self.inner.emissions_row() {
            append_emissions_csv(&self.csv, row).map_err(|e| MeterError::Read {
                meter: "system".into(),
                reason: format!("{}: {e}", self.csv.display()),
            })?;
        }
        Ok(report)
    }
}

/// The meters `a2perf train` and `a2perf infer` run around their phases.
pub fn system_meters() -> MeterFactory {
    Arc::new(|phase, dir, settings| {
        vec![Box::new(RunSystemMeter::new(phase, dir, settings)) as Box<dyn Meter>]
    })
}
