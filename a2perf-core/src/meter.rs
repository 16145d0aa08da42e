//! Meters: things that measure a phase (training, inference) and report named values with units.
//!
//! Pipelines own meters; algorithms never see them. A [`MeterSet`] composes several meters into one.

use serde::{Deserialize, Serialize};

/// Errors raised by meters.
#[derive(Debug, thiserror::Error)]
pub enum MeterError {
    /// `sample` or `finish` was called before `start`.
    #[error("meter `{0}` was not started")]
    NotStarted(String),
    /// Reading a system counter failed.
    #[error("meter `{meter}`: {reason}")]
    Read {
        /// The meter.
        meter: String,
        /// What failed.
        reason: String,
    },
}

/// How a value was obtained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind", content = "method")]
pub enum Provenance {
    /// Read from a hardware or OS counter.
    Measured,
    /// Derived from a model; the string says how (e.g. "TDP 65 W × CPU-time fraction").
    Estimated(String),
    /// The quantity cannot be measured here (e.g. no GPU); never reported as 0.
    Absent(String),
}

/// One named value with its unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Name, e.g. `peak_ram_gb`.
    pub name: String,
    /// Value (`None` when absent).
    pub value: Option<f64>,
    /// Unit, e.g. `GB`, `W`, `kWh`, `ms`.
    pub unit: String,
    /// Measured, estimated (and how) or absent (and why).
    pub provenance: Provenance,
}

impl Measurement {
    /// A measured value.
    pub fn measured(name: &str, value: f64, unit: &str) -> Self {
        Self {
            name: name.into(),
            value: Some(value),
            unit: unit.into(),
            provenance: Provenance::Measured,
        }
    }

    /// An estimated value and the method used.
    pub fn estimated(name: &str, value: f64, unit: &str, method: &str) -> Self {
        Self {
            name: name.into(),
            value: Some(value),
            unit: unit.into(),
            provenance: Provenance::Estimated(method.into()),
        }
    }

    /// A value that cannot be obtained here, and why.
    pub fn absent(name: &str, unit: &str, why: &str) -> Self {
        Self {
            name: name.into(),
            value: None,
            unit: unit.into(),
            provenance: Provenance::Absent(why.into()),
        }
    }
}

/// The values a meter (or set of meters) produced.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeterReport {
    /// The values, in the order produced.
    pub measurements: Vec<Measurement>,
}

impl MeterReport {
    /// The measurement called `name`.
    pub fn get(&self, name: &str) -> Option<&Measurement> {
        self.measurements.iter().find(|m| m.name == name)
    }

    /// The numeric value of `name`, if present and not absent.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.get(name).and_then(|m| m.value)
    }

    /// Appends another report.
    pub fn extend(&mut self, other: MeterReport) {
        self.measurements.extend(other.measurements);
    }
}

/// Something that measures a phase.
pub trait Meter: Send {
    /// A short name (`ram`, `energy`, `inference_time`).
    fn name(&self) -> &str;
    /// Begins measuring.
    fn start(&mut self) -> Result<(), MeterError>;
    /// Takes an intermediate sample (meters with their own sampling thread may ignore it).
    fn sample(&mut self) -> Result<(), MeterError> {
        Ok(())
    }
    /// Stops measuring and reports.
    fn finish(&mut self) -> Result<MeterReport, MeterError>;
}

/// Several meters used as one: started in order, finished in reverse order, reports concatenated.
///
/// ```
/// use a2perf_core::{Measurement, Meter, MeterError, MeterReport, MeterSet};
/// struct Const(f64);
/// impl Meter for Const {
///     fn name(&self) -> &str { "const" }
///     fn start(&mut self) -> Result<(), MeterError> { Ok(()) }
///     fn finish(&mut self) -> Result<MeterReport, MeterError> {
///         Ok(MeterReport { measurements: vec![Measurement::measured("c", self.0, "1")] })
///     }
/// }
/// let mut set = MeterSet::new(vec![Box::new(Const(1.0)), Box::new(Const(2.0))]);
/// set.start().unwrap();
/// let r = set.finish().unwrap();
/// assert_eq!(r.measurements.len(), 2);
/// ```
#[derive(Default)]
pub struct MeterSet {
    meters: Vec<Box<dyn Meter>>,
}

impl MeterSet {
    /// Composes `meters`.
    pub fn new(meters: Vec<Box<dyn Meter>>) -> Self {
        Self { meters }
    }

    /// Adds a meter.
    pub fn push(&mut self, meter: Box<dyn Meter>) {
        self.meters.push(meter);
    }
}

impl Meter for MeterSet {
    fn name(&self) -> &str {
        "set"
    }

    fn start(&mut self) -> Result<(), MeterError> {
        self.meters.iter_mut().try_for_each(|m| m.start())
    }

    fn sample(&mut self) -> Result<(), MeterError> {
        self.meters.iter_mut().try_for_each(|m| m.sample())
    }

    fn finish(&mut self) -> Result<MeterReport, MeterError> {
        let mut parts = Vec::with_capacity(self.meters.len());
        for m in self.meters.iter_mut().rev() {
            parts.push(m.finish()?);
        }
        let mut report = MeterReport::default();
        for p in parts.into_iter().rev() {
            report.extend(p);
        }
        Ok(report)
    }
}
