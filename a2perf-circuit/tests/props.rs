//! Invariants: incremental == full recompute, mask ⇔ legality, round trips, no panics.

use a2perf_circuit::{
    Blockage, CostBreakdown, GeneratorConfig, Netlist, NodeKind, Orientation, Placement,
    PlacementCost, SoftMacroRule, generate,
};
use proptest::prelude::*;

fn small_cost(seed: u64) -> (Netlist, PlacementCost) {
    let g = generate(&GeneratorConfig::small(), seed);
    let mut cost = PlacementCost::new(&g.netlist, g.settings.clone()).unwrap();
    cost.apply_placement(&g.placement).unwrap();
    (g.netlist, cost)
}

fn assert_close(a: &CostBreakdown, b: &CostBreakdown) {
    let pairs = [
        (a.wirelength, b.wirelength),
        (a.wirelength_cost, b.wirelength_cost),
        (a.density_cost, b.density_cost),
        (a.congestion_cost, b.congestion_cost),
        (a.h_congestion_cost, b.h_congestion_cost),
        (a.v_congestion_cost, b.v_congestion_cost),
        (a.proxy_cost, b.proxy_cost),
    ];
    for (x, y) in pairs {
        assert!(
            (x - y).abs() <= 1e-9 * x.abs().max(y.abs()) + 1e-12,
            "{a:?} vs {b:?}"
        );
    }
}

