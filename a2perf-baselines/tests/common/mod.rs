//! Toy environments that prove the algorithms without the domains.
#![allow(dead_code)]

use std::collections::BTreeMap;

use a2perf_core::{
    Action, Algorithm, CancelToken, DType, DiscardCheckpoints, Env, EnvError, EnvSpec,
    LearningCurve, Observation, Policy, RngStream, Space, Step, Tensor, TrainingContext,
    TrainingSettings, Value,
};

/// One-step contextual bandit with masks: 4 contexts (one-hot), 6 arms; in context c, arms
/// `c` and `c+1` are illegal and arm `(c + 3) % 6` pays 1, every other legal arm 0.
pub struct MaskedBandit {
    spec: EnvSpec,
    ctx: usize,
    rng: RngStream,
}

impl MaskedBandit {
    pub fn new() -> Self {
        Self {
            spec: EnvSpec {
                id: "MaskedBandit-v0".into(),
                observation_space: Space::uniform_box(&[4], 0.0, 1.0),
                action_space: Space::Discrete { n: 6 },
                max_episode_steps: Some(1),
                metadata: BTreeMap::new(),
            },
            ctx: 0,
            rng: RngStream::new(0, "bandit"),
        }
    }
    pub fn best(ctx: usize) -> usize {
        (ctx + 3) % 6
    }
    fn write(&self, obs: &mut Observation) {
        let mut v = vec![0.0; 4];
        v[self.ctx] = 1.0;
        *obs = Observation::flat(v);
        let mut mask = vec![true; 6];
        mask[self.ctx] = false;
        mask[self.ctx + 1] = false;
        obs.action_mask = Some(mask);
    }
}

impl Env for MaskedBandit {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        if let Some(s) = seed {
            self.rng = RngStream::new(s, "bandit");
        }
        self.ctx = self.rng.index(4);
        self.write(obs);
        Ok(())
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        let Action::Discrete(a) = *action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "discrete".into(),
            });
        };
        if a == self.ctx || a == self.ctx + 1 || a >= 6 {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "masked".into(),
            });
        }
        out.reward = if a == Self::best(self.ctx) { 1.0 } else { 0.0 };
        out.terminated = true;
        out.truncated = false;
        out.info.clear();
        self.write(&mut out.observation);
        Ok(())
    }
}

/// 4×4 gridworld: start (0,0), goal (3,3), actions up/down/left/right, one-hot position,
/// −0.01 per step, +1 at the goal, 20-step limit.
pub struct Grid {
    spec: EnvSpec,
    pos: (i32, i32),
}

impl Grid {
    pub fn new() -> Self {
        Self {
            spec: EnvSpec {
                id: "Grid-v0".into(),
                observation_space: Space::uniform_box(&[16], 0.0, 1.0),
                action_space: Space::Discrete { n: 4 },
                max_episode_steps: Some(20),
                metadata: BTreeMap::new(),
            },
            pos: (0, 0),
        }
    }
    fn write(&self, obs: &mut Observation) {
        let mut v = vec![0.0; 16];
        v[(self.pos.0 * 4 + self.pos.1) as usize] = 1.0;
        *obs = Observation::flat(v);
    }
}

impl Env for Grid {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }
    fn reset_into(&mut self, _seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        self.pos = (0, 0);
        self.write(obs);
        Ok(())
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        let Action::Discrete(a) = *action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "discrete".into(),
            });
        };
        let (dr, dc) = [(-1, 0), (1, 0), (0, -1), (0, 1)][a.min(3)];
        self.pos = ((self.pos.0 + dr).clamp(0, 3), (self.pos.1 + dc).clamp(0, 3));
        let goal = self.pos == (3, 3);
        out.reward = if goal { 1.0 } else { -0.01 };
        out.terminated = goal;
        out.truncated = false;
        out.info.clear();
        self.write(&mut out.observation);
        Ok(())
    }
}

/// 1-D point: x' = x + 0.25·a, a ∈ [−1, 1], reward −x², start x ∈ [−1, 1], 20 steps.
pub struct Point {
    spec: EnvSpec,
    x: f32,
    rng: RngStream,
}

impl Point {
    pub fn new() -> Self {
        Self {
            spec: EnvSpec {
                id: "Point-v0".into(),
                observation_space: Space::uniform_box(&[1], -5.0, 5.0),
                action_space: Space::uniform_box(&[1], -1.0, 1.0),
                max_episode_steps: Some(20),
                metadata: BTreeMap::new(),
            },
            x: 0.0,
            rng: RngStream::new(0, "point"),
        }
    }
}

