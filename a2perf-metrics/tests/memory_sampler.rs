//! The RAM sampler must see a large allocation made while it runs.

use std::time::Duration;

use a2perf_core::Meter;
use a2perf_metrics::system::MemorySampler;

#[test]
fn sampler_sees_a_200_mb_allocation() {
    let mut m = MemorySampler::new(Duration::from_millis(10));
    m.start().unwrap();
    std::thread::sleep(Duration::from_millis(30));
    let base = m.baseline_gb().unwrap();
    let mut block = vec![0u8; 200_000_000];
    // Touch every page so it is resident, not just reserved.
    for i in (0..block.len()).step_by(4096) {
        block[i] = (i % 251) as u8 + 1;
    }
    std::hint::black_box(&block);
    std::thread::sleep(Duration::from_millis(100));
    let report = m.finish().unwrap();
    drop(block);
    let peak = report.value("peak_ram_gb").unwrap();
    let mean = report.value("mean_ram_gb").unwrap();
    assert!(peak - base >= 0.15, "peak {peak} GB, baseline {base} GB");
    assert!(mean <= peak && mean >= base * 0.5);
}

#[test]
fn finish_without_start_is_an_error() {
    let mut m = MemorySampler::new(Duration::from_millis(10));
    assert!(m.finish().is_err());
}
