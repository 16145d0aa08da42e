//! The robot model: a Laikago-class quadruped written as project-owned RON data, plus its
//! kinematics (forward kinematics of the legs, motor ↔ URDF joint conventions).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Number of legs.
pub const NUM_LEGS: usize = 4;
/// Number of actuated joints (3 per leg).
pub const NUM_MOTORS: usize = 12;

/// The built-in model's RON text (embedded, so the library never reads `../shared`).
pub const BUILTIN_MODEL_RON: &str = include_str!("../data/laikago.ron");

/// Mass, centre of mass and diagonal inertia of one rigid link.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinkInertial {
    /// Mass \[kg\].
    pub mass: f64,
    /// Centre of mass in the link frame \[m\] (robot axes).
    pub com: (f64, f64, f64),
    /// Principal moments of inertia about the COM [kg·m²] (robot axes).
    pub inertia: (f64, f64, f64),
}

/// Geometry and inertia of one leg (abduction → hip pitch → knee → toe).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LegModel {
    /// Leg name: FR, FL, RR or RL.
    pub name: String,
    /// Abduction joint origin in the chassis link frame.
    pub hip_origin: (f64, f64, f64),
    /// Abduction axis (robot axes).
    pub abduction_axis: (f64, f64, f64),
    /// Hip-pitch joint origin in the hip-motor frame.
    pub upper_origin: (f64, f64, f64),
    /// Knee joint origin in the upper-leg frame.
    pub knee_origin: (f64, f64, f64),
    /// Toe sphere centre in the lower-leg frame.
    pub toe_origin: (f64, f64, f64),
    /// Hip-motor link.
    pub hip_motor: LinkInertial,
    /// Upper-leg (thigh) link.
    pub upper_leg: LinkInertial,
    /// Lower-leg (calf) link.
    pub lower_leg: LinkInertial,
    /// Toe link (rigidly attached to the lower leg).
    pub toe: LinkInertial,
}

/// A quadruped model: links, joints, conventions and gains.
///
/// ```
/// let m = a2perf_locomotion::RobotModel::builtin();
/// assert!((m.total_mass() - 25.567).abs() < 1e-9);
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotModel {
    /// Model name.
    pub name: String,
    /// Chassis (base) link; its frame is the URDF chassis frame in robot axes.
    pub chassis: LinkInertial,
    /// Legs in the order FR, FL, RR, RL.
    pub legs: Vec<LegModel>,
    /// Axis of the hip-pitch and knee joints.
    pub pitch_axis: (f64, f64, f64),
    /// URDF joint limits per joint kind (abduction, hip pitch, knee).
    pub joint_limits: [(f64, f64); 3],
    /// Default motor-space pose of one leg (abduction, hip, knee).
    pub default_motor_pose: (f64, f64, f64),
    /// Motor directions, `q_urdf = dir·q_motor + offset`.
    pub joint_directions: [f64; NUM_MOTORS],
    /// Motor offsets, `q_urdf = dir·q_motor + offset`.
    pub joint_offsets: [f64; NUM_MOTORS],
    /// Proportional gains per joint kind [N·m/rad].
    pub kp: (f64, f64, f64),
    /// Derivative gains per joint kind [N·m·s/rad].
    pub kd: (f64, f64, f64),
    /// Base COM position at reset.
    pub init_position: (f64, f64, f64),
    /// Toe sphere radius.
    pub toe_radius: f64,
    /// Chassis collision box centre relative to the chassis COM.
    pub chassis_box_center: (f64, f64, f64),
    /// Chassis collision box half extents.
    pub chassis_box_half_extents: (f64, f64, f64),
    /// Hip-motor collision sphere radius.
    pub hip_motor_radius: f64,
    /// Upper-leg collision capsule radius.
    pub upper_leg_radius: f64,
    /// Lower-leg collision capsule radius.
    pub lower_leg_radius: f64,
    /// Lateral friction of the robot's links (multiplied with the ground's).
    pub foot_friction: f64,
    /// Lateral friction of the ground.
    pub ground_friction: f64,
    /// Vertical gravity [m/s²].
    pub gravity: f64,
}

