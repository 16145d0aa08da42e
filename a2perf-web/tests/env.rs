//! Environment semantics on the simulated backend: contract, rewards, termination, masks,
//! determinism.

mod common;

use std::collections::BTreeMap;

use a2perf_core::{
    Action, DType, Env, EnvError, Observation, Registry, RngStream, Space, Step, Value,
};
use a2perf_web::site::{Behaviour, Tag};
use a2perf_web::{VOCAB_SIZE, WebNavConfig, WebNavEnv};
use common::slot;
use proptest::prelude::*;

fn env_with(pages: &[&[&str]]) -> WebNavEnv {
    common::env_on(pages, WebNavConfig::new(1))
}

#[test]
fn registered_ids_have_the_documented_contract() {
    let mut reg = Registry::new();
    a2perf_web::register(&mut reg);
    for level in 1..=3 {
        let id = format!("WebNavigation-Difficulty-0{level}-v0");
        let mut p = BTreeMap::new();
        p.insert("num_websites".to_string(), Value::Int(5));
        p.insert("seed".to_string(), Value::Int(3));
        let mut env = reg.make_env(&id, &p).unwrap();
        let spec = env.spec().clone();
        assert_eq!(spec.action_space, Space::Discrete { n: 250 * 25 * 2 });
        assert_eq!(spec.max_episode_steps, Some(25));
        assert_eq!(spec.metadata["vocab_size"], VOCAB_SIZE.to_string());
        let obs = env.reset(Some(0)).unwrap();
        let shapes: Vec<(&str, Vec<usize>)> = obs
            .tensors
            .iter()
            .map(|t| (t.name.as_str(), t.shape.clone()))
            .collect();
        assert_eq!(
            shapes,
            vec![
                ("profile_keys", vec![25, 10]),
                ("profile_values", vec![25, 10]),
                ("profile_mask", vec![25]),
                ("dom_tokens", vec![250, 5, 10]),
                ("dom_features", vec![250, 8]),
                ("dom_mask", vec![250]),
                ("time_step", vec![1]),
            ]
        );
        if let Space::Dict(items) = &spec.observation_space {
            assert_eq!(items.len(), 7);
        } else {
            panic!("observation space must be a dict");
        }
        assert_eq!(obs.action_mask.as_ref().unwrap().len(), 12_500);
    }
    let mut bad = BTreeMap::new();
    bad.insert("backend".to_string(), Value::Str("firefox".into()));
    assert!(
        reg.make_env("WebNavigation-Difficulty-01-v0", &bad)
            .is_err()
    );
    let mut bad = BTreeMap::new();
    bad.insert("num_websites".to_string(), Value::Int(0));
    assert!(
        reg.make_env("WebNavigation-Difficulty-01-v0", &bad)
            .is_err()
    );
    let mut bad = BTreeMap::new();
    bad.insert("pool".to_string(), Value::Str("a2perff".into()));
    let err = reg
        .make_env("WebNavigation-Difficulty-01-v0", &bad)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("did you mean `a2perf`"), "{err}");
    // The original's pool needs its design file, given by path.
    let mut bad = BTreeMap::new();
    bad.insert("pool".to_string(), Value::Str("a2perf".into()));
    let err = reg
        .make_env("WebNavigation-Difficulty-01-v0", &bad)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("designs") && err.contains("01.json"), "{err}");
    // Every switch is a documented parameter whose default is the corrected behaviour.
    let entry = reg.env("WebNavigation-Difficulty-01-v0").unwrap();
    let default = |name: &str| {
        let spec = entry.params.iter().find(|p| p.name == name).unwrap();
        assert!(!spec.doc.is_empty());
        spec.default.clone()
    };
    assert_eq!(default("pool"), Value::Str("generated".into()));
    assert_eq!(default("actions"), Value::Str("masked".into()));
    assert_eq!(default("cc_bug"), Value::Bool(false));
    assert_eq!(default("placeholders"), Value::Bool(true));
    assert_eq!(default("limit_terminates"), Value::Bool(false));
    assert_eq!(reg.generalization("web_navigation").len(), 5);
}

