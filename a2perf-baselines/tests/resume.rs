//! Resumed training is bit-identical to uninterrupted training, for every built-in algorithm on
//! the real domains (release builds only: `cargo test --release`; debug builds print why they
//! skip).
//!
//! Each case trains once without interruption, keeping every resume point in memory (a point is
//! exactly what an interrupted process leaves on disk at that step), then resumes from the
//! points at a checkpoint boundary and from one taken mid-interval by a cancellation, and checks
//! that the final policy's checkpoint bytes, the curve (steps and the bits of every return) and
//! the later interval checkpoints are the same, as is the return of the final policy.

mod common;

use std::collections::BTreeMap;
use std::sync::Arc;

use a2perf_baselines::dataset::JsonDatasetFile;
use a2perf_baselines::{Bc, Dataset, DatasetLoader};
use common::{
    domains_registry, env_params, fingerprint, ints, reproduces_pinned_bits, skip_in_debug,
};

use a2perf_core::{
    ActMode, CancelToken, Checkpoint, CheckpointSink, Env, EnvError, Params, Policy, RandomPolicy,
    Registry, ResumePoint, RunError, TrainingContext, TrainingSettings, Value, rollout,
};

/// Keeps checkpoints and resume points in memory; cancels `cancel` when the policy checkpoint
/// at `cancel_at` is written, so that the next progress call is interrupted mid-interval.
#[derive(Default)]
struct Memory {
    checkpoints: Vec<(u64, Vec<u8>)>,
    points: Vec<ResumePoint>,
    cancel_at: Option<(u64, CancelToken)>,
}

impl CheckpointSink for Memory {
    fn save(&mut self, env_steps: u64, checkpoint: &Checkpoint) -> std::io::Result<()> {
        self.checkpoints.push((env_steps, checkpoint.to_bytes()));
        if let Some((at, token)) = &self.cancel_at
            && *at == env_steps
        {
            token.cancel();
        }
        Ok(())
    }
    fn keeps_resume_points(&self) -> bool {
        true
    }
    fn save_resume(&mut self, point: &ResumePoint) -> std::io::Result<u64> {
        // Through the on-disk encoding, as a real interruption would.
        let bytes = point.to_bytes();
        self.points
            .push(ResumePoint::from_bytes(&bytes).expect("decodes"));
        Ok(bytes.len() as u64)
    }
}

/// What a training run produced.
struct Trained {
    policy: Vec<u8>,
    curve: Vec<(u64, u64, u64)>,
    inference: Vec<u64>,
    resumed_from: Option<u64>,
    warnings: Vec<String>,
}

struct Case {
    algorithm: &'static str,
    hp: BTreeMap<String, Value>,
    env_id: &'static str,
    env_params: BTreeMap<String, Value>,
    settings: TrainingSettings,
    dataset: Option<Arc<dyn DatasetLoader>>,
}

impl Case {
    /// Trains (from `resume` if given) into `sink`, cancelling as `sink.cancel_at` says.
    fn train(
        &self,
        reg: &Registry,
        resume: Option<ResumePoint>,
        sink: &mut Memory,
    ) -> Result<Trained, RunError> {
        let cancel = sink
            .cancel_at
            .as_ref()
            .map_or_else(CancelToken::new, |(_, t)| t.clone());
        let mut alg = match &self.dataset {
            Some(data) => {
                let p = Params::resolve(&Bc::params(), &self.hp).expect("hyperparameters");
                Box::new(Bc::from_params(&p)?.with_loader(data.clone()))
            }
            None => reg
                .make_algorithm(self.algorithm, &self.hp)
                .expect("hyperparameters"),
        };
        let (reg2, id, p) = (
            reg.clone(),
            self.env_id.to_string(),
            self.env_params.clone(),
        );
        let factory = move |_i: usize| -> Result<Box<dyn Env>, EnvError> {
            reg2.make_env(&id, &p)
                .map_err(|e| EnvError::Backend(e.to_string()))
        };
        let mut ctx = TrainingContext::new(&factory, 5, self.settings.clone(), sink, cancel);
        if let Some(point) = resume {
            ctx = ctx.with_resume(point);
        }
        let result = alg.train(&mut ctx);
        let resumed_from = ctx.resumed_from();
        let warnings = ctx.warnings().to_vec();
        let curve = ctx
            .take_curve()
            .points
            .iter()
            .map(|p| (p.env_steps, p.mean_return.to_bits(), p.std_return.to_bits()))
            .collect();
        let mut policy = result?;
        let mut env = reg.make_env(self.env_id, &self.env_params).expect("env");
        let inference = (0..3)
            .map(|s| {
                rollout(
                    env.as_mut(),
                    policy.as_mut(),
                    900 + s,
                    ActMode::Greedy,
                    false,
                )
                .expect("rollout")
                .episode_return
                .to_bits()
            })
            .collect();
        Ok(Trained {
            policy: policy.checkpoint().expect("checkpoint").to_bytes(),
            curve,
            inference,
            resumed_from,
            warnings,
        })
    }

