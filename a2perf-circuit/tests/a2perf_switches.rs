//! The switches that reproduce A2Perf's circuit environment (README, "Differences from the
//! original A2Perf"): with each one set, the deviation behaves as A2Perf's fork
//! (Farama-Foundation/a2perf-circuit-training @ b2ccc18); without it, our default holds.

mod common;

use std::collections::BTreeMap;

use a2perf_circuit::env::{
    A2PERF_INFEASIBLE_REWARD, INFEASIBLE_REWARD, PADDED_GRID, cell_to_padded_action,
    padded_action_to_cell, padding,
};
use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
use a2perf_circuit::{
    CircuitEnv, CircuitEnvConfig, CostSettings, GeneratorConfig, InitialLocations, Netlist,
    NodeKind, Placement, PlacementCost, SoftMacroRule, generate,
};
use a2perf_core::{Action, Env, EnvError, Observation, RngStream, Space, Step, Value};
use common::{
    coarse_small, find_infeasible_episode, infeasible, params, registry, shared_circuit_dir,
};
use proptest::prelude::*;

const SMALL: &str = "CircuitTraining-Synthetic-Small-v0";

/// The values of tensor `name` as `f32` (the int32 ones are small indices and flags).
fn tensor(obs: &Observation, name: &str) -> Vec<f32> {
    obs.tensor(name)
        .unwrap_or_else(|| panic!("tensor {name}"))
        .data
        .to_f32_vec()
}

fn first_legal(obs: &Observation) -> usize {
    obs.action_mask
        .as_ref()
        .and_then(|m| m.iter().position(|l| *l))
        .expect("a legal action")
}

/// Every step of the episode that always takes the first legal action: (observation before the
/// action, the step), the last one ending the episode.
fn first_legal_episode(env: &mut dyn Env) -> Vec<(Observation, Step)> {
    let mut obs = env.reset(Some(0)).unwrap();
    let mut out = Vec::new();
    loop {
        let step = env.step(&Action::Discrete(first_legal(&obs))).unwrap();
        let done = step.done();
        let next = step.observation.clone();
        out.push((obs, step));
        if done {
            return out;
        }
        obs = next;
    }
}

#[test]
fn every_switch_is_a_documented_parameter_of_every_circuit_id() {
    let reg = registry();
    let expected = [
        ("infeasible_reward", Value::Float(INFEASIBLE_REWARD)),
        ("infeasible_auto_reset", Value::Bool(false)),
        ("congestion_grid", Value::Str("legacy".into())),
        ("soft_macros_placed", Value::Bool(false)),
        ("initial_locations", Value::Str("fd".into())),
        ("padded_action", Value::Bool(false)),
    ];
    for id in [
        "CircuitTraining-ToyMacro-v0",
        "CircuitTraining-Ariane-v0",
        "CircuitTraining-Synthetic-Small-v0",
        "CircuitTraining-Synthetic-Medium-v0",
        "CircuitTraining-Synthetic-Ariane-v0",
    ] {
        let entry = reg.env(id).unwrap();
        for (name, default) in &expected {
            let p = entry
                .params
                .iter()
                .find(|p| p.name == *name)
                .unwrap_or_else(|| panic!("{id} has no parameter {name}"));
            assert_eq!(&p.default, default, "{id}.{name}");
            assert!(p.doc.len() > 20, "{id}.{name} is documented");
        }
    }
    // The values in force are recorded with the environment.
    let env = reg
        .make_env(
            SMALL,
            &params(&[
                ("infeasible_auto_reset", Value::Bool(true)),
                ("initial_locations", Value::Str("plc".into())),
                ("congestion_grid", Value::Str("ct".into())),
            ]),
        )
        .unwrap();
    let md = &env.spec().metadata;
    assert_eq!(md["infeasible_auto_reset"], "true");
    assert_eq!(md["initial_locations"], "plc");
    assert_eq!(md["soft_macros_placed"], "false");
    assert_eq!(md["congestion_grid"], "14x14", "200 µm / 13.81 µm cells");
    // A value outside the choices is refused with the parameter's name.
    let err = reg
        .make_env(
            SMALL,
            &params(&[("initial_locations", Value::Str("random".into()))]),
        )
        .err()
        .expect("an unknown choice is an error")
        .to_string();
    assert!(err.contains("initial_locations"), "{err}");
}

