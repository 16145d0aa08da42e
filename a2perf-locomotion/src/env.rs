//! The motion-imitation environment (`QuadrupedLocomotion-Dog*-v0`).
//!
//! Observation: one tensor `"obs"` of shape \[160\]:
//! `[0:12]` IMU × 3 (roll, pitch, ω_x, ω_y; newest first), `[12:48]` last action × 3 (motor-space
//! PD targets before filtering), `[48:84]` motor angles × 3 (motor space, latency-delayed, wrapped
//! to [−π, π)), `[84:160]` reference frames at +1, +2, +10, +30 control steps (19 values each:
//! root position relative to the current reference root in the robot's heading frame, root
//! quaternion `heading⁻¹ ⊗ q_ref` in the URDF-base convention (x, y, z, w; w ≥ 0), 12 URDF
//! joint angles).
//!
//! Rendering: [`Env::render`] with `"rgb_array"` draws a 320×240 side view of the robot and the
//! reference pose ([`crate::render::side_view`]), only when called.
//!
//! Action: `Box(−2π, 2π, [12])`, **offsets around the default motor pose** (as the reference's
//! `LaikagoPoseOffsetGenerator`): the PD target is `[0, 0.67, −1.25]×4 + a` in motor space. Actions
//! are not residuals around the reference pose. Out-of-box values are clipped (the original's
//! `ActionClipWrapper`); non-finite values or a wrong length are errors.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

use a2perf_core::{
    Action, DType, Env, EnvError, EnvSpec, Frame, Observation, RngStream, Space, Step, Tensor,
};
use nalgebra::{UnitQuaternion, Vector3};

use crate::filter::ActionFilter;
use crate::gait::{self, Gait};
use crate::model::{NUM_LEGS, NUM_MOTORS, RobotModel};
use crate::motion::{
    MotionClip, MotionFrame, MotionVelocity, ReferenceMotion, heading_of, yaw_rotation,
};
use crate::render::{side_view, state_points};
use crate::sim::{Physics, RobotState, SimConfig, Simulation};

/// Observation size.
pub const OBS_DIM: usize = 160;
/// Physics substeps per control step.
pub const ACTION_REPEAT: usize = 33;
/// Physics step \[s\].
pub const SIM_DT: f64 = 0.001;
/// Control step \[s\].
pub const CONTROL_DT: f64 = SIM_DT * ACTION_REPEAT as f64;
/// Future reference frames in the observation, in control steps.
pub const TARGET_STEPS: [usize; 4] = [1, 2, 10, 30];
/// Largest PD-target change allowed around the observed angle per substep \[rad\].
pub const MAX_MOTOR_ANGLE_CHANGE: f64 = 0.2;
/// Action bound (|a| ≤ 2π).
pub const ACTION_LIMIT: f64 = 2.0 * PI;
/// Train-mode knee joint friction range [N·m], sampled per knee at every reset (the reference's
/// joint-friction randomisation on the foot-link joints, of which only the knees move).
pub const KNEE_FRICTION_RANGE: (f64, f64) = (0.0, 0.05);

/// Reward weights: pose, velocity, end effector, root pose, root velocity.
pub const REWARD_WEIGHTS: [f64; 5] = [0.5, 0.05, 0.2, 0.15, 0.1];

/// Keys of `Step::info`, in order.
pub const INFO_KEYS: [&str; 6] = [
    "reward_pose",
    "reward_velocity",
    "reward_end_effector",
    "reward_root_pose",
    "reward_root_velocity",
    "reference_time",
];

/// Test (evaluation) or train mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// No randomisation, fixed episode length.
    Test,
    /// Domain randomisation and the episode-length curriculum.
    Train,
}

/// Which clip the task imitates.
#[derive(Clone, Debug, PartialEq)]
pub enum MotionSource {
    /// A built-in generated gait.
    Generated(Gait),
    /// A motion_imitation JSON clip file.
    File(String),
    /// A clip already in memory.
    Clip(MotionClip),
}

