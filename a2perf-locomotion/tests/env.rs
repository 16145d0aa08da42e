//! Behaviour of the imitation environment: reward check, standing check, terminations,
//! determinism.

use a2perf_core::{Action, Env, Observation, Step};
use a2perf_locomotion::RobotModel;
use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, MotionSource, OBS_DIM, Termination};
use a2perf_locomotion::gait::Gait;
use a2perf_locomotion::sim::Physics;
use nalgebra::{UnitQuaternion, Vector3};

/// The behaviour tests run on both engines.
const ENGINES: [Physics; 2] = [Physics::Rapier, Physics::Articulated];

fn env(gait: Gait) -> LocomotionEnv {
    env_on(gait, Physics::Rapier)
}

fn env_on(gait: Gait, physics: Physics) -> LocomotionEnv {
    let mut cfg = EnvConfig::new("test", MotionSource::Generated(gait));
    cfg.physics = physics;
    LocomotionEnv::new(cfg).unwrap()
}

#[test]
fn state_equal_to_reference_scores_one_on_every_term() {
    for g in [Gait::Pace, Gait::Trot, Gait::Spin] {
        let mut e = env(g);
        e.reset(Some(3)).unwrap();
        let t = e.reference_time() + 0.2;
        let s = e.reference_state(t);
        e.set_robot_state(&s);
        let r = e.reward_terms(t);
        for (name, v) in [
            ("pose", r.pose),
            ("velocity", r.velocity),
            ("end_effector", r.end_effector),
            ("root_pose", r.root_pose),
            ("root_velocity", r.root_velocity),
        ] {
            assert!((v - 1.0).abs() < 1e-4, "{g:?} {name} = {v}");
        }
        assert!((r.total() - 1.0).abs() < 1e-4);
    }
}

#[test]
fn reward_terms_drop_when_the_state_differs() {
    let mut e = env(Gait::Pace);
    e.reset(Some(3)).unwrap();
    let t = e.reference_time();
    let mut s = e.reference_state(t);
    s.q[1] += 0.3;
    s.base_pos.x += 0.1;
    e.set_robot_state(&s);
    let r = e.reward_terms(t);
    assert!(
        r.pose < 0.7 && r.root_pose < 0.9 && r.end_effector < 0.99,
        "{r:?}"
    );
}

#[test]
fn default_pose_with_zero_actions_stays_up_for_100_steps() {
    // Reference = standing still in the default pose, so only a fall can end the episode.
    for physics in ENGINES {
        stays_up(physics);
    }
}

fn stays_up(physics: Physics) {
    let clip = a2perf_locomotion::gait::standing_clip(&RobotModel::builtin());
    let mut cfg = EnvConfig::new("stand", MotionSource::Clip(clip));
    cfg.ref_state_init_prob = 1.0;
    cfg.physics = physics;
    let mut e = LocomotionEnv::new(cfg).unwrap();
    e.reset(Some(0)).unwrap();
    let z0 = e.sim().state().base_pos.z;
    let mut step = Step::default();
    for i in 0..120 {
        e.step_into(&Action::Continuous(vec![0.0; 12]), &mut step)
            .unwrap();
        let s = e.sim().state();
        assert!(
            !step.done(),
            "{physics:?}: episode ended at step {i}: {:?}",
            e.last_termination()
        );
        assert!(
            (s.base_pos.z - z0).abs() < 0.05,
            "{physics:?}: sagged at step {i}: z = {}",
            s.base_pos.z
        );
        let up = s.base_rot * Vector3::z();
        assert!(up.z > 0.99, "{physics:?}: tipped at step {i}");
        assert!(
            !e.sim().ground_contacts().1,
            "{physics:?}: body touched the ground at step {i}"
        );
        assert!(
            e.sim().toe_contacts().iter().all(|c| *c),
            "{physics:?}: a toe left the ground at step {i}"
        );
    }
    // Standing still on the reference scores high.
    assert!(step.reward > 0.8, "{physics:?}: reward {}", step.reward);
}

#[test]
fn body_contact_terminates() {
    for physics in ENGINES {
        belly_landing_terminates(physics);
    }
}

