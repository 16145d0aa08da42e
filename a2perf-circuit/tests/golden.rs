//! Reproduces every value of `../shared/data/circuit/golden.json` (to 1e-9 relative).

use std::path::{Path, PathBuf};

use a2perf_circuit::{
    CostSettings, CostWeights, Netlist, NodeKind, Placement, PlacementCost, SoftMacroRule,
};
use serde_json::Value;

fn data_dir() -> Option<PathBuf> {
    let d = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit"
    ));
    if d.join("golden.json").exists() {
        Some(d.to_path_buf())
    } else if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
        panic!("A2PERF_REQUIRE_SHARED=1 but {} is missing", d.display());
    } else {
        eprintln!("skipping: {} not present", d.display());
        None
    }
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()) + 1e-12
}

struct Checker {
    failures: Vec<String>,
    checked: usize,
}

impl Checker {
    fn check(&mut self, what: &str, got: f64, want: &Value) {
        let Some(w) = want.as_f64() else { return };
        self.checked += 1;
        if !close(got, w) {
            self.failures
                .push(format!("{what}: got {got:.17}, want {w:.17}"));
        }
    }
}

fn settings_from(profile: &Value) -> CostSettings {
    let f = |k: &str| profile[k].as_f64().unwrap();
    CostSettings {
        canvas_width: f("canvas_width"),
        canvas_height: f("canvas_height"),
        grid_cols: f("grid_cols") as usize,
        grid_rows: f("grid_rows") as usize,
        smooth_range: f("smooth_range"),
        make_soft_macros_square: profile["make_soft_macros_square"].as_bool().unwrap(),
        hroutes_per_micron: f("hroutes_per_micron"),
        vroutes_per_micron: f("vroutes_per_micron"),
        hrouting_alloc: f("hrouting_alloc"),
        vrouting_alloc: f("vrouting_alloc"),
        congestion_grid: None,
        weights: CostWeights::default(),
    }
}

fn build(
    dir: &Path,
    entry: &Value,
    placement: &Value,
    settings: CostSettings,
    round_f32: bool,
) -> (Netlist, PlacementCost) {
    let rule = match entry["soft_macro_rule"].as_str() {
        Some("type_case") => SoftMacroRule::TypeCase,
        _ => SoftMacroRule::NamePrefix,
    };
    let mut nl_path = dir.join(
        entry["netlist"]
            .as_str()
            .unwrap()
            .split(' ')
            .next()
            .unwrap(),
    );
    if !nl_path.exists() {
        nl_path.set_extension("txt.gz");
    }
    let netlist = Netlist::from_file_with(&nl_path, rule, round_f32).unwrap();
    let mut cost = PlacementCost::new(&netlist, settings).unwrap();
    if let Some(init) = entry["initial_placement"].as_str() {
        cost.apply_placement(&Placement::from_file(dir.join(init)).unwrap())
            .unwrap();
    }
    if let Some(p) = placement["plc_file"].as_str() {
        cost.apply_placement(&Placement::from_file(dir.join(p)).unwrap())
            .unwrap();
    }
    (netlist, cost)
}

fn sum(v: &[f64]) -> f64 {
    v.iter().sum()
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
}

