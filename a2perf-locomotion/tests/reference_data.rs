//! Agreement with the reference data in `../shared/data/locomotion/` (skipped with a message when
//! absent, unless `A2PERF_REQUIRE_SHARED=1`).

use std::collections::BTreeMap;
use std::path::PathBuf;

use a2perf_locomotion::{MotionClip, ReferenceMotion, RobotModel, UrdfRobot};
use nalgebra::{Point3, Vector3};

fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/locomotion/"
    ))
    .join(rel);
    if p.exists() {
        Some(p)
    } else if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
        panic!("required shared data missing: {}", p.display());
    } else {
        eprintln!("SKIP: {} not found", p.display());
        None
    }
}

/// URDF (Y-up, x left, z forward) → robot axes (x forward, y left, z up).
fn robot_axes(v: Vector3<f64>) -> Vector3<f64> {
    Vector3::new(v.z, v.x, v.y)
}

#[test]
fn builtin_model_agrees_with_the_urdf() {
    let Some(path) = shared("laikago/laikago_toes_limits.urdf") else {
        return;
    };
    let urdf = UrdfRobot::load(&path).unwrap();
    let model = RobotModel::builtin();
    // Masses: exact to the URDF's printed digits.
    assert!((urdf.total_mass() - model.total_mass()).abs() < 1e-9);
    let names = ["FR", "FL", "RR", "RL"];
    for (leg, n) in names.iter().enumerate() {
        let l = &model.legs[leg];
        for (link, mass) in [
            ("hip_motor", l.hip_motor.mass),
            ("upper_leg", l.upper_leg.mass),
            ("lower_leg", l.lower_leg.mass),
        ] {
            assert!((urdf.link(&format!("{n}_{link}")).unwrap().mass - mass).abs() < 1e-9);
        }
        // Limits.
        let joints = [
            format!("{n}_hip_motor_2_chassis_joint"),
            format!("{n}_upper_leg_2_hip_motor_joint"),
            format!("{n}_lower_leg_2_upper_leg_joint"),
        ];
        for (k, j) in joints.iter().enumerate() {
            let (lo, hi) = urdf.joint(j).unwrap().limits.unwrap();
            assert!(
                (lo - model.joint_limits[k].0).abs() < 1e-9
                    && (hi - model.joint_limits[k].1).abs() < 1e-9,
                "{j}"
            );
        }
    }
    assert!((urdf.link("chassis").unwrap().mass - model.chassis.mass).abs() < 1e-9);
    // Default toe positions relative to the base COM, from the URDF chain: within 0.1 mm.
    let q = model.default_urdf_angles();
    let mut angles = BTreeMap::new();
    for (leg, n) in names.iter().enumerate() {
        angles.insert(format!("{n}_hip_motor_2_chassis_joint"), q[3 * leg]);
        angles.insert(format!("{n}_upper_leg_2_hip_motor_joint"), q[3 * leg + 1]);
        angles.insert(format!("{n}_lower_leg_2_upper_leg_joint"), q[3 * leg + 2]);
    }
    let com = urdf.link("chassis").unwrap().com;
    for (leg, n) in names.iter().enumerate() {
        let toe_link = format!("toe{n}");
        let pose = urdf.link_pose(&toe_link, &angles).unwrap();
        let p = robot_axes((pose * Point3::origin()).coords - com);
        let mine = model.toe_position(leg, [q[3 * leg], q[3 * leg + 1], q[3 * leg + 2]]);
        assert!(
            (p - mine).norm() < 1e-4,
            "{n}: urdf {p:?} vs model {mine:?}"
        );
    }
}

#[test]
fn clip_loader_reproduces_the_reference_table() {
    // (file, frames, frame duration, duration, cycle position offset, cycle rotation offset)
    let table = [
        ("dog_pace", 39, 0.01667, 0.6335, true, false),
        ("dog_trot", 33, 0.01667, 0.5334, true, false),
        ("dog_spin", 46, 0.01667, 0.7501, true, true),
        ("hopturn", 91, 0.041667, 3.75, true, false),
        ("sidesteps", 146, 0.041667, 6.0417, true, false),
    ];
    for (name, n, dt, dur, cpos, crot) in table {
        let Some(path) = shared(&format!("motions/{name}.txt")) else {
            return;
        };
        let clip = MotionClip::load(&path).unwrap();
        assert_eq!(clip.frames.len(), n, "{name}");
        assert!(
            (clip.frame_duration - dt).abs() < 1e-5,
            "{name}: {}",
            clip.frame_duration
        );
        assert!(
            (clip.duration() - dur).abs() < 1e-4,
            "{name}: {}",
            clip.duration()
        );
        assert_eq!(
            (clip.cycle_offset_position, clip.cycle_offset_rotation),
            (cpos, crot)
        );
        assert_eq!(clip.frames[0][0], 0.0);
        let m = ReferenceMotion::new(clip);
        if name == "dog_pace" {
            assert!((m.cycle_delta_pos().x - 0.6877).abs() < 1e-3);
        }
        if name == "dog_spin" {
            assert!(
                (m.cycle_delta_heading() - 1.7394).abs() < 0.02,
                "{}",
                m.cycle_delta_heading()
            );
        }
        // Every sampled frame is finite and within one cycle's reach.
        for k in 0..50 {
            let f = m.frame_at(k as f64 * 0.05);
            assert!(f.root_pos.iter().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn truncated_clip_file_is_an_error_naming_the_file() {
    let Some(path) = shared("motions/dog_pace.txt") else {
        return;
    };
    let text = std::fs::read_to_string(path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("broken.txt");
    std::fs::write(&bad, &text[..text.len() / 2]).unwrap();
    let err = MotionClip::load(&bad).unwrap_err().to_string();
    assert!(err.contains("broken.txt"), "{err}");
    let urdf = dir.path().join("broken.urdf");
    let Some(upath) = shared("laikago/laikago_toes_limits.urdf") else {
        return;
    };
    let utext = std::fs::read_to_string(upath).unwrap();
    std::fs::write(&urdf, &utext[..utext.len() / 2]).unwrap();
    assert!(UrdfRobot::load(&urdf).is_err());
}
