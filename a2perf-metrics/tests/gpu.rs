//! GPU readings with the `nvml` feature: absent with the NVML error on machines without NVIDIA
//! drivers, measured and sane on machines with them.
#![cfg(feature = "nvml")]

use std::time::Duration;

use a2perf_core::{Meter, Provenance};
use a2perf_metrics::system::{SystemMeter, SystemMeterConfig};

#[test]
fn gpu_nvml_reading_is_absent_with_reason_or_measured() {
    let nvml = nvml_wrapper::Nvml::init();
    let gpus = nvml
        .as_ref()
        .ok()
        .and_then(|n| n.device_count().ok())
        .unwrap_or(0);
    drop(nvml);
    let mut m = SystemMeter::new(SystemMeterConfig {
        interval: Duration::from_millis(5),
        powercap_root: "/nonexistent".into(),
        force_cpu_tdp_watts: Some(50.0),
        ..SystemMeterConfig::default()
    });
    m.start().unwrap();
    for _ in 0..3 {
        std::thread::sleep(Duration::from_millis(20));
        m.sample().unwrap();
    }
    let r = m.finish().unwrap();
    let row = m.emissions_row().unwrap().clone();
    let fields = row.fields();
    let total = r.value("energy_kwh").unwrap();
    let cpu_ram = r.value("cpu_energy_kwh").unwrap() + r.value("ram_energy_kwh").unwrap();
    if gpus == 0 {
        println!("no NVIDIA GPU reachable through NVML: checking the absent path");
        for name in ["gpu_power_w", "gpu_energy_kwh"] {
            let g = r.get(name).unwrap();
            assert_ne!(g.value, Some(0.0), "{name} must never be 0 when unmeasured");
            assert_eq!(g.value, None, "{name}");
            match &g.provenance {
                Provenance::Absent(why) => {
                    println!("{name}: {why}");
                    assert!(why.contains("NVML"), "{name}: {why}");
                }
                other => panic!("{name}: expected absent, got {other:?}"),
            }
        }
        assert_eq!((row.gpu_power_w, row.gpu_energy_kwh), (None, None));
        assert_eq!((fields[8].as_str(), fields[11].as_str()), ("", ""));
        assert_eq!((fields[25].as_str(), fields[26].as_str()), ("", ""));
        assert!((total - cpu_ram).abs() < 1e-15);
    } else {
        println!("{gpus} NVIDIA GPU(s) found: checking the measured path");
        for name in ["gpu_power_w", "gpu_energy_kwh"] {
            let g = r.get(name).unwrap();
            assert_eq!(g.provenance, Provenance::Measured, "{name}");
            let v = g.value.unwrap();
            assert!(v.is_finite() && v >= 0.0, "{name} = {v}");
        }
        let gpu_e = r.value("gpu_energy_kwh").unwrap();
        assert!((total - (cpu_ram + gpu_e)).abs() <= 1e-12 * total.max(1e-9));
        assert_eq!(row.gpu_energy_kwh, Some(gpu_e));
        let count = row.gpu_count.unwrap();
        assert!(count >= 1 && count <= gpus as usize);
        assert!(row.gpu_model.contains(" x "), "{}", row.gpu_model);
    }
}
