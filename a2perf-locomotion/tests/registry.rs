//! Registered ids, parameters, train mode and the HTML render.

use std::collections::BTreeMap;

use a2perf_core::{Action, Env, Registry, Space, Value};
use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, Mode, MotionSource};
use a2perf_locomotion::gait::Gait;
use a2perf_locomotion::render::{RenderPolicy, record_rollout, rollout_html};

fn registry() -> Registry {
    let mut reg = Registry::new();
    a2perf_locomotion::register(&mut reg);
    reg
}

#[test]
fn every_registered_task_builds_and_records_its_clip() {
    let reg = registry();
    for task in reg.generalization("quadruped_locomotion") {
        let mut env = reg.make_env(&task.env_id, &task.params).unwrap();
        let spec = env.spec().clone();
        assert_eq!(spec.observation_space.flat_dim(), 160, "{}", task.name);
        let Space::Box { low, high, .. } = &spec.action_space else {
            panic!("box expected")
        };
        assert_eq!(low.len(), 12);
        assert!((high[0] - f64::from(2.0 * std::f32::consts::PI)).abs() < 1e-6);
        assert!(spec.metadata["clip"].starts_with("gen_"));
        assert_eq!(spec.metadata["clip_hash"].len(), 16);
        assert_eq!(spec.max_episode_steps, Some(600));
        env.reset(Some(0)).unwrap();
        let step = env.step(&Action::Continuous(vec![0.0; 12])).unwrap();
        assert!(step.reward.is_finite());
    }
    let names: Vec<_> = reg
        .generalization("quadruped_locomotion")
        .iter()
        .map(|t| t.name.clone())
        .collect();
    assert_eq!(
        names,
        [
            "dog_pace",
            "dog_trot",
            "dog_spin",
            "bound",
            "pronk",
            "side_step",
            "turn"
        ]
    );
}

#[test]
fn bad_parameters_are_errors() {
    let reg = registry();
    let mut p = BTreeMap::new();
    p.insert("mode".to_string(), Value::Str("evaluate".into()));
    assert!(reg.make_env("QuadrupedLocomotion-DogPace-v0", &p).is_err());
    let mut p = BTreeMap::new();
    p.insert(
        "motion_file".to_string(),
        Value::Str("/nonexistent/clip.txt".into()),
    );
    let err = reg
        .make_env("QuadrupedLocomotion-DogPace-v0", &p)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("/nonexistent/clip.txt"), "{err}");
    let mut p = BTreeMap::new();
    p.insert("gait".to_string(), Value::Str("gallop".into()));
    assert!(reg.make_env("QuadrupedLocomotion-Gait-v0", &p).is_err());
}

#[test]
fn train_mode_uses_the_curriculum_and_randomises_deterministically() {
    let mut cfg = EnvConfig::new("t", MotionSource::Generated(Gait::Trot));
    cfg.mode = Mode::Train;
    cfg.randomize = true;
    let run = |cfg: EnvConfig| {
        let mut env = LocomotionEnv::new(cfg).unwrap();
        let mut rewards = Vec::new();
        env.reset(Some(11)).unwrap();
        assert_eq!(env.episode_limit(), 20, "curriculum starts at 20 steps");
        for _ in 0..25 {
            let s = env.step(&Action::Continuous(vec![0.0; 12])).unwrap();
            rewards.push(s.reward);
            if s.done() {
                env.reset(None).unwrap();
            }
        }
        rewards
    };
    assert_eq!(run(cfg.clone()), run(cfg));
}

#[test]
fn render_writes_a_self_contained_animation() {
    let mut env =
        LocomotionEnv::new(EnvConfig::new("x", MotionSource::Generated(Gait::Spin))).unwrap();
    let r = record_rollout(&mut env, RenderPolicy::Reference, 10, 3).unwrap();
    assert!(r.frames.len() >= 2);
    assert_eq!(
        r.frames[0].robot.len(),
        a2perf_locomotion::render::POINTS_PER_ROBOT
    );
    let html = rollout_html(&r);
    assert!(html.starts_with("<!DOCTYPE html>"));
    assert!(html.contains("const ROBOT=") && html.contains("const REF="));
    assert!(!html.contains("src=\"http") && !html.contains("href=\"http"));
}