#[test]
fn rewards_follow_the_reference_formula() {
    let mut env = env_with(&[
        &["username", "password", "navbar", "header"],
        &["rememberme"],
    ]);
    env.reset(Some(1)).unwrap();
    let fields = env.website().fields.len();
    assert_eq!(fields, 3);
    // Clicking an id-less element changes nothing: −0.05 − 0.5.
    let label = slot(&env, |n| n.tag == Tag::H5);
    let s = env.step(&Action::Discrete(label * 50)).unwrap();
    assert!((s.reward + 0.55).abs() < 1e-12);
    // Typing the right value: +1/3 − 0.05.
    let a = env.oracle_action().unwrap();
    let s = env.step(&Action::Discrete(a)).unwrap();
    assert!((s.reward - (1.0 / 3.0 - 0.05)).abs() < 1e-12);
    // Typing it again: no change → −0.55.
    let s = env.step(&Action::Discrete(a)).unwrap();
    assert!((s.reward + 0.55).abs() < 1e-12);
    // Typing a wrong field value into a filled input loses the potential: −1/3 − 0.05.
    let (e, f, _) = env.decode_action(a);
    let wrong = (1..=fields).find(|&g| g != f).unwrap();
    let s = env
        .step(&Action::Discrete(env.action_index(e, wrong, 1)))
        .unwrap();
    assert!((s.reward - (-1.0 / 3.0 - 0.05)).abs() < 1e-12);
    // Distractor: −1 and the episode ends.
    let brand = slot(&env, |n| n.behaviour == Behaviour::Distractor);
    let s = env.step(&Action::Discrete(brand * 50)).unwrap();
    assert!(s.terminated && !s.truncated);
    assert!((s.reward + 1.0).abs() < 1e-12);
    assert_eq!(s.info.get("distractor"), Some(1.0));
    assert!(matches!(
        env.step(&Action::Discrete(0)),
        Err(EnvError::NeedsReset)
    ));
    // Submitting an incomplete form: −1.
    env.reset(Some(2)).unwrap();
    let next = slot(&env, |n| matches!(n.behaviour, Behaviour::Next(_)));
    let s = env.step(&Action::Discrete(next * 50)).unwrap();
    assert!((s.reward + 0.05).abs() < 1e-12, "{}", s.reward);
    let submit = slot(&env, |n| n.behaviour == Behaviour::Submit);
    let s = env.step(&Action::Discrete(submit * 50)).unwrap();
    assert!(s.terminated);
    assert!((s.reward + 1.0).abs() < 1e-12);
    assert_eq!(s.info.get("success"), Some(0.0));
}

#[test]
fn the_navbar_menu_opens_and_its_links_are_distractors() {
    let mut env = env_with(&[&["navbar", "city"]]);
    env.reset(Some(0)).unwrap();
    let before = env.dom().order.len();
    let toggler = slot(&env, |n| matches!(n.behaviour, Behaviour::Toggle(_)));
    let s = env.step(&Action::Discrete(toggler * 50)).unwrap();
    assert_eq!(env.dom().order.len(), before + 6);
    assert!((s.reward + 0.05).abs() < 1e-12);
    // Newly shown elements are flagged "new".
    let feats = s
        .observation
        .tensor("dom_features")
        .unwrap()
        .data
        .as_f32()
        .unwrap();
    let new_count = (0..250).filter(|e| feats[e * 8 + 2] == 1.0).count();
    assert_eq!(new_count, 6);
    let link = env
        .dom()
        .order
        .iter()
        .rposition(|&n| env.website().nodes[n as usize].text == "Checkout")
        .unwrap();
    let s = env.step(&Action::Discrete(link * 50)).unwrap();
    assert!(s.terminated && s.reward < -0.99);
}

#[test]
fn the_cc_radio_group_is_selectable() {
    let mut env = env_with(&[&["cc", "submit"]]);
    env.reset(Some(4)).unwrap();
    let a = env.oracle_action().unwrap();
    let s = env.step(&Action::Discrete(a)).unwrap();
    assert!((s.reward - 0.95).abs() < 1e-12);
    let a = env.oracle_action().unwrap();
    let s = env.step(&Action::Discrete(a)).unwrap();
    assert_eq!(s.info.get("success"), Some(1.0));
}

#[test]
fn the_step_limit_truncates() {
    let mut env = env_with(&[&["city", "header"]]);
    env.reset(Some(0)).unwrap();
    let h = slot(&env, |n| n.tag == Tag::H5);
    for t in 1..=25 {
        let s = env.step(&Action::Discrete(h * 50)).unwrap();
        assert_eq!(s.truncated, t == 25);
        assert!(!s.terminated);
    }
    assert!(env.step(&Action::Discrete(h * 50)).is_err());
}

#[test]
fn masks_allow_clicks_with_field_zero_and_typing_into_controls_only() {
    let mut env = env_with(&[&["username", "header", "state"]]);
    let obs = env.reset(Some(0)).unwrap();
    let mask = obs.action_mask.clone().unwrap();
    let n = env.dom().order.len();
    let fields = env.website().fields.len();
    for (a, &legal) in mask.iter().enumerate() {
        let (e, f, kind) = env.decode_action(a);
        let node = env
            .dom()
            .order
            .get(e)
            .map(|&i| &env.website().nodes[i as usize]);
        // Field 0 is `_dummy`: clicks use it, typing uses the website's fields 1..=fields.
        let expect = match (node, kind) {
            (None, _) => false,
            (Some(_), 0) => f == 0,
            (Some(nd), _) => nd.tag.is_control() && (1..=fields).contains(&f),
        };
        assert_eq!(legal, expect, "action {a}");
        assert_eq!(env.is_legal(a), expect);
    }
    assert!(n < 250);
    let dm = obs.tensor("dom_mask").unwrap().data.as_f32().unwrap();
    assert_eq!(dm.iter().filter(|&&x| x == 1.0).count(), n);
    let pm = obs.tensor("profile_mask").unwrap().data.as_f32().unwrap();
    assert_eq!(pm.iter().filter(|&&x| x == 1.0).count(), fields + 1);
    let masked = (0..mask.len()).find(|&a| !mask[a]).unwrap();
    assert!(matches!(
        env.step(&Action::Discrete(masked)),
        Err(EnvError::InvalidAction { .. })
    ));
}

