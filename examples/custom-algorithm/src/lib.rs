//! # Plugging your own algorithm into A2Perf
//!
//! This crate lives outside the benchmark's code and depends only on `a2perf-core`. It shows the
//! three things a participant writes:
//!
//! 1. an [`Algorithm`] that trains a [`Policy`], reporting its curve and checkpoints through the
//!    [`TrainingContext`] ([`RandomSearch`]: hill climbing on a linear policy), and opting in to
//!    resumable training: it saves its whole state when the context asks, and continues from it
//!    when the context hands it back, so an interrupted run resumes exactly;
//! 2. a loader that rebuilds the policy from its [`Checkpoint`] ([`load_policy`]);
//! 3. a `register` function adding both to a [`Registry`] (here with a tiny environment,
//!    [`Corridor`], and its generalization suite, so the whole pipeline can be tried in seconds).
//!
//! A binary that wants the benchmark's pipelines for this algorithm builds a registry with the
//! built-in domains plus `a2perf_example_custom::register(&mut reg)` and calls
//! `a2perf_pipeline` (see docs/your-agent.md).
//!
//! ```
//! use a2perf_core::{CancelToken, DiscardCheckpoints, Registry, TrainingContext, TrainingSettings};
//! let mut reg = Registry::new();
//! a2perf_example_custom::register(&mut reg);
//! let entry = reg.env("Corridor-v0").unwrap().clone();
//! let params = reg.env_params("Corridor-v0", &Default::default()).unwrap();
//! let factory = move |_i: usize| (entry.make)(&params);
//! let mut algo = reg.make_algorithm("random_search", &Default::default()).unwrap();
//! let settings = TrainingSettings { total_env_steps: 400, eval_interval: 200, ..Default::default() };
//! let mut sink = DiscardCheckpoints;
//! let mut ctx = TrainingContext::new(&factory, 0, settings, &mut sink, CancelToken::new());
//! let _policy = algo.train(&mut ctx).unwrap();
//! assert_eq!(ctx.curve().points.last().unwrap().env_steps >= 400, true);
//! ```
//!
//! It deliberately does not try to be a good learner: the point is the plumbing.

#![warn(missing_docs)]

use std::collections::BTreeMap;
use std::sync::Arc;

use a2perf_core::{
    ActMode, Action, Algorithm, AlgorithmEntry, Checkpoint, Control, Env, EnvEntry, EnvError,
    EnvSpec, Observation, ParamKind, ParamSpec, Params, Policy, PolicyError, Registry, RngStream,
    RunError, Space, Step, TaskRef, TrainingContext, Value,
};
use serde::{Deserialize, Serialize};

/// Id of the example environment.
pub const CORRIDOR_ID: &str = "Corridor-v0";
/// Domain name of the example environment.
pub const DOMAIN: &str = "example";

/// A corridor of `length` cells: start near the left end, walk right (action 1) to reach the exit
/// (reward 1, terminal); every step costs 0.01. Observation: `[position / length, 1]`.
#[derive(Debug)]
pub struct Corridor {
    spec: EnvSpec,
    length: usize,
    position: usize,
    rng: RngStream,
}

impl Corridor {
    /// A corridor of `length` cells (at least 2).
    pub fn new(length: usize) -> Result<Self, EnvError> {
        if length < 2 {
            return Err(EnvError::InvalidParameter {
                name: "length".into(),
                reason: format!("must be at least 2, got {length}"),
            });
        }
        let mut metadata = BTreeMap::new();
        metadata.insert("length".into(), length.to_string());
        Ok(Self {
            spec: EnvSpec {
                id: CORRIDOR_ID.into(),
                observation_space: Space::uniform_box(&[2], 0.0, 1.0),
                action_space: Space::Discrete { n: 2 },
                max_episode_steps: Some(4 * length),
                metadata,
            },
            length,
            position: 0,
            rng: RngStream::new(0, "corridor"),
        })
    }