// ------------------------------------------------------------------ 1. infeasible episodes

#[test]
fn infeasible_minus_one_with_a2perf_auto_reset_semantics() {
    let reg = registry();
    let a2perf_switches = [
        ("infeasible_reward", Value::Float(A2PERF_INFEASIBLE_REWARD)),
        ("infeasible_auto_reset", Value::Bool(true)),
    ];
    let (seed, actions) = find_infeasible_episode(coarse_small(&reg, &[]).as_mut());
    let (last, before) = actions.split_last().unwrap();

    // A2Perf: `obs, _ = self.reset(); return obs, -1.0, True, True, {wirelength, congestion,
    // density: -1}`; the environment is then at the start of a new episode.
    let mut env = coarse_small(&reg, &a2perf_switches);
    let fresh = coarse_small(&reg, &a2perf_switches).reset(Some(0)).unwrap();
    env.reset(Some(seed)).unwrap();
    for &a in before {
        assert!(!env.step(&Action::Discrete(a)).unwrap().done());
    }
    let step = env.step(&Action::Discrete(*last)).unwrap();
    assert_eq!(step.reward, -1.0);
    assert!(
        step.terminated && step.truncated,
        "A2Perf returns True, True"
    );
    assert!(infeasible(&step.info));
    for k in ["wirelength", "congestion", "density"] {
        assert_eq!(step.info.get(k), Some(-1.0), "{k}");
    }
    assert_eq!(
        step.observation, fresh,
        "the observation is the reset observation"
    );
    // No `reset` needed: the next step is the first of a new episode, exactly as after a reset.
    let a = first_legal(&step.observation);
    let continued = env.step(&Action::Discrete(a)).unwrap();
    let mut reset_env = coarse_small(&reg, &a2perf_switches);
    reset_env.reset(Some(0)).unwrap();
    assert_eq!(continued, reset_env.step(&Action::Discrete(a)).unwrap());
    // An explicit reset right after the infeasible step is harmless (A2Perf's TF-Agents wrapper
    // resets again): the same observation.
    let mut again = coarse_small(&reg, &a2perf_switches);
    common::replay(again.as_mut(), seed, &actions);
    assert_eq!(again.reset(Some(1)).unwrap(), fresh);

    // Default: −4, terminated only, the stranded state is returned and `step` wants a reset.
    let mut env = coarse_small(&reg, &[]);
    env.reset(Some(seed)).unwrap();
    for &a in before {
        env.step(&Action::Discrete(a)).unwrap();
    }
    let step = env.step(&Action::Discrete(*last)).unwrap();
    assert_eq!(step.reward, INFEASIBLE_REWARD);
    assert!(step.terminated && !step.truncated);
    assert!(infeasible(&step.info));
    let stranded = tensor(&step.observation, "current_node")[0];
    assert_ne!(
        stranded,
        tensor(&fresh, "current_node")[0],
        "the macro left without a cell, not the first one"
    );
    assert!(
        !step
            .observation
            .action_mask
            .as_ref()
            .unwrap()
            .iter()
            .any(|m| *m)
    );
    assert!(matches!(
        env.step(&Action::Discrete(a)),
        Err(EnvError::NeedsReset)
    ));
    // The reward switch alone keeps our step semantics.
    let mut minus_one = coarse_small(
        &reg,
        &[("infeasible_reward", Value::Float(A2PERF_INFEASIBLE_REWARD))],
    );
    let (reward, was_infeasible, len) = common::replay(minus_one.as_mut(), seed, &actions);
    assert_eq!((reward, was_infeasible, len), (-1.0, true, actions.len()));
    assert!(matches!(
        minus_one.step(&Action::Discrete(a)),
        Err(EnvError::NeedsReset)
    ));
}

// ------------------------------------------------------------------ 2. congestion grid