    /// The uninterrupted run, then resumptions at the second interval boundary and at a point
    /// taken mid-interval by a cancellation just after the first boundary.
    fn check(&self) {
        let reg = domains_registry();
        let mut clean_sink = Memory::default();
        let clean = self
            .train(&reg, None, &mut clean_sink)
            .expect("uninterrupted");
        let interval = self.settings.checkpoint_interval;
        let boundaries: Vec<u64> = clean_sink
            .points
            .iter()
            .map(|p| p.progress.env_steps)
            .collect();
        assert!(
            boundaries.len() >= 2,
            "{}: want at least two resume points, got {boundaries:?}",
            self.algorithm
        );
        assert!(
            boundaries
                .iter()
                .all(|s| *s >= interval && *s < self.settings.total_env_steps)
        );
        self.check_pinned(&clean, &clean_sink);
        let sizes: Vec<usize> = clean_sink.points.iter().map(|p| p.state.len()).collect();
        println!(
            "{} on {}: resume points at {boundaries:?}, algorithm state {sizes:?} bytes",
            self.algorithm, self.env_id
        );

        let check_same = |point: ResumePoint, what: &str| {
            let from = point.progress.env_steps;
            let mut sink = Memory::default();
            let resumed = self
                .train(&reg, Some(point), &mut sink)
                .unwrap_or_else(|e| panic!("{}: {what}: {e}", self.algorithm));
            let what = format!(
                "{} on {}, {what} at step {from}",
                self.algorithm, self.env_id
            );
            assert_eq!(resumed.resumed_from, Some(from), "{what}");
            assert!(
                resumed.warnings.is_empty(),
                "{what}: {:?}",
                resumed.warnings
            );
            assert!(
                resumed.policy == clean.policy,
                "{what}: final policy differs"
            );
            assert_eq!(resumed.curve, clean.curve, "{what}: curve differs");
            assert_eq!(
                resumed.inference, clean.inference,
                "{what}: inference differs"
            );
            let later: Vec<&(u64, Vec<u8>)> = clean_sink
                .checkpoints
                .iter()
                .filter(|(s, _)| *s > from)
                .collect();
            let got: Vec<&(u64, Vec<u8>)> = sink.checkpoints.iter().collect();
            assert!(!later.is_empty(), "{what}: no checkpoint after the point");
            assert!(
                got == later,
                "{what}: checkpoints after the resume point differ"
            );
        };

        check_same(
            clean_sink.points[1].clone(),
            "resumed at a checkpoint boundary",
        );

        // Interrupted: cancelled as the first interval checkpoint is written, so the next progress
        // call (mid-interval) writes a resume point and stops.
        let mut sink = Memory {
            cancel_at: Some((boundaries[0], CancelToken::new())),
            ..Default::default()
        };
        let interrupted = self.train(&reg, None, &mut sink);
        assert!(
            matches!(interrupted, Err(RunError::Cancelled)),
            "{}: the cancelled run did not stop",
            self.algorithm
        );
        let mid = sink
            .points
            .last()
            .expect("a point at the interruption")
            .clone();
        let at = mid.progress.env_steps;
        assert!(
            at > boundaries[0] && at < boundaries[0] + interval,
            "{}: interruption point {at} is not mid-interval after {}",
            self.algorithm,
            boundaries[0]
        );
        check_same(mid, "resumed after a mid-interval interruption");
    }
}

