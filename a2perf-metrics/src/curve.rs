//! Learning curves: one run's evaluation values against training steps.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Why a curve could not be built.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum CurveError {
    /// Steps and values differ in length.
    #[error("{steps} steps but {values} values")]
    Length {
        /// Number of steps.
        steps: usize,
        /// Number of values.
        values: usize,
    },
    /// A step or value is NaN or infinite.
    #[error("non-finite {what} at index {index}")]
    NonFinite {
        /// `step` or `value`.
        what: &'static str,
        /// Position in the curve.
        index: usize,
    },
    /// Steps must strictly increase.
    #[error("steps must strictly increase: step {step} at index {index} follows {previous}")]
    NotIncreasing {
        /// Position in the curve.
        index: usize,
        /// The offending step.
        step: f64,
        /// The step before it.
        previous: f64,
    },
}

/// One run's learning curve: `values[i]` was measured at `steps[i]`.
///
/// Steps are the *timepoints* of the originals (environment or train steps); they strictly
/// increase and need not be evenly spaced. Construct with [`Curve::new`], which checks this.
///
/// ```
/// use a2perf_metrics::Curve;
/// let c = Curve::new(vec![0.0, 10.0, 20.0], vec![1.0, 2.0, 1.5]).unwrap();
/// assert_eq!(c.len(), 3);
/// assert!(Curve::new(vec![0.0, 0.0], vec![1.0, 2.0]).is_err());
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Curve {
    steps: Vec<f64>,
    values: Vec<f64>,
}

impl Curve {
    /// A curve from matching step and value vectors (finite, steps strictly increasing).
    pub fn new(steps: Vec<f64>, values: Vec<f64>) -> Result<Self, CurveError> {
        if steps.len() != values.len() {
            return Err(CurveError::Length {
                steps: steps.len(),
                values: values.len(),
            });
        }
        for (i, (s, v)) in steps.iter().zip(&values).enumerate() {
            if !s.is_finite() {
                return Err(CurveError::NonFinite {
                    what: "step",
                    index: i,
                });
            }
            if !v.is_finite() {
                return Err(CurveError::NonFinite {
                    what: "value",
                    index: i,
                });
            }
            if i > 0 && *s <= steps[i - 1] {
                return Err(CurveError::NotIncreasing {
                    index: i,
                    step: *s,
                    previous: steps[i - 1],
                });
            }
        }
        Ok(Self { steps, values })
    }

    /// A curve sampled at steps `0, 1, 2, …`.
    pub fn from_values(values: Vec<f64>) -> Result<Self, CurveError> {
        let steps = (0..values.len()).map(|i| i as f64).collect();
        Self::new(steps, values)
    }

    /// The timepoints.
    pub fn steps(&self) -> &[f64] {
        &self.steps
    }

    /// The values.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.steps.len()
    }

    /// `true` when the curve has no points.
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// The last value (the run's final performance).
    pub fn last_value(&self) -> Option<f64> {
        self.values.last().copied()
    }

    /// Same steps, new values (internal: lengths are known to match and values finite or not,
    /// as produced by our own transforms).
    pub(crate) fn with_values(&self, values: Vec<f64>) -> Curve {
        Curve {
            steps: self.steps.clone(),
            values,
        }
    }

    /// Raw first differences `y[i] − y[i−1]` (A2Perf's `Value.diff()`), at steps `t[1..]`.
    pub fn raw_diffs(&self) -> Vec<f64> {
        self.values.windows(2).map(|w| w[1] - w[0]).collect()
    }

    /// The library's `differences`: `Δy/Δt` at timepoints `t[1..]`, which does not depend on the
    /// evaluation frequency.
    pub fn slope_curve(&self) -> Curve {
        let values = self
            .values
            .windows(2)
            .zip(self.steps.windows(2))
            .map(|(y, t)| (y[1] - y[0]) / (t[1] - t[0]))
            .collect();
        Curve {
            steps: self.steps.get(1..).unwrap_or(&[]).to_vec(),
            values,
        }
    }
}
