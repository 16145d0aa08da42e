//! Knee joint friction: the simulation's velocity-motor model and its train-mode randomisation.

use a2perf_core::{Action, Env, Observation, Step};
use a2perf_locomotion::env::{EnvConfig, KNEE_FRICTION_RANGE, LocomotionEnv, Mode, MotionSource};
use a2perf_locomotion::gait::Gait;
use a2perf_locomotion::sim::Physics;
use a2perf_locomotion::{NUM_LEGS, RobotModel, RobotState, SimConfig, Simulation};

const ENGINES: [Physics; 2] = [Physics::Rapier, Physics::Articulated];

fn config(physics: Physics) -> SimConfig {
    SimConfig {
        physics,
        ..SimConfig::default()
    }
}
use nalgebra::Vector3;

/// FR knee velocity [rad/s] after `substeps` unactuated 1 ms steps, starting at the default pose
/// in the air with the FR knee turning at 3 rad/s, with the given friction on every knee.
fn knee_velocity_after(physics: Physics, friction: f64, substeps: usize) -> f64 {
    let model = RobotModel::builtin();
    let mut sim = Simulation::new(&model, config(physics));
    let mut state = RobotState {
        base_pos: Vector3::new(0.0, 0.0, 1.0),
        q: model.default_urdf_angles(),
        ..RobotState::default()
    };
    state.qd[2] = 3.0;
    sim.set_state(&state);
    sim.set_knee_friction([friction; NUM_LEGS]);
    assert_eq!(sim.knee_friction(), [friction; NUM_LEGS]);
    for _ in 0..substeps {
        sim.step_physics();
    }
    sim.joint_state().1[2]
}

#[test]
fn knee_friction_brakes_the_knee_and_a_large_one_stops_it() {
    for physics in ENGINES {
        knee_brakes(physics);
    }
}

fn knee_brakes(physics: Physics) {
    let free = knee_velocity_after(physics, 0.0, 5);
    let reference = knee_velocity_after(physics, 0.05, 5);
    let stopped = knee_velocity_after(physics, 1.0e4, 5);
    // Without friction the knee keeps turning (the leg is free in the air).
    assert!(free > 3.0, "{physics:?}: frictionless knee velocity {free}");
    // The reference's largest friction (0.05 N·m) acting for 5 ms on a lower leg whose
    // effective inertia about the knee is ~0.01 kg·m² takes off a few hundredths of a rad/s.
    let drop = free - reference;
    assert!(
        (0.01..0.1).contains(&drop),
        "{physics:?}: 0.05 N·m friction slowed the knee by {drop} rad/s"
    );
    // A bound far above the needed torque turns the motor into a velocity lock (soft: with one
    // solver iteration it converges over a few substeps).
    assert!(
        stopped.abs() < 0.2,
        "{physics:?}: stopped knee velocity {stopped}"
    );
}

#[test]
fn friction_only_acts_on_the_knees_it_is_set_on() {
    let model = RobotModel::builtin();
    let run = |physics: Physics, friction: [f64; NUM_LEGS]| {
        let mut sim = Simulation::new(&model, config(physics));
        let mut state = RobotState {
            base_pos: Vector3::new(0.0, 0.0, 1.0),
            q: model.default_urdf_angles(),
            ..RobotState::default()
        };
        for leg in 0..NUM_LEGS {
            state.qd[3 * leg + 2] = 3.0;
        }
        sim.set_state(&state);
        sim.set_knee_friction(friction);
        for _ in 0..5 {
            sim.step_physics();
        }
        sim.joint_state().1
    };
    for physics in ENGINES {
        let free = run(physics, [0.0; NUM_LEGS]);
        let qd = run(physics, [0.0, 1.0e4, 0.0, 0.0]);
        assert!(
            qd[5].abs() < 0.2,
            "{physics:?}: FL knee not stopped: {}",
            qd[5]
        );
        // The other knees keep turning: stopping one leg in the air moves the base a little,
        // which the other legs feel (1.5% articulated, 3% rapier), but no friction acts on them.
        for knee in [2, 8, 11] {
            assert!(
                free[knee] > 3.0,
                "{physics:?}: free knee {knee}: {}",
                free[knee]
            );
            assert!(
                (qd[knee] - free[knee]).abs() < 0.05 * free[knee],
                "{physics:?}: knee {knee} braked: {} against {}",
                qd[knee],
                free[knee]
            );
        }
    }
}

fn train_env(randomize: bool) -> LocomotionEnv {
    let mut cfg = EnvConfig::new("train", MotionSource::Generated(Gait::Pace));
    cfg.mode = Mode::Train;
    cfg.randomize = randomize;
    LocomotionEnv::new(cfg).unwrap()
}

#[test]
fn train_mode_randomises_knee_friction_within_the_reference_range() {
    let (lo, hi) = KNEE_FRICTION_RANGE;
    assert_eq!((lo, hi), (0.0, 0.05));
    let mut env = train_env(true);
    let mut obs = Observation::default();
    let mut seen = Vec::new();
    for seed in 0..20 {
        env.reset_into(Some(seed), &mut obs).unwrap();
        let f = env.sim().knee_friction();
        assert!(f.iter().all(|v| (lo..hi).contains(v)), "{f:?}");
        seen.extend(f);
    }
    // Independent per knee and per reset, spread over the range.
    let min = seen.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = seen.iter().cloned().fold(0.0, f64::max);
    assert!(min < 0.01 && max > 0.04, "range covered: [{min}, {max}]");
    let first = env.sim().knee_friction();
    assert!(first.iter().any(|v| *v != first[0]));

    // Same seed, same draw.
    env.reset_into(Some(3), &mut obs).unwrap();
    let a = env.sim().knee_friction();
    let mut other = train_env(true);
    other.reset_into(Some(3), &mut obs).unwrap();
    assert_eq!(a, other.sim().knee_friction());
}

#[test]
fn knee_friction_is_off_without_randomisation_and_changes_train_trajectories() {
    let mut plain = train_env(false);
    let mut obs = Observation::default();
    plain.reset_into(Some(1), &mut obs).unwrap();
    assert_eq!(plain.sim().knee_friction(), [0.0; NUM_LEGS]);

    let mut test =
        LocomotionEnv::new(EnvConfig::new("test", MotionSource::Generated(Gait::Pace))).unwrap();
    test.reset_into(Some(1), &mut obs).unwrap();
    assert_eq!(test.sim().knee_friction(), [0.0; NUM_LEGS]);

    // With friction present the same seeded rollout is deterministic.
    let rollout = || {
        let mut e = train_env(true);
        let mut obs = Observation::default();
        e.reset_into(Some(9), &mut obs).unwrap();
        let mut step = Step::default();
        let mut trace = Vec::new();
        for k in 0..15 {
            let a: Vec<f32> = (0..12).map(|j| 0.1 * ((k + j) as f32).cos()).collect();
            e.step_into(&Action::Continuous(a), &mut step).unwrap();
            trace.extend(step.observation.flat_values());
            if step.done() {
                break;
            }
        }
        trace
    };
    assert_eq!(rollout(), rollout());
}
