//! Env steps/s (33 physics substeps each), reset time, raw physics substeps/s, and allocations
//! per env step (counting global allocator).

use std::hint::black_box;

use a2perf_core::alloc_count::{CountingAllocator, count_allocations};
use a2perf_core::{Action, Env, Observation, Step};
use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, Mode, MotionSource};
use a2perf_locomotion::gait::Gait;
use a2perf_locomotion::sim::Physics;
use a2perf_locomotion::{RobotModel, SimConfig, Simulation};
use criterion::{Criterion, criterion_group, criterion_main};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

fn make_with(physics: Physics, solver_iterations: usize, train: bool) -> LocomotionEnv {
    let mut cfg = EnvConfig::new(
        "QuadrupedLocomotion-DogPace-v0",
        MotionSource::Generated(Gait::Pace),
    );
    cfg.solver_iterations = solver_iterations;
    cfg.physics = physics;
    if train {
        // Domain randomisation (incl. the knee-friction motors), full-length episodes.
        cfg.mode = Mode::Train;
        cfg.randomize = true;
        cfg.curriculum_steps = 1.0;
    }
    LocomotionEnv::new(cfg).unwrap()
}

fn make(physics: Physics) -> LocomotionEnv {
    make_with(physics, SimConfig::default().solver_iterations, false)
}

fn allocations_per_step(physics: Physics) {
    let mut env = make(physics);
    let mut obs = Observation::default();
    env.reset_into(Some(0), &mut obs).unwrap();
    let action = Action::Continuous(vec![0.0; 12]);
    let mut step = Step::default();
    for _ in 0..5 {
        env.step_into(&action, &mut step).unwrap();
    }
    let mut steps = 0usize;
    let (n, ()) = count_allocations(|| {
        for _ in 0..50 {
            env.step_into(&action, &mut step).unwrap();
            steps += 1;
            if step.done() {
                break;
            }
        }
    });
    println!(
        "allocations ({}): {n} over {steps} env steps = {:.2}/env step ({:.3}/physics substep)",
        physics.name(),
        n as f64 / steps as f64,
        n as f64 / (steps * 33) as f64
    );
}

/// Nanoseconds this thread has spent on a CPU (Linux schedstat), to report speed independent of
/// how loaded the shared machine is; `None` elsewhere.
fn thread_cpu_ns() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn cpu_time_throughput(physics: Physics, solver_iterations: usize, random: bool, train: bool) {
    let mut env = make_with(physics, solver_iterations, train);
    let mut obs = Observation::default();
    env.reset_into(Some(0), &mut obs).unwrap();
    let mut rng = a2perf_core::RngStream::new(0, "bench-actions");
    let space = env.spec().action_space.clone();
    let mut action = Action::Continuous(vec![0.0; 12]);
    let mut step = Step::default();
    let n = 2000;
    let (Some(c0), w0) = (thread_cpu_ns(), std::time::Instant::now()) else {
        return;
    };
    for _ in 0..n {
        if random && let Some(a) = space.sample(&mut rng, None) {
            action = a;
        }
        env.step_into(&action, &mut step).unwrap();
        if step.done() {
            env.reset_into(None, &mut obs).unwrap();
        }
    }
    let cpu = (thread_cpu_ns().unwrap_or(c0) - c0) as f64 * 1e-9;
    let wall = w0.elapsed().as_secs_f64();
    println!(
        "env steps (DogPace, {}, {}, {} actions, resets included, {solver_iterations} solver iteration(s)): {:.0} per CPU-second ({:.0} substeps/CPU-s), {:.0} per wall-second",
        physics.name(),
        if train {
            "train mode + randomisation"
        } else {
            "test mode"
        },
        if random { "uniform random" } else { "zero" },
        n as f64 / cpu,
        n as f64 * 33.0 / cpu,
        n as f64 / wall
    );
}

fn benches(c: &mut Criterion) {
    for physics in [Physics::Rapier, Physics::Articulated] {
        allocations_per_step(physics);
        cpu_time_throughput(physics, 1, false, false);
        cpu_time_throughput(physics, 2, false, false);
        cpu_time_throughput(physics, 1, true, false);
        cpu_time_throughput(physics, 1, false, true);
    }
    let mut g = c.benchmark_group("locomotion");
    g.sample_size(20);
    for physics in [Physics::Rapier, Physics::Articulated] {
        // The rapier names stay as they were, so earlier baselines still compare.
        let suffix = match physics {
            Physics::Rapier => "",
            Physics::Articulated => "_articulated",
        };
        let mut env = make(physics);
        let mut obs = Observation::default();
        env.reset_into(Some(0), &mut obs).unwrap();
        let action = Action::Continuous(vec![0.0; 12]);
        let mut step = Step::default();
        g.bench_function(format!("env_step_dog_pace{suffix}"), |b| {
            b.iter(|| {
                env.step_into(black_box(&action), &mut step).unwrap();
                if step.done() {
                    env.reset_into(None, &mut obs).unwrap();
                }
            })
        });
        g.bench_function(format!("env_reset{suffix}"), |b| {
            b.iter(|| env.reset_into(None, &mut obs).unwrap())
        });
        let model = RobotModel::builtin();
        let config = SimConfig {
            physics,
            ..SimConfig::default()
        };
        let mut sim = Simulation::new(&model, config);
        let target = model.default_motor_angles();
        g.bench_function(format!("physics_substep_pd{suffix}"), |b| {
            b.iter(|| sim.step_pd(black_box(&target)))
        });
    }
    g.finish();
}

criterion_group!(group, benches);
criterion_main!(group);
