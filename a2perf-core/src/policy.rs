//! Policies, algorithms and the training context they run in.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::env::{Env, EnvError, EnvSpec};
use crate::resume::{ResumeDir, ResumePoint, ResumeWrite, TrainingProgress};
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

impl From<crate::bytes::Truncated> for PolicyError {
    fn from(e: crate::bytes::Truncated) -> Self {
        PolicyError::BadCheckpoint(format!("the data is {e}"))
    }
}

/// A trained (or training) policy: maps observations to actions.
pub trait Policy: Send {
    /// Chooses an action for `obs`. `ActMode::Greedy` must be deterministic; `ActMode::Explore`
    /// may sample from the policy's own seeded stream.
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError>;

    /// Called by the inference benchmark with the observation the next `act` call gets, before
    /// its timer starts: the place for work the original harness counted as the environment's,
    /// such as a policy living in another runtime converting the observation into that
    /// runtime's arrays (the original's environments returned them already converted). `act`
    /// must give the same action whether or not `prepare` was called. Default: nothing.
    ///
    /// ```
    /// use a2perf_core::{ActMode, Observation, Policy, RandomPolicy, Space};
    /// let mut p = RandomPolicy::new(Space::Discrete { n: 2 }, 0);
    /// let obs = Observation::flat(vec![0.0]);
    /// p.prepare(&obs).unwrap(); // a Rust policy has nothing to convert
    /// assert!(p.act(&obs, ActMode::Greedy).is_ok());
    /// ```
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        let _ = obs;
        Ok(())
    }

    /// Serialises the policy so that the algorithm's loader can rebuild it.
    fn checkpoint(&self) -> Result<Checkpoint, PolicyError>;
}

impl<P: Policy + ?Sized> Policy for Box<P> {
    fn act(&mut self, obs: &Observation, mode: ActMode) -> Result<Action, PolicyError> {
        (**self).act(obs, mode)
    }
    fn prepare(&mut self, obs: &Observation) -> Result<(), PolicyError> {
        (**self).prepare(obs)
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

fn fnv1a64(parts: &[&[u8]]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in parts.iter().flat_map(|p| p.iter()) {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01B3);
    }
    h
}

/// The checkpoint container around a payload given in parts (concatenated), so that large
/// payloads are copied once.
pub(crate) fn encode_container(algorithm: &str, format_version: u32, parts: &[&[u8]]) -> Vec<u8> {
    let len: usize = parts.iter().map(|p| p.len()).sum();
    let mut out = Vec::with_capacity(40 + algorithm.len() + len);
    write_container(&mut out, algorithm, format_version, parts)
        .unwrap_or_else(|_| unreachable!("writing to a Vec cannot fail"));
    out
}

/// Writes the container of `parts` (their concatenation is the payload) to `w` without
/// gathering the payload in one buffer; returns the bytes written.
pub(crate) fn write_container(
    w: &mut impl std::io::Write,
    algorithm: &str,
    format_version: u32,
    parts: &[&[u8]],
) -> std::io::Result<u64> {
    let name = algorithm.as_bytes();
    let len: usize = parts.iter().map(|p| p.len()).sum();
    let mut head = Vec::with_capacity(40 + name.len());
    head.extend_from_slice(CHECKPOINT_MAGIC);
    head.extend_from_slice(&CONTAINER_VERSION.to_le_bytes());
    head.extend_from_slice(&(name.len() as u32).to_le_bytes());
    head.extend_from_slice(name);
    head.extend_from_slice(&format_version.to_le_bytes());
    head.extend_from_slice(&(len as u64).to_le_bytes());
    head.extend_from_slice(&fnv1a64(parts).to_le_bytes());
    w.write_all(&head)?;
    for p in parts {
        w.write_all(p)?;
    }
    Ok((head.len() + len) as u64)
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
        encode_container(&self.algorithm, self.format_version, &[&self.payload])
    }

