//! System meters: RAM, CPU/RAM/GPU power and energy, wall-clock, emissions, inference time.
//!
//! They implement [`a2perf_core::Meter`], so a pipeline starts them around a training or inference
//! phase and gets a [`MeterReport`] whose every value says whether it was measured, estimated
//! (and how) or is absent (and why):
//!
//! ```no_run
//! use a2perf_core::Meter;
//! use a2perf_metrics::system::{SystemMeter, SystemMeterConfig};
//! let mut meter = SystemMeter::new(SystemMeterConfig::default());
//! meter.start().unwrap();
//! // … train …
//! let report = meter.finish().unwrap();
//! println!("{:?}", report.value("energy_kwh"));
//! ```
//!
//! How each figure is obtained (CodeCarbon's methods, `tracking_mode="process"`):
//! - **RAM**: a sampler thread sums the resident set size of this process and all its
//!   descendants (sysinfo) every `interval`; mean and peak in GB (10⁹ bytes).
//! - **CPU energy**: Intel RAPL package counters (`/sys/class/powercap/*/energy_uj`, wrap-around
//!   corrected with `max_energy_range_uj`) when readable — whole-machine, *measured*. Otherwise
//!   *estimated*: CPU TDP (a small built-in table, else 4 W per logical CPU for a detected but
//!   unknown model, else 85 W; or a forced value) × the process tree's CPU-time share
//!   (`Δcpu_time / Δwall / logical_cpus`).
//! - **RAM power**: CodeCarbon v2's model used by A2Perf's fork: 3 W per 8 GB (0.375 W/GB) of the
//!   process tree's mean RSS — *estimated*.
//! - **GPU**: with the `nvml` cargo feature, NVIDIA GPUs through NVML — the device energy counter
//!   difference, or integrated power samples on GPUs without one (see [`crate::gpu`]); whole-device,
//!   *measured*, and added to the total. Without the feature, or when NVML cannot be initialised,
//!   *absent* with the reason, never 0.
//! - **Emissions**: total energy × PUE × carbon intensity (default 475 g CO₂e/kWh, the IEA 2019
//!   world average CodeCarbon falls back to) — *estimated*.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use a2perf_core::{Measurement, Meter, MeterError, MeterReport, Provenance};
use sysinfo::{Pid, ProcessRefreshKind, ProcessesToUpdate, System};

use crate::gpu::{self, GpuPhase, GpuSource};
use crate::numeric;

/// CodeCarbon's µJ→kWh path uses `JOULES_TO_KWH = 2.77778e-7`; we use the exact 1/3.6e6.
const JOULES_PER_KWH: f64 = 3.6e6;
/// Bytes per GB (decimal, as CodeCarbon and A2Perf report).
const BYTES_PER_GB: f64 = 1e9;
/// CodeCarbon v2 / A2Perf fork RAM power rule.
pub const RAM_WATTS_PER_GB: f64 = 3.0 / 8.0;
/// World-average carbon intensity (IEA 2019), CodeCarbon's last-resort default.
pub const WORLD_CARBON_INTENSITY_G_PER_KWH: f64 = 475.0;

fn read_err(meter: &str, reason: impl Into<String>) -> MeterError {
    MeterError::Read {
        meter: meter.into(),
        reason: reason.into(),
    }
}

/// RSS (bytes) and accumulated CPU time (ms) of a process and all its descendants.
///
/// On Linux `sysinfo` also lists every thread as an entry whose parent is its process, with the
/// process's RSS and its own CPU time; those are skipped, as the process entry already covers its
/// threads (counting them multiplied the RSS by the number of threads).
fn process_tree(sys: &System, root: Pid) -> (u64, u64) {
    let procs = sys.processes();
    let mut rss = 0;
    let mut cpu = 0;
    for (pid, p) in procs {
        if p.thread_kind().is_some() {
            continue;
        }
        // Walk up the parent chain; bounded so a cycle in stale data cannot hang us.
        let mut cur = Some(*pid);
        let mut depth = 0;
        while let Some(c) = cur {
            if c == root {
                rss += p.memory();
                cpu += p.accumulated_cpu_time();
                break;
            }
            depth += 1;
            if depth > 64 {
                break;
            }
            cur = procs.get(&c).and_then(|q| q.parent());
        }
    }
    (rss, cpu)
}

fn refresh(sys: &mut System) {
    sys.refresh_processes_specifics(
        ProcessesToUpdate::All,
        true,
        ProcessRefreshKind::nothing().with_memory().with_cpu(),
    );
}

#[derive(Default)]
struct MemStats {
    sum_gb: f64,
    count: u64,
    peak_gb: f64,
    first_gb: Option<f64>,
}

impl MemStats {
    fn add(&mut self, gb: f64) {
        self.sum_gb += gb;
        self.count += 1;
        self.peak_gb = self.peak_gb.max(gb);
        self.first_gb.get_or_insert(gb);
    }
}