/// Environment configuration.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvConfig {
    /// Registered id to report in the spec.
    pub id: String,
    /// The clip.
    pub motion: MotionSource,
    /// Test or train mode.
    pub mode: Mode,
    /// Episode length in test mode (and the curriculum's final length).
    pub episode_steps: usize,
    /// Curriculum horizon in steps that do not end an episode (train mode):
    /// `T = (1−s³)·20 + s³·episode_steps`.
    pub curriculum_steps: f64,
    /// Probability of starting at a random phase (otherwise a warm-up episode).
    pub ref_state_init_prob: f64,
    /// Observation latency \[s\] (randomised in train mode).
    pub control_latency: f64,
    /// Domain randomisation, resampled at every reset: mass ×U[0.8, 1.2] and inertia ×U[0.5, 1.5]
    /// (base and leg groups), motor strength ×U[0.8, 1.2] per motor, latency U[0, 0.04] s, foot
    /// friction U[0.5, 1.25], knee joint friction [`KNEE_FRICTION_RANGE`] per knee (the
    /// reference's ranges). The registry turns it on by default in train mode.
    pub randomize: bool,
    /// Solver iterations per physics step (see [`SimConfig::solver_iterations`]).
    pub solver_iterations: usize,
    /// The physics engine (rapier by default, the engine of every recorded result).
    pub physics: Physics,
    /// End an episode at the length limit with `terminated` (A2Perf's environment, whose
    /// gymnasium compatibility layer reports motion_imitation's time limit as a termination)
    /// instead of `truncated` (Gymnasium semantics, what motion_imitation's own `info` says).
    pub time_limit_terminates: bool,
}

impl EnvConfig {
    /// Test-mode defaults for a built-in gait.
    pub fn new(id: &str, motion: MotionSource) -> Self {
        Self {
            id: id.into(),
            motion,
            mode: Mode::Test,
            episode_steps: 600,
            curriculum_steps: 30e6,
            ref_state_init_prob: 0.9,
            control_latency: 0.002,
            randomize: false,
            solver_iterations: SimConfig::default().solver_iterations,
            physics: Physics::Rapier,
            time_limit_terminates: false,
        }
    }
}

/// The five reward terms (each in (0, 1]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RewardTerms {
    /// Joint pose.
    pub pose: f64,
    /// Joint velocity.
    pub velocity: f64,
    /// End effectors (toes and lower legs).
    pub end_effector: f64,
    /// Root pose.
    pub root_pose: f64,
    /// Root velocity.
    pub root_velocity: f64,
}

impl RewardTerms {
    /// Weighted sum.
    pub fn total(&self) -> f64 {
        let w = REWARD_WEIGHTS;
        w[0] * self.pose
            + w[1] * self.velocity
            + w[2] * self.end_effector
            + w[3] * self.root_pose
            + w[4] * self.root_velocity
    }
}

/// Why an episode terminated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Termination {
    /// A link other than toes and lower legs touched the ground.
    BodyContact,
    /// Root position error² exceeded 1 m².
    RootPosition,
    /// Root rotation error exceeded π/2.
    RootRotation,
}

#[derive(Clone, Copy, Debug, Default)]
struct Reading {
    motor: [f64; NUM_MOTORS],
    imu: [f64; 4],
}

/// Ring buffer of per-substep sensor readings (newest first when read).
#[derive(Clone, Debug)]
struct History {
    buf: [Reading; 64],
    head: usize,
    len: usize,
}

impl History {
    fn new() -> Self {
        Self {
            buf: [Reading::default(); 64],
            head: 0,
            len: 0,
        }
    }
    fn clear(&mut self) {
        self.len = 0;
    }
    fn push(&mut self, r: Reading) {
        self.head = (self.head + 1) % self.buf.len();
        self.buf[self.head] = r;
        self.len = (self.len + 1).min(self.buf.len());
    }
    fn ago(&self, n: usize) -> &Reading {
        let n = n.min(self.len.saturating_sub(1));
        &self.buf[(self.head + self.buf.len() - n) % self.buf.len()]
    }
    /// motion_imitation's `_GetDelayedObservation`: linear blend of the readings around
    /// `latency` ago; the oldest reading when the history is too short.
    fn delayed(&self, latency: f64, dt: f64) -> Reading {
        if latency <= 0.0 || self.len <= 1 {
            return *self.ago(0);
        }
        let n = (latency / dt + 1e-9).floor() as usize;
        if n + 1 >= self.len {
            return *self.ago(self.len - 1);
        }
        let alpha = ((latency - n as f64 * dt) / dt).clamp(0.0, 1.0);
        let (a, b) = (self.ago(n), self.ago(n + 1));
        Reading {
            motor: std::array::from_fn(|j| (1.0 - alpha) * a.motor[j] + alpha * b.motor[j]),
            imu: std::array::from_fn(|j| (1.0 - alpha) * a.imu[j] + alpha * b.imu[j]),
        }
    }
}

