//! Reference motions: the motion_imitation JSON clip format and its interpolation.
//!
//! A frame holds 19 numbers: root position (world, base COM, z up), root quaternion (x, y, z, w,
//! of the Y-up URDF base, so ≈ (0.5, 0.5, 0.5, 0.5) when facing +x) and 12 URDF joint angles
//! ordered FR, FL, RR, RL × (abduction, hip, knee).

use std::path::Path;

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::model::NUM_MOTORS;

/// Values per frame.
pub const FRAME_SIZE: usize = 19;

/// The URDF base's mounting rotation: robot orientation = `q_urdf_base ⊗ mount⁻¹`.
pub fn mount_rotation() -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(0.5, 0.5, 0.5, 0.5))
}

/// Heading (yaw of the robot's forward axis) of a robot-frame orientation.
pub fn heading_of(robot_rot: &UnitQuaternion<f64>) -> f64 {
    let f = robot_rot * Vector3::x();
    f.y.atan2(f.x)
}

/// Rotation about +z by `angle`.
pub fn yaw_rotation(angle: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle)
}

/// How a clip continues past its last frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, serde::Serialize)]
pub enum LoopMode {
    /// Hold the last frame.
    Clamp,
    /// Start again from the first frame (plus cycle offsets).
    Wrap,
}

/// Errors reading a clip.
#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The content is not a valid clip.
    #[error("{origin}: {reason}")]
    Invalid {
        /// File or clip name.
        origin: String,
        /// What is wrong (with line and column for JSON errors).
        reason: String,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ClipFile {
    #[serde(rename = "LoopMode")]
    loop_mode: LoopMode,
    #[serde(rename = "FrameDuration")]
    frame_duration: f64,
    #[serde(rename = "EnableCycleOffsetPosition", default)]
    cycle_offset_position: bool,
    #[serde(rename = "EnableCycleOffsetRotation", default)]
    cycle_offset_rotation: bool,
    #[serde(rename = "MotionWeight", default)]
    _motion_weight: Option<f64>,
    #[serde(rename = "Frames")]
    frames: Vec<Vec<f64>>,
}

/// A reference motion clip (frames already normalised as motion_imitation does on load).
#[derive(Clone, Debug, PartialEq)]
pub struct MotionClip {
    /// Clip name (file stem or generator name).
    pub name: String,
    /// Looping behaviour.
    pub loop_mode: LoopMode,
    /// Seconds between frames.
    pub frame_duration: f64,
    /// Each completed cycle adds the clip's root displacement.
    pub cycle_offset_position: bool,
    /// Each completed cycle adds the clip's heading change.
    pub cycle_offset_rotation: bool,
    /// Frames of 19 values.
    pub frames: Vec<[f64; FRAME_SIZE]>,
}

/// One interpolated reference state, in the clip's (or world) frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionFrame {
    /// Base COM position.
    pub root_pos: Vector3<f64>,
    /// Robot-frame base orientation (x forward, y left, z up; identity = level, facing +x).
    pub root_rot: UnitQuaternion<f64>,
    /// URDF joint angles.
    pub joints: [f64; NUM_MOTORS],
}

impl Default for MotionFrame {
    fn default() -> Self {
        Self {
            root_pos: Vector3::zeros(),
            root_rot: UnitQuaternion::identity(),
            joints: [0.0; NUM_MOTORS],
        }
    }
}

impl MotionFrame {
    /// Root orientation in the file convention (URDF base, including the mounting rotation).
    pub fn urdf_base_rot(&self) -> UnitQuaternion<f64> {
        self.root_rot * mount_rotation()
    }
}

/// Velocities of a reference state (world frame for the root).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionVelocity {
    /// Base linear velocity.
    pub linear: Vector3<f64>,
    /// Base angular velocity.
    pub angular: Vector3<f64>,
    /// Joint velocities.
    pub joints: [f64; NUM_MOTORS],
}

