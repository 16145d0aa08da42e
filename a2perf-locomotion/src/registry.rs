//! Registration of the locomotion environments and the generalization suite.
//!
//! Ids: `QuadrupedLocomotion-DogPace-v0`, `-DogTrot-v0`, `-DogSpin-v0` (the original's names) and
//! `QuadrupedLocomotion-Gait-v0`, whose `gait` parameter selects any built-in gait (pace, trot,
//! spin, bound, pronk, side_step, turn). The generalization suite runs dog_pace, dog_trot and
//! dog_spin (as in A2Perf) plus bound, pronk, side_step and turn through `Gait-v0`.

use std::collections::BTreeMap;
use std::sync::Arc;

use a2perf_core::{EnvEntry, EnvError, ParamKind, ParamSpec, Params, Registry, TaskRef, Value};

use crate::env::{EnvConfig, LocomotionEnv, Mode, MotionSource};
use crate::gait::Gait;
use crate::sim::Physics;

/// Domain name.
pub const DOMAIN: &str = "quadruped_locomotion";

const GAIT_NAMES: &[&str] = &[
    "pace",
    "trot",
    "spin",
    "bound",
    "pronk",
    "side_step",
    "turn",
];

fn common_params() -> Vec<ParamSpec> {
    vec![
        ParamSpec::new(
            "motion_file",
            ParamKind::Path,
            Value::Null,
            "motion_imitation JSON clip; default: the built-in generated gait",
        ),
        ParamSpec::new(
            "mode",
            ParamKind::Choice(&["test", "train"]),
            Value::Str("test".into()),
            "test: fixed 600-step episodes; train: domain randomisation + episode-length curriculum",
        ),
        ParamSpec::new(
            "episode_steps",
            ParamKind::Int,
            Value::Int(600),
            "episode length (test mode) and final curriculum length",
        ),
        ParamSpec::new(
            "curriculum_steps",
            ParamKind::Float,
            Value::Float(30e6),
            "train mode: steps that do not end an episode until episodes reach full length",
        ),
        ParamSpec::new(
            "randomize",
            ParamKind::Bool,
            Value::Null,
            "domain randomisation of mass, inertia, motor strength, latency, foot friction and knee joint friction (default: on in train mode)",
        ),
        ParamSpec::new(
            "ref_state_init_prob",
            ParamKind::Float,
            Value::Float(0.9),
            "probability of a random-phase start",
        ),
        ParamSpec::new(
            "control_latency",
            ParamKind::Float,
            Value::Float(0.002),
            "observation latency [s]",
        ),
        ParamSpec::new(
            "solver_iterations",
            ParamKind::Int,
            Value::Int(1),
            "solver iterations per 1 ms step (rapier: 2 gives ~6x tighter joints, ~35% slower; articulated: 4 Gauss-Seidel sweeps each)",
        )
        .follows_run(),
        ParamSpec::new(
            "physics",
            ParamKind::Str,
            Value::Str("rapier".into()),
            "physics engine: rapier (13 bodies and impulse joints; every recorded result) or articulated (reduced coordinates, exact joints, about twice as fast, different trajectories); the generalization tasks follow the run's",
        )
        .follows_run(),
        ParamSpec::new(
            "time_limit_terminates",
            ParamKind::Bool,
            Value::Bool(false),
            "report the episode-length limit as terminated (A2Perf: its gymnasium compatibility layer turns motion_imitation's time limit into terminated=True) instead of truncated",
        ),
    ]
}

fn bad(name: &str, e: impl std::fmt::Display) -> EnvError {
    EnvError::InvalidParameter {
        name: name.into(),
        reason: e.to_string(),
    }
}