impl Case {
    /// Compares the uninterrupted run (final policy, curve, inference returns, every interval
    /// checkpoint and every resume point's algorithm state) with its pinned fingerprint.
    fn check_pinned(&self, clean: &Trained, sink: &Memory) {
        let curve: Vec<u8> = clean
            .curve
            .iter()
            .chain(std::iter::once(&(0, 0, 0)))
            .flat_map(|(s, m, d)| [*s, *m, *d])
            .chain(clean.inference.iter().copied())
            .flat_map(u64::to_le_bytes)
            .collect();
        let steps: Vec<u8> = sink
            .checkpoints
            .iter()
            .map(|(s, _)| *s)
            .chain(sink.points.iter().map(|p| p.progress.env_steps))
            .flat_map(u64::to_le_bytes)
            .collect();
        let got = fingerprint(
            [clean.policy.as_slice(), &curve, &steps]
                .into_iter()
                .chain(sink.checkpoints.iter().map(|(_, c)| c.as_slice()))
                .chain(sink.points.iter().map(|p| p.state.as_slice())),
        );
        let what = format!("{} on {}", self.algorithm, self.env_id);
        println!("{what}: fingerprint {got:#018x}");
        if reproduces_pinned_bits(&what) {
            let pinned = PINNED
                .iter()
                .find(|(a, e, _)| *a == self.algorithm && *e == self.env_id)
                .map(|(_, _, h)| *h);
            assert_eq!(Some(got), pinned, "{what}: the training output moved");
        }
    }
}

/// Fingerprints of the uninterrupted runs (see [`Case::check_pinned`]), computed from the code
/// at commit 9603bb3, before the training loops were split into named steps (issue 35): a
/// refactoring must keep every floating-point operation and its order. The three circuit values
/// were pinned again after the force-directed placer took plc_client_os's exact-centre start and
/// summation order (issue 36, commits 54676ed and 30c3b0a), which changes every circuit episode's
/// final reward. The two web values were pinned again when the web network computed its first
/// layers through projected embedding tables and its scores on the active pairs only (issue 38):
/// the same function in another order of floating-point operations. The other three are
/// unchanged from 9603bb3.
const PINNED: &[(&str, &str, u64)] = &[
    ("ppo", CIRCUIT, 0x9a38_4377_c92f_58ed),
    ("ppo", PACE, 0xa78f_0441_b010_cfe4),
    ("ppo", WEB, 0x8e37_6aaf_b5bb_8694),
    ("ddqn", WEB, 0x2726_7205_a241_e45b),
    ("ddqn", CIRCUIT, 0xbcfd_296b_08fa_6c3d),
    ("sac", PACE, 0xa168_15bf_3214_bbe7),
    ("bc", CIRCUIT, 0x79ca_9812_59c2_8f1e),
    ("bc", PACE, 0x9852_e93f_925c_9502),
];

const CIRCUIT: &str = "CircuitTraining-Synthetic-Small-v0";
const WEB: &str = "WebNavigation-Difficulty-01-v0";
const PACE: &str = "QuadrupedLocomotion-DogPace-v0";

fn settings(total: u64, eval: u64, checkpoint: u64, num_envs: usize) -> TrainingSettings {
    TrainingSettings {
        total_env_steps: total,
        eval_interval: eval,
        eval_episodes: 1,
        checkpoint_interval: checkpoint,
        num_envs,
    }
}

fn web_params() -> BTreeMap<String, Value> {
    env_params(&[("num_websites", Value::Int(1))])
}

