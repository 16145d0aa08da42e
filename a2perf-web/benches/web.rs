//! Benchmarks: simulated step and reset; Chromium step (p50/p90), reset and memory per
//! environment. Chromium parts are skipped (with a message) when the browser is not installed.

use std::hint::black_box;
use std::time::{Duration, Instant};

use a2perf_core::{Action, Env, Observation, RngStream, Step};
use a2perf_web::{
    BackendKind, ChromiumOptions, TreeMemory, WebNavConfig, WebNavEnv, chromium_available,
    other_browser_processes,
};
use criterion::{Criterion, criterion_group, criterion_main};

/// Picks the oracle action 3 times in 4, a random legal one otherwise (chosen outside the timing).
fn next_action(
    env: &WebNavEnv,
    obs: &Observation,
    rng: &mut RngStream,
    t: usize,
    legal: &mut Vec<usize>,
) -> Option<usize> {
    if t % 4 == 3 {
        let mask = obs.action_mask.as_ref()?;
        legal.clear();
        legal.extend((0..mask.len()).filter(|&i| mask[i]));
        (!legal.is_empty()).then(|| legal[rng.index(legal.len())])
    } else {
        env.oracle_action()
    }
}

/// Times `n` steps (only `step_into`), resetting when episodes end.
fn timed_steps(env: &mut WebNavEnv, n: u64, seed: u64) -> (Duration, Vec<f64>) {
    let mut obs = Observation::default();
    let mut step = Step::default();
    let mut rng = RngStream::new(seed, "bench");
    let mut legal = Vec::with_capacity(20_000);
    let mut total = Duration::ZERO;
    let mut samples = Vec::with_capacity(n as usize);
    let mut episode = seed;
    env.reset_into(Some(episode), &mut obs).unwrap();
    let mut t = 0;
    while (samples.len() as u64) < n {
        let Some(a) = next_action(env, &obs, &mut rng, t, &mut legal) else {
            episode += 1;
            env.reset_into(Some(episode), &mut obs).unwrap();
            t = 0;
            continue;
        };
        let action = Action::Discrete(a);
        let start = Instant::now();
        env.step_into(black_box(&action), &mut step).unwrap();
        let dt = start.elapsed();
        total += dt;
        samples.push(dt.as_secs_f64() * 1e6);
        t += 1;
        if step.done() {
            episode += 1;
            env.reset_into(Some(episode), &mut obs).unwrap();
            t = 0;
        } else {
            std::mem::swap(&mut obs, &mut step.observation);
        }
    }
    (total, samples)
}

fn percentile(samples: &mut [f64], q: f64) -> f64 {
    samples.sort_by(f64::total_cmp);
    samples[((samples.len() - 1) as f64 * q).round() as usize]
}

fn simulated(c: &mut Criterion) {
    for level in [1u8, 3] {
        let mut env = WebNavEnv::new(WebNavConfig::new(level)).unwrap();
        c.bench_function(&format!("simulated_step_level{level}"), |b| {
            b.iter_custom(|iters| timed_steps(&mut env, iters, 1).0)
        });
        let mut obs = Observation::default();
        let mut seed = 0;
        c.bench_function(&format!("simulated_reset_level{level}"), |b| {
            b.iter(|| {
                seed += 1;
                env.reset_into(Some(seed), &mut obs).unwrap();
            })
        });
        let (_, mut s) = timed_steps(&mut env, 20_000, 9);
        println!(
            "simulated level {level}: step p50 {:.2} µs, p90 {:.2} µs over {} steps",
            percentile(&mut s, 0.5),
            percentile(&mut s, 0.9),
            s.len()
        );
    }
    // The original's semantics (every switch of `WebNavConfig::a2perf`) on the generated level-3
    // pool (A2Perf's design files are not shipped).
    let mut cfg = WebNavConfig::a2perf(3, "unused".into());
    cfg.designs_file = None;
    let pool = WebNavConfig::new(3).pool().unwrap();
    let mut env = WebNavEnv::with_pool(pool, cfg, "bench").unwrap();
    c.bench_function("simulated_step_level3_a2perf_semantics", |b| {
        b.iter_custom(|iters| timed_steps(&mut env, iters, 1).0)
    });
    let (_, mut s) = timed_steps(&mut env, 20_000, 9);
    println!(
        "simulated level 3, A2Perf's semantics: step p50 {:.2} µs, p90 {:.2} µs over {} steps",
        percentile(&mut s, 0.5),
        percentile(&mut s, 0.9),
        s.len()
    );
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_default()
}

