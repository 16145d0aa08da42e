#!/usr/bin/env python3
"""Generates the FD parity goldens of a2perf-circuit/tests/fd_parity.rs.

Runs MacroPlacement's pure-Python `plc_client_os.PlacementCost.optimize_stdcells` (the open
re-implementation of circuit_training's force-directed std-cell placer) with circuit_training's
end-of-episode schedule and records the positions of the movable nodes after a few cumulative steps
and the proxy cost at the end of the schedule.

Usage:
    python make_golden.py PLC_CLIENT_DIR DATA_DIR OUT_JSON [case ...]

PLC_CLIENT_DIR holds plc_client_os.py (MacroPlacement CodeElements/Plc_client/); DATA_DIR is
shared/data/circuit. Only numbers are written; nothing of plc_client_os is copied.
"""

import contextlib
import gzip
import io
import json
import math
import os
import random
import re
import sys
import tempfile

# circuit_training's fd_placement_schedule defaults (end of episode).
NUM_STEPS = [100, 100, 100]
MOVE_FACTORS = [1.0, 1.0, 1.0]
ATTRACT = [100.0, 1e-3, 1e-5]
REPEL = [0.0, 1e6, 1e7]
IO_FACTOR = 1.0
# Cumulative steps of the schedule after which positions are recorded.
RECORD = [int(v) for v in os.environ.get("FD_RECORD", "1,10,100,101,110,200,300").split(",")]
# CT environment settings (placement_util.create_placement_cost), legacy congestion grid.
ROUTES = (70.33, 74.51)
ALLOC = (51.79, 51.79)
SMOOTH = 5


# ----------------------------------------------------------------------------- netlist text

def tokens(text):
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        for m in re.finditer(r'"(?:[^"\\]|\\.)*"|[{}:]|[^\s{}:"]+', line):
            yield m.group(0)


def parse_nodes(text):
    """Nodes of a GraphDef text: [{name, inputs, attrs: {key: (kind, value)}}]."""
    toks = list(tokens(text))
    i, nodes = 0, []

    def block(i):
        # Returns (dict of field -> list of values, next index); values are str or dict.
        fields = {}
        while toks[i] != "}":
            key = toks[i]
            i += 1
            if toks[i] == ":":
                i += 1
                fields.setdefault(key, []).append(toks[i].strip('"'))
                i += 1
            else:
                assert toks[i] == "{"
                sub, i = block(i + 1)
                fields.setdefault(key, []).append(sub)
        return fields, i + 1

    while i < len(toks):
        assert toks[i] == "node" and toks[i + 1] == "{", toks[i:i + 3]
        fields, i = block(i + 2)
        attrs = {}
        for a in fields.get("attr", []):
            (kind, v), = [(k, vv[0]) for k, vv in a["value"][0].items()]
            attrs[a["key"][0]] = (kind, v)
        nodes.append({"name": fields["name"][0], "inputs": fields.get("input", []), "attrs": attrs})
    return nodes


def write_nodes(nodes):
    """CT's multi-line GraphDef text layout (the one plc_client_os's line parser expects)."""
    out = []
    for n in nodes:
        out.append("node {")
        out.append(f'  name: "{n["name"]}"')
        for s in n["inputs"]:
            out.append(f'  input: "{s}"')
        for key in sorted(n["attrs"]):
            kind, v = n["attrs"][key]
            v = f'"{v}"' if kind == "placeholder" else v
            out += ["  attr {", f'    key: "{key}"', "    value {", f"      {kind}: {v}", "    }", "  }"]
        out.append("}")
    return "\n".join(out) + "\n"


def num(v):
    # Positional notation: the line parser of plc_client_os does not read exponents.
    return repr(float(v)) if "e" not in repr(float(v)) else f"{v:.20f}"


# ----------------------------------------------------------------------------- cases

def toy_rewrite(nodes, macros):
    """The toy with every STDCELL as a soft macro (`macro`) plus one pin `<cell>/P` right after it,
    which plc_client_os understands (it has no STDCELL type). Soft macros keep their netlist order,
    so the pair order of the repulsion is the same. `macros` = {name: (x, y, orientation)}.
    Returns the text and {rewritten index: original index} of the soft macros."""
    cells = {n["name"] for n in nodes if n["attrs"]["type"][1] == "STDCELL"}
    ren = lambda s: s + "/P" if s in cells else s
    pos = {n["name"]: (float(n["attrs"].get("x", ("f", 0))[1]), float(n["attrs"].get("y", ("f", 0))[1]))
           for n in nodes}
    for name, (x, y, _) in macros.items():
        pos[name] = (x, y)
    out, soft = [], {}
    for k, n in enumerate(nodes):
        t = n["attrs"]["type"][1]
        a = dict(n["attrs"])
        ins = [ren(s) for s in n["inputs"]]
        if t == "MACRO":
            x, y, o = macros[n["name"]]
            a.update(x=("f", num(x)), y=("f", num(y)), orientation=("placeholder", o))
            out.append({"name": n["name"], "inputs": ins, "attrs": a})
        elif t == "MACRO_PIN":
            mx, my = pos[a["macro_name"][1]]
            a.update(x=("f", num(mx)), y=("f", num(my)))
            out.append({"name": n["name"], "inputs": ins, "attrs": a})
        elif t == "PORT":
            a.setdefault("side", ("placeholder", "BOTTOM"))
            out.append({"name": n["name"], "inputs": ins, "attrs": a})
        elif t == "STDCELL":
            a["type"] = ("placeholder", "macro")
            soft[len(out)] = k
            out.append({"name": n["name"], "inputs": [], "attrs": a})
            x, y = pos[n["name"]]
            pin = {"type": ("placeholder", "macro_pin"), "macro_name": ("placeholder", n["name"]),
                   "x": ("f", num(x)), "y": ("f", num(y)),
                   "x_offset": ("f", "0"), "y_offset": ("f", "0")}
            if "weight" in a:
                pin["weight"] = a.pop("weight")
            out.append({"name": n["name"] + "/P", "inputs": ins, "attrs": pin})
        else:
            raise ValueError(f"unexpected type {t}")
    return write_nodes(out), soft


