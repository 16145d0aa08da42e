//! What the baselines' benches share: on-CPU time of the calling thread.

/// Nanoseconds this thread has run on a CPU, when the kernel says (Linux:
/// `/proc/thread-self/schedstat`).
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

/// Thread CPU time per call of `f`, in milliseconds, over `rounds` rounds of `per` calls each,
/// sorted (empty where the kernel does not say). The kernel may account thread time in
/// scheduler ticks (4 ms here), so rounds of many calls, and their median, mean more than one
/// call would; a loaded machine disturbs thread CPU time less than wall time.
pub fn thread_cpu_rounds(rounds: usize, per: usize, f: &mut dyn FnMut()) -> Vec<f64> {
    let mut cpu = Vec::new();
    for _ in 0..rounds {
        let t0 = thread_cpu_ns();
        for _ in 0..per {
            f();
        }
        if let (Some(a), Some(b)) = (t0, thread_cpu_ns()) {
            cpu.push((b - a) as f64 / per as f64 / 1e6);
        }
    }
    cpu.sort_by(f64::total_cmp);
    cpu
}

/// `rows` transitions of uniformly random legal play on `env` from reset seed 0 (each episode
/// after the first from the next seed): the observations, the next observations and the
/// actions, row by row.
pub fn random_play(
    env: &mut dyn a2perf_core::Env,
    layout: &a2perf_baselines::batch::ObsLayout,
    rows: usize,
) -> Option<(
    a2perf_baselines::batch::ObsBatch,
    a2perf_baselines::batch::ObsBatch,
    Vec<a2perf_core::Action>,
)> {
    use a2perf_baselines::batch::ObsBatch;
    let space = env.spec().action_space.clone();
    let mut rng = a2perf_core::RngStream::new(0, "bench/play");
    let (mut obs, mut next) = (ObsBatch::new(layout), ObsBatch::new(layout));
    let mut actions = Vec::new();
    let mut cur = env.reset(Some(0)).ok()?;
    let mut episode = 0;
    while obs.len() < rows {
        let row = obs.push(&cur).ok()?;
        let action = space.sample(&mut rng, obs.mask(row))?;
        let step = env.step(&action).ok()?;
        actions.push(action);
        next.push(&step.observation).ok()?;
        cur = if step.terminated || step.truncated {
            episode += 1;
            env.reset(Some(episode)).ok()?
        } else {
            step.observation
        };
    }
    Some((obs, next, actions))
}
