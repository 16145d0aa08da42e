//! A procedural gait generator: per-leg phase patterns plus leg inverse kinematics produce
//! reference clips in the motion_imitation format.
//!
//! These clips stand in for the CC BY-NC mocap clips of the original (which users load from a
//! path). They are not retargeted dog motions: feet follow straight stance lines and half-sine
//! swing arcs under a level body, at speeds chosen to be feasible for the model.

use std::f64::consts::PI;

use nalgebra::Vector3;

use crate::model::{NUM_LEGS, RobotModel};
use crate::motion::{FRAME_SIZE, LoopMode, MotionClip, mount_rotation, yaw_rotation};

/// The built-in gaits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Gait {
    /// Lateral pairs (FR+RR, FL+RL) alternate, about 1 m/s forward.
    Pace,
    /// Diagonal pairs (FR+RL, FL+RR) alternate, about 1.4 m/s forward.
    Trot,
    /// Trot in place while turning at about 2.3 rad/s.
    Spin,
    /// Front pair and rear pair alternate.
    Bound,
    /// All four legs together (small hops).
    Pronk,
    /// Trot sideways to the left.
    SideStep,
    /// Four-beat walk along a curve.
    Turn,
}

impl Gait {
    /// Every built-in gait.
    pub const ALL: [Gait; 7] = [
        Gait::Pace,
        Gait::Trot,
        Gait::Spin,
        Gait::Bound,
        Gait::Pronk,
        Gait::SideStep,
        Gait::Turn,
    ];

    /// Lower-case name (`pace`, `side_step`, …).
    pub fn name(self) -> &'static str {
        match self {
            Gait::Pace => "pace",
            Gait::Trot => "trot",
            Gait::Spin => "spin",
            Gait::Bound => "bound",
            Gait::Pronk => "pronk",
            Gait::SideStep => "side_step",
            Gait::Turn => "turn",
        }
    }

    /// Parses a name as returned by [`Gait::name`].
    pub fn from_name(name: &str) -> Option<Gait> {
        Gait::ALL.into_iter().find(|g| g.name() == name)
    }

    /// The gait's parameters.
    pub fn params(self) -> GaitParams {
        let base = GaitParams {
            period: 0.5,
            duty: 0.5,
            offsets: [0.0, 0.5, 0.5, 0.0],
            velocity: (0.0, 0.0),
            yaw_rate: 0.0,
            step_height: 0.08,
            body_height: 0.44,
            bob: 0.0,
        };
        match self {
            Gait::Pace => GaitParams {
                period: 0.6,
                duty: 0.6,
                offsets: [0.0, 0.5, 0.0, 0.5],
                velocity: (1.0, 0.0),
                ..base
            },
            Gait::Trot => GaitParams {
                velocity: (1.4, 0.0),
                ..base
            },
            Gait::Spin => GaitParams {
                period: 0.75,
                yaw_rate: 2.3,
                step_height: 0.07,
                ..base
            },
            Gait::Bound => GaitParams {
                period: 0.4,
                duty: 0.45,
                offsets: [0.0, 0.0, 0.5, 0.5],
                velocity: (0.9, 0.0),
                bob: 0.015,
                ..base
            },
            Gait::Pronk => GaitParams {
                period: 0.5,
                duty: 0.6,
                offsets: [0.0; 4],
                velocity: (0.3, 0.0),
                bob: 0.02,
                step_height: 0.06,
                ..base
            },
            Gait::SideStep => GaitParams {
                velocity: (0.0, 0.35),
                step_height: 0.07,
                ..base
            },
            Gait::Turn => GaitParams {
                period: 0.8,
                duty: 0.75,
                offsets: [0.0, 0.5, 0.75, 0.25],
                velocity: (0.5, 0.0),
                yaw_rate: 0.8,
                step_height: 0.07,
                ..base
            },
        }
    }
}

/// Parameters of a periodic gait.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitParams {
    /// Cycle period \[s\].
    pub period: f64,
    /// Fraction of the cycle each foot is on the ground.
    pub duty: f64,
    /// Phase at which each leg (FR, FL, RR, RL) starts its stance, in cycles.
    pub offsets: [f64; NUM_LEGS],
    /// Body-frame velocity (forward, left) [m/s].
    pub velocity: (f64, f64),
    /// Yaw rate [rad/s].
    pub yaw_rate: f64,
    /// Swing apex height \[m\].
    pub step_height: f64,
    /// Base COM height \[m\].
    pub body_height: f64,
    /// Vertical body oscillation amplitude (twice per cycle) \[m\].
    pub bob: f64,
}

/// Frame period of generated clips (the mocap clips' 60 Hz).
pub const FRAME_DURATION: f64 = 1.0 / 60.0;

/// Generates the clip of `gait` for `model`.
///
/// ```
/// use a2perf_locomotion::{gait, RobotModel};
/// let clip = gait::generate(&RobotModel::builtin(), gait::Gait::Pace);
/// assert_eq!(clip.name, "gen_pace");
/// assert!(clip.frames.len() > 30);
/// ```
pub fn generate(model: &RobotModel, gait: Gait) -> MotionClip {
    generate_with_residual(model, gait, &gait.params()).0
}

