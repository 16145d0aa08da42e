//! How numbers are printed in every output of the report: a leaf module, so that the
//! renderers and the paper comparison (whose notes and findings print numbers too) share it
//! without depending on each other.

/// The original's number format: two decimals, or scientific notation below 0.01.
///
/// ```
/// use a2perf_pipeline::report::format::format_value;
/// assert_eq!(format_value(12.345), "12.35");
/// assert_eq!(format_value(0.00123), "1.23e-3");
/// assert_eq!(format_value(0.0), "0.00");
/// assert_eq!(format_value(-0.0), "0.00");
/// ```
pub fn format_value(v: f64) -> String {
    if v != 0.0 && v.abs() < 1e-2 {
        format!("{v:.2e}")
    } else {
        // `-0.00` would suggest a sign the value does not have.
        format!("{:.2}", if v == 0.0 { 0.0 } else { v })
    }
}

/// A ratio to three significant digits (scientific notation far from 1).
///
/// ```
/// use a2perf_pipeline::report::format::format_ratio;
/// assert_eq!(format_ratio(0.026579), "0.0266");
/// assert_eq!(format_ratio(1.0), "1.00");
/// assert_eq!(format_ratio(123.456), "123");
/// assert_eq!(format_ratio(6.38e-4), "6.38e-4");
/// ```
pub fn format_ratio(r: f64) -> String {
    let a = r.abs();
    if r == 0.0 || !(1e-3..1e3).contains(&a) {
        format!("{r:.2e}")
    } else {
        let decimals = (2 - a.log10().floor() as i32).max(0) as usize;
        format!("{r:.decimals$}")
    }
}
