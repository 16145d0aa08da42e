//! Rollout recording and a self-contained HTML animation (inline canvas + JavaScript, no external
//! downloads) showing the reference and the simulated robot side by side.

use a2perf_core::{Action, Env, EnvError, Observation, Step};
use nalgebra::{Point3, Vector3};

use crate::env::{CONTROL_DT, LocomotionEnv};
use crate::model::{NUM_LEGS, NUM_MOTORS, RobotModel, v3};
use crate::sim::{RobotState, Simulation};

/// Points drawn per robot: 8 chassis-box corners, then per leg hip, hip-pitch joint, knee, toe.
pub const POINTS_PER_ROBOT: usize = 8 + 4 * NUM_LEGS;

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