def random_toy_macros(nodes, canvas, grid, seed):
    """Two hard macros at random cell centres, inside the canvas and not overlapping, random
    orientation of the N family (as the environment: the centre at a cell centre)."""
    rng = random.Random(seed)
    (cw, ch), (cols, rows) = canvas, grid
    gw, gh = cw / cols, ch / rows
    hard = [n for n in nodes if n["attrs"]["type"][1] == "MACRO"]
    placed = {}
    for n in hard:
        w, h = float(n["attrs"]["width"][1]), float(n["attrs"]["height"][1])
        while True:
            c, r = rng.randrange(cols), rng.randrange(rows)
            x, y = (c + 0.5) * gw, (r + 0.5) * gh
            if x - w / 2 < 0 or x + w / 2 > cw or y - h / 2 < 0 or y + h / 2 > ch:
                continue
            if any(abs(x - px) < (w + pw) / 2 and abs(y - py) < (h + ph) / 2
                   for px, py, pw, ph in placed.values()):
                continue
            placed[n["name"]] = (x, y, w, h)
            break
    orients = ["N", "FN", "S", "FS"]
    return {k: (v[0], v[1], rng.choice(orients)) for k, v in placed.items()}


def read_plc_macros(path, nodes):
    byidx = {k: n for k, n in enumerate(nodes)}
    out = {}
    for line in open(path):
        if line.startswith("#") or not line.strip():
            continue
        i, x, y, o, _ = line.split()
        n = byidx[int(i)]
        if n["attrs"]["type"][1] == "MACRO":
            out[n["name"]] = (float(x), float(y), o)
    return out


# ----------------------------------------------------------------------------- running

class IndexList(list):
    """A list whose membership test is a set lookup: plc_client_os tests `i in <index list>` for
    every pin of every net each step, which is quadratic on Ariane. Order, contents and every
    answer stay the same, so the placer's arithmetic is untouched."""

    def __init__(self, items):
        super().__init__(items)
        self._set = set(items)

    def __contains__(self, x):
        return x in self._set

    def append(self, x):
        super().append(x)
        self._set.add(x)

    def extend(self, xs):
        xs = list(xs)
        super().extend(xs)
        self._set.update(xs)


INDEX_LISTS = ["port_indices", "hard_macro_indices", "hard_macro_pin_indices",
               "soft_macro_indices", "soft_macro_pin_indices"]


def run(plc_mod, netlist_path, plc_path, canvas, grid, square, soft_map, restore):
    plc = plc_mod.PlacementCost(netlist_path)
    for name in INDEX_LISTS:
        setattr(plc, name, IndexList(getattr(plc, name)))
    if square:
        plc.make_soft_macros_square()
    plc.set_canvas_size(*canvas)
    plc.set_placement_grid(*grid)
    plc.set_routes_per_micron(*ROUTES)
    plc.set_macro_routing_allocation(*ALLOC)
    plc.set_congestion_smooth_range(SMOOTH)
    if restore:
        plc.restore_placement(plc_path)
    max_move = [f * max(canvas) / s for f, s in zip(MOVE_FACTORS, NUM_STEPS)]
    soft = sorted(plc.soft_macro_indices)
    snaps, done, bounds = {}, 0, [0]
    for s in NUM_STEPS:
        bounds.append(bounds[-1] + s)
    for target in RECORD:
        # The schedule between `done` and `target`, as round slices with their own factors.
        steps, mm, at, rp = [], [], [], []
        for r in range(len(NUM_STEPS)):
            lo, hi = max(done, bounds[r]), min(target, bounds[r + 1])
            if hi > lo:
                steps.append(hi - lo); mm.append(max_move[r]); at.append(ATTRACT[r]); rp.append(REPEL[r])
        with contextlib.redirect_stdout(io.StringIO()):
            plc.optimize_stdcells(use_current_loc=done > 0, move_stdcells=True, move_macros=False,
                                  log_scale_conns=False, use_sizes=False, io_factor=IO_FACTOR,
                                  num_steps=steps, max_move_distance=mm, attract_factor=at,
                                  repel_factor=rp)
        done = target
        snaps[str(target)] = {str(soft_map.get(i, i)): list(plc.get_node_location(i)) for i in soft}
    plc.FLAG_UPDATE_WIRELENGTH = plc.FLAG_UPDATE_DENSITY = plc.FLAG_UPDATE_CONGESTION = True
    wl, den, cong = plc.get_cost(), plc.get_density_cost(), plc.get_congestion_cost()
    return {
        "positions_after_steps": snaps,
        "end": {"wirelength": plc.get_wirelength(), "wirelength_cost": wl, "density_cost": den,
                "congestion_cost": cong, "proxy_cost": wl + den + 0.5 * cong},
    }


