//! Reduced-coordinate dynamics of the quadruped: the 13-body tree as 18 generalized coordinates
//! (floating base + 12 hinge angles), so the legs cannot come apart and no joint constraint has
//! to be solved.
//!
//! One step of `dt` (semi-implicit Euler, as rapier and MuJoCo's default):
//! 1. forward kinematics of the tree;
//! 2. the joint-space mass matrix `M` (summed from each body's COM and rotation Jacobians) and
//!    the bias forces `h` (Coriolis, centrifugal, gyroscopic and gravity, one recursive pass at
//!    zero acceleration), then `u* = u + dt·M⁻¹(τ − h)` through a Cholesky factor of `M`;
//! 3. velocity-level impulses for the unilateral constraints — ground contacts (normal and a
//!    Coulomb disk), joint limits and the knees' dry friction — by projected Gauss–Seidel on
//!    the constraint rows, warm-started from the previous step's contact impulses;
//! 4. positions from the new velocities (base rotation by the exponential map).
//!
//! Contacts: the toes are the reference's soft contacts (PyBullet's stiffness and damping, as an
//! implicit spring-damper row, active while the toe is in the ground). Every other shape follows
//! rapier 0.36's defaults for contacts with a fixed body: penetration beyond 5 mm is pushed out
//! at `erp/dt` of a 60 Hz, ζ = 10 spring (at most 3 m/s), and a shape above the ground may
//! approach it by its gap in one step (speculative contact). What counts as touching (for the
//! termination on non-foot contact) is rapier's too: within its 2 cm prediction distance. The
//! collision shapes are rapier's simplified ones (box chassis: its corners; spheres; capsules:
//! their end spheres) against the plane `z = 0`.

// Dense 18 × 18 linear algebra and per-joint arrays indexed side by side: index loops read as the
// formulas they implement.
#![allow(clippy::needless_range_loop)]

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::model::{NUM_LEGS, NUM_MOTORS, RobotModel, v3};
use crate::sim::{LinkKind, RobotState};

/// Bodies: base, then per leg hip motor, upper leg, lower leg (with the toe).
const NB: usize = 1 + 3 * NUM_LEGS;
/// Generalized velocities: base linear (world, of the base COM), base angular (world), joints.
const ND: usize = 6 + NUM_MOTORS;
/// Contact candidates: 8 chassis-box corners, per leg a hip sphere, two upper-leg and two
/// lower-leg capsule end spheres and the toe sphere.
const NP: usize = 8 + 6 * NUM_LEGS;
/// Collision shapes: chassis box, per leg hip sphere, upper capsule, lower capsule, toe.
const NC: usize = 1 + 4 * NUM_LEGS;
/// Most constraint rows in one step: three per contact point, two limits and a friction row
/// per joint.
const MAX_ROWS: usize = 3 * NP + 3 * NUM_MOTORS;

/// Distance below which a shape is in contact with the ground (rapier's default prediction).
const PREDICTION: f64 = 0.02;
/// Penetration left alone (rapier's default allowed linear error).
const ALLOWED_PENETRATION: f64 = 0.005;
/// Fastest push-out of a penetration \[m/s\] (rapier's default maximum corrective velocity).
const MAX_CORRECTION: f64 = 3.0;
/// Contact spring against a fixed body: natural frequency \[Hz\] and damping ratio (rapier's
/// `contact_static_defaults`).
const CONTACT_HZ: f64 = 60.0;
const CONTACT_ZETA: f64 = 10.0;
/// The toes' contact stiffness \[N/m\] and damping \[N·s/m\]: the reference's soft toe
/// contacts (motion_imitation's Laikago toes, `contact_stiffness` / `contact_damping` in PyBullet).
const TOE_STIFFNESS: f64 = 30_000.0;
const TOE_DAMPING: f64 = 1_000.0;
/// Gauss–Seidel sweeps per solver iteration.
const SWEEPS_PER_ITERATION: usize = 4;