/// Hands the heap's free pages back to the operating system (glibc's `malloc_trim(0)`); a no-op
/// on other platforms.
///
/// glibc keeps memory a program frees for reuse, and the process's RSS goes on counting it. In a
/// process that runs one phase after another (`a2perf run` trains, infers and evaluates every run
/// in turn), a phase's RAM readings would then include what earlier phases freed: measured on the
/// 2026-11-28 paper suite, web PPO's training read 0.28 GB inside the suite (after the Ariane
/// runs) and 0.05 GB on its own. [`MemorySampler::start`] calls this first, so that a phase's
/// readings start from what the process still holds.
///
/// ```
/// a2perf_metrics::system::release_freed_memory();
/// ```
pub fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn malloc_trim(pad: usize) -> std::ffi::c_int;
        }
        // SAFETY: `malloc_trim` only walks glibc's own arenas, under their locks; it takes no
        // pointer and may be called from any thread at any time.
        unsafe {
            malloc_trim(0);
        }
    }
}

/// Samples the RAM of this process and its children on a background thread.
///
/// Reports `mean_ram_gb` and `peak_ram_gb` (measured). [`start`](Meter::start) first returns
/// freed heap memory to the system ([`release_freed_memory`]).
pub struct MemorySampler {
    interval: Duration,
    root: Option<Pid>,
    stats: Arc<Mutex<MemStats>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl MemorySampler {
    /// A sampler taking one reading every `interval` (A2Perf used 5 s for training, 1 s for
    /// inference).
    pub fn new(interval: Duration) -> Self {
        Self {
            interval,
            root: None,
            stats: Arc::default(),
            stop: Arc::default(),
            thread: None,
        }
    }

    /// Mean and peak so far (GB), `None` before the first sample.
    pub fn current(&self) -> Option<(f64, f64)> {
        let s = self.stats.lock().ok()?;
        (s.count > 0).then(|| (s.sum_gb / s.count as f64, s.peak_gb))
    }

    /// The first reading (GB) of this phase.
    pub fn baseline_gb(&self) -> Option<f64> {
        self.stats.lock().ok()?.first_gb
    }
}

impl Meter for MemorySampler {
    fn name(&self) -> &str {
        "ram"
    }

    fn start(&mut self) -> Result<(), MeterError> {
        let root = sysinfo::get_current_pid().map_err(|e| read_err("ram", e.to_string()))?;
        let mut sys = System::new().map_err(|e| read_err("ram", e.to_string()))?;
        self.root = Some(root);
        self.stats = Arc::default();
        self.stop = Arc::default();
        release_freed_memory();
        refresh(&mut sys);
        let (rss, _) = process_tree(&sys, root);
        if let Ok(mut s) = self.stats.lock() {
            s.add(rss as f64 / BYTES_PER_GB);
        }
        let (stats, stop, interval) = (self.stats.clone(), self.stop.clone(), self.interval);
        self.thread = Some(std::thread::spawn(move || {
            let tick = interval
                .min(Duration::from_millis(50))
                .max(Duration::from_millis(1));
            let mut next = Instant::now() + interval;
            while !stop.load(Ordering::Relaxed) {
                if Instant::now() >= next {
                    refresh(&mut sys);
                    let (rss, _) = process_tree(&sys, root);
                    if let Ok(mut s) = stats.lock() {
                        s.add(rss as f64 / BYTES_PER_GB);
                    }
                    next += interval;
                } else {
                    std::thread::sleep(tick.min(next.saturating_duration_since(Instant::now())));
                }
            }
        }));
        Ok(())
    }