/// Errors reading a robot model.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// The RON text is not a valid model.
    #[error("{origin}: {reason}")]
    Parse {
        /// File name or `<builtin>`.
        origin: String,
        /// Parser message with position.
        reason: String,
    },
    /// The model parsed but is not a quadruped this crate can simulate.
    #[error("{origin}: {reason}")]
    Invalid {
        /// File name or `<builtin>`.
        origin: String,
        /// What is wrong.
        reason: String,
    },
}

/// Converts a tuple to a vector.
pub(crate) fn v3(t: (f64, f64, f64)) -> Vector3<f64> {
    Vector3::new(t.0, t.1, t.2)
}

/// World poses (relative to the base COM frame) of the links of one leg.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegPoses {
    /// Hip-motor link frame.
    pub hip_motor: Isometry3<f64>,
    /// Upper-leg link frame.
    pub upper_leg: Isometry3<f64>,
    /// Lower-leg link frame.
    pub lower_leg: Isometry3<f64>,
}

impl RobotModel {
    /// The built-in Laikago-class model.
    ///
    /// ```
    /// let m = a2perf_locomotion::RobotModel::builtin();
    /// assert_eq!(m.legs.len(), 4);
    /// ```
    pub fn builtin() -> Self {
        match Self::from_ron(BUILTIN_MODEL_RON, "<builtin>") {
            Ok(m) => m,
            // The embedded text is checked by the test suite; reaching this is a build defect.
            Err(e) => unreachable!("built-in robot model is invalid: {e}"),
        }
    }

    /// Parses a model from RON text; `origin` names the source in errors.
    pub fn from_ron(text: &str, origin: &str) -> Result<Self, ModelError> {
        let model: RobotModel = ron::from_str(text).map_err(|e| ModelError::Parse {
            origin: origin.into(),
            reason: e.to_string(),
        })?;
        model.validate(origin)?;
        Ok(model)
    }

    fn validate(&self, origin: &str) -> Result<(), ModelError> {
        let bad = |reason: String| ModelError::Invalid {
            origin: origin.into(),
            reason,
        };
        if self.legs.len() != NUM_LEGS {
            return Err(bad(format!("expected 4 legs, found {}", self.legs.len())));
        }
        let mut links = vec![&self.chassis];
        for leg in &self.legs {
            links.extend([&leg.hip_motor, &leg.upper_leg, &leg.lower_leg, &leg.toe]);
        }
        for l in links {
            let (a, b, c) = l.inertia;
            if !(l.mass > 0.0 && a > 0.0 && b > 0.0 && c > 0.0) {
                return Err(bad("link masses and inertias must be positive".into()));
            }
        }
        for (lo, hi) in self.joint_limits {
            if lo > hi {
                return Err(bad(format!("joint limit [{lo}, {hi}] is empty")));
            }
        }
        if self.joint_directions.iter().any(|d| d.abs() != 1.0) {
            return Err(bad("joint directions must be ±1".into()));
        }
        Ok(())
    }

    /// Sum of all link masses.
    pub fn total_mass(&self) -> f64 {
        self.chassis.mass
            + self
                .legs
                .iter()
                .map(|l| l.hip_motor.mass + l.upper_leg.mass + l.lower_leg.mass + l.toe.mass)
                .sum::<f64>()
    }

    /// Chassis COM in the chassis link frame.
    pub fn chassis_com(&self) -> Vector3<f64> {
        v3(self.chassis.com)
    }

    /// Motor angle → URDF joint angle for motor `i`.
    pub fn motor_to_urdf(&self, i: usize, q_motor: f64) -> f64 {
        self.joint_directions[i] * q_motor + self.joint_offsets[i]
    }

    /// URDF joint angle → motor angle for motor `i`.
    pub fn urdf_to_motor(&self, i: usize, q_urdf: f64) -> f64 {
        (q_urdf - self.joint_offsets[i]) * self.joint_directions[i]
    }

    /// The default pose in motor space, all 12 motors.
    pub fn default_motor_angles(&self) -> [f64; NUM_MOTORS] {
        let (a, h, k) = self.default_motor_pose;
        std::array::from_fn(|i| [a, h, k][i % 3])
    }