/// Generates a clip from explicit parameters; also returns the largest inverse-kinematics
/// residual \[m\] over all frames and feet (0 when every foot target was reachable).
pub fn generate_with_residual(model: &RobotModel, gait: Gait, p: &GaitParams) -> (MotionClip, f64) {
    let n_frames = ((p.period / FRAME_DURATION).round() as usize).max(2) + 1;
    let dt = p.period / (n_frames - 1) as f64;
    let q0 = model.default_urdf_angles();
    // Nominal feet: below the default-pose toes, on the ground at the body height.
    let ground_z = model.toe_radius - p.body_height;
    let nominal: [Vector3<f64>; NUM_LEGS] = std::array::from_fn(|leg| {
        let mut t = model.toe_position(leg, [q0[3 * leg], q0[3 * leg + 1], q0[3 * leg + 2]]);
        t.z = ground_z;
        t
    });
    let stance_time = p.duty * p.period;
    let v = Vector3::new(p.velocity.0, p.velocity.1, 0.0);
    let w = Vector3::new(0.0, 0.0, p.yaw_rate);
    let mut seeds: [[f64; 3]; NUM_LEGS] =
        std::array::from_fn(|leg| [q0[3 * leg], q0[3 * leg + 1], q0[3 * leg + 2]]);
    let mut worst = 0.0f64;
    let mut frames = Vec::with_capacity(n_frames);
    for i in 0..n_frames {
        let t = i as f64 * dt;
        let phase = t / p.period;
        // Root: integrate the body-frame velocity along the turning heading (closed form).
        let yaw = p.yaw_rate * t;
        let root_xy = if p.yaw_rate.abs() < 1e-9 {
            v * t
        } else {
            let (s, c) = yaw.sin_cos();
            let r = 1.0 / p.yaw_rate;
            Vector3::new(
                r * (v.x * s - v.y * (1.0 - c)),
                r * (v.x * (1.0 - c) + v.y * s),
                0.0,
            )
        };
        let z = p.body_height + p.bob * (4.0 * PI * phase).cos();
        let mut f = [0.0; FRAME_SIZE];
        f[0] = root_xy.x;
        f[1] = root_xy.y;
        f[2] = z;
        let q = (yaw_rotation(yaw) * mount_rotation()).into_inner();
        f[3] = q.i;
        f[4] = q.j;
        f[5] = q.k;
        f[6] = q.w;
        for leg in 0..NUM_LEGS {
            let nom = nominal[leg];
            // Ground-relative foot travel over one stance, in the body frame.
            let travel = (v + w.cross(&nom)) * stance_time;
            let local = (phase - p.offsets[leg]).rem_euclid(1.0);
            let mut target = if local < p.duty {
                let s = local / p.duty;
                nom + travel * (0.5 - s)
            } else {
                let u = (local - p.duty) / (1.0 - p.duty);
                let blend = 0.5 - 0.5 * (PI * u).cos();
                let mut x = nom + travel * (blend - 0.5);
                x.z += p.step_height * (PI * u).sin();
                x
            };
            // Feet are placed relative to the ground; the body bob moves the hip, not the foot.
            target.z -= z - p.body_height;
            let (sol, err) = model.leg_ik(leg, target, seeds[leg]);
            worst = worst.max(err);
            seeds[leg] = sol;
            f[7 + 3 * leg..10 + 3 * leg].copy_from_slice(&sol);
        }
        frames.push(f);
    }
    let clip = MotionClip::from_frames(
        &format!("gen_{}", gait.name()),
        LoopMode::Wrap,
        dt,
        true,
        p.yaw_rate != 0.0,
        frames,
    );
    match clip {
        Ok(c) => (c, worst),
        // from_frames only fails on fewer than 2 frames or zero quaternions, neither possible here.
        Err(e) => unreachable!("generated clip invalid: {e}"),
    }
}

/// A clip that stands still in the default pose, with the toes on the ground.
///
/// ```
/// use a2perf_locomotion::{gait, RobotModel};
/// let clip = gait::standing_clip(&RobotModel::builtin());
/// assert_eq!(clip.frames.len(), 2);
/// ```
pub fn standing_clip(model: &RobotModel) -> MotionClip {
    let q = model.default_urdf_angles();
    let toe = model.toe_position(0, [q[0], q[1], q[2]]);
    let mut f = [0.0; FRAME_SIZE];
    f[2] = model.toe_radius - toe.z;
    let m = mount_rotation().into_inner();
    f[3..7].copy_from_slice(&[m.i, m.j, m.k, m.w]);
    f[7..].copy_from_slice(&q);
    match MotionClip::from_frames("stand", LoopMode::Wrap, 0.5, false, false, vec![f, f]) {
        Ok(c) => c,
        Err(e) => unreachable!("standing clip invalid: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::{ReferenceMotion, heading_of};

    #[test]
    fn every_gait_is_kinematically_feasible_and_periodic() {
        let m = RobotModel::builtin();
        for g in Gait::ALL {
            let (clip, err) = generate_with_residual(&m, g, &g.params());
            assert!(err < 2e-3, "{g:?}: IK residual {err}");
            let first = &clip.frames[0];
            let last = &clip.frames[clip.frames.len() - 1];
            for j in 7..FRAME_SIZE {
                assert!(
                    (first[j] - last[j]).abs() < 1e-3,
                    "{g:?} joint {j} not periodic"
                );
            }
            let r = ReferenceMotion::new(clip);
            let p = g.params();
            let expect_heading = p.yaw_rate * p.period;
            assert!((r.cycle_delta_heading() - expect_heading).abs() < 1e-6);
            let start = r.frame_at(0.0);
            assert!(heading_of(&start.root_rot).abs() < 1e-9);
        }
    }

    #[test]
    fn gait_names_round_trip() {
        for g in Gait::ALL {
            assert_eq!(Gait::from_name(g.name()), Some(g));
        }
        assert_eq!(Gait::from_name("gallop"), None);
    }
}