impl MotionClip {
    /// Reads a clip file.
    pub fn load(path: &Path) -> Result<Self, MotionError> {
        let text = std::fs::read_to_string(path).map_err(|source| MotionError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        Self::parse(&text, &name).map_err(|e| match e {
            MotionError::Invalid { reason, .. } => MotionError::Invalid {
                origin: path.display().to_string(),
                reason,
            },
            other => other,
        })
    }

    /// Parses clip JSON text; `name` names the clip (and the source in errors).
    ///
    /// ```
    /// let text = r#"{"LoopMode": "Wrap", "FrameDuration": 0.5, "Frames": [
    ///   [1,2,0.4, 0.5,0.5,0.5,0.5, 0,0,0,0,0,0,0,0,0,0,0,0],
    ///   [2,2,0.4, 0.5,0.5,0.5,0.5, 0,0,0,0,0,0,0,0,0,0,0,0]]}"#;
    /// let clip = a2perf_locomotion::MotionClip::parse(text, "walk").unwrap();
    /// assert_eq!(clip.frames.len(), 2);
    /// assert_eq!(clip.duration(), 0.5);
    /// assert_eq!(clip.frames[0][0], 0.0); // frame-0 xy is subtracted
    /// assert!(a2perf_locomotion::MotionClip::parse("{}", "bad").is_err());
    /// ```
    pub fn parse(text: &str, name: &str) -> Result<Self, MotionError> {
        let bad = |reason: String| MotionError::Invalid {
            origin: name.into(),
            reason,
        };
        let file: ClipFile = serde_json::from_str(text).map_err(|e| bad(e.to_string()))?;
        if !(file.frame_duration.is_finite() && file.frame_duration > 0.0) {
            return Err(bad(format!(
                "FrameDuration must be positive, found {}",
                file.frame_duration
            )));
        }
        if file.frames.len() < 2 {
            return Err(bad(format!(
                "a clip needs at least 2 frames, found {}",
                file.frames.len()
            )));
        }
        let mut frames = Vec::with_capacity(file.frames.len());
        for (i, f) in file.frames.iter().enumerate() {
            if f.len() != FRAME_SIZE {
                return Err(bad(format!(
                    "frame {i} has {} values, expected {FRAME_SIZE}",
                    f.len()
                )));
            }
            if f.iter().any(|v| !v.is_finite()) {
                return Err(bad(format!("frame {i} has a non-finite value")));
            }
            let mut a = [0.0; FRAME_SIZE];
            a.copy_from_slice(f);
            frames.push(a);
        }
        Self::from_frames(
            name,
            file.loop_mode,
            file.frame_duration,
            file.cycle_offset_position,
            file.cycle_offset_rotation,
            frames,
        )
        .map_err(|e| match e {
            MotionError::Invalid { reason, .. } => bad(reason),
            other => other,
        })
    }

    /// Builds a clip from raw frames, normalising as motion_imitation does: frame-0 xy is
    /// subtracted from every frame and quaternions are normalised with w ≥ 0.
    pub fn from_frames(
        name: &str,
        loop_mode: LoopMode,
        frame_duration: f64,
        cycle_offset_position: bool,
        cycle_offset_rotation: bool,
        mut frames: Vec<[f64; FRAME_SIZE]>,
    ) -> Result<Self, MotionError> {
        let bad = |reason: String| MotionError::Invalid {
            origin: name.into(),
            reason,
        };
        if frames.len() < 2 {
            return Err(bad("a clip needs at least 2 frames".into()));
        }
        let (x0, y0) = (frames[0][0], frames[0][1]);
        for (i, f) in frames.iter_mut().enumerate() {
            f[0] -= x0;
            f[1] -= y0;
            let n = (f[3] * f[3] + f[4] * f[4] + f[5] * f[5] + f[6] * f[6]).sqrt();
            if n.is_nan() || n <= 1e-6 {
                return Err(bad(format!("frame {i} has a zero quaternion")));
            }
            let s = if f[6] < 0.0 { -1.0 / n } else { 1.0 / n };
            for v in &mut f[3..7] {
                *v *= s;
            }
        }
        Ok(Self {
            name: name.into(),
            loop_mode,
            frame_duration,
            cycle_offset_position,
            cycle_offset_rotation,
            frames,
        })
    }

    /// Serialises to the motion_imitation JSON format.
    pub fn to_json(&self) -> String {
        let mut s = format!(
            "{{\n\"LoopMode\": \"{:?}\",\n\"FrameDuration\": {},\n\"EnableCycleOffsetPosition\": {},\n\"EnableCycleOffsetRotation\": {},\n\"Frames\":\n[\n",
            self.loop_mode,
            self.frame_duration,
            self.cycle_offset_position,
            self.cycle_offset_rotation
        );
        for (i, f) in self.frames.iter().enumerate() {
            let vals: Vec<String> = f.iter().map(|v| format!("{v:.5}")).collect();
            s.push_str(&format!(
                "  [{}]{}\n",
                vals.join(", "),
                if i + 1 < self.frames.len() { "," } else { "" }
            ));
        }
        s.push_str("]\n}\n");
        s
    }

    /// Clip duration `(N − 1)·FrameDuration`.
    pub fn duration(&self) -> f64 {
        (self.frames.len() - 1) as f64 * self.frame_duration
    }

    /// FNV-1a hash of the frame data and settings (for provenance records).
    pub fn content_hash(&self) -> String {
        let mut h = a2perf_core::hash::Fnv1a::new();
        h.write(&self.frame_duration.to_le_bytes());
        h.write(&[
            self.loop_mode as u8,
            u8::from(self.cycle_offset_position),
            u8::from(self.cycle_offset_rotation),
        ]);
        for f in &self.frames {
            for v in f {
                h.write(&v.to_le_bytes());
            }
        }
        format!("{:016x}", h.finish())
    }

    fn frame(&self, i: usize) -> MotionFrame {
        let f = &self.frames[i];
        let q = UnitQuaternion::from_quaternion(Quaternion::new(f[6], f[3], f[4], f[5]));
        MotionFrame {
            root_pos: Vector3::new(f[0], f[1], f[2]),
            root_rot: q * mount_rotation().inverse(),
            joints: std::array::from_fn(|j| f[7 + j]),
        }
    }
}

/// A clip prepared for sampling at arbitrary times (cycle offsets, finite-difference
/// velocities). Sampling allocates nothing.
///
/// ```
/// use a2perf_locomotion::{gait, ReferenceMotion, RobotModel};
/// let clip = gait::generate(&RobotModel::builtin(), gait::Gait::Trot);
/// let motion = ReferenceMotion::new(clip);
/// let a = motion.frame_at(0.0);
/// let b = motion.frame_at(motion.duration());
/// // One full cycle later the robot has moved forward by the cycle displacement.
/// assert!(b.root_pos.x - a.root_pos.x > 0.1);
/// ```
#[derive(Clone, Debug)]
pub struct ReferenceMotion {
    clip: MotionClip,
    frames: Vec<MotionFrame>,
    velocities: Vec<MotionVelocity>,
    cycle_delta_pos: Vector3<f64>,
    cycle_delta_heading: f64,
    joint_min: [f64; NUM_MOTORS],
    joint_max: [f64; NUM_MOTORS],
}

impl ReferenceMotion {
    /// Prepares `clip` for sampling.
    pub fn new(clip: MotionClip) -> Self {
        let n = clip.frames.len();
        let frames: Vec<MotionFrame> = (0..n).map(|i| clip.frame(i)).collect();
        let dt = clip.frame_duration;
        let mut velocities = Vec::with_capacity(n);
        for i in 0..n {
            // Forward differences; the last frame repeats the previous velocity.
            let (a, b) = if i + 1 < n {
                (&frames[i], &frames[i + 1])
            } else {
                (&frames[n - 2], &frames[n - 1])
            };
            let dq = b.root_rot * a.root_rot.inverse();
            velocities.push(MotionVelocity {
                linear: (b.root_pos - a.root_pos) / dt,
                angular: dq.scaled_axis() / dt,
                joints: std::array::from_fn(|j| (b.joints[j] - a.joints[j]) / dt),
            });
        }
        let first = &frames[0];
        let last = &frames[n - 1];
        let mut cycle_delta_pos = last.root_pos - first.root_pos;
        cycle_delta_pos.z = 0.0;
        let cycle_delta_heading = heading_of(&last.root_rot) - heading_of(&first.root_rot);
        let mut joint_min = [f64::INFINITY; NUM_MOTORS];
        let mut joint_max = [f64::NEG_INFINITY; NUM_MOTORS];
        for f in &frames {
            for j in 0..NUM_MOTORS {
                joint_min[j] = joint_min[j].min(f.joints[j]);
                joint_max[j] = joint_max[j].max(f.joints[j]);
            }
        }
        Self {
            clip,
            frames,
            velocities,
            cycle_delta_pos,
            cycle_delta_heading,
            joint_min,
            joint_max,
        }
    }

