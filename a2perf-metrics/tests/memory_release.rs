//! A phase's RAM readings start from what the process holds, not from what it freed before
//! (its own test binary: the other RAM test allocates at the same time).

use std::time::Duration;

use a2perf_core::Meter;
use a2perf_metrics::system::MemorySampler;

/// Resident set size of this process \[GB\], from `/proc/self/statm`.
fn rss_gb() -> Option<f64> {
    let statm = std::fs::read_to_string("/proc/self/statm").ok()?;
    let pages: f64 = statm.split_whitespace().nth(1)?.parse().ok()?;
    Some(pages * 4096.0 / 1e9)
}

#[test]
fn memory_an_earlier_phase_freed_is_not_counted() {
    if cfg!(not(all(target_os = "linux", target_env = "gnu"))) {
        eprintln!("skipped: glibc's malloc_trim is what is tested");
        return;
    }
    // 256 MB in 64 KiB chunks (below glibc's mmap threshold, so they live in the heap), each
    // touched; then a small allocation after them that stays alive, so that freeing the chunks
    // leaves a hole glibc keeps instead of shrinking the heap: a phase that ended.
    let chunks: Vec<Vec<u8>> = (0..4096)
        .map(|i| {
            let mut c = vec![0u8; 64 * 1024];
            for j in (0..c.len()).step_by(4096) {
                c[j] = (i + j) as u8 | 1;
            }
            c
        })
        .collect();
    let pin = std::hint::black_box(vec![1u8; 1024]);
    let Some(held) = rss_gb() else {
        eprintln!("skipped: /proc/self/statm is not readable");
        return;
    };
    drop(std::hint::black_box(chunks));
    let mut m = MemorySampler::new(Duration::from_millis(10));
    m.start().unwrap();
    let base = m.baseline_gb().unwrap();
    let report = m.finish().unwrap();
    let peak = report.value("peak_ram_gb").unwrap();
    drop(pin);
    assert!(
        held - base >= 0.2 && held - peak >= 0.2,
        "256 MB freed before the phase: RSS {held:.3} GB while held, the phase read {base:.3} GB \
         at its start and {peak:.3} GB at its peak"
    );
}