/// Random-policy demonstrations on `env_id`, for BC.
fn random_dataset(reg: &Registry, env_id: &str, episodes: usize) -> Arc<Dataset> {
    let mut env = reg.make_env(env_id, &BTreeMap::new()).expect("env");
    let mut policy = RandomPolicy::new(env.spec().action_space.clone(), 3);
    Arc::new(
        Dataset::collect(env.as_mut(), &mut policy, episodes, 0, ActMode::Explore).expect("data"),
    )
}

#[test]
fn ppo_resumes_exactly_on_circuit() {
    if skip_in_debug(
        "ppo_resumes_exactly_on_circuit",
        "resume tests on the domains",
    ) {
        return;
    }
    Case {
        algorithm: "ppo",
        hp: env_params(&[
            ("num_steps", Value::Int(24)),
            ("minibatch_size", Value::Int(32)),
            ("latent_dim", Value::Int(16)),
            ("hidden_sizes", ints(&[32, 32])),
            ("lr_schedule", Value::Str("cosine".into())),
        ]),
        env_id: CIRCUIT,
        env_params: BTreeMap::new(),
        settings: settings(480, 96, 144, 2),
        dataset: None,
    }
    .check();
}

#[test]
fn ppo_resumes_exactly_on_locomotion() {
    if skip_in_debug(
        "ppo_resumes_exactly_on_locomotion",
        "resume tests on the domains",
    ) {
        return;
    }
    Case {
        algorithm: "ppo",
        hp: env_params(&[
            ("num_steps", Value::Int(64)),
            ("minibatch_size", Value::Int(64)),
            ("hidden_sizes", ints(&[32, 32])),
        ]),
        env_id: PACE,
        env_params: BTreeMap::new(),
        settings: settings(1024, 256, 384, 2),
        dataset: None,
    }
    .check();
}

#[test]
fn ppo_resumes_exactly_on_web() {
    if skip_in_debug("ppo_resumes_exactly_on_web", "resume tests on the domains") {
        return;
    }
    Case {
        algorithm: "ppo",
        hp: env_params(&[
            ("num_steps", Value::Int(32)),
            ("minibatch_size", Value::Int(32)),
            ("embedding_dim", Value::Int(16)),
            ("latent_dim", Value::Int(16)),
        ]),
        env_id: WEB,
        env_params: web_params(),
        settings: settings(448, 128, 128, 2),
        dataset: None,
    }
    .check();
}

#[test]
fn ddqn_resumes_exactly_on_web() {
    if skip_in_debug("ddqn_resumes_exactly_on_web", "resume tests on the domains") {
        return;
    }
    Case {
        algorithm: "ddqn",
        hp: env_params(&[
            ("batch_size", Value::Int(16)),
            ("replay_capacity", Value::Int(150)),
            ("learning_starts", Value::Int(32)),
            ("updates_per_step", Value::Float(0.5)),
            ("target_update_period", Value::Int(10)),
            ("embedding_dim", Value::Int(16)),
            ("latent_dim", Value::Int(16)),
        ]),
        env_id: WEB,
        env_params: web_params(),
        settings: settings(400, 100, 120, 2),
        dataset: None,
    }
    .check();
}

#[test]
fn ddqn_resumes_exactly_on_circuit() {
    if skip_in_debug(
        "ddqn_resumes_exactly_on_circuit",
        "resume tests on the domains",
    ) {
        return;
    }
    Case {
        algorithm: "ddqn",
        hp: env_params(&[
            ("batch_size", Value::Int(16)),
            ("replay_capacity", Value::Int(200)),
            ("learning_starts", Value::Int(30)),
            ("target_tau", Value::Float(0.1)),
            ("target_update_period", Value::Int(1)),
            ("latent_dim", Value::Int(16)),
            ("hidden_sizes", ints(&[32, 32])),
        ]),
        env_id: CIRCUIT,
        env_params: BTreeMap::new(),
        settings: settings(360, 90, 120, 2),
        dataset: None,
    }
    .check();
}