    /// The underlying clip.
    pub fn clip(&self) -> &MotionClip {
        &self.clip
    }

    /// Cycle duration.
    pub fn duration(&self) -> f64 {
        self.clip.duration()
    }

    /// Root displacement per cycle (z = 0).
    pub fn cycle_delta_pos(&self) -> Vector3<f64> {
        self.cycle_delta_pos
    }

    /// Heading change per cycle \[rad\].
    pub fn cycle_delta_heading(&self) -> f64 {
        self.cycle_delta_heading
    }

    /// Per-joint minimum and maximum over the clip's frames (the environment's observation
    /// bounds widen them to include the default pose shown before the clip starts).
    pub fn joint_range(&self) -> ([f64; NUM_MOTORS], [f64; NUM_MOTORS]) {
        (self.joint_min, self.joint_max)
    }

    /// Number of completed cycles at time `t` (0 for clamped clips).
    pub fn cycle_count(&self, t: f64) -> i64 {
        match self.clip.loop_mode {
            LoopMode::Wrap => (t / self.duration()).floor() as i64,
            LoopMode::Clamp => 0,
        }
    }

    fn blend_index(&self, t: f64) -> (usize, usize, f64) {
        let n = self.frames.len();
        let dur = self.duration();
        let phase = match self.clip.loop_mode {
            LoopMode::Wrap => {
                let p = t / dur;
                p - p.floor()
            }
            LoopMode::Clamp => (t / dur).clamp(0.0, 1.0),
        };
        let x = phase * (n - 1) as f64;
        let f0 = (x.floor() as usize).min(n - 1);
        let f1 = (f0 + 1).min(n - 1);
        (f0, f1, (x - f0 as f64).clamp(0.0, 1.0))
    }