/// Builds an [`EnvConfig`] from resolved parameters.
pub fn config_from_params(
    id: &str,
    default_gait: Option<Gait>,
    p: &Params,
) -> Result<EnvConfig, EnvError> {
    let gait = match default_gait {
        Some(g) => g,
        None => {
            let name = p.str("gait").map_err(|e| bad("gait", e))?;
            Gait::from_name(name).ok_or_else(|| bad("gait", format!("unknown gait `{name}`")))?
        }
    };
    let motion = match p
        .opt_str("motion_file")
        .map_err(|e| bad("motion_file", e))?
    {
        Some(path) => MotionSource::File(path.to_string()),
        None => MotionSource::Generated(gait),
    };
    let mut c = EnvConfig::new(id, motion);
    c.mode = match p.str("mode").map_err(|e| bad("mode", e))? {
        "train" => Mode::Train,
        _ => Mode::Test,
    };
    c.episode_steps = p
        .usize("episode_steps")
        .map_err(|e| bad("episode_steps", e))?;
    if c.episode_steps == 0 {
        return Err(bad("episode_steps", "must be at least 1"));
    }
    c.curriculum_steps = p
        .f64("curriculum_steps")
        .map_err(|e| bad("curriculum_steps", e))?;
    c.randomize = match p.get("randomize") {
        Some(v) => v
            .as_bool()
            .ok_or_else(|| bad("randomize", "expected a bool"))?,
        None => c.mode == Mode::Train,
    };
    c.ref_state_init_prob = p
        .f64("ref_state_init_prob")
        .map_err(|e| bad("ref_state_init_prob", e))?;
    if !(0.0..=1.0).contains(&c.ref_state_init_prob) {
        return Err(bad("ref_state_init_prob", "must be in [0, 1]"));
    }
    c.control_latency = p
        .f64("control_latency")
        .map_err(|e| bad("control_latency", e))?;
    if !(0.0..=0.05).contains(&c.control_latency) {
        return Err(bad("control_latency", "must be in [0, 0.05] s"));
    }
    let it = p
        .usize("solver_iterations")
        .map_err(|e| bad("solver_iterations", e))?;
    if !(1..=50).contains(&it) {
        return Err(bad("solver_iterations", "must be in 1..=50"));
    }
    c.solver_iterations = it;
    let physics = p.str("physics").map_err(|e| bad("physics", e))?;
    c.physics = Physics::from_name(physics).ok_or_else(|| {
        bad(
            "physics",
            format!("unknown engine `{physics}` (expected rapier or articulated)"),
        )
    })?;
    c.time_limit_terminates = p
        .bool("time_limit_terminates")
        .map_err(|e| bad("time_limit_terminates", e))?;
    Ok(c)
}

fn entry(id: &str, summary: &str, gait: Option<Gait>) -> EnvEntry {
    let mut params = common_params();
    if gait.is_none() {
        params.insert(
            0,
            ParamSpec::new(
                "gait",
                ParamKind::Choice(GAIT_NAMES),
                Value::Str("pace".into()),
                "built-in gait to imitate",
            ),
        );
    }
    let id_owned = id.to_string();
    EnvEntry {
        id: id.into(),
        domain: DOMAIN.into(),
        summary: summary.into(),
        params,
        make: Arc::new(move |p: &Params| {
            let cfg = config_from_params(&id_owned, gait, p)?;
            Ok(Box::new(LocomotionEnv::new(cfg)?) as Box<dyn a2perf_core::Env>)
        }),
    }
}

/// Registers the locomotion environments and the generalization suite.
///
/// ```
/// let mut reg = a2perf_core::Registry::new();
/// a2perf_locomotion::register(&mut reg);
/// assert!(reg.env("QuadrupedLocomotion-DogPace-v0").is_ok());
/// assert_eq!(reg.generalization("quadruped_locomotion").len(), 7);
/// ```
pub fn register(reg: &mut Registry) {
    reg.register_env(entry(
        "QuadrupedLocomotion-DogPace-v0",
        "Laikago imitating a pace (rapier3d)",
        Some(Gait::Pace),
    ));
    reg.register_env(entry(
        "QuadrupedLocomotion-DogTrot-v0",
        "Laikago imitating a trot (rapier3d)",
        Some(Gait::Trot),
    ));
    reg.register_env(entry(
        "QuadrupedLocomotion-DogSpin-v0",
        "Laikago imitating an in-place spin (rapier3d)",
        Some(Gait::Spin),
    ));
    reg.register_env(entry(
        "QuadrupedLocomotion-Gait-v0",
        "Laikago imitating a built-in gait chosen by `gait`",
        None,
    ));
    let mut tasks = vec![
        TaskRef {
            name: "dog_pace".into(),
            env_id: "QuadrupedLocomotion-DogPace-v0".into(),
            params: BTreeMap::new(),
        },
        TaskRef {
            name: "dog_trot".into(),
            env_id: "QuadrupedLocomotion-DogTrot-v0".into(),
            params: BTreeMap::new(),
        },
        TaskRef {
            name: "dog_spin".into(),
            env_id: "QuadrupedLocomotion-DogSpin-v0".into(),
            params: BTreeMap::new(),
        },
    ];
    for g in [Gait::Bound, Gait::Pronk, Gait::SideStep, Gait::Turn] {
        let mut params = BTreeMap::new();
        params.insert("gait".to_string(), Value::Str(g.name().into()));
        tasks.push(TaskRef {
            name: g.name().into(),
            env_id: "QuadrupedLocomotion-Gait-v0".into(),
            params,
        });
    }
    reg.register_generalization(DOMAIN, tasks);
}