impl Env for Point {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        if let Some(s) = seed {
            self.rng = RngStream::new(s, "point");
        }
        self.x = self.rng.range(-1.0, 1.0) as f32;
        *obs = Observation::flat(vec![self.x]);
        Ok(())
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        let Action::Continuous(a) = action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "box".into(),
            });
        };
        let a = a.first().copied().unwrap_or(0.0).clamp(-1.0, 1.0);
        self.x = (self.x + 0.25 * a).clamp(-5.0, 5.0);
        out.reward = -f64::from(self.x * self.x);
        out.terminated = false;
        out.truncated = false;
        out.info.clear();
        match out
            .observation
            .tensors
            .first_mut()
            .and_then(|t| t.data.as_f32_mut())
        {
            Some(d) => d[0] = self.x,
            None => out.observation = Observation::flat(vec![self.x]),
        }
        Ok(())
    }
}

/// A tiny web-shaped environment (contract tensors) for gradient checks and smoke tests:
/// F fields, E elements, T tokens. The right action is "type field f into element f".
pub struct MiniWeb {
    spec: EnvSpec,
    pub f: usize,
    pub e: usize,
    pub t: usize,
    rng: RngStream,
    filled: Vec<bool>,
    steps: usize,
}

impl MiniWeb {
    pub fn new(f: usize, e: usize, t: usize) -> Self {
        let mut metadata = BTreeMap::new();
        metadata.insert("vocab_size".to_string(), "20".to_string());
        let b = |s: &[usize]| Space::uniform_box(s, 0.0, 20.0);
        let ids = |s: &[usize]| Space::uniform_box_of(s, DType::I32, 0.0, 19.0);
        Self {
            spec: EnvSpec {
                id: "MiniWeb-v0".into(),
                observation_space: Space::Dict(vec![
                    ("profile_keys".into(), ids(&[f, t])),
                    ("profile_values".into(), ids(&[f, t])),
                    ("profile_mask".into(), b(&[f])),
                    ("dom_tokens".into(), ids(&[e, 5, t])),
                    ("dom_features".into(), b(&[e, 8])),
                    ("dom_mask".into(), b(&[e])),
                ]),
                action_space: Space::Discrete { n: e * f * 2 },
                max_episode_steps: Some(2 * f),
                metadata,
            },
            f,
            e,
            t,
            rng: RngStream::new(0, "miniweb"),
            filled: vec![false; f],
            steps: 0,
        }
    }

    pub fn observation(&self, rng: &mut RngStream) -> Observation {
        let (f, e, t) = (self.f, self.e, self.t);
        let mut tok = |n: usize| -> Vec<i32> {
            (0..n)
                .map(|i| {
                    if i % t < 2 {
                        (1 + rng.index(19)) as i32
                    } else {
                        0
                    }
                })
                .collect()
        };
        let mut dom_mask = vec![1.0; e];
        dom_mask[e - 1] = 0.0;
        let mut profile_mask = vec![1.0; f];
        if f > 2 {
            profile_mask[f - 1] = 0.0;
        }
        Observation {
            tensors: vec![
                Tensor {
                    name: "profile_keys".into(),
                    shape: vec![f, t],
                    data: tok(f * t).into(),
                },
                Tensor {
                    name: "profile_values".into(),
                    shape: vec![f, t],
                    data: tok(f * t).into(),
                },
                Tensor {
                    name: "profile_mask".into(),
                    shape: vec![f],
                    data: profile_mask.into(),
                },
                Tensor {
                    name: "dom_tokens".into(),
                    shape: vec![e, 5, t],
                    data: tok(e * 5 * t).into(),
                },
                Tensor {
                    name: "dom_features".into(),
                    shape: vec![e, 8],
                    data: (0..e * 8)
                        .map(|_| rng.uniform_f32())
                        .collect::<Vec<f32>>()
                        .into(),
                },
                Tensor {
                    name: "dom_mask".into(),
                    shape: vec![e],
                    data: dom_mask.into(),
                },
            ],
            action_mask: None,
        }
    }

    pub fn spec_ref(&self) -> &EnvSpec {
        &self.spec
    }
}

