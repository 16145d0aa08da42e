//! The action low-pass filter: a 2nd-order Butterworth per joint (4 Hz cutoff at the 30.303 Hz
//! control rate), with the coefficients motion_imitation uses.

use crate::model::NUM_MOTORS;

/// Numerator coefficients `b`.
pub const BUTTER_B: [f64; 3] = [0.1066931, 0.2133862, 0.1066931];
/// Denominator coefficients `a` (a0 = 1).
pub const BUTTER_A: [f64; 3] = [1.0, -0.8877195, 0.3144918];

/// Per-joint 2nd-order IIR filter `y[n] = b0x[n] + b1x[n−1] + b2x[n−2] − a1y[n−1] − a2y[n−2]`.
///
/// ```
/// use a2perf_locomotion::filter::ActionFilter;
/// let mut f = ActionFilter::default();
/// f.init(&[0.0; 12]);
/// let mut y = [0.0; 12];
/// for _ in 0..200 { y = f.filter(&[1.0; 12]); }
/// assert!((y[0] - 1.0).abs() < 1e-6); // unit DC gain
/// ```
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ActionFilter {
    x: [[f64; NUM_MOTORS]; 2],
    y: [[f64; NUM_MOTORS]; 2],
}

impl ActionFilter {
    /// Fills the input and output history with `value` (the filter's steady state at `value`).
    pub fn init(&mut self, value: &[f64; NUM_MOTORS]) {
        self.x = [*value; 2];
        self.y = [*value; 2];
    }

    /// Filters one sample per joint.
    pub fn filter(&mut self, x: &[f64; NUM_MOTORS]) -> [f64; NUM_MOTORS] {
        let mut y = [0.0; NUM_MOTORS];
        for j in 0..NUM_MOTORS {
            y[j] = BUTTER_B[0] * x[j] + BUTTER_B[1] * self.x[0][j] + BUTTER_B[2] * self.x[1][j]
                - BUTTER_A[1] * self.y[0][j]
                - BUTTER_A[2] * self.y[1][j];
        }
        self.x[1] = self.x[0];
        self.x[0] = *x;
        self.y[1] = self.y[0];
        self.y[0] = y;
        y
    }
}