const ORIENTS: [Orientation; 4] = [
    Orientation::N,
    Orientation::FN,
    Orientation::S,
    Orientation::FS,
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    #[test]
    fn incremental_equals_full(seed in 0u64..4, moves in prop::collection::vec((0usize..10_000, -20.0f64..220.0, -20.0f64..220.0, 0usize..6), 1..40)) {
        let (netlist, mut cost) = small_cost(seed);
        let movable: Vec<usize> = (0..netlist.nodes.len())
            .filter(|&i| matches!(netlist.nodes[i].kind, NodeKind::HardMacro | NodeKind::SoftMacro | NodeKind::StdCell | NodeKind::Port))
            .collect();
        for (k, x, y, op) in moves {
            let i = movable[k % movable.len()];
            match op {
                0 if netlist.nodes[i].kind == NodeKind::HardMacro => cost.set_orientation(i, ORIENTS[k % 4]),
                1 if netlist.nodes[i].kind == NodeKind::HardMacro => cost.set_placed(i, !cost.is_placed(i)),
                2 if netlist.nodes[i].kind == NodeKind::HardMacro => {
                    let (c, r) = cost.grid();
                    cost.place_at_cell(i, k % (c * r));
                }
                _ => cost.set_position(i, x, y),
            }
            // Query in between, so cached parts are exercised.
            if k % 3 == 0 {
                let _ = cost.costs();
            }
        }
        let inc = cost.costs();
        let mut full = cost.clone();
        full.recompute();
        assert_close(&inc, &full.costs());
    }

    #[test]
    fn mask_matches_legality(
        seed in 0u64..4,
        placed in prop::collection::vec(0usize..256, 0..10),
        blockages in prop::collection::vec(
            (0.0f64..1.0, 0.0f64..1.0, 0.0f64..0.5, 0.0f64..0.5, prop::sample::select(vec![0.0, 0.1, 0.99, 1.0])),
            0..3,
        ),
    ) {
        let (netlist, mut cost) = small_cost(seed);
        let (w, h) = (cost.settings().canvas_width, cost.settings().canvas_height);
        let blockages: Vec<Blockage> = blockages
            .iter()
            .map(|&(x, y, bw, bh, rate)| Blockage { rect: [x * w, y * h, (x + bw) * w, (y + bh) * h, rate] })
            .collect();
        cost.set_blockages(&blockages);
        let hard: Vec<usize> = netlist.indices_of(NodeKind::HardMacro);
        for &h in &hard {
            cost.set_placed(h, false);
        }
        for (k, cell) in placed.iter().enumerate() {
            cost.place_at_cell(hard[k % hard.len()], *cell);
        }
        let (c, r) = cost.grid();
        let mut mask = vec![false; c * r];
        for &h in &hard {
            cost.node_mask(h, &mut mask);
            for (cell, &m) in mask.iter().enumerate() {
                prop_assert_eq!(m, cost.is_legal_cell(h, cell), "macro {} cell {}", h, cell);
            }
        }
    }

    #[test]
    fn generated_netlists_round_trip(seed in 0u64..1000) {
        let g = generate(&GeneratorConfig::small(), seed);
        let text = g.netlist.to_pbtxt();
        let back = Netlist::parse(&text, SoftMacroRule::default()).unwrap();
        prop_assert_eq!(&back.nodes, &g.netlist.nodes);
        prop_assert_eq!(&back.nets, &g.netlist.nets);
        prop_assert_eq!(back.content_hash, g.netlist.content_hash.clone());
        prop_assert_eq!(back.fp_bbox, g.netlist.fp_bbox);
        // Determinism.
        let again = generate(&GeneratorConfig::small(), seed);
        prop_assert_eq!(again.netlist.to_pbtxt(), text);
    }

    #[test]
    fn generator_handles_odd_configs(
        seed in 0u64..100,
        hard in 0usize..14,
        soft in 0usize..40,
        bank_size in 0usize..20,
        bank_logic in 0.0f64..=1.0,
        bus in 0.0f64..=1.0,
    ) {
        // Any bank size (0 = one macro per bank), fraction or macro count (0 = at least one)
        // gives a circuit that parses back identically.
        let cfg = GeneratorConfig {
            num_hard_macros: hard,
            num_soft_macros: soft,
            bank_size,
            bank_logic_fraction: bank_logic,
            bus_fraction: bus,
            ..GeneratorConfig::small()
        };
        let g = generate(&cfg, seed);
        let back = Netlist::parse(&g.netlist.to_pbtxt(), SoftMacroRule::default()).unwrap();
        prop_assert_eq!(&back.nodes, &g.netlist.nodes);
        prop_assert_eq!(&back.nets, &g.netlist.nets);
    }

    #[test]
    fn placements_round_trip(entries in prop::collection::vec((0usize..100_000, -1e6f64..1e6, -1e6f64..1e6, 0usize..9, any::<bool>()), 0..50),
                             comments in prop::collection::vec("[ -~]{0,40}", 0..5)) {
        let orients = ["N", "FN", "S", "FS", "E", "FE", "W", "FW"];
        let p = Placement {
            comments,
            header: Default::default(),
            entries: entries.into_iter().map(|(index, x, y, o, fixed)| a2perf_circuit::PlcEntry {
                index, x, y,
                orientation: orients.get(o).and_then(|s| Orientation::parse(s)),
                fixed,
            }).collect(),
        };
        let p = Placement::parse(&p.to_text()).unwrap();
        let q = Placement::parse(&p.to_text()).unwrap();
        prop_assert_eq!(p, q);
    }

    #[test]
    fn random_netlist_text_never_panics(text in "[ -~\n]{0,400}") {
        let _ = Netlist::parse(&text, SoftMacroRule::default());
        let _ = Placement::parse(&text);
    }

    #[test]
    fn mutated_netlist_never_panics(seed in 0u64..50, cuts in prop::collection::vec((0usize..100_000, 0usize..64, "[ -~\n{}:\"]{0,8}"), 1..6)) {
        let g = generate(&GeneratorConfig::small(), seed);
        let mut text = g.netlist.to_pbtxt().into_bytes();
        for (pos, len, ins) in cuts {
            let pos = pos % (text.len() + 1);
            let end = (pos + len).min(text.len());
            text.splice(pos..end, ins.bytes());
        }
        let text = String::from_utf8_lossy(&text).into_owned();
        if let Ok(n) = Netlist::parse(&text, SoftMacroRule::default()) {
            // A mutated netlist that still parses must also be costable without panics.
            let mut s = g.settings.clone();
            s.make_soft_macros_square = true;
            if let Ok(mut c) = PlacementCost::new(&n, s) {
                let _ = c.costs();
            }
        }
        let mut plc = g.placement.to_text();
        plc.insert_str(plc.len() / 2, "\n7 1.5 nan N 0\n");
        prop_assert!(Placement::parse(&plc).is_err());
    }
}