/// The imitation environment.
pub struct LocomotionEnv {
    spec: EnvSpec,
    config: EnvConfig,
    model: RobotModel,
    sim: Simulation,
    motion: ReferenceMotion,
    rng: RngStream,
    /// Knee-friction draws, a separate stream so that adding them left every other draw (DR
    /// parameters, start phase) unchanged for a given seed.
    knee_rng: RngStream,
    history: History,
    filter: ActionFilter,
    prev_filtered: Option<[f64; NUM_MOTORS]>,
    latency: f64,
    /// Sensor histories at control rate, newest first: IMU, last action, motor angles.
    imu_hist: [[f64; 4]; 3],
    action_hist: [[f64; NUM_MOTORS]; 3],
    motor_hist: [[f64; NUM_MOTORS]; 3],
    time_offset: f64,
    substeps: u64,
    steps: usize,
    episode_limit: usize,
    origin_rot: UnitQuaternion<f64>,
    origin_pos: Vector3<f64>,
    last_cycle: i64,
    total_nonterminal_steps: u64,
    needs_reset: bool,
    last_terms: RewardTerms,
    last_termination: Option<Termination>,
}

fn motion_for(model: &RobotModel, source: &MotionSource) -> Result<(MotionClip, String), EnvError> {
    match source {
        MotionSource::Generated(g) => Ok((gait::generate(model, *g), "builtin-generator".into())),
        MotionSource::File(path) => {
            let clip = MotionClip::load(Path::new(path)).map_err(|e| EnvError::BadFile {
                path: path.clone(),
                reason: match e {
                    crate::motion::MotionError::Io { source, .. } => source.to_string(),
                    crate::motion::MotionError::Invalid { reason, .. } => reason,
                },
            })?;
            Ok((clip, path.clone()))
        }
        MotionSource::Clip(clip) => Ok((clip.clone(), "in-memory".into())),
    }
}

