//! The vectorised stepper is deterministic: trajectories depend on the seed, not on thread timing.

use a2perf_core::{
    ActMode, Action, Env, EnvError, EnvSpec, Observation, Policy, RandomPolicy, RngStream, Space,
    Step, VecEnv,
};

/// A noisy random walk whose episode length and rewards depend on the reset seed.
struct NoisyWalk {
    spec: EnvSpec,
    rng: RngStream,
    x: f32,
    t: usize,
    work: usize,
}

impl NoisyWalk {
    fn new(work: usize) -> Self {
        Self {
            spec: EnvSpec {
                id: "NoisyWalk-v0".into(),
                observation_space: Space::uniform_box(&[2], -100.0, 100.0),
                action_space: Space::Discrete { n: 3 },
                max_episode_steps: Some(40),
                metadata: Default::default(),
            },
            rng: RngStream::new(0, "walk"),
            x: 0.0,
            t: 0,
            work,
        }
    }
}

impl Env for NoisyWalk {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        if let Some(s) = seed {
            self.rng = RngStream::new(s, "walk");
        }
        self.x = self.rng.range(-1.0, 1.0) as f32;
        self.t = 0;
        *obs = Observation::flat(vec![self.x, 0.0]);
        Ok(())
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        let Action::Discrete(a) = action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "discrete expected".into(),
            });
        };
        // Uneven busy work so threads finish in varying order.
        let mut acc = 0u64;
        for i in 0..(self.work * (1 + (self.rng.next_u32() % 7) as usize)) {
            acc = acc.wrapping_mul(31).wrapping_add(i as u64);
        }
        std::hint::black_box(acc);
        self.x += (*a as f32 - 1.0) * 0.5 + self.rng.normal() as f32 * 0.1;
        self.t += 1;
        out.observation = Observation::flat(vec![self.x, self.t as f32]);
        out.reward = -f64::from(self.x.abs());
        out.terminated = self.x.abs() > 5.0;
        out.truncated = false;
        out.info.clear();
        out.info.set("x", f64::from(self.x));
        Ok(())
    }
}

fn trajectory(seed: u64, n_envs: usize, steps: usize) -> Vec<(Vec<f32>, f64, bool, bool)> {
    let envs: Vec<Box<dyn Env>> = (0..n_envs)
        .map(|i| Box::new(NoisyWalk::new(200 + 150 * i)) as Box<dyn Env>)
        .collect();
    let mut vec_env = VecEnv::new(envs, seed);
    let mut policies: Vec<RandomPolicy> = (0..n_envs)
        .map(|i| RandomPolicy::new(Space::Discrete { n: 3 }, seed * 100 + i as u64))
        .collect();
    let mut out = Vec::new();
    let mut obs: Vec<Observation> = vec_env
        .reset_all()
        .unwrap()
        .iter()
        .map(|s| s.step.observation.clone())
        .collect();
    for _ in 0..steps {
        let actions: Vec<Action> = policies
            .iter_mut()
            .zip(&obs)
            .map(|(p, o)| p.act(o, ActMode::Explore).unwrap())
            .collect();
        let result = vec_env.step_all(&actions).unwrap();
        obs.clear();
        for r in result {
            out.push((
                r.step.observation.flat_values(),
                r.step.reward,
                r.step.terminated,
                r.step.truncated,
            ));
            obs.push(r.step.observation.clone());
        }
    }
    out
}

#[test]
fn same_seed_gives_identical_trajectories() {
    let a = trajectory(11, 6, 150);
    let b = trajectory(11, 6, 150);
    assert_eq!(a, b);
    // Episodes did end and restart during the run, so auto-reset seeding is exercised.
    assert!(a.iter().any(|(_, _, term, trunc)| *term || *trunc));
}

#[test]
fn different_seeds_give_different_trajectories() {
    assert_ne!(trajectory(1, 3, 50), trajectory(2, 3, 50));
}

#[test]
fn vec_env_matches_sequential_stepping() {
    // Environment i in the vector behaves exactly like a lone environment reset with the same
    // per-index seeds: parallelism changes nothing.
    let seed = 5;
    let parallel = trajectory(seed, 4, 60);
    let base = RngStream::new(seed, "vec-env/reset");
    for i in 0..4usize {
        let mut env = NoisyWalk::new(200 + 150 * i);
        let seeds = base.derive_index(i as u64);
        let mut episode = 0u64;
        let mut policy = RandomPolicy::new(Space::Discrete { n: 3 }, seed * 100 + i as u64);
        let mut o = env
            .reset(Some(seeds.derive_index(episode).next_u64()))
            .unwrap();
        episode += 1;
        let mut len = 0;
        for t in 0..60 {
            let a = policy.act(&o, ActMode::Explore).unwrap();
            let s = env.step(&a).unwrap();
            len += 1;
            let truncated = s.truncated || (!s.terminated && len >= 40);
            let expected = &parallel[t * 4 + i];
            assert_eq!(expected.1, s.reward);
            if s.terminated || truncated {
                o = env
                    .reset(Some(seeds.derive_index(episode).next_u64()))
                    .unwrap();
                episode += 1;
                len = 0;
            } else {
                assert_eq!(expected.0, s.observation.flat_values());
                o = s.observation;
            }
        }
    }
}