/// Replays golden placement `name` of `netlist_dir` through the registered env (hard macros to
/// the golden cells, no standard-cell placement, initial positions from the `.plc`) and returns
/// the final reward and the env's congestion grid.
fn golden_replay(
    id: &str,
    netlist: &str,
    plc: &str,
    golden: &serde_json::Value,
    grid: &str,
) -> (f64, (usize, usize)) {
    let dir = shared_circuit_dir("").expect("checked by the caller");
    let p = params(&[
        (
            "netlist_file",
            Value::Str(dir.join(netlist).display().to_string()),
        ),
        (
            "init_placement",
            Value::Str(dir.join(plc).display().to_string()),
        ),
        ("std_cell_placer", Value::Str("none".into())),
        ("initial_locations", Value::Str("plc".into())),
        ("congestion_grid", Value::Str(grid.into())),
    ]);
    let reg = registry();
    let mut env = reg.make_env(id, &p).unwrap();
    // Cells of the golden hard-macro centres (the placement grid of the golden run).
    let positions = golden["macro_positions"].as_object().unwrap();
    let [cols, rows] = [0, 1].map(|k| golden["grid_used_for_cells"][k].as_u64().unwrap() as usize);
    let [cw, ch] = [0, 1].map(|k| golden["canvas_used"][k].as_f64().unwrap());
    let (gw, gh) = (cw / cols as f64, ch / rows as f64);
    let netlist_text = Netlist::from_file(dir.join(netlist), SoftMacroRule::default()).unwrap();
    let cell_of = |node: usize| {
        let xy = &positions[&node.to_string()];
        let (x, y) = (xy[0].as_f64().unwrap(), xy[1].as_f64().unwrap());
        let (c, r) = ((x / gw) as usize, (y / gh) as usize);
        assert!(
            ((c as f64 + 0.5) * gw - x).abs() < 1e-6 && ((r as f64 + 0.5) * gh - y).abs() < 1e-6
        );
        r * cols + c
    };
    let mut obs = env.reset(Some(0)).unwrap();
    loop {
        // current_node is the position among the macros in node order.
        let k = tensor(&obs, "current_node")[0] as usize;
        let node = netlist_text
            .nodes
            .iter()
            .enumerate()
            .filter(|(_, n)| matches!(n.kind, NodeKind::HardMacro | NodeKind::SoftMacro))
            .nth(k)
            .unwrap()
            .0;
        let step = env.step(&Action::Discrete(cell_of(node))).unwrap();
        if step.done() {
            assert!(!infeasible(&step.info));
            let g = &env.spec().metadata["congestion_grid"];
            let grid = if g == "legacy" {
                (cols, rows)
            } else {
                let (c, r) = g.split_once('x').unwrap();
                (c.parse().unwrap(), r.parse().unwrap())
            };
            return (step.reward, grid);
        }
        obs = step.observation;
    }
}

fn golden_json() -> Option<serde_json::Value> {
    let dir = shared_circuit_dir("")?;
    let text = std::fs::read_to_string(dir.join("golden.json")).ok()?;
    serde_json::from_str(&text).ok()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs())
}

#[test]
fn congestion_grid_switch_gives_the_separate_grid_costs_on_golden_netlists() {
    let Some(golden) = golden_json() else {
        return;
    };
    for (id, name, netlist, plc) in [
        (
            "CircuitTraining-ToyMacro-v0",
            "toy_macro_stdcell",
            "toy_macro_stdcell/netlist.pb.txt",
            "toy_macro_stdcell/initial.plc",
        ),
        (
            "CircuitTraining-Ariane-v0",
            "ariane133_ng45",
            "ariane133_ng45/netlist.pb.txt.gz",
            "ariane133_ng45/legalized.plc",
        ),
    ] {
        let g = &golden["netlists"][name];
        let profile = &g["profiles"]["ct_env"];
        let ct_grid = (
            profile["congestion_grid_cols"].as_u64().unwrap() as usize,
            profile["congestion_grid_rows"].as_u64().unwrap() as usize,
        );
        // perturb_a moves the hard macros to grid cells and keeps their orientation, as the
        // environment does (perturb_b also rotates them).
        let p = &g["placements"]["perturb_a"];
        let values = &p["results"]["ct_env"]["values"];
        // A2Perf's separate congestion grid: the golden value computed independently (the
        // binary's use of that grid is assumed: the same routing model on it).
        let (reward, grid) = golden_replay(id, netlist, plc, p, "ct");
        assert_eq!(grid, ct_grid, "{name}");
        let want = values["proxy_cost_ct_default_weights_congestion_grid_ASSUMED"]
            .as_f64()
            .unwrap();
        assert!(close(-reward, want), "{name} ct: {} vs {want}", -reward);
        // Default: the placement grid, Google's verified computation.
        let (reward, _) = golden_replay(id, netlist, plc, p, "legacy");
        let want = values["proxy_cost_ct_default_weights"].as_f64().unwrap();
        assert!(close(-reward, want), "{name} legacy: {} vs {want}", -reward);
    }
}