impl LocomotionEnv {
    /// Builds the environment.
    ///
    /// ```
    /// use a2perf_core::{Action, Env};
    /// use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, MotionSource};
    /// use a2perf_locomotion::gait::Gait;
    /// let cfg = EnvConfig::new("QuadrupedLocomotion-DogPace-v0", MotionSource::Generated(Gait::Pace));
    /// let mut env = LocomotionEnv::new(cfg).unwrap();
    /// let obs = env.reset(Some(0)).unwrap();
    /// assert_eq!(obs.tensor("obs").unwrap().data.len(), 160);
    /// let step = env.step(&Action::Continuous(vec![0.0; 12])).unwrap();
    /// assert!(step.reward > 0.0 && step.reward <= 1.0);
    /// ```
    pub fn new(config: EnvConfig) -> Result<Self, EnvError> {
        let model = RobotModel::builtin();
        let (clip, source) = motion_for(&model, &config.motion)?;
        let motion = ReferenceMotion::new(clip);
        let sim = Simulation::new(
            &model,
            SimConfig {
                dt: SIM_DT,
                solver_iterations: config.solver_iterations,
                physics: config.physics,
            },
        );
        let mut metadata = BTreeMap::new();
        metadata.insert("clip".into(), motion.clip().name.clone());
        metadata.insert("clip_hash".into(), motion.clip().content_hash());
        metadata.insert("clip_source".into(), source);
        metadata.insert("mode".into(), format!("{:?}", config.mode).to_lowercase());
        metadata.insert("robot".into(), model.name.clone());
        metadata.insert(
            "physics".into(),
            match config.physics {
                Physics::Rapier => format!(
                    "rapier3d 0.36, impulse joints, dt {SIM_DT} s x {ACTION_REPEAT}, {} solver iterations",
                    config.solver_iterations
                ),
                Physics::Articulated => format!(
                    "articulated (reduced coordinates), dt {SIM_DT} s x {ACTION_REPEAT}, {} solver iterations",
                    config.solver_iterations
                ),
            },
        );
        metadata.insert(
            "action".into(),
            "offset from default motor pose [0, 0.67, -1.25]x4".into(),
        );
        let spec = EnvSpec {
            id: config.id.clone(),
            observation_space: observation_space(&motion, &model),
            action_space: Space::uniform_box(
                &[NUM_MOTORS],
                -ACTION_LIMIT as f32,
                ACTION_LIMIT as f32,
            ),
            max_episode_steps: Some(config.episode_steps),
            metadata,
        };
        Ok(Self {
            spec,
            rng: RngStream::new(0, "locomotion-episode"),
            knee_rng: RngStream::new(0, "locomotion-episode").derive("knee-friction"),
            latency: config.control_latency,
            episode_limit: config.episode_steps,
            config,
            model,
            sim,
            motion,
            history: History::new(),
            filter: ActionFilter::default(),
            prev_filtered: None,
            imu_hist: [[0.0; 4]; 3],
            action_hist: [[0.0; NUM_MOTORS]; 3],
            motor_hist: [[0.0; NUM_MOTORS]; 3],
            time_offset: 0.0,
            substeps: 0,
            steps: 0,
            origin_rot: UnitQuaternion::identity(),
            origin_pos: Vector3::zeros(),
            last_cycle: 0,
            total_nonterminal_steps: 0,
            needs_reset: true,
            last_terms: RewardTerms::default(),
            last_termination: None,
        })
    }

    /// The reference motion.
    pub fn motion(&self) -> &ReferenceMotion {
        &self.motion
    }

    /// The simulation (read-only).
    pub fn sim(&self) -> &Simulation {
        &self.sim
    }

    /// The configuration.
    pub fn config(&self) -> &EnvConfig {
        &self.config
    }

    /// Reward terms of the last step.
    pub fn last_reward_terms(&self) -> RewardTerms {
        self.last_terms
    }

    /// Termination cause of the last step, if it terminated.
    pub fn last_termination(&self) -> Option<Termination> {
        self.last_termination
    }

    /// Current episode length limit (changes with the curriculum in train mode).
    pub fn episode_limit(&self) -> usize {
        self.episode_limit
    }

    /// Reference time \[s\] now.
    pub fn reference_time(&self) -> f64 {
        self.substeps as f64 * SIM_DT + self.time_offset
    }

    fn warmup_frame(&self) -> MotionFrame {
        let f0 = self.motion.frame_at(0.0);
        MotionFrame {
            root_pos: Vector3::new(f0.root_pos.x, f0.root_pos.y, self.model.init_position.2),
            root_rot: yaw_rotation(heading_of(&f0.root_rot)),
            joints: self.model.default_urdf_angles(),
        }
    }

    /// The reference state (world frame) at reference time `t`.
    pub fn reference_at(&self, t: f64) -> (MotionFrame, MotionVelocity) {
        let (f, v) = if t < 0.0 {
            (self.warmup_frame(), MotionVelocity::default())
        } else {
            (self.motion.frame_at(t), self.motion.velocity_at(t))
        };
        (
            MotionFrame {
                root_pos: self.origin_rot * f.root_pos + self.origin_pos,
                root_rot: self.origin_rot * f.root_rot,
                joints: f.joints,
            },
            MotionVelocity {
                linear: self.origin_rot * v.linear,
                angular: self.origin_rot * v.angular,
                joints: v.joints,
            },
        )
    }

    /// Robot state equal to the reference at time `t`.
    pub fn reference_state(&self, t: f64) -> RobotState {
        let (f, v) = self.reference_at(t);
        RobotState {
            base_pos: f.root_pos,
            base_rot: f.root_rot,
            base_linvel: v.linear,
            base_angvel: v.angular,
            q: f.joints,
            qd: v.joints,
        }
    }

    /// Teleports the robot (for tests and tools; the episode continues).
    pub fn set_robot_state(&mut self, state: &RobotState) {
        self.sim.set_state(state);
    }

