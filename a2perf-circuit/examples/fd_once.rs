//! Runs the standard-cell placer once on Ariane133/NG45 (when `../shared` is present) and on the
//! generated Ariane-scale circuit, printing the resulting proxy cost at full precision and a hash
//! of the placed positions — a fixed workload for `valgrind --tool=callgrind` and for checking
//! that placer changes keep the result deterministic.
//!
//! `cargo run --release -p a2perf-circuit --example fd_once [ng45|synthetic|both] [steps per round]`

use std::path::Path;

use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
use a2perf_circuit::{
    CostSettings, GeneratorConfig, Netlist, Placement, PlacementCost, SoftMacroRule, generate,
};

fn run(name: &str, netlist: &Netlist, placement: &Placement, settings: CostSettings) {
    let mut cost = PlacementCost::new(netlist, settings).expect("settings valid");
    cost.apply_placement(placement).expect("placement fits");
    let mut schedule = FdSchedule::default();
    // Optional second argument: steps per round (to compare placer variants before chaos sets in).
    if let Some(n) = std::env::args().nth(2).and_then(|a| a.parse().ok()) {
        schedule.num_steps = vec![n; 3];
    }
    place_std_cells(&mut cost, &schedule, &mut FdScratch::default());
    let c = cost.costs();
    // FNV-1a over the bit patterns of all coordinates: any change in the placement shows.
    let mut h = a2perf_core::hash::Fnv1a::new();
    for i in 0..cost.num_nodes() {
        let (x, y) = cost.position(i);
        h.write_u64(x.to_bits());
        h.write_u64(y.to_bits());
    }
    let h = h.finish();
    println!(
        "{name:<18} proxy {:.12e}  wl {:.12e}  density {:.12e}  congestion {:.12e}  hash {h:016x}",
        c.proxy_cost, c.wirelength_cost, c.density_cost, c.congestion_cost
    );
}

fn main() {
    let which = std::env::args().nth(1).unwrap_or_else(|| "both".into());
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit/ariane133_ng45"
    ));
    if which != "synthetic" && dir.join("netlist.pb.txt.gz").exists() {
        let n = Netlist::from_file(dir.join("netlist.pb.txt.gz"), SoftMacroRule::default())
            .expect("ng45 parses");
        let p = Placement::from_file(dir.join("legalized.plc")).expect("plc parses");
        let s = CostSettings::ct_env(&n, Some(&p.header));
        run("ariane133_ng45", &n, &p, s);
    }
    if which != "ng45" {
        let g = generate(&GeneratorConfig::ariane_scale(), 0);
        run("synthetic_ariane", &g.netlist, &g.placement, g.settings);
    }
}