fn belly_landing_terminates(physics: Physics) {
    let mut e = env_on(Gait::Trot, physics);
    e.reset(Some(1)).unwrap();
    let t = e.reference_time();
    let mut s = e.reference_state(t);
    // Drop the robot onto its belly (legs in the ground: each engine pushes them out at its own
    // pace, so how soon the robot is up again differs).
    s.base_pos.z = 0.1;
    e.set_robot_state(&s);
    let mut step = Step::default();
    e.step_into(&Action::Continuous(vec![0.0; 12]), &mut step)
        .unwrap();
    // The first step skips the contact check, as in the reference; the belly's contact is seen
    // and the rule ends the episode on it.
    assert!(!step.terminated, "{physics:?}");
    assert!(e.sim().ground_contacts().1, "{physics:?}");
    assert_eq!(
        e.termination(e.reference_time(), true),
        Some(Termination::BodyContact),
        "{physics:?}"
    );
}

#[test]
fn root_position_and_rotation_errors_terminate() {
    let mut e = env(Gait::Pace);
    e.reset(Some(2)).unwrap();
    let t = e.reference_time();
    let mut s = e.reference_state(t);
    s.base_pos.x += 1.1;
    e.set_robot_state(&s);
    assert_eq!(e.termination(t, false), Some(Termination::RootPosition));
    let mut s = e.reference_state(t);
    s.base_pos.x += 0.9;
    e.set_robot_state(&s);
    assert_eq!(e.termination(t, false), None);

    let mut s = e.reference_state(t);
    s.base_rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.7) * s.base_rot;
    e.set_robot_state(&s);
    assert_eq!(e.termination(t, false), Some(Termination::RootRotation));
    let mut s = e.reference_state(t);
    s.base_rot = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.4) * s.base_rot;
    e.set_robot_state(&s);
    assert_eq!(e.termination(t, false), None);
}

fn rollout(physics: Physics, seed: u64, steps: usize) -> Vec<f32> {
    let mut e = env_on(Gait::Trot, physics);
    let mut obs = Observation::default();
    e.reset_into(Some(seed), &mut obs).unwrap();
    let mut trace = obs.flat_values();
    let mut step = Step::default();
    for k in 0..steps {
        let a: Vec<f32> = (0..12).map(|j| 0.1 * ((k + j) as f32).sin()).collect();
        e.step_into(&Action::Continuous(a), &mut step).unwrap();
        trace.extend(step.observation.flat_values());
        trace.push(step.reward as f32);
        if step.done() {
            e.reset_into(None, &mut obs).unwrap();
        }
    }
    trace
}

#[test]
fn same_seed_gives_the_same_trajectory() {
    for physics in ENGINES {
        let a = rollout(physics, 7, 30);
        let b = rollout(physics, 7, 30);
        assert_eq!(a, b, "{physics:?}");
        let c = rollout(physics, 8, 30);
        assert_ne!(a, c, "{physics:?}");
    }
    assert_ne!(
        rollout(Physics::Rapier, 7, 30),
        rollout(Physics::Articulated, 7, 30)
    );
}

/// Observation and reward bits of an episode of `steps` steps after `reset(seed)`.
fn episode_bits(e: &mut LocomotionEnv, seed: u64, steps: usize) -> Vec<u32> {
    let mut obs = Observation::default();
    e.reset_into(Some(seed), &mut obs).unwrap();
    let mut bits: Vec<u32> = obs.flat_values().iter().map(|v| v.to_bits()).collect();
    let mut step = Step::default();
    for k in 0..steps {
        let a: Vec<f32> = (0..12).map(|j| 0.2 * ((3 * k + j) as f32).cos()).collect();
        e.step_into(&Action::Continuous(a), &mut step).unwrap();
        bits.extend(step.observation.flat_values().iter().map(|v| v.to_bits()));
        bits.push((step.reward as f32).to_bits());
        if step.done() {
            break;
        }
    }
    bits
}

#[test]
fn an_episode_depends_only_on_its_seed_and_actions() {
    // Resumed training rebuilds an environment's state by replaying its episode on a fresh
    // environment, so what ran before in the same environment must not leak into an episode.
    for physics in ENGINES {
        let mut fresh = env_on(Gait::Pace, physics);
        let want = episode_bits(&mut fresh, 41, 25);
        let mut used = env_on(Gait::Pace, physics);
        for s in 0..3 {
            episode_bits(&mut used, s, 60);
        }
        assert_eq!(episode_bits(&mut used, 41, 25), want, "{physics:?}");
    }
}

