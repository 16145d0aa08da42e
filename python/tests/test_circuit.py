"""PlacementCost against ../shared/data/circuit/golden.json (as a2perf-circuit/tests/golden.rs reads
it, 1e-9 relative) and against `a2perf circuit cost` with the same settings."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from a2perf_rs.circuit import PlacementCost
from conftest import a2perf_cli, shared


def close(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b)) + 1e-12


def netlist_path(root: Path, entry: dict) -> Path:
    p = root / entry["netlist"].split(" ")[0]
    return p if p.exists() else p.with_name(p.name + ".gz")


def build(root: Path, entry: dict, placement: dict, profile: dict) -> PlacementCost:
    rule = "type_case" if entry.get("soft_macro_rule") == "type_case" else "name_prefix"
    init = entry.get("initial_placement")
    plc = PlacementCost(netlist_path(root, entry), root / init if init else None, soft_macro_rule=rule)
    plc.set_canvas_size(profile["canvas_width"], profile["canvas_height"])
    plc.set_placement_grid(int(profile["grid_cols"]), int(profile["grid_rows"]))
    plc.set_routes_per_micron(profile["hroutes_per_micron"], profile["vroutes_per_micron"])
    plc.set_macro_routing_allocation(profile["hrouting_alloc"], profile["vrouting_alloc"])
    plc.set_congestion_smooth_range(profile["smooth_range"])
    if profile["make_soft_macros_square"]:
        plc.make_soft_macros_square()
    if placement.get("plc_file"):
        plc.restore_placement(root / placement["plc_file"])
    return plc


def test_golden_costs() -> None:
    root = shared("circuit", "golden.json").parent
    golden = json.loads((root / "golden.json").read_text())
    failures, checked, netlists = [], 0, 0
    for name, entry in golden["netlists"].items():
        profiles = entry.get("profiles")
        if not isinstance(profiles, dict):
            continue
        netlists += 1
        for pname, placement in entry["placements"].items():
            for profile_name, result in placement["results"].items():
                plc = build(root, entry, placement, profiles[profile_name])
                v = result["values"]
                c = plc.costs()
                for key, got in [
                    ("wirelength", plc.get_wirelength()),
                    ("wirelength_cost", plc.get_cost()),
                    ("wirelength_cost", plc.get_wirelength_cost()),
                    ("density_cost", plc.get_density_cost()),
                    ("congestion_cost", plc.get_congestion_cost()),
                    ("proxy_cost_ct_default_weights", c["proxy_cost"]),
                    ("h_congestion_cost_top5pct_of_H_only", c["h_congestion_cost"]),
                    ("v_congestion_cost_top5pct_of_V_only", c["v_congestion_cost"]),
                    ("net_count_weighted", c["net_count"]),
                ]:
                    if isinstance(v.get(key), (int, float)):
                        checked += 1
                        if not close(got, v[key]):
                            failures.append(f"{name}/{pname}/{profile_name} {key}: {got!r} vs {v[key]!r}")
                for idx, pos in (placement.get("macro_positions") or {}).items():
                    x, y = plc.get_node_location(int(idx))
                    checked += 2
                    if not (close(x, pos[0]) and close(y, pos[1])):
                        failures.append(f"{name}/{pname} position {idx}")
                    assert plc.get_macro_orientation(int(idx)) == pos[2]
                arrays = v.get("arrays_row_major_index_row_times_cols_plus_col")
                if arrays:
                    for key, got in [
                        ("density_per_cell", plc.get_grid_cells_density()),
                        ("H_congestion_total", plc.get_horizontal_routing_congestion()),
                        ("V_congestion_total", plc.get_vertical_routing_congestion()),
                    ]:
                        want = np.array(arrays[key])
                        checked += want.size
                        ok = np.abs(got - want) <= 1e-9 * np.maximum(np.abs(got), np.abs(want)) + 1e-12
                        if not ok.all():
                            failures.append(f"{name}/{pname}/{profile_name} {key}")
    assert netlists >= 4
    assert checked > 1000
    assert not failures, "\n".join(failures[:20])


def test_google_binary_reference_on_macro_tiles() -> None:
    root = shared("circuit", "golden.json").parent
    ref = json.loads((root / "golden.json").read_text())["netlists"]["macro_tiles_10x10"]
    plc = PlacementCost(root / "macro_tiles_10x10" / "netlist.pb.txt")
    g = ref["google_binary_reference"]
    # Binary defaults: canvas from the area, 10×10 grid, default routing, no smoothing.
    p = ref["profiles"]["google_binary_defaults"]
    plc.set_canvas_size(p["canvas_width"], p["canvas_height"])
    plc.set_placement_grid(10, 10)
    plc.set_routes_per_micron(p["hroutes_per_micron"], p["vroutes_per_micron"])
    plc.set_macro_routing_allocation(p["hrouting_alloc"], p["vrouting_alloc"])
    plc.set_congestion_smooth_range(0)
    assert close(plc.get_cost(), g["get_cost"])
    assert close(plc.get_wirelength(), g["get_wirelength"])
    assert close(plc.get_density_cost(), g["get_density_cost"])
    assert close(plc.get_congestion_cost(), g["get_congestion_cost"])
    assert close(plc.get_area(), g["get_area"])


def test_equal_to_a2perf_circuit_cost_with_the_same_settings(tmp_path: Path) -> None:
    root = shared("circuit", "ariane133_ng45")
    cli = a2perf_cli()
    netlist, placement = root / "netlist.pb.txt.gz", root / "legalized.plc"
    for flags, setup in [
        ([], lambda p: None),
        (
            ["--canvas", "1400,1450", "--grid", "30,28", "--routes-per-micron", "70.33,74.51",
             "--macro-routing-alloc", "51.79,51.79", "--smooth-range", "2", "--square-soft-macros"],
            lambda p: (
                p.set_canvas_size(1400, 1450), p.set_placement_grid(30, 28),
                p.set_routes_per_micron(70.33, 74.51), p.set_macro_routing_allocation(51.79, 51.79),
                p.set_congestion_smooth_range(2), p.make_soft_macros_square(),
            ),
        ),
    ]:
        out = subprocess.run(
            [cli, "circuit", "cost", "--netlist", str(netlist), "--placement", str(placement),
             "--soft-macro-rule", "type-case", "--json", *flags],
            check=True, capture_output=True, text=True,
        )
        want = json.loads(out.stdout)
        plc = PlacementCost(netlist, placement, soft_macro_rule="type_case")
        setup(plc)
        got = plc.costs()
        for key in got:
            assert got[key] == want[key], (flags, key, got[key], want[key])
        assert plc.settings() == want["settings"]


def test_moves_and_restores() -> None:
    root = shared("circuit", "toy_macro_stdcell")
    plc = PlacementCost(root / "netlist.pb.txt", root / "initial.plc", soft_macro_rule="type_case")
    before = plc.costs()
    m = plc.get_hard_macro_indices()[0]
    x, y = plc.get_node_location(m)
    plc.update_node_coords(m, x + 10.0, y)
    assert plc.get_node_location(m) == (x + 10.0, y)
    assert plc.get_wirelength() != before["wirelength"]
    plc.update_node_coords(m, x, y)
    assert plc.costs() == before
    plc.restore_placement(root / "perturb_a.plc")
    assert plc.get_node_location(m) != (x, y) or plc.costs() != before
    out = Path(os.environ.get("TMPDIR", "/tmp")) / f"a2perf_rs_test_{os.getpid()}.plc"
    plc.save_placement(out)
    again = PlacementCost(root / "netlist.pb.txt", out, soft_macro_rule="type_case")
    assert again.get_node_location(m) == plc.get_node_location(m)
    out.unlink()