    fn write_obs(&self, obs: &mut Observation) {
        let x = self.position as f32 / self.length as f32;
        match obs.tensors.first_mut().and_then(|t| t.data.as_f32_mut()) {
            Some(d) if d.len() == 2 => {
                d[0] = x;
                d[1] = 1.0;
            }
            _ => *obs = Observation::flat(vec![x, 1.0]),
        }
    }
}

impl Env for Corridor {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        if let Some(seed) = seed {
            self.rng = RngStream::new(seed, "corridor");
        }
        self.position = self.rng.index(self.length / 2);
        self.write_obs(obs);
        Ok(())
    }

    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        let Action::Discrete(a) = action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "expected a discrete action".into(),
            });
        };
        match a {
            0 => self.position = self.position.saturating_sub(1),
            1 => self.position += 1,
            _ => {
                return Err(EnvError::InvalidAction {
                    action: action.clone(),
                    reason: "expected 0 (left) or 1 (right)".into(),
                });
            }
        }
        out.info.clear();
        out.terminated = self.position >= self.length;
        out.truncated = false;
        out.reward = if out.terminated { 1.0 } else { -0.01 };
        self.position = self.position.min(self.length);
        self.write_obs(&mut out.observation);
        Ok(())
    }
}

/// A linear policy: `argmax(W x)` for discrete actions, `tanh(W x)` scaled to the box otherwise.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearPolicy {
    /// Row-major `outputs × inputs` weights.
    pub weights: Vec<f32>,
    /// Observation size.
    pub inputs: usize,
    /// Action space.
    pub action_space: Space,
    #[serde(skip)]
    scratch: Vec<f32>,
}

impl LinearPolicy {
    fn outputs(space: &Space) -> Result<usize, String> {
        match space {
            Space::Discrete { n } => Ok(*n),
            Space::Box { low, .. } => Ok(low.len()),
            Space::Dict(_) => Err("dict action spaces are not supported".into()),
        }
    }

    /// A zero policy for `spec`.
    pub fn zeros(spec: &EnvSpec) -> Result<Self, String> {
        let inputs = spec.observation_space.flat_dim();
        let outputs = Self::outputs(&spec.action_space)?;
        Ok(Self {
            weights: vec![0.0; inputs * outputs],
            inputs,
            action_space: spec.action_space.clone(),
            scratch: Vec::with_capacity(inputs),
        })
    }
}

impl Policy for LinearPolicy {
    fn act(&mut self, obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        self.scratch.clear();
        obs.write_flat(&mut self.scratch);
        if self.scratch.len() != self.inputs {
            return Err(PolicyError::BadObservation(format!(
                "expected {} values, got {}",
                self.inputs,
                self.scratch.len()
            )));
        }
        let x = &self.scratch;
        let score = |row: usize| -> f32 {
            self.weights[row * self.inputs..(row + 1) * self.inputs]
                .iter()
                .zip(x)
                .map(|(w, v)| w * v)
                .sum()
        };
        match &self.action_space {
            Space::Discrete { n } => {
                let mut best: Option<(usize, f32)> = None;
                for a in (0..*n).filter(|a| obs.is_legal(*a)) {
                    let s = score(a);
                    if best.is_none_or(|(_, b)| s > b) {
                        best = Some((a, s));
                    }
                }
                best.map(|(a, _)| Action::Discrete(a))
                    .ok_or(PolicyError::NoLegalAction)
            }
            Space::Box { low, high, .. } => Ok(Action::Continuous(
                (0..low.len())
                    .map(|i| {
                        let t = score(i).tanh();
                        let (l, h) = (low[i] as f32, high[i] as f32);
                        if l.is_finite() && h.is_finite() {
                            l + (t + 1.0) * 0.5 * (h - l)
                        } else {
                            t
                        }
                    })
                    .collect(),
            )),
            Space::Dict(_) => Err(PolicyError::BadObservation("dict action space".into())),
        }
    }

    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: "random_search".into(),
            format_version: 1,
            payload: serde_json::to_vec(self)
                .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?,
        })
    }
}