#[test]
fn observation_layout_after_reset() {
    let mut e = env(Gait::Spin);
    let obs = e.reset(Some(4)).unwrap();
    let t = obs.tensor("obs").unwrap();
    assert_eq!(t.shape, vec![OBS_DIM]);
    let d = t.data.as_f32().unwrap();
    // Reset quirk: histories show the default pose, zero IMU and zero last action.
    assert!(d[0..12].iter().all(|v| v.abs() < 1e-6));
    assert!(d[12..48].iter().all(|v| *v == 0.0));
    for k in 0..3 {
        let m = &d[48 + 12 * k..60 + 12 * k];
        assert!(
            (m[1] - 0.67).abs() < 1e-5 && (m[2] + 1.25).abs() < 1e-5,
            "{m:?}"
        );
    }
    // Target frames: unit quaternions with w >= 0.
    for k in 0..4 {
        let f = &d[84 + 19 * k..84 + 19 * (k + 1)];
        let n: f32 = f[3..7].iter().map(|v| v * v).sum();
        assert!((n - 1.0).abs() < 1e-4 && f[6] >= 0.0);
    }
    assert!(e.spec().observation_space.flat_dim() == OBS_DIM);
}

#[test]
fn invalid_actions_are_errors() {
    let mut e = env(Gait::Pace);
    assert!(
        e.step(&Action::Continuous(vec![0.0; 12])).is_err(),
        "step before reset"
    );
    e.reset(Some(0)).unwrap();
    assert!(e.step(&Action::Continuous(vec![0.0; 11])).is_err());
    assert!(e.step(&Action::Continuous(vec![f32::NAN; 12])).is_err());
    assert!(e.step(&Action::Discrete(0)).is_err());
}

#[test]
fn impulse_joints_stay_together_during_a_rollout() {
    // Default settings: 1 solver iteration per 1 ms step. Measured worst case here is ~1.8 mm
    // (2 iterations: ~0.3 mm).
    let mut e = env(Gait::Trot);
    e.reset(Some(5)).unwrap();
    assert!(e.sim().max_joint_error() < 1e-5);
    let mut step = Step::default();
    let mut worst = 0.0f64;
    for k in 0..60 {
        let a: Vec<f32> = (0..12)
            .map(|j| 0.3 * ((k * 3 + j) as f32 * 0.7).sin())
            .collect();
        e.step_into(&Action::Continuous(a), &mut step).unwrap();
        worst = worst.max(e.sim().max_joint_error());
        if step.done() {
            e.reset(None).unwrap();
        }
    }
    assert!(worst < 2.5e-3, "joint separation {worst} m");
    eprintln!("max joint separation over the rollout: {worst:.2e} m");
}

/// Every observation lies in the declared space: from a warmup start (negative reference time,
/// the default pose as target), from a random phase of the clip, and across the resets random
/// actions lead to, for every built-in gait.
#[test]
fn observations_stay_in_the_space_from_warmup_through_the_clip() {
    for (gait, physics) in Gait::ALL.into_iter().flat_map(|g| ENGINES.map(|p| (g, p))) {
        for warmup in [true, false] {
            let mut cfg = EnvConfig::new("test", MotionSource::Generated(gait));
            cfg.ref_state_init_prob = if warmup { 0.0 } else { 1.0 };
            cfg.physics = physics;
            let mut e = LocomotionEnv::new(cfg).unwrap();
            let space = e.spec().observation_space.clone();
            let actions = e.spec().action_space.clone();
            let a2perf_core::Space::Box { low, high, .. } = &space else {
                panic!("box expected")
            };
            let (low, high) = (low.clone(), high.clone());
            let mut rng = a2perf_core::RngStream::new(4, "observation bounds");
            for seed in 0..3 {
                let mut obs = e.reset(Some(seed)).unwrap();
                for step in 0..40 {
                    let d = obs.tensor("obs").unwrap();
                    if !space.contains_observation(&obs) {
                        let i = (0..low.len())
                            .find(|&i| {
                                let x = d.data.get_f64(i).unwrap();
                                !(x >= low[i] && x <= high[i])
                            })
                            .unwrap_or(usize::MAX);
                        panic!(
                            "{} on {physics:?} (warmup start: {warmup}), seed {seed}, step {step}: \
                             element {i} = {:?} outside [{:?}, {:?}]",
                            gait.name(),
                            d.data.get_f64(i),
                            low.get(i),
                            high.get(i)
                        );
                    }
                    let s = e.step(&actions.sample(&mut rng, None).unwrap()).unwrap();
                    obs = if s.done() {
                        e.reset(None).unwrap()
                    } else {
                        s.observation
                    };
                }
            }
        }
    }
}