    /// Decodes and verifies a checkpoint container.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, PolicyError> {
        let bad = |m: &str| PolicyError::BadCheckpoint(m.to_string());
        let mut r = crate::bytes::ByteReader::new(bytes);
        if r.take(8)? != CHECKPOINT_MAGIC {
            return Err(bad("not an a2perf checkpoint (bad magic bytes)"));
        }
        let container = r.u32()?;
        if container != CONTAINER_VERSION {
            return Err(PolicyError::BadCheckpoint(format!(
                "container version {container} is not supported (expected {CONTAINER_VERSION})"
            )));
        }
        let name_len = r.u32()?;
        if name_len > 256 {
            return Err(bad("algorithm name is implausibly long"));
        }
        let algorithm = std::str::from_utf8(r.take(name_len as usize)?)
            .map_err(|_| bad("algorithm name is not UTF-8"))?
            .to_string();
        let format_version = r.u32()?;
        let len = r.u64()?;
        let sum = r.u64()?;
        let len = usize::try_from(len).map_err(|_| bad("payload length overflows"))?;
        let payload = r.take(len)?.to_vec();
        if r.remaining() != 0 {
            return Err(bad("trailing bytes after payload"));
        }
        if fnv1a64(&[&payload]) != sum {
            return Err(bad("checksum mismatch: the file is corrupt"));
        }
        Ok(Self {
            algorithm,
            format_version,
            payload,
        })
    }
}

/// A cooperative cancellation flag shared between a pipeline and its training runs (Ctrl-C,
/// SIGTERM): runs stop at their next progress call, writing a resume point first when their
/// algorithm supports it.
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

/// Receives checkpoints (and, when it keeps them, resume points) during training.
pub trait CheckpointSink: Send {
    /// Stores `checkpoint`, taken after `env_steps` steps.
    fn save(&mut self, env_steps: u64, checkpoint: &Checkpoint) -> std::io::Result<()>;

    /// Whether this sink keeps resume points. Only then does the context ask an algorithm that
    /// opted in ([`TrainingContext::progress_resumable`]) for its state.
    fn keeps_resume_points(&self) -> bool {
        false
    }

    /// Stores a resume point; returns its size in bytes.
    fn save_resume(&mut self, _point: &ResumePoint) -> std::io::Result<u64> {
        Ok(0)
    }

    /// Forgets every resume point (training starts again from scratch).
    fn discard_resume_points(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Discards checkpoints.
#[derive(Debug, Default)]
pub struct DiscardCheckpoints;

impl CheckpointSink for DiscardCheckpoints {
    fn save(&mut self, _env_steps: u64, _checkpoint: &Checkpoint) -> std::io::Result<()> {
        Ok(())
    }
}

/// Writes checkpoints atomically as `DIR/step_000000012345.ckpt` and, with
/// [`with_resume_dir`](Self::with_resume_dir), resume points into a [`ResumeDir`].
#[derive(Debug)]
pub struct DirectoryCheckpoints {
    dir: PathBuf,
    resume: Option<ResumeDir>,
}

impl DirectoryCheckpoints {
    /// Checkpoints go into `dir` (created on first save).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            resume: None,
        }
    }

    /// Also keeps resume points, in `dir`.
    pub fn with_resume_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.resume = Some(ResumeDir::new(dir));
        self
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

    fn keeps_resume_points(&self) -> bool {
        self.resume.is_some()
    }

    fn save_resume(&mut self, point: &ResumePoint) -> std::io::Result<u64> {
        match &self.resume {
            Some(r) => r.save(point),
            None => Ok(0),
        }
    }