/// Rebuilds a [`LinearPolicy`] from its checkpoint, checking it fits `spec`.
pub fn load_policy(ckpt: &Checkpoint, spec: &EnvSpec) -> Result<Box<dyn Policy>, PolicyError> {
    if ckpt.algorithm != "random_search" || ckpt.format_version != 1 {
        return Err(PolicyError::BadCheckpoint(format!(
            "expected a random_search v1 checkpoint, got {} v{}",
            ckpt.algorithm, ckpt.format_version
        )));
    }
    let mut p: LinearPolicy = serde_json::from_slice(&ckpt.payload)
        .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?;
    let outputs = LinearPolicy::outputs(&p.action_space).map_err(PolicyError::BadCheckpoint)?;
    if p.inputs != spec.observation_space.flat_dim()
        || p.action_space != spec.action_space
        || p.weights.len() != p.inputs * outputs
    {
        return Err(PolicyError::BadCheckpoint(format!(
            "policy of {} inputs does not fit environment {}",
            p.inputs, spec.id
        )));
    }
    p.scratch = Vec::with_capacity(p.inputs);
    Ok(Box::new(p))
}

/// Hill climbing on a linear policy: perturb the weights, keep the candidate if its return over a
/// few seeded episodes is at least as good.
///
/// It opts in to resumable training (see [`TrainingContext`]): everything the rest of the run
/// depends on is in [`SearchState`], which it hands to
/// [`progress_resumable`](TrainingContext::progress_resumable) and takes back with
/// [`take_resume_state`](TrainingContext::take_resume_state). Its episodes are reset with explicit
/// seeds, so no environment state needs saving.
#[derive(Debug)]
pub struct RandomSearch {
    noise: f64,
    episodes_per_candidate: usize,
}

/// Everything [`RandomSearch`] needs to continue exactly where it stopped.
#[derive(Debug, Serialize, Deserialize)]
pub struct SearchState {
    /// The best weights so far, as raw bits (decimal JSON floats would almost always round-trip;
    /// bits make it certain).
    pub best_bits: Vec<u32>,
    /// The perturbation stream, at its exact position.
    pub noise: RngStream,
    /// Environment steps consumed.
    pub steps: u64,
    /// Candidates tried (it numbers the episode seeds of the next one).
    pub candidate_index: u64,
}

fn resume_error(e: impl std::fmt::Display) -> RunError {
    RunError::Resume(e.to_string())
}

impl Algorithm for RandomSearch {
    fn name(&self) -> &str {
        "random_search"
    }

    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError> {
        let mut env = ctx.make_env(0)?;
        let spec = env.spec().clone();
        let mut best = LinearPolicy::zeros(&spec).map_err(RunError::Unsupported)?;
        let mut noise = ctx.rng("random_search/noise");
        let episode_seeds = ctx.rng("random_search/episodes");
        let mut steps = 0u64;
        let mut candidate_index = 0u64;
        if let Some(bytes) = ctx.take_resume_state() {
            let state: SearchState = serde_json::from_slice(&bytes).map_err(resume_error)?;
            if state.best_bits.len() != best.weights.len() {
                return Err(resume_error(format!(
                    "{} weights saved, the policy has {}",
                    state.best_bits.len(),
                    best.weights.len()
                )));
            }
            best.weights = state.best_bits.iter().map(|b| f32::from_bits(*b)).collect();
            noise = state.noise;
            steps = state.steps;
            candidate_index = state.candidate_index;
        }
        let score = |policy: &mut LinearPolicy,
                     env: &mut Box<dyn Env>,
                     steps: &mut u64,
                     index: u64|
         -> Result<f64, RunError> {
            let mut total = 0.0;
            for e in 0..self.episodes_per_candidate {
                let seed = episode_seeds
                    .derive_index(index)
                    .derive_index(e as u64)
                    .next_u64();
                let ep = a2perf_core::rollout(env.as_mut(), policy, seed, ActMode::Greedy, false)?;
                total += ep.episode_return;
                *steps += ep.length as u64;
            }
            Ok(total / self.episodes_per_candidate as f64)
        };
        loop {
            let save = |best: &LinearPolicy| {
                serde_json::to_vec(&SearchState {
                    best_bits: best.weights.iter().map(|w| w.to_bits()).collect(),
                    noise: noise.clone(),
                    steps,
                    candidate_index,
                })
                .map_err(resume_error)
            };
            if ctx.progress_resumable(steps, &mut best, save)? == Control::Stop {
                break;
            }
            candidate_index += 1;
            let mut cand = best.clone();
            for w in &mut cand.weights {
                *w += (noise.normal() * self.noise) as f32;
            }
            // Both are scored on the same episodes (common random numbers).
            let s = score(&mut cand, &mut env, &mut steps, candidate_index)?;
            let b = score(&mut best, &mut env, &mut steps, candidate_index)?;
            if s >= b {
                best = cand;
            }
        }
        ctx.finish(steps, &mut best)?;
        Ok(Box::new(best))
    }
}

