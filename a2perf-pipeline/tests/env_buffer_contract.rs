//! The observation-buffer contract of [`a2perf_core::Env`]: `reset_into`/`step_into` overwrite
//! every element of the observation (and the whole action mask) they are given, whatever the
//! buffers held before. The Python bindings rely on it: they hand the buffers of one step to
//! numpy without a copy and give the environment recycled buffers holding an older observation.
//!
//! Checked for every built-in environment that can be built from defaults: three instances with
//! the same seed and actions, one reusing its buffers (the normal path), one whose buffers are
//! poisoned (NaN floats, `int32` tensors turned into NaN `float32` ones, all-legal mask) before
//! every call, one given fresh empty buffers (`Env::step`), must agree bit for bit, element types
//! included.
//!
//! Also checked for every such environment: each observation lies in the declared observation
//! space (every tensor has its box's element type, shape and bounds).

use std::collections::BTreeMap;

use a2perf_core::{Action, DType, Env, Observation, RngStream, Space, Step, TensorData, Value};

/// Bit patterns of everything a step reports.
#[derive(Debug, PartialEq)]
struct Fingerprint {
    tensors: Vec<(String, Vec<usize>, DType, Vec<u64>)>,
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
                let mut bits = Vec::with_capacity(t.data.len());
                t.data.for_each_bits(|b| bits.push(b));
                (t.name.clone(), t.shape.clone(), t.dtype(), bits)
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
        // Floats become NaN; integer tensors become NaN floats, so the environment must also
        // restore the element type.
        t.data = TensorData::F32(vec![f32::NAN; t.data.len()]);
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
                !want.tensors.is_empty() && want.tensors.iter().all(|(.., d)| !d.is_empty()),
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

/// Why `obs` is not in `space`, naming the first tensor that is not in its box.
fn outside(space: &Space, obs: &Observation) -> Option<String> {
    let Space::Dict(items) = space else {
        return (!space.contains_observation(obs)).then(|| format!("{:?}", obs.tensors));
    };
    if obs.tensors.len() != items.len() {
        return Some(format!(
            "{} tensors for {} boxes",
            obs.tensors.len(),
            items.len()
        ));
    }
    items.iter().zip(&obs.tensors).find_map(|((name, b), t)| {
        let Space::Box { shape, dtype, .. } = b else {
            return Some(format!("`{name}` is not a box"));
        };
        (t.name != *name || !b.contains_tensor(t)).then(|| {
            format!(
                "tensor `{}` {} {:?} is not in box `{name}` {dtype} {shape:?} (or out of bounds)",
                t.name,
                t.dtype(),
                t.shape
            )
        })
    })
}

#[test]
fn every_observation_is_in_the_observation_space() {
    let reg = a2perf_pipeline::registry::full_registry();
    let mut checked = Vec::new();
    for entry in reg.envs() {
        let Ok(mut env) = reg.make_env(&entry.id, &BTreeMap::new()) else {
            continue;
        };
        let space = env.spec().observation_space.clone();
        let actions = env.spec().action_space.clone();
        let mut rng = RngStream::new(3, "dtype contract");
        let mut obs = env.reset(Some(5)).unwrap();
        for step in 0..6 {
            if let Some(why) = outside(&space, &obs) {
                panic!("{}, step {step}: {why}", entry.id);
            }
            let Some(action) = actions.sample(&mut rng, obs.action_mask.as_deref()) else {
                break;
            };
            let s = env.step(&action).unwrap();
            obs = if s.done() {
                env.reset(None).unwrap()
            } else {
                s.observation
            };
        }
        checked.push(entry.id.clone());
    }
    for domain in ["CircuitTraining", "QuadrupedLocomotion", "WebNavigation"] {
        assert!(
            checked.iter().any(|id| id.starts_with(domain)),
            "no {domain} environment was checked: {checked:?}"
        );
    }
}