    fn reading(&self) -> Reading {
        let s = self.sim.state();
        let (roll, pitch, _) = s.base_rot.euler_angles();
        let w = s.base_rot.inverse() * s.base_angvel;
        Reading {
            motor: std::array::from_fn(|i| self.model.urdf_to_motor(i, s.q[i])),
            imu: [roll, pitch, w.x, w.y],
        }
    }

    /// End-effector points (toe centres, lower-leg COMs) of a state, world frame.
    fn end_effectors(model: &RobotModel, s: &RobotState) -> [Vector3<f64>; 2 * NUM_LEGS] {
        let poses = Simulation::body_poses(model, s);
        std::array::from_fn(|k| {
            let leg = k % NUM_LEGS;
            let lower = poses[3 + 3 * leg];
            let local = if k < NUM_LEGS {
                crate::model::v3(model.legs[leg].toe_origin)
            } else {
                crate::model::v3(model.legs[leg].lower_leg.com)
            };
            (lower * nalgebra::Point3::from(local)).coords
        })
    }

    /// The reward terms for the current simulator state against the reference at time `t`.
    pub fn reward_terms(&self, t: f64) -> RewardTerms {
        let sim = self.sim.state();
        let refs = self.reference_state(t);
        let mut pose_err = 0.0;
        let mut vel_err = 0.0;
        for j in 0..NUM_MOTORS {
            pose_err += (refs.q[j] - sim.q[j]).powi(2);
            vel_err += (refs.qd[j] - sim.qd[j]).powi(2);
        }
        let ee_sim = Self::end_effectors(&self.model, &sim);
        let ee_ref = Self::end_effectors(&self.model, &refs);
        let inv_h_sim = yaw_rotation(-heading_of(&sim.base_rot));
        let inv_h_ref = yaw_rotation(-heading_of(&refs.base_rot));
        let mut ee_err = 0.0;
        for k in 0..2 * NUM_LEGS {
            let a = inv_h_ref * (ee_ref[k] - refs.base_pos);
            let b = inv_h_sim * (ee_sim[k] - sim.base_pos);
            let dz = ee_ref[k].z - ee_sim[k].z;
            ee_err += (a.x - b.x).powi(2) + (a.y - b.y).powi(2) + 3.0 * dz * dz;
        }
        let dp = (refs.base_pos - sim.base_pos).norm_squared();
        let theta = rotation_error(&refs.base_rot, &sim.base_rot);
        let dv = (refs.base_linvel - sim.base_linvel).norm_squared();
        let dw = (refs.base_angvel - sim.base_angvel).norm_squared();
        RewardTerms {
            pose: (-5.0 * pose_err).exp(),
            velocity: (-0.1 * vel_err).exp(),
            end_effector: (-40.0 * ee_err).exp(),
            root_pose: (-20.0 * (dp + 0.5 * theta * theta)).exp(),
            root_velocity: (-2.0 * (dv + 0.1 * dw)).exp(),
        }
    }

    /// Termination rules (a)–(c) of the reference for the current state at reference time `t`.
    /// `check_contact` is false on the first step of an episode, as in the reference.
    pub fn termination(&self, t: f64, check_contact: bool) -> Option<Termination> {
        if check_contact && self.sim.ground_contacts().1 {
            return Some(Termination::BodyContact);
        }
        let sim = self.sim.state();
        let (f, _) = self.reference_at(t);
        if (f.root_pos - sim.base_pos).norm_squared() > 1.0 {
            return Some(Termination::RootPosition);
        }
        if rotation_error(&f.root_rot, &sim.base_rot) > 0.5 * PI {
            return Some(Termination::RootRotation);
        }
        None
    }