/// Registers [`Corridor`] (`Corridor-v0`, parameter `length`), its generalization suite (lengths
/// 6, 8 and 12) and the `random_search` algorithm.
pub fn register(reg: &mut Registry) {
    reg.register_env(EnvEntry {
        id: CORRIDOR_ID.into(),
        domain: DOMAIN.into(),
        summary: "Example: walk right along a corridor to its exit".into(),
        params: vec![ParamSpec::new(
            "length",
            ParamKind::Int,
            Value::Int(8),
            "number of cells",
        )],
        make: Arc::new(|p: &Params| {
            let length = p.usize("length").map_err(|e| EnvError::InvalidParameter {
                name: "length".into(),
                reason: e.to_string(),
            })?;
            Ok(Box::new(Corridor::new(length)?) as Box<dyn Env>)
        }),
    });
    reg.register_generalization(
        DOMAIN,
        [("corridor_6", 6), ("corridor_8", 8), ("corridor_12", 12)]
            .into_iter()
            .map(|(name, length)| TaskRef {
                name: name.into(),
                env_id: CORRIDOR_ID.into(),
                params: [("length".to_string(), Value::Int(length))].into(),
            })
            .collect(),
    );
    reg.register_algorithm(AlgorithmEntry {
        name: "random_search".into(),
        summary: "Example: hill climbing on a linear policy".into(),
        params: vec![
            ParamSpec::new(
                "noise",
                ParamKind::Float,
                Value::Float(0.5),
                "std of the weight perturbation",
            ),
            ParamSpec::new(
                "episodes_per_candidate",
                ParamKind::Int,
                Value::Int(2),
                "episodes used to score each candidate",
            ),
        ],
        make: Arc::new(|p: &Params| {
            let bad = |name: &str, e: a2perf_core::ParamError| RunError::InvalidHyperparameter {
                name: name.into(),
                reason: e.to_string(),
            };
            let noise = p.f64("noise").map_err(|e| bad("noise", e))?;
            let episodes = p
                .usize("episodes_per_candidate")
                .map_err(|e| bad("episodes_per_candidate", e))?;
            if !(noise.is_finite() && noise > 0.0) || episodes == 0 {
                return Err(RunError::InvalidHyperparameter {
                    name: "noise/episodes_per_candidate".into(),
                    reason: "noise must be positive and episodes at least 1".into(),
                });
            }
            Ok(Box::new(RandomSearch {
                noise,
                episodes_per_candidate: episodes,
            }) as Box<dyn Algorithm>)
        }),
        load_policy,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use a2perf_core::{
        CancelToken, CheckpointSink, DiscardCheckpoints, ResumePoint, TrainingSettings,
    };

    /// Keeps resume points in memory and cancels `cancel` once the first one is written.
    #[derive(Default)]
    struct Points {
        kept: Vec<ResumePoint>,
        cancel: Option<CancelToken>,
    }

    impl CheckpointSink for Points {
        fn save(&mut self, _: u64, _: &Checkpoint) -> std::io::Result<()> {
            Ok(())
        }
        fn keeps_resume_points(&self) -> bool {
            true
        }
        fn save_resume(&mut self, point: &ResumePoint) -> std::io::Result<u64> {
            self.kept
                .push(ResumePoint::from_bytes(&point.to_bytes()).map_err(std::io::Error::other)?);
            if let Some(c) = &self.cancel {
                c.cancel();
            }
            Ok(0)
        }
    }

    fn settings() -> TrainingSettings {
        TrainingSettings {
            total_env_steps: 2_000,
            eval_interval: 500,
            eval_episodes: 4,
            checkpoint_interval: 600,
            ..Default::default()
        }
    }

    /// The curve, the final policy's checkpoint and the step training resumed from.
    type Trained = (Vec<(u64, f64)>, Checkpoint, Option<u64>);

    /// Trains on the corridor into `sink`, from `resume` if given.
    fn train_with(
        seed: u64,
        sink: &mut dyn CheckpointSink,
        cancel: CancelToken,
        resume: Option<ResumePoint>,
    ) -> Result<Trained, RunError> {
        let mut reg = Registry::new();
        register(&mut reg);
        let entry = reg.env(CORRIDOR_ID).unwrap().clone();
        let params = reg.env_params(CORRIDOR_ID, &BTreeMap::new()).unwrap();
        let factory = move |_i: usize| (entry.make)(&params);
        let mut algo = reg
            .make_algorithm("random_search", &BTreeMap::new())
            .unwrap();
        let mut ctx = TrainingContext::new(&factory, seed, settings(), sink, cancel);
        if let Some(p) = resume {
            ctx = ctx.with_resume(p);
        }
        let policy = algo.train(&mut ctx)?;
        Ok((
            ctx.curve().returns(),
            policy.checkpoint().unwrap(),
            ctx.resumed_from(),
        ))
    }

    fn train(seed: u64) -> (Vec<(u64, f64)>, Checkpoint) {
        let (curve, ckpt, _) =
            train_with(seed, &mut DiscardCheckpoints, CancelToken::new(), None).unwrap();
        (curve, ckpt)
    }

    #[test]
    fn an_interrupted_run_resumes_to_the_uninterrupted_result() {
        let (curve, ckpt) = train(4);
        // Interrupted as soon as its first resume point (at the 600-step interval) is written:
        // the next progress call, mid-interval, writes another and stops.
        let cancel = CancelToken::new();
        let mut sink = Points {
            cancel: Some(cancel.clone()),
            ..Default::default()
        };
        let stopped = train_with(4, &mut sink, cancel, None);
        assert!(matches!(stopped, Err(RunError::Cancelled)));
        let steps: Vec<u64> = sink.kept.iter().map(|p| p.progress.env_steps).collect();
        assert_eq!(steps.len(), 2, "{steps:?}");
        assert!(
            steps[0] >= 600 && steps[1] > steps[0] && steps[1] < 1200,
            "{steps:?}"
        );
        for point in sink.kept {
            let from = point.progress.env_steps;
            let (c, k, resumed) =
                train_with(4, &mut DiscardCheckpoints, CancelToken::new(), Some(point)).unwrap();
            assert_eq!(resumed, Some(from));
            assert_eq!(c, curve, "resumed from {from}");
            assert_eq!(k, ckpt, "resumed from {from}");
        }
    }

    #[test]
    fn training_is_deterministic_and_learns_to_walk_right() {
        let (a, ca) = train(3);
        let (b, cb) = train(3);
        assert_eq!(a, b);
        assert_eq!(ca, cb);
        // The zero policy always picks action 0 (left) and never reaches the exit.
        assert!(a.last().unwrap().1 > 0.5, "{a:?}");
    }

    #[test]
    fn checkpoint_round_trips_and_rejects_other_envs() {
        let (_, ckpt) = train(1);
        let spec = Corridor::new(8).unwrap().spec().clone();
        assert!(load_policy(&ckpt, &spec).is_ok());
        let mut other = spec.clone();
        other.observation_space = Space::uniform_box(&[3], 0.0, 1.0);
        assert!(load_policy(&ckpt, &other).is_err());
        let bad = Checkpoint {
            payload: b"{".to_vec(),
            ..ckpt
        };
        assert!(load_policy(&bad, &spec).is_err());
    }
}
