//! The rapier3d world: a 13-body quadruped (chassis, 4 × hip motor, upper leg, lower leg with
//! the toe sphere merged in) on a flat ground, actuated by PD torques computed here.
//!
//! Design choices (rapier 0.36):
//! - **Impulse joints**, not multibody joints: for this 13-body tree the multibody path is about
//!   5× slower per step and allocates per step; impulse joints with the small 1 ms step hold the
//!   tree together well.
//! - **Explicit PD torques** every 1 ms substep from the current joint state, applied as equal
//!   and opposite torques about the joint axis on the child and parent bodies (the reference's
//!   `TORQUE_CONTROL`, no torque limit).
//! - Only robot–ground contacts exist (no self-collision, as in the reference); collision shapes
//!   are simplified (box chassis, sphere hip motors, capsule legs, sphere toes).

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rapier3d::glamx::{Quat, Vec3};
use rapier3d::prelude::*;

use crate::articulated::Articulated;
use crate::model::{NUM_LEGS, NUM_MOTORS, RobotModel, v3};

/// Kind of a robot link, for contact bookkeeping.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkKind {
    /// The chassis.
    Chassis,
    /// A hip-motor link.
    HipMotor,
    /// An upper leg.
    UpperLeg,
    /// A lower leg (a "foot" link for termination purposes).
    LowerLeg,
    /// A toe sphere (a "foot" link).
    Toe,
}

impl LinkKind {
    /// Whether ground contact on this link is allowed (toes and lower legs, as in the reference).
    pub fn is_foot(self) -> bool {
        matches!(self, LinkKind::LowerLeg | LinkKind::Toe)
    }
}

/// Which engine steps the robot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Physics {
    /// rapier3d: 13 rigid bodies held together by impulse joints (the engine of every recorded
    /// result).
    #[default]
    Rapier,
    /// This crate's reduced-coordinate engine (`articulated`): the tree as 18 generalized
    /// coordinates, exact joints, contacts and limits by projected Gauss–Seidel. About twice
    /// as fast; its trajectories differ from rapier's.
    Articulated,
}

impl Physics {
    /// The name used in environment parameters: `rapier` or `articulated`.
    ///
    /// ```
    /// use a2perf_locomotion::sim::Physics;
    /// assert_eq!(Physics::from_name("articulated"), Some(Physics::Articulated));
    /// assert_eq!(Physics::Rapier.name(), "rapier");
    /// assert_eq!(Physics::from_name("bullet"), None);
    /// ```
    pub fn name(self) -> &'static str {
        match self {
            Physics::Rapier => "rapier",
            Physics::Articulated => "articulated",
        }
    }

    /// Parses [`Self::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "rapier" => Some(Physics::Rapier),
            "articulated" => Some(Physics::Articulated),
            _ => None,
        }
    }
}

/// Simulation settings.
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig {
    /// Physics step \[s\].
    pub dt: f64,
    /// Solver iterations per step. Rapier: the default, 1, meets the speed target; joints then
    /// separate by at most ~2 mm under violent random actions (2 iterations: ~0.3 mm, about 35%
    /// slower). The reference uses 9 Bullet iterations, which rapier's soft-constraint solver with
    /// a 1 ms step does not need for stability. Articulated: 4 Gauss–Seidel sweeps over the
    /// contact, limit and friction rows per iteration.
    pub solver_iterations: usize,
    /// The engine.
    pub physics: Physics,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            dt: 0.001,
            solver_iterations: 1,
            physics: Physics::Rapier,
        }
    }
}

/// The full kinematic state of the robot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotState {
    /// Base COM position (world).
    pub base_pos: Vector3<f64>,
    /// Base orientation (robot frame: x forward, y left, z up).
    pub base_rot: UnitQuaternion<f64>,
    /// Base COM linear velocity (world).
    pub base_linvel: Vector3<f64>,
    /// Base angular velocity (world).
    pub base_angvel: Vector3<f64>,
    /// URDF joint angles.
    pub q: [f64; NUM_MOTORS],
    /// URDF joint velocities.
    pub qd: [f64; NUM_MOTORS],
}

