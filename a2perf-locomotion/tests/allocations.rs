//! Heap allocations per environment step, counted by a per-thread counting global allocator.
//!
//! The crate's own step code allocates nothing. rapier3d 0.36.1 allocates inside
//! `PhysicsPipeline::step`, which no way of driving it through its public API avoids while the
//! PD torques stay explicit per-substep body torques (see the crate README, "Allocations"):
//! - 3 per substep: `RigidBodySet`'s modified-body list is moved out by every step, so the
//!   first `&mut` accesses to the 13 robot bodies (to set torques) regrow it (capacity 4, 8, 16);
//! - 1 per substep: `ImpulseJointSet::select_active_interactions` collects its candidate joints
//!   into a fresh `Vec`, because modifying a jointed body invalidates its memo;
//! - 1 per substep: the staged island solver's `StageSync::new` builds its per-worker cursor
//!   `Vec` on every solve, unconditionally;
//! - 1 per substep in which some contact begins or ends (narrow-phase transition list).
//!
//! The reduced-coordinate engine (`physics: articulated`) allocates nothing per step.
//!
//! These tests pin that budget, so that any allocation added to our per-step code (which would
//! come on top of rapier's) fails them, and print the measured figures.

use a2perf_core::alloc_count::{CountingAllocator, count_allocations};
use a2perf_core::{Action, Env, Observation, Step};
use a2perf_locomotion::env::{ACTION_REPEAT, EnvConfig, LocomotionEnv, Mode, MotionSource};
use a2perf_locomotion::gait::{self, Gait};
use a2perf_locomotion::sim::Physics;
use a2perf_locomotion::{RobotModel, SimConfig, Simulation};

#[global_allocator]
static GLOBAL: CountingAllocator = CountingAllocator;

/// Allocations (including reallocations) made on this thread by `f`.
fn count(f: impl FnOnce()) -> usize {
    count_allocations(f).0
}

/// rapier 0.36.1's floor per physics substep when body torques are set (see the module docs).
/// Builds with debug assertions add 3: rapier's `NarrowPhase::debug_validate_*` checks of its
/// solver contact graph, compiled only then.
const RAPIER_PER_SUBSTEP: usize = if cfg!(debug_assertions) { 8 } else { 5 };

/// Allocations per env step over `steps` zero-action steps after a warm-up, standing still on
/// the default pose (constant contacts, no episode end).
fn standing_allocations(physics: Physics, mode: Mode, randomize: bool, steps: usize) -> f64 {
    let clip = gait::standing_clip(&RobotModel::builtin());
    let mut cfg = EnvConfig::new("stand", MotionSource::Clip(clip));
    cfg.ref_state_init_prob = 1.0;
    cfg.mode = mode;
    cfg.randomize = randomize;
    cfg.episode_steps = 10_000;
    cfg.curriculum_steps = 1.0;
    cfg.physics = physics;
    let mut env = LocomotionEnv::new(cfg).unwrap();
    let mut obs = Observation::default();
    env.reset_into(Some(0), &mut obs).unwrap();
    let action = Action::Continuous(vec![0.0; 12]);
    let mut step = Step::default();
    // Train mode's curriculum ends the first episode after 20 steps; the next one is full length.
    for _ in 0..30 {
        env.step_into(&action, &mut step).unwrap();
        if step.done() {
            env.reset_into(None, &mut obs).unwrap();
        }
    }
    let n = count(|| {
        for _ in 0..steps {
            env.step_into(&action, &mut step).unwrap();
            assert!(!step.done(), "{:?}", env.last_termination());
        }
    });
    n as f64 / steps as f64
}

#[test]
fn env_step_allocates_only_rapiers_per_substep_floor() {
    let budget = (RAPIER_PER_SUBSTEP * ACTION_REPEAT) as f64;
    for (mode, randomize) in [(Mode::Test, false), (Mode::Train, true)] {
        let per_step = standing_allocations(Physics::Rapier, mode, randomize, 200);
        eprintln!("{mode:?}: {per_step:.2} allocations per env step (budget {budget})");
        assert!(per_step <= budget, "{mode:?}: {per_step} > {budget}");
    }
}

#[test]
fn the_articulated_engine_allocates_nothing_per_step() {
    for (mode, randomize) in [(Mode::Test, false), (Mode::Train, true)] {
        let per_step = standing_allocations(Physics::Articulated, mode, randomize, 200);
        assert_eq!(per_step, 0.0, "{mode:?}");
    }
    // Walking too: contacts beginning and ending, random actions, episode ends and resets.
    let mut cfg = EnvConfig::new("trot", MotionSource::Generated(Gait::Trot));
    cfg.physics = Physics::Articulated;
    let mut env = LocomotionEnv::new(cfg).unwrap();
    let mut obs = Observation::default();
    env.reset_into(Some(1), &mut obs).unwrap();
    let mut step = Step::default();
    // The first step sizes the step's buffers.
    env.step_into(&Action::Continuous(vec![0.0; 12]), &mut step)
        .unwrap();
    let actions: Vec<Action> = (0..60)
        .map(|k| Action::Continuous((0..12).map(|j| 0.3 * ((k * 5 + j) as f32).sin()).collect()))
        .collect();
    let n = count(|| {
        for a in &actions {
            env.step_into(a, &mut step).unwrap();
            if step.done() {
                break;
            }
        }
    });
    assert_eq!(n, 0);
}

#[test]
fn walking_adds_at_most_one_allocation_per_substep_for_contact_changes() {
    let mut env =
        LocomotionEnv::new(EnvConfig::new("trot", MotionSource::Generated(Gait::Trot))).unwrap();
    let mut obs = Observation::default();
    env.reset_into(Some(2), &mut obs).unwrap();
    let mut step = Step::default();
    let action = Action::Continuous(vec![0.0; 12]);
    env.step_into(&action, &mut step).unwrap();
    let mut steps = 0usize;
    let n = count(|| {
        for _ in 0..10 {
            env.step_into(&action, &mut step).unwrap();
            steps += 1;
            if step.done() {
                break;
            }
        }
    });
    let per_step = n as f64 / steps as f64;
    eprintln!("walking: {per_step:.2} allocations per env step over {steps} steps");
    assert!(per_step <= ((RAPIER_PER_SUBSTEP + 1) * ACTION_REPEAT) as f64);
}

#[test]
fn the_rapier_floor_is_in_the_physics_substep() {
    // One bare PD substep of the world (no env code) already costs the floor, which is what
    // the env step budget above is made of.
    let model = RobotModel::builtin();
    let mut sim = Simulation::new(&model, SimConfig::default());
    let target = model.default_motor_angles();
    for _ in 0..50 {
        sim.step_pd(&target);
    }
    let n = count(|| {
        for _ in 0..100 {
            sim.step_pd(&target);
        }
    });
    eprintln!("{:.2} allocations per physics substep", n as f64 / 100.0);
    assert!(n <= 100 * RAPIER_PER_SUBSTEP);
    assert!(
        n >= 100 * (RAPIER_PER_SUBSTEP - 1),
        "fewer allocations than expected: update the documented budget"
    );
}
