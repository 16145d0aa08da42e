//! How good can an episode of the paper's circuit tasks get with *our* standard-cell placer?
//!
//! The paper's circuit returns (toy macro: −0.97 ± 0.008) were scored with Google's closed placer;
//! ours is a re-implementation, so the best return any agent can reach here may differ. This
//! measures that ceiling under the A2Perf-compatible profile's switches (`configs/paper/
//! profile.ron`: infeasible reward −1 with auto-reset, CT's congestion grid, the padded 128×128
//! action space, the analytical `dreamplace` standard-cell placer):
//!
//! - `toy`: every legal placement of the toy netlist's macros, enumerated exhaustively (the toy
//!   has 2 hard macros on a 20×10 grid): best, median and worst episode return.
//! - `ariane`: the return of one good placement of Ariane133 (NG45): each macro, in the
//!   environment's order, put on the legal cell nearest to its position in MacroPlacement's
//!   `legalized.plc` (a placement made by a commercial flow), then our placer. Not a proof of a
//!   ceiling, a reference point.
//! - `random`: 200 episodes of uniformly random legal actions on each netlist (seeded): mean,
//!   best and worst return, and how many episodes stranded a macro (the infeasible reward), which
//!   tells whether an exploring agent meets the infeasible outcome at all.
//!
//! `cargo run --release -p a2perf-circuit --example reward_floor -- [toy|ariane|both|random] [DATA_DIR] [--placer dreamplace|fd]`
//! (`DATA_DIR` defaults to `../shared/data`, as `A2PERF_PAPER_DATA` does; `--placer fd` swaps
//! the profile's standard-cell placer for the force-directed one, the environment's default.)

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use a2perf_circuit::env::{cell_to_padded_action, padded_action_to_cell, placement_order};
use a2perf_circuit::{CostSettings, Netlist, Placement, PlacementCost, SoftMacroRule, register};
use a2perf_core::{Action, Env, Observation, Registry, Value};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// The profile's circuit switches, plus the netlist.
fn profile_params(netlist: &Path, placer: &str) -> BTreeMap<String, Value> {
    BTreeMap::from([
        (
            "netlist_file".to_string(),
            Value::Str(netlist.display().to_string()),
        ),
        ("infeasible_reward".into(), Value::Float(-1.0)),
        ("infeasible_auto_reset".into(), Value::Bool(true)),
        ("congestion_grid".into(), Value::Str("ct".into())),
        ("padded_action".into(), Value::Bool(true)),
        ("initial_locations".into(), Value::Str("fd".into())),
        ("soft_macros_placed".into(), Value::Bool(false)),
        ("std_cell_placer".into(), Value::Str(placer.into())),
    ])
}

fn legal_actions(obs: &Observation) -> Vec<usize> {
    obs.action_mask
        .as_ref()
        .map(|m| (0..m.len()).filter(|&a| m[a]).collect())
        .unwrap_or_default()
}

/// Replays `prefix` from a reset; returns the observation after it, or the episode's return if
/// the prefix ended the episode.
fn replay(env: &mut dyn Env, prefix: &[usize]) -> Result<std::result::Result<Observation, f64>> {
    let mut obs = env.reset(Some(0))?;
    for &a in prefix {
        let step = env.step(&Action::Discrete(a))?;
        if step.done() {
            return Ok(Err(step.reward));
        }
        obs = step.observation;
    }
    Ok(Ok(obs))
}

/// Every complete episode's return, depth first over the legal actions.
fn enumerate(
    env: &mut dyn Env,
    prefix: &mut Vec<usize>,
    out: &mut Vec<(f64, Vec<usize>)>,
) -> Result<()> {
    let obs = match replay(env, prefix)? {
        Ok(obs) => obs,
        Err(ret) => {
            out.push((ret, prefix.clone()));
            return Ok(());
        }
    };
    let legal = legal_actions(&obs);
    if legal.is_empty() {
        return Err("no legal action before the episode ended".into());
    }
    for a in legal {
        prefix.push(a);
        enumerate(env, prefix, out)?;
        prefix.pop();
    }
    Ok(())
}

fn toy(reg: &Registry, data: &Path, placer: &str) -> Result<()> {
    let netlist = data.join("circuit/toy_macro_stdcell/netlist.pb.txt");
    let mut env = reg.make_env(
        "CircuitTraining-ToyMacro-v0",
        &profile_params(&netlist, placer),
    )?;
    let start = std::time::Instant::now();
    let mut episodes = Vec::new();
    enumerate(env.as_mut(), &mut Vec::new(), &mut episodes)?;
    episodes.sort_by(|a, b| b.0.total_cmp(&a.0));
    let infeasible = episodes.iter().filter(|(r, _)| *r == -1.0).count();
    let (best, best_actions) = &episodes[0];
    println!(
        "toy_macro_stdcell: {} complete placements ({infeasible} infeasible) in {:.1} s",
        episodes.len(),
        start.elapsed().as_secs_f64()
    );
    println!(
        "  best return {best:.6} (actions {best_actions:?}), median {:.6}, worst {:.6}",
        episodes[episodes.len() / 2].0,
        episodes[episodes.len() - 1].0
    );
    Ok(())
}