impl Default for RobotState {
    fn default() -> Self {
        Self {
            base_pos: Vector3::zeros(),
            base_rot: UnitQuaternion::identity(),
            base_linvel: Vector3::zeros(),
            base_angvel: Vector3::zeros(),
            q: [0.0; NUM_MOTORS],
            qd: [0.0; NUM_MOTORS],
        }
    }
}

fn to_vec3(v: &Vector3<f64>) -> Vec3 {
    Vec3::new(v.x as f32, v.y as f32, v.z as f32)
}

fn from_vec3(v: Vec3) -> Vector3<f64> {
    Vector3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

fn to_pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    Pose::from_parts(
        to_vec3(&iso.translation.vector),
        Quat::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
    )
}

fn from_pose(p: &Pose) -> Isometry3<f64> {
    let r = p.rotation;
    Isometry3::from_parts(
        Translation3::from(from_vec3(p.translation)),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            f64::from(r.w),
            f64::from(r.x),
            f64::from(r.y),
            f64::from(r.z),
        )),
    )
}

/// Mass properties of a link, optionally scaled.
fn mass_props(com: Vector3<f64>, mass: f64, inertia: Vector3<f64>) -> MassProperties {
    MassProperties::new(to_vec3(&com), mass as f32, to_vec3(&inertia))
}

/// Velocity-motor gain of the knee friction: large, so that below the friction bound the motor
/// acts as a (nearly) hard zero-velocity constraint, like PyBullet's velocity motor; rapier's
/// regularisation is then `1/(dt·gain)` = 0.1% at dt = 1 ms.
const KNEE_FRICTION_GAIN: f32 = 1.0e6;

/// The physics world of one robot, on the engine its [`SimConfig`] names.
pub struct Simulation {
    config: SimConfig,
    time: f64,
    engine: Engine,
}

enum Engine {
    Rapier(Box<Rapier>),
    Articulated(Box<Articulated>),
}

/// Calls the same method on whichever engine runs.
macro_rules! engine {
    ($self:expr, $e:ident => $body:expr) => {
        match &$self.engine {
            Engine::Rapier($e) => $body,
            Engine::Articulated($e) => $body,
        }
    };
    (mut $self:expr, $e:ident => $body:expr) => {
        match &mut $self.engine {
            Engine::Rapier($e) => $body,
            Engine::Articulated($e) => $body,
        }
    };
}

impl Simulation {
    /// Builds the world with the robot at the model's initial position and default pose.
    ///
    /// ```
    /// use a2perf_locomotion::sim::{Physics, SimConfig, Simulation};
    /// use a2perf_locomotion::RobotModel;
    /// let model = RobotModel::builtin();
    /// let config = SimConfig { physics: Physics::Articulated, ..SimConfig::default() };
    /// let mut sim = Simulation::new(&model, config);
    /// let target = model.default_motor_angles();
    /// for _ in 0..500 {
    ///     sim.step_pd(&target);
    /// }
    /// // Standing on its toes, the joints exact.
    /// assert!(sim.toe_contacts().iter().all(|&t| t));
    /// assert!((sim.state().base_pos.z - 0.43).abs() < 0.05);
    /// assert_eq!(sim.max_joint_error(), 0.0);
    /// ```
    pub fn new(model: &RobotModel, config: SimConfig) -> Self {
        let engine = match config.physics {
            Physics::Rapier => Engine::Rapier(Box::new(Rapier::new(model, &config))),
            // Built at the initial position and default pose, at rest.
            Physics::Articulated => Engine::Articulated(Box::new(Articulated::new(
                model,
                config.dt,
                config.solver_iterations,
            ))),
        };
        Self {
            config,
            time: 0.0,
            engine,
        }
    }

    /// The robot model.
    pub fn model(&self) -> &RobotModel {
        engine!(self, e => e.model())
    }

    /// The simulation settings.
    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Simulated time since construction \[s\].
    pub fn time(&self) -> f64 {
        self.time
    }