// ------------------------------------------------------------------ 3. soft macros' state

#[test]
fn soft_macros_are_reported_as_a2perf_does_unless_switched() {
    let reg = registry();
    let mut a2perf = reg.make_env(SMALL, &BTreeMap::new()).unwrap();
    let mut ours = reg
        .make_env(SMALL, &params(&[("soft_macros_placed", Value::Bool(true))]))
        .unwrap();
    let ep_a = first_legal_episode(a2perf.as_mut());
    let ep_o = first_legal_episode(ours.as_mut());
    assert_eq!(ep_a.len(), ep_o.len());
    let reset = &ep_a[0].0;
    let types = tensor(reset, "node_types").to_vec();
    let soft: Vec<usize> = (0..types.len()).filter(|&k| types[k] == 2.0).collect();
    let hard: Vec<usize> = (0..types.len()).filter(|&k| types[k] == 1.0).collect();
    assert!(!soft.is_empty() && !hard.is_empty());
    let observations = |ep: &[(Observation, Step)]| -> Vec<Observation> {
        ep.iter()
            .map(|(o, _)| o.clone())
            .chain(ep.last().map(|(_, s)| s.observation.clone()))
            .collect()
    };
    let (obs_a, obs_o) = (observations(&ep_a), observations(&ep_o));
    for (t, (oa, oo)) in obs_a.iter().zip(&obs_o).enumerate() {
        // Only these two tensors differ: masks, the features and the rewards are the same.
        assert_eq!(oa.action_mask, oo.action_mask);
        assert_eq!(tensor(oa, "features"), tensor(oo, "features"));
        assert_eq!(tensor(oa, "grid"), tensor(oo, "grid"));
        let (placed_a, placed_o) = (tensor(oa, "is_node_placed"), tensor(oo, "is_node_placed"));
        for &k in &soft {
            assert_eq!(placed_a[k], 0.0, "A2Perf: soft macros are never placed");
            assert_eq!(placed_o[k], 1.0);
            for name in ["locations_x", "locations_y"] {
                assert_eq!(
                    tensor(oa, name)[k],
                    tensor(reset, name)[k],
                    "A2Perf never updates a soft macro's location (step {t})"
                );
            }
        }
        // Hard macros: placed after their step, in both.
        let n_placed = hard.iter().filter(|&&k| placed_a[k] == 1.0).count();
        assert_eq!(n_placed, t, "step {t}");
        for &k in &hard {
            assert_eq!(placed_a[k], placed_o[k]);
        }
    }
    for ((_, sa), (_, so)) in ep_a.iter().zip(&ep_o) {
        assert_eq!(sa.reward, so.reward);
    }
    // At the end our placer has moved the soft macros; only the switch shows it.
    let (end_a, end_o) = (obs_a.last().unwrap(), obs_o.last().unwrap());
    let moved = soft
        .iter()
        .filter(|&&k| tensor(end_o, "locations_x")[k] != tensor(end_a, "locations_x")[k])
        .count();
    assert!(moved > soft.len() / 2, "{moved} of {} moved", soft.len());
}

// ------------------------------------------------------------------ 4. initial locations