#[test]
fn sac_resumes_exactly_on_locomotion() {
    if skip_in_debug(
        "sac_resumes_exactly_on_locomotion",
        "resume tests on the domains",
    ) {
        return;
    }
    Case {
        algorithm: "sac",
        hp: env_params(&[
            ("batch_size", Value::Int(32)),
            ("replay_capacity", Value::Int(300)),
            ("learning_starts", Value::Int(64)),
            ("updates_per_step", Value::Float(0.5)),
            ("hidden_sizes", ints(&[32, 32])),
            ("normalize_observations", Value::Bool(true)),
            ("action_limit", Value::Float(0.3)),
        ]),
        env_id: PACE,
        env_params: BTreeMap::new(),
        settings: settings(600, 200, 200, 2),
        dataset: None,
    }
    .check();
}

#[test]
fn bc_resumes_exactly_on_circuit_and_locomotion() {
    if skip_in_debug(
        "bc_resumes_exactly_on_circuit_and_locomotion",
        "resume tests on the domains",
    ) {
        return;
    }
    let reg = domains_registry();
    for (env_id, episodes) in [(CIRCUIT, 10), (PACE, 3)] {
        bc_case(env_id, random_dataset(&reg, env_id, episodes), 320).check();
    }
}

/// BC on `env_id` from `data`: 30 batches of 32, a resume point every `checkpoint` samples.
fn bc_case(env_id: &'static str, data: Arc<dyn DatasetLoader>, checkpoint: u64) -> Case {
    Case {
        algorithm: "bc",
        hp: env_params(&[
            ("batch_size", Value::Int(32)),
            ("learning_rate", Value::Float(1e-3)),
            ("latent_dim", Value::Int(16)),
            ("hidden_sizes", ints(&[32, 32])),
        ]),
        env_id,
        env_params: BTreeMap::new(),
        settings: settings(32 * 30, 320, checkpoint, 1),
        dataset: Some(data),
    }
}

/// BC reading its demonstrations from a JSON file (parsed sample by sample into its compact
/// store) trains the same policy, bit for bit, as BC given them in memory: on circuit, where the
/// netlist's adjacency is one shared row of the store, and on locomotion, where the observations
/// are normalised.
#[test]
fn bc_trains_the_same_from_a_file_as_from_memory() {
    if skip_in_debug(
        "bc_trains_the_same_from_a_file_as_from_memory",
        "BC training on the domains",
    ) {
        return;
    }
    let reg = domains_registry();
    let dir = tempfile::tempdir().expect("tempdir");
    for (env_id, episodes) in [(CIRCUIT, 10), (PACE, 3)] {
        let data = random_dataset(&reg, env_id, episodes);
        let path = dir.path().join(format!("{env_id}.json"));
        data.save_json(&path).expect("save");
        let memory = bc_case(env_id, data.clone(), 0)
            .train(&reg, None, &mut Memory::default())
            .expect("train from memory");
        let file = bc_case(env_id, Arc::new(JsonDatasetFile(path)), 0)
            .train(&reg, None, &mut Memory::default())
            .expect("train from the file");
        assert_eq!(memory.policy, file.policy, "{env_id}: policy bytes");
        assert_eq!(memory.curve, file.curve, "{env_id}: curve");
    }
}

/// A resume state from another configuration is refused with a clear error, not misread.
#[test]
fn a_state_from_another_configuration_is_refused() {
    if skip_in_debug(
        "a_state_from_another_configuration_is_refused",
        "resume tests on the domains",
    ) {
        return;
    }
    let reg = domains_registry();
    let case = |hidden: i64| Case {
        algorithm: "ppo",
        hp: env_params(&[
            ("num_steps", Value::Int(24)),
            ("latent_dim", Value::Int(16)),
            ("hidden_sizes", ints(&[hidden, hidden])),
        ]),
        env_id: CIRCUIT,
        env_params: BTreeMap::new(),
        settings: settings(144, 0, 48, 2),
        dataset: None,
    };
    let mut sink = Memory::default();
    case(32).train(&reg, None, &mut sink).expect("trains");
    let point = sink.points[0].clone();
    let err = case(16)
        .train(&reg, Some(point), &mut Memory::default())
        .err()
        .expect("refused")
        .to_string();
    assert!(err.contains("cannot resume: policy parameters"), "{err}");
}
