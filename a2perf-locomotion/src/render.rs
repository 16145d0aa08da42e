//! Pictures of the robot: the environment's `rgb_array` frame ([`side_view`]), and rollout
//! recording with a self-contained HTML animation (inline canvas + JavaScript, no external
//! downloads) showing the reference and the simulated robot side by side.

use a2perf_core::render::{Canvas, Frame};
use a2perf_core::{Action, Env, EnvError, Observation, Step};
use nalgebra::{Point3, Vector3};

use crate::env::{CONTROL_DT, LocomotionEnv};
use crate::model::{NUM_LEGS, NUM_MOTORS, RobotModel, v3};
use crate::sim::{RobotState, Simulation};

/// Points drawn per robot: 8 chassis-box corners, then per leg hip, hip-pitch joint, knee, toe.
pub const POINTS_PER_ROBOT: usize = 8 + 4 * NUM_LEGS;

/// Width of [`side_view`] frames, pixels.
pub const FRAME_WIDTH: usize = 320;
/// Height of [`side_view`] frames, pixels.
pub const FRAME_HEIGHT: usize = 240;
/// Scale of [`side_view`] frames: pixels per metre.
pub const PIXELS_PER_METRE: f64 = 250.0;
/// Row of [`side_view`] frames where the ground (`z = 0`) is.
pub const GROUND_ROW: f64 = 200.0;
/// Colour of the simulated robot (as in [`rollout_html`]).
pub const ROBOT_COLOR: [u8; 3] = [0xcc, 0x44, 0x33];
/// Colour of the reference pose (as in [`rollout_html`]).
pub const REFERENCE_COLOR: [u8; 3] = [0x22, 0xaa, 0x77];
const SKY: [u8; 3] = [0xff, 0xff, 0xff];
const GROUND: [u8; 3] = [0xea, 0xea, 0xea];
const GROUND_LINE: [u8; 3] = [0x60, 0x60, 0x60];
const TICK: [u8; 3] = [0x99, 0x99, 0x99];
/// Ground marks every this many metres (every fifth one longer), fixed in the world so that
/// they scroll past as the robot walks.
const TICK_SPACING: f64 = 0.1;
/// Chassis-box edges between the 8 corners of [`state_points`] (corner `k` has bit 0 = +x,
/// bit 1 = +y, bit 2 = +z).
const BOX_EDGES: [(usize, usize); 12] = [
    (0, 1),
    (2, 3),
    (4, 5),
    (6, 7),
    (0, 2),
    (1, 3),
    (4, 6),
    (5, 7),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

/// A side view of the robot and the reference pose: an orthographic projection onto the x–z
/// plane, [`FRAME_WIDTH`] × [`FRAME_HEIGHT`] pixels at [`PIXELS_PER_METRE`], the camera centred
/// horizontally on `camera_x` (the robot's base) with the ground at row [`GROUND_ROW`].
///
/// `robot` and `reference` are [`state_points`] (other lengths draw the complete chassis and
/// legs they hold); the reference is drawn first in [`REFERENCE_COLOR`], the robot over it in
/// [`ROBOT_COLOR`]: chassis-box edges, legs (hip, hip-pitch joint, knee, toe) and a dot at each
/// toe. Points off the frame, or not finite, are clipped away.
///
/// ```
/// use a2perf_core::{Env, Frame};
/// use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, MotionSource};
/// use a2perf_locomotion::gait::Gait;
/// use a2perf_locomotion::render::{side_view, state_points, FRAME_HEIGHT, FRAME_WIDTH};
/// let mut env = LocomotionEnv::new(EnvConfig::new("x", MotionSource::Generated(Gait::Trot))).unwrap();
/// env.reset(Some(0)).unwrap();
/// let state = env.sim().state();
/// let robot = state_points(env.sim().model(), &state);
/// let reference = state_points(env.sim().model(), &env.reference_state(env.reference_time()));
/// let frame = side_view(&robot, &reference, state.base_pos.x);
/// assert_eq!(frame, env.render("rgb_array").unwrap());
/// let Frame::Rgb { height, width, .. } = frame else { unreachable!() };
/// assert_eq!((height, width), (FRAME_HEIGHT, FRAME_WIDTH));
/// ```
pub fn side_view(robot: &[[f64; 3]], reference: &[[f64; 3]], camera_x: f64) -> Frame {
    let camera_x = if camera_x.is_finite() { camera_x } else { 0.0 };
    let (w, h) = (FRAME_WIDTH as f64, FRAME_HEIGHT as f64);
    let mut c = Canvas::new(FRAME_WIDTH, FRAME_HEIGHT, SKY);
    c.fill_rect(0.0, GROUND_ROW, w, h, GROUND, 1.0);
    let px = |x: f64| w / 2.0 + (x - camera_x) * PIXELS_PER_METRE;
    let half_width = w / 2.0 / PIXELS_PER_METRE;
    let first = ((camera_x - half_width) / TICK_SPACING).floor();
    let ticks = (2.0 * half_width / TICK_SPACING).ceil() as usize + 1;
    for i in 0..=ticks {
        let k = first + i as f64;
        let len = if k.rem_euclid(5.0) == 0.0 { 10.0 } else { 5.0 };
        let x = px(k * TICK_SPACING);
        c.line(x, GROUND_ROW, x, GROUND_ROW + len, TICK, 1);
    }
    c.line(0.0, GROUND_ROW, w, GROUND_ROW, GROUND_LINE, 1);
    for (points, color) in [(reference, REFERENCE_COLOR), (robot, ROBOT_COLOR)] {
        let p = |i: usize| {
            (
                px(points[i][0]),
                GROUND_ROW - points[i][2] * PIXELS_PER_METRE,
            )
        };
        if points.len() >= 8 {
            for (a, b) in BOX_EDGES {
                let ((x0, y0), (x1, y1)) = (p(a), p(b));
                c.line(x0, y0, x1, y1, color, 1);
            }
        }
        for leg in 0..NUM_LEGS {
            let base = 8 + 4 * leg;
            if points.len() < base + 4 {
                break;
            }
            for k in base..base + 3 {
                let ((x0, y0), (x1, y1)) = (p(k), p(k + 1));
                c.line(x0, y0, x1, y1, color, 2);
            }
            let (tx, ty) = p(base + 3);
            c.disc(tx, ty, 2.5, color);
        }
    }
    c.into_frame()
}

/// How actions are chosen for a rendered rollout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderPolicy {
    /// Zero offsets: hold the default pose.
    Zero,
    /// Open-loop feed-forward: PD targets equal to the reference's next joint angles.
    Reference,
}

