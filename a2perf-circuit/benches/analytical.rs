//! The analytical placer (`std_cell_placer = "dreamplace"`) at the end of an episode: hard
//! macros fixed at the netlist's initial placement, soft macros and standard cells placed, on
//! circuit_training's toy and on Ariane133/NanGate45 from `../shared/data/circuit` (a row whose
//! data is absent is skipped with the reason printed). One thread: the placer has no parallel
//! code.
//!
//! ```text
//! cargo bench -p a2perf-circuit --bench analytical
//! ```

use std::hint::black_box;
use std::path::Path;

use a2perf_circuit::analytical::{
    AnalyticalParams, AnalyticalScratch, MovableMacros, place_analytical,
};
use a2perf_circuit::{CostSettings, Netlist, Placement, PlacementCost, SoftMacroRule};
use criterion::{Criterion, criterion_group, criterion_main};

fn shared(name: &str, netlist: &str) -> Option<PlacementCost> {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit"
    ))
    .join(name);
    if !dir.join(netlist).exists() {
        return None;
    }
    let netlist = Netlist::from_file(dir.join(netlist), SoftMacroRule::default()).ok()?;
    let placement = Placement::from_file(dir.join("initial.plc")).ok()?;
    let settings = CostSettings::ct_env(&netlist, Some(&placement.header));
    let mut cost = PlacementCost::new(&netlist, settings).ok()?;
    cost.apply_placement(&placement).ok()?;
    Some(cost)
}

fn benches(c: &mut Criterion) {
    let mut cases = Vec::new();
    for (name, file) in [
        ("toy_macro_stdcell", "netlist.pb.txt"),
        ("ariane133_ng45", "netlist.pb.txt.gz"),
    ] {
        match shared(name, file) {
            Some(cost) => cases.push((name, cost)),
            None => eprintln!(
                "skipping circuit/{name}: ../shared/data/circuit/{name}/{file} and initial.plc \
                 are absent or unreadable"
            ),
        }
    }
    let params = AnalyticalParams::circuit_training();
    for (name, cost) in cases {
        let mut g = c.benchmark_group(format!("circuit/{name}"));
        g.sample_size(10);
        let mut scratch = AnalyticalScratch::default();
        let mut placed = cost.clone();
        g.bench_function("analytical_placer", |b| {
            b.iter(|| {
                placed.clone_from(&cost);
                place_analytical(&mut placed, &params, MovableMacros::None, &mut scratch).unwrap();
                black_box(placed.costs().proxy_cost)
            })
        });
        g.finish();
    }
}

criterion_group!(analytical, benches);
criterion_main!(analytical);