    fn sample(&mut self) -> Result<(), MeterError> {
        let root = self
            .root
            .ok_or_else(|| MeterError::NotStarted("ram".into()))?;
        let mut sys = System::new().map_err(|e| read_err("ram", e.to_string()))?;
        refresh(&mut sys);
        let (rss, _) = process_tree(&sys, root);
        if let Ok(mut s) = self.stats.lock() {
            s.add(rss as f64 / BYTES_PER_GB);
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<MeterReport, MeterError> {
        let thread = self
            .thread
            .take()
            .ok_or_else(|| MeterError::NotStarted("ram".into()))?;
        self.sample()?;
        self.stop.store(true, Ordering::Relaxed);
        thread
            .join()
            .map_err(|_| read_err("ram", "sampler thread panicked"))?;
        let (mean, peak) = self
            .current()
            .ok_or_else(|| read_err("ram", "no samples"))?;
        Ok(MeterReport {
            measurements: vec![
                Measurement::measured("mean_ram_gb", mean, "GB"),
                Measurement::measured("peak_ram_gb", peak, "GB"),
            ],
        })
    }
}

/// One RAPL energy counter.
#[derive(Clone, Debug)]
struct RaplDomain {
    energy_path: PathBuf,
    max_uj: u64,
}

fn rapl_domains(root: &Path) -> Vec<RaplDomain> {
    let Ok(entries) = std::fs::read_dir(root) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for e in entries.flatten() {
        let dir = e.path();
        let name = std::fs::read_to_string(dir.join("name")).unwrap_or_default();
        if !name.trim().starts_with("package") {
            continue;
        }
        let energy_path = dir.join("energy_uj");
        let readable = std::fs::read_to_string(&energy_path)
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok())
            .is_some();
        let max_uj = std::fs::read_to_string(dir.join("max_energy_range_uj"))
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok());
        if let (true, Some(max_uj)) = (readable, max_uj) {
            out.push(RaplDomain {
                energy_path,
                max_uj,
            });
        }
    }
    out.sort_by(|a, b| a.energy_path.cmp(&b.energy_path));
    out
}

fn read_rapl(domains: &[RaplDomain]) -> Option<Vec<u64>> {
    domains
        .iter()
        .map(|d| {
            std::fs::read_to_string(&d.energy_path)
                .ok()
                .and_then(|s| s.trim().parse::<u64>().ok())
        })
        .collect()
}

/// Energy (µJ) between two counter readings, corrected for one wrap-around.
///
/// ```
/// use a2perf_metrics::system::rapl_delta_uj;
/// assert_eq!(rapl_delta_uj(100, 250, 1000), 150);
/// assert_eq!(rapl_delta_uj(900, 50, 1000), 150);
/// ```
pub fn rapl_delta_uj(before: u64, after: u64, max_range_uj: u64) -> u64 {
    if after >= before {
        after - before
    } else {
        after + max_range_uj.saturating_sub(before)
    }
}

/// TDP (W) of a few CPU models, matched by substring of the model name. CodeCarbon ships a
/// table of thousands; this one covers the machines A2Perf reported and common cloud CPUs.
const TDP_TABLE: &[(&str, f64)] = &[
    ("Xeon(R) Platinum 8273CL", 165.0),
    ("Xeon(R) Platinum 8373C", 270.0),
    ("Xeon(R) Platinum 8259CL", 210.0),
    ("Xeon(R) Platinum 8175M", 240.0),
    ("Xeon(R) CPU @ 2.20GHz", 165.0),
    ("EPYC 7B12", 240.0),
    ("EPYC 7B13", 240.0),
    ("EPYC 7R32", 280.0),
    ("EPYC 7763", 280.0),
    ("EPYC 9654", 360.0),
    ("Core(TM) i7-8700", 65.0),
    ("Core(TM) i9-9900K", 95.0),
    ("Ryzen 9 5950X", 105.0),
    ("Apple M1", 20.0),
];

/// How the CPU power of the whole package was chosen.
#[derive(Clone, Debug, PartialEq)]
pub struct CpuTdp {
    /// Watts for all sockets.
    pub watts: f64,
    /// Where the figure comes from.
    pub source: String,
}

/// CodeCarbon's TDP fallback chain for a CPU `model` with `logical_cpus` threads.
///
/// ```
/// use a2perf_metrics::system::cpu_tdp;
/// assert_eq!(cpu_tdp("Intel(R) Xeon(R) Platinum 8273CL CPU @ 2.20GHz", 4).watts, 165.0);
/// assert_eq!(cpu_tdp("Some Unknown CPU", 8).watts, 32.0);
/// assert_eq!(cpu_tdp("", 8).watts, 85.0);
/// ```
pub fn cpu_tdp(model: &str, logical_cpus: usize) -> CpuTdp {
    if let Some((m, w)) = TDP_TABLE.iter().find(|(m, _)| model.contains(m)) {
        return CpuTdp {
            watts: *w,
            source: format!("TDP table entry `{m}`"),
        };
    }
    if model.trim().is_empty() {
        CpuTdp {
            watts: 85.0,
            source: "no CPU model detected: CodeCarbon's 85 W constant".into(),
        }
    } else {
        CpuTdp {
            watts: 4.0 * logical_cpus as f64,
            source: format!("model `{model}` not in table: 4 W × {logical_cpus} logical CPUs"),
        }
    }
}

/// Settings of a [`SystemMeter`].
#[derive(Clone, Debug, PartialEq)]
pub struct SystemMeterConfig {
    /// RAM sampling period.
    pub interval: Duration,
    /// Grid carbon intensity (g CO₂e per kWh).
    pub carbon_intensity_g_per_kwh: f64,
    /// Power usage effectiveness multiplier on energy (CodeCarbon default 1.0).
    pub pue: f64,
    /// Overrides the CPU TDP (W) of the estimate.
    pub force_cpu_tdp_watts: Option<f64>,
    /// RAM power per GB of process RSS.
    pub ram_watts_per_gb: f64,
    /// Where to look for RAPL counters.
    pub powercap_root: PathBuf,
    /// `project_name` column of `emissions.csv`.
    pub project_name: String,
    /// `run_id` column.
    pub run_id: String,
    /// `experiment_id` column.
    pub experiment_id: String,
    /// `country_iso_code` column (informational; the intensity above is what is used).
    pub country_iso_code: String,
    /// `region` column.
    pub region: String,
}

impl Default for SystemMeterConfig {
    fn default() -> Self {
        Self {
            interval: Duration::from_secs(1),
            carbon_intensity_g_per_kwh: WORLD_CARBON_INTENSITY_G_PER_KWH,
            pue: 1.0,
            force_cpu_tdp_watts: None,
            ram_watts_per_gb: RAM_WATTS_PER_GB,
            powercap_root: PathBuf::from("/sys/class/powercap"),
            project_name: "a2perf".into(),
            run_id: String::new(),
            experiment_id: String::new(),
            country_iso_code: String::new(),
            region: String::new(),
        }
    }
}

struct PhaseStart {
    instant: Instant,
    wall: SystemTime,
    cpu_ms: u64,
    rapl: Option<(Vec<RaplDomain>, Vec<u64>)>,
}

/// Energy, power, RAM, wall-clock and emissions of one phase (see the module docs).
///
/// Reports `wall_clock_h`, `mean_ram_gb`, `peak_ram_gb`, `cpu_power_w`, `cpu_energy_kwh`,
/// `ram_power_w`, `ram_energy_kwh`, `gpu_power_w`, `gpu_energy_kwh`, `energy_kwh` and
/// `emissions_kg`. After `finish`, [`SystemMeter::emissions_row`] gives the CodeCarbon-style row.
pub struct SystemMeter {
    cfg: SystemMeterConfig,
    memory: MemorySampler,
    gpu: Box<dyn GpuSource>,
    start: Option<PhaseStart>,
    row: Option<EmissionsRow>,
    sys: Option<System>,
    root: Option<Pid>,
}

impl SystemMeter {
    /// A meter with these settings and the default GPU source ([`gpu::default_source`]: NVML
    /// with the `nvml` feature, otherwise absent).
    pub fn new(cfg: SystemMeterConfig) -> Self {
        Self::with_gpu(cfg, gpu::default_source())
    }

