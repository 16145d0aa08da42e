//! NVIDIA GPUs through NVML (`nvml` feature).
//!
//! Per device, like CodeCarbon: the difference of `nvmlDeviceGetTotalEnergyConsumption` (mJ)
//! between start and finish (Volta and newer). Devices without that counter fall back to the
//! trapezoidal integral of `nvmlDeviceGetPowerUsage` (mW) samples taken at start, every meter
//! interval on a background thread, at each explicit `sample()` and at finish. Readings are
//! whole-device (every process on the GPU counts), as in CodeCarbon's process mode.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nvml_wrapper::Nvml;

use super::{GpuPhase, GpuReading, GpuSource};

const MJ_PER_KWH: f64 = 3.6e9;
const WHY: &str = "GPU power is not measured";

/// How one device's energy is obtained.
#[derive(Clone, Copy, Debug)]
enum Track {
    /// The energy counter (mJ) read at start.
    Counter(u64),
    /// Index into the power integrals.
    Power(usize),
}

#[derive(Debug)]
struct Device {
    index: u32,
    name: String,
    track: Track,
}

/// Trapezoidal integral of power samples.
#[derive(Clone, Copy, Debug, Default)]
struct PowerIntegral {
    last: Option<(Instant, f64)>,
    joules: f64,
    samples: u64,
}

impl PowerIntegral {
    fn add(&mut self, t: Instant, watts: f64) {
        if let Some((t0, w0)) = self.last {
            self.joules += 0.5 * (w0 + watts) * t.saturating_duration_since(t0).as_secs_f64();
        }
        self.last = Some((t, watts));
        self.samples += 1;
    }

    /// Extends the last reading flat to `t` (when the final reading fails).
    fn hold_until(&mut self, t: Instant) {
        if let Some((_, w)) = self.last {
            self.add(t, w);
        }
    }
}

/// Reads the power of the devices in `indices` into the matching integrals.
fn sample_power(nvml: &Nvml, indices: &[u32], integrals: &Mutex<Vec<PowerIntegral>>) {
    let now = Instant::now();
    let readings: Vec<Option<f64>> = indices
        .iter()
        .map(|&i| {
            nvml.device_by_index(i)
                .and_then(|d| d.power_usage())
                .ok()
                .map(|mw| f64::from(mw) / 1000.0)
        })
        .collect();
    if let Ok(mut ints) = integrals.lock() {
        for (int, w) in ints.iter_mut().zip(readings) {
            // A failed intermediate reading is skipped; the trapezoid bridges the gap.
            if let Some(w) = w {
                int.add(now, w);
            }
        }
    }
}

/// CodeCarbon's `gpu_model`: `"{count} x {name}"` per distinct name in order of first
/// appearance, concatenated without a separator.
fn model_string<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for n in names {
        match counts.iter_mut().find(|(m, _)| *m == n) {
            Some((_, c)) => *c += 1,
            None => counts.push((n, 1)),
        }
    }
    counts.iter().map(|(n, c)| format!("{c} x {n}")).collect()
}