fn walks(n: usize) -> Vec<Box<dyn Env>> {
    (0..n)
        .map(|i| Box::new(NoisyWalk::new(10 + i)) as Box<dyn Env>)
        .collect()
}

/// Steps `vec_env` `steps` times with actions from `policies`, returning every output.
fn drive(
    vec_env: &mut VecEnv,
    policies: &mut [RandomPolicy],
    obs: &mut Vec<Observation>,
    steps: usize,
) -> Vec<(Vec<f32>, u64, bool, bool, u64)> {
    let mut out = Vec::new();
    for _ in 0..steps {
        let actions: Vec<Action> = policies
            .iter_mut()
            .zip(obs.iter())
            .map(|(p, o)| p.act(o, ActMode::Explore).unwrap())
            .collect();
        obs.clear();
        for r in vec_env.step_all(&actions).unwrap() {
            out.push((
                r.step.observation.flat_values(),
                r.step.reward.to_bits(),
                r.step.terminated,
                r.step.truncated,
                // The return of an episode that ends after the restore covers steps taken
                // before it too.
                if r.step.done() {
                    r.episode_return.to_bits()
                } else {
                    0
                },
            ));
            obs.push(r.step.observation.clone());
        }
    }
    out
}

#[test]
fn restored_environments_continue_exactly() {
    let n = 3;
    let mut a = VecEnv::new(walks(n), 9);
    let mut policies: Vec<RandomPolicy> = (0..n)
        .map(|i| RandomPolicy::new(Space::Discrete { n: 3 }, i as u64))
        .collect();
    let mut obs: Vec<Observation> = a
        .reset_all()
        .unwrap()
        .iter()
        .map(|s| s.step.observation.clone())
        .collect();
    let before = drive(&mut a, &mut policies, &mut obs, 57);
    assert!(before.iter().any(|s| s.2 || s.3), "episodes ended before");
    let snap = a.snapshot();
    assert!(snap.envs.iter().all(|e| e.episodes >= 1));
    assert!(
        snap.envs.iter().any(|e| !e.actions.is_empty()),
        "mid-episode"
    );
    let json = serde_json::to_string(&snap).unwrap();
    let mut saved_policies = policies.clone();
    let mut saved_obs = obs.clone();
    let after = drive(&mut a, &mut policies, &mut obs, 80);

    let mut b = VecEnv::new(walks(n), 9);
    let restored: a2perf_core::VecEnvSnapshot = serde_json::from_str(&json).unwrap();
    let (outs, restarted) = b.restore(&restored).unwrap();
    assert!(restarted.is_empty(), "{restarted:?}");
    let current: Vec<Observation> = outs.iter().map(|s| s.step.observation.clone()).collect();
    assert_eq!(current, saved_obs);
    assert_eq!(b.snapshot(), snap);
    let resumed = drive(&mut b, &mut saved_policies, &mut saved_obs, 80);
    assert_eq!(resumed, after);
}

/// A walk that remembers every step it ever took: its episodes are not a function of the seed
/// and the actions, so a replay cannot reproduce them.
struct Forgetful {
    inner: NoisyWalk,
    lifetime_steps: u64,
}

impl Env for Forgetful {
    fn spec(&self) -> &EnvSpec {
        self.inner.spec()
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        self.inner.reset_into(seed, obs)
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        self.inner.step_into(action, out)?;
        self.lifetime_steps += 1;
        out.observation.tensors[0].data.as_f32_mut().unwrap()[1] = self.lifetime_steps as f32;
        Ok(())
    }
}

#[test]
fn an_environment_that_does_not_replay_starts_a_new_episode() {
    let make = || -> Vec<Box<dyn Env>> {
        (0..2)
            .map(|_| {
                Box::new(Forgetful {
                    inner: NoisyWalk::new(1),
                    lifetime_steps: 0,
                }) as Box<dyn Env>
            })
            .collect()
    };
    let mut a = VecEnv::new(make(), 3);
    a.reset_all().unwrap();
    let acts = vec![Action::Discrete(1); 2];
    for _ in 0..45 {
        a.step_all(&acts).unwrap();
    }
    let snap = a.snapshot();
    let mut b = VecEnv::new(make(), 3);
    let (outs, restarted) = b.restore(&snap).unwrap();
    assert_eq!(outs.len(), 2);
    // Both walks had finished an episode (40-step limit), so their lifetime counters differ from
    // a fresh environment's; each starts its next episode, whose seed is the one the
    // uninterrupted run would use next.
    assert_eq!(restarted, vec![0, 1]);
    let after = b.snapshot();
    for (s, saved) in after.envs.iter().zip(&snap.envs) {
        assert_eq!(s.episodes, saved.episodes + 1);
        assert!(s.actions.is_empty());
    }
    b.step_all(&acts).unwrap();

    let mut small = VecEnv::new(walks(1), 3);
    let err = small.restore(&snap).unwrap_err().to_string();
    assert!(err.contains("2 environments saved, 1 here"), "{err}");
}