/// One recorded control step.
#[derive(Clone, Debug, PartialEq)]
pub struct RolloutFrame {
    /// Robot points (world).
    pub robot: Vec<[f64; 3]>,
    /// Reference points (world).
    pub reference: Vec<[f64; 3]>,
    /// Reward of the step that led here (0 for the first frame).
    pub reward: f64,
}

/// A recorded rollout.
#[derive(Clone, Debug, PartialEq)]
pub struct Rollout {
    /// Environment id.
    pub env_id: String,
    /// Clip name.
    pub clip: String,
    /// Frames, one per control step (plus the initial state).
    pub frames: Vec<RolloutFrame>,
    /// Episode return.
    pub total_reward: f64,
}

/// Drawing points of a robot state.
pub fn state_points(model: &RobotModel, s: &RobotState) -> Vec<[f64; 3]> {
    let poses = Simulation::body_poses(model, s);
    let base = poses[0];
    let c = v3(model.chassis_box_center);
    let h = v3(model.chassis_box_half_extents);
    let mut out = Vec::with_capacity(POINTS_PER_ROBOT);
    for k in 0..8 {
        let sx = if k & 1 == 0 { -1.0 } else { 1.0 };
        let sy = if k & 2 == 0 { -1.0 } else { 1.0 };
        let sz = if k & 4 == 0 { -1.0 } else { 1.0 };
        let p = base * Point3::from(c + Vector3::new(sx * h.x, sy * h.y, sz * h.z));
        out.push([p.x, p.y, p.z]);
    }
    for leg in 0..NUM_LEGS {
        let hip = poses[1 + 3 * leg].translation.vector;
        let upper = poses[2 + 3 * leg].translation.vector;
        let lower = poses[3 + 3 * leg];
        let knee = lower.translation.vector;
        let toe = lower * Point3::from(v3(model.legs[leg].toe_origin));
        for p in [hip, upper, knee, toe.coords] {
            out.push([p.x, p.y, p.z]);
        }
    }
    out
}