    /// A meter reading GPU energy from `gpu` (see [`crate::gpu`] for an example).
    pub fn with_gpu(cfg: SystemMeterConfig, gpu: Box<dyn GpuSource>) -> Self {
        let memory = MemorySampler::new(cfg.interval);
        Self {
            cfg,
            memory,
            gpu,
            start: None,
            row: None,
            sys: None,
            root: None,
        }
    }

    /// The `emissions.csv` row of the last finished phase.
    pub fn emissions_row(&self) -> Option<&EmissionsRow> {
        self.row.as_ref()
    }

    fn cpu_ms(&mut self) -> Result<u64, MeterError> {
        let (Some(sys), Some(root)) = (self.sys.as_mut(), self.root) else {
            return Err(MeterError::NotStarted("system".into()));
        };
        refresh(sys);
        Ok(process_tree(sys, root).1)
    }
}

impl Meter for SystemMeter {
    fn name(&self) -> &str {
        "system"
    }

    fn start(&mut self) -> Result<(), MeterError> {
        self.root =
            Some(sysinfo::get_current_pid().map_err(|e| read_err("system", e.to_string()))?);
        self.sys = Some(System::new().map_err(|e| read_err("system", e.to_string()))?);
        let cpu_ms = self.cpu_ms()?;
        let domains = rapl_domains(&self.cfg.powercap_root);
        let rapl = if domains.is_empty() {
            None
        } else {
            read_rapl(&domains).map(|r| (domains, r))
        };
        self.memory.start()?;
        self.gpu.start(self.cfg.interval);
        self.start = Some(PhaseStart {
            instant: Instant::now(),
            wall: SystemTime::now(),
            cpu_ms,
            rapl,
        });
        Ok(())
    }

    fn sample(&mut self) -> Result<(), MeterError> {
        self.memory.sample()?;
        if self.start.is_some() {
            self.gpu.sample();
        }
        Ok(())
    }

