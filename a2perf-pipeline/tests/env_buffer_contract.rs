//! The observation-buffer contract of [`a2perf_core::Env`]: `reset_into`/`step_into` overwrite
//! every element of the observation (and the whole action mask) they are given, whatever the
//! buffers held before. The Python bindings rely on it: they hand the buffers of one step to
//! numpy without a copy and give the environment recycled buffers holding an older observation.
//!
//! Checked for every built-in environment that can be built from defaults: three instances with
//! the same seed and actions, one reusing its buffers (the normal path), one whose buffers are
//! poisoned (NaN, all-legal mask) before every call, one given fresh empty buffers (`Env::step`),
//! must agree bit for bit.

use std::collections::BTreeMap;

use a2perf_core::{Action, Env, Observation, RngStream, Step, Value};

/// Bit patterns of everything a step reports.
#[derive(Debug, PartialEq)]
struct Fingerprint {
    tensors: Vec<(String, Vec<usize>, Vec<u32>)>,
    mask: Option<Vec<bool>>,
    reward: u64,
    terminated: bool,
    truncated: bool,
    info: String,
}

fn fingerprint(step: &Step) -> Fingerprint {
    Fingerprint {
        tensors: step
            .observation
            .tensors
            .iter()
            .map(|t| {
                (
                    t.name.clone(),
                    t.shape.clone(),
                    t.data.iter().map(|x| x.to_bits()).collect(),
                )
            })
            .collect(),
        mask: step.observation.action_mask.clone(),
        reward: step.reward.to_bits(),
        terminated: step.terminated,
        truncated: step.truncated,
        info: format!("{:?}", step.info),
    }
}

fn poison(obs: &mut Observation) {
    for t in &mut obs.tensors {
        t.data.fill(f32::NAN);
    }
    if let Some(m) = &mut obs.action_mask {
        m.fill(true);
    }
}

/// Environment ids whose defaults need no files (the file-backed circuit ids are skipped).
type Instances = (String, Box<dyn Env>, Box<dyn Env>, Box<dyn Env>);

fn buildable() -> Vec<Instances> {
    let reg = a2perf_pipeline::registry::full_registry();
    let mut out = Vec::new();
    for entry in reg.envs() {
        let params = BTreeMap::<String, Value>::new();
        let make = || reg.make_env(&entry.id, &params);
        match (make(), make(), make()) {
            (Ok(a), Ok(b), Ok(c)) => out.push((entry.id.clone(), a, b, c)),
            (Err(e), _, _) => eprintln!("skipping {}: needs files ({e})", entry.id),
            _ => panic!("{} built once but not twice", entry.id),
        }
    }
    out
}

#[test]
fn every_environment_overwrites_its_whole_observation() {
    let envs = buildable();
    let ids: Vec<&str> = envs.iter().map(|(id, ..)| id.as_str()).collect();
    for domain in ["CircuitTraining", "QuadrupedLocomotion", "WebNavigation"] {
        assert!(
            ids.iter().any(|id| id.starts_with(domain)),
            "no {domain} environment was checked: {ids:?}"
        );
    }
    for (id, mut reused, mut poisoned, mut fresh) in envs {
        let space = reused.spec().action_space.clone();
        let mut rng = RngStream::new(7, "buffer contract");
        let (mut s_reused, mut s_poisoned) = (Step::default(), Step::default());
        let mut episode_seed = 11;
        let mut needs_reset = true;
        let mut steps = 0;
        // Long enough for several episodes of the short-episode ids (circuit: one step per
        // macro) and for the web and locomotion ids to leave their first state.
        while steps < 40 {
            let s_fresh = if needs_reset {
                reused
                    .reset_into(Some(episode_seed), &mut s_reused.observation)
                    .unwrap();
                poison(&mut s_poisoned.observation);
                poisoned
                    .reset_into(Some(episode_seed), &mut s_poisoned.observation)
                    .unwrap();
                episode_seed += 1;
                needs_reset = false;
                for s in [&mut s_reused, &mut s_poisoned] {
                    s.reward = 0.0;
                    s.terminated = false;
                    s.truncated = false;
                    s.info.clear();
                }
                Step {
                    observation: fresh.reset(Some(episode_seed - 1)).unwrap(),
                    ..Step::default()
                }
            } else {
                let action: Action = space
                    .sample(&mut rng, s_reused.observation.action_mask.as_deref())
                    .unwrap_or_else(|| panic!("{id}: no legal action"));
                reused.step_into(&action, &mut s_reused).unwrap();
                poison(&mut s_poisoned.observation);
                poisoned.step_into(&action, &mut s_poisoned).unwrap();
                steps += 1;
                needs_reset = s_reused.done();
                fresh.step(&action).unwrap()
            };
            let want = fingerprint(&s_reused);
            assert!(
                !want.tensors.is_empty() && want.tensors.iter().all(|(_, _, d)| !d.is_empty()),
                "{id}: empty observation"
            );
            assert_eq!(
                fingerprint(&s_poisoned),
                want,
                "{id}, step {steps}: the observation depends on what its buffers held"
            );
            assert_eq!(
                fingerprint(&s_fresh).tensors,
                want.tensors,
                "{id}, step {steps}: fresh buffers give another observation"
            );
            assert_eq!(
                s_fresh.observation.action_mask,
                s_reused.observation.action_mask
            );
        }
    }
}