    fn discard_resume_points(&mut self) -> std::io::Result<()> {
        match &self.resume {
            Some(r) => r.clear(),
            None => Ok(()),
        }
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
    /// The algorithm cannot continue from the resume state it was given (another format
    /// version, another configuration, a changed dataset). Pipelines then train from scratch.
    #[error("cannot resume: {0}")]
    Resume(String),
    /// Training was cancelled (Ctrl-C, SIGTERM). When the algorithm opted in to resumption and
    /// the sink keeps resume points, one was written first.
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
///
/// # Resumable training (opt-in)
///
/// An algorithm that can save and restore its complete state opts in with two calls:
///
/// - at the start, [`take_resume_state`](Self::take_resume_state): `Some(bytes)` when the run is
///   being resumed, with the bytes the algorithm itself wrote; the context has then already
///   restored its own part (curve, schedule of evaluations and checkpoints, clock);
/// - in the loop, [`progress_resumable`](Self::progress_resumable) instead of
///   [`progress`](Self::progress), with a closure that serialises the state. The context calls it
///   only when a resume point is due: at every checkpoint interval, and when cancellation was
///   requested (SIGTERM, Ctrl-C) — then the point is written at this very step and the call
///   returns [`RunError::Cancelled`].
///
/// The state must hold everything that the rest of the run depends on (network and optimiser,
/// normalisation statistics, every random stream's [`state`](RngStream::state), replay buffers,
/// counters, environments in mid-episode), so that the resumed run is bit-identical to an
/// uninterrupted one. Algorithms that do not opt in are restarted from scratch by the pipelines.
///
/// ```
/// use a2perf_core::*;
/// # struct Zero;
/// # impl Policy for Zero {
/// #     fn act(&mut self, _: &Observation, _: ActMode) -> Result<Action, PolicyError> { Ok(Action::Discrete(0)) }
/// #     fn checkpoint(&self) -> Result<Checkpoint, PolicyError> {
/// #         Ok(Checkpoint { algorithm: "zero".into(), format_version: 1, payload: vec![] })
/// #     }
/// # }
/// /// Counts its steps; its whole state is the step counter and one random stream.
/// fn train(ctx: &mut TrainingContext<'_>) -> Result<(u64, u64), RunError> {
///     let (mut steps, mut rng) = match ctx.take_resume_state() {
///         Some(bytes) => serde_json::from_slice(&bytes).map_err(|e| RunError::Resume(e.to_string()))?,
///         None => (0u64, ctx.rng("counter")),
///     };
///     let mut policy = Zero;
///     loop {
///         steps += 10;
///         rng.next_u64();
///         let save = |_: &Zero| serde_json::to_vec(&(steps, &rng)).map_err(|e| RunError::Resume(e.to_string()));
///         if ctx.progress_resumable(steps, &mut policy, save)? == Control::Stop {
///             break;
///         }
///     }
///     ctx.finish(steps, &mut policy)?;
///     Ok((steps, rng.next_u64()))
/// }
/// # struct Env1(EnvSpec);
/// # impl Env for Env1 {
/// #     fn spec(&self) -> &EnvSpec { &self.0 }
/// #     fn reset_into(&mut self, _: Option<u64>, o: &mut Observation) -> Result<(), EnvError> { *o = Observation::flat(vec![0.0]); Ok(()) }
/// #     fn step_into(&mut self, _: &Action, s: &mut Step) -> Result<(), EnvError> { s.terminated = true; Ok(()) }
/// # }
/// # let spec = EnvSpec { id: "E-v0".into(), observation_space: Space::uniform_box(&[1], 0.0, 1.0),
/// #     action_space: Space::Discrete { n: 1 }, max_episode_steps: Some(1), metadata: Default::default() };
/// # let factory = move |_| Ok(Box::new(Env1(spec.clone())) as Box<dyn Env>);
/// /// Keeps resume points in memory.
/// #[derive(Default)]
/// struct Keep(Vec<ResumePoint>);
/// impl CheckpointSink for Keep {
///     fn save(&mut self, _: u64, _: &Checkpoint) -> std::io::Result<()> { Ok(()) }
///     fn keeps_resume_points(&self) -> bool { true }
///     fn save_resume(&mut self, p: &ResumePoint) -> std::io::Result<u64> { self.0.push(p.clone()); Ok(0) }
/// }
/// let settings = TrainingSettings { total_env_steps: 100, checkpoint_interval: 30, ..Default::default() };
/// let mut keep = Keep::default();
/// let mut ctx = TrainingContext::new(&factory, 0, settings.clone(), &mut keep, CancelToken::new());
/// let uninterrupted = train(&mut ctx).unwrap();
/// let curve = ctx.take_curve();
/// // Resume from the point at step 60: the result is the same.
/// let point = keep.0.iter().find(|p| p.progress.env_steps == 60).unwrap().clone();
/// let mut sink = DiscardCheckpoints;
/// let mut ctx = TrainingContext::new(&factory, 0, settings, &mut sink, CancelToken::new()).with_resume(point);
/// assert_eq!(train(&mut ctx).unwrap(), uninterrupted);
/// assert_eq!(ctx.resumed_from(), Some(60));
/// assert_eq!(ctx.curve().returns(), curve.returns());
/// ```
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
    clock_offset: f64,
    last_checkpoint: Option<u64>,
    pending_resume: Option<ResumePoint>,
    resumed_from: Option<u64>,
    resume_writes: Vec<ResumeWrite>,
    warnings: Vec<String>,
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
            clock_offset: 0.0,
            last_checkpoint: None,
            pending_resume: None,
            resumed_from: None,
            resume_writes: Vec::new(),
            warnings: Vec::new(),
        }
    }

    /// Offers `point` to the algorithm: it continues from there if it takes the state with
    /// [`take_resume_state`](Self::take_resume_state) before its first progress call; otherwise
    /// the point is dropped, the sink's resume points are discarded and training starts from
    /// scratch (a warning says so).
    pub fn with_resume(mut self, point: ResumePoint) -> Self {
        self.pending_resume = Some(point);
        self
    }

    /// The algorithm's state saved at the resume point this run continues from, if any. Taking
    /// it restores the context's own part (curve, evaluation and checkpoint schedule, clock).
    pub fn take_resume_state(&mut self) -> Option<Vec<u8>> {
        let point = self.pending_resume.take()?;
        let p = point.progress;
        self.curve = p.curve;
        self.next_eval = p.next_eval;
        self.next_checkpoint = p.next_checkpoint;
        self.last_checkpoint = p.last_checkpoint;
        self.clock_offset = p.clock_s;
        self.resumed_from = Some(p.env_steps);
        Some(point.state)
    }

    /// The environment steps of the resume point this run continued from, if it did.
    pub fn resumed_from(&self) -> Option<u64> {
        self.resumed_from
    }

    /// Resume points written so far: their size and how long each took.
    pub fn resume_writes(&self) -> &[ResumeWrite] {
        &self.resume_writes
    }

    /// Records a warning for the front end (the library never prints).
    pub fn warn(&mut self, message: impl Into<String>) {
        self.warnings.push(message.into());
    }

    /// Warnings recorded so far.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
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

    /// Seconds of training so far, over every segment of a resumed run.
    pub fn clock(&self) -> f64 {
        self.clock_offset + self.started.elapsed().as_secs_f64()
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
        let wall_seconds = self.clock();
        self.curve.points.push(CurvePoint {
            env_steps,
            mean_return,
            std_return,
            wall_seconds,
        });
    }

    /// Call after every batch of environment steps: evaluates and checkpoints when their
    /// intervals are crossed, and says whether to stop (budget spent). On cancellation it
    /// returns [`RunError::Cancelled`] at once; the run then restarts from scratch. Algorithms
    /// that can save their state use [`progress_resumable`](Self::progress_resumable) instead.
    pub fn progress(
        &mut self,
        env_steps: u64,
        policy: &mut dyn Policy,
    ) -> Result<Control, RunError> {
        self.settle_resume()?;
        if self.cancel.is_cancelled() {
            return Err(RunError::Cancelled);
        }
        Ok(self.advance(env_steps, policy)?.0)
    }

    /// [`progress`](Self::progress) for an algorithm that can be resumed: when a resume point
    /// is due (at every checkpoint interval, and at once when cancellation was requested),
    /// `save_state` is called with the policy and returns the algorithm's complete state as
    /// bytes, which [`take_resume_state`](Self::take_resume_state) hands back when the run is
    /// resumed. The point is taken after this call's evaluation and checkpoint, so the resumed
    /// algorithm continues right after this call. On cancellation the point is written and
    /// [`RunError::Cancelled`] returned (unless the budget is spent: then training finishes).
    pub fn progress_resumable<P: Policy>(
        &mut self,
        env_steps: u64,
        policy: &mut P,
        save_state: impl FnOnce(&P) -> Result<Vec<u8>, RunError>,
    ) -> Result<Control, RunError> {
        self.settle_resume()?;
        let done = env_steps >= self.settings.total_env_steps;
        let interrupt = self.cancel.is_cancelled() && !done;
        let keeps = self.checkpoints.keeps_resume_points();
        if interrupt && !keeps {
            return Err(RunError::Cancelled);
        }
        let (control, checkpointed) = self.advance(env_steps, policy)?;
        if keeps && (checkpointed || interrupt) {
            let t = Instant::now();
            let state = save_state(policy)?;
            let point = ResumePoint {
                progress: TrainingProgress {
                    env_steps,
                    curve: self.curve.clone(),
                    next_eval: self.next_eval,
                    next_checkpoint: self.next_checkpoint,
                    last_checkpoint: self.last_checkpoint,
                    clock_s: self.clock(),
                },
                state,
            };
            let bytes = self.checkpoints.save_resume(&point)?;
            self.resume_writes.push(ResumeWrite {
                env_steps,
                bytes,
                seconds: t.elapsed().as_secs_f64(),
            });
        }
        if interrupt {
            return Err(RunError::Cancelled);
        }
        Ok(control)
    }

    /// Evaluation and interval checkpoint at `env_steps`: (whether to stop, whether a
    /// checkpoint was written).
    fn advance(
        &mut self,
        env_steps: u64,
        policy: &mut dyn Policy,
    ) -> Result<(Control, bool), RunError> {
        let done = env_steps >= self.settings.total_env_steps;
        if self.settings.eval_interval > 0 && env_steps >= self.next_eval && !done {
            let (m, s) = self.evaluate(policy)?;
            self.record(env_steps, m, s);
            while self.next_eval <= env_steps {
                self.next_eval += self.settings.eval_interval;
            }
        }
        let mut checkpointed = false;
        if self.settings.checkpoint_interval > 0 && env_steps >= self.next_checkpoint && !done {
            self.save_checkpoint(env_steps, policy)?;
            checkpointed = true;
            while self.next_checkpoint <= env_steps {
                self.next_checkpoint += self.settings.checkpoint_interval;
            }
        }
        let control = if done {
            Control::Stop
        } else {
            Control::Continue
        };
        Ok((control, checkpointed))
    }

    /// A resume point offered but not taken by the first progress call is dropped: the
    /// algorithm started from scratch, so older resume points must not outlive this run.
    fn settle_resume(&mut self) -> Result<(), RunError> {
        if let Some(p) = self.pending_resume.take() {
            self.checkpoints.discard_resume_points()?;
            self.warn(format!(
                "the algorithm did not take the resume point at step {}; trained from scratch",
                p.progress.env_steps
            ));
        }
        Ok(())
    }

    /// Ends training at `env_steps`: records a final evaluation and a final checkpoint (unless one
    /// was already taken at exactly this step).
    pub fn finish(&mut self, env_steps: u64, policy: &mut dyn Policy) -> Result<(), RunError> {
        self.settle_resume()?;
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