    fn finish(&mut self) -> Result<MeterReport, MeterError> {
        let start = self
            .start
            .take()
            .ok_or_else(|| MeterError::NotStarted("system".into()))?;
        let gpu = self.gpu.finish();
        let mem = self.memory.finish()?;
        let secs = start.instant.elapsed().as_secs_f64().max(1e-9);
        let hours = secs / 3600.0;
        let cpu_ms = self.cpu_ms()?;
        let mean_ram = mem.value("mean_ram_gb").unwrap_or(0.0);
        let peak_ram = mem.value("peak_ram_gb").unwrap_or(0.0);
        let logical = self
            .sys
            .as_ref()
            .map_or(1, |s| s.cpus().len())
            .max(std::thread::available_parallelism().map_or(1, usize::from));

        // CPU.
        let (cpu_energy, cpu_prov) = match start.rapl.as_ref().and_then(|(d, before)| {
            read_rapl(d).map(|after| {
                d.iter()
                    .zip(before.iter().zip(&after))
                    .map(|(dom, (b, a))| rapl_delta_uj(*b, *a, dom.max_uj))
                    .sum::<u64>()
            })
        }) {
            Some(uj) => (uj as f64 * 1e-6 / JOULES_PER_KWH, Provenance::Measured),
            None => {
                let model = cpu_model();
                let tdp = match self.cfg.force_cpu_tdp_watts {
                    Some(w) => CpuTdp {
                        watts: w,
                        source: "forced TDP".into(),
                    },
                    None => cpu_tdp(&model, logical),
                };
                let share =
                    (cpu_ms.saturating_sub(start.cpu_ms) as f64 / 1000.0) / secs / logical as f64;
                let watts = tdp.watts * share.clamp(0.0, 1.0);
                (
                    watts * secs / JOULES_PER_KWH,
                    Provenance::Estimated(format!(
                        "RAPL not readable; {} W ({}) × process CPU-time share {:.4} of {logical} logical CPUs",
                        tdp.watts, tdp.source, share
                    )),
                )
            }
        };
        let cpu_power = cpu_energy * JOULES_PER_KWH / secs;
        // RAM.
        let ram_power = self.cfg.ram_watts_per_gb * mean_ram;
        let ram_energy = ram_power * secs / JOULES_PER_KWH;
        let ram_method = format!(
            "{} W per GB of mean process RSS (CodeCarbon v2 rule)",
            self.cfg.ram_watts_per_gb
        );
        // GPU: CodeCarbon's gpu_power is the phase's mean, ΔE / Δt.
        let (gpu_energy, gpu_power, [gpu_power_m, gpu_energy_m]) = match &gpu {
            GpuPhase::Measured(r) => {
                let p = r.energy_kwh * JOULES_PER_KWH / secs;
                (
                    Some(r.energy_kwh),
                    Some(p),
                    [
                        Measurement::measured("gpu_power_w", p, "W"),
                        Measurement::measured("gpu_energy_kwh", r.energy_kwh, "kWh"),
                    ],
                )
            }
            GpuPhase::Absent(why) => (
                None,
                None,
                [
                    Measurement::absent("gpu_power_w", "W", why),
                    Measurement::absent("gpu_energy_kwh", "kWh", why),
                ],
            ),
        };
        let energy = (cpu_energy + ram_energy + gpu_energy.unwrap_or(0.0)) * self.cfg.pue;
        let emissions = energy * self.cfg.carbon_intensity_g_per_kwh / 1000.0;
        let cpu_how = match &cpu_prov {
            Provenance::Measured => "RAPL",
            _ => "estimated",
        };
        let energy_method = match &gpu {
            GpuPhase::Measured(r) => format!(
                "CPU ({cpu_how}) + RAM (estimated) + GPU (measured: {}), × PUE {}",
                r.method, self.cfg.pue
            ),
            GpuPhase::Absent(_) => format!(
                "CPU ({cpu_how}) + RAM (estimated), × PUE {}; GPU not included (absent)",
                self.cfg.pue
            ),
        };
        let with = |name: &str, v: f64, unit: &str, p: &Provenance| Measurement {
            name: name.into(),
            value: Some(v),
            unit: unit.into(),
            provenance: p.clone(),
        };
        let measurements = vec![
            Measurement::measured("wall_clock_h", hours, "h"),
            Measurement::measured("mean_ram_gb", mean_ram, "GB"),
            Measurement::measured("peak_ram_gb", peak_ram, "GB"),
            with("cpu_power_w", cpu_power, "W", &cpu_prov),
            with("cpu_energy_kwh", cpu_energy, "kWh", &cpu_prov),
            Measurement::estimated("ram_power_w", ram_power, "W", &ram_method),
            Measurement::estimated("ram_energy_kwh", ram_energy, "kWh", &ram_method),
            gpu_power_m,
            gpu_energy_m,
            Measurement::estimated("energy_kwh", energy, "kWh", &energy_method),
            Measurement::estimated(
                "emissions_kg",
                emissions,
                "kg",
                &format!(
                    "energy × {} g CO2e/kWh",
                    self.cfg.carbon_intensity_g_per_kwh
                ),
            ),
        ];
        let total_ram_gb = self
            .sys
            .as_mut()
            .map(|s| {
                s.refresh_memory();
                s.total_memory() as f64 / BYTES_PER_GB
            })
            .unwrap_or(f64::NAN);
        self.row = Some(EmissionsRow {
            timestamp: iso8601(start.wall + Duration::from_secs_f64(secs)),
            project_name: self.cfg.project_name.clone(),
            run_id: self.cfg.run_id.clone(),
            experiment_id: self.cfg.experiment_id.clone(),
            duration_s: secs,
            emissions_kg: emissions,
            cpu_power_w: cpu_power,
            gpu_power_w: gpu_power,
            ram_power_w: ram_power,
            cpu_energy_kwh: cpu_energy,
            gpu_energy_kwh: gpu_energy,
            ram_energy_kwh: ram_energy,
            energy_kwh: energy,
            country_iso_code: self.cfg.country_iso_code.clone(),
            region: self.cfg.region.clone(),
            cpu_count: logical,
            cpu_model: cpu_model(),
            gpu_count: match &gpu {
                GpuPhase::Measured(r) => Some(r.count),
                GpuPhase::Absent(_) => None,
            },
            gpu_model: match &gpu {
                GpuPhase::Measured(r) => r.model.clone(),
                GpuPhase::Absent(_) => String::new(),
            },
            ram_total_gb: total_ram_gb,
            ram_used_gb: mean_ram,
            pue: self.cfg.pue,
        });
        Ok(MeterReport { measurements })
    }
}

fn cpu_model() -> String {
    let Ok(mut sys) = System::new() else {
        return String::new();
    };
    sys.refresh_cpu_all();
    sys.cpus()
        .first()
        .map(|c| c.brand().trim().to_string())
        .unwrap_or_default()
}

/// UTC timestamp `YYYY-MM-DDTHH:MM:SS` (civil-from-days, Hinnant's algorithm).
fn iso8601(t: SystemTime) -> String {
    let secs = t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}-{m:02}-{d:02}T{:02}:{:02}:{:02}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// CodeCarbon's `emissions.csv` columns, in order.
pub const EMISSIONS_COLUMNS: [&str; 38] = [
    "timestamp",
    "project_name",
    "run_id",
    "experiment_id",
    "duration",
    "emissions",
    "emissions_rate",
    "cpu_power",
    "gpu_power",
    "ram_power",
    "cpu_energy",
    "gpu_energy",
    "ram_energy",
    "energy_consumed",
    "water_consumed",
    "country_name",
    "country_iso_code",
    "region",
    "cloud_provider",
    "cloud_region",
    "os",
    "python_version",
    "codecarbon_version",
    "cpu_count",
    "cpu_model",
    "gpu_count",
    "gpu_model",
    "longitude",
    "latitude",
    "ram_total_size",
    "tracking_mode",
    "cpu_utilization_percent",
    "gpu_utilization_percent",
    "ram_utilization_percent",
    "ram_used_gb",
    "on_cloud",
    "pue",
    "wue",
];

/// One `emissions.csv` row (units as CodeCarbon: s, kg, W, kWh, GB).
#[derive(Clone, Debug, PartialEq)]
pub struct EmissionsRow {
    /// UTC end time.
    pub timestamp: String,
    /// Project name.
    pub project_name: String,
    /// Run id.
    pub run_id: String,
    /// Experiment id.
    pub experiment_id: String,
    /// Phase duration (s).
    pub duration_s: f64,
    /// Emissions (kg CO₂e).
    pub emissions_kg: f64,
    /// Mean CPU power (W).
    pub cpu_power_w: f64,
    /// Mean GPU power (W); `None` = not measured (written as an empty field, not 0).
    pub gpu_power_w: Option<f64>,
    /// Mean RAM power (W).
    pub ram_power_w: f64,
    /// CPU energy (kWh).
    pub cpu_energy_kwh: f64,
    /// GPU energy (kWh); `None` = not measured.
    pub gpu_energy_kwh: Option<f64>,
    /// RAM energy (kWh).
    pub ram_energy_kwh: f64,
    /// Total energy (kWh).
    pub energy_kwh: f64,
    /// ISO country code.
    pub country_iso_code: String,
    /// Region.
    pub region: String,
    /// Logical CPUs.
    pub cpu_count: usize,
    /// CPU model.
    pub cpu_model: String,
    /// GPUs measured; `None` when GPU energy is absent (written as an empty field).
    pub gpu_count: Option<usize>,
    /// GPU models, CodeCarbon-style (`2 x NVIDIA A100-SXM4-40GB`); empty when absent.
    pub gpu_model: String,
    /// Machine RAM (GB).
    pub ram_total_gb: f64,
    /// Mean RSS of the process tree (GB).
    pub ram_used_gb: f64,
    /// PUE applied.
    pub pue: f64,
}

fn field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

impl EmissionsRow {
    /// The row as CSV fields in [`EMISSIONS_COLUMNS`] order.
    pub fn fields(&self) -> Vec<String> {
        let opt = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
        let rate = if self.duration_s > 0.0 {
            self.emissions_kg / self.duration_s
        } else {
            0.0
        };
        vec![
            self.timestamp.clone(),
            field(&self.project_name),
            field(&self.run_id),
            field(&self.experiment_id),
            self.duration_s.to_string(),
            self.emissions_kg.to_string(),
            rate.to_string(),
            self.cpu_power_w.to_string(),
            opt(self.gpu_power_w),
            self.ram_power_w.to_string(),
            self.cpu_energy_kwh.to_string(),
            opt(self.gpu_energy_kwh),
            self.ram_energy_kwh.to_string(),
            self.energy_kwh.to_string(),
            "0".into(),
            String::new(),
            field(&self.country_iso_code),
            field(&self.region),
            String::new(),
            String::new(),
            field(std::env::consts::OS),
            String::new(),
            String::new(),
            self.cpu_count.to_string(),
            field(&self.cpu_model),
            self.gpu_count.map(|n| n.to_string()).unwrap_or_default(),
            field(&self.gpu_model),
            String::new(),
            String::new(),
            self.ram_total_gb.to_string(),
            "process".into(),
            String::new(),
            String::new(),
            String::new(),
            self.ram_used_gb.to_string(),
            "N".into(),
            self.pue.to_string(),
            "0".into(),
        ]
    }
}

/// Appends `row` to an `emissions.csv` (header written when the file is new or empty), like
/// CodeCarbon's `on_csv_write="append"`.
///
/// ```
/// use a2perf_metrics::system::{append_emissions_csv, EmissionsRow, EMISSIONS_COLUMNS};
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("emissions.csv");
/// let row = EmissionsRow {
///     timestamp: "2026-01-01T00:00:00".into(), project_name: "p".into(), run_id: "r".into(),
///     experiment_id: String::new(), duration_s: 10.0, emissions_kg: 0.001, cpu_power_w: 20.0,
///     gpu_power_w: None, ram_power_w: 1.0, cpu_energy_kwh: 5e-5, gpu_energy_kwh: None,
///     ram_energy_kwh: 3e-6, energy_kwh: 5.3e-5, country_iso_code: "USA".into(), region: String::new(),
///     cpu_count: 2, cpu_model: "cpu".into(), gpu_count: None, gpu_model: String::new(),
///     ram_total_gb: 8.0, ram_used_gb: 0.5, pue: 1.0,
/// };
/// append_emissions_csv(&path, &row).unwrap();
/// append_emissions_csv(&path, &row).unwrap();
/// let text = std::fs::read_to_string(&path).unwrap();
/// assert_eq!(text.lines().count(), 3);
/// assert!(text.starts_with(&EMISSIONS_COLUMNS.join(",")));
/// ```
pub fn append_emissions_csv(path: &Path, row: &EmissionsRow) -> std::io::Result<()> {
    use std::io::Write;
    let new = std::fs::metadata(path).map_or(true, |m| m.len() == 0);
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    if new {
        writeln!(f, "{}", EMISSIONS_COLUMNS.join(","))?;
    }
    writeln!(f, "{}", row.fields().join(","))
}

/// Times individual inference calls; reports milliseconds.
///
/// Reports `inference_time_ms_{mean,std,p50,p90,p99,min,max}` and `inference_calls` (std is
/// `np.std`, ddof 0; percentiles linear). The original timed seconds and labelled them ms; these
/// are real milliseconds.
///
/// ```
/// use a2perf_core::Meter;
/// use a2perf_metrics::system::InferenceTimer;
/// let mut t = InferenceTimer::default();
/// t.start().unwrap();
/// let x = t.time(|| 2 + 2);
/// assert_eq!(x, 4);
/// t.record(std::time::Duration::from_millis(3));
/// let r = t.finish().unwrap();
/// assert_eq!(r.value("inference_calls"), Some(2.0));
/// assert!(r.value("inference_time_ms_max").unwrap() >= 3.0);
/// ```
#[derive(Default)]
pub struct InferenceTimer {
    samples_ms: Vec<f64>,
    started: bool,
}

impl InferenceTimer {
    /// Runs `f` and records how long it took.
    pub fn time<R>(&mut self, f: impl FnOnce() -> R) -> R {
        let t = Instant::now();
        let r = f();
        self.record(t.elapsed());
        r
    }

