//! Property tests: parsers never panic, interpolation stays well formed.

use a2perf_locomotion::gait::{self, Gait};
use a2perf_locomotion::{MotionClip, ReferenceMotion, RobotModel, UrdfRobot};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn urdf_parser_never_panics(text in "[<>/=\"a-z0-9 .\\-!?]{0,200}") {
        let _ = UrdfRobot::parse(&text, "fuzz.urdf");
    }

    #[test]
    fn clip_parser_never_panics(text in "[\\[\\]{}:,\"0-9a-zA-Z. \\-]{0,200}") {
        let _ = MotionClip::parse(&text, "fuzz");
    }

    #[test]
    fn sampled_frames_are_finite_with_unit_rotations(t in -5.0f64..50.0, g in 0usize..7) {
        let motion = ReferenceMotion::new(gait::generate(&RobotModel::builtin(), Gait::ALL[g]));
        let f = motion.frame_at(t.max(0.0));
        prop_assert!(f.root_pos.iter().all(|v| v.is_finite()));
        prop_assert!((f.root_rot.quaternion().norm() - 1.0).abs() < 1e-9);
        prop_assert!(f.joints.iter().all(|v| v.is_finite()));
        let v = motion.velocity_at(t.max(0.0));
        prop_assert!(v.linear.iter().chain(v.angular.iter()).all(|x| x.is_finite()));
    }
}
