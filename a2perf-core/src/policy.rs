//! Policies, algorithms and the training context they run in.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::env::{Env, EnvError, EnvSpec};
use crate::rng::RngStream;
use crate::rollout::{ActMode, rollout};
use crate::space::{Action, Observation};

/// Errors raised by policies (inference, checkpoint encoding and decoding).
#[derive(Debug, thiserror::Error)]
pub enum PolicyError {
    /// The observation does not fit the policy (wrong shape or missing tensor).
    #[error("observation does not fit the policy: {0}")]
    BadObservation(String),
    /// No legal action exists (all masked out).
    #[error("no legal action available")]
    NoLegalAction,
    /// A checkpoint could not be decoded.
    #[error("invalid checkpoint: {0}")]
    BadCheckpoint(String),
}

/// A trained (or training) policy: maps observations to actions.
pub trait Policy: Send {
    /// Chooses an action for `obs`. `ActMode::Greedy` must be deterministic; `ActMode::Explore`
    /// may sample from the policy's own seeded stream.
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError>;

    /// Serialises the policy so that the algorithm's loader can rebuild it.
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError>;
}

impl<P: Policy + ?Sized> Policy for Box<P> {
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError> {
        (**self).act(obs, mode)
    }
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        (**self).checkpoint()
    }
}

/// A policy that draws uniformly random legal actions (the benchmark's reference point).
///
/// ```
/// use a2perf_core::{ActMode, Observation, Policy, RandomPolicy, Space};
/// let mut p = RandomPolicy::new(Space::Discrete { n: 3 }, 0);
/// let mut obs = Observation::flat(vec![0.0]);
/// obs.action_mask = Some(vec![false, false, true]);
/// assert_eq!(p.act(&obs, ActMode::Explore).unwrap(), a2perf_core::Action::Discrete(2));
/// ```
#[derive(Clone, Debug)]
pub struct RandomPolicy {
    space: crate::space::Space,
    rng: RngStream,
}

impl RandomPolicy {
    /// A random policy over `space`, seeded by `seed`.
    pub fn new(space: crate::space::Space, seed: u64) -> Self {
        Self {
            space,
            rng: RngStream::new(seed, "random-policy"),
        }
    }
}

impl Policy for RandomPolicy {
    fn act(&mut self, obs: &Observation, _mode: ActMode) -> Result<Action, PolicyError> {
        self.space
            .sample(&mut self.rng, obs.action_mask.as_deref())
            .ok_or(PolicyError::NoLegalAction)
    }

    fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
        Ok(Checkpoint {
            algorithm: "random".into(),
            format_version: 1,
            payload: serde_json::to_vec(&self.space)
                .map_err(|e| PolicyError::BadCheckpoint(e.to_string()))?,
        })
    }
}

/// A serialised policy: which algorithm made it, its payload format version and the bytes.
///
/// On disk a checkpoint is a small self-checking container (magic, versions, length, checksum), so
/// truncated or corrupted files are rejected with a clear error before any algorithm decodes them.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Checkpoint {
    /// Registered algorithm name, used to find the loader.
    pub algorithm: String,
    /// Version of the algorithm's payload format.
    pub format_version: u32,
    /// Algorithm-specific bytes.
    pub payload: Vec<u8>,
}

const CHECKPOINT_MAGIC: &[u8; 8] = b"A2PERFCK";
const CONTAINER_VERSION: u32 = 1;

fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    h
}

impl Checkpoint {
    /// Encodes the checkpoint container.
    ///
    /// ```
    /// use a2perf_core::Checkpoint;
    /// let c = Checkpoint { algorithm: "ppo".into(), format_version: 2, payload: vec![1, 2, 3] };
    /// assert_eq!(Checkpoint::from_bytes(&c.to_bytes()).unwrap(), c);
    /// let mut bad = c.to_bytes();
    /// let last = bad.len() - 1;
    /// bad[last] ^= 1;
    /// assert!(Checkpoint::from_bytes(&bad).is_err());
    /// ```
    pub fn to_bytes(&self) -> Vec<u8> {
        let name = self.algorithm.as_bytes();
        let mut out = Vec::with_capacity(40 + name.len() + self.payload.len());
        out.extend_from_slice(CHECKPOINT_MAGIC);
        out.extend_from_slice(&CONTAINER_VERSION.to_le_bytes());
        out.extend_from_slice(&(name.len() as u32).to_le_bytes());
        out.extend_from_slice(name);
        out.extend_from_slice(&self.format_version.to_le_bytes());
        out.extend_from_slice(&(self.payload.len() as u64).to_le_bytes());
        out.extend_from_slice(&fnv1a64(&self.payload).to_le_bytes());
        out.extend_from_slice(&self.payload);
        out
    }