    /// Records one call's duration.
    pub fn record(&mut self, d: Duration) {
        self.samples_ms.push(d.as_secs_f64() * 1000.0);
    }

    /// The recorded durations (ms).
    pub fn samples_ms(&self) -> &[f64] {
        &self.samples_ms
    }
}

impl Meter for InferenceTimer {
    fn name(&self) -> &str {
        "inference_time"
    }

    fn start(&mut self) -> Result<(), MeterError> {
        self.samples_ms.clear();
        self.started = true;
        Ok(())
    }

    fn finish(&mut self) -> Result<MeterReport, MeterError> {
        if !self.started {
            return Err(MeterError::NotStarted("inference_time".into()));
        }
        self.started = false;
        let n = self.samples_ms.len();
        let name = |s: &str| format!("inference_time_ms_{s}");
        if n == 0 {
            let why = "no inference calls were timed";
            return Ok(MeterReport {
                measurements: ["mean", "std", "p50", "p90", "p99", "min", "max"]
                    .iter()
                    .map(|s| Measurement::absent(&name(s), "ms", why))
                    .chain(std::iter::once(Measurement::measured(
                        "inference_calls",
                        0.0,
                        "1",
                    )))
                    .collect(),
            });
        }
        let s = numeric::sorted(&self.samples_ms);
        let vals = [
            ("mean", numeric::mean(&s)),
            ("std", numeric::std(&s, 0)),
            ("p50", numeric::percentile_sorted(&s, 50.0)),
            ("p90", numeric::percentile_sorted(&s, 90.0)),
            ("p99", numeric::percentile_sorted(&s, 99.0)),
            ("min", s[0]),
            ("max", s[n - 1]),
        ];
        let mut measurements: Vec<Measurement> = vals
            .iter()
            .map(|(k, v)| Measurement::measured(&name(k), *v, "ms"))
            .collect();
        measurements.push(Measurement::measured("inference_calls", n as f64, "1"));
        Ok(MeterReport { measurements })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn threads_are_not_counted_as_processes() {
        let stop = Arc::new(AtomicBool::new(false));
        let threads: Vec<_> = (0..4)
            .map(|_| {
                let stop = stop.clone();
                std::thread::spawn(move || {
                    while !stop.load(Ordering::Relaxed) {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                })
            })
            .collect();
        let root = sysinfo::get_current_pid().unwrap();
        let mut sys = System::new().unwrap();
        refresh(&mut sys);
        let own = sys.process(root).unwrap().memory();
        let (tree, _) = process_tree(&sys, root);
        stop.store(true, Ordering::Relaxed);
        for t in threads {
            t.join().unwrap();
        }
        // Five or more threads of one process would count its RSS five times or more.
        assert!(
            tree >= own && tree < own + own / 2,
            "tree {tree} vs own {own}"
        );
    }

    #[test]
    fn iso8601_known_dates() {
        assert_eq!(iso8601(UNIX_EPOCH), "1970-01-01T00:00:00");
        assert_eq!(
            iso8601(UNIX_EPOCH + Duration::from_secs(951_782_400 + 3661)),
            "2000-02-29T01:01:01"
        );
    }

    #[test]
    fn rapl_reader_handles_fake_powercap_tree() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("intel-rapl:0");
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join("name"), "package-0\n").unwrap();
        std::fs::write(d.join("energy_uj"), "999000\n").unwrap();
        std::fs::write(d.join("max_energy_range_uj"), "1000000\n").unwrap();
        let core = dir.path().join("intel-rapl:0:0");
        std::fs::create_dir_all(&core).unwrap();
        std::fs::write(core.join("name"), "core\n").unwrap();
        std::fs::write(core.join("energy_uj"), "5\n").unwrap();
        std::fs::write(core.join("max_energy_range_uj"), "10\n").unwrap();
        let doms = rapl_domains(dir.path());
        assert_eq!(doms.len(), 1, "only package domains count");
        let before = read_rapl(&doms).unwrap();
        std::fs::write(d.join("energy_uj"), "1000\n").unwrap();
        let after = read_rapl(&doms).unwrap();
        assert_eq!(rapl_delta_uj(before[0], after[0], doms[0].max_uj), 2000);
    }

