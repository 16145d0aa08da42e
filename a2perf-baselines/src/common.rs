//! Pieces shared by the algorithms: hyperparameter reading, environment setup, network choice.

use a2perf_core::{
    Control, EnvSpec, ParamKind, ParamSpec, Params, Policy, RngStream, RunError, Space, TimeSplit,
    TrainingContext, Value, VecEnv, VecStep,
};

use crate::batch::{ObsBatch, ObsLayout};
use crate::model::{DiscreteNet, GaussianArch, NetOptions};
use crate::nn::optim::LrSchedule;
use crate::policy::{Head, NetPolicy};
use crate::replay::ReplayBuffer;

pub(crate) fn hp(e: a2perf_core::ParamError) -> RunError {
    RunError::InvalidHyperparameter {
        name: match &e {
            a2perf_core::ParamError::Unknown { key, .. }
            | a2perf_core::ParamError::WrongType { key, .. }
            | a2perf_core::ParamError::Missing { key, .. } => key.clone(),
        },
        reason: e.to_string(),
    }
}

pub(crate) fn invalid(name: &str, reason: &str) -> RunError {
    RunError::InvalidHyperparameter {
        name: name.into(),
        reason: reason.into(),
    }
}

pub(crate) fn positive_f32(p: &Params, name: &str) -> Result<f32, RunError> {
    let v = p.f64(name).map_err(hp)?;
    if !(v.is_finite() && v > 0.0) {
        return Err(invalid(name, "must be a positive number"));
    }
    Ok(v as f32)
}

pub(crate) fn unit_f32(p: &Params, name: &str) -> Result<f32, RunError> {
    let v = p.f64(name).map_err(hp)?;
    if !(0.0..=1.0).contains(&v) {
        return Err(invalid(name, "must be in [0, 1]"));
    }
    Ok(v as f32)
}

pub(crate) fn nonneg_f32(p: &Params, name: &str) -> Result<f32, RunError> {
    let v = p.f64(name).map_err(hp)?;
    if !(v.is_finite() && v >= 0.0) {
        return Err(invalid(name, "must be a non-negative number"));
    }
    Ok(v as f32)
}

pub(crate) fn positive_usize(p: &Params, name: &str) -> Result<usize, RunError> {
    let v = p.usize(name).map_err(hp)?;
    if v == 0 {
        return Err(invalid(name, "must be at least 1"));
    }
    Ok(v)
}

/// Hyperparameters of the networks, shared by every algorithm.
pub(crate) fn net_specs(default_hidden: &[i64]) -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            "architecture",
            ParamKind::Choice(&["auto", "mlp"]),
            Value::Str("auto".into()),
            "network: `auto` picks the web/circuit encoders from the observation tensors, `mlp` always flattens",
        ),
        ParamSpec::new(
            "hidden_sizes",
            ParamKind::IntList,
            Value::List(default_hidden.iter().map(|h| Value::Int(*h)).collect()),
            "hidden layer sizes of the MLPs (paper: 512, 256 for locomotion)",
        ),
        ParamSpec::new(
            "embedding_dim",
            ParamKind::Int,
            Value::Int(100),
            "token embedding width of the web encoder (paper: 100)",
        ),
        ParamSpec::new(
            "latent_dim",
            ParamKind::Int,
            Value::Int(50),
            "element/field latent width (web, paper: 50) and per-cell hidden width (circuit)",
        ),
    ]
}

pub(crate) fn net_options(p: &Params) -> Result<NetOptions, RunError> {
    let hidden: Vec<usize> = match p.get("hidden_sizes") {
        Some(Value::List(items)) => items
            .iter()
            .map(|v| {
                v.as_i64()
                    .and_then(|i| usize::try_from(i).ok())
                    .filter(|i| *i > 0)
            })
            .collect::<Option<Vec<_>>>()
            .ok_or_else(|| invalid("hidden_sizes", "must be a list of positive integers"))?,
        _ => {
            return Err(invalid(
                "hidden_sizes",
                "must be a list of positive integers",
            ));
        }
    };
    if hidden.is_empty() {
        return Err(invalid("hidden_sizes", "needs at least one layer"));
    }
    Ok(NetOptions {
        architecture: p.str("architecture").map_err(hp)?.to_string(),
        hidden_sizes: hidden,
        embedding_dim: positive_usize(p, "embedding_dim")?,
        latent_dim: positive_usize(p, "latent_dim")?,
    })
}

pub(crate) fn schedule_specs() -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            "lr_schedule",
            ParamKind::Choice(&["constant", "cosine"]),
            Value::Str("constant".into()),
            "learning-rate schedule over the training budget (circuit PPO in the paper: cosine)",
        ),
        ParamSpec::new(
            "lr_final_fraction",
            ParamKind::Float,
            Value::Float(0.1),
            "final learning rate of the cosine schedule as a fraction of the initial (paper: alpha = 0.1)",
        ),
    ]
}

pub(crate) fn schedule(p: &Params, lr: f32) -> Result<LrSchedule, RunError> {
    Ok(match p.str("lr_schedule").map_err(hp)? {
        "cosine" => LrSchedule::Cosine {
            initial: lr,
            final_fraction: unit_f32(p, "lr_final_fraction")?,
        },
        _ => LrSchedule::Constant(lr),
    })
}