    /// Decodes and verifies a checkpoint container.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PolicyError> {
        let bad = |m: &str| PolicyError::BadCheckpoint(m.to_string());
        let mut rest = bytes;
        let mut take = |n: usize| -> Result<&[u8], PolicyError> {
            if rest.len() < n {
                return Err(bad("file is truncated"));
            }
            let (head, tail) = rest.split_at(n);
            rest = tail;
            Ok(head)
        };
        if take(8)? != CHECKPOINT_MAGIC {
            return Err(bad("not an a2perf checkpoint (bad magic bytes)"));
        }
        let container = u32::from_le_bytes(take(4)?.try_into().map_err(|_| bad("truncated"))?);
        if container != CONTAINER_VERSION {
            return Err(PolicyError::BadCheckpoint(format!(
                "container version {container} is not supported (expected {CONTAINER_VERSION})"
            )));
        }
        let name_len = u32::from_le_bytes(take(4)?.try_into().map_err(|_| bad("truncated"))?);
        if name_len > 256 {
            return Err(bad("algorithm name is implausibly long"));
        }
        let algorithm = std::str::from_utf8(take(name_len as usize)?)
            .map_err(|_| bad("algorithm name is not UTF-8"))?
            .to_string();
        let format_version = u32::from_le_bytes(take(4)?.try_into().map_err(|_| bad("truncated"))?);
        let len = u64::from_le_bytes(take(8)?.try_into().map_err(|_| bad("truncated"))?);
        let sum = u64::from_le_bytes(take(8)?.try_into().map_err(|_| bad("truncated"))?);
        let len = usize::try_from(len).map_err(|_| bad("payload length overflows"))?;
        let payload = take(len)?.to_vec();
        if !rest.is_empty() {
            return Err(bad("trailing bytes after payload"));
        }
        if fnv1a64(&payload) != sum {
            return Err(bad("checksum mismatch: the file is corrupt"));
        }
        Ok(Self {
            algorithm,
            format_version,
            payload,
        })
    }
}

/// A cooperative cancellation flag shared between a pipeline and its training runs (Ctrl-C).
#[derive(Clone, Debug, Default)]
pub struct CancelToken(Arc<AtomicBool>);

impl CancelToken {
    /// A fresh, un-cancelled token.
    pub fn new() -> Self {
        Self::default()
    }
    /// Requests cancellation.
    pub fn cancel(&self) {
        self.0.store(true, Ordering::SeqCst);
    }
    /// Whether cancellation was requested.
    pub fn is_cancelled(&self) -> bool {
        self.0.load(Ordering::SeqCst)
    }
}

/// One point of a training curve.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurvePoint {
    /// Environment steps consumed so far.
    pub env_steps: u64,
    /// Mean evaluation return (greedy policy).
    pub mean_return: f64,
    /// Standard deviation of the evaluation returns.
    pub std_return: f64,
    /// Seconds since training started (not deterministic; excluded from equality checks of curves).
    pub wall_seconds: f64,
}

/// Evaluation return against environment steps.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LearningCurve {
    /// Points in increasing `env_steps`.
    pub points: Vec<CurvePoint>,
}

impl LearningCurve {
    /// `(env_steps, mean_return)` pairs, the deterministic part of the curve.
    pub fn returns(&self) -> Vec<(u64, f64)> {
        self.points
            .iter()
            .map(|p| (p.env_steps, p.mean_return))
            .collect()
    }
}

/// Receives checkpoints during training.
pub trait CheckpointSink: Send {
    /// Stores `checkpoint`, taken after `env_steps` steps.
    fn save(&mut self, env_steps: u64, checkpoint: &Checkpoint) -> std::io::Result<()>;
}

/// Discards checkpoints.
#[derive(Debug, Default)]
pub struct DiscardCheckpoints;

impl CheckpointSink for DiscardCheckpoints {
    fn save(&mut self, _env_steps: u64, _checkpoint: &Checkpoint) -> std::io::Result<()> {
        Ok(())
    }
}

/// Writes checkpoints atomically as `DIR/step_000000012345.ckpt`.
#[derive(Debug)]
pub struct DirectoryCheckpoints {
    dir: PathBuf,
}