    /// World poses of every body: base (COM frame), then per leg hip motor, upper leg, lower leg
    /// (joint frames), computed from a state by forward kinematics.
    pub fn body_poses(
        model: &RobotModel,
        state: &RobotState,
    ) -> [Isometry3<f64>; 1 + 3 * NUM_LEGS] {
        let base = Isometry3::from_parts(Translation3::from(state.base_pos), state.base_rot);
        let mut out = [base; 1 + 3 * NUM_LEGS];
        for leg in 0..NUM_LEGS {
            let p = model.leg_poses(
                leg,
                [state.q[3 * leg], state.q[3 * leg + 1], state.q[3 * leg + 2]],
            );
            out[1 + 3 * leg] = base * p.hip_motor;
            out[2 + 3 * leg] = base * p.upper_leg;
            out[3 + 3 * leg] = base * p.lower_leg;
        }
        out
    }

    /// Teleports the robot to `state` (poses and velocities of every body).
    pub fn set_state(&mut self, state: &RobotState) {
        engine!(mut self, e => e.set_state(state))
    }

    /// World pose of body `i` (0 = base COM frame, then legs × (hip, upper, lower)).
    pub fn body_pose(&self, i: usize) -> Isometry3<f64> {
        match &self.engine {
            Engine::Rapier(e) => e.body_pose(i),
            Engine::Articulated(e) => Self::body_poses(e.model(), &e.state())[i],
        }
    }

    /// The current state.
    pub fn state(&self) -> RobotState {
        engine!(self, e => e.state())
    }

    /// URDF joint angles and velocities.
    pub fn joint_state(&self) -> ([f64; NUM_MOTORS], [f64; NUM_MOTORS]) {
        match &self.engine {
            Engine::Rapier(e) => *e.joint_state(),
            Engine::Articulated(e) => e.joint_state(),
        }
    }

    /// Largest separation \[m\] between the two bodies' copies of a joint anchor — how far the
    /// impulse-joint solver lets the tree come apart (0 for the articulated engine, whose joints
    /// are exact).
    pub fn max_joint_error(&self) -> f64 {
        match &self.engine {
            Engine::Rapier(e) => e.max_joint_error(),
            Engine::Articulated(_) => 0.0,
        }
    }

    /// Sets the per-motor strength multipliers (1 = nominal).
    pub fn set_motor_strength(&mut self, strength: [f64; NUM_MOTORS]) {
        engine!(mut self, e => e.set_motor_strength(strength))
    }

    /// Scales masses and inertias: `base` for the chassis and hip motors, `leg` for the upper and
    /// lower legs (with toes), as the reference's randomiser groups them.
    pub fn set_mass_scale(
        &mut self,
        base_mass: f64,
        leg_mass: f64,
        base_inertia: f64,
        leg_inertia: f64,
    ) {
        engine!(mut self, e => e.set_mass_scale(base_mass, leg_mass, base_inertia, leg_inertia))
    }

    /// Sets the lateral friction of the toes and lower legs (before multiplying with the ground).
    pub fn set_foot_friction(&mut self, friction: f64) {
        engine!(mut self, e => e.set_foot_friction(friction))
    }

    /// Sets the dry friction torque [N·m] of each knee joint (FR, FL, RR, RL), as the reference's
    /// randomiser does with a PyBullet velocity motor (target velocity 0, maximum force =
    /// friction) on the foot-link joints — of which only the knees move.
    ///
    /// Rapier: a joint motor driving the knee's relative velocity to zero with its torque bounded
    /// by the friction; joints are only touched when a value changes, so a world that never sets
    /// friction steps exactly as one without this feature. Articulated: a velocity row of the
    /// constraint solver with the same bound.
    pub fn set_knee_friction(&mut self, friction: [f64; NUM_LEGS]) {
        engine!(mut self, e => e.set_knee_friction(friction))
    }

    /// Current knee joint friction torques [N·m] (FR, FL, RR, RL).
    pub fn knee_friction(&self) -> [f64; NUM_LEGS] {
        engine!(self, e => e.knee_friction())
    }