fn print_memory(label: &str, m: &TreeMemory) {
    let mib = |b: u64| b as f64 / 1048576.0;
    println!(
        "{label}: PSS {:.1} MiB = {:.1} MB (anon {:.1}, file {:.1}, shmem {:.1} MiB) over {} \
         processes; USS {:.1} MiB; summed RSS {:.1} MiB",
        mib(m.pss_bytes),
        m.pss_bytes as f64 / 1e6,
        mib(m.pss_anon_bytes),
        mib(m.pss_file_bytes),
        mib(m.pss_shmem_bytes),
        m.processes,
        mib(m.uss_bytes),
        mib(m.rss_bytes)
    );
}

fn chromium(c: &mut Criterion) {
    if let Err(e) = chromium_available() {
        println!("SKIP chromium benches: {e}");
        return;
    }
    let opts = ChromiumOptions::from_env();
    println!(
        "chromium: {} with extra flags {:?}; load average {}",
        opts.chromium.display(),
        opts.extra_args,
        load_average()
    );
    let others = other_browser_processes();
    if !others.is_empty() {
        println!(
            "WARNING: {} Chromium/chromedriver processes of other programs are running; they share \
             code pages with ours, so the lone-environment PSS below comes out too low",
            others.len()
        );
    }
    let mut cfg = WebNavConfig::new(1);
    cfg.backend = BackendKind::Chromium;
    let t0 = Instant::now();
    let mut env = WebNavEnv::new(cfg).unwrap();
    let launch = t0.elapsed();
    let mut obs = Observation::default();
    env.reset_into(Some(0), &mut obs).unwrap();
    let mem0 = env.chromium().unwrap().memory();
    // Warm up, then sample step latencies.
    timed_steps(&mut env, 200, 2);
    let (_, mut s) = timed_steps(&mut env, 1000, 3);
    let mut resets = Vec::new();
    for seed in 0..50 {
        let t = Instant::now();
        env.reset_into(Some(100 + seed), &mut obs).unwrap();
        resets.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let mem1 = env.chromium().unwrap().memory();
    println!(
        "chromium: launch {:.0} ms; step p50 {:.2} ms, p90 {:.2} ms, p99 {:.2} ms over {} steps; \
         reset p50 {:.1} ms, p90 {:.1} ms",
        launch.as_secs_f64() * 1e3,
        percentile(&mut s, 0.5) / 1e3,
        percentile(&mut s, 0.9) / 1e3,
        percentile(&mut s, 0.99) / 1e3,
        s.len(),
        percentile(&mut resets, 0.5),
        percentile(&mut resets, 0.9),
    );
    // RAM of an environment = PSS summed over chromedriver + every Chromium process it started
    // (TreeMemory's documentation says why). A lone environment pays for all of Chromium's code
    // pages it touched: that is what a user running one environment sees.
    for (when, m) in [
        ("after launch + first reset", mem0),
        ("after 1,200 steps + 50 resets", mem1),
    ] {
        print_memory(&format!("RAM of one environment, lone, {when}"), &m);
    }
    // Several side by side: Chromium's code pages are split between them.
    let n = 4u64;
    let mut envs: Vec<WebNavEnv> = (0..n)
        .map(|i| {
            let mut c = WebNavConfig::new(3);
            c.seed = i;
            c.backend = BackendKind::Chromium;
            WebNavEnv::new(c).unwrap()
        })
        .collect();
    for e in envs.iter_mut() {
        timed_steps(e, 300, 5);
    }
    let ms: Vec<TreeMemory> = envs
        .iter_mut()
        .map(|e| e.chromium().unwrap().memory())
        .collect();
    let avg = TreeMemory::mean(&ms);
    print_memory(
        &format!("RAM per environment, {n} side by side, 300 steps each"),
        &avg,
    );
    for e in envs.iter_mut() {
        e.close().unwrap();
    }
    let mut group = c.benchmark_group("chromium");
    group.sample_size(20);
    group.measurement_time(Duration::from_secs(8));
    group.bench_function("chromium_step", |b| {
        b.iter_custom(|iters| timed_steps(&mut env, iters, 4).0)
    });
    let mut seed = 1000;
    group.bench_function("chromium_reset", |b| {
        b.iter(|| {
            seed += 1;
            env.reset_into(Some(seed), &mut obs).unwrap();
        })
    });
    group.finish();
    env.close().unwrap();
    println!("load average at the end: {}", load_average());
}

criterion_group!(benches, simulated, chromium);
criterion_main!(benches);
