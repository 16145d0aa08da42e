//! Quadruped locomotion for A2Perf: a Laikago-class robot imitating reference motions, simulated
//! with rapier3d (the default) or the crate's own reduced-coordinate engine
//! (`physics: articulated`, [`sim::Physics`]).
//!
//! - [`model`]: the robot as project-owned RON data (masses, inertias, geometry, limits, default
//!   pose, motor conventions, PD gains) and its kinematics; [`urdf`] reads real URDF files.
//! - [`motion`]: motion_imitation JSON clips and their interpolation; [`gait`] generates the
//!   built-in clips (pace, trot, spin, bound, pronk, side step, turn).
//! - [`sim`]: the physics world (1 ms steps, PD torques every step) on either engine.
//! - [`env`](mod@env): the imitation task (160-D observation, 5-term reward, terminations);
//!   [`register`] adds `QuadrupedLocomotion-Dog{Pace,Trot,Spin}-v0` and `-Gait-v0`.
//!
//! ```
//! use a2perf_core::{Action, Registry};
//! let mut reg = Registry::new();
//! a2perf_locomotion::register(&mut reg);
//! let mut env = reg.make_env("QuadrupedLocomotion-DogTrot-v0", &Default::default()).unwrap();
//! let obs = env.reset(Some(1)).unwrap();
//! assert_eq!(obs.flat_values().len(), 160);
//! let step = env.step(&Action::Continuous(vec![0.0; 12])).unwrap();
//! assert!(step.reward.is_finite());
//! ```
//!
//! Deliberately not included: the original's mocap clips (CC BY-NC; load them with
//! `motion_file`), mesh collision shapes (simplified boxes, spheres and capsules are used),
//! rendering beyond the CLI's HTML export and the environment's stick-figure side view
//! ([`render::side_view`]), and PyBullet's exact contact model (rapier's
//! soft-constraint contacts stand in for Bullet's; the articulated engine has Bullet's soft toes,
//! its other contacts are rigid).
#![warn(missing_docs)]

mod articulated;
pub mod env;
pub mod filter;
pub mod gait;
pub mod model;
pub mod motion;
pub mod registry;
pub mod render;
pub mod sim;
pub mod urdf;

pub use env::{EnvConfig, LocomotionEnv, Mode, MotionSource, RewardTerms, Termination};
pub use model::{NUM_LEGS, NUM_MOTORS, RobotModel};
pub use motion::{LoopMode, MotionClip, MotionError, MotionFrame, MotionVelocity, ReferenceMotion};
pub use registry::register;
pub use sim::{RobotState, SimConfig, Simulation};
pub use urdf::{UrdfError, UrdfRobot};