    /// Last applied motor-space torques.
    pub fn torques(&self) -> &[f64; NUM_MOTORS] {
        engine!(self, e => e.torques())
    }

    /// Advances one physics step with motor-space PD targets `target`: torques
    /// `strength·(−kp(q − q*) − kd·q̇)` from the current true joint state.
    pub fn step_pd(&mut self, target: &[f64; NUM_MOTORS]) {
        engine!(mut self, e => e.step_pd(target));
        self.time += self.config.dt;
    }

    /// Advances one physics step with no actuation change (rapier) or no actuation
    /// (articulated).
    pub fn step_physics(&mut self) {
        engine!(mut self, e => e.step_physics());
        self.time += self.config.dt;
    }

    /// Whether any link touches the ground: returns (foot contact, non-foot contact).
    pub fn ground_contacts(&self) -> (bool, bool) {
        engine!(self, e => e.ground_contacts())
    }

    /// Which toes touch the ground (FR, FL, RR, RL).
    pub fn toe_contacts(&self) -> [bool; NUM_LEGS] {
        engine!(self, e => e.toe_contacts())
    }
}

/// One actuated joint: parent and child bodies, axis in the parent body frame.
#[derive(Clone, Copy, Debug)]
struct Motor {
    parent: RigidBodyHandle,
    child: RigidBodyHandle,
    axis: Vec3,
}

/// The rapier3d world of one robot.
struct Rapier {
    model: RobotModel,
    gravity: Vec3,
    params: IntegrationParameters,
    pipeline: PhysicsPipeline,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    soft_bodies: SoftBodySet,
    ccd: CCDSolver,
    ground: ColliderHandle,
    base: RigidBodyHandle,
    legs: [[RigidBodyHandle; 3]; NUM_LEGS],
    motors: [Motor; NUM_MOTORS],
    /// Knee (lower-leg) joints, FR, FL, RR, RL, for joint friction.
    knee_joints: [ImpulseJointHandle; NUM_LEGS],
    knee_friction: [f64; NUM_LEGS],
    robot_colliders: Vec<(ColliderHandle, LinkKind, usize)>,
    /// Nominal mass properties per body (base, then legs × 3), for randomisation.
    nominal_mass: Vec<(RigidBodyHandle, Vector3<f64>, f64, Vector3<f64>)>,
    strength: [f64; NUM_MOTORS],
    torques: [f64; NUM_MOTORS],
    /// Joint angles and velocities of the current body state (refreshed after every change).
    joints: ([f64; NUM_MOTORS], [f64; NUM_MOTORS]),
}

