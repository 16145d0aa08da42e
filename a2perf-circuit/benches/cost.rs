//! Full cost, standard-cell placer, incremental move and one environment episode on an
//! Ariane-scale netlist.
//!
//! Uses Ariane133/NanGate45 from `../shared/data/circuit` when present, otherwise the generated
//! Ariane-scale circuit (133 hard macros).

use std::hint::black_box;
use std::path::Path;

use a2perf_circuit::{
    CircuitEnv, CircuitEnvConfig, CostSettings, GeneratorConfig, Netlist, Placement, PlacementCost,
    SoftMacroRule, generate,
};
use a2perf_core::{Action, Env, Observation, RngStream, Step};
use criterion::{Criterion, criterion_group, criterion_main};

struct Case {
    name: String,
    netlist: Netlist,
    placement: Placement,
    settings: CostSettings,
}

fn case() -> Case {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit/ariane133_ng45"
    ));
    if dir.join("netlist.pb.txt.gz").exists() {
        let netlist = Netlist::from_file(dir.join("netlist.pb.txt.gz"), SoftMacroRule::default())
            .expect("ng45 netlist parses");
        let placement = Placement::from_file(dir.join("legalized.plc")).expect("plc parses");
        let settings = CostSettings::ct_env(&netlist, Some(&placement.header));
        return Case {
            name: "ariane133_ng45".into(),
            netlist,
            placement,
            settings,
        };
    }
    eprintln!("../shared absent: benchmarking the generated Ariane-scale netlist");
    let g = generate(&GeneratorConfig::ariane_scale(), 0);
    Case {
        name: "synthetic_ariane".into(),
        netlist: g.netlist,
        placement: g.placement,
        settings: g.settings,
    }
}

fn benches(c: &mut Criterion) {
    let case = case();
    let mut cost = PlacementCost::new(&case.netlist, case.settings.clone()).unwrap();
    cost.apply_placement(&case.placement).unwrap();
    let mut g = c.benchmark_group(format!("circuit/{}", case.name));
    g.sample_size(20);
    {
        use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
        let (schedule, mut scratch, mut placed) =
            (FdSchedule::default(), FdScratch::default(), cost.clone());
        g.bench_function("fd_placer", |b| {
            b.iter(|| {
                placed.clone_from(&cost);
                place_std_cells(&mut placed, &schedule, &mut scratch);
                black_box(placed.costs().proxy_cost)
            })
        });
    }
    g.bench_function("full_cost", |b| {
        b.iter(|| {
            cost.recompute();
            black_box(cost.costs())
        })
    });
    let hard: Vec<usize> = cost.hard_macros().iter().map(|&i| i as usize).collect();
    let (cols, rows) = cost.grid();
    let mut rng = RngStream::new(0, "bench/moves");
    g.bench_function("incremental_move_and_cost", |b| {
        b.iter(|| {
            let m = hard[rng.index(hard.len())];
            cost.place_at_cell(m, rng.index(cols * rows));
            black_box(cost.costs())
        })
    });
    g.bench_function("incremental_move_only", |b| {
        b.iter(|| {
            let m = hard[rng.index(hard.len())];
            cost.place_at_cell(m, rng.index(cols * rows));
            black_box(cost.wirelength())
        })
    });
    let mut env = CircuitEnv::new(
        &case.netlist,
        Some(&case.placement),
        case.settings.clone(),
        CircuitEnvConfig::default(),
    )
    .unwrap();
    let mut obs = Observation::default();
    let mut step = Step::default();
    let mut ep = 0u64;
    g.sample_size(10);
    g.bench_function("episode_with_std_cell_placement", |b| {
        b.iter(|| {
            ep += 1;
            let mut rng = RngStream::new(ep, "bench/episode");
            env.reset_into(Some(ep), &mut obs).unwrap();
            let mut mask = obs.action_mask.clone().unwrap_or_default();
            loop {
                let legal = mask.iter().filter(|m| **m).count();
                if legal == 0 {
                    break;
                }
                let k = rng.index(legal);
                let a = mask
                    .iter()
                    .enumerate()
                    .filter(|(_, m)| **m)
                    .nth(k)
                    .map(|(a, _)| a)
                    .unwrap();
                env.step_into(&Action::Discrete(a), &mut step).unwrap();
                if step.done() {
                    break;
                }
                mask.clone_from(step.observation.action_mask.as_ref().unwrap());
            }
            black_box(step.reward)
        })
    });
    g.finish();
}

criterion_group!(circuit, benches);
criterion_main!(circuit);
