//! Measures CPU time (not wall time) per operation, for machines shared with other jobs.
//!
//! `cargo run --release -p a2perf-circuit --example cpu_time` — reads `/proc/self/schedstat`
//! (Linux), so the figures exclude time the process spent waiting for a core. Uses Ariane133/NG45
//! from `../shared/data/circuit` when present, else the generated Ariane-scale circuit.

use std::path::Path;
use std::time::Instant;

use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
use a2perf_circuit::{
    CircuitEnv, CircuitEnvConfig, CostSettings, GeneratorConfig, Netlist, Placement, PlacementCost,
    SoftMacroRule, StdCellPlacer, generate,
};
use a2perf_core::{Action, Env, Observation, RngStream, Step};

fn cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/self/schedstat")
        .ok()?
        .split_whitespace()
        .next()?
        .parse()
        .ok()
}

fn measure(label: &str, n: u64, mut f: impl FnMut()) {
    let (c0, t0) = (cpu_ns(), Instant::now());
    for _ in 0..n {
        f();
    }
    let wall = t0.elapsed().as_secs_f64() / n as f64;
    match (c0, cpu_ns()) {
        (Some(a), Some(b)) => println!(
            "{label:<44} cpu {:>10.1} µs   wall {:>10.1} µs   ({n} runs)",
            (b - a) as f64 / 1e3 / n as f64,
            wall * 1e6
        ),
        _ => println!(
            "{label:<44} wall {:>10.1} µs (no /proc/self/schedstat)",
            wall * 1e6
        ),
    }
}

fn main() {
    let dir = Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit/ariane133_ng45"
    ));
    let (name, netlist, placement, settings) = if dir.join("netlist.pb.txt.gz").exists() {
        let n = Netlist::from_file(dir.join("netlist.pb.txt.gz"), SoftMacroRule::default())
            .expect("ng45 parses");
        let p = Placement::from_file(dir.join("legalized.plc")).expect("plc parses");
        let s = CostSettings::ct_env(&n, Some(&p.header));
        ("ariane133_ng45", n, p, s)
    } else {
        let g = generate(&GeneratorConfig::ariane_scale(), 0);
        ("synthetic_ariane", g.netlist, g.placement, g.settings)
    };
    println!("netlist {name}");
    let mut cost = PlacementCost::new(&netlist, settings.clone()).expect("settings valid");
    cost.apply_placement(&placement).expect("placement fits");
    measure("full cost (recompute + costs)", 200, || {
        cost.recompute();
        std::hint::black_box(cost.costs());
    });
    let hard: Vec<usize> = cost.hard_macros().iter().map(|&i| i as usize).collect();
    let (c, r) = cost.grid();
    let mut rng = RngStream::new(0, "moves");
    measure("incremental move + all costs", 5000, || {
        let m = hard[rng.index(hard.len())];
        cost.place_at_cell(m, rng.index(c * r));
        std::hint::black_box(cost.costs());
    });
    measure("incremental move only", 5000, || {
        let m = hard[rng.index(hard.len())];
        cost.place_at_cell(m, rng.index(c * r));
    });
    // The standard-cell placer alone, on this placement's hard macros.
    let mut scratch = FdScratch::default();
    let schedule = FdSchedule::default();
    let mut placed = cost.clone();
    measure("FD standard-cell placer alone", 10, || {
        placed.clone_from(&cost);
        place_std_cells(&mut placed, &schedule, &mut scratch);
    });
    let ct_settings = CostSettings {
        congestion_grid: Some(settings.ct_congestion_grid()),
        ..settings.clone()
    };
    for (label, fd, settings) in [
        ("episode, 133 macros + FD placer", true, &settings),
        ("episode, 133 macros, no FD", false, &settings),
        (
            "episode + FD placer, A2Perf congestion grid",
            true,
            &ct_settings,
        ),
    ] {
        let config = CircuitEnvConfig {
            std_cell_placer: if fd {
                StdCellPlacer::Fd
            } else {
                StdCellPlacer::None
            },
            ..Default::default()
        };
        let mut env = CircuitEnv::new(&netlist, Some(&placement), settings.clone(), config)
            .expect("env builds");
        let mut obs = Observation::default();
        let mut step = Step::default();
        let mut ep = 0;
        measure(label, 10, || {
            ep += 1;
            let mut rng = RngStream::new(ep, "episode");
            env.reset_into(Some(ep), &mut obs).expect("reset");
            let mut mask = obs.action_mask.clone().unwrap_or_default();
            loop {
                let legal: Vec<usize> = (0..mask.len()).filter(|&a| mask[a]).collect();
                if legal.is_empty() {
                    break;
                }
                env.step_into(&Action::Discrete(legal[rng.index(legal.len())]), &mut step)
                    .expect("legal step");
                if step.done() {
                    break;
                }
                mask.clone_from(step.observation.action_mask.as_ref().expect("mask"));
            }
        });
    }
    measure("env construction (mixed-size FD run)", 5, || {
        let env = CircuitEnv::new(
            &netlist,
            Some(&placement),
            settings.clone(),
            CircuitEnvConfig::default(),
        );
        std::hint::black_box(env.is_ok());
    });
}