impl Rapier {
    /// Builds the world with the robot at the model's initial position and default pose.
    fn new(model: &RobotModel, config: &SimConfig) -> Self {
        let mut bodies = RigidBodySet::new();
        let mut colliders = ColliderSet::new();
        let mut impulse_joints = ImpulseJointSet::new();
        let robot_group =
            InteractionGroups::new(Group::GROUP_1, Group::GROUP_2, InteractionTestMode::And);
        let ground_group =
            InteractionGroups::new(Group::GROUP_2, Group::GROUP_1, InteractionTestMode::And);

        let ground_body = bodies.insert(RigidBodyBuilder::fixed());
        let ground = colliders.insert_with_parent(
            ColliderBuilder::cuboid(500.0, 500.0, 1.0)
                .translation(Vec3::new(0.0, 0.0, -1.0))
                .friction(model.ground_friction as f32)
                .friction_combine_rule(CoefficientCombineRule::Multiply)
                .collision_groups(ground_group),
            ground_body,
            &mut bodies,
        );

        let com = model.chassis_com();
        let mut nominal_mass = Vec::new();
        let base_inertia = v3(model.chassis.inertia);
        let base = bodies.insert(
            RigidBodyBuilder::dynamic()
                .can_sleep(false)
                .additional_mass_properties(mass_props(
                    Vector3::zeros(),
                    model.chassis.mass,
                    base_inertia,
                )),
        );
        nominal_mass.push((base, Vector3::zeros(), model.chassis.mass, base_inertia));
        let collider = |b: ColliderBuilder| {
            b.mass_properties(MassProperties::new(Vec3::ZERO, 0.0, Vec3::ZERO))
                .friction(model.foot_friction as f32)
                .friction_combine_rule(CoefficientCombineRule::Multiply)
                .collision_groups(robot_group)
        };
        let mut robot_colliders = Vec::new();
        let (hx, hy, hz) = model.chassis_box_half_extents;
        let c = collider(
            ColliderBuilder::cuboid(hx as f32, hy as f32, hz as f32)
                .translation(to_vec3(&v3(model.chassis_box_center))),
        );
        robot_colliders.push((
            colliders.insert_with_parent(c, base, &mut bodies),
            LinkKind::Chassis,
            0,
        ));

        let mut legs = [[base; 3]; NUM_LEGS];
        let mut knee_joints = [ImpulseJointHandle::invalid(); NUM_LEGS];
        let mut motors = [Motor {
            parent: base,
            child: base,
            axis: Vec3::X,
        }; NUM_MOTORS];
        for (li, leg) in model.legs.iter().enumerate() {
            // Lower leg and toe are one rigid body.
            let toe = v3(leg.toe_origin);
            let specs = model.leg_bodies(li);
            let origins = [
                v3(leg.hip_origin) - com,
                v3(leg.upper_origin),
                v3(leg.knee_origin),
            ];
            let axes = [
                v3(leg.abduction_axis),
                v3(model.pitch_axis),
                v3(model.pitch_axis),
            ];
            let mut parent = base;
            for k in 0..3 {
                let (c, m, i) = specs[k];
                let h = bodies.insert(
                    RigidBodyBuilder::dynamic()
                        .can_sleep(false)
                        .additional_mass_properties(mass_props(c, m, i)),
                );
                nominal_mass.push((h, c, m, i));
                let (lo, hi) = model.joint_limits[k];
                let joint = RevoluteJointBuilder::new(to_vec3(&axes[k]))
                    .local_anchor1(to_vec3(&origins[k]))
                    .local_anchor2(Vec3::ZERO)
                    .limits([lo as f32, hi as f32])
                    .contacts_enabled(false);
                let jh = impulse_joints.insert(parent, h, joint, true);
                if k == 2 {
                    knee_joints[li] = jh;
                }
                motors[3 * li + k] = Motor {
                    parent,
                    child: h,
                    axis: to_vec3(&axes[k]),
                };
                legs[li][k] = h;
                parent = h;
            }
            let hip = collider(ColliderBuilder::ball(model.hip_motor_radius as f32));
            robot_colliders.push((
                colliders.insert_with_parent(hip, legs[li][0], &mut bodies),
                LinkKind::HipMotor,
                li,
            ));
            let knee = v3(leg.knee_origin);
            let r = model.upper_leg_radius as f32;
            let upper = collider(ColliderBuilder::capsule_from_endpoints(
                Vec3::new(0.0, 0.0, -(r + 0.01)),
                to_vec3(&knee),
                r,
            ));
            robot_colliders.push((
                colliders.insert_with_parent(upper, legs[li][1], &mut bodies),
                LinkKind::UpperLeg,
                li,
            ));
            let lower = collider(ColliderBuilder::capsule_from_endpoints(
                Vec3::ZERO,
                to_vec3(&(toe * 0.75)),
                model.lower_leg_radius as f32,
            ));
            robot_colliders.push((
                colliders.insert_with_parent(lower, legs[li][2], &mut bodies),
                LinkKind::LowerLeg,
                li,
            ));
            let toe_c =
                collider(ColliderBuilder::ball(model.toe_radius as f32).translation(to_vec3(&toe)));
            robot_colliders.push((
                colliders.insert_with_parent(toe_c, legs[li][2], &mut bodies),
                LinkKind::Toe,
                li,
            ));
        }

        let params = IntegrationParameters {
            dt: config.dt as f32,
            num_solver_iterations: config.solver_iterations.max(1),
            // No CCD: at 1 ms substeps no link moves its own size in a step, so the sweep never
            // fires, yet its per-body bookkeeping cost ~12% of a step. Results are bit-identical.
            max_ccd_substeps: 0,
            ..IntegrationParameters::default()
        };
        let mut sim = Self {
            model: model.clone(),
            gravity: Vec3::new(0.0, 0.0, model.gravity as f32),
            params,
            pipeline: PhysicsPipeline::new(),
            islands: IslandManager::new(),
            broad_phase: BroadPhaseBvh::new(),
            narrow_phase: NarrowPhase::new(),
            bodies,
            colliders,
            impulse_joints,
            multibody_joints: MultibodyJointSet::new(),
            soft_bodies: SoftBodySet::new(),
            ccd: CCDSolver::new(),
            ground,
            base,
            legs,
            motors,
            knee_joints,
            knee_friction: [0.0; NUM_LEGS],
            robot_colliders,
            nominal_mass,
            strength: [1.0; NUM_MOTORS],
            torques: [0.0; NUM_MOTORS],
            joints: ([0.0; NUM_MOTORS], [0.0; NUM_MOTORS]),
        };
        let (x, y, z) = model.init_position;
        let state = RobotState {
            base_pos: Vector3::new(x, y, z),
            q: model.default_urdf_angles(),
            ..RobotState::default()
        };
        sim.set_state(&state);
        sim
    }

