"""The Python harness's overhead per timed policy call (the README's performance row).

    python python/benchmarks/harness_overhead.py [--episodes 30] [--repeats 3]

``a2perf_rs.infer`` times every call of the Python policy with the pipeline's timer (the one
that times built-in policies). What that timer sees around a callable that does nothing is the
harness's own cost per call: taking the GIL, calling into Python, reading back and checking the
action. (The observation is converted to numpy arrays before the timer starts, as the original
harness's Gymnasium environment handed it over already converted.) Measured on DogPace with a
no-op policy returning a constant action, with and without the ``info`` argument, and on web
navigation level 1 with a policy that only picks the first legal action (``argmax`` of the
mask, whose own cost is measured apart with ``timeit``). Prints one JSON object with the
timer's median and mean in µs per call; the load average is recorded, since on a shared machine
preemption inflates means (medians are robust to it).
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import timeit

import numpy as np

import a2perf_rs


def timed_calls_us(env_id: str, params: dict, policy, episodes: int) -> dict:
    """Median and mean µs per call that ``a2perf_rs.infer`` records for ``policy``."""
    with tempfile.TemporaryDirectory() as out:
        with a2perf_rs.TrainingRun(
            out, env_id=env_id, env_params=params, algorithm="noop",
            set=[f"inference.rollouts={episodes}"],
        ) as run:
            run.log_evaluation(1, 0.0)
        t = a2perf_rs.infer(run.run_dir, policy)["inference_time_ms"]
    return {"median_us": t["median"] * 1e3, "mean_us": t["mean"] * 1e3, "calls": t["count"]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--episodes", type=int, default=30, help="inference episodes per measurement")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    zero = np.zeros(12, dtype=np.float32)
    mask = np.zeros(12_500, dtype=np.int8)
    mask[7] = 1
    cases = {
        "dogpace_noop(obs)": ("QuadrupedLocomotion-DogPace-v0", {}, lambda obs: zero),
        "dogpace_noop(obs, info)": (
            "QuadrupedLocomotion-DogPace-v0", {}, lambda obs, info: zero
        ),
        "web_first_legal(obs, info)": (
            "WebNavigation-Difficulty-01-v0", {"num_websites": 1},
            lambda obs, info: int(info["action_mask"].argmax()),
        ),
    }
    res: dict = {"load_average": os.getloadavg()}
    for name, (env_id, params, policy) in cases.items():
        res[name] = [timed_calls_us(env_id, params, policy, args.episodes) for _ in range(args.repeats)]
    n = 100_000
    res["web_mask_argmax_alone_us"] = (
        min(timeit.repeat(lambda: int(mask.argmax()), number=n, repeat=args.repeats)) / n * 1e6
    )
    print(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