impl DirectoryCheckpoints {
    /// Checkpoints go into `dir` (created on first save).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// Path of the checkpoint taken at `env_steps`.
    pub fn path_for(&self, env_steps: u64) -> PathBuf {
        self.dir.join(format!("step_{env_steps:012}.ckpt"))
    }
}

impl CheckpointSink for DirectoryCheckpoints {
    fn save(&mut self, env_steps: u64, checkpoint: &Checkpoint) -> std::io::Result<()> {
        std::fs::create_dir_all(&self.dir)?;
        crate::results::write_atomic(&self.path_for(env_steps), &checkpoint.to_bytes())
    }
}

/// Errors raised while training or rolling out.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The environment failed.
    #[error(transparent)]
    Env(#[from] EnvError),
    /// The policy failed.
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// Writing a checkpoint or result failed.
    #[error("i/o error: {0}")]
    Io(#[from] std::io::Error),
    /// A hyperparameter is invalid for this environment.
    #[error("invalid hyperparameter `{name}`: {reason}")]
    InvalidHyperparameter {
        /// Name of the hyperparameter.
        name: String,
        /// Why it is invalid.
        reason: String,
    },
    /// The algorithm does not support this environment's spaces.
    #[error("unsupported environment: {0}")]
    Unsupported(String),
    /// Training diverged (non-finite loss or parameters).
    #[error("training diverged: {0}")]
    Diverged(String),
    /// Training was cancelled.
    #[error("cancelled")]
    Cancelled,
}

/// Budgets and schedules of one training run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingSettings {
    /// Total environment steps the algorithm may consume.
    pub total_env_steps: u64,
    /// Evaluate the greedy policy every this many environment steps (0 = only at the end).
    pub eval_interval: u64,
    /// Episodes per evaluation.
    pub eval_episodes: usize,
    /// Save a checkpoint every this many environment steps (0 = only at the end).
    pub checkpoint_interval: u64,
    /// Number of parallel environments the algorithm should use.
    pub num_envs: usize,
}

impl Default for TrainingSettings {
    fn default() -> Self {
        Self {
            total_env_steps: 10_000,
            eval_interval: 1_000,
            eval_episodes: 5,
            checkpoint_interval: 0,
            num_envs: 1,
        }
    }
}

/// Builds environment instances for training (index = parallel environment number).
pub type EnvFactory = dyn Fn(usize) -> Result<Box<dyn Env>, EnvError> + Send + Sync;

/// Whether training should go on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Keep training.
    Continue,
    /// Budget exhausted or cancelled: return the policy.
    Stop,
}

/// Everything an algorithm may use while training: environments, random streams, the curve
/// recorder, the checkpoint sink and the cancellation flag. Meters are not visible here; pipelines
/// own them.
pub struct TrainingContext<'a> {
    env_factory: &'a EnvFactory,
    seed: u64,
    settings: TrainingSettings,
    curve: LearningCurve,
    checkpoints: &'a mut dyn CheckpointSink,
    cancel: CancelToken,
    next_eval: u64,
    next_checkpoint: u64,
    eval_env: Option<Box<dyn Env>>,
    started: Instant,
    last_checkpoint: Option<u64>,
}

impl<'a> TrainingContext<'a> {
    /// A context for one training run.
    pub fn new(
        env_factory: &'a EnvFactory,
        seed: u64,
        settings: TrainingSettings,
        checkpoints: &'a mut dyn CheckpointSink,
        cancel: CancelToken,
    ) -> Self {
        let next_eval = settings.eval_interval;
        let next_checkpoint = settings.checkpoint_interval;
        Self {
            env_factory,
            seed,
            settings,
            curve: LearningCurve::default(),
            checkpoints,
            cancel,
            next_eval,
            next_checkpoint,
            eval_env: None,
            started: Instant::now(),
            last_checkpoint: None,
        }
    }

    /// The run's seed.
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Budgets and schedules.
    pub fn settings(&self) -> &TrainingSettings {
        &self.settings
    }

    /// A new training environment (`index` distinguishes parallel copies).
    pub fn make_env(&self, index: usize) -> Result<Box<dyn Env>, EnvError> {
        (self.env_factory)(index)
    }

    /// The random stream for `purpose` under this run's seed.
    pub fn rng(&self, purpose: &str) -> RngStream {
        RngStream::new(self.seed, purpose)
    }