/// Runs one episode of at most `steps` control steps and records it.
pub fn record_rollout(
    env: &mut LocomotionEnv,
    policy: RenderPolicy,
    steps: usize,
    seed: u64,
) -> Result<Rollout, EnvError> {
    let model = RobotModel::builtin();
    let mut obs = Observation::default();
    env.reset_into(Some(seed), &mut obs)?;
    let mut frames = Vec::with_capacity(steps + 1);
    let snapshot = |env: &LocomotionEnv, reward: f64| RolloutFrame {
        robot: state_points(&model, &env.sim().state()),
        reference: state_points(&model, &env.reference_state(env.reference_time())),
        reward,
    };
    frames.push(snapshot(env, 0.0));
    let default = model.default_motor_angles();
    let mut step = Step::default();
    let mut total = 0.0;
    let mut action = vec![0.0f32; NUM_MOTORS];
    for _ in 0..steps {
        if policy == RenderPolicy::Reference {
            let next = env.reference_state(env.reference_time() + CONTROL_DT);
            for i in 0..NUM_MOTORS {
                action[i] = (model.urdf_to_motor(i, next.q[i]) - default[i]) as f32;
            }
        }
        env.step_into(&Action::Continuous(action.clone()), &mut step)?;
        total += step.reward;
        frames.push(snapshot(env, step.reward));
        if step.done() {
            break;
        }
    }
    Ok(Rollout {
        env_id: env.spec().id.clone(),
        clip: env.motion().clip().name.clone(),
        frames,
        total_reward: total,
    })
}

