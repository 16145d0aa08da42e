//! Learning curves: evaluation return against environment steps.

use serde::{Deserialize, Serialize};

/// One point of a training curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Environment steps consumed so far.
    pub env_steps: u64,
    /// Mean evaluation return (greedy policy); NaN when a reward was (written as `null`).
    #[serde(deserialize_with = "crate::results::f64_or_nan")]
    pub mean_return: f64,
    /// Standard deviation of the evaluation returns.
    #[serde(deserialize_with = "crate::results::f64_or_nan")]
    pub std_return: f64,
    /// Seconds since training started (not deterministic; excluded from equality checks of curves).
    pub wall_seconds: f64,
}

/// Evaluation return against environment steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LearningCurve {
    /// Points in increasing `env_steps`.
    pub points: Vec<CurvePoint>,
}

impl LearningCurve {
    /// `(env_steps, mean_return)` pairs, the deterministic part of the curve.
    pub fn returns(&self) -> Vec<(u64, f64)> {
        self.points
            .iter()
            .map(|p| (p.env_steps, p.mean_return))
            .collect()
    }
}
