//! The simulated backend's step allocates nothing (counted with a global allocator).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use a2perf_core::{Action, Env, Observation, RngStream, Step};
use a2perf_web::{WebNavConfig, WebNavEnv};

struct Counting;
static ALLOCS: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(l) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.realloc(p, l, n) }
    }
}

#[global_allocator]
static A: Counting = Counting;

#[test]
fn simulated_step_does_not_allocate() {
    let mut env = WebNavEnv::new(WebNavConfig::new(3)).unwrap();
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
            let before = ALLOCS.load(Ordering::SeqCst);
            env.step_into(&action, &mut step).unwrap();
            let after = ALLOCS.load(Ordering::SeqCst);
            // The first step of the first episode sizes the step's buffers.
            if ep > 0 || t > 0 {
                assert_eq!(after, before, "episode {ep} step {t} allocated");
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
