"""Timings of the Python bindings against the native benchmark (the README's Python rows).

    python python/benchmarks/bench.py [--a2perf PATH] [--shared ../shared/data] [--quick]

Prints one JSON object. The native figures come from `a2perf_rs.bench` (the loop of `a2perf bench`,
run in this process so that native and Python rounds can alternate); the `a2perf` binary (default:
$CARGO_TARGET_DIR/release/a2perf) gives one cross-check;
../shared/data gives the Ariane133 placement cost. The load average is
recorded: on a shared machine the figures are only comparable within one run.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import threading
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

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
    """Env steps/s of a vector env (one run: absolute figures, for the README's table). Random
    uniform actions topple the robot every ~10 steps, so in next-step mode every ~10th step of
    an env is a cheap autoreset step; zero actions (standing) never end an episode early."""
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


def vector_speedup(blocks: int, per: int, zero: bool = False) -> dict:
    """make_vec N = 2 against one environment, measured in interleaved blocks of `per` steps per
    arm (order rotated) so that every arm sees the same machine: on a shared VM a core's speed
    drifts by tens of percent within seconds, which separate runs turn into noise. The arms:

    - `single`: a `gym.make` env, reset by hand (a single env's steps/s: resets take time but
      are not steps);
    - `vec1`, `vec2`: make_vec N = 1, 2, next-step autoreset (the default), counted as Gymnasium
      and every RL library count a vector env: N steps per call, autoreset steps included;
    - `vec2_same_step`: make_vec N = 2 with same-step autoreset, where every step is a
      transition (the reset happens inside the step that ended the episode);
    - `free1`, `free2`: the native loop of `a2perf bench` (`a2perf_rs.bench`, GIL released) on
      one thread, and on two threads at once, timed by the loop itself (building its env is
      not counted): what this machine gives two independent threads of this workload at that
      moment (their summed steps/s: `machine_two_thread_scaling`), and what a lockstep pair of
      them could get (twice the slower thread's steps/s: `machine_two_thread_lockstep_bound`; the
      two vCPUs of a shared host often run at different speeds). The same two loops' timelines
      paired unit by unit (`free2_paired`: unit i of both threads, a step or the reset after an
      episode's end, as next-step autoreset spends them, costs the slower of the two) give what
      any lockstep N = 2 env with one env per thread could reach with those step times:
      `machine_lockstep_bound_paired`, and `make_vec_2_of_paired_bound` is the share of it
      that make_vec N = 2 delivers;
    - `cpu0`, `cpu1`: the native loop alone on one thread pinned to CPU 0, then CPU 1 (when the
      machine has both): `vcpu_speed_ratio` is the slower CPU's steps/s over the faster one's.
      On two real cores it is ~1; where it is not, the single env's figure depends on the CPU it
      happens to run on, and a lockstep pair runs at the slower one's pace.

    Random actions only for the native arms: the native loop has no zero-action mode, so `zero`
    runs leave them out.

    With random actions DogPace episodes last ~10 steps, so in next-step mode about one step in
    ten of each env is an autoreset step (no transition): `transitions_per_s` leaves them out."""
    dog = f"a2perf/{DOG}"
    make = lambda n, **kw: gym.make_vec(dog, num_envs=n, vectorization_mode="vector_entry_point", **kw)  # noqa: E731
    vec = {"vec1": make(1), "vec2": make(2), "vec2_same_step": make(2, autoreset_mode=AutoresetMode.SAME_STEP)}
    single = gym.make(dog)
    rng = np.random.default_rng(0)
    low, high = single.action_space.low, single.action_space.high
    for v in vec.values():
        v.reset(seed=0)
    single.reset(seed=0)
    cpus = [c for c in (0, 1) if c in os.sched_getaffinity(0)] if hasattr(os, "sched_getaffinity") else []
    # The native loop steps with random actions: native arms only for that workload.
    pinned = [f"cpu{c}" for c in cpus] if len(cpus) == 2 and not zero else []
    arms = ["single", *vec, *([] if zero else ["free1", "free2"]), *pinned]
    width = {"single": 1, "vec1": 1, "vec2": 2, "vec2_same_step": 2, "free1": 1, "free2": 2,
             "free2_slower": 2, "free2_paired": 2, "cpu0": 1, "cpu1": 1}
    # Not arms: free2's two threads as lockstep bounds, recorded with it.
    measured = [*arms, *([] if zero else ["free2_slower", "free2_paired"])]
    seconds = dict.fromkeys(measured, 0.0)
    transitions = dict.fromkeys(vec, 0)
    ended = {arm: np.zeros(width[arm], bool) for arm in vec}
    block_rates: dict[str, list[float]] = {arm: [] for arm in measured}
    block_real: dict[str, list[float]] = {arm: [] for arm in vec}
    seeds = itertools.count()

    def native_runs(n: int, cpu: int | None = None) -> list[dict]:
        """The native loop on `n` threads at once (building an env is not timed), each with its
        timeline; `cpu`: each thread pinned to that CPU (its own affinity only)."""
        runs: list[dict] = []

        def one() -> None:
            if cpu is not None:
                os.sched_setaffinity(0, {cpu})
            runs.append(a2perf_rs.bench(DOG, steps=per, seed=next(seeds), timeline=True))

        threads = [threading.Thread(target=one) for _ in range(n)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        return runs

    for b in range(blocks):
        for arm in arms[b % len(arms):] + arms[: b % len(arms)]:
            n = width[arm]
            actions = rng.uniform(low, high, (per, n, 12)).astype(np.float32)
            if zero:
                actions[:] = 0.0
            t = time.perf_counter()
            if arm == "single":
                for a in actions:
                    _, _, term, trunc, _ = single.step(a[0])
                    if term or trunc:
                        single.reset()
                dt = time.perf_counter() - t
            elif arm in vec:
                v, done = vec[arm], ended[arm]
                real = 0
                for a in actions:
                    # Next-step mode: an env whose episode ended last step only resets now.
                    real += n if arm == "vec2_same_step" else int((~done).sum())
                    _, _, term, trunc, _ = v.step(a)
                    done[:] = term | trunc
                dt = time.perf_counter() - t
                transitions[arm] += real
                block_real[arm].append(real / dt)
            else:
                # Native threads: the loops' own timing, summed over the threads that ran at once.
                runs = native_runs(n, int(arm[3:]) if arm in pinned else None)
                rates = [r["steps_per_second"] for r in runs]
                dt = per * n / sum(rates)
                if n == 2:  # what lockstep could get from these two threads: the slower one, twice
                    seconds["free2_slower"] += per / min(rates)
                    block_rates["free2_slower"].append(2 * min(rates))
                    # ... and unit by unit: each pair of units costs the slower one.
                    units = min(len(r["timeline_us"]) for r in runs)
                    paired = np.maximum(*(np.array(r["timeline_us"][:units]) for r in runs))
                    call_s = float(paired.sum()) / 1e6 / units
                    seconds["free2_paired"] += per * call_s
                    block_rates["free2_paired"].append(2 / call_s)
            seconds[arm] += dt
            block_rates[arm].append(per * n / dt)
    for v in vec.values():
        v.close()
    rate = {arm: blocks * per * width[arm] / sec for arm, sec in seconds.items()}
    real = {arm: transitions[arm] / seconds[arm] for arm in vec}

    def ratio(a: str, b: str, transitions_of_a: bool = False) -> dict:
        """`a`'s steps (or transitions) per second over `b`'s: over the whole run, and the
        median of the per-block ratios (robust to the host taking a vCPU away for a few
        blocks, which stalls two threads while one runs on)."""
        top, tops = (real[a], block_real[a]) if transitions_of_a else (rate[a], block_rates[a])
        per_block = np.array(tops) / np.array(block_rates[b])
        return {"whole_run": top / rate[b], "median_block": float(np.median(per_block))}

    return {
        "steps_per_s": rate,
        "transitions_per_s": real,
        "speedup_over_gym_make": ratio("vec2", "single"),
        "transition_speedup_over_gym_make_same_step": ratio("vec2_same_step", "single", True),
        "transition_speedup_over_gym_make_next_step": ratio("vec2", "single", True),
        "speedup_over_make_vec_1": ratio("vec2", "vec1"),
        **({} if zero else {
            "machine_two_thread_scaling": ratio("free2", "free1"),
            "machine_two_thread_lockstep_bound": ratio("free2_slower", "free1"),
            "machine_lockstep_bound_paired": ratio("free2_paired", "free1"),
            "make_vec_2_of_paired_bound": ratio("vec2", "free2_paired"),
        }),
        **({} if not pinned else {
            "vcpu_speed_ratio": {
                "whole_run": min(rate["cpu0"], rate["cpu1"]) / max(rate["cpu0"], rate["cpu1"]),
                "median_block": float(np.median(
                    np.minimum(block_rates["cpu0"], block_rates["cpu1"])
                    / np.maximum(block_rates["cpu0"], block_rates["cpu1"]))),
            },
        }),
        "block_ratio_quartiles_over_gym_make": [
            float(q)
            for q in np.percentile(np.array(block_rates["vec2"]) / np.array(block_rates["single"]), [25, 75])
        ],
    }


def lockstep_ceiling(steps: int, zero: bool = False) -> float:
    """The best speed-up a lockstep N = 2 vector env could reach if two cores ran as fast as one:
    two environments stepped one after the other on this thread, each step timed, sum of both
    times over the slower one's (next-step autoreset: a reset-only step is paired with a full
    step of the other env). The spread of step times it pairs is mostly the host's, not the
    physics': replaying the same actions twice, per-step times correlate by only 0.1–0.2, while
    the mean step time differs by under 20% between contact states."""
    envs = [A2PerfEnv(DOG) for _ in range(2)]
    rng = np.random.default_rng(1)
    low, high = envs[0].action_space.low, envs[0].action_space.high
    pending = [False, False]
    for i, e in enumerate(envs):
        e.reset(seed=i)
    total = slowest = 0.0
    for _ in range(steps):
        t = [0.0, 0.0]
        for i, e in enumerate(envs):
            a = np.zeros(12, np.float32) if zero else rng.uniform(low, high).astype(np.float32)
            start = time.perf_counter()
            if pending[i]:
                e.reset()
                pending[i] = False
            else:
                _, _, term, trunc, _ = e.step(a)
                pending[i] = term or trunc
            t[i] = time.perf_counter() - start
        total += t[0] + t[1]
        slowest += max(t)
    return total / slowest


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
    # Native and Python alternated in short rounds in this process (the native loop through
    # `a2perf_rs.bench`, the loop of `a2perf bench`): on a shared VM one core's speed drifts by
    # tens of percent within seconds, so only interleaved figures compare.
    rounds, steps = (10, 1500) if not args.quick else (2, 500)
    native, python = [], []
    for r in range(rounds):
        native.append(a2perf_rs.bench(DOG, steps=steps, seed=r)["steps_per_second"])
        python.append(python_steps_per_s(DOG, steps))
    res["dogpace_native_rounds"], res["dogpace_python_rounds"] = native, python
    res["dogpace_python_over_native"] = sum(python) / sum(native)
    res["dogpace_a2perf_bench_binary"] = native_bench(args.a2perf, DOG, steps)["steps_per_second"]
    web_native, web_python = [], []
    for r in range(rounds):
        web_native.append(a2perf_rs.bench(WEB, steps=int(20000 * k), seed=r)["step_latency_us"]["p50"])
        web_python.append(web_step_us(int(20000 * k))[1])
    res["web_native_step_median_us_rounds"] = web_native
    res["web_python_step_median_us_rounds"] = web_python
    res["web_overhead_us_per_round"] = list(np.array(web_python) - np.array(web_native))
    res["web_overhead_us"] = float(np.median(res["web_overhead_us_per_round"]))
    vsteps = int(1000 * k)
    native = lambda n: gym.make_vec(f"a2perf/{DOG}", num_envs=n, vectorization_mode="vector_entry_point")  # noqa: E731
    asynch = lambda n: gym.vector.AsyncVectorEnv([lambda: A2PerfEnv(DOG)] * n)  # noqa: E731
    for n in (1, 2, 8):
        res[f"make_vec_{n}_steps_per_s"] = vector_steps_per_s(native, n, vsteps)
        res[f"async_{n}_steps_per_s"] = vector_steps_per_s(asynch, n, vsteps)
        res[f"make_vec_{n}_zero_steps_per_s"] = vector_steps_per_s(native, n, vsteps, zero=True)
        res[f"async_{n}_zero_steps_per_s"] = vector_steps_per_s(asynch, n, vsteps, zero=True)
    for kind, zero in (("", False), ("_zero", True)):
        res[f"make_vec_2{kind}_speedup"] = vector_speedup(int(60 * k) or 6, 100, zero)
        res[f"lockstep_ceiling{kind}"] = lockstep_ceiling(int(3000 * k), zero)
    if Path(args.shared, "circuit", "ariane133_ng45").exists():
        res.update(placement_cost_ms(Path(args.shared), int(200 * k) or 20))
    res["load_average_after"] = os.getloadavg()
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