    fn cycle_offset(&self, cycles: i64) -> (Vector3<f64>, UnitQuaternion<f64>) {
        let rot = if self.clip.cycle_offset_rotation {
            yaw_rotation(cycles as f64 * self.cycle_delta_heading)
        } else {
            UnitQuaternion::identity()
        };
        let mut pos = Vector3::zeros();
        if self.clip.cycle_offset_position {
            if self.clip.cycle_offset_rotation {
                let (range, sign) = if cycles >= 0 {
                    (0..cycles, 1.0)
                } else {
                    (cycles..0, -1.0)
                };
                for i in range {
                    pos += sign
                        * (yaw_rotation(i as f64 * self.cycle_delta_heading)
                            * self.cycle_delta_pos);
                }
            } else {
                pos = cycles as f64 * self.cycle_delta_pos;
            }
        }
        (pos, rot)
    }

    /// The reference state at time `t` (slerp for the root rotation, linear otherwise, plus
    /// cycle offsets).
    pub fn frame_at(&self, t: f64) -> MotionFrame {
        let (f0, f1, s) = self.blend_index(t);
        let (a, b) = (&self.frames[f0], &self.frames[f1]);
        let root_pos = a.root_pos.lerp(&b.root_pos, s);
        let root_rot = a.root_rot.slerp(&b.root_rot, s);
        let joints = std::array::from_fn(|j| a.joints[j] + s * (b.joints[j] - a.joints[j]));
        let (off_pos, off_rot) = self.cycle_offset(self.cycle_count(t));
        MotionFrame {
            root_pos: off_rot * root_pos + off_pos,
            root_rot: off_rot * root_rot,
            joints,
        }
    }