    /// The default pose in URDF joint space.
    pub fn default_urdf_angles(&self) -> [f64; NUM_MOTORS] {
        let m = self.default_motor_angles();
        std::array::from_fn(|i| self.motor_to_urdf(i, m[i]))
    }

    /// URDF limits of motor `i`.
    pub fn urdf_limits(&self, i: usize) -> (f64, f64) {
        self.joint_limits[i % 3]
    }

    /// Proportional and derivative gains of motor `i`.
    pub fn gains(&self, i: usize) -> (f64, f64) {
        let kp = [self.kp.0, self.kp.1, self.kp.2][i % 3];
        let kd = [self.kd.0, self.kd.1, self.kd.2][i % 3];
        (kp, kd)
    }

    /// Joint axis of motor `i` (in its parent link frame, robot axes).
    pub fn joint_axis(&self, i: usize) -> Vector3<f64> {
        if i.is_multiple_of(3) {
            v3(self.legs[i / 3].abduction_axis)
        } else {
            v3(self.pitch_axis)
        }
    }

    /// Mass properties of the three bodies of leg `leg` as the simulators build them — hip
    /// motor, upper leg, and the lower leg with the toe merged in (combined COM; both inertias
    /// moved there by the parallel-axis theorem) — each as (COM in the link frame, mass,
    /// principal inertia about the COM).
    ///
    /// ```
    /// let m = a2perf_locomotion::RobotModel::builtin();
    /// let [_, _, (_, lower, _)] = m.leg_bodies(0);
    /// assert!((lower - (m.legs[0].lower_leg.mass + m.legs[0].toe.mass)).abs() < 1e-12);
    /// ```
    pub fn leg_bodies(&self, leg: usize) -> [(Vector3<f64>, f64, Vector3<f64>); 3] {
        let leg = &self.legs[leg];
        let toe = v3(leg.toe_origin);
        let (ml, mt) = (leg.lower_leg.mass, leg.toe.mass);
        let cl = v3(leg.lower_leg.com);
        let ct = toe + v3(leg.toe.com);
        let c_lower = (cl * ml + ct * mt) / (ml + mt);
        let par = |i: Vector3<f64>, m: f64, d: Vector3<f64>| {
            Vector3::new(
                i.x + m * (d.y * d.y + d.z * d.z),
                i.y + m * (d.x * d.x + d.z * d.z),
                i.z + m * (d.x * d.x + d.y * d.y),
            )
        };
        let i_lower = par(v3(leg.lower_leg.inertia), ml, cl - c_lower)
            + par(v3(leg.toe.inertia), mt, ct - c_lower);
        [
            (
                v3(leg.hip_motor.com),
                leg.hip_motor.mass,
                v3(leg.hip_motor.inertia),
            ),
            (
                v3(leg.upper_leg.com),
                leg.upper_leg.mass,
                v3(leg.upper_leg.inertia),
            ),
            (c_lower, ml + mt, i_lower),
        ]
    }

    /// Forward kinematics of leg `leg` at URDF angles `q`, relative to the base COM frame.
    pub fn leg_poses(&self, leg: usize, q: [f64; 3]) -> LegPoses {
        let l = &self.legs[leg];
        let com = self.chassis_com();
        let joint = |origin: Vector3<f64>, axis: Vector3<f64>, angle: f64| {
            Isometry3::from_parts(
                Translation3::from(origin),
                UnitQuaternion::from_scaled_axis(axis * angle),
            )
        };
        let hip_motor = joint(v3(l.hip_origin) - com, v3(l.abduction_axis), q[0]);
        let upper_leg = hip_motor * joint(v3(l.upper_origin), v3(self.pitch_axis), q[1]);
        let lower_leg = upper_leg * joint(v3(l.knee_origin), v3(self.pitch_axis), q[2]);
        LegPoses {
            hip_motor,
            upper_leg,
            lower_leg,
        }
    }