    fn sample_randomization(&mut self) {
        if !self.config.randomize {
            self.sim.set_mass_scale(1.0, 1.0, 1.0, 1.0);
            self.sim.set_motor_strength([1.0; NUM_MOTORS]);
            self.sim.set_foot_friction(self.model.foot_friction);
            self.sim.set_knee_friction([0.0; NUM_LEGS]);
            self.latency = self.config.control_latency;
            return;
        }
        let r = &mut self.rng;
        let (bm, lm) = (r.range(0.8, 1.2), r.range(0.8, 1.2));
        let (bi, li) = (r.range(0.5, 1.5), r.range(0.5, 1.5));
        let strength = std::array::from_fn(|_| r.range(0.8, 1.2));
        self.latency = r.range(0.0, 0.04);
        let friction = r.range(0.5, 1.25);
        let k = &mut self.knee_rng;
        let knee_friction =
            std::array::from_fn(|_| k.range(KNEE_FRICTION_RANGE.0, KNEE_FRICTION_RANGE.1));
        self.sim.set_mass_scale(bm, lm, bi, li);
        self.sim.set_motor_strength(strength);
        self.sim.set_foot_friction(friction);
        self.sim.set_knee_friction(knee_friction);
    }

    fn write_obs(&self, out: &mut Observation) {
        if out.tensors.len() != 1
            || out.tensors[0].data.len() != OBS_DIM
            || out.tensors[0].dtype() != DType::F32
            || out.tensors[0].name != "obs"
        {
            out.tensors.clear();
            out.tensors.push(Tensor::zeros("obs", &[OBS_DIM]));
        }
        out.action_mask = None;
        // A float32 tensor of OBS_DIM values (checked or rebuilt just above).
        let Some(d) = out.tensors[0].data.as_f32_mut() else {
            return;
        };
        let mut k = 0;
        for h in &self.imu_hist {
            for v in h {
                d[k] = *v as f32;
                k += 1;
            }
        }
        for h in &self.action_hist {
            for v in h {
                d[k] = *v as f32;
                k += 1;
            }
        }
        for h in &self.motor_hist {
            for v in h {
                d[k] = (v + PI).rem_euclid(2.0 * PI) as f32 - PI as f32;
                k += 1;
            }
        }
        let t = self.reference_time();
        let (now, _) = self.reference_at(t);
        let sim_rot = self.sim.state().base_rot;
        let inv_heading = yaw_rotation(-heading_of(&sim_rot));
        for steps in TARGET_STEPS {
            let (f, _) = self.reference_at(t + steps as f64 * CONTROL_DT);
            let p = inv_heading * (f.root_pos - now.root_pos);
            let mut q = (inv_heading * f.urdf_base_rot()).into_inner();
            if q.w < 0.0 {
                q = -q;
            }
            for v in [p.x, p.y, p.z, q.i, q.j, q.k, q.w] {
                d[k] = v as f32;
                k += 1;
            }
            for v in f.joints {
                d[k] = v as f32;
                k += 1;
            }
        }
        debug_assert_eq!(k, OBS_DIM);
    }
}

/// Angle of `a ⊗ b⁻¹`, wrapped to [0, π].
fn rotation_error(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    (a * b.inverse()).angle()
}

fn observation_space(motion: &ReferenceMotion, model: &RobotModel) -> Space {
    let mut low = Vec::with_capacity(OBS_DIM);
    let mut high = Vec::with_capacity(OBS_DIM);
    let two_pi = 2.0 * PI as f32;
    for _ in 0..3 {
        low.extend([-two_pi, -two_pi, -1000.0 * two_pi, -1000.0 * two_pi]);
        high.extend([two_pi, two_pi, 1000.0 * two_pi, 1000.0 * two_pi]);
    }
    let default = model.default_motor_angles();
    for _ in 0..3 {
        low.extend(default.iter().map(|d| *d as f32 - two_pi));
        high.extend(default.iter().map(|d| *d as f32 + two_pi));
    }
    for _ in 0..3 {
        low.extend([-PI as f32; NUM_MOTORS]);
        high.extend([PI as f32; NUM_MOTORS]);
    }
    // The target joints range over the clip's frames and, before the clip starts (a reset's
    // negative reference time), the warmup's default pose. motion_imitation's bounds take the
    // frames only, so its warmup observations fall outside its own space.
    let (mut jmin, mut jmax) = motion.joint_range();
    for (j, d) in model.default_urdf_angles().iter().enumerate() {
        jmin[j] = jmin[j].min(*d);
        jmax[j] = jmax[j].max(*d);
    }
    for _ in TARGET_STEPS {
        low.extend([-2.0, -2.0, -2.0, -1.0, -1.0, -1.0, -1.0]);
        high.extend([2.0, 2.0, 2.0, 1.0, 1.0, 1.0, 1.0]);
        low.extend(jmin.iter().map(|v| *v as f32));
        high.extend(jmax.iter().map(|v| *v as f32));
    }
    Space::Box {
        low: low.into_iter().map(f64::from).collect(),
        high: high.into_iter().map(f64::from).collect(),
        shape: vec![OBS_DIM],
        dtype: DType::F32,
    }
}

