//! Prints a backtrace for each heap allocation made during warmed-up env steps (DogPace, zero
//! actions): `cargo run --release -p a2perf-locomotion --example alloc_trace [STEPS]` (default 1).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use a2perf_core::{Action, Env, Observation, Step};
use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, MotionSource};
use a2perf_locomotion::gait::Gait;

struct Tracing;
static TRACE: AtomicBool = AtomicBool::new(false);
static COUNT: AtomicUsize = AtomicUsize::new(0);
thread_local! { static INSIDE: Cell<bool> = const { Cell::new(false) }; }

unsafe impl GlobalAlloc for Tracing {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if TRACE.load(Ordering::Relaxed) && !INSIDE.with(|c| c.replace(true)) {
            COUNT.fetch_add(1, Ordering::Relaxed);
            let bt = std::backtrace::Backtrace::force_capture();
            eprintln!("=== alloc {} bytes\n{bt}", l.size());
            INSIDE.with(|c| c.set(false));
        }
        unsafe { System.alloc(l) }
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        if TRACE.load(Ordering::Relaxed) && !INSIDE.with(|c| c.replace(true)) {
            COUNT.fetch_add(1, Ordering::Relaxed);
            let bt = std::backtrace::Backtrace::force_capture();
            eprintln!("=== realloc {} -> {n} bytes\n{bt}", l.size());
            INSIDE.with(|c| c.set(false));
        }
        unsafe { System.realloc(p, l, n) }
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) }
    }
}
#[global_allocator]
static GLOBAL: Tracing = Tracing;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let mut env =
        LocomotionEnv::new(EnvConfig::new("trace", MotionSource::Generated(Gait::Pace))).unwrap();
    let mut obs = Observation::default();
    env.reset_into(Some(0), &mut obs).unwrap();
    let action = Action::Continuous(vec![0.0; 12]);
    let mut step = Step::default();
    for _ in 0..5 {
        env.step_into(&action, &mut step).unwrap();
    }
    TRACE.store(true, Ordering::Relaxed);
    for _ in 0..n {
        env.step_into(&action, &mut step).unwrap();
    }
    TRACE.store(false, Ordering::Relaxed);
    println!(
        "{} allocations over {n} env steps",
        COUNT.load(Ordering::Relaxed)
    );
}