#[test]
fn episodes_are_reproducible_from_the_seed() {
    let run = |seed: u64| {
        let mut env = WebNavEnv::new(WebNavConfig::new(2)).unwrap();
        let mut rng = RngStream::new(seed, "actions");
        let mut trace = Vec::new();
        let mut obs = env.reset(Some(seed)).unwrap();
        trace.push((env.pool_index(), obs.flat_values(), 0.0));
        for _ in 0..3 {
            for _ in 0..25 {
                let a = a2perf_core::Space::Discrete { n: 12_500 }
                    .sample(&mut rng, obs.action_mask.as_deref())
                    .unwrap();
                let s = env.step(&a).unwrap();
                trace.push((env.pool_index(), s.observation.flat_values(), s.reward));
                obs = s.observation;
                if s.terminated || s.truncated {
                    break;
                }
            }
            obs = env.reset(None).unwrap();
        }
        trace
    };
    assert_eq!(run(5), run(5));
    assert_ne!(run(5), run(6));
    let a = WebNavEnv::new(WebNavConfig::new(1)).unwrap();
    let b = WebNavEnv::new(WebNavConfig::new(1)).unwrap();
    assert_eq!(
        a.spec().metadata["pool_hash"],
        b.spec().metadata["pool_hash"]
    );
    let mut c = WebNavConfig::new(1);
    c.seed = 1;
    let c = WebNavEnv::new(c).unwrap();
    assert_ne!(
        a.spec().metadata["pool_hash"],
        c.spec().metadata["pool_hash"]
    );
}

#[test]
fn smaller_observation_sizes_are_respected() {
    let mut cfg = WebNavConfig::new(3);
    cfg.num_fields = 12;
    cfg.num_elements = 120;
    cfg.num_tokens = 4;
    cfg.num_websites = 20;
    let mut env = WebNavEnv::new(cfg).unwrap();
    assert_eq!(env.spec().action_space, Space::Discrete { n: 120 * 12 * 2 });
    for (i, d) in env.pool().iter().enumerate() {
        assert!(d.unique_active().len() <= 12, "website {i}");
    }
    for seed in 0..20 {
        env.reset(Some(seed)).unwrap();
        let mut ok = false;
        while let Some(a) = env.oracle_action() {
            let s = env.step(&Action::Discrete(a)).unwrap();
            if s.done() {
                ok = s.info.get("success") == Some(1.0);
                break;
            }
        }
        assert!(ok);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]
    #[test]
    fn random_play_keeps_observations_in_range(seed in 0u64..1_000_000, level in 1u8..=3) {
        let mut cfg = WebNavConfig::new(level);
        cfg.num_websites = 3;
        cfg.seed = seed % 7;
        let mut env = WebNavEnv::new(cfg).unwrap();
        let mut obs = Observation::default();
        let mut step = Step::default();
        env.reset_into(Some(seed), &mut obs).unwrap();
        let mut rng = RngStream::new(seed, "prop");
        for _ in 0..25 {
            let a = Space::Discrete { n: 12_500 }.sample(&mut rng, obs.action_mask.as_deref()).unwrap();
            env.step_into(&a, &mut step).unwrap();
            prop_assert!(step.reward >= -2.6 && step.reward <= 2.0);
            let phi = step.info.get("potential").unwrap();
            prop_assert!((0.0..=1.0).contains(&phi));
            let ts = step.observation.tensor("time_step").unwrap().data.as_f32().unwrap()[0];
            prop_assert_eq!(ts, env.steps() as f32 / 25.0);
            for t in step.observation.tensors.iter().filter(|t| t.name != "time_step") {
                let hi = if t.name.contains("tokens") || t.name.starts_with("profile_k") || t.name.starts_with("profile_v") {
                    (VOCAB_SIZE - 1) as f32
                } else {
                    1.0
                };
                let ids = ["profile_keys", "profile_values", "dom_tokens"].contains(&t.name.as_str());
                prop_assert_eq!(t.dtype(), if ids { DType::I32 } else { DType::F32 });
                let values = t.data.to_f32_vec();
                prop_assert!(values.iter().all(|&x| (0.0..=hi).contains(&x) && x.fract() == 0.0 || (t.name == "dom_features" && (0.0..=1.0).contains(&x))));
            }
            obs.copy_from(&step.observation);
            if step.done() {
                break;
            }
        }
    }
}