    /// The robot model.
    pub fn model(&self) -> &RobotModel {
        &self.model
    }

    /// Teleports the robot to `state` (poses and velocities of every body).
    pub fn set_state(&mut self, state: &RobotState) {
        let poses = Simulation::body_poses(&self.model, state);
        let handles = self.body_handles();
        // Joint origins and world axes along each leg for the velocity propagation.
        for (b, h) in handles.iter().enumerate() {
            let pose = poses[b];
            let rb = &mut self.bodies[*h];
            rb.set_position(to_pose(&pose), true);
            let com_local = from_vec3(rb.mass_properties().local_mprops.local_com);
            let com_world = pose * Point3::from(com_local);
            let mut w = state.base_angvel;
            let mut v = state.base_linvel
                + state
                    .base_angvel
                    .cross(&(com_world.coords - state.base_pos));
            if b > 0 {
                let leg = (b - 1) / 3;
                let depth = (b - 1) % 3;
                for k in 0..=depth {
                    let m = 3 * leg + k;
                    let jpose = poses[1 + 3 * leg + k];
                    let axis_local = self.model.joint_axis(m);
                    // The joint frame rotates about the joint axis, which is the same in the
                    // parent and child frames.
                    let axis = jpose.rotation * axis_local;
                    let o = jpose.translation.vector;
                    let wj = axis * state.qd[m];
                    w += wj;
                    v += wj.cross(&(com_world.coords - o));
                }
            }
            let rb = &mut self.bodies[*h];
            rb.set_linvel(to_vec3(&v), true);
            rb.set_angvel(to_vec3(&w), true);
        }
        self.refresh_joints();
    }

    fn body_handles(&self) -> [RigidBodyHandle; 1 + 3 * NUM_LEGS] {
        let mut h = [self.base; 1 + 3 * NUM_LEGS];
        for leg in 0..NUM_LEGS {
            for k in 0..3 {
                h[1 + 3 * leg + k] = self.legs[leg][k];
            }
        }
        h
    }

    /// World pose of body `i` (0 = base COM frame, then legs × (hip, upper, lower)).
    pub fn body_pose(&self, i: usize) -> Isometry3<f64> {
        let h = if i == 0 {
            self.base
        } else {
            self.legs[(i - 1) / 3][(i - 1) % 3]
        };
        from_pose(self.bodies[h].position())
    }

