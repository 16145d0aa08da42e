//! Replay speed against the raw environment: one recorded episode of random legal actions per
//! domain, stepped through once by replaying its log (what `a2perf verify` does) and once by
//! feeding the same prepared actions to the environment directly. The replay's overhead is
//! decoding each logged action into a reused buffer and keeping each reward; the target is a
//! replay rate of at least 80% of the raw step rate.

use std::collections::BTreeMap;
use std::hint::black_box;

use a2perf_core::replay::{EpisodeLog, Recorder, replay};
use a2perf_core::{ActMode, Action, Env, RandomPolicy, Step, Value};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

/// An episode of random legal actions, recorded.
fn recorded(env: &mut dyn Env, seed: u64) -> EpisodeLog {
    let mut policy = RandomPolicy::new(env.spec().action_space.clone(), seed);
    let mut rec = Recorder::new(env);
    a2perf_core::rollout(&mut rec, &mut policy, seed, ActMode::Explore, false).unwrap();
    rec.into_logs().remove(0)
}

/// The same episode without the log: reset, then each prepared action.
fn raw(env: &mut dyn Env, seed: u64, actions: &[Action], step: &mut Step) -> f64 {
    env.reset_into(Some(seed), &mut step.observation).unwrap();
    let mut ret = 0.0;
    for a in actions {
        env.step_into(a, step).unwrap();
        ret += step.reward;
    }
    ret
}

fn bench(c: &mut Criterion) {
    let reg = a2perf_pipeline::registry::full_registry();
    let none = BTreeMap::<String, Value>::new();
    let envs = [
        (
            "circuit Synthetic-Small",
            "CircuitTraining-Synthetic-Small-v0",
        ),
        ("web Difficulty-01", "WebNavigation-Difficulty-01-v0"),
        ("locomotion DogPace", "QuadrupedLocomotion-DogPace-v0"),
    ];
    let mut group = c.benchmark_group("replay");
    for (name, id) in envs {
        let mut env = reg.make_env(id, &none).unwrap();
        let log = recorded(env.as_mut(), 7);
        let actions: Vec<Action> = (0..log.actions.len())
            .map(|i| log.actions.get(i).unwrap())
            .collect();
        let mut step = Step::default();
        let expected = raw(env.as_mut(), log.seed, &actions, &mut step);
        assert_eq!(expected.to_bits(), log.logged_return().to_bits());
        group.throughput(Throughput::Elements(actions.len() as u64));
        group.bench_function(format!("{name}: raw env steps"), |b| {
            b.iter(|| black_box(raw(env.as_mut(), log.seed, &actions, &mut step)))
        });
        group.bench_function(format!("{name}: replayed steps"), |b| {
            b.iter(|| black_box(replay(env.as_mut(), &log).unwrap().episode_return))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
