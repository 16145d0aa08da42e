"""Locomotion PPO training wall: `a2perf train` against Stable-Baselines3's PPO with the same
hyperparameters on our DogPace, in one run (the README's same-run ratio row; target >= 3x).

    python3 python/benchmarks/sb3_ratio.py [--a2perf PATH] [--wheel PATH] [--rounds 2] [--steps 60000]

By hand, not in CI (PyTorch stays out of CI). On first use it makes its own venv
(~/.cache/a2perf-rs/sb3-venv, or $A2PERF_BENCH_CACHE/sb3-venv) with ``stable-baselines3``,
``torch`` (CPU is enough; PyPI's Linux build brings its CUDA libraries, several GB) and
``gymnasium`` from PyPI, installs the a2perf_rs wheel (``--wheel``; default the newest in dist/)
and re-runs itself there. Run it from anywhere; it works in the repository root, where the paper
profile finds its data (``A2PERF_PAPER_DATA``, default ``../shared/data``). ``--a2perf`` is the
binary to time (default ``$CARGO_TARGET_DIR/release/a2perf``, else ``target/release/a2perf``);
build it from the same tree as the wheel.

Ours: ``a2perf train configs/paper/quadruped_locomotion/dog_pace/ppo.ron --seeds 0`` with the
training budget set to ``--steps`` environment steps, 2 environments, an evaluation (5 greedy
episodes) every ``steps/20`` steps and a checkpoint every ``steps/4``; its wall is the process's.
SB3: ``PPO("MlpPolicy")`` on ``A2PerfEnv`` with the hyperparameters that run recorded in its
run.json (the environment's parameters too), mapped as:

    num_steps -> n_steps (per environment), minibatch_size -> batch_size, num_epochs -> n_epochs,
    learning_rate -> learning_rate (constant), gamma, gae_lambda, clip_ratio -> clip_range,
    value_coef -> vf_coef, entropy_coef -> ent_coef, max_grad_norm, hidden_sizes -> separate pi
    and vf MLPs (net_arch=dict(pi=..., vf=...)), Tanh (both), init_log_std -> log_std_init,
    normalize_observations / normalize_rewards -> VecNormalize(norm_obs, norm_reward, gamma),
    Adam eps 1e-5 (both), advantage normalisation (both), num_envs -> DummyVecEnv of that many;
    evaluation: EvalCallback (deterministic, same episodes and cadence, normalisation synced);
    checkpoints: CheckpointCallback at the same cadence.

Not matched: SB3 clips observations at 10 after normalising and its reward scaling differs in
detail; weight initialisation (SB3: orthogonal); ``learn_log_std=False`` has no SB3 switch (the
paper config trains it, as SB3 does); our run also writes its run files, curve and resume state.
Each side's arithmetic is its own (float32 both; faer vs torch). Torch runs on one thread
(``--torch-threads``): at these layer sizes more threads only add synchronisation, and on a loaded
machine its spinning worker threads slowed SB3 several-fold (0 keeps torch's default).

Rounds alternate (ours, then SB3); prints one JSON object with both walls (median over rounds),
their CPU times, the ratio (SB3 wall / ours) and the load average.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _venv  # noqa: E402

CONFIG = "configs/paper/quadruped_locomotion/dog_pace/ppo.ron"
DOG = "QuadrupedLocomotion-DogPace-v0"
NUM_ENVS = 2
EVAL_EPISODES = 5


def default_binary() -> str:
    target = os.environ.get("CARGO_TARGET_DIR", str(_venv.REPO / "target"))
    return str(Path(target) / "release" / "a2perf")


def children_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def self_cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def ours(binary: str, steps: int, out: Path) -> tuple[dict, dict]:
    """One `a2perf train` run: (timing, the run's run.json)."""
    shutil.rmtree(out, ignore_errors=True)
    training = (f"training=(total_env_steps: {steps}, eval_interval: {steps // 20}, "
                f"eval_episodes: {EVAL_EPISODES}, checkpoint_interval: {steps // 4}, "
                f"num_envs: {NUM_ENVS})")
    cmd = [binary, "train", CONFIG, "--seeds", "0", "--quiet",
           "--set", f"output.dir={out}", "--set", training]
    c, w = children_cpu_s(), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall, cpu = time.perf_counter() - w, children_cpu_s() - c
    run_json = next(out.rglob("run.json"))
    return {"wall_s": wall, "cpu_s": cpu}, json.loads(run_json.read_text())


def sb3(run: dict, steps: int, out: Path, threads: int) -> dict:
    """One SB3 PPO run with `run`'s hyperparameters and environment."""
    import torch

    if threads > 0:
        torch.set_num_threads(threads)
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from a2perf_rs import A2PerfEnv

    p = run["algorithm"]["params"]
    if p.get("lr_schedule", "constant") != "constant":
        raise SystemExit("only a constant learning rate is mapped")
    env_params = {k: v for k, v in run["task"]["env_params"].items() if v is not None}
    seed = int(run["seed"])

    def make(i: int):
        return lambda: Monitor(A2PerfEnv(DOG, episode_seeds=(seed, i), **env_params))

    def normalized(n: int, offset: int) -> VecNormalize:
        return VecNormalize(DummyVecEnv([make(offset + i) for i in range(n)]),
                            norm_obs=bool(p["normalize_observations"]),
                            norm_reward=bool(p["normalize_rewards"]), gamma=p["gamma"])

    shutil.rmtree(out, ignore_errors=True)
    c, w = self_cpu_s(), time.perf_counter()
    venv = normalized(NUM_ENVS, 0)
    eval_env = normalized(1, 1000)
    eval_env.training = False
    eval_env.norm_reward = False
    hidden = list(p["hidden_sizes"])
    model = PPO(
        "MlpPolicy", venv, seed=seed, device="cpu", verbose=0,
        learning_rate=p["learning_rate"], n_steps=p["num_steps"], batch_size=p["minibatch_size"],
        n_epochs=p["num_epochs"], gamma=p["gamma"], gae_lambda=p["gae_lambda"],
        clip_range=p["clip_ratio"], vf_coef=p["value_coef"], ent_coef=p["entropy_coef"],
        max_grad_norm=p["max_grad_norm"] if p["max_grad_norm"] > 0 else 1e9,
        policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden}, "activation_fn": torch.nn.Tanh,
                       "log_std_init": p["init_log_std"]},
    )
    callbacks = [
        EvalCallback(eval_env, n_eval_episodes=EVAL_EPISODES, eval_freq=max(steps // 20 // NUM_ENVS, 1),
                     deterministic=True, verbose=0),
        CheckpointCallback(save_freq=max(steps // 4 // NUM_ENVS, 1), save_path=str(out), verbose=0),
    ]
    model.learn(total_timesteps=steps, callback=callbacks)
    return {"wall_s": time.perf_counter() - w, "cpu_s": self_cpu_s() - c,
            "torch_threads": torch.get_num_threads(), "sb3_version": __import__("stable_baselines3").__version__,
            "torch_version": torch.__version__}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a2perf", default=default_binary(), help="a2perf binary to time")
    ap.add_argument("--wheel", help="a2perf_rs wheel (default: newest in dist/)")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--steps", type=int, default=60_000)
    ap.add_argument("--torch-threads", type=int, default=1,
                    help="torch's intra-op threads (0: torch's default, one per core)")
    args = ap.parse_args()
    args.a2perf = str(Path(args.a2perf).resolve())
    _venv.enter("sb3-venv", ["stable-baselines3", "torch", "gymnasium", "numpy"], args.wheel)

    os.chdir(_venv.REPO)
    load_before = _venv.load_average()
    ours_runs, sb3_runs = [], []
    with tempfile.TemporaryDirectory(prefix="sb3-ratio-") as tmp:
        for _ in range(args.rounds):
            timing, run = ours(args.a2perf, args.steps, Path(tmp) / "ours")
            ours_runs.append(timing)
            print(f"ours: {timing}", file=sys.stderr, flush=True)
            sb3_runs.append(sb3(run, args.steps, Path(tmp) / "sb3", args.torch_threads))
            print(f"sb3: {sb3_runs[-1]}", file=sys.stderr, flush=True)
    ours_wall = _venv.summary([r["wall_s"] for r in ours_runs])
    sb3_wall = _venv.summary([r["wall_s"] for r in sb3_runs])
    print(json.dumps({
        "what": f"locomotion PPO wall, {args.steps} env steps, {CONFIG}, seed 0, "
                f"{NUM_ENVS} envs, eval every {args.steps // 20} steps ({EVAL_EPISODES} episodes)",
        "ours_wall_s": ours_wall,
        "sb3_wall_s": sb3_wall,
        "ratio_sb3_over_ours": sb3_wall["median"] / ours_wall["median"],
        "ours_runs": ours_runs,
        "sb3_runs": sb3_runs,
        "hyperparameters": run["algorithm"]["params"],
        "load_average_before": load_before,
        "load_average_after": _venv.load_average(),
    }, indent=1))


if __name__ == "__main__":
    main()