    fn quiet_cfg() -> SystemMeterConfig {
        SystemMeterConfig {
            interval: Duration::from_millis(5),
            force_cpu_tdp_watts: Some(100.0),
            powercap_root: PathBuf::from("/nonexistent"),
            carbon_intensity_g_per_kwh: 1000.0,
            ..SystemMeterConfig::default()
        }
    }

    #[test]
    fn gpu_is_absent_not_zero_and_emissions_follow_intensity() {
        let mut m = SystemMeter::with_gpu(quiet_cfg(), Box::new(gpu::NoGpu::new("no GPU here")));
        m.start().unwrap();
        let mut x = 0u64;
        for i in 0..3_000_000u64 {
            x = x.wrapping_mul(31).wrapping_add(i);
        }
        std::hint::black_box(x);
        let r = m.finish().unwrap();
        let gpu = r.get("gpu_power_w").unwrap();
        assert!(gpu.value.is_none());
        assert!(matches!(gpu.provenance, Provenance::Absent(_)));
        assert!(matches!(
            r.get("cpu_energy_kwh").unwrap().provenance,
            Provenance::Estimated(_)
        ));
        let e = r.value("energy_kwh").unwrap();
        assert!(e > 0.0);
        assert!((r.value("emissions_kg").unwrap() - e).abs() < 1e-15);
        let row = m.emissions_row().unwrap();
        assert_eq!(row.fields().len(), EMISSIONS_COLUMNS.len());
        assert_eq!(row.fields()[8], "", "gpu_power is empty, not 0");
    }