    /// Whether cancellation was requested.
    pub fn is_cancelled(&self) -> bool {
        self.cancel.is_cancelled()
    }

    /// The curve recorded so far.
    pub fn curve(&self) -> &LearningCurve {
        &self.curve
    }

    /// Takes the recorded curve out of the context.
    pub fn take_curve(&mut self) -> LearningCurve {
        std::mem::take(&mut self.curve)
    }

    /// Mean and std of greedy returns over `settings.eval_episodes` episodes. The evaluation seeds
    /// are the same at every evaluation (common random numbers), so curve points are comparable.
    pub fn evaluate(&mut self, policy: &mut dyn Policy) -> Result<(f64, f64), RunError> {
        if self.eval_env.is_none() {
            self.eval_env = Some((self.env_factory)(usize::MAX)?);
        }
        let env = self.eval_env.as_mut().ok_or(RunError::Cancelled)?;
        let seeds = RngStream::new(self.seed, "evaluation-seeds");
        let n = self.settings.eval_episodes.max(1);
        let mut returns = Vec::with_capacity(n);
        for i in 0..n {
            let seed = seeds.derive_index(i as u64).next_u64();
            let ep = rollout(env.as_mut(), policy, seed, ActMode::Greedy, false)?;
            returns.push(ep.episode_return);
        }
        let mean = returns.iter().sum::<f64>() / n as f64;
        let var = returns.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / n as f64;
        Ok((mean, var.sqrt()))
    }

    /// Records an evaluation point at `env_steps`.
    pub fn record(&mut self, env_steps: u64, mean_return: f64, std_return: f64) {
        self.curve.points.push(CurvePoint {
            env_steps,
            mean_return,
            std_return,
            wall_seconds: self.started.elapsed().as_secs_f64(),
        });
    }

    /// Call after every batch of environment steps: evaluates and checkpoints when their
    /// intervals are crossed, and says whether to stop (budget spent or cancelled).
    pub fn progress(
        &mut self,
        env_steps: u64,
        policy: &mut dyn Policy,
    ) -> Result<Control, RunError> {
        if self.cancel.is_cancelled() {
            return Err(RunError::Cancelled);
        }
        let done = env_steps >= self.settings.total_env_steps;
        if self.settings.eval_interval > 0 && env_steps >= self.next_eval && !done {
            let (m, s) = self.evaluate(policy)?;
            self.record(env_steps, m, s);
            while self.next_eval <= env_steps {
                self.next_eval += self.settings.eval_interval;
            }
        }
        if self.settings.checkpoint_interval > 0 && env_steps >= self.next_checkpoint && !done {
            self.save_checkpoint(env_steps, policy)?;
            while self.next_checkpoint <= env_steps {
                self.next_checkpoint += self.settings.checkpoint_interval;
            }
        }
        Ok(if done {
            Control::Stop
        } else {
            Control::Continue
        })
    }

    /// Ends training at `env_steps`: records a final evaluation and a final checkpoint (unless one
    /// was already taken at exactly this step).
    pub fn finish(&mut self, env_steps: u64, policy: &mut dyn Policy) -> Result<(), RunError> {
        if self.curve.points.last().map(|p| p.env_steps) != Some(env_steps) {
            let (m, s) = self.evaluate(policy)?;
            self.record(env_steps, m, s);
        }
        if self.last_checkpoint != Some(env_steps) {
            self.save_checkpoint(env_steps, policy)?;
        }
        Ok(())
    }

    fn save_checkpoint(&mut self, env_steps: u64, policy: &dyn Policy) -> Result<(), RunError> {
        let ckpt = policy.checkpoint()?;
        self.checkpoints.save(env_steps, &ckpt)?;
        self.last_checkpoint = Some(env_steps);
        Ok(())
    }
}

/// A training algorithm. Implement it in your own crate and register it to benchmark it.
pub trait Algorithm: Send {
    /// Registered name (`ppo`, `ddqn`, …).
    fn name(&self) -> &str;

    /// Trains a policy for the environments made by `ctx`, reporting progress through it.
    /// Implementations call [`TrainingContext::progress`] regularly and
    /// [`TrainingContext::finish`] at the end.
    fn train(&mut self, ctx: &mut TrainingContext<'_>) -> Result<Box<dyn Policy>, RunError>;
}

/// Rebuilds a policy from a checkpoint for an environment.
pub type PolicyLoader = fn(&Checkpoint, &EnvSpec) -> Result<Box<dyn Policy>, PolicyError>;
