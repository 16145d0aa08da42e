//! Rolls out the open-loop reference-tracking policy on each built-in task and prints returns.
//! `cargo run --release -p a2perf-locomotion --example rollout [OUT_DIR]` also writes HTML files.

use a2perf_locomotion::env::{EnvConfig, LocomotionEnv, MotionSource};
use a2perf_locomotion::gait::Gait;
use a2perf_locomotion::render::{RenderPolicy, record_rollout, rollout_html};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1);
    for gait in Gait::ALL {
        for policy in [RenderPolicy::Zero, RenderPolicy::Reference] {
            let mut env =
                LocomotionEnv::new(EnvConfig::new(gait.name(), MotionSource::Generated(gait)))?;
            let mut lens = Vec::new();
            let mut rets = Vec::new();
            for seed in 0..5 {
                let r = record_rollout(&mut env, policy, 600, seed)?;
                lens.push(r.frames.len() - 1);
                rets.push(r.total_reward);
                if let (Some(dir), 0) = (&out, seed) {
                    std::fs::write(
                        format!("{dir}/{}_{policy:?}.html", gait.name()),
                        rollout_html(&r),
                    )?;
                }
            }
            println!(
                "{:<10} {policy:?}: lengths {lens:?} returns {:?}",
                gait.name(),
                rets.iter()
                    .map(|r| (r * 10.0).round() / 10.0)
                    .collect::<Vec<_>>()
            );
        }
    }
    Ok(())
}
