"""DogPace env steps/s against MuJoCo's bare physics of a comparable quadruped, in one run (the
README's same-run ratio row; target >= 1.5x).

    python3 python/benchmarks/mujoco_ratio.py [--wheel dist/a2perf_rs-...whl] [--rounds 7] [--steps 1000]
        [--physics rapier|articulated]

By hand, not in CI. On first use it makes its own venv (~/.cache/a2perf-rs/bench-venv, or
$A2PERF_BENCH_CACHE/bench-venv) with ``mujoco``, ``numpy`` and ``gymnasium`` from PyPI, then
installs the a2perf_rs wheel (``--wheel``; default the newest in dist/, built by scripts/wheel
when there is none; rebuild it after changing the Rust code) and re-runs itself there.

The MuJoCo side is a Laikago-class quadruped written here in MJCF (not taken from any model
collection): a 0.5 x 0.2 x 0.1 m, 13 kg trunk; four legs with hip-abduction, hip and knee hinges
(12 joints) and capsule links with a toe sphere; 12 position actuators; a floor plane, robot-floor
contacts only (as ours). Bare physics: ``mj_step`` with a fixed standing action, 1 ms timestep,
33 steps per env step, MuJoCo's default solver settings, nothing else (no observation, reward or
reset). Our side: ``A2PerfEnv("QuadrupedLocomotion-DogPace-v0", physics=...)`` stepped from
Python with the zero action (the default pose), observation, reward, PD control and resets
included, on the engine ``--physics`` names (default ``articulated``, this crate's
reduced-coordinate engine; ``rapier``, the engine of the recorded results).

Both run in this process, pinned to one core, one thread each, in alternating rounds. Three rates
per side, medians over rounds: per second of this thread's CPU time, per wall second, and one
over the median env step (``ratio_step_median``, the headline: preemption on a loaded machine
inflates a few steps, not the median; resets are not steps). Prints one JSON object with the
rates, the ratios (ours / MuJoCo) and the load average.

``--a2perf PATH`` times ours with that binary's ``a2perf bench`` instead (its native loop, uniform
random actions, which topple the robot every ~10 steps so resets are frequent; no wheel needed,
no CPU-time rate), in a child process pinned to the same core.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _venv  # noqa: E402

DOG = "QuadrupedLocomotion-DogPace-v0"
SUBSTEPS = 33

# Legs: name, hip x, side (+1 left).
LEGS = [("FR", 0.21, -1), ("FL", 0.21, 1), ("RR", -0.21, -1), ("RL", -0.21, 1)]
# Standing pose: abduction, hip, knee [rad]; about 0.40 m trunk height.
POSE = (0.0, 0.67, -1.25)


def quadruped_mjcf() -> str:
    """The 12-actuator quadruped: trunk 13 kg, hip motor 1.0 kg, upper leg 1.5 kg, lower leg with
    toe 0.3 kg per leg (about 24 kg in all, as Laikago)."""
    legs, actuators = [], []
    for name, x, side in LEGS:
        y = 0.08 * side
        legs.append(f"""
      <body name="{name}_hip" pos="{x} {y} 0">
        <joint name="{name}_abd" axis="1 0 0" range="-0.8 0.8"/>
        <geom type="sphere" size="0.05" mass="1.0"/>
        <body name="{name}_upper" pos="0 {0.06 * side} 0">
          <joint name="{name}_hip" axis="0 1 0" range="-1.0 3.0"/>
          <geom type="capsule" fromto="0 0 0 0 0 -0.25" size="0.03" mass="1.5"/>
          <body name="{name}_lower" pos="0 0 -0.25">
            <joint name="{name}_knee" axis="0 1 0" range="-2.6 -0.5"/>
            <geom type="capsule" fromto="0 0 0 0 0 -0.23" size="0.02" mass="0.25"/>
            <geom type="sphere" pos="0 0 -0.25" size="0.025" mass="0.05"/>
          </body>
        </body>
      </body>""")
        for joint in ("abd", "hip", "knee"):
            actuators.append(
                f'<position joint="{name}_{joint}" kp="100" kv="2" ctrlrange="-3 3"/>'
            )
    return f"""
<mujoco model="laikago-class quadruped">
  <compiler angle="radian"/>
  <option timestep="0.001"/>
  <default>
    <geom contype="1" conaffinity="0" friction="1 0.005 0.0001"/>
    <joint damping="0.05" limited="true"/>
  </default>
  <worldbody>
    <geom name="floor" type="plane" size="50 50 0.1" contype="0" conaffinity="1"/>
    <body name="trunk" pos="0 0 0.45">
      <freejoint/>
      <geom type="box" size="0.25 0.1 0.05" mass="13"/>{"".join(legs)}
    </body>
  </worldbody>
  <actuator>
    {chr(10).join("    " + a for a in actuators)}
  </actuator>
