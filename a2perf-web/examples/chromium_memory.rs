//! RAM and latency of Chromium environments: one environment alone, then N side by side.
//!
//! ```text
//! cargo run --release -p a2perf-web --example chromium_memory -- [N] [STEPS]
//! A2PERF_CHROMIUM_ARGS="--single-process ..." cargo run --release -p a2perf-web --example chromium_memory
//! ```
//!
//! Each environment is reset and stepped (oracle actions, a random legal one every fourth step)
//! for STEPS steps (default 500) and 50 more resets before its process tree is measured; the
//! definition of the figures is on [`a2perf_web::TreeMemory`]. N defaults to 4.

use std::time::Instant;

use a2perf_core::{Action, Env, Observation, RngStream, Step};
use a2perf_web::{
    BackendKind, ChromiumOptions, TreeMemory, WebNavConfig, WebNavEnv, chromium_available,
    other_browser_processes,
};

fn mib(b: u64) -> f64 {
    b as f64 / 1048576.0
}

fn percentile(s: &mut [f64], q: f64) -> f64 {
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// Runs `n` steps and 50 resets; returns step and reset latencies in ms.
fn exercise(env: &mut WebNavEnv, n: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let (mut obs, mut step) = (Observation::default(), Step::default());
    let mut rng = RngStream::new(seed, "memory-example");
    let mut episode = seed * 100_000;
    env.reset_into(Some(episode), &mut obs).unwrap();
    let (mut steps, mut resets) = (Vec::with_capacity(n), Vec::new());
    let trace: usize = std::env::var("A2PERF_MEMORY_TRACE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let mut t = 0;
    while steps.len() < n {
        if trace > 0 && !steps.is_empty() && steps.len() % trace == 0 && t == 0 {
            let chrome = env.chromium().unwrap();
            let m = chrome.memory();
            // DevTools' figures are exact; `performance.memory` rounds to coarse buckets.
            let heap = chrome
                .cdp("Runtime.getHeapUsage", serde_json::json!({}))
                .unwrap_or_default();
            let f = |k: &str| heap[k].as_f64().unwrap_or(f64::NAN) / 1e6;
            println!(
                "  trace: {} steps, PSS {:.1} MiB (anon {:.1}), JS heap used {:.1} MB of {:.1} MB",
                steps.len(),
                mib(m.pss_bytes),
                mib(m.pss_anon_bytes),
                f("usedSize"),
                f("totalSize")
            );
        }
        let a = if t % 4 == 3 {
            let mask = obs.action_mask.as_ref().unwrap();
            let legal: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
            Some(legal[rng.index(legal.len())])
        } else {
            env.oracle_action()
        };
        let done = match a {
            Some(a) => {
                let s = Instant::now();
                env.step_into(&Action::Discrete(a), &mut step).unwrap();
                steps.push(s.elapsed().as_secs_f64() * 1e3);
                std::mem::swap(&mut obs, &mut step.observation);
                t += 1;
                step.done()
            }
            None => true,
        };
        if done {
            episode += 1;
            t = 0;
            env.reset_into(Some(episode), &mut obs).unwrap();
        }
    }
    for _ in 0..50 {
        episode += 1;
        let s = Instant::now();
        env.reset_into(Some(episode), &mut obs).unwrap();
        resets.push(s.elapsed().as_secs_f64() * 1e3);
    }
    (steps, resets)
}

fn print_memory(label: &str, m: &TreeMemory) {
    println!(
        "{label}: {} processes, PSS {:.1} MiB (anon {:.1}, file {:.1}, shmem {:.1}), USS {:.1} MiB, summed RSS {:.1} MiB",
        m.processes,
        mib(m.pss_bytes),
        mib(m.pss_anon_bytes),
        mib(m.pss_file_bytes),
        mib(m.pss_shmem_bytes),
        mib(m.uss_bytes),
        mib(m.rss_bytes)
    );
}

fn main() {
    if let Err(e) = chromium_available() {
        println!("SKIP: {e}");
        return;
    }
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n: usize = args.first().and_then(|s| s.parse().ok()).unwrap_or(4);
    let steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(500);
    let opts = ChromiumOptions::from_env();
    println!("chromium extra flags: {:?}", opts.extra_args);
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("load average at start: {}", load.trim());
    let others = other_browser_processes();
    if !others.is_empty() {
        println!(
            "WARNING: {} other Chromium/chromedriver processes are running; they share code pages \
             and lower the PSS figures below",
            others.len()
        );
    }

    let make = |i: usize| {
        let mut c = WebNavConfig::new((i % 3 + 1) as u8);
        c.seed = i as u64;
        c.backend = BackendKind::Chromium;
        WebNavEnv::new(c).unwrap()
    };

    // One environment alone.
    let t0 = Instant::now();
    let mut env = make(0);
    let launch = t0.elapsed().as_secs_f64() * 1e3;
    env.reset(Some(0)).unwrap();
    let m0 = env.chromium().unwrap().memory();
    let (mut s, mut r) = exercise(&mut env, steps, 1);
    let m1 = env.chromium().unwrap().memory();
    println!(
        "lone environment: launch {launch:.0} ms; step p50 {:.2} ms, p90 {:.2} ms ({} steps); reset p50 {:.2} ms, p90 {:.2} ms",
        percentile(&mut s, 0.5),
        percentile(&mut s, 0.9),
        s.len(),
        percentile(&mut r, 0.5),
        percentile(&mut r, 0.9)
    );
    print_memory("lone environment after the first reset", &m0);
    print_memory(
        &format!("lone environment after {steps} steps + 50 resets"),
        &m1,
    );
    if std::env::var_os("A2PERF_MEMORY_DETAIL").is_some() {
        for (pid, role, m) in env.chromium().unwrap().memory_by_process() {
            print_memory(&format!("  pid {pid} {role}"), &m);
        }
    }
    if let Ok(heap) = env
        .chromium()
        .unwrap()
        .cdp("Runtime.getHeapUsage", serde_json::json!({}))
    {
        println!("lone environment JS heap (DevTools Runtime.getHeapUsage, bytes): {heap}");
    }
    if let Ok(heap) = env
        .chromium()
        .unwrap()
        .execute("return [performance.memory.usedJSHeapSize, performance.memory.totalJSHeapSize, innerWidth, innerHeight];", "[]")
    {
        println!("lone environment JS heap used, total (bytes), viewport width, height: {heap}");
    }
    env.close().unwrap();
    drop(env);

    if n > 1 {
        let mut envs: Vec<WebNavEnv> = (0..n).map(make).collect();
        let mut all_steps = Vec::new();
        for (i, e) in envs.iter_mut().enumerate() {
            all_steps.extend(exercise(e, steps, 10 + i as u64).0);
        }
        let ms: Vec<TreeMemory> = envs
            .iter_mut()
            .map(|e| e.chromium().unwrap().memory())
            .collect();
        let avg = TreeMemory::mean(&ms);
        println!(
            "{n} environments side by side: step p50 {:.2} ms, p90 {:.2} ms",
            percentile(&mut all_steps, 0.5),
            percentile(&mut all_steps, 0.9)
        );
        print_memory(&format!("per environment, {n} side by side"), &avg);
        for e in envs.iter_mut() {
            e.close().unwrap();
        }
    }
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    println!("load average at end: {}", load.trim());
}