    /// Toe centre of leg `leg` at URDF angles `q`, relative to the base COM (base axes).
    ///
    /// ```
    /// let m = a2perf_locomotion::RobotModel::builtin();
    /// let q = m.default_urdf_angles();
    /// let toe = m.toe_position(0, [q[0], q[1], q[2]]);
    /// assert!((toe.z + 0.4558).abs() < 1e-3);
    /// ```
    pub fn toe_position(&self, leg: usize, q: [f64; 3]) -> Vector3<f64> {
        let p = self.leg_poses(leg, q);
        (p.lower_leg * nalgebra::Point3::from(v3(self.legs[leg].toe_origin))).coords
    }

    /// Solves leg inverse kinematics: URDF angles placing the toe of `leg` at `target` (relative
    /// to the base COM, base axes), starting from `seed`, by damped Gauss–Newton. Returns the
    /// angles (clamped to the joint limits) and the remaining position error \[m\].
    pub fn leg_ik(&self, leg: usize, target: Vector3<f64>, seed: [f64; 3]) -> ([f64; 3], f64) {
        let mut q = seed;
        let clamp = |q: &mut [f64; 3]| {
            for (j, v) in q.iter_mut().enumerate() {
                let (lo, hi) = self.joint_limits[j];
                *v = v.clamp(lo, hi);
            }
        };
        for _ in 0..60 {
            let p = self.toe_position(leg, q);
            let err = target - p;
            if err.norm() < 1e-9 {
                break;
            }
            let mut jac = nalgebra::Matrix3::zeros();
            let h = 1e-6;
            for j in 0..3 {
                let mut qh = q;
                qh[j] += h;
                let d = (self.toe_position(leg, qh) - p) / h;
                jac.set_column(j, &d);
            }
            let lambda = 1e-4;
            let jt = jac.transpose();
            let a = jt * jac + nalgebra::Matrix3::identity() * lambda;
            let Some(dq) = a.try_inverse().map(|inv| inv * jt * err) else {
                break;
            };
            for j in 0..3 {
                q[j] += dq[j].clamp(-0.3, 0.3);
            }
            clamp(&mut q);
        }
        let e = (target - self.toe_position(leg, q)).norm();
        (q, e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_model_parses_and_has_reference_mass() {
        let m = RobotModel::builtin();
        assert!((m.total_mass() - 25.567).abs() < 1e-9);
    }

    #[test]
    fn default_pose_matches_reference_conventions() {
        let m = RobotModel::builtin();
        let q = m.default_urdf_angles();
        let want = [0.0, 0.07, -0.59];
        for i in 0..12 {
            assert!((q[i] - want[i % 3]).abs() < 1e-12, "motor {i}: {}", q[i]);
            assert!((m.urdf_to_motor(i, q[i]) - m.default_motor_angles()[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn default_toe_positions_match_reference_table() {
        let m = RobotModel::builtin();
        let q = m.default_urdf_angles();
        let want = [
            [0.1478, -0.1146, -0.4558],
            [0.1478, 0.1169, -0.4558],
            [-0.2895, -0.1146, -0.4558],
            [-0.2895, 0.1169, -0.4558],
        ];
        for leg in 0..4 {
            let p = m.toe_position(leg, [q[3 * leg], q[3 * leg + 1], q[3 * leg + 2]]);
            for k in 0..3 {
                assert!((p[k] - want[leg][k]).abs() < 1e-3, "leg {leg}: {p:?}");
            }
        }
    }

    #[test]
    fn ik_inverts_fk() {
        let m = RobotModel::builtin();
        for leg in 0..4 {
            let q = [0.1, 0.3, -1.0];
            let target = m.toe_position(leg, q);
            let (sol, err) = m.leg_ik(leg, target, [0.0, 0.07, -0.59]);
            assert!(err < 1e-6, "leg {leg} err {err}");
            assert!((m.toe_position(leg, sol) - target).norm() < 1e-6);
        }
    }

    #[test]
    fn malformed_ron_is_an_error() {
        assert!(RobotModel::from_ron("RobotModel(name: 3)", "x.ron").is_err());
        let broken = BUILTIN_MODEL_RON.replace("mass: 13.715", "mass: -1.0");
        assert!(matches!(
            RobotModel::from_ron(&broken, "x.ron"),
            Err(ModelError::Invalid { .. })
        ));
    }
}