/// Scratch rows of the constraint solver, kept between steps so a step allocates nothing.
struct Rows {
    n: usize,
    /// Jacobian row.
    j: [[f64; ND]; MAX_ROWS],
    /// `M⁻¹ Jᵀ` of the row.
    y: [[f64; ND]; MAX_ROWS],
    /// `1 / (J M⁻¹ Jᵀ + γ)`.
    inv_w: [f64; MAX_ROWS],
    /// Softness `γ` of a spring-damper row (0: rigid).
    soft: [f64; MAX_ROWS],
    /// Velocity the row drives `J·u` towards (at least this, for unilateral rows).
    target: [f64; MAX_ROWS],
    /// What bounds the impulse.
    kind: [RowKind; MAX_ROWS],
    lambda: [f64; MAX_ROWS],
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum RowKind {
    /// `λ ≥ 0`: a contact normal or a joint limit.
    Unilateral,
    /// First tangent of a contact: the pair with the next row lies in the disk `μ·λₙ` of
    /// normal row `normal`.
    Tangent { normal: usize, mu: f64 },
    /// Second tangent (handled with the first).
    Tangent2,
    /// `|λ| ≤ bound`.
    Boxed { bound: f64 },
}

/// A sphere (radius 0 for a box corner) fixed on a body, tested against the ground.
#[derive(Clone, Copy, Debug)]
struct ContactPoint {
    body: usize,
    local: Vector3<f64>,
    radius: f64,
    shape: usize,
}

/// The reduced-coordinate world of one robot.
pub(crate) struct Articulated {
    model: RobotModel,
    dt: f64,
    sweeps: usize,
    gravity: Vector3<f64>,
    /// Per body, in its frame: COM, mass, principal inertia (body axes).
    com: [Vector3<f64>; NB],
    mass: [f64; NB],
    inertia: [Vector3<f64>; NB],
    nominal: [(Vector3<f64>, f64, Vector3<f64>); NB],
    /// Per motor: joint origin in the parent frame, unit axis (parent and child frames).
    origin: [Vector3<f64>; NUM_MOTORS],
    axis: [Vector3<f64>; NUM_MOTORS],
    limits: [(f64, f64); NUM_MOTORS],
    points: [ContactPoint; NP],
    /// Per shape: link kind, leg, friction (before multiplying with the ground's).
    shapes: [(LinkKind, usize, f64); NC],
    ground_friction: f64,
    // State.
    pos: Vector3<f64>,
    rot: UnitQuaternion<f64>,
    linvel: Vector3<f64>,
    angvel: Vector3<f64>,
    q: [f64; NUM_MOTORS],
    qd: [f64; NUM_MOTORS],
    strength: [f64; NUM_MOTORS],
    torques: [f64; NUM_MOTORS],
    knee_friction: [f64; NUM_LEGS],
    /// Which shapes were within the prediction distance at the start of the last step.
    touching: [bool; NC],
    /// Last step's contact impulses per point (normal, tangent x, tangent y).
    warm: [[f64; 3]; NP],
    rows: Box<Rows>,
}

/// Forward kinematics of the tree at one instant (world frame).
#[derive(Clone, Copy)]
struct Frames {
    rot: [Matrix3<f64>; NB],
    org: [Vector3<f64>; NB],
    /// World axis of each motor.
    axis: [Vector3<f64>; NUM_MOTORS],
}

fn parent(b: usize) -> usize {
    if (b - 1).is_multiple_of(3) { 0 } else { b - 1 }
}

/// Motors between the base and body `b` (its own last), as a range.
fn ancestors(b: usize) -> std::ops::Range<usize> {
    if b == 0 {
        0..0
    } else {
        let leg = (b - 1) / 3;
        3 * leg..b
    }
}

fn axis_rotation(a: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = angle.sin_cos();
    let k = a.cross_matrix();
    Matrix3::identity() * c + k * s + (a * a.transpose()) * (1.0 - c)
}

/// Cholesky factor (lower) of a symmetric positive-definite matrix, in place; false if not SPD.
fn cholesky(m: &mut [[f64; ND]; ND]) -> bool {
    for j in 0..ND {
        let mut d = m[j][j];
        for k in 0..j {
            d -= m[j][k] * m[j][k];
        }
        if d <= 0.0 || !d.is_finite() {
            return false;
        }
        let d = d.sqrt();
        m[j][j] = d;
        for i in j + 1..ND {
            let mut s = m[i][j];
            for k in 0..j {
                s -= m[i][k] * m[j][k];
            }
            m[i][j] = s / d;
        }
    }
    true
}

/// Solves `L Lᵀ x = b` in place.
fn cholesky_solve(l: &[[f64; ND]; ND], x: &mut [f64; ND]) {
    for i in 0..ND {
        let mut s = x[i];
        for k in 0..i {
            s -= l[i][k] * x[k];
        }
        x[i] = s / l[i][i];
    }
    for i in (0..ND).rev() {
        let mut s = x[i];
        for k in i + 1..ND {
            s -= l[k][i] * x[k];
        }
        x[i] = s / l[i][i];
    }
}

fn dot(a: &[f64; ND], b: &[f64; ND]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

impl Articulated {
    /// Builds the tree from the model (bodies as [`crate::sim::Simulation`] builds them).
    pub(crate) fn new(model: &RobotModel, dt: f64, solver_iterations: usize) -> Self {
        let zero = Vector3::zeros();
        let mut nominal = [(zero, 0.0, zero); NB];
        nominal[0] = (zero, model.chassis.mass, v3(model.chassis.inertia));
        let mut origin = [zero; NUM_MOTORS];
        let mut axis = [zero; NUM_MOTORS];
        let mut limits = [(0.0, 0.0); NUM_MOTORS];
        let com0 = model.chassis_com();
        let mut points = [ContactPoint {
            body: 0,
            local: zero,
            radius: 0.0,
            shape: 0,
        }; NP];
        let friction = model.foot_friction;
        let mut shapes = [(LinkKind::Chassis, 0, friction); NC];
        let (hx, hy, hz) = model.chassis_box_half_extents;
        let center = v3(model.chassis_box_center);
        for (i, p) in points.iter_mut().take(8).enumerate() {
            let s = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
            p.local = center + Vector3::new(s(1) * hx, s(2) * hy, s(4) * hz);
        }
        let mut np = 8;
        for (li, leg) in model.legs.iter().enumerate() {
            let toe = v3(leg.toe_origin);
            let b = 1 + 3 * li;
            nominal[b..b + 3].copy_from_slice(&model.leg_bodies(li));
            let origins = [
                v3(leg.hip_origin) - com0,
                v3(leg.upper_origin),
                v3(leg.knee_origin),
            ];
            for k in 0..3 {
                let m = 3 * li + k;
                origin[m] = origins[k];
                axis[m] = model.joint_axis(m).normalize();
                limits[m] = model.joint_limits[k];
            }
            let s = 1 + 4 * li;
            shapes[s] = (LinkKind::HipMotor, li, friction);
            shapes[s + 1] = (LinkKind::UpperLeg, li, friction);
            shapes[s + 2] = (LinkKind::LowerLeg, li, friction);
            shapes[s + 3] = (LinkKind::Toe, li, friction);
            let r_up = model.upper_leg_radius;
            let knee = v3(leg.knee_origin);
            let mut add = |body: usize, local: Vector3<f64>, radius: f64, shape: usize| {
                points[np] = ContactPoint {
                    body,
                    local,
                    radius,
                    shape,
                };
                np += 1;
            };
            add(b, zero, model.hip_motor_radius, s);
            add(b + 1, Vector3::new(0.0, 0.0, -(r_up + 0.01)), r_up, s + 1);
            add(b + 1, knee, r_up, s + 1);
            add(b + 2, zero, model.lower_leg_radius, s + 2);
            add(b + 2, toe * 0.75, model.lower_leg_radius, s + 2);
            add(b + 2, toe, model.toe_radius, s + 3);
        }
        debug_assert_eq!(np, NP);
        let rows = Box::new(Rows {
            n: 0,
            j: [[0.0; ND]; MAX_ROWS],
            y: [[0.0; ND]; MAX_ROWS],
            inv_w: [0.0; MAX_ROWS],
            soft: [0.0; MAX_ROWS],
            target: [0.0; MAX_ROWS],
            kind: [RowKind::Boxed { bound: 0.0 }; MAX_ROWS],
            lambda: [0.0; MAX_ROWS],
        });
        let (x, y, z) = model.init_position;
        let mut sim = Self {
            model: model.clone(),
            dt,
            sweeps: solver_iterations.max(1) * SWEEPS_PER_ITERATION,
            gravity: Vector3::new(0.0, 0.0, model.gravity),
            com: [zero; NB],
            mass: [0.0; NB],
            inertia: [zero; NB],
            nominal,
            origin,
            axis,
            limits,
            points,
            shapes,
            ground_friction: model.ground_friction,
            pos: Vector3::new(x, y, z),
            rot: UnitQuaternion::identity(),
            linvel: zero,
            angvel: zero,
            q: model.default_urdf_angles(),
            qd: [0.0; NUM_MOTORS],
            strength: [1.0; NUM_MOTORS],
            torques: [0.0; NUM_MOTORS],
            knee_friction: [0.0; NUM_LEGS],
            touching: [false; NC],
            warm: [[0.0; 3]; NP],
            rows,
        };
        sim.set_mass_scale(1.0, 1.0, 1.0, 1.0);
        sim
    }

    pub(crate) fn model(&self) -> &RobotModel {
        &self.model
    }

    pub(crate) fn set_state(&mut self, s: &RobotState) {
        self.pos = s.base_pos;
        self.rot = s.base_rot;
        self.linvel = s.base_linvel;
        self.angvel = s.base_angvel;
        self.q = s.q;
        self.qd = s.qd;
        self.warm = [[0.0; 3]; NP];
        self.touching = [false; NC];
    }

    pub(crate) fn state(&self) -> RobotState {
        RobotState {
            base_pos: self.pos,
            base_rot: self.rot,
            base_linvel: self.linvel,
            base_angvel: self.angvel,
            q: self.q,
            qd: self.qd,
        }
    }

    pub(crate) fn joint_state(&self) -> ([f64; NUM_MOTORS], [f64; NUM_MOTORS]) {
        (self.q, self.qd)
    }

    pub(crate) fn set_motor_strength(&mut self, strength: [f64; NUM_MOTORS]) {
        self.strength = strength;
    }

    pub(crate) fn set_mass_scale(&mut self, bm: f64, lm: f64, bi: f64, li: f64) {
        for b in 0..NB {
            let (c, m, i) = self.nominal[b];
            let base_group = b == 0 || (b - 1) % 3 == 0;
            let (ms, is) = if base_group { (bm, bi) } else { (lm, li) };
            self.com[b] = c;
            self.mass[b] = m * ms;
            self.inertia[b] = i * is;
        }
    }

    pub(crate) fn set_foot_friction(&mut self, friction: f64) {
        for s in &mut self.shapes {
            if s.0.is_foot() {
                s.2 = friction;
            }
        }
    }

    pub(crate) fn set_knee_friction(&mut self, friction: [f64; NUM_LEGS]) {
        self.knee_friction = friction.map(|f| f.max(0.0));
    }

    pub(crate) fn knee_friction(&self) -> [f64; NUM_LEGS] {
        self.knee_friction
    }

    pub(crate) fn torques(&self) -> &[f64; NUM_MOTORS] {
        &self.torques
    }

    /// (foot contact, non-foot contact) at the start of the last step.
    pub(crate) fn ground_contacts(&self) -> (bool, bool) {
        let (mut foot, mut other) = (false, false);
        for (s, t) in self.shapes.iter().zip(&self.touching) {
            if *t {
                if s.0.is_foot() {
                    foot = true;
                } else {
                    other = true;
                }
            }
        }
        (foot, other)
    }

    pub(crate) fn toe_contacts(&self) -> [bool; NUM_LEGS] {
        std::array::from_fn(|leg| self.touching[1 + 4 * leg + 3])
    }

    fn frames(&self) -> Frames {
        let mut f = Frames {
            rot: [Matrix3::identity(); NB],
            org: [self.pos; NB],
            axis: [Vector3::zeros(); NUM_MOTORS],
        };
        f.rot[0] = *self.rot.to_rotation_matrix().matrix();
        for b in 1..NB {
            let m = b - 1;
            let p = parent(b);
            f.org[b] = f.org[p] + f.rot[p] * self.origin[m];
            f.axis[m] = f.rot[p] * self.axis[m];
            f.rot[b] = f.rot[p] * axis_rotation(&self.axis[m], self.q[m]);
        }
        f
    }

    /// Advances one step with motor-space PD targets (torques from the current joint state).
    pub(crate) fn step_pd(&mut self, target: &[f64; NUM_MOTORS]) {
        for i in 0..NUM_MOTORS {
            let dir = self.model.joint_directions[i];
            let qm = self.model.urdf_to_motor(i, self.q[i]);
            let qdm = dir * self.qd[i];
            let (kp, kd) = self.model.gains(i);
            self.torques[i] = self.strength[i] * (-kp * (qm - target[i]) - kd * qdm);
        }
        let tau: [f64; NUM_MOTORS] =
            std::array::from_fn(|i| self.model.joint_directions[i] * self.torques[i]);
        self.step(&tau);
    }

    /// Advances one step with no actuation.
    pub(crate) fn step_physics(&mut self) {
        self.torques = [0.0; NUM_MOTORS];
        self.step(&[0.0; NUM_MOTORS]);
    }

    /// The joint-space mass matrix and bias forces at the current state.
    fn dynamics(&self, f: &Frames, m: &mut [[f64; ND]; ND], h: &mut [f64; ND]) {
        let p = self.pos;
        // Angular velocity, and angular and origin accelerations at zero generalized
        // acceleration, per body.
        let mut w = [self.angvel; NB];
        let mut alpha = [Vector3::zeros(); NB];
        let mut acc = [Vector3::zeros(); NB];
        for b in 1..NB {
            let j = b - 1;
            let pa = parent(b);
            let d = f.org[b] - f.org[pa];
            let spin = f.axis[j] * self.qd[j];
            w[b] = w[pa] + spin;
            alpha[b] = alpha[pa] + w[pa].cross(&spin);
            acc[b] = acc[pa] + alpha[pa].cross(&d) + w[pa].cross(&w[pa].cross(&d));
        }
        for b in 0..NB {
            let r_b = f.rot[b];
            let c = f.org[b] + r_b * self.com[b];
            let d = self.inertia[b];
            let iw = r_b * Matrix3::from_diagonal(&d) * r_b.transpose();
            let mass = self.mass[b];
            let r = c - p;
            let x = r.cross_matrix();
            // Base block.
            for i in 0..3 {
                m[i][i] += mass;
            }
            let xtx = x.transpose() * x * mass + iw;
            for i in 0..3 {
                for k in 0..3 {
                    m[i][3 + k] -= mass * x[(i, k)];
                    m[3 + i][k] += mass * x[(i, k)];
                    m[3 + i][3 + k] += xtx[(i, k)];
                }
            }
            // Bias force of the body.
            let rc = c - f.org[b];
            let a_c = acc[b] + alpha[b].cross(&rc) + w[b].cross(&w[b].cross(&rc));
            let force = (a_c - self.gravity) * mass;
            let torque = iw * alpha[b] + w[b].cross(&(iw * w[b]));
            let tb = r.cross(&force) + torque;
            for i in 0..3 {
                h[i] += force[i];
                h[3 + i] += tb[i];
            }
            let anc = ancestors(b);
            let mut s = [Vector3::zeros(); 3];
            let mut ia = [Vector3::zeros(); 3];
            for (n, j) in anc.clone().enumerate() {
                s[n] = f.axis[j].cross(&(c - f.org[j + 1]));
                ia[n] = iw * f.axis[j];
                let lin = s[n] * mass;
                let ang = r.cross(&s[n]) * mass + ia[n];
                for i in 0..3 {
                    m[i][6 + j] += lin[i];
                    m[6 + j][i] += lin[i];
                    m[3 + i][6 + j] += ang[i];
                    m[6 + j][3 + i] += ang[i];
                }
                h[6 + j] += s[n].dot(&force) + f.axis[j].dot(&torque);
            }
            for (n1, j1) in anc.clone().enumerate() {
                for (n2, j2) in anc.clone().enumerate() {
                    m[6 + j1][6 + j2] += mass * s[n1].dot(&s[n2]) + f.axis[j1].dot(&ia[n2]);
                }
            }
        }
    }

    /// Jacobian row of the velocity along world direction `d` of world point `x` on body `b`.
    fn point_row(&self, f: &Frames, b: usize, x: &Vector3<f64>, d: &Vector3<f64>) -> [f64; ND] {
        let mut row = [0.0; ND];
        let ang = (x - self.pos).cross(d);
        for i in 0..3 {
            row[i] = d[i];
            row[3 + i] = ang[i];
        }
        for j in ancestors(b) {
            row[6 + j] = f.axis[j].dot(&(x - f.org[j + 1]).cross(d));
        }
        row
    }

    /// Adds a constraint row; `soft` is the `γ` of a spring-damper row, 0 for a rigid one.
    fn push_row(
        &mut self,
        l: &[[f64; ND]; ND],
        j: [f64; ND],
        target: f64,
        soft: f64,
        kind: RowKind,
    ) {
        let rows = &mut *self.rows;
        let n = rows.n;
        let mut y = j;
        cholesky_solve(l, &mut y);
        let w = dot(&j, &y);
        rows.j[n] = j;
        rows.y[n] = y;
        rows.inv_w[n] = if w + soft > 1e-12 {
            1.0 / (w + soft)
        } else {
            0.0
        };
        rows.soft[n] = soft;
        rows.target[n] = target;
        rows.kind[n] = kind;
        rows.lambda[n] = 0.0;
        rows.n = n + 1;
    }

    fn step(&mut self, tau: &[f64; NUM_MOTORS]) {
        let dt = self.dt;
        let f = self.frames();
        let mut m = [[0.0; ND]; ND];
        let mut h = [0.0; ND];
        self.dynamics(&f, &mut m, &mut h);
        if !cholesky(&mut m) {
            // A degenerate mass matrix cannot come from positive masses and inertias; keep the
            // state rather than write NaN into it. From here `m` holds the factor `L`.
            return;
        }
        let mut u = [0.0; ND];
        let mut acc = [0.0; ND];
        for i in 0..3 {
            u[i] = self.linvel[i];
            u[3 + i] = self.angvel[i];
            acc[i] = -h[i];
            acc[3 + i] = -h[3 + i];
        }
        for j in 0..NUM_MOTORS {
            u[6 + j] = self.qd[j];
            acc[6 + j] = tau[j] - h[6 + j];
        }
        cholesky_solve(&m, &mut acc);
        for i in 0..ND {
            u[i] += dt * acc[i];
        }

        // Constraint rows.
        self.rows.n = 0;
        self.touching = [false; NC];
        let erp_inv_dt = {
            let w = CONTACT_HZ * std::f64::consts::TAU;
            w / (dt * w + 2.0 * CONTACT_ZETA)
        };
        let mut point_rows = [usize::MAX; NP];
        for pi in 0..NP {
            let cp = self.points[pi];
            let centre = f.org[cp.body] + f.rot[cp.body] * cp.local;
            let dist = centre.z - cp.radius;
            if dist >= PREDICTION {
                continue;
            }
            self.touching[cp.shape] = true;
            let x = Vector3::new(centre.x, centre.y, centre.z - cp.radius);
            let (target, soft) = if self.shapes[cp.shape].0 == LinkKind::Toe {
                // The reference's compliant toes: force k·depth − c·v while in the ground
                // (implicit spring-damper row: J·u + (β/h)·φ + γ·λ = 0).
                if dist >= 0.0 {
                    continue;
                }
                let hk_c = dt * TOE_STIFFNESS + TOE_DAMPING;
                (-(TOE_STIFFNESS / hk_c) * dist, 1.0 / (dt * hk_c))
            } else if dist > 0.0 {
                (-dist / dt, 0.0)
            } else {
                let push = (-dist - ALLOWED_PENETRATION).max(0.0) * erp_inv_dt;
                (push.min(MAX_CORRECTION), 0.0)
            };
            let mu = self.shapes[cp.shape].2 * self.ground_friction;
            let n = self.rows.n;
            point_rows[pi] = n;
            let jn = self.point_row(&f, cp.body, &x, &Vector3::z());
            self.push_row(&m, jn, target, soft, RowKind::Unilateral);
            let jx = self.point_row(&f, cp.body, &x, &Vector3::x());
            self.push_row(&m, jx, 0.0, 0.0, RowKind::Tangent { normal: n, mu });
            let jy = self.point_row(&f, cp.body, &x, &Vector3::y());
            self.push_row(&m, jy, 0.0, 0.0, RowKind::Tangent2);
        }
        for j in 0..NUM_MOTORS {
            let (lo, hi) = self.limits[j];
            let (q, reach) = (self.q[j], dt * u[6 + j].abs() + 0.01);
            let mut e = [0.0; ND];
            if q - lo < reach {
                e[6 + j] = 1.0;
                self.push_row(&m, e, (lo - q) / dt, 0.0, RowKind::Unilateral);
            }
            if hi - q < reach {
                e[6 + j] = -1.0;
                self.push_row(&m, e, (q - hi) / dt, 0.0, RowKind::Unilateral);
            }
        }
        for (leg, fr) in self.knee_friction.into_iter().enumerate() {
            if fr > 0.0 {
                let mut e = [0.0; ND];
                e[6 + 3 * leg + 2] = 1.0;
                self.push_row(&m, e, 0.0, 0.0, RowKind::Boxed { bound: fr * dt });
            }
        }

        // Warm start from the last step's contact impulses.
        let rows = &mut *self.rows;
        for (pi, &r) in point_rows.iter().enumerate() {
            if r == usize::MAX {
                continue;
            }
            for k in 0..3 {
                let lam = self.warm[pi][k];
                if lam != 0.0 {
                    rows.lambda[r + k] = lam;
                    for (ui, yi) in u.iter_mut().zip(&rows.y[r + k]) {
                        *ui += lam * yi;
                    }
                }
            }
        }
        for _ in 0..self.sweeps {
            let mut r = 0;
            while r < rows.n {
                match rows.kind[r] {
                    RowKind::Unilateral | RowKind::Boxed { .. } => {
                        let v = dot(&rows.j[r], &u);
                        let old = rows.lambda[r];
                        let mut new =
                            old + (rows.target[r] - v - rows.soft[r] * old) * rows.inv_w[r];
                        new = match rows.kind[r] {
                            RowKind::Boxed { bound } => new.clamp(-bound, bound),
                            _ => new.max(0.0),
                        };
                        rows.lambda[r] = new;
                        let dl = new - old;
                        if dl != 0.0 {
                            for (ui, yi) in u.iter_mut().zip(&rows.y[r]) {
                                *ui += dl * yi;
                            }
                        }
                        r += 1;
                    }
                    RowKind::Tangent { normal, mu } => {
                        let bound = mu * rows.lambda[normal];
                        let old = [rows.lambda[r], rows.lambda[r + 1]];
                        let mut new = [0.0; 2];
                        for k in 0..2 {
                            let v = dot(&rows.j[r + k], &u);
                            new[k] = old[k] - v * rows.inv_w[r + k];
                        }
                        let norm = (new[0] * new[0] + new[1] * new[1]).sqrt();
                        if norm > bound {
                            let s = if norm > 0.0 { bound / norm } else { 0.0 };
                            new = [new[0] * s, new[1] * s];
                        }
                        for k in 0..2 {
                            rows.lambda[r + k] = new[k];
                            let dl = new[k] - old[k];
                            if dl != 0.0 {
                                for (ui, yi) in u.iter_mut().zip(&rows.y[r + k]) {
                                    *ui += dl * yi;
                                }
                            }
                        }
                        r += 2;
                    }
                    RowKind::Tangent2 => r += 1,
                }
            }
        }
        self.warm = [[0.0; 3]; NP];
        for (pi, &r) in point_rows.iter().enumerate() {
            if r != usize::MAX {
                self.warm[pi] = [rows.lambda[r], rows.lambda[r + 1], rows.lambda[r + 2]];
            }
        }

        // Positions.
        self.linvel = Vector3::new(u[0], u[1], u[2]);
        self.angvel = Vector3::new(u[3], u[4], u[5]);
        self.pos += self.linvel * dt;
        self.rot = UnitQuaternion::from_scaled_axis(self.angvel * dt) * self.rot;
        self.rot.renormalize();
        self.qd.copy_from_slice(&u[6..]);
        for (q, qd) in self.q.iter_mut().zip(&self.qd) {
            *q += dt * qd;
        }
    }

    /// Kinetic energy of the tree (tests).
    #[cfg(test)]
    fn kinetic_energy(&self) -> f64 {
        let f = self.frames();
        let mut m = [[0.0; ND]; ND];
        let mut h = [0.0; ND];
        self.dynamics(&f, &mut m, &mut h);
        let u = self.velocity();
        let mut e = 0.0;
        for i in 0..ND {
            for k in 0..ND {
                e += 0.5 * u[i] * m[i][k] * u[k];
            }
        }
        e
    }

    #[cfg(test)]
    fn velocity(&self) -> [f64; ND] {
        let mut u = [0.0; ND];
        for i in 0..3 {
            u[i] = self.linvel[i];
            u[3 + i] = self.angvel[i];
        }
        u[6..].copy_from_slice(&self.qd);
        u
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Simulation;

    fn floating(model: &mut RobotModel) -> Articulated {
        model.gravity = 0.0;
        let mut a = Articulated::new(model, 1e-4, 1);
        // Far from the ground and the joint limits.
        let mut s = a.state();
        s.base_pos.z = 10.0;
        s.base_linvel = Vector3::new(0.3, -0.2, 0.1);
        s.base_angvel = Vector3::new(0.5, 0.2, -0.7);
        for j in 0..NUM_MOTORS {
            s.qd[j] = 0.25 * ((j as f64) * 1.7).sin();
        }
        a.set_state(&s);
        a
    }

    #[test]
    fn mass_matrix_matches_the_bodies_kinetic_energy() {
        // ½ uᵀ M u against Σ ½ m |v_c|² + ½ ωᵀ I ω with body velocities from rigid-body
        // kinematics of the posed tree (finite differences of the body poses).
        let mut model = RobotModel::builtin();
        let a = floating(&mut model);
        let e = a.kinetic_energy();
        let eps = 1e-7;
        let s0 = a.state();
        let mut s1 = s0;
        s1.base_pos += s0.base_linvel * eps;
        s1.base_rot = UnitQuaternion::from_scaled_axis(s0.base_angvel * eps) * s0.base_rot;
        for j in 0..NUM_MOTORS {
            s1.q[j] += s0.qd[j] * eps;
        }
        let p0 = Simulation::body_poses(&model, &s0);
        let p1 = Simulation::body_poses(&model, &s1);
        let mut want = 0.0;
        for b in 0..NB {
            let c0 = p0[b] * nalgebra::Point3::from(a.com[b]);
            let c1 = p1[b] * nalgebra::Point3::from(a.com[b]);
            let v = (c1 - c0) / eps;
            let dr = p1[b].rotation * p0[b].rotation.inverse();
            let w = dr.scaled_axis() / eps;
            let r = p0[b].rotation.to_rotation_matrix();
            let iw = r.matrix() * Matrix3::from_diagonal(&a.inertia[b]) * r.matrix().transpose();
            want += 0.5 * a.mass[b] * v.norm_squared() + 0.5 * w.dot(&(iw * w));
        }
        assert!((e - want).abs() < 1e-5 * want, "{e} vs {want}");
    }

    #[test]
    fn a_free_tree_keeps_its_energy_and_momentum() {
        let mut model = RobotModel::builtin();
        let mut a = floating(&mut model);
        let momentum = |a: &Articulated| {
            let f = a.frames();
            let mut m = [[0.0; ND]; ND];
            let mut h = [0.0; ND];
            a.dynamics(&f, &mut m, &mut h);
            let u = a.velocity();
            Vector3::new(dot(&m[0], &u), dot(&m[1], &u), dot(&m[2], &u))
        };
        let (e0, p0) = (a.kinetic_energy(), momentum(&a));
        // 0.2 s: the joints stay clear of their limits, so nothing but the bias forces acts.
        for _ in 0..2_000 {
            a.step_physics();
            assert_eq!(a.rows.n, 0, "a constraint row at {:?}", a.q);
        }
        let (e1, p1) = (a.kinetic_energy(), momentum(&a));
        // Semi-implicit Euler drifts O(dt): 4e-5 relative at 1 ms, 4e-6 at 0.1 ms.
        assert!((e1 - e0).abs() < 1e-5 * e0, "energy {e0} -> {e1}");
        assert!((p1 - p0).norm() < 1e-6 * p0.norm(), "momentum {p0} -> {p1}");
    }

    #[test]
    fn a_dropped_tree_falls_at_g() {
        let mut model = RobotModel::builtin();
        model.gravity = -9.0;
        let mut a = Articulated::new(&model, 1e-3, 1);
        let mut s = a.state();
        s.base_pos.z = 5.0;
        a.set_state(&s);
        for _ in 0..100 {
            a.step_physics();
        }
        let v = a.state().base_linvel;
        assert!((v.z + 0.9).abs() < 1e-9, "{v}");
        assert!(a.state().qd.iter().all(|w| w.abs() < 1e-9));
    }
}