#[test]
fn errors_carry_line_numbers() {
    let err = Netlist::parse(
        "node {\n  name: \"a\"\n  attr { key: \"type\" value { placeholder: \"BOGUS\" } }\n}\n",
        SoftMacroRule::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains(":3:") && err.contains("BOGUS"), "{err}");
    let err = Netlist::parse("node {\n name: \"p\"\n input: \"nowhere\"\n attr { key: \"type\" value { placeholder: \"PORT\" } }\n}", SoftMacroRule::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains(":3:") && err.contains("nowhere"), "{err}");
    let err = Netlist::parse("node {\n name: \"x\"\n", SoftMacroRule::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("end of file"), "{err}");
    let err = Placement::parse("# c\n0 1 2 N 0\n1 2 3 Q 0\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains(":3:") && err.contains('Q'), "{err}");
}

#[test]
fn bad_node_indices_are_errors() {
    let (_, mut cost) = small_cost(0);
    let p = Placement::parse("999999 1 2 N 0\n").unwrap();
    assert!(cost.apply_placement(&p).is_err());
}

#[test]
fn shared_placements_round_trip_identically() {
    let dir = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit"
    ));
    if !dir.exists() {
        if std::env::var("A2PERF_REQUIRE_SHARED").as_deref() == Ok("1") {
            panic!("A2PERF_REQUIRE_SHARED=1 but {} is missing", dir.display());
        }
        eprintln!("skipping: {} not present", dir.display());
        return;
    }
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let d = entry.unwrap().path();
        if !d.is_dir() {
            continue;
        }
        for f in std::fs::read_dir(&d).unwrap() {
            let f = f.unwrap().path();
            if f.extension().and_then(|e| e.to_str()) == Some("plc") {
                let p = Placement::from_file(&f).unwrap();
                assert_eq!(
                    Placement::parse(&p.to_text()).unwrap(),
                    p,
                    "{}",
                    f.display()
                );
                n += 1;
            }
        }
        let nl = if d.join("netlist.pb.txt").exists() {
            d.join("netlist.pb.txt")
        } else {
            d.join("netlist.pb.txt.gz")
        };
        if nl.exists() {
            let netlist = Netlist::from_file(&nl, SoftMacroRule::default()).unwrap();
            let back = Netlist::parse(&netlist.to_pbtxt(), SoftMacroRule::default()).unwrap();
            assert_eq!(back.nodes, netlist.nodes, "{}", nl.display());
            assert_eq!(back.nets, netlist.nets);
        }
    }
    assert!(n >= 8, "found {n} .plc files");
    // Blockages in the header.
    let b = Placement::from_file(dir.join("simple_grouped_with_coords_with_blockage/initial.plc"))
        .unwrap();
    assert_eq!(b.header.blockages.len(), 2);
    assert_eq!(
        b.header.blockages[1].rect,
        [490.0, 490.0, 500.0, 500.0, 1.0]
    );
}

#[test]
fn fd_placer_is_deterministic_and_stays_inside() {
    use a2perf_circuit::placer::{FdSchedule, FdScratch, place_std_cells};
    let (netlist, cost0) = small_cost(5);
    let mut a = cost0.clone();
    let mut b = cost0.clone();
    let sched = FdSchedule::default();
    place_std_cells(&mut a, &sched, &mut FdScratch::default());
    // A scratch warmed on another circuit must leave no trace in the result.
    let mut warm = FdScratch::default();
    let (_, mut other) = small_cost(6);
    place_std_cells(&mut other, &sched, &mut warm);
    place_std_cells(&mut b, &sched, &mut warm);
    let (w, h) = (a.settings().canvas_width, a.settings().canvas_height);
    let mut moved = 0;
    for i in 0..netlist.nodes.len() {
        assert_eq!(a.position(i), b.position(i), "node {i}");
        if netlist.nodes[i].kind == NodeKind::SoftMacro {
            let (x, y) = a.position(i);
            let (sw, sh) = a.size(i);
            assert!(
                x - sw / 2.0 >= 0.0
                    && x + sw / 2.0 <= w
                    && y - sh / 2.0 >= 0.0
                    && y + sh / 2.0 <= h
            );
            moved += usize::from(a.position(i) != cost0.position(i));
        } else {
            assert_eq!(a.position(i), cost0.position(i), "only soft macros move");
        }
    }
    assert!(moved > 0);
    // Costs after the placer equal a full recompute.
    let mut full = a.clone();
    full.recompute();
    assert_close(&a.costs(), &full.costs());
}
