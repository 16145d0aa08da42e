"""Timings of the Python bindings against the native benchmark (the README's Python rows).

    python python/benchmarks/bench.py [--a2perf PATH] [--shared ../shared/data] [--quick]

Prints one JSON object. Needs the `a2perf` binary (default: $CARGO_TARGET_DIR/release/a2perf) for
the native comparisons and ../shared/data for the Ariane133 placement cost. The load average is
recorded: on a shared machine the figures are only comparable within one run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import a2perf_rs
from a2perf_rs import A2PerfEnv
from a2perf_rs.circuit import PlacementCost

DOG = "QuadrupedLocomotion-DogPace-v0"
WEB = "WebNavigation-Difficulty-01-v0"


def native_bench(binary: str, env_id: str, steps: int) -> dict:
    out = subprocess.run(
        [binary, "bench", env_id, "--steps", str(steps), "--json"],
        check=True, capture_output=True, text=True,
    )
    return json.loads(out.stdout)


def python_steps_per_s(env_id: str, steps: int) -> float:
    """Wall-clock env steps/s from Python with random actions, resets included (as `a2perf bench`)."""
    env = A2PerfEnv(env_id)
    rng = np.random.default_rng(0)
    actions = rng.uniform(env.action_space.low, env.action_space.high, (steps, 12)).astype(np.float32)
    env.reset(seed=0)
    t = time.perf_counter()
    for a in actions:
        _, _, term, trunc, _ = env.step(a)
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t)


def web_step_us(steps: int) -> tuple[float, float]:
    """Mean and median µs of `env.step` (the call alone) on the simulated web backend, legal
    random actions (the median discounts preemption on a loaded machine)."""
    env = A2PerfEnv(WEB)
    rng = np.random.default_rng(0)
    _, info = env.reset(seed=0)
    times = np.empty(steps)
    for k in range(steps):
        a = int(rng.choice(np.flatnonzero(info["action_mask"])))
        t = time.perf_counter_ns()
        _, _, term, trunc, info = env.step(a)
        times[k] = time.perf_counter_ns() - t
        if term or trunc:
            _, info = env.reset()
    return float(times.mean() / 1e3), float(np.median(times) / 1e3)


def vector_steps_per_s(make, n: int, steps: int, zero: bool = False) -> float:
    """Env steps/s of a vector env. Random uniform actions topple the robot every ~10 steps, so
    step times vary a lot (contacts) and lockstep stepping waits for the slowest env; zero actions
    (standing, the fixed-pose baseline) give near-uniform step times."""
    venv = make(n)
    rng = np.random.default_rng(0)
    low, high = venv.single_action_space.low, venv.single_action_space.high
    actions = rng.uniform(low, high, (steps, n, 12)).astype(np.float32)
    if zero:
        actions[:] = 0.0
    venv.reset(seed=0)
    t = time.perf_counter()
    for a in actions:
        venv.step(a)
    rate = steps * n / (time.perf_counter() - t)
    venv.close()
    return rate


def placement_cost_ms(shared: Path, calls: int) -> dict:
    root = shared / "circuit" / "ariane133_ng45"
    plc = PlacementCost(root / "netlist.pb.txt.gz", root / "legalized.plc", soft_macro_rule="type_case")
    m = plc.get_hard_macro_indices()[0]
    x, y = plc.get_node_location(m)
    out = {}
    # get_cost() after a macro move: the placement changed, so the cost is recomputed in full.
    t = time.perf_counter()
    for i in range(calls):
        plc.update_node_coords(m, x + (i % 2), y)
        plc.get_cost()
    out["get_cost_after_move_ms"] = (time.perf_counter() - t) / calls * 1e3
    t = time.perf_counter()
    for i in range(calls):
        plc.update_node_coords(m, x + (i % 2), y)
        plc.costs()
    out["all_terms_after_move_ms"] = (time.perf_counter() - t) / calls * 1e3
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    target = Path(os.environ.get("CARGO_TARGET_DIR", Path(__file__).resolve().parents[2] / "target"))
    ap.add_argument("--a2perf", default=str(target / "release" / "a2perf"))
    ap.add_argument("--shared", default=str(Path(__file__).resolve().parents[3] / "shared" / "data"))
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    k = 1 if not args.quick else 0.2
    res: dict = {"load_average_before": os.getloadavg(), "version": a2perf_rs.__version__}
    steps = int(5000 * k)
    res["dogpace_native"] = native_bench(args.a2perf, DOG, steps)["steps_per_second"]
    res["dogpace_python"] = python_steps_per_s(DOG, steps)
    res["dogpace_native_again"] = native_bench(args.a2perf, DOG, steps)["steps_per_second"]
    for run in ("", "_again"):
        nat = native_bench(args.a2perf, WEB, int(20000 * k))
        res[f"web_native_step_us{run}"] = (nat["mean_step_us"], nat["step_latency_us"]["p50"])
        res[f"web_python_step_us{run}"] = web_step_us(int(20000 * k))
    vsteps = int(1000 * k)
    native = lambda n: gym.make_vec(f"a2perf/{DOG}", num_envs=n, vectorization_mode="vector_entry_point")  # noqa: E731
    asynch = lambda n: gym.vector.AsyncVectorEnv([lambda: A2PerfEnv(DOG)] * n)  # noqa: E731
    for n in (1, 2, 8):
        res[f"make_vec_{n}_steps_per_s"] = vector_steps_per_s(native, n, vsteps)
        res[f"async_{n}_steps_per_s"] = vector_steps_per_s(asynch, n, vsteps)
        res[f"make_vec_{n}_zero_steps_per_s"] = vector_steps_per_s(native, n, vsteps, zero=True)
        res[f"async_{n}_zero_steps_per_s"] = vector_steps_per_s(asynch, n, vsteps, zero=True)
    for kind in ("", "_zero"):
        one = res[f"make_vec_1{kind}_steps_per_s"]
        res[f"make_vec_2{kind}_speedup"] = res[f"make_vec_2{kind}_steps_per_s"] / one
    if Path(args.shared, "circuit", "ariane133_ng45").exists():
        res.update(placement_cost_ms(Path(args.shared), int(200 * k) or 20))
    res["load_average_after"] = os.getloadavg()
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
