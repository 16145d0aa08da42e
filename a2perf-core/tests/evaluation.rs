//! The training context's evaluation: a policy that forks plays its episodes on two threads,
//! and the mean and std are those of the episodes played one after the other, to the bit.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use a2perf_core::{
    ActMode, Action, CancelToken, Checkpoint, DiscardCheckpoints, Env, EnvError, EnvSpec,
    Observation, Policy, PolicyError, Space, Step, TrainingContext, TrainingSettings,
};

/// An episode of `seed % 9 + 1` steps whose rewards depend on the seed, the step and the action;
/// each step sleeps briefly, so the second thread gets episodes to play.
struct SeedWalk {
    spec: EnvSpec,
    seed: u64,
    t: u64,
}

impl Env for SeedWalk {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }
    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        self.seed = seed.unwrap_or(0);
        self.t = 0;
        *obs = Observation::flat(vec![(self.seed % 101) as f32 / 101.0]);
        Ok(())
    }
    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        std::thread::sleep(std::time::Duration::from_micros(200));
        let a = match action {
            Action::Continuous(v) => f64::from(v[0]),
            Action::Discrete(a) => *a as f64,
        };
        self.t += 1;
        out.reward = (self.seed % 1000) as f64 * 1e-3 / 3.0 + a * self.t as f64 / 7.0;
        out.terminated = self.t > self.seed % 9;
        out.observation = Observation::flat(vec![self.t as f32 * 0.1]);
        Ok(())
    }
}

fn factory() -> impl Fn(usize) -> Result<Box<dyn Env>, EnvError> + Send + Sync {
    let spec = EnvSpec {
        id: "SeedWalk-v0".into(),
        observation_space: Space::uniform_box(&[1], 0.0, 10.0),
        action_space: Space::uniform_box(&[1], -1.0, 1.0),
        max_episode_steps: Some(20),
        metadata: Default::default(),
    };
    move |_| {
        Ok(Box::new(SeedWalk {
            spec: spec.clone(),
            seed: 0,
            t: 0,
        }) as Box<dyn Env>)
    }
}

/// Greedy action `sin(3 x)`; counts the actions it chose and, when `forks`, hands out copies
/// that count into their own counter.
struct Sine {
    forks: bool,
    played: Arc<AtomicUsize>,
    copies: Arc<AtomicUsize>,
}

impl Policy for Sine {
    fn act(&mut self, obs: &Observation, _: ActMode) -> Result<Action, PolicyError> {
        let x = obs.flat_values()[0];
        self.played.fetch_add(1, Ordering::Relaxed);
        Ok(Action::Continuous(vec![(3.0 * x).sin()]))
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: "sine".into(),
            format_version: 1,
            payload: Vec::new(),
        })
    }
    fn fork(&self) -> Option<Box<dyn Policy>> {
        self.forks.then(|| {
            Box::new(Sine {
                forks: false,
                played: self.copies.clone(),
                copies: self.copies.clone(),
            }) as Box<dyn Policy>
        })
    }
}

fn evaluate(forks: bool, threads: usize) -> ((f64, f64), usize, usize) {
    let factory = factory();
    let settings = TrainingSettings {
        total_env_steps: 1,
        eval_interval: 1,
        eval_episodes: 40,
        checkpoint_interval: 0,
        ..TrainingSettings::default()
    };
    let mut sink = DiscardCheckpoints;
    let mut ctx = TrainingContext::new(&factory, 3, settings, &mut sink, CancelToken::new());
    let (played, copies) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
    let mut policy = Sine {
        forks,
        played: played.clone(),
        copies: copies.clone(),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a pool");
    let r = pool
        .install(|| ctx.evaluate(&mut policy))
        .expect("evaluation");
    (
        r,
        played.load(Ordering::Relaxed),
        copies.load(Ordering::Relaxed),
    )
}

#[test]
fn a_forked_policy_evaluates_on_two_threads_to_the_same_bits() {
    let (serial, steps, none) = evaluate(false, 2);
    assert_eq!(none, 0, "no fork: one thread plays all");
    let (two, played, copies) = evaluate(true, 2);
    assert_eq!(played + copies, steps, "every episode played once");
    assert!(copies > 0, "the copy played some episodes");
    assert_eq!(two.0.to_bits(), serial.0.to_bits(), "mean");
    assert_eq!(two.1.to_bits(), serial.1.to_bits(), "std");
    assert!(serial.1 > 0.0, "the episodes differ");
}

#[test]
fn one_thread_evaluates_one_episode_after_another() {
    let (serial, steps, _) = evaluate(false, 2);
    let (one, played, copies) = evaluate(true, 1);
    assert_eq!((played, copies), (steps, 0), "a pool of one: no copy plays");
    assert_eq!(one.0.to_bits(), serial.0.to_bits());
    assert_eq!(one.1.to_bits(), serial.1.to_bits());
}