    /// Reference velocities at time `t` (blended forward differences, root velocities rotated
    /// by the cycle rotation offset).
    pub fn velocity_at(&self, t: f64) -> MotionVelocity {
        let (f0, f1, s) = self.blend_index(t);
        let (a, b) = (&self.velocities[f0], &self.velocities[f1]);
        let (_, off_rot) = self.cycle_offset(self.cycle_count(t));
        MotionVelocity {
            linear: off_rot * a.linear.lerp(&b.linear, s),
            angular: off_rot * a.angular.lerp(&b.angular, s),
            joints: std::array::from_fn(|j| a.joints[j] + s * (b.joints[j] - a.joints[j])),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn clip(frames: usize, rot: bool) -> MotionClip {
        let fr: Vec<[f64; FRAME_SIZE]> = (0..frames)
            .map(|i| {
                let yaw = if rot { 0.1 * i as f64 } else { 0.0 };
                let q = (yaw_rotation(yaw) * mount_rotation()).into_inner();
                let mut f = [0.0; FRAME_SIZE];
                f[0] = 0.1 * i as f64 + 3.0;
                f[2] = 0.45;
                f[3] = q.i;
                f[4] = q.j;
                f[5] = q.k;
                f[6] = q.w;
                f[7] = i as f64;
                f
            })
            .collect();
        MotionClip::from_frames("t", LoopMode::Wrap, 0.1, true, rot, fr).unwrap()
    }

    #[test]
    fn interpolation_and_cycle_offsets() {
        let m = ReferenceMotion::new(clip(5, false));
        assert!((m.duration() - 0.4).abs() < 1e-12);
        let f = m.frame_at(0.15);
        assert!((f.root_pos.x - 0.15).abs() < 1e-9);
        assert!((f.joints[0] - 1.5).abs() < 1e-9);
        let g = m.frame_at(0.4 + 0.15);
        assert!((g.root_pos.x - 0.55).abs() < 1e-9, "{}", g.root_pos.x);
        let v = m.velocity_at(0.05);
        assert!((v.linear.x - 1.0).abs() < 1e-9);
        assert!((v.joints[0] - 10.0).abs() < 1e-9);
        assert!(f.root_rot.angle() < 1e-9);
    }

    #[test]
    fn rotation_offsets_accumulate_heading() {
        let m = ReferenceMotion::new(clip(5, true));
        assert!((m.cycle_delta_heading() - 0.4).abs() < 1e-9);
        let f = m.frame_at(0.4 * 2.0 + 0.1);
        assert!((heading_of(&f.root_rot) - 0.9).abs() < 1e-9);
        let w = m.velocity_at(0.05);
        assert!((w.angular.z - 1.0).abs() < 1e-6);
    }

    #[test]
    fn malformed_clips_are_errors() {
        for text in [
            "",
            "{",
            r#"{"LoopMode": "Wrap", "FrameDuration": 0.1, "Frames": [[1,2,3]]}"#,
            r#"{"LoopMode": "Bounce", "FrameDuration": 0.1, "Frames": []}"#,
            r#"{"LoopMode": "Wrap", "FrameDuration": -1, "Frames": []}"#,
            r#"{"LoopMode": "Wrap", "FrameDuration": 0.1, "Frames": [[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0],[0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0,0]]}"#,
        ] {
            assert!(MotionClip::parse(text, "bad").is_err(), "accepted {text}");
        }
    }
}