#[test]
fn initial_locations_come_from_the_mixed_size_placer_unless_switched() {
    let reg = registry();
    let g = generate(&GeneratorConfig::small(), 0);
    let norm = (g.settings.canvas_width + g.settings.canvas_height) as f32;
    // An independent mixed-size run on the generator's placement.
    let mut fd = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
    fd.apply_placement(&g.placement).unwrap();
    let plc = fd.clone();
    place_std_cells(
        &mut fd,
        &FdSchedule::mixed_size(),
        &mut FdScratch::default(),
    );
    let macros: Vec<usize> = (0..fd.num_nodes())
        .filter(|&i| matches!(fd.kind(i), NodeKind::HardMacro | NodeKind::SoftMacro))
        .collect();

    let mut a2perf = reg.make_env(SMALL, &BTreeMap::new()).unwrap();
    let mut ours = reg
        .make_env(
            SMALL,
            &params(&[("initial_locations", Value::Str("plc".into()))]),
        )
        .unwrap();
    let (oa, oo) = (a2perf.reset(Some(0)).unwrap(), ours.reset(Some(0)).unwrap());
    let mut hard_moved = 0;
    for (k, &i) in macros.iter().enumerate() {
        let (fx, fy) = fd.position(i);
        let (px, py) = plc.position(i);
        assert_eq!(tensor(&oa, "locations_x")[k], (fx / norm as f64) as f32);
        assert_eq!(tensor(&oa, "locations_y")[k], (fy / norm as f64) as f32);
        assert_eq!(tensor(&oo, "locations_x")[k], (px / norm as f64) as f32);
        assert_eq!(tensor(&oo, "locations_y")[k], (py / norm as f64) as f32);
        if fd.kind(i) == NodeKind::HardMacro && (fx, fy) != (px, py) {
            hard_moved += 1;
        }
        // Everything stays on the canvas.
        let (w, h) = fd.size(i);
        assert!(fx - w / 2.0 >= 0.0 && fx + w / 2.0 <= g.settings.canvas_width);
        assert!(fy - h / 2.0 >= 0.0 && fy + h / 2.0 <= g.settings.canvas_height);
    }
    assert_eq!(
        hard_moved, 12,
        "the mixed-size run moves the hard macros too"
    );
    // Only the observation changes: the end-of-episode placer starts from the canvas centre
    // (CT's use_current_loc=False), so the same actions give the same masks and reward.
    let (ea, eo) = (
        first_legal_episode(a2perf.as_mut()),
        first_legal_episode(ours.as_mut()),
    );
    assert_eq!(ea.len(), eo.len());
    for ((oa, sa), (oo, so)) in ea.iter().zip(&eo) {
        assert_eq!(oa.action_mask, oo.action_mask);
        assert_eq!(sa.reward, so.reward);
    }
    // Deterministic.
    let again = reg
        .make_env(SMALL, &BTreeMap::new())
        .unwrap()
        .reset(Some(5));
    assert_eq!(again.unwrap(), oa);
}

#[test]
fn mixed_size_placer_pulls_hard_macros_at_their_pins() {
    // Hard macro A (20×10) has its pin on its right edge, B on its left edge; each pin is tied to
    // a port at x = 30 (A's net driven by the port, B's by the macro pin). Pulled at their pins, A settles with its centre at x ≈ 20 and B at
    // x ≈ 40 (pulled at their centres, both would sit at 30). Each step moves the largest force
    // by the round's maximum move (2 µm at the end), hence the tolerance.
    let text = r#"
node { name: "P1" input: "A/p" attr { key: "type" value { placeholder: "PORT" } }
       attr { key: "x" value { f: 30 } } attr { key: "y" value { f: 20 } } }
node { name: "P2" attr { key: "type" value { placeholder: "PORT" } }
       attr { key: "x" value { f: 30 } } attr { key: "y" value { f: 80 } } }
node { name: "A" attr { key: "type" value { placeholder: "MACRO" } }
       attr { key: "width" value { f: 20 } } attr { key: "height" value { f: 10 } }
       attr { key: "x" value { f: 50 } } attr { key: "y" value { f: 50 } } }
node { name: "A/p" attr { key: "type" value { placeholder: "MACRO_PIN" } }
       attr { key: "macro_name" value { placeholder: "A" } }
       attr { key: "x_offset" value { f: 10 } } attr { key: "y_offset" value { f: 0 } } }
node { name: "B" attr { key: "type" value { placeholder: "MACRO" } }
       attr { key: "width" value { f: 20 } } attr { key: "height" value { f: 10 } }
       attr { key: "x" value { f: 50 } } attr { key: "y" value { f: 50 } } }
node { name: "B/p" input: "P2" attr { key: "type" value { placeholder: "MACRO_PIN" } }
       attr { key: "macro_name" value { placeholder: "B" } }
       attr { key: "x_offset" value { f: -10 } } attr { key: "y_offset" value { f: 0 } } }
"#;
    let netlist = Netlist::parse(text, SoftMacroRule::default()).unwrap();
    let mut settings = CostSettings::google_binary_defaults(&netlist);
    settings.canvas_width = 100.0;
    settings.canvas_height = 100.0;
    let mut cost = PlacementCost::new(&netlist, settings).unwrap();
    place_std_cells(
        &mut cost,
        &FdSchedule::mixed_size(),
        &mut FdScratch::default(),
    );
    let (a, b) = (cost.position(2), cost.position(4));
    let near =
        |(x, y): (f64, f64), (ex, ey): (f64, f64)| (x - ex).abs() < 3.0 && (y - ey).abs() < 3.0;
    assert!(near(a, (20.0, 20.0)), "A at {a:?}");
    assert!(near(b, (40.0, 80.0)), "B at {b:?}");
    // The end-of-episode schedule leaves hard macros where they are.
    place_std_cells(&mut cost, &FdSchedule::default(), &mut FdScratch::default());
    assert_eq!((cost.position(2), cost.position(4)), (a, b));
}