    /// The current state read back from the bodies.
    pub fn state(&self) -> RobotState {
        let b = &self.bodies[self.base];
        let pose = from_pose(b.position());
        let mut s = RobotState {
            base_pos: pose.translation.vector,
            base_rot: pose.rotation,
            // Velocity of the base frame origin (the model's COM), independent of where rapier
            // places the body's mass centre.
            base_linvel: {
                let com =
                    pose * Point3::from(from_vec3(b.mass_properties().local_mprops.local_com));
                from_vec3(b.linvel())
                    + from_vec3(b.angvel()).cross(&(pose.translation.vector - com.coords))
            },
            base_angvel: from_vec3(b.angvel()),
            ..RobotState::default()
        };
        (s.q, s.qd) = self.joints;
        s
    }

    /// URDF joint angles and velocities.
    pub fn joint_state(&self) -> &([f64; NUM_MOTORS], [f64; NUM_MOTORS]) {
        &self.joints
    }

    /// Recomputes the joint state from the relative rotations of the bodies.
    fn refresh_joints(&mut self) {
        let (mut q, mut qd) = ([0.0; NUM_MOTORS], [0.0; NUM_MOTORS]);
        self.compute_joint_state(&mut q, &mut qd);
        self.joints = (q, qd);
    }

    fn compute_joint_state(&self, q: &mut [f64; NUM_MOTORS], qd: &mut [f64; NUM_MOTORS]) {
        for (i, m) in self.motors.iter().enumerate() {
            let p = &self.bodies[m.parent];
            let c = &self.bodies[m.child];
            let rel = p.rotation().inverse() * *c.rotation();
            let s = rel.x * m.axis.x + rel.y * m.axis.y + rel.z * m.axis.z;
            q[i] = 2.0 * f64::from(s).atan2(f64::from(rel.w));
            let axis_w = *p.rotation() * m.axis;
            qd[i] = f64::from((c.angvel() - p.angvel()).dot(axis_w));
        }
    }

    /// Largest separation \[m\] between the two bodies' copies of a joint anchor — how far the
    /// impulse-joint solver lets the tree come apart (0 for an exact articulation).
    pub fn max_joint_error(&self) -> f64 {
        let mut worst = 0.0f64;
        for leg in 0..NUM_LEGS {
            let origins = [
                v3(self.model.legs[leg].hip_origin) - self.model.chassis_com(),
                v3(self.model.legs[leg].upper_origin),
                v3(self.model.legs[leg].knee_origin),
            ];
            for (k, origin) in origins.iter().enumerate() {
                let m = self.motors[3 * leg + k];
                let a = from_pose(self.bodies[m.parent].position()) * Point3::from(*origin);
                let b = from_pose(self.bodies[m.child].position()) * Point3::origin();
                worst = worst.max((a - b).norm());
            }
        }
        worst
    }

    /// Sets the per-motor strength multipliers (1 = nominal).
    pub fn set_motor_strength(&mut self, strength: [f64; NUM_MOTORS]) {
        self.strength = strength;
    }

    /// See [`Simulation::set_mass_scale`].
    fn set_mass_scale(&mut self, bm: f64, lm: f64, bi: f64, li: f64) {
        for (idx, (h, c, m, i)) in self.nominal_mass.iter().enumerate() {
            let is_base_group = idx == 0 || (idx - 1) % 3 == 0;
            let (ms, is) = if is_base_group { (bm, bi) } else { (lm, li) };
            self.bodies[*h].set_additional_mass_properties(mass_props(*c, m * ms, i * is), true);
        }
    }

    /// Sets the lateral friction of the toes and lower legs (before multiplying with the ground).
    pub fn set_foot_friction(&mut self, friction: f64) {
        for (h, kind, _) in &self.robot_colliders {
            if kind.is_foot()
                && let Some(c) = self.colliders.get_mut(*h)
            {
                c.set_friction(friction as f32);
            }
        }
    }