fn ariane(reg: &Registry, data: &Path, placer: &str) -> Result<()> {
    let dir = data.join("circuit/ariane133_ng45");
    let netlist_path = dir.join("netlist.pb.txt.gz");
    let netlist = Netlist::from_file(&netlist_path, SoftMacroRule::default())?;
    let init = Placement::from_file(dir.join("initial.plc"))?;
    let legalized = Placement::from_file(dir.join("legalized.plc"))?;
    let settings = CostSettings::ct_env(&netlist, Some(&init.header));
    let mut target = PlacementCost::new(&netlist, settings)?;
    target.apply_placement(&legalized)?;
    let fixed: Vec<bool> = (0..target.num_nodes())
        .map(|i| target.is_fixed(i))
        .collect();
    let order = placement_order(&netlist, &fixed);
    let (cols, rows) = target.grid();

    let mut env = reg.make_env(
        "CircuitTraining-Ariane-v0",
        &profile_params(&netlist_path, placer),
    )?;
    let mut obs = env.reset(Some(0))?;
    let (mut moved, mut ret) = (0, None);
    for &node in &order {
        let (x, y) = target.position(node);
        let want = target.cell_of(x, y);
        let legal = legal_actions(&obs);
        let want_action = cell_to_padded_action(want, cols, rows);
        let action = if legal.contains(&want_action) {
            want_action
        } else {
            moved += 1;
            // The legal cell whose centre is nearest the wanted one.
            let (wx, wy) = target.cell_center(want);
            *legal
                .iter()
                .min_by(|&&a, &&b| {
                    let d = |a: usize| {
                        let cell = padded_action_to_cell(a, cols, rows)
                            .expect("a legal action is on the grid");
                        let (cx, cy) = target.cell_center(cell);
                        (cx - wx).powi(2) + (cy - wy).powi(2)
                    };
                    d(a).total_cmp(&d(b))
                })
                .ok_or("no legal cell left")?
        };
        let step = env.step(&Action::Discrete(action))?;
        if step.done() {
            ret = Some(step.reward);
            break;
        }
        obs = step.observation;
    }
    let ret = ret.ok_or("the episode did not end after every macro was placed")?;
    println!(
        "ariane133_ng45: legalized.plc's macro cells ({} macros, {moved} moved to the nearest \
         legal cell), our placer: return {ret:.6}",
        order.len()
    );
    Ok(())
}

/// `episodes` episodes of uniformly random legal actions: (returns, stranded episodes).
fn random_episodes(env: &mut dyn Env, episodes: u64) -> Result<(Vec<f64>, usize)> {
    // splitmix64: enough for picking among legal cells, and no dependency for an example.
    let mut state: u64 = 7;
    let mut next_u64 = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let (mut returns, mut stranded) = (Vec::new(), 0);
    for ep in 0..episodes {
        let mut obs = env.reset(Some(ep))?;
        loop {
            let legal = legal_actions(&obs);
            if legal.is_empty() {
                return Err("no legal action before the episode ended".into());
            }
            let a = legal[(next_u64() % legal.len() as u64) as usize];
            let step = env.step(&Action::Discrete(a))?;
            if step.done() {
                if step.reward == -1.0 {
                    stranded += 1;
                }
                returns.push(step.reward);
                break;
            }
            obs = step.observation;
        }
    }
    Ok((returns, stranded))
}

fn random(reg: &Registry, data: &Path, placer: &str) -> Result<()> {
    for (id, file) in [
        (
            "CircuitTraining-ToyMacro-v0",
            "circuit/toy_macro_stdcell/netlist.pb.txt",
        ),
        (
            "CircuitTraining-Ariane-v0",
            "circuit/ariane133_ng45/netlist.pb.txt.gz",
        ),
    ] {
        let mut env = reg.make_env(id, &profile_params(&data.join(file), placer))?;
        let (r, stranded) = random_episodes(env.as_mut(), 200)?;
        let mean = r.iter().sum::<f64>() / r.len() as f64;
        let best = r.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let worst = r.iter().copied().fold(f64::INFINITY, f64::min);
        println!(
            "{id}: {} random legal episodes: mean {mean:.4}, best {best:.4}, worst {worst:.4}, \
             {stranded} stranded a macro (return -1.0)",
            r.len()
        );
    }
    Ok(())
}

fn main() -> Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let placer = match args.iter().position(|a| a == "--placer") {
        Some(i) if i + 1 < args.len() => {
            let p = args.remove(i + 1);
            args.remove(i);
            p
        }
        Some(_) => return Err("--placer needs a value (dreamplace or fd)".into()),
        None => "dreamplace".into(),
    };
    let which = args.first().cloned().unwrap_or_else(|| "both".into());
    let data = args
        .get(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"));
    println!("standard-cell placer: {placer}");
    let mut reg = Registry::new();
    register(&mut reg);
    if matches!(which.as_str(), "toy" | "both") {
        toy(&reg, &data, &placer)?;
    }
    if matches!(which.as_str(), "ariane" | "both") {
        ariane(&reg, &data, &placer)?;
    }
    if which == "random" {
        random(&reg, &data, &placer)?;
    }
    if !matches!(which.as_str(), "toy" | "ariane" | "both" | "random") {
        return Err(format!("unknown task `{which}` (toy, ariane, both or random)").into());
    }
    Ok(())
}