// ------------------------------------------------------------------ 5. padded action space

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// A2Perf's layout: the grid centred with `(128 − rows)/2` rows before it and
    /// `(128 − cols)/2` columns before it; a bijection between cells and the actions inside it.
    #[test]
    fn padded_layout_is_a2perfs_and_a_bijection(cols in 1usize..=128, rows in 1usize..=128) {
        let (up, right) = padding(cols, rows);
        prop_assert_eq!((up, right), ((128 - rows) / 2, (128 - cols) / 2));
        let mut hits = vec![false; cols * rows];
        for a in 0..PADDED_GRID * PADDED_GRID {
            let (r, c) = (a / PADDED_GRID, a % PADDED_GRID);
            let inside = (up..up + rows).contains(&r) && (right..right + cols).contains(&c);
            match padded_action_to_cell(a, cols, rows) {
                Some(cell) => {
                    prop_assert!(inside);
                    prop_assert_eq!(cell, (r - up) * cols + (c - right));
                    prop_assert_eq!(cell_to_padded_action(cell, cols, rows), a);
                    prop_assert!(!hits[cell]);
                    hits[cell] = true;
                }
                None => prop_assert!(!inside),
            }
        }
        prop_assert!(hits.iter().all(|h| *h));
        prop_assert_eq!(padded_action_to_cell(PADDED_GRID * PADDED_GRID, cols, rows), None);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// With the padded action space every padding action is masked and refused, and the padded
    /// episode is the unpadded one (same masks up to the layout, same rewards).
    #[test]
    fn padded_masks_are_sound(cols in 6usize..=40, rows in 6usize..=40, seed in 0u64..1000) {
        let reg = registry();
        let grid = [("grid_cols", Value::Int(cols as i64)), ("grid_rows", Value::Int(rows as i64))];
        let mut padded_p = grid.to_vec();
        padded_p.push(("padded_action", Value::Bool(true)));
        let mut padded = reg.make_env(SMALL, &params(&padded_p)).unwrap();
        let mut plain = reg.make_env(SMALL, &params(&grid)).unwrap();
        prop_assert_eq!(&padded.spec().action_space, &Space::Discrete { n: 128 * 128 });
        let mut rng = RngStream::new(seed, "test/padded");
        let (mut op, mut oq) = (padded.reset(Some(seed)).unwrap(), plain.reset(Some(seed)).unwrap());
        loop {
            let (mp, mq) = (op.action_mask.clone().unwrap(), oq.action_mask.clone().unwrap());
            prop_assert_eq!(mp.len(), 128 * 128);
            for (a, &legal) in mp.iter().enumerate() {
                match padded_action_to_cell(a, cols, rows) {
                    Some(cell) => prop_assert_eq!(legal, mq[cell]),
                    None => prop_assert!(!legal, "padding action {} unmasked", a),
                }
            }
            // A padding action is refused, whatever the state.
            let pad = (0..128 * 128).find(|&a| padded_action_to_cell(a, cols, rows).is_none());
            if let Some(pad) = pad {
                let refused = matches!(padded.step(&Action::Discrete(pad)), Err(EnvError::InvalidAction { .. }));
                prop_assert!(refused);
            }
            let legal: Vec<usize> = (0..mq.len()).filter(|&c| mq[c]).collect();
            prop_assert_eq!(legal.len(), mp.iter().filter(|m| **m).count());
            if legal.is_empty() {
                break;
            }
            let cell = legal[rng.index(legal.len())];
            let sp = padded.step(&Action::Discrete(cell_to_padded_action(cell, cols, rows))).unwrap();
            let sq = plain.step(&Action::Discrete(cell)).unwrap();
            prop_assert_eq!(sp.reward, sq.reward);
            prop_assert_eq!(sp.done(), sq.done());
            prop_assert_eq!(&sp.info, &sq.info);
            if sp.done() {
                break;
            }
            op = sp.observation;
            oq = sq.observation;
        }
    }
}