</mujoco>
"""


class Mujoco:
    def __init__(self) -> None:
        import mujoco
        import numpy as np

        self.mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(quadruped_mjcf())
        self.data = mujoco.MjData(self.model)
        pose = np.tile(POSE, 4)
        self.data.qpos[7:] = pose
        self.data.ctrl[:] = pose
        mujoco.mj_forward(self.model, self.data)

    def run(self, steps: int) -> list[float]:
        lat, clock, step = [], time.perf_counter, self.mujoco.mj_step
        for _ in range(steps):
            t = clock()
            step(self.model, self.data, SUBSTEPS)
            lat.append(clock() - t)
        return lat

    def trunk_height(self) -> float:
        return float(self.data.qpos[2])


class Ours:
    def __init__(self, physics: str) -> None:
        import numpy as np
        from a2perf_rs import A2PerfEnv

        self.env = A2PerfEnv(DOG, physics=physics)
        self.action = np.zeros(self.env.action_space.shape, dtype=np.float32)
        self.env.reset(seed=0)
        self.resets = 0

    def run(self, steps: int) -> list[float]:
        env, action, lat, clock = self.env, self.action, [], time.perf_counter
        for _ in range(steps):
            t = clock()
            _, _, term, trunc, _ = env.step(action)
            lat.append(clock() - t)
            if term or trunc:
                env.reset()
                self.resets += 1
        return lat


class OursCli:
    """`a2perf bench` (native loop, uniform random actions, resets included in its wall rate),
    for a binary built from a tree whose wheel is not at hand."""

    def __init__(self, binary: str, physics: str) -> None:
        self.binary = binary
        self.physics = physics
        self.resets = 0
        self.round = 0

    def bench(self, steps: int) -> dict:
        self.round += 1
        out = subprocess.run([self.binary, "bench", DOG, "--steps", str(steps), "--seed",
                              str(self.round), "--set", f"physics={self.physics}", "--json"],
                             check=True, capture_output=True, text=True)
        report = json.loads(out.stdout)
        self.resets += report["episodes"] - 1
        return report


def timed(sim, steps: int) -> tuple[float | None, float, float]:
    """(env steps per CPU-second, per wall-second, median seconds of one env step). The median
    step is what preemption on a loaded machine distorts least; resets are not steps."""
    if isinstance(sim, OursCli):
        r = sim.bench(steps)
        return None, r["steps_per_second"], r["step_latency_us"]["p50"] * 1e-6
    c, w = time.thread_time(), time.perf_counter()
    lat = sim.run(steps)
    return steps / (time.thread_time() - c), steps / (time.perf_counter() - w), statistics.median(lat)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--wheel", help="a2perf_rs wheel to measure (default: newest in dist/)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--steps", type=int, default=1000, help="env steps per round and side")
    ap.add_argument("--a2perf", help="time ours with this binary's `a2perf bench` (random "
                    "actions, native loop) instead of the wheel")
    ap.add_argument("--physics", choices=["articulated", "rapier"], default="articulated",
                    help="our engine (default articulated)")
    args = ap.parse_args()
    if args.a2perf:
        args.a2perf = str(Path(args.a2perf).resolve())
        _venv.enter_without_wheel("bench-venv", ["mujoco", "numpy", "gymnasium"])
    else:
        _venv.enter("bench-venv", ["mujoco", "numpy", "gymnasium"], args.wheel)

    import mujoco

    cpu = _venv.pin_one_core()
    load_before = _venv.load_average()
    ours = OursCli(args.a2perf, args.physics) if args.a2perf else Ours(args.physics)
    sims = {"mujoco": Mujoco(), "ours": ours}
    for sim in sims.values():  # warm-up
        timed(sim, 50)
    rates: dict[str, dict[str, list]] = {k: {"cpu": [], "wall": [], "p50": []} for k in sims}
    for r in range(args.rounds):
        # Alternate which side goes first, so a drift of the machine's speed hits both alike.
        for name in sorted(sims, reverse=r % 2 == 1):
            c, w, p50 = timed(sims[name], args.steps)
            rates[name]["cpu"].append(c)
            rates[name]["wall"].append(w)
            rates[name]["p50"].append(1.0 / p50)
    cpu_s = {k: _venv.summary(v["cpu"]) if None not in v["cpu"] else None for k, v in rates.items()}
    wall_s = {k: _venv.summary(v["wall"]) for k, v in rates.items()}
    step_s = {k: _venv.summary(v["p50"]) for k, v in rates.items()}
    print(json.dumps({
        "what": f"env steps/s on one core: ours (DogPace, {args.physics}, " + (
            "`a2perf bench`, random actions" if args.a2perf else "wheel, zero action") +
            ", obs+reward+PD; resets in the wall rates) vs MuJoCo bare physics (12-actuator "
            "quadruped, 1 ms x 33 mj_step, fixed action)",
        "ratio_step_median": step_s["ours"]["median"] / step_s["mujoco"]["median"],
        "physics": args.physics,
        "mujoco_version": mujoco.__version__,
        "cpu": cpu,
        "rounds": args.rounds,
        "steps_per_round": args.steps,
        "ours_per_cpu_s": cpu_s["ours"],
        "mujoco_per_cpu_s": cpu_s["mujoco"],
        "ratio_cpu": cpu_s["ours"]["median"] / cpu_s["mujoco"]["median"] if cpu_s["ours"] else None,
        "ours_per_median_step": step_s["ours"],
        "mujoco_per_median_step": step_s["mujoco"],
        "ours_per_wall_s": wall_s["ours"],
        "mujoco_per_wall_s": wall_s["mujoco"],
        "ratio_wall": wall_s["ours"]["median"] / wall_s["mujoco"]["median"],
        "ours_resets": sims["ours"].resets,
        "mujoco_trunk_height_m": sims["mujoco"].trunk_height(),
        "load_average_before": load_before,
        "load_average_after": _venv.load_average(),
    }, indent=1))


if __name__ == "__main__":
    main()