/// Builds `settings.num_envs` training environments, stepped in parallel.
pub(crate) fn make_vec_env(ctx: &TrainingContext<'_>) -> Result<(VecEnv, EnvSpec), RunError> {
    let n = ctx.settings().num_envs.max(1);
    let envs = (0..n)
        .map(|i| ctx.make_env(i))
        .collect::<Result<Vec<_>, _>>()?;
    let spec = envs
        .first()
        .map(|e| e.spec().clone())
        .ok_or_else(|| RunError::Unsupported("no environment".into()))?;
    Ok((VecEnv::new(envs, ctx.seed()), spec))
}

/// The network of a policy for `spec`: discrete (auto-chosen encoder) or diagonal Gaussian.
pub(crate) fn head_for(
    spec: &EnvSpec,
    layout: &ObsLayout,
    opts: &NetOptions,
    with_value: bool,
) -> Result<Head, RunError> {
    match &spec.action_space {
        Space::Discrete { .. } => Ok(Head::Discrete(DiscreteNet::for_spec(
            spec, layout, opts, with_value,
        )?)),
        Space::Box { low, .. } => Ok(Head::Gaussian(GaussianArch::new(
            layout.total_dim(),
            low.len(),
            &opts.hidden_sizes,
            with_value,
        ))),
        Space::Dict(_) => Err(RunError::Unsupported(
            "dict action spaces are not supported".into(),
        )),
    }
}

pub(crate) fn check_finite(what: &str, v: &[f32]) -> Result<(), RunError> {
    if v.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(RunError::Diverged(format!("{what} became non-finite")))
    }
}

/// Fresh parameters for `head` (a masked categorical or a Gaussian with log-std
/// `init_log_std`; a squashed head is SAC's, which initialises its own).
pub(crate) fn initial_params(
    head: &Head,
    rng: &mut RngStream,
    init_log_std: f32,
) -> Result<Vec<f32>, RunError> {
    match head {
        Head::Discrete(net) => Ok(net.init_params(rng)),
        Head::Gaussian(g) => Ok(g.init_params(rng, init_log_std)),
        Head::Squashed(_) => Err(RunError::Unsupported("squashed head".into())),
    }
}

/// Row `i` of `batch` becomes environment `i`'s current observation (after a reset, a resume
/// or a step).
pub(crate) fn write_observations(batch: &mut ObsBatch, outs: &[VecStep]) -> Result<(), RunError> {
    for (i, out) in outs.iter().enumerate() {
        batch.write_row(i, &out.step.observation)?;
    }
    Ok(())
}

/// Stores one step of every environment in `replay`, from its row of `cur` (the observation
/// the action was chosen on) to its next observation (an ended episode's final one), with
/// discrete action `act_d(i)` or the `d` continuous values of row `i` of `act_c`; then the new
/// observations become `cur`.
pub(crate) fn push_transitions(
    replay: &mut ReplayBuffer,
    cur: &mut ObsBatch,
    outs: &[VecStep],
    act_d: impl Fn(usize) -> usize,
    act_c: &[f32],
    d: usize,
) -> Result<(), RunError> {
    for (i, out) in outs.iter().enumerate() {
        let next = if out.step.done() {
            &out.final_observation
        } else {
            &out.step.observation
        };
        replay.push(
            i,
            cur,
            i,
            next,
            act_d(i),
            &act_c[i * d..(i + 1) * d],
            out.step.reward as f32,
            out.step.terminated,
        )?;
    }
    write_observations(cur, outs)
}

/// An online algorithm's run between its setup and its end: one iteration of its loop (act,
/// step the environments, learn), its step count, its resume state and its environments.
/// [`drive`] runs the loop the same way for every algorithm.
pub(crate) trait OnlineRun {
    /// Continues from a state written by [`save_state`](Self::save_state).
    fn restore(
        &mut self,
        bytes: &[u8],
        policy: &mut NetPolicy,
        ctx: &mut TrainingContext<'_>,
    ) -> Result<(), RunError>;
    /// Resets every environment and stores the first observations (a fresh start).
    fn reset(&mut self) -> Result<(), RunError>;
    /// One iteration of the loop, its acting, stepping and learning timed into `split`.
    fn iterate(&mut self, policy: &mut NetPolicy, split: &mut TimeSplit) -> Result<(), RunError>;
    /// Environment steps taken so far.
    fn env_steps(&self) -> u64;
    /// Everything the run needs to continue exactly, besides what the context keeps.
    fn save_state(&self, policy: &NetPolicy) -> Vec<u8>;
    /// Closes the environments.
    fn close(&mut self) -> Result<(), RunError>;
}

/// Runs `run` from its resume state (or a reset) until the context stops it, then evaluates
/// and checkpoints the final policy and closes the environments.
pub(crate) fn drive(
    mut run: impl OnlineRun,
    mut policy: NetPolicy,
    resume: Option<Vec<u8>>,
    ctx: &mut TrainingContext<'_>,
) -> Result<Box<dyn Policy>, RunError> {
    match &resume {
        Some(bytes) => run.restore(bytes, &mut policy, ctx)?,
        None => run.reset()?,
    }
    loop {
        run.iterate(&mut policy, ctx.time_split_mut())?;
        let save = |p: &NetPolicy| Ok(run.save_state(p));
        if ctx.progress_resumable(run.env_steps(), &mut policy, save)? == Control::Stop {
            break;
        }
    }
    ctx.finish(run.env_steps(), &mut policy)?;
    run.close()?;
    Ok(Box::new(policy))
}