#[test]
fn golden_values() {
    let Some(dir) = data_dir() else { return };
    let golden: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("golden.json")).unwrap()).unwrap();
    let mut ck = Checker {
        failures: Vec::new(),
        checked: 0,
    };
    let mut netlists_done = 0;
    for (name, entry) in golden["netlists"].as_object().unwrap() {
        let Some(profiles) = entry["profiles"].as_object() else {
            eprintln!("{name}: no netlist available, nothing to check");
            continue;
        };
        netlists_done += 1;
        for (pname, placement) in entry["placements"].as_object().unwrap() {
            // Macro positions listed in the golden file are what we loaded.
            for (profile_name, result) in placement["results"].as_object().unwrap() {
                let profile = &profiles[profile_name];
                let (netlist, mut cost) =
                    build(&dir, entry, placement, settings_from(profile), true);
                let tag = format!("{name}/{pname}/{profile_name}");
                if let Some(mp) = placement["macro_positions"].as_object() {
                    for (idx, pos) in mp {
                        let i: usize = idx.parse().unwrap();
                        let (x, y) = cost.position(i);
                        ck.check(&format!("{tag} x[{i}]"), x, &pos[0]);
                        ck.check(&format!("{tag} y[{i}]"), y, &pos[1]);
                        assert_eq!(
                            cost.orientation(i).as_str(),
                            pos[2].as_str().unwrap(),
                            "{tag} orientation {i}"
                        );
                    }
                }
                let v = &result["values"];
                let c = cost.costs();
                ck.check(&format!("{tag} wirelength"), c.wirelength, &v["wirelength"]);
                ck.check(
                    &format!("{tag} net_count"),
                    c.net_count,
                    &v["net_count_weighted"],
                );
                ck.check(
                    &format!("{tag} wirelength_cost"),
                    c.wirelength_cost,
                    &v["wirelength_cost"],
                );
                ck.check(
                    &format!("{tag} density_cost"),
                    c.density_cost,
                    &v["density_cost"],
                );
                ck.check(
                    &format!("{tag} congestion_cost"),
                    c.congestion_cost,
                    &v["congestion_cost"],
                );
                ck.check(
                    &format!("{tag} h_only"),
                    c.h_congestion_cost,
                    &v["h_congestion_cost_top5pct_of_H_only"],
                );
                ck.check(
                    &format!("{tag} v_only"),
                    c.v_congestion_cost,
                    &v["v_congestion_cost_top5pct_of_V_only"],
                );
                ck.check(
                    &format!("{tag} proxy"),
                    c.proxy_cost,
                    &v["proxy_cost_ct_default_weights"],
                );
                let google = c.wirelength_cost + 0.5 * c.density_cost + 0.5 * c.congestion_cost;
                ck.check(
                    &format!("{tag} proxy_google"),
                    google,
                    &v["proxy_cost_google_internal_weights"],
                );
                ck.check(&format!("{tag} area"), netlist.total_area(), &v["area"]);
                let mut dens = Vec::new();
                cost.density_cells(&mut dens);
                ck.check(
                    &format!("{tag} density_max"),
                    max(&dens),
                    &v["density_max_cell"],
                );
                ck.check(
                    &format!("{tag} density_max_no_half"),
                    max(&dens),
                    &v["density_max_cell_no_half_factor"],
                );
                ck.check(
                    &format!("{tag} density_sum"),
                    sum(&dens),
                    &v["density_sum_cells"],
                );
                if let Some(alt) = v["density_cost_ALT_top1_rule_for_grids_below_10_cells"].as_f64()
                {
                    ck.check(
                        &format!("{tag} density_alt"),
                        0.5 * max(&dens),
                        &Value::from(alt),
                    );
                }
                let (h, vv) = cost.congestion_maps();
                let (h, vv) = (h.to_vec(), vv.to_vec());
                ck.check(&format!("{tag} h_max"), max(&h), &v["h_congestion_max"]);
                ck.check(&format!("{tag} v_max"), max(&vv), &v["v_congestion_max"]);
                ck.check(&format!("{tag} h_sum"), sum(&h), &v["h_congestion_sum"]);
                ck.check(&format!("{tag} v_sum"), sum(&vv), &v["v_congestion_sum"]);
                let (hm, vm) = cost.macro_congestion_maps();
                let (hm, vm) = (hm.to_vec(), vm.to_vec());
                ck.check(
                    &format!("{tag} h_macro_sum"),
                    sum(&hm),
                    &v["h_macro_routing_sum"],
                );
                ck.check(
                    &format!("{tag} v_macro_sum"),
                    sum(&vm),
                    &v["v_macro_routing_sum"],
                );
                ck.check(
                    &format!("{tag} h_net_sum"),
                    sum(&h) - sum(&hm),
                    &v["h_net_routing_smoothed_sum"],
                );
                ck.check(
                    &format!("{tag} v_net_sum"),
                    sum(&vv) - sum(&vm),
                    &v["v_net_routing_smoothed_sum"],
                );
                if let Some(arrays) =
                    v["arrays_row_major_index_row_times_cols_plus_col"].as_object()
                {
                    for (key, mine) in [
                        ("density_per_cell", &dens),
                        ("H_congestion_total", &h),
                        ("V_congestion_total", &vv),
                        ("H_macro_congestion", &hm),
                        ("V_macro_congestion", &vm),
                    ] {
                        let want = arrays[key].as_array().unwrap();
                        assert_eq!(want.len(), mine.len(), "{tag} {key} length");
                        for (i, w) in want.iter().enumerate() {
                            ck.check(&format!("{tag} {key}[{i}]"), mine[i], w);
                        }
                    }
                }
                // The assumed separate congestion grid.
                if let (Some(cc), Some(cr)) = (
                    profile["congestion_grid_cols"].as_u64(),
                    profile["congestion_grid_rows"].as_u64(),
                ) && v
                    .get("congestion_cost_on_congestion_grid_ASSUMED")
                    .is_some()
                {
                    let mut s = settings_from(profile);
                    s.congestion_grid = Some((cc as usize, cr as usize));
                    assert_eq!(
                        s.ct_congestion_grid(),
                        (cc as usize, cr as usize),
                        "{tag} CT congestion grid size"
                    );
                    let (_, mut c2) = build(&dir, entry, placement, s, true);
                    let cc2 = c2.costs();
                    ck.check(
                        &format!("{tag} cong_grid"),
                        cc2.congestion_cost,
                        &v["congestion_cost_on_congestion_grid_ASSUMED"],
                    );
                    ck.check(
                        &format!("{tag} proxy_cong_grid"),
                        cc2.proxy_cost,
                        &v["proxy_cost_ct_default_weights_congestion_grid_ASSUMED"],
                    );
                }
                // Pure f64 attributes.
                if let Some(f) = result["values_f64_attrs"].as_object() {
                    let (_, mut c64) = build(&dir, entry, placement, settings_from(profile), false);
                    let c = c64.costs();
                    for (key, got) in [
                        ("wirelength", c.wirelength),
                        ("wirelength_cost", c.wirelength_cost),
                        ("density_cost", c.density_cost),
                        ("congestion_cost", c.congestion_cost),
                        ("proxy_cost_ct_default_weights", c.proxy_cost),
                    ] {
                        ck.check(&format!("{tag} f64 {key}"), got, &f[key]);
                    }
                }
            }
        }
        // Perturbation logs: legal-cell counts under the mask rule, chosen cells, padded actions.
        for (pname, placement) in entry["placements"].as_object().unwrap() {
            let Some(log) = placement["log"].as_array() else {
                continue;
            };
            let profile = profiles.values().next().unwrap();
            let (_, mut cost) = build(&dir, entry, &Value::Null, settings_from(profile), true);
            let grid = placement["grid_used_for_cells"].as_array().unwrap();
            let (cols, rows) = (
                grid[0].as_u64().unwrap() as usize,
                grid[1].as_u64().unwrap() as usize,
            );
            assert_eq!(cost.grid(), (cols, rows));
            let hard: Vec<usize> = cost.hard_macros().iter().map(|&i| i as usize).collect();
            for &h in &hard {
                cost.set_placed(h, false);
            }
            let mut mask = vec![false; cols * rows];
            for e in log {
                let node = e["node_index"].as_u64().unwrap() as usize;
                let cell = e["cell"].as_u64().unwrap() as usize;
                cost.node_mask(node, &mut mask);
                let legal = mask.iter().filter(|m| **m).count();
                assert_eq!(
                    legal as u64,
                    e["num_legal_cells_in_mask"].as_u64().unwrap(),
                    "{name}/{pname} node {node}"
                );
                assert!(
                    mask[cell],
                    "{name}/{pname}: chosen cell {cell} must be legal"
                );
                let action =
                    (cell / cols + (128 - rows) / 2) * 128 + (cell % cols + (128 - cols) / 2);
                assert_eq!(action as u64, e["padded_action_128"].as_u64().unwrap());
                cost.place_at_cell(node, cell);
                let (x, y) = cost.position(node);
                ck.check(&format!("{name}/{pname} log x {node}"), x, &e["x"]);
                ck.check(&format!("{name}/{pname} log y {node}"), y, &e["y"]);
            }
        }
        // Mask examples.
        if let Some(me) = entry.get("mask_examples_plc_client_os_rule") {
            let profile = profiles.values().next().unwrap();
            let (_, mut cost) = build(&dir, entry, &Value::Null, settings_from(profile), true);
            let hard: Vec<usize> = cost.hard_macros().iter().map(|&i| i as usize).collect();
            for &h in &hard {
                cost.set_placed(h, false);
            }
            let (cols, rows) = cost.grid();
            let mut mask = vec![false; cols * rows];
            for stepk in ["step0", "step1"] {
                let st = &me[stepk];
                for pl in st["placed"].as_array().unwrap() {
                    let node = pl[0].as_u64().unwrap() as usize;
                    cost.place_at_cell(node, pl[1].as_u64().unwrap() as usize);
                }
                let node = st["node_index"].as_u64().unwrap() as usize;
                cost.node_mask(node, &mut mask);
                let got: Vec<u64> = mask
                    .iter()
                    .enumerate()
                    .filter(|(_, m)| **m)
                    .map(|(c, _)| c as u64)
                    .collect();
                let want: Vec<u64> = st["legal_cells"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_u64().unwrap())
                    .collect();
                assert_eq!(got, want, "{name} mask {stepk}");
            }
        }
        // Stats.
        let stats = &entry["stats"];
        let rule = match entry["soft_macro_rule"].as_str() {
            Some("type_case") => SoftMacroRule::TypeCase,
            _ => SoftMacroRule::NamePrefix,
        };
        let mut nl_path = dir.join(
            entry["netlist"]
                .as_str()
                .unwrap()
                .split(' ')
                .next()
                .unwrap(),
        );
        if !nl_path.exists() {
            nl_path.set_extension("txt.gz");
        }
        let netlist = Netlist::from_file(&nl_path, rule).unwrap();
        let n = |k: &str| stats[k].as_u64().unwrap() as usize;
        assert_eq!(netlist.nodes.len(), n("num_nodes"), "{name} nodes");
        assert_eq!(
            netlist.count(NodeKind::HardMacro),
            n("num_hard_macros"),
            "{name}"
        );
        assert_eq!(
            netlist.count(NodeKind::SoftMacro),
            n("num_soft_macros"),
            "{name}"
        );
        assert_eq!(netlist.count(NodeKind::Port), n("num_ports"), "{name}");
        assert_eq!(
            netlist.count(NodeKind::StdCell),
            n("num_stdcells"),
            "{name}"
        );
        assert_eq!(
            netlist.count(NodeKind::HardMacroPin),
            n("num_hard_macro_pins"),
            "{name}"
        );
        assert_eq!(
            netlist.count(NodeKind::SoftMacroPin),
            n("num_soft_macro_pins"),
            "{name}"
        );
        assert_eq!(netlist.nets.len(), n("num_nets"), "{name}");
        let endpoints: usize = netlist.nets.iter().map(|x| 1 + x.sinks.len()).sum();
        assert_eq!(endpoints, n("num_pin_endpoints_total"), "{name}");
        ck.check(
            &format!("{name} weighted nets"),
            netlist.weighted_net_count(),
            &stats["weighted_net_count"],
        );
        ck.check(
            &format!("{name} area"),
            netlist.total_area(),
            &stats["total_area_f32_attrs"],
        );
        if let Some(p) = profiles.get("google_binary_defaults") {
            let d = CostSettings::google_binary_defaults(&netlist);
            ck.check(
                &format!("{name} default canvas"),
                d.canvas_width,
                &p["canvas_width"],
            );
            assert_eq!((d.grid_cols, d.grid_rows), (10, 10));
            let mut want = settings_from(p);
            want.weights = d.weights;
            want.canvas_width = d.canvas_width;
            want.canvas_height = d.canvas_height;
            assert_eq!(d, want, "binary defaults = golden profile");
        }
        if let Some(order) = stats["env_placement_order_a2perf_fork"].as_array() {
            let got = a2perf_circuit_order(&netlist);
            let want: Vec<usize> = order.iter().map(|v| v.as_u64().unwrap() as usize).collect();
            assert_eq!(got, want, "{name} A2Perf placement order");
        }
    }
    assert!(netlists_done >= 4, "expected the four netlists with files");
    eprintln!("checked {} golden values", ck.checked);
    assert!(
        ck.failures.is_empty(),
        "{} of {} golden values differ:\n{}",
        ck.failures.len(),
        ck.checked,
        ck.failures
            .iter()
            .map(|f| f.split(" ").take(1).collect::<String>())
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

fn a2perf_circuit_order(netlist: &Netlist) -> Vec<usize> {
    a2perf_circuit::env::placement_order(netlist, &vec![false; netlist.nodes.len()])
}
