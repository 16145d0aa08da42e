//! GPU power and energy for [`SystemMeter`](crate::system::SystemMeter).
//!
//! The meter asks a [`GpuSource`] for the GPU energy of each phase. With the `nvml` cargo feature
//! the default source is `NvmlGpu`, which reads NVIDIA GPUs through NVML (`libnvidia-ml.so`,
//! loaded at run time, so the build needs no system library). Without the feature, or when NVML
//! cannot be initialised (no driver, no library, no GPU), the GPU figures are *absent* with the
//! reason — never 0.
//!
//! Other sources (another vendor, a fake for tests) plug in through
//! [`SystemMeter::with_gpu`](crate::system::SystemMeter::with_gpu):
//!
//! ```
//! use std::time::Duration;
//! use a2perf_core::{Meter, Provenance};
//! use a2perf_metrics::gpu::{GpuPhase, GpuReading, GpuSource};
//! use a2perf_metrics::system::{SystemMeter, SystemMeterConfig};
//!
//! /// Pretends one GPU used 1 Wh per phase.
//! struct Fixed;
//! impl GpuSource for Fixed {
//!     fn start(&mut self, _interval: Duration) {}
//!     fn finish(&mut self) -> GpuPhase {
//!         GpuPhase::Measured(GpuReading {
//!             count: 1,
//!             model: "1 x Fake GPU".into(),
//!             energy_kwh: 1e-3,
//!             method: "fixed".into(),
//!         })
//!     }
//! }
//!
//! let mut m = SystemMeter::with_gpu(SystemMeterConfig::default(), Box::new(Fixed));
//! m.start().unwrap();
//! let r = m.finish().unwrap();
//! assert_eq!(r.value("gpu_energy_kwh"), Some(1e-3));
//! assert_eq!(r.get("gpu_power_w").unwrap().provenance, Provenance::Measured);
//! assert!(r.value("energy_kwh").unwrap() >= 1e-3);
//! assert_eq!(m.emissions_row().unwrap().gpu_count, Some(1));
//! ```

use std::time::Duration;

#[cfg(feature = "nvml")]
mod nvml;
#[cfg(feature = "nvml")]
pub use nvml::NvmlGpu;

/// GPU energy of one measured phase.
#[derive(Clone, Debug, PartialEq)]
pub struct GpuReading {
    /// Devices measured (`gpu_count` of `emissions.csv`).
    pub count: usize,
    /// CodeCarbon-style model string, e.g. `2 x NVIDIA A100-SXM4-40GB` (`gpu_model`).
    pub model: String,
    /// Energy of all measured devices over the phase (kWh).
    pub energy_kwh: f64,
    /// How it was obtained (counter or power samples, skipped devices).
    pub method: String,
}

/// What a [`GpuSource`] found over one phase.
#[derive(Clone, Debug, PartialEq)]
pub enum GpuPhase {
    /// Not measured, and why.
    Absent(String),
    /// Measured.
    Measured(GpuReading),
}

/// Where a [`SystemMeter`](crate::system::SystemMeter) gets GPU energy from.
///
/// Sources never fail: what they cannot read is reported as [`GpuPhase::Absent`].
pub trait GpuSource: Send {
    /// Begins a phase; `interval` is the meter's sampling period, for sources that sample power.
    fn start(&mut self, interval: Duration);
    /// Takes an extra reading when the pipeline asks the meter to sample.
    fn sample(&mut self) {}
    /// Ends the phase.
    fn finish(&mut self) -> GpuPhase;
}

/// A source that never measures; it reports its reason as absent.
///
/// ```
/// use a2perf_metrics::gpu::{GpuPhase, GpuSource, NoGpu};
/// let mut g = NoGpu::new("no GPU here");
/// g.start(std::time::Duration::from_secs(1));
/// assert_eq!(g.finish(), GpuPhase::Absent("no GPU here".into()));
/// ```
#[derive(Clone, Debug)]
pub struct NoGpu {
    reason: String,
}

impl NoGpu {
    /// Reports `reason` for every phase.
    pub fn new(reason: &str) -> Self {
        Self {
            reason: reason.into(),
        }
    }
}

impl GpuSource for NoGpu {
    fn start(&mut self, _interval: Duration) {}

    fn finish(&mut self) -> GpuPhase {
        GpuPhase::Absent(self.reason.clone())
    }
}

/// The absence reason of a build without the `nvml` feature.
pub const WITHOUT_NVML_FEATURE: &str =
    "GPU power is not measured: a2perf-metrics was built without the `nvml` feature";

/// The source [`SystemMeter::new`](crate::system::SystemMeter::new) uses: NVML with the `nvml`
/// feature, otherwise [`NoGpu`] with [`WITHOUT_NVML_FEATURE`].
///
/// ```
/// let mut g = a2perf_metrics::gpu::default_source();
/// g.start(std::time::Duration::from_millis(10));
/// // Absent with a reason, or measured on a machine with NVIDIA GPUs and the `nvml` feature.
/// let _ = g.finish();
/// ```
pub fn default_source() -> Box<dyn GpuSource> {
    #[cfg(feature = "nvml")]
    {
        Box::new(NvmlGpu::default())
    }
    #[cfg(not(feature = "nvml"))]
    {
        Box::new(NoGpu::new(WITHOUT_NVML_FEATURE))
    }
}
