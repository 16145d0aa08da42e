//! Algorithms and the training context they run in: budgets, evaluations, checkpoints, resume
//! points and cancellation.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::cancel::CancelToken;
use crate::checkpoint::Checkpoint;
use crate::curve::{CurvePoint, LearningCurve};
use crate::env::{Env, EnvError};
use crate::error::RunError;
use crate::policy::{ActMode, Policy};
use crate::resume::{ResumeDir, ResumePoint, ResumeWrite, TrainingProgress};
use crate::rng::RngStream;
use crate::rollout::rollout;
use crate::time_split::{TimePart, TimeSplit};

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
    /// The second evaluation environment, for a policy that forks ([`Policy::fork`]).
    eval_env_b: Option<Box<dyn Env>>,
    started: Instant,
    clock_offset: f64,
    last_checkpoint: Option<u64>,
    pending_resume: Option<ResumePoint>,
    resumed_from: Option<u64>,
    resume_writes: Vec<ResumeWrite>,
    warnings: Vec<String>,
    split: TimeSplit,
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
            eval_env_b: None,
            started: Instant::now(),
            clock_offset: 0.0,
            last_checkpoint: None,
            pending_resume: None,
            resumed_from: None,
            resume_writes: Vec::new(),
            warnings: Vec::new(),
            split: TimeSplit::default(),
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

    /// Where the run's time went so far (see [`TimeSplit`]).
    pub fn time_split(&self) -> &TimeSplit {
        &self.split
    }

    /// The split, for an algorithm to time its own parts (acting, stepping, learning) into.
    pub fn time_split_mut(&mut self) -> &mut TimeSplit {
        &mut self.split
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
    ///
    /// A policy that forks ([`Policy::fork`]) plays the episodes on two threads of rayon's pool,
    /// the copy in a second evaluation environment, each thread taking the next episode not yet
    /// begun. An episode's return depends on its seed and the policy's greedy actions alone, and
    /// the returns are summed in episode order, so the mean and std are those of the episodes
    /// one after the other, to the bit.
    pub fn evaluate(&mut self, policy: &mut dyn Policy) -> Result<(f64, f64), RunError> {
        let t = Instant::now();
        let r = self.evaluate_untimed(policy);
        self.split
            .add(TimePart::Evaluation, t.elapsed().as_secs_f64());
        r
    }

    fn evaluate_untimed(&mut self, policy: &mut dyn Policy) -> Result<(f64, f64), RunError> {
        if self.eval_env.is_none() {
            self.eval_env = Some((self.env_factory)(usize::MAX)?);
        }
        let seeds = RngStream::new(self.seed, "evaluation-seeds");
        let n = self.settings.eval_episodes.max(1);
        let seeds: Vec<u64> = (0..n)
            .map(|i| seeds.derive_index(i as u64).next_u64())
            .collect();
        let fork = if n > 1 && rayon::current_num_threads() > 1 {
            policy.fork()
        } else {
            None
        };
        if fork.is_some() && self.eval_env_b.is_none() {
            self.eval_env_b = Some((self.env_factory)(usize::MAX - 1)?);
        }
        let (Some(env), env_b) = (self.eval_env.as_deref_mut(), self.eval_env_b.as_deref_mut())
        else {
            return Err(RunError::Cancelled);
        };
        let mut returns = vec![0.0; n];
        match (fork, env_b) {
            (Some(mut copy), Some(env_b)) => {
                let next = AtomicUsize::new(0);
                let play = |env: &mut dyn Env, policy: &mut dyn Policy| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= n {
                            return Ok(done);
                        }
                        let ep = rollout(env, policy, seeds[i], ActMode::Greedy, false)?;
                        done.push((i, ep.episode_return));
                    }
                };
                let (a, b): (Result<_, RunError>, Result<_, RunError>) =
                    rayon::join(|| play(env, policy), || play(env_b, copy.as_mut()));
                for (i, r) in a?.into_iter().chain(b?) {
                    returns[i] = r;
                }
            }
            _ => {
                for (r, &seed) in returns.iter_mut().zip(&seeds) {
                    *r = rollout(env, policy, seed, ActMode::Greedy, false)?.episode_return;
                }
            }
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
            let seconds = t.elapsed().as_secs_f64();
            self.split.add(TimePart::Io, seconds);
            self.resume_writes.push(ResumeWrite {
                env_steps,
                bytes,
                seconds,
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
        let t = Instant::now();
        let ckpt = policy.checkpoint()?;
        self.checkpoints.save(env_steps, &ckpt)?;
        self.split.add(TimePart::Io, t.elapsed().as_secs_f64());
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
