//! Both standard-cell placers at the netlist's own macro positions (`initial.plc`), on
//! circuit_training's toy and Ariane133/NanGate45 from `../shared/data/circuit`, and at
//! Ariane133's `legalized.plc` (the reference placement's cells as the start): HPWL, the three
//! cost terms, the proxy cost and the placer's CPU time (median of seven runs, one thread).
//!
//! ```text
//! cargo run --release -p a2perf-circuit --example placers
//! ```

use std::path::Path;

use a2perf_circuit::analytical::{
    AnalyticalParams, AnalyticalScratch, MovableMacros, place_analytical,
};
use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
use a2perf_circuit::{CostSettings, Netlist, Placement, PlacementCost, SoftMacroRule};

/// On-CPU nanoseconds of this thread (Linux), so that a loaded machine does not inflate the
/// figures.
fn cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn main() {
    let root = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit"
    ));
    for (name, file, plc) in [
        ("toy_macro_stdcell", "netlist.pb.txt", "initial.plc"),
        ("ariane133_ng45", "netlist.pb.txt.gz", "initial.plc"),
        ("ariane133_ng45", "netlist.pb.txt.gz", "legalized.plc"),
    ] {
        let dir = root.join(name);
        let (Ok(netlist), Ok(placement)) = (
            Netlist::from_file(dir.join(file), SoftMacroRule::default()),
            Placement::from_file(dir.join(plc)),
        ) else {
            eprintln!("{name}: not found under {}", root.display());
            continue;
        };
        let settings = CostSettings::ct_env(&netlist, Some(&placement.header));
        let Ok(mut cost) = PlacementCost::new(&netlist, settings) else {
            eprintln!("{name}: bad settings");
            continue;
        };
        if let Err(e) = cost.apply_placement(&placement) {
            eprintln!("{name}: {e}");
            continue;
        }
        println!("{name} {plc}:");
        let c = cost.costs();
        println!(
            "{name:18} {:10} HPWL {:12.1} wl {:.6} density {:.6} congestion {:.6} proxy {:.6}",
            "as given",
            c.wirelength,
            c.wirelength_cost,
            c.density_cost,
            c.congestion_cost,
            c.proxy_cost
        );
        let (schedule, params) = (FdSchedule::default(), AnalyticalParams::circuit_training());
        let (mut fd, mut an) = (FdScratch::default(), AnalyticalScratch::default());
        for mode in ["fd", "dreamplace"] {
            let mut times = Vec::new();
            let mut placed = cost.clone();
            let mut note = String::new();
            for _ in 0..7 {
                placed.clone_from(&cost);
                let t = cpu_ns().unwrap_or(0);
                if mode == "fd" {
                    place_std_cells(&mut placed, &schedule, &mut fd);
                } else {
                    match place_analytical(&mut placed, &params, MovableMacros::None, &mut an) {
                        Ok(r) => {
                            note = format!(
                                " ({} iterations, {} evaluations, overflow {:.3})",
                                r.iterations, r.evaluations, r.overflow
                            );
                        }
                        Err(e) => {
                            eprintln!("{name}: {e}");
                            break;
                        }
                    }
                }
                times.push(cpu_ns().unwrap_or(0).saturating_sub(t) as f64 / 1e6);
            }
            times.sort_by(f64::total_cmp);
            let c = placed.costs();
            println!(
                "{name:18} {mode:10} HPWL {:12.1} wl {:.6} density {:.6} congestion {:.6} proxy {:.6} time {:.2} ms{note}",
                c.wirelength,
                c.wirelength_cost,
                c.density_cost,
                c.congestion_cost,
                c.proxy_cost,
                times.get(times.len() / 2).copied().unwrap_or(f64::NAN)
            );
        }
    }
}