fn points_json(frames: &[RolloutFrame], pick: impl Fn(&RolloutFrame) -> &Vec<[f64; 3]>) -> String {
    let mut s = String::from("[");
    for (i, f) in frames.iter().enumerate() {
        if i > 0 {
            s.push(',');
        }
        s.push('[');
        for (j, p) in pick(f).iter().enumerate() {
            if j > 0 {
                s.push(',');
            }
            s.push_str(&format!("{:.4},{:.4},{:.4}", p[0], p[1], p[2]));
        }
        s.push(']');
    }
    s.push(']');
    s
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The rollout as a self-contained HTML page.
///
/// ```
/// use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, MotionSource};
/// use a2perf_locomotion::gait::Gait;
/// use a2perf_locomotion::render::{record_rollout, rollout_html, RenderPolicy};
/// let mut env = LocomotionEnv::new(EnvConfig::new("x", MotionSource::Generated(Gait::Trot))).unwrap();
/// let r = record_rollout(&mut env, RenderPolicy::Reference, 3, 0).unwrap();
/// let html = rollout_html(&r);
/// assert!(html.contains("<canvas") && !html.contains("http"));
/// ```
pub fn rollout_html(r: &Rollout) -> String {
    let robot = points_json(&r.frames, |f| &f.robot);
    let reference = points_json(&r.frames, |f| &f.reference);
    let rewards: Vec<String> = r
        .frames
        .iter()
        .map(|f| format!("{:.4}", f.reward))
        .collect();
    let title = format!("{} — clip {}", escape(&r.env_id), escape(&r.clip));
    let mut html = String::new();
    html.push_str("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>");
    html.push_str(&title);
    html.push_str("</title><style>body{font-family:sans-serif;margin:12px;background:#fafafa}canvas{background:#fff;border:1px solid #ccc}</style></head><body>\n<h3>");
    html.push_str(&title);
    html.push_str(&format!(
        "</h3><p>{} control steps (33 ms each), return {:.2}. Left: reference motion. Right: simulated robot.</p>\n",
        r.frames.len().saturating_sub(1),
        r.total_reward
    ));
    html.push_str("<canvas id=\"c\" width=\"960\" height=\"420\"></canvas><br>\n<button id=\"play\">pause</button> <input id=\"slider\" type=\"range\" min=\"0\" value=\"0\" style=\"width:700px\"> <span id=\"info\"></span>\n<script>\n");
    html.push_str(&format!(
        "const ROBOT={robot};\nconst REF={reference};\nconst REWARD=[{}];\n",
        rewards.join(",")
    ));
    html.push_str(
        r#"const N=ROBOT.length, NP=ROBOT[0].length/3;
const cv=document.getElementById('c'), ctx=cv.getContext('2d');
const slider=document.getElementById('slider'), info=document.getElementById('info'), btn=document.getElementById('play');
slider.max=N-1; let frame=0, playing=true;
const az=-0.6, el=0.35, S=420;
function proj(x,y,z,cx,cy,ox){
  const ca=Math.cos(az), sa=Math.sin(az);
  const u=ca*(x-cx)-sa*(y-cy), v=sa*(x-cx)+ca*(y-cy);
  return [ox+u*S, 330-(z*Math.cos(el)-v*Math.sin(el))*S];
}
function drawRobot(P,ox,label,color){
  const cx=(P[0]+P[21])/2, cy=(P[1]+P[22])/2;
  ctx.strokeStyle='#ddd'; ctx.lineWidth=1;
  const g0x=Math.floor(cx*4)/4, g0y=Math.floor(cy*4)/4;
  for(let k=-4;k<=4;k++){
    let a=proj(g0x+k/4,g0y-1,0,cx,cy,ox), b=proj(g0x+k/4,g0y+1,0,cx,cy,ox);
    ctx.beginPath(); ctx.moveTo(a[0],a[1]); ctx.lineTo(b[0],b[1]); ctx.stroke();
    a=proj(g0x-1,g0y+k/4,0,cx,cy,ox); b=proj(g0x+1,g0y+k/4,0,cx,cy,ox);
    ctx.beginPath(); ctx.moveTo(a[0],a[1]); ctx.lineTo(b[0],b[1]); ctx.stroke();
  }
  const p=i=>proj(P[3*i],P[3*i+1],P[3*i+2],cx,cy,ox);
  ctx.strokeStyle=color; ctx.lineWidth=2;
  const edges=[[0,1],[2,3],[4,5],[6,7],[0,2],[1,3],[4,6],[5,7],[0,4],[1,5],[2,6],[3,7]];
  for(const [a,b] of edges){const A=p(a),B=p(b);ctx.beginPath();ctx.moveTo(A[0],A[1]);ctx.lineTo(B[0],B[1]);ctx.stroke();}
  ctx.lineWidth=4;
  for(let l=0;l<4;l++){
    ctx.beginPath(); for(let k=0;k<4;k++){const A=p(8+4*l+k); if(k==0)ctx.moveTo(A[0],A[1]); else ctx.lineTo(A[0],A[1]);} ctx.stroke();
    const T=p(8+4*l+3); ctx.beginPath(); ctx.arc(T[0],T[1],5,0,6.3); ctx.fillStyle=color; ctx.fill();
  }
  ctx.fillStyle='#333'; ctx.font='15px sans-serif'; ctx.fillText(label,ox-60,30);
}
function draw(){
  ctx.clearRect(0,0,cv.width,cv.height);
  drawRobot(REF[frame],240,'reference','#2a7');
  drawRobot(ROBOT[frame],720,'robot','#c43');
  slider.value=frame; info.textContent='step '+frame+'/'+(N-1)+'  reward '+REWARD[frame].toFixed(3);
}
slider.oninput=()=>{frame=+slider.value; draw();};
btn.onclick=()=>{playing=!playing; btn.textContent=playing?'pause':'play';};
setInterval(()=>{if(playing){frame=(frame+1)%N; draw();}},33);
draw();
</script></body></html>
"#,
    );
    html
}

#[cfg(test)]
mod tests {
    use a2perf_core::{Action, Env, EnvError, Frame, Step};

    use super::*;
    use crate::env::{EnvConfig, MotionSource};
    use crate::gait::Gait;

    fn env() -> LocomotionEnv {
        LocomotionEnv::new(EnvConfig::new(
            "QuadrupedLocomotion-DogTrot-v0",
            MotionSource::Generated(Gait::Trot),
        ))
        .unwrap()
    }

    fn data(frame: &Frame) -> &[u8] {
        match frame {
            Frame::Rgb { data, .. } => data,
            Frame::Text(_) => panic!("expected an rgb frame"),
        }
    }

    fn count(frame: &Frame, color: [u8; 3]) -> usize {
        data(frame).chunks(3).filter(|p| *p == color).count()
    }

    /// `steps` steps following the reference; with `render`, the frame of every state.
    fn episode(render: bool, steps: usize) -> (Vec<Step>, Vec<Frame>) {
        let mut env = env();
        env.reset(Some(7)).unwrap();
        let model = RobotModel::builtin();
        let default = model.default_motor_angles();
        let (mut out, mut frames) = (Vec::new(), Vec::new());
        for _ in 0..steps {
            if render {
                frames.push(env.render("rgb_array").unwrap());
            }
            let next = env.reference_state(env.reference_time() + CONTROL_DT);
            let action = (0..NUM_MOTORS)
                .map(|i| (model.urdf_to_motor(i, next.q[i]) - default[i]) as f32)
                .collect();
            let step = env.step(&Action::Continuous(action)).unwrap();
            let done = step.done();
            out.push(step);
            if done {
                break;
            }
        }
        (out, frames)
    }

    #[test]
    fn frames_show_robot_reference_and_ground() {
        let mut env = env();
        env.reset(Some(0)).unwrap();
        let frame = env.render("rgb_array").unwrap();
        let Frame::Rgb {
            height,
            width,
            ref data,
        } = frame
        else {
            panic!("rgb");
        };
        assert_eq!((height, width, data.len()), (240, 320, 240 * 320 * 3));
        // At reset the robot stands exactly on the reference, which it hides.
        assert!(count(&frame, ROBOT_COLOR) > 100);
        assert_eq!(count(&frame, REFERENCE_COLOR), 0);
        // Holding the default pose, the robot soon parts from the reference.
        for _ in 0..10 {
            env.step(&Action::Continuous(vec![0.0; NUM_MOTORS]))
                .unwrap();
        }
        let frame = env.render("rgb_array").unwrap();
        assert!(count(&frame, ROBOT_COLOR) > 100);
        assert!(count(&frame, REFERENCE_COLOR) > 20);
        let Frame::Rgb {
            width, ref data, ..
        } = frame
        else {
            panic!("rgb");
        };
        let row = GROUND_ROW as usize;
        assert!(
            data[row * width * 3..(row + 1) * width * 3]
                .chunks(3)
                .all(|p| p == GROUND_LINE || p == ROBOT_COLOR || p == REFERENCE_COLOR)
        );
        assert!(
            data[(height - 1) * width * 3..]
                .chunks(3)
                .all(|p| p == GROUND)
        );
        let above = |color| {
            data.chunks(3)
                .enumerate()
                .filter(|(_, p)| *p == color)
                .all(|(i, _)| i / width <= row + 3)
        };
        assert!(above(ROBOT_COLOR) && above(REFERENCE_COLOR));
    }

    #[test]
    fn frames_are_deterministic_change_with_the_state_and_leave_the_episode_alone() {
        let (steps, frames) = episode(true, 20);
        let (steps_again, frames_again) = episode(true, 20);
        let (quiet, none) = episode(false, 20);
        assert!(none.is_empty());
        assert_eq!(steps, quiet, "rendering changed the episode");
        assert_eq!(steps, steps_again);
        assert!(frames == frames_again, "same episode, same frames");
        assert!(frames.len() > 5);
        assert!(frames[0] != frames[5], "the robot moved, the frame did not");
        let mut env = env();
        env.reset(Some(1)).unwrap();
        let a = env.render("rgb_array").unwrap();
        assert!(a == env.render("rgb_array").unwrap());
    }

    #[test]
    fn the_camera_follows_the_base_and_bad_points_are_clipped() {
        let mut env = env();
        env.reset(Some(0)).unwrap();
        let s = env.sim().state();
        let robot = state_points(env.sim().model(), &s);
        let here = side_view(&robot, &[], s.base_pos.x);
        // Shifting the world and the camera together leaves the robot where it was.
        let shifted: Vec<[f64; 3]> = robot.iter().map(|p| [p[0] + 0.05, p[1], p[2]]).collect();
        let there = side_view(&shifted, &[], s.base_pos.x + 0.05);
        let robot_pixels = |f: &Frame| -> Vec<usize> {
            data(f)
                .chunks(3)
                .enumerate()
                .filter(|(_, p)| *p == ROBOT_COLOR)
                .map(|(i, _)| i)
                .collect()
        };
        assert_eq!(robot_pixels(&here), robot_pixels(&there));
        // …while the ground marks scroll.
        assert!(here != there);
        let bad = vec![[f64::NAN, 0.0, f64::INFINITY]; POINTS_PER_ROBOT];
        let far = vec![[1e300, -1e300, 1e300]; POINTS_PER_ROBOT];
        for frame in [
            side_view(&bad, &far, f64::NAN),
            side_view(&far, &bad, 1e300),
            side_view(&robot[..5], &[], 0.0),
        ] {
            assert_eq!(data(&frame).len(), FRAME_WIDTH * FRAME_HEIGHT * 3);
            assert_eq!(
                count(&frame, ROBOT_COLOR) + count(&frame, REFERENCE_COLOR),
                0
            );
        }
    }

    #[test]
    fn unknown_modes_name_the_supported_one() {
        let mut env = env();
        assert_eq!(env.render_modes(), &["rgb_array"]);
        let err = env.render("svg").unwrap_err();
        assert!(matches!(err, EnvError::InvalidParameter { .. }));
        assert!(
            err.to_string().contains("supported modes: rgb_array"),
            "{err}"
        );
    }
}