impl Env for LocomotionEnv {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset_into(&mut self, seed: Option<u64>, obs: &mut Observation) -> Result<(), EnvError> {
        if let Some(s) = seed {
            self.rng = RngStream::new(s, "locomotion-episode");
            self.knee_rng = self.rng.derive("knee-friction");
        }
        if self.config.mode == Mode::Train {
            let s = (self.total_nonterminal_steps as f64 / self.config.curriculum_steps.max(1.0))
                .clamp(0.0, 1.0);
            let s3 = s * s * s;
            self.episode_limit =
                ((1.0 - s3) * 20.0 + s3 * self.config.episode_steps as f64) as usize;
        } else {
            self.episode_limit = self.config.episode_steps;
        }
        let dur = self.motion.duration();
        self.time_offset = if self.rng.bernoulli(self.config.ref_state_init_prob) {
            self.rng.range(0.0, dur)
        } else {
            self.rng.range(0.0, 0.25) - 0.25
        };
        self.substeps = 0;
        self.steps = 0;
        // A fresh physics world: rapier keeps contact manifolds (warm-start impulses), islands
        // and broad-phase structure across a teleport, so a reused world would make an episode
        // depend on the episodes before it. Fresh, an episode is a function of its seed and
        // actions (Gymnasium's reset contract), which also lets resumed training replay it.
        self.sim = Simulation::new(&self.model, self.sim.config().clone());
        // 1. Robot to the initial position and default pose.
        let (x, y, z) = self.model.init_position;
        let init = RobotState {
            base_pos: Vector3::new(x, y, z),
            q: self.model.default_urdf_angles(),
            ..RobotState::default()
        };
        self.sim.set_state(&init);
        self.history.clear();
        let default_reading = self.reading();
        self.history.push(default_reading);
        // 2. Reference origin: the reference starts at the robot's xy and heading.
        self.origin_rot = UnitQuaternion::identity();
        self.origin_pos = Vector3::zeros();
        let (f, _) = self.reference_at(self.time_offset);
        self.origin_rot = yaw_rotation(-heading_of(&f.root_rot));
        let mut p = -(self.origin_rot * f.root_pos) + init.base_pos;
        p.z = 0.0;
        self.origin_pos = p;
        self.last_cycle = self.motion.cycle_count(self.time_offset.max(0.0));
        // 3. Randomisation, then teleport the robot onto the reference.
        self.sample_randomization();
        let state = self.reference_state(self.time_offset);
        self.sim.set_state(&state);
        let r = self.reading();
        self.history.push(r);
        // Sensor histories hold the default-pose reading (the reference's reset quirk).
        self.imu_hist = [default_reading.imu; 3];
        self.motor_hist = [default_reading.motor; 3];
        self.action_hist = [[0.0; NUM_MOTORS]; 3];
        self.prev_filtered = None;
        self.needs_reset = false;
        self.last_termination = None;
        self.write_obs(obs);
        Ok(())
    }

