//! The simulated backend's step allocates nothing (counted with a global allocator).

use a2perf_core::alloc_count::{CountingAllocator, count_allocations};
use a2perf_core::{Action, Env, Observation, RngStream, Step};
use a2perf_web::{WebNavConfig, WebNavEnv};

#[global_allocator]
static A: CountingAllocator = CountingAllocator;

#[test]
fn simulated_step_does_not_allocate() {
    assert_steps_do_not_allocate(WebNavEnv::new(WebNavConfig::new(3)).unwrap());
}

#[test]
fn simulated_step_with_a2perf_semantics_does_not_allocate() {
    // Every switch of the original but the pool (its design files are not shipped).
    let mut cfg = WebNavConfig::a2perf(3, "unused".into());
    cfg.designs_file = None;
    let pool = WebNavConfig::new(3).pool().unwrap();
    assert_steps_do_not_allocate(WebNavEnv::with_pool(pool, cfg, "alloc").unwrap());
}

fn assert_steps_do_not_allocate(mut env: WebNavEnv) {
    let mut obs = Observation::default();
    let mut step = Step::default();
    let mut rng = RngStream::new(0, "alloc");
    let mut legal = Vec::with_capacity(20_000);
    let (mut steps, mut counted) = (0, 0);
    for ep in 0..40 {
        env.reset_into(Some(ep), &mut obs).unwrap();
        for t in 0..25 {
            let a = if t % 3 == 2 {
                legal.clear();
                let mask = obs.action_mask.as_ref().unwrap();
                legal.extend((0..mask.len()).filter(|&i| mask[i]));
                legal[rng.index(legal.len())]
            } else {
                match env.oracle_action() {
                    Some(a) => a,
                    None => break,
                }
            };
            let action = Action::Discrete(a);
            let (n, r) = count_allocations(|| env.step_into(&action, &mut step));
            r.unwrap();
            // The first step of the first episode sizes the step's buffers.
            if ep > 0 || t > 0 {
                assert_eq!(n, 0, "episode {ep} step {t} allocated");
                counted += 1;
            }
            steps += 1;
            std::mem::swap(&mut obs, &mut step.observation);
            if step.done() {
                break;
            }
        }
    }
    assert!(counted > 200, "only {counted} of {steps} steps checked");
}