/// A tiny circuit-shaped spec: `features` [5], `grid` [2, 3, 4], Discrete(12).
pub fn mini_circuit_spec() -> EnvSpec {
    EnvSpec {
        id: "MiniCircuit-v0".into(),
        observation_space: Space::Dict(vec![
            ("features".into(), Space::uniform_box(&[5], -1.0, 1.0)),
            ("grid".into(), Space::uniform_box(&[2, 3, 4], 0.0, 1.0)),
        ]),
        action_space: Space::Discrete { n: 12 },
        max_episode_steps: Some(4),
        metadata: BTreeMap::new(),
    }
}

pub fn mini_circuit_obs(rng: &mut RngStream) -> Observation {
    Observation {
        tensors: vec![
            Tensor {
                name: "features".into(),
                shape: vec![5],
                data: (0..5)
                    .map(|_| rng.normal() as f32)
                    .collect::<Vec<f32>>()
                    .into(),
            },
            Tensor {
                name: "grid".into(),
                shape: vec![2, 3, 4],
                data: (0..24)
                    .map(|_| rng.uniform_f32())
                    .collect::<Vec<f32>>()
                    .into(),
            },
        ],
        action_mask: Some((0..12).map(|i| i % 5 != 0).collect()),
    }
}

/// Trains `alg` on environments made by `make`, returning the policy and the curve.
pub fn train(
    alg: &mut dyn Algorithm,
    make: impl Fn() -> Box<dyn Env> + Send + Sync + 'static,
    seed: u64,
    settings: TrainingSettings,
) -> (Box<dyn Policy>, LearningCurve) {
    let factory = move |_i: usize| -> Result<Box<dyn Env>, EnvError> { Ok(make()) };
    let mut sink = DiscardCheckpoints;
    let mut ctx = TrainingContext::new(&factory, seed, settings, &mut sink, CancelToken::new());
    let policy = alg.train(&mut ctx).expect("training failed");
    let curve = ctx.take_curve();
    (policy, curve)
}

/// Hyperparameters for an algorithm from the registry, with overrides.
pub fn make_alg(name: &str, overrides: &[(&str, Value)]) -> Box<dyn Algorithm> {
    let mut reg = a2perf_core::Registry::new();
    a2perf_baselines::register(&mut reg);
    let given: BTreeMap<String, Value> = overrides
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    reg.make_algorithm(name, &given)
        .expect("valid hyperparameters")
}

/// Mean greedy return over `episodes` episodes.
pub fn mean_return(env: &mut dyn Env, policy: &mut dyn Policy, episodes: usize) -> f64 {
    (0..episodes)
        .map(|i| {
            a2perf_core::rollout(
                env,
                policy,
                10_000 + i as u64,
                a2perf_core::ActMode::Greedy,
                false,
            )
            .expect("rollout")
            .episode_return
        })
        .sum::<f64>()
        / episodes as f64
}

pub fn ints(v: &[i64]) -> Value {
    Value::List(v.iter().map(|i| Value::Int(*i)).collect())
}

/// Whether to skip a test on the real domains: they run only in release builds (prints why).
pub fn skip_in_debug(name: &str, what: &str) -> bool {
    if cfg!(debug_assertions) {
        println!("skipping {name}: {what} run only in release builds (cargo test --release)");
        return true;
    }
    false
}

/// The baselines and the three domains.
pub fn domains_registry() -> a2perf_core::Registry {
    let mut reg = a2perf_core::Registry::new();
    a2perf_baselines::register(&mut reg);
    a2perf_web::register(&mut reg);
    a2perf_circuit::register(&mut reg);
    a2perf_locomotion::register(&mut reg);
    reg
}

/// Environment parameters from `(name, value)` pairs.
pub fn env_params(pairs: &[(&str, Value)]) -> BTreeMap<String, Value> {
    pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect()
}

/// FNV-1a (64-bit) over the concatenation of `parts`: a short fingerprint of training output
/// for the tests that pin it.
pub fn fingerprint<'a>(parts: impl IntoIterator<Item = &'a [u8]>) -> u64 {
    let mut h = a2perf_core::hash::Fnv1a::new();
    for p in parts {
        h.write(p);
    }
    h.finish()
}

/// Whether this machine should reproduce the pinned training fingerprints bit for bit. They
/// were taken on an x86_64 machine with AVX-512; faer picks its matrix kernels by CPU features
/// at run time, and other kernels may round differently (still deterministic on one machine).
pub fn reproduces_pinned_bits(name: &str) -> bool {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        return true;
    }
    println!(
        "{name}: the pinned fingerprints come from an x86_64 machine with AVX-512; not compared here"
    );
    false
}
