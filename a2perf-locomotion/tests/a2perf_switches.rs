//! Where A2Perf's locomotion environment (motion_imitation through gymnasium's compatibility
//! layer) signals an episode end differently, and the curriculum's step count.

use std::collections::BTreeMap;

use a2perf_core::{Action, Env, Registry, Value};
use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, Mode, MotionSource};
use a2perf_locomotion::gait;
use a2perf_locomotion::model::RobotModel;

/// Standing still on the default pose: no episode ends before the length limit.
fn standing(episode_steps: usize) -> EnvConfig {
    let clip = gait::standing_clip(&RobotModel::builtin());
    let mut cfg = EnvConfig::new("stand", MotionSource::Clip(clip));
    cfg.ref_state_init_prob = 1.0;
    cfg.episode_steps = episode_steps;
    cfg
}

/// Steps with zero actions until the episode ends; returns (steps, last step).
fn run_to_end(env: &mut LocomotionEnv) -> (usize, a2perf_core::Step) {
    for n in 1.. {
        let step = env.step(&Action::Continuous(vec![0.0; 12])).unwrap();
        if step.done() {
            return (n, step);
        }
    }
    unreachable!()
}

#[test]
fn time_limit_is_truncation_unless_a2perfs_termination_is_asked_for() {
    let mut ours = LocomotionEnv::new(standing(7)).unwrap();
    let mut cfg = standing(7);
    cfg.time_limit_terminates = true;
    let mut a2perf = LocomotionEnv::new(cfg).unwrap();
    ours.reset(Some(3)).unwrap();
    a2perf.reset(Some(3)).unwrap();
    let (n_ours, end_ours) = run_to_end(&mut ours);
    let (n_a2perf, end_a2perf) = run_to_end(&mut a2perf);
    assert_eq!((n_ours, n_a2perf), (7, 7));
    assert!(
        end_ours.truncated && !end_ours.terminated,
        "Gymnasium: truncated"
    );
    assert!(
        end_a2perf.terminated && !end_a2perf.truncated,
        "A2Perf: terminated"
    );
    assert_eq!(end_ours.reward, end_a2perf.reward);
    assert_eq!(end_ours.observation, end_a2perf.observation);
    assert_eq!(ours.last_termination(), None);
    assert_eq!(a2perf.last_termination(), None, "no termination rule fired");

    // The registered ids take the switch.
    let mut reg = Registry::new();
    a2perf_locomotion::register(&mut reg);
    let entry = reg.env("QuadrupedLocomotion-DogPace-v0").unwrap();
    let p = entry
        .params
        .iter()
        .find(|p| p.name == "time_limit_terminates")
        .expect("documented parameter");
    assert_eq!(p.default, Value::Bool(false));
    let mut params = BTreeMap::new();
    params.insert("episode_steps".to_string(), Value::Int(1));
    params.insert("time_limit_terminates".to_string(), Value::Bool(true));
    let mut env = reg
        .make_env("QuadrupedLocomotion-DogPace-v0", &params)
        .unwrap();
    env.reset(Some(0)).unwrap();
    let step = env.step(&Action::Continuous(vec![0.0; 12])).unwrap();
    assert!(step.terminated && !step.truncated);
}

#[test]
fn curriculum_counts_the_steps_that_do_not_end_an_episode() {
    // motion_imitation: `done |= time limit; if not done: total_step_count += 1`, then at reset
    // T = int((1 − s³)·20 + s³·600), s = count / curriculum_steps.
    let mut cfg = standing(600);
    cfg.mode = Mode::Train;
    cfg.randomize = false;
    cfg.curriculum_steps = 100.0;
    let mut env = LocomotionEnv::new(cfg).unwrap();
    env.reset(Some(0)).unwrap();
    assert_eq!(env.episode_limit(), 20);
    let (n, end) = run_to_end(&mut env);
    assert_eq!(n, 20);
    assert!(end.truncated);
    env.reset(None).unwrap();
    let limit = |count: f64| {
        let s3 = (count / 100.0f64).powi(3);
        ((1.0 - s3) * 20.0 + s3 * 600.0) as usize
    };
    // 19 counted steps (the 20th ended the episode), not 20.
    assert_eq!(limit(19.0), 23);
    assert_eq!(limit(20.0), 24);
    assert_eq!(env.episode_limit(), limit(19.0));
}
