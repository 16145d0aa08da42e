//! The machine and software a result was produced on (recorded next to every run and in the
//! leaderboard entry).

use serde::{Deserialize, Serialize};

/// Hardware and software of the machine that produced a result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SystemInfo {
    /// CPU brand string (`unknown` when the OS does not say).
    pub cpu_model: String,
    /// Physical cores, when known.
    pub physical_cores: Option<usize>,
    /// Logical CPUs available to this process.
    pub logical_cpus: usize,
    /// Total RAM in GB (10⁹ bytes).
    pub ram_total_gb: f64,
    /// GPU models found (empty when none; NVIDIA only, via the driver's `/proc` entries or
    /// `nvidia-smi`).
    pub gpus: Vec<String>,
    /// Operating system, long form.
    pub os: String,
    /// Kernel version.
    pub kernel: String,
    /// CPU architecture.
    pub arch: String,
    /// `rustc --version` of the compiler that built this binary.
    pub rustc_version: String,
    /// Version of the `a2perf` crate.
    pub crate_version: String,
    /// Git commit the binary was built from (`-dirty` when the tree had changes), or `unknown`.
    pub git_commit: String,
}

impl SystemInfo {
    /// Inspects the current machine.
    ///
    /// ```
    /// let info = a2perf_pipeline::SystemInfo::current();
    /// assert!(info.logical_cpus >= 1);
    /// assert!(info.rustc_version.starts_with("rustc") || info.rustc_version == "unknown");
    /// ```
    pub fn current() -> Self {
        let (cpu_model, ram_total_gb) = match sysinfo::System::new() {
            Ok(mut sys) => {
                sys.refresh_cpu_all();
                sys.refresh_memory();
                let model = sys
                    .cpus()
                    .first()
                    .map(|c| c.brand().trim().to_string())
                    .filter(|b| !b.is_empty())
                    .unwrap_or_else(|| "unknown".into());
                (model, sys.total_memory() as f64 / 1e9)
            }
            Err(_) => ("unknown".into(), f64::NAN),
        };
        Self {
            cpu_model,
            physical_cores: sysinfo::System::physical_core_count().ok(),
            logical_cpus: std::thread::available_parallelism().map_or(1, |n| n.get()),
            ram_total_gb,
            gpus: detect_gpus(),
            os: sysinfo::System::long_os_version().unwrap_or_else(|_| std::env::consts::OS.into()),
            kernel: sysinfo::System::kernel_version().unwrap_or_else(|_| "unknown".into()),
            arch: std::env::consts::ARCH.into(),
            rustc_version: env!("A2PERF_RUSTC_VERSION").into(),
            crate_version: env!("CARGO_PKG_VERSION").into(),
            git_commit: env!("A2PERF_GIT_COMMIT").into(),
        }
    }
}

fn detect_gpus() -> Vec<String> {
    let mut out = Vec::new();
    if let Ok(entries) = std::fs::read_dir("/proc/driver/nvidia/gpus") {
        for e in entries.flatten() {
            if let Ok(text) = std::fs::read_to_string(e.path().join("information"))
                && let Some(model) = text
                    .lines()
                    .find_map(|l| l.strip_prefix("Model:"))
                    .map(|m| m.trim().to_string())
            {
                out.push(model);
            }
        }
    }
    if out.is_empty()
        && let Ok(o) = std::process::Command::new("nvidia-smi")
            .args(["--query-gpu=name", "--format=csv,noheader"])
            .output()
        && o.status.success()
    {
        out.extend(
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .map(str::trim)
                .filter(|l| !l.is_empty())
                .map(String::from),
        );
    }
    out.sort();
    out
}