// ------------------------------------------------------------------ 6. loading defaults

#[test]
fn canvas_grid_and_blockages_are_read_as_circuit_training_does() {
    let body = r#"
node { name: "M" attr { key: "type" value { placeholder: "MACRO" } }
       attr { key: "width" value { f: 10 } } attr { key: "height" value { f: 10 } }
       attr { key: "x" value { f: 50 } } attr { key: "y" value { f: 50 } } }
node { name: "M/p" input: "P" attr { key: "type" value { placeholder: "MACRO_PIN" } }
       attr { key: "macro_name" value { placeholder: "M" } } }
node { name: "P" attr { key: "type" value { placeholder: "PORT" } }
       attr { key: "x" value { f: 0 } } attr { key: "y" value { f: 10 } } }
"#;
    // `FP bbox: {x0 y0} {W H}`: CT's regex takes the second pair as the canvas size.
    let text = format!("# FP bbox: {{10.0 10.0}} {{100.0 80.0}}\n# Columns : 8  Rows : 5\n{body}");
    let netlist = Netlist::parse(&text, SoftMacroRule::default()).unwrap();
    let s = CostSettings::ct_env(&netlist, None);
    assert_eq!(
        (s.canvas_width, s.canvas_height, s.grid_cols, s.grid_rows),
        (100.0, 80.0, 8, 5)
    );
    // The placement's header comes after the netlist's and wins.
    let plc =
        Placement::parse("# Columns : 10  Rows : 10\n# Width : 120.0  Height : 90.0\n").unwrap();
    let s = CostSettings::ct_env(&netlist, Some(&plc.header));
    assert_eq!(
        (s.canvas_width, s.canvas_height, s.grid_cols, s.grid_rows),
        (120.0, 90.0, 10, 10)
    );
    // Blockages: the netlist's, when it has any, win over the placement's (CT reads the first of
    // [netlist, plc] that has blockages).
    let blocked = format!("# Blockage : 0 0 30 80 1.0\n{text}");
    let netlist = Netlist::parse(&blocked, SoftMacroRule::default()).unwrap();
    let plc = Placement::parse(
        "# Columns : 10  Rows : 10\n# Width : 100.0  Height : 100.0\n# Blockage : 70 0 100 100 1.0\n",
    )
    .unwrap();
    let settings = CostSettings::ct_env(&netlist, Some(&plc.header));
    let config = CircuitEnvConfig {
        initial_locations: InitialLocations::Plc,
        ..Default::default()
    };
    let mut env = CircuitEnv::new(&netlist, Some(&plc), settings, config).unwrap();
    assert_eq!(env.cost().blockages().len(), 1);
    assert_eq!(env.cost().blockages()[0].rect, [0.0, 0.0, 30.0, 80.0, 1.0]);
    let obs = env.reset(None).unwrap();
    let mask = obs.action_mask.unwrap();
    // Row 2 (y ∈ [20, 30]): footprints of columns 0–2 overlap x < 30; column 3's touches the
    // blockage (allowed); the placement's blockage (x > 70) is not in force.
    assert!(!mask[2 * 10] && !mask[2 * 10 + 2]);
    assert!(mask[2 * 10 + 3]);
    assert!(mask[2 * 10 + 8]);
}