fn list(indices: impl IntoIterator<Item = u32>) -> String {
    indices
        .into_iter()
        .map(|i| i.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

struct Active {
    nvml: Arc<Nvml>,
    devices: Vec<Device>,
    skipped: Vec<String>,
    power_indices: Arc<Vec<u32>>,
    power: Arc<Mutex<Vec<PowerIntegral>>>,
    interval: Duration,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Active {
    fn start(interval: Duration) -> Result<Self, String> {
        let nvml = Arc::new(
            Nvml::init().map_err(|e| format!("{WHY}: NVML could not be initialised ({e})"))?,
        );
        let n = nvml
            .device_count()
            .map_err(|e| format!("{WHY}: NVML could not count the GPUs ({e})"))?;
        if n == 0 {
            return Err(format!("{WHY}: NVML found no GPU"));
        }
        let now = Instant::now();
        let (mut devices, mut skipped, mut power_indices, mut integrals) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for index in 0..n {
            let dev = match nvml.device_by_index(index) {
                Ok(d) => d,
                Err(e) => {
                    skipped.push(format!("GPU {index}: {e}"));
                    continue;
                }
            };
            let name = dev
                .name()
                .unwrap_or_else(|_| "unknown NVIDIA GPU".to_string());
            let track = match dev.total_energy_consumption() {
                Ok(mj) => Track::Counter(mj),
                Err(counter_err) => match dev.power_usage() {
                    Ok(mw) => {
                        let mut p = PowerIntegral::default();
                        p.add(now, f64::from(mw) / 1000.0);
                        integrals.push(p);
                        power_indices.push(index);
                        Track::Power(integrals.len() - 1)
                    }
                    Err(e) => {
                        skipped.push(format!(
                            "GPU {index} ({name}): no energy counter ({counter_err}) nor power reading ({e})"
                        ));
                        continue;
                    }
                },
            };
            devices.push(Device { index, name, track });
        }
        if devices.is_empty() {
            return Err(format!(
                "{WHY}: NVML found {n} GPU(s) but none reports energy or power: {}",
                skipped.join("; ")
            ));
        }
        let mut active = Self {
            nvml,
            devices,
            skipped,
            power_indices: Arc::new(power_indices),
            power: Arc::new(Mutex::new(integrals)),
            interval,
            stop: Arc::default(),
            thread: None,
        };
        if !active.power_indices.is_empty() {
            let (nvml, indices, power, stop) = (
                active.nvml.clone(),
                active.power_indices.clone(),
                active.power.clone(),
                active.stop.clone(),
            );
            active.thread = Some(std::thread::spawn(move || {
                let tick = interval
                    .min(Duration::from_millis(50))
                    .max(Duration::from_millis(1));
                let mut next = Instant::now() + interval;
                while !stop.load(Ordering::Relaxed) {
                    if Instant::now() >= next {
                        sample_power(&nvml, &indices, &power);
                        next += interval;
                    } else {
                        std::thread::sleep(
                            tick.min(next.saturating_duration_since(Instant::now())),
                        );
                    }
                }
            }));
        }
        Ok(active)
    }

    fn stop_thread(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            // A panicked sampler only loses intermediate samples; finish still reads the ends.
            let _ = t.join();
        }
    }

    fn finish(&mut self) -> GpuPhase {
        self.stop_thread();
        let now = Instant::now();
        sample_power(&self.nvml, &self.power_indices, &self.power);
        let Ok(mut integrals) = self.power.lock().map(|g| g.clone()) else {
            return GpuPhase::Absent(format!("{WHY}: the GPU power sampler failed"));
        };
        for int in &mut integrals {
            if int.last.is_some_and(|(t, _)| t < now) {
                int.hold_until(now);
            }
        }
        let mut joules = 0.0;
        for d in &self.devices {
            match d.track {
                Track::Counter(before) => {
                    let after = self
                        .nvml
                        .device_by_index(d.index)
                        .and_then(|dev| dev.total_energy_consumption());
                    match after {
                        Ok(after) if after >= before => joules += (after - before) as f64 / 1000.0,
                        Ok(after) => {
                            return GpuPhase::Absent(format!(
                                "{WHY}: the NVML energy counter of GPU {} went backwards ({before} → {after} mJ; driver reloaded?)",
                                d.index
                            ));
                        }
                        Err(e) => {
                            return GpuPhase::Absent(format!(
                                "{WHY}: reading the energy counter of GPU {} at finish failed ({e})",
                                d.index
                            ));
                        }
                    }
                }
                Track::Power(k) => joules += integrals[k].joules,
            }
        }
        let counters = self
            .devices
            .iter()
            .filter(|d| matches!(d.track, Track::Counter(_)))
            .map(|d| d.index);
        let mut method = String::from("NVML");
        let counters = list(counters);
        if !counters.is_empty() {
            method += &format!("; energy counter on GPU {counters}");
        }
        if !self.power_indices.is_empty() {
            let n_samples: u64 = integrals.iter().map(|i| i.samples).sum();
            method += &format!(
                "; trapezoid over {n_samples} power samples (every {:?}) on GPU {}",
                self.interval,
                list(self.power_indices.iter().copied())
            );
        }
        if !self.skipped.is_empty() {
            method += &format!("; not measured: {}", self.skipped.join("; "));
        }
        GpuPhase::Measured(GpuReading {
            count: self.devices.len(),
            model: model_string(self.devices.iter().map(|d| d.name.as_str())),
            energy_kwh: joules * 1000.0 / MJ_PER_KWH,
            method,
        })
    }
}

/// Reads every NVIDIA GPU through NVML (see the module docs of [`crate::gpu`]).
///
/// NVML is initialised at each `start`; if that fails the phase reports the NVML error as the
/// absence reason.
///
/// ```
/// use a2perf_metrics::gpu::{GpuPhase, GpuSource, NvmlGpu};
/// let mut g = NvmlGpu::default();
/// g.start(std::time::Duration::from_millis(10));
/// match g.finish() {
///     GpuPhase::Absent(why) => assert!(why.contains("NVML")),
///     GpuPhase::Measured(r) => assert!(r.energy_kwh >= 0.0),
/// }
/// ```
#[derive(Default)]
pub struct NvmlGpu {
    state: Option<Result<Active, String>>,
}

impl GpuSource for NvmlGpu {
    fn start(&mut self, interval: Duration) {
        if let Some(Ok(a)) = self.state.as_mut() {
            a.stop_thread();
        }
        self.state = Some(Active::start(interval));
    }

    fn sample(&mut self) {
        if let Some(Ok(a)) = self.state.as_ref() {
            sample_power(&a.nvml, &a.power_indices, &a.power);
        }
    }

    fn finish(&mut self) -> GpuPhase {
        match self.state.take() {
            None => GpuPhase::Absent(format!("{WHY}: the GPU meter was not started")),
            Some(Err(why)) => GpuPhase::Absent(why),
            Some(Ok(mut a)) => a.finish(),
        }
    }
}

impl Drop for NvmlGpu {
    fn drop(&mut self) {
        if let Some(Ok(a)) = self.state.as_mut() {
            a.stop_thread();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gpu_model_string_counts_names_in_first_seen_order() {
        assert_eq!(model_string(["A", "B", "A"]), "2 x A1 x B");
        assert_eq!(model_string(["Tesla V100"]), "1 x Tesla V100");
    }

    #[test]
    fn gpu_power_trapezoid_and_hold() {
        let t0 = Instant::now();
        let mut p = PowerIntegral::default();
        p.add(t0, 100.0);
        p.add(t0 + Duration::from_secs(2), 200.0);
        assert!((p.joules - 300.0).abs() < 1e-9);
        p.hold_until(t0 + Duration::from_secs(3));
        assert!((p.joules - 500.0).abs() < 1e-9);
        assert_eq!(p.samples, 3);
    }
}