    /// A GPU that used a fixed energy per phase, standing in for NVML.
    struct FakeGpu {
        started: bool,
        samples: usize,
    }

    impl GpuSource for FakeGpu {
        fn start(&mut self, _interval: Duration) {
            self.started = true;
        }
        fn sample(&mut self) {
            self.samples += 1;
        }
        fn finish(&mut self) -> GpuPhase {
            assert!(self.started, "finish before start");
            self.started = false;
            GpuPhase::Measured(gpu::GpuReading {
                count: 2,
                model: "2 x Fake, GPU".into(),
                energy_kwh: 2e-3,
                method: format!("fake, {} samples", self.samples),
            })
        }
    }

    #[test]
    fn measured_gpu_is_reported_added_to_energy_and_written_to_csv() {
        let cfg = SystemMeterConfig {
            pue: 1.5,
            ..quiet_cfg()
        };
        let fake = FakeGpu {
            started: false,
            samples: 0,
        };
        let mut m = SystemMeter::with_gpu(cfg, Box::new(fake));
        m.start().unwrap();
        m.sample().unwrap();
        let r = m.finish().unwrap();
        let secs = r.value("wall_clock_h").unwrap() * 3600.0;
        let e = r.get("gpu_energy_kwh").unwrap();
        assert_eq!(e.value, Some(2e-3));
        assert_eq!(e.provenance, Provenance::Measured);
        let p = r.get("gpu_power_w").unwrap();
        assert_eq!(p.provenance, Provenance::Measured);
        // Mean power over the phase; the wall clock is measured a moment later, hence the slack.
        let expected_w = 2e-3 * JOULES_PER_KWH / secs;
        assert!((p.value.unwrap() / expected_w - 1.0).abs() < 0.05);
        let parts = r.value("cpu_energy_kwh").unwrap() + r.value("ram_energy_kwh").unwrap() + 2e-3;
        let total = r.value("energy_kwh").unwrap();
        assert!(
            (total - 1.5 * parts).abs() < 1e-15,
            "{total} vs 1.5 × {parts}"
        );
        match &r.get("energy_kwh").unwrap().provenance {
            Provenance::Estimated(how) => {
                assert!(how.contains("GPU (measured: fake, 1 samples)"), "{how}")
            }
            other => panic!("{other:?}"),
        }
        let row = m.emissions_row().unwrap();
        let f = row.fields();
        assert_eq!(f[8].parse::<f64>().unwrap(), p.value.unwrap());
        assert_eq!(f[11].parse::<f64>().unwrap(), 2e-3);
        assert_eq!(f[25], "2");
        assert_eq!(f[26], "\"2 x Fake, GPU\"");
    }

    #[cfg(not(feature = "nvml"))]
    #[test]
    fn gpu_default_without_feature_names_the_feature() {
        let mut m = SystemMeter::new(quiet_cfg());
        m.start().unwrap();
        let r = m.finish().unwrap();
        for name in ["gpu_power_w", "gpu_energy_kwh"] {
            let g = r.get(name).unwrap();
            assert_eq!(g.value, None);
            assert_eq!(
                g.provenance,
                Provenance::Absent(gpu::WITHOUT_NVML_FEATURE.into())
            );
        }
        assert!(gpu::WITHOUT_NVML_FEATURE.contains("built without the `nvml` feature"));
        let row = m.emissions_row().unwrap();
        assert_eq!((row.gpu_count, row.gpu_model.as_str()), (None, ""));
    }
}