    fn step_into(&mut self, action: &Action, out: &mut Step) -> Result<(), EnvError> {
        if self.needs_reset {
            return Err(EnvError::NeedsReset);
        }
        let Action::Continuous(a) = action else {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: "expected a continuous action of 12 values".into(),
            });
        };
        if a.len() != NUM_MOTORS || a.iter().any(|v| !v.is_finite()) {
            return Err(EnvError::InvalidAction {
                action: action.clone(),
                reason: format!("expected 12 finite values, found {}", a.len()),
            });
        }
        let default = self.model.default_motor_angles();
        let target: [f64; NUM_MOTORS] = std::array::from_fn(|i| {
            default[i] + f64::from(a[i]).clamp(-ACTION_LIMIT, ACTION_LIMIT)
        });
        let first = self.prev_filtered.is_none();
        if first {
            let init = self.history.delayed(self.latency, SIM_DT).motor;
            self.filter.init(&init);
        }
        let filtered = self.filter.filter(&target);
        let prev = self.prev_filtered.unwrap_or(filtered);
        for i in 0..ACTION_REPEAT {
            let s = (i + 1) as f64 / ACTION_REPEAT as f64;
            let observed = self.history.delayed(self.latency, SIM_DT).motor;
            let u: [f64; NUM_MOTORS] = std::array::from_fn(|j| {
                let v = prev[j] + s * (filtered[j] - prev[j]);
                v.clamp(
                    observed[j] - MAX_MOTOR_ANGLE_CHANGE,
                    observed[j] + MAX_MOTOR_ANGLE_CHANGE,
                )
            });
            self.sim.step_pd(&u);
            self.substeps += 1;
            let r = self.reading();
            self.history.push(r);
        }
        self.prev_filtered = Some(filtered);
        self.steps += 1;

        // Reference update with cycle sync: on a phase wrap the reference origin moves so that
        // the reference root xy equals the robot's.
        let t = self.reference_time();
        if t >= 0.0 {
            let cycle = self.motion.cycle_count(t);
            if cycle != self.last_cycle {
                self.last_cycle = cycle;
                let (f, _) = self.reference_at(t);
                let sim_pos = self.sim.state().base_pos;
                self.origin_pos.x += sim_pos.x - f.root_pos.x;
                self.origin_pos.y += sim_pos.y - f.root_pos.y;
            }
        }
        let terms = self.reward_terms(t);
        let termination = self.termination(t, self.steps > 1);
        self.last_terms = terms;
        self.last_termination = termination;

        // Sensors (control rate).
        let delayed = self.history.delayed(self.latency, SIM_DT);
        self.imu_hist.rotate_right(1);
        self.imu_hist[0] = delayed.imu;
        self.motor_hist.rotate_right(1);
        self.motor_hist[0] = delayed.motor;
        self.action_hist.rotate_right(1);
        self.action_hist[0] = target;

        out.reward = terms.total();
        let time_limit = termination.is_none() && self.steps >= self.episode_limit;
        out.terminated = termination.is_some() || (time_limit && self.config.time_limit_terminates);
        out.truncated = time_limit && !self.config.time_limit_terminates;
        // The curriculum counts the steps that do not end the episode (motion_imitation's
        // `ImitationWrapperEnv`: `if not done`, the time limit included in `done`).
        if !out.terminated && !out.truncated {
            self.total_nonterminal_steps += 1;
        }
        self.needs_reset = out.terminated || out.truncated;
        self.write_obs(&mut out.observation);
        // `Info::clear` drops the key strings, so re-setting would allocate them every step;
        // when the info already holds exactly our keys, overwrite the values in place.
        let ours = out
            .info
            .iter()
            .map(|(k, _)| k)
            .eq(INFO_KEYS.iter().copied());
        if !ours {
            out.info.clear();
        }
        out.info.set("reward_pose", terms.pose);
        out.info.set("reward_velocity", terms.velocity);
        out.info.set("reward_end_effector", terms.end_effector);
        out.info.set("reward_root_pose", terms.root_pose);
        out.info.set("reward_root_velocity", terms.root_velocity);
        out.info.set("reference_time", t);
        Ok(())
    }

    fn render_modes(&self) -> &'static [&'static str] {
        &["rgb_array"]
    }

    /// `"rgb_array"`: [`side_view`] of the robot and the reference pose now, the camera on the
    /// robot's base (computed only here; stepping does no rendering work).
    fn render(&mut self, mode: &str) -> Result<Frame, EnvError> {
        if mode != "rgb_array" {
            return Err(EnvError::unsupported_render_mode(mode, self.render_modes()));
        }
        let model = self.sim.model();
        let state = self.sim.state();
        let robot = state_points(model, &state);
        let reference = state_points(model, &self.reference_state(self.reference_time()));
        Ok(side_view(&robot, &reference, state.base_pos.x))
    }
}