def from_debug_log(log_path, steps):
    """Positions after the given cumulative steps, read from the log plc_client_os appends to
    `os_debug.txt` in the working directory: one line `node x y dx dy` per soft macro per step
    (in its soft-macro order, floats printed round-trip exactly). For a run cut short: the Ariane
    case's positions came from the log of a run that had not reached the end of the schedule."""
    rows = [l.split() for l in open(log_path) if l.strip()]
    per_step = len({r[0] for r in rows})
    snaps = {}
    for k in steps:
        block = rows[(k - 1) * per_step:k * per_step]
        if len(block) == per_step:
            snaps[str(k)] = {r[0]: [float(r[1]), float(r[2])] for r in block}
    return snaps


def main():
    if sys.argv[1] == "--from-debug-log":
        # make_golden.py --from-debug-log OS_DEBUG_TXT OUT_JSON CASE NETLIST PLACEMENT
        log, out_path, case, netlist, placement = sys.argv[2:7]
        r = {"netlist": netlist, "placement": placement,
             "positions_after_steps": from_debug_log(log, RECORD), "end": None}
        json.dump({case: r}, open(out_path, "w"), indent=1)
        return
    client_dir, data, out_path = sys.argv[1:4]
    only = set(sys.argv[4:])
    sys.path.insert(0, client_dir)
    import plc_client_os as plc_mod

    results = {}
    tmp = tempfile.mkdtemp(prefix="fd_parity_")
    os.chdir(tmp)  # plc_client_os writes a debug file into the working directory

    toy_dir = os.path.join(data, "toy_macro_stdcell")
    toy_nodes = parse_nodes(open(os.path.join(toy_dir, "netlist.pb.txt")).read())
    canvas, grid = (200.0, 100.0), (20, 10)
    netlist_macros = {n["name"]: (float(n["attrs"]["x"][1]), float(n["attrs"]["y"][1]), "N")
                      for n in toy_nodes if n["attrs"]["type"][1] == "MACRO"}
    toy_cases = {
        "toy_initial": netlist_macros,
        "toy_perturb_a": read_plc_macros(os.path.join(toy_dir, "perturb_a.plc"), toy_nodes),
        "toy_perturb_b": read_plc_macros(os.path.join(toy_dir, "perturb_b.plc"), toy_nodes),
    }
    for seed in range(3):
        toy_cases[f"toy_random_{seed}"] = random_toy_macros(toy_nodes, canvas, grid, seed)
    index = {n["name"]: k for k, n in enumerate(toy_nodes)}
    for name, macros in toy_cases.items():
        if only and name not in only:
            continue
        text, soft_map = toy_rewrite(toy_nodes, macros)
        nl = os.path.join(tmp, name + ".pb.txt")
        open(nl, "w").write(text)
        r = run(plc_mod, nl, None, canvas, grid, False, soft_map, restore=False)
        r["netlist"] = "toy_macro_stdcell/netlist.pb.txt"
        # No body lines; its header gives the 20x10 grid, as in the environment.
        r["placement"] = "toy_macro_stdcell/initial.plc"
        r["hard_macros"] = {str(index[k]): [v[0], v[1], v[2]] for k, v in sorted(macros.items())}
        results[name] = r
        print(name, r["end"], file=sys.stderr)

    if not only or "ariane133_legalized" in only:
        ad = os.path.join(data, "ariane133_ng45")
        nl = os.path.join(tmp, "ariane133.pb.txt")
        open(nl, "w").write(gzip.open(os.path.join(ad, "netlist.pb.txt.gz"), "rt").read())
        r = run(plc_mod, nl, os.path.join(ad, "legalized.plc"), (1433.406, 1433.406), (24, 21),
                True, {}, restore=True)
        r["netlist"] = "ariane133_ng45/netlist.pb.txt.gz"
        r["placement"] = "ariane133_ng45/legalized.plc"
        results["ariane133_legalized"] = r
        print("ariane133_legalized", r["end"], file=sys.stderr)

    json.dump(results, open(out_path, "w"), indent=1)


if __name__ == "__main__":
    main()
