//! Placement blockages: which cells they mask for hard macros, and that they leave costs alone.

use a2perf_circuit::{Blockage, CostSettings, Netlist, Placement, PlacementCost, SoftMacroRule};

/// One 10×10 hard macro with a pin on a port, on a 100×100 canvas with a 10×10 grid.
fn one_macro() -> PlacementCost {
    let text = r#"
node { name: "M0" attr { key: "type" value { placeholder: "MACRO" } }
  attr { key: "width" value { f: 10 } } attr { key: "height" value { f: 10 } }
  attr { key: "x" value { f: 55 } } attr { key: "y" value { f: 55 } } }
node { name: "M0/P" input: "P0" attr { key: "type" value { placeholder: "MACRO_PIN" } }
  attr { key: "macro_name" value { placeholder: "M0" } } }
node { name: "P0" attr { key: "type" value { placeholder: "PORT" } }
  attr { key: "x" value { f: 0 } } attr { key: "y" value { f: 30 } } }
"#;
    let netlist = Netlist::parse(text, SoftMacroRule::default()).unwrap();
    let mut s = CostSettings::google_binary_defaults(&netlist);
    (s.canvas_width, s.canvas_height) = (100.0, 100.0);
    (s.grid_cols, s.grid_rows) = (10, 10);
    PlacementCost::new(&netlist, s).unwrap()
}

fn legal_cells(cost: &PlacementCost) -> Vec<usize> {
    let mut mask = vec![false; 100];
    cost.node_mask(0, &mut mask);
    for (cell, &m) in mask.iter().enumerate() {
        assert_eq!(m, cost.is_legal_cell(0, cell), "cell {cell}");
    }
    (0..100).filter(|&c| mask[c]).collect()
}

#[test]
fn blockages_mask_exactly_the_overlapping_cells() {
    let mut cost = one_macro();
    assert_eq!(legal_cells(&cost).len(), 100);
    cost.set_blockages(&[
        // Overlaps footprints [10c, 10c+10] for c, r ∈ {0, 1, 2}.
        Blockage {
            rect: [0.0, 0.0, 25.0, 25.0, 1.0],
        },
        // Macro-spacing blockage (rate 0.1): columns/rows 8, 9; the footprints of column 7
        // ([70, 80]) only touch it.
        Blockage {
            rect: [80.0, 80.0, 100.0, 100.0, 0.1],
        },
        // Rate 0 blocks nothing.
        Blockage {
            rect: [40.0, 40.0, 60.0, 60.0, 0.0],
        },
    ]);
    let mut expected: Vec<usize> = (0..100)
        .filter(|&cell| {
            let (r, c) = (cell / 10, cell % 10);
            let in_first = r <= 2 && c <= 2;
            let in_second = r >= 8 && c >= 8;
            !(in_first || in_second)
        })
        .collect();
    expected.sort_unstable();
    assert_eq!(legal_cells(&cost), expected);
    assert_eq!(expected.len(), 100 - 9 - 4);
}

#[test]
fn blockages_come_from_the_plc_header_and_leave_costs_unchanged() {
    let mut cost = one_macro();
    let before = cost.costs();
    let plc = Placement::parse(
        "# Columns : 10  Rows : 10\n# Width : 100.0  Height : 100.0\n\
         # Blockage : 0 0 10 100 0.99\n0 55 55 N 0\n",
    )
    .unwrap();
    cost.apply_placement(&plc).unwrap();
    assert_eq!(cost.blockages().len(), 1);
    assert_eq!(cost.costs(), before);
    // Only column 0's footprints ([0, 10]) overlap the strip x ∈ [0, 10].
    let legal = legal_cells(&cost);
    assert_eq!(legal.len(), 90);
    assert!(legal.iter().all(|cell| cell % 10 != 0));
    // A placement without blockage lines keeps the ones in force.
    let plain = Placement::parse("0 45 45 N 0\n").unwrap();
    cost.apply_placement(&plain).unwrap();
    assert_eq!(cost.blockages().len(), 1);
}

#[test]
fn shared_blockage_netlist_reads_its_blockages() {
    let dir = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/data/circuit/simple_grouped_with_coords_with_blockage"
    ));
    if !dir.join("netlist.pb.txt").exists() {
        assert!(
            std::env::var("A2PERF_REQUIRE_SHARED").as_deref() != Ok("1"),
            "shared data missing: {}",
            dir.display()
        );
        eprintln!("skipping: {} absent", dir.display());
        return;
    }
    let netlist = Netlist::from_file(dir.join("netlist.pb.txt"), SoftMacroRule::default()).unwrap();
    let plc = Placement::from_file(dir.join("initial.plc")).unwrap();
    let settings = CostSettings::ct_env(&netlist, Some(&plc.header));
    let mut cost = PlacementCost::new(&netlist, settings).unwrap();
    let mut no_blockage = cost.clone();
    cost.apply_placement(&plc).unwrap();
    let rects: Vec<[f64; 5]> = cost.blockages().iter().map(|b| b.rect).collect();
    assert_eq!(
        rects,
        vec![
            [0.0, 0.0, 10.0, 10.0, 1.0],
            [490.0, 490.0, 500.0, 500.0, 1.0]
        ]
    );
    // Costs are those of the same placement without blockages.
    let mut plain = plc.clone();
    plain.header.blockages.clear();
    no_blockage.apply_placement(&plain).unwrap();
    assert_eq!(cost.costs(), no_blockage.costs());
    // The mask agrees with the direct rule for every hard macro.
    let (c, r) = cost.grid();
    let mut mask = vec![false; c * r];
    for &m in cost.hard_macros() {
        cost.node_mask(m as usize, &mut mask);
        for (cell, &legal) in mask.iter().enumerate() {
            assert_eq!(legal, cost.is_legal_cell(m as usize, cell));
        }
    }
}
