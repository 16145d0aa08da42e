//! Shared helpers for the golden tests: loading `../shared/data/metrics/*.json` and comparing.
#![allow(dead_code)]

use serde_json::Value;

/// Loads a golden file, or `None` (with a printed reason) when it is absent and
/// `A2PERF_REQUIRE_SHARED` is not set.
pub fn load(name: &str) -> Option<Value> {
    let path = format!(
        "{}/../../shared/data/metrics/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    match std::fs::read_to_string(&path) {
        Ok(text) => Some(serde_json::from_str(&text).expect("golden file is valid JSON")),
        Err(e) => {
            if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
                panic!("A2PERF_REQUIRE_SHARED=1 but {path} is unreadable: {e}");
            }
            eprintln!("SKIP: {path} not available ({e})");
            None
        }
    }
}

pub fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

pub fn vec1(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(f)
        .collect()
}

pub fn vec2(v: &Value) -> Vec<Vec<f64>> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(vec1)
        .collect()
}

/// |a − b| ≤ abs + rel·|b| elementwise.
pub fn assert_close(what: &str, got: &[f64], want: &[f64], rel: f64, abs: f64) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let tol = abs + rel * w.abs();
        assert!(
            (g - w).abs() <= tol,
            "{what}[{i}]: got {g}, want {w} (diff {:e}, tol {tol:e})",
            (g - w).abs()
        );
    }
}