    /// Sets the dry friction torque [N·m] of each knee joint (FR, FL, RR, RL), as the reference's
    /// randomiser does with a PyBullet velocity motor (target velocity 0, maximum force =
    /// friction) on the foot-link joints — of which only the knees move.
    ///
    /// Modelled the same way: a rapier joint motor driving the knee's relative velocity to zero
    /// with its torque bounded by the friction. Joints are only touched when a value changes,
    /// so a world that never sets friction steps exactly as one without this feature; setting
    /// a knee back to 0 leaves a motor whose torque bound is 0 (no effect).
    pub fn set_knee_friction(&mut self, friction: [f64; NUM_LEGS]) {
        for (leg, &f) in friction.iter().enumerate() {
            let f = f.max(0.0);
            if f == self.knee_friction[leg] {
                continue;
            }
            self.knee_friction[leg] = f;
            if let Some(joint) = self.impulse_joints.get_mut(self.knee_joints[leg], false) {
                joint
                    .data
                    .set_motor_velocity(JointAxis::AngX, 0.0, KNEE_FRICTION_GAIN)
                    .set_motor_max_force(JointAxis::AngX, f as f32);
            }
        }
    }

    /// Current knee joint friction torques [N·m] (FR, FL, RR, RL).
    pub fn knee_friction(&self) -> [f64; NUM_LEGS] {
        self.knee_friction
    }

    /// Last applied motor-space torques.
    pub fn torques(&self) -> &[f64; NUM_MOTORS] {
        &self.torques
    }

    /// Advances one physics step with motor-space PD targets `target`: torques
    /// `strength·(−kp(q − q*) − kd·q̇)` from the current true joint state.
    pub fn step_pd(&mut self, target: &[f64; NUM_MOTORS]) {
        let (q, qd) = self.joints;
        for b in self.body_handles() {
            self.bodies[b].reset_torques(false);
        }
        for i in 0..NUM_MOTORS {
            let dir = self.model.joint_directions[i];
            let qm = self.model.urdf_to_motor(i, q[i]);
            let qdm = dir * qd[i];
            let (kp, kd) = self.model.gains(i);
            let tau_m = self.strength[i] * (-kp * (qm - target[i]) - kd * qdm);
            self.torques[i] = tau_m;
            let m = self.motors[i];
            let axis_w = *self.bodies[m.parent].rotation() * m.axis;
            let t = axis_w * (dir * tau_m) as f32;
            self.bodies[m.child].add_torque(t, false);
            self.bodies[m.parent].add_torque(-t, false);
        }
        self.step_physics();
    }

    /// Advances one physics step with no actuation change.
    ///
    /// Heap use: rapier 0.36.1 allocates twice inside `PhysicsPipeline::step`, plus once in a
    /// step where a contact begins or ends, and the next step's first `&mut` body accesses
    /// (torques in [`Self::step_pd`]) regrow the modified-body list the step dropped (3 more) —
    /// 5 per PD substep (see the crate README); this crate's own per-step code allocates nothing.
    pub fn step_physics(&mut self) {
        self.pipeline.step(
            self.gravity,
            &self.params,
            &mut self.islands,
            &mut self.broad_phase,
            &mut self.narrow_phase,
            &mut self.bodies,
            &mut self.colliders,
            &mut self.impulse_joints,
            &mut self.multibody_joints,
            &mut self.soft_bodies,
            &mut self.ccd,
            &(),
            &(),
        );
        self.refresh_joints();
    }

    /// Whether any link of `kind`-class touches the ground: returns (foot contact, non-foot
    /// contact).
    pub fn ground_contacts(&self) -> (bool, bool) {
        let mut foot = false;
        let mut other = false;
        for (h, kind, _) in &self.robot_colliders {
            let touching = self
                .narrow_phase
                .contact_pair(self.ground, *h)
                .is_some_and(|p| p.has_any_active_contact());
            if touching {
                if kind.is_foot() {
                    foot = true;
                } else {
                    other = true;
                }
            }
        }
        (foot, other)
    }

    /// Which toes touch the ground (FR, FL, RR, RL).
    pub fn toe_contacts(&self) -> [bool; NUM_LEGS] {
        let mut out = [false; NUM_LEGS];
        for (h, kind, leg) in &self.robot_colliders {
            if *kind == LinkKind::Toe {
                out[*leg] = self
                    .narrow_phase
                    .contact_pair(self.ground, *h)
                    .is_some_and(|p| p.has_any_active_contact());
            }
        }
        out
    }
}
