//! Reliability metrics and rliable statistics (filled in below).

use pyo3::prelude::*;

/// Adds the metric functions to the module.
pub fn register(_m: &Bound<'_, PyModule>) -> PyResult<()> {
    Ok(())
}
