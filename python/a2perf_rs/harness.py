"""Benchmark your own (Python) agent with the same four metric families, measured by the same
Rust meters, in the same report as the built-in baselines.

Train inside a :class:`TrainingRun`; it creates the run directory exactly as ``a2perf train``
does and measures the block with the same system meters::

    import a2perf_rs

    with a2perf_rs.TrainingRun("results/mine", env_id="WebNavigation-Difficulty-01-v0",
                               env_params={"num_websites": 1}, algorithm="my-agent", seed=0,
                               hyperparameters={"learning_rate": 0.1}) as run:
        env = run.make_env()          # seeded from the run's seed, like the built-in agents'
        ...                           # your training loop
        run.log_evaluation(env_steps, mean_return, std_return)   # or run.evaluate(steps, policy)
        run.save_checkpoint(env_steps, "my_checkpoint.npz")      # for a2perf_rs.collect
    a2perf_rs.infer(run.run_dir, policy)        # inference.json (100 episodes, each call timed)
    a2perf_rs.generalize(run.run_dir, policy)   # generalization.json
    a2perf_rs.report(["results/mine", "results/web_ppo"], "results/report")

A *policy* is any callable ``policy(obs) -> action`` or ``policy(obs, info) -> action``: ``obs``
is exactly what the Gymnasium environment returns (a float32 array or a dict of them; fresh
arrays at every call), ``info`` holds ``action_mask`` (``np.int8``, 1 = legal) for discrete
environments with masks, as the environment's ``info`` does, and the action must be one
``env.step`` accepts (type, shape, bounds) and the mask allows. A policy that raises, or returns
an action that is refused, stops the phase with an exception of the same type naming the run,
the episode and the step; nothing is written.
"""

from __future__ import annotations

import inspect
import json
import os
import platform
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, Iterable, Union

from . import _native
from .envs import A2PerfEnv
from .vector import A2PerfVectorEnv

PathLike = Union[str, "os.PathLike[str]"]

__all__ = ["TrainingRun", "collect", "generalize", "infer", "report"]


def _takes_info(policy: Any, what: str = "policy") -> bool:
    """Whether ``policy`` is called as ``policy(obs, info)`` (two positional parameters, or
    ``*args``) rather than ``policy(obs)``; ``TypeError`` when it is not a usable callable."""
    if not callable(policy):
        raise TypeError(f"{what} must be callable (obs -> action), got {type(policy).__name__}")
    try:
        sig = inspect.signature(policy)
    except (TypeError, ValueError):  # some builtins have no signature: call them with obs only
        return False
    params = list(sig.parameters.values())
    if any(p.kind == p.VAR_POSITIONAL for p in params):
        return True
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    required = [p for p in positional if p.default is p.empty]
    keyword_only = [p.name for p in params if p.kind == p.KEYWORD_ONLY and p.default is p.empty]
    if keyword_only:
        raise TypeError(f"{what} requires keyword arguments {keyword_only}: it must take obs only")
    if not positional:
        raise TypeError(f"{what} takes no positional argument: it must take the observation")
    if len(required) > 2:
        raise TypeError(
            f"{what} requires {len(required)} arguments ({', '.join(p.name for p in required)}); "
            "it must take obs, and optionally info"
        )
    return len(positional) >= 2


def _runtime() -> str:
    """The agent's runtime as recorded in run.json: the interpreter and the array/ML libraries
    already imported."""
    parts = [f"{platform.python_implementation()} {platform.python_version()}"]
    for name in ("numpy", "torch", "jax", "tensorflow"):
        module = sys.modules.get(name)
        version = getattr(module, "__version__", None)
        if version is not None:
            parts.append(f"{name} {version}")
    return ", ".join(parts)


class TrainingRun:
    """A Python agent's training run, recorded exactly as ``a2perf train`` records a built-in
    one. Use it as a context manager; the block is what the system meters measure.

    Entering creates ``run_dir`` (``out_dir/<experiment>/<task>__<algorithm>__seed<k>``: the
    directory ``a2perf train`` would create for that task, algorithm and seed) with
    ``status.json`` (running), ``run.json`` (the task with every parameter, the algorithm name
    and hyperparameters as given, the settings, and the agent's runtime), the operative config,
    ``system_info.json`` and ``train_segments.json``, and starts the meters: RAM of the whole
    process tree (this Python process and its children), energy (RAPL counters, or an estimate
    labelled as such), wall-clock time. Leaving normally marks the run complete and writes
    ``train_system.json`` and ``train_emissions.csv``; leaving by an exception marks it failed
    (``KeyboardInterrupt``: interrupted) and re-raises, keeping everything written before;
    ``a2perf report`` lists such runs as left out with the reason. Running the same run again
    starts it from scratch; a complete run is refused.

    One trainer per run: entering takes the run directory's exclusive training lock (the lock
    ``a2perf train`` takes), held until the block is left. A run another process (or another
    ``TrainingRun`` of this one) is training raises :class:`a2perf_rs.RunLockedError` naming that
    trainer's pid and host, and leaves the directory alone. A trainer that dies, even by
    ``kill -9``, releases the lock with its process.

    Args:
        out_dir: The output root (as a config's ``output.dir``).
        algorithm: The agent's name, the report's column (not a built-in algorithm's name).
        env_id: The environment (``a2perf list``); default: the config's.
        seed: The run's seed: :meth:`make_env` and :meth:`make_vec` draw their episodes from
            it as the built-in algorithms' environments do.
        hyperparameters: Recorded in ``run.json``, the operative config and the leaderboard:
            numbers, booleans, strings, lists of numbers, ``None``.
        env_params: Environment parameters (over the config's).
        experiment: Experiment name (the directory under ``out_dir``); default: ``algorithm``.
        config: An experiment file (e.g. ``configs/web_navigation/ppo.ron``) whose task,
            profile, generalization suite and settings the run takes, its algorithm replaced by
            yours — the way to be scored on exactly a built-in run's task.
        set: ``dotted.path=value`` overrides, as ``a2perf train --set``
            (``"training.total_env_steps=50000"``, ``"inference.rollouts=20"``).
    """

    def __init__(
        self,
        out_dir: PathLike,
        *,
        algorithm: str,
        env_id: str | None = None,
        seed: int = 0,
        hyperparameters: dict[str, Any] | None = None,
        env_params: dict[str, Any] | None = None,
        experiment: str | None = None,
        config: PathLike | None = None,
        set: Iterable[str] = (),  # noqa: A002  (the CLI's name)
    ) -> None:
        if isinstance(set, str):
            set = [set]
        if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
        self._native = _native.TrainingRun(
            os.fspath(out_dir),
            algorithm,
            env_id=env_id,
            seed=seed,
            hyperparameters=hyperparameters,
            env_params=env_params,
            experiment=experiment,
            config=None if config is None else os.fspath(config),
            set=[str(s) for s in set],
        )
        self.algorithm = algorithm
        # What drives the run, as run.json records it (a2perf submit sets its own).
        self._harness: str | None = None

    # -- the block ------------------------------------------------------------------------------

    def __enter__(self) -> TrainingRun:
        for warning in self._native.begin(_runtime(), self._harness):
            warnings.warn(f"{self.run_dir}: {warning}", stacklevel=2)
        return self

    def __exit__(self, exc_type: Any, exc: BaseException | None, tb: Any) -> bool:
        if exc_type is None:
            self._native.finish("completed", "")
            return False
        outcome = "interrupted" if issubclass(exc_type, KeyboardInterrupt) else "failed"
        note = f"{exc_type.__name__}: {exc}" if str(exc) else exc_type.__name__
        try:
            self._native.finish(outcome, note)
        except Exception as finish_error:  # the agent's exception matters more
            warnings.warn(
                f"{self.run_dir}: could not mark the run {outcome}: {finish_error}", stacklevel=2
            )
        return False

    # -- what the run is ------------------------------------------------------------------------

    @property
    def run_dir(self) -> Path:
        """The run directory."""
        return Path(self._native.run_dir)

    @property
    def seed(self) -> int:
        """The run's seed."""
        return self._native.seed

    @property
    def env_id(self) -> str:
        """The environment id."""
        return self._native.env_id

    @property
    def task(self) -> str:
        """The task's name (the report's table): the id, with the parameters that differ from
        its defaults."""
        return self._native.task

    @property
    def env_params(self) -> dict[str, Any]:
        """Every environment parameter in force."""
        return self._native.env_params

    @property
    def training(self) -> dict[str, int]:
        """The training settings recorded in ``run.json``: ``total_env_steps`` (the budget),
        ``eval_interval``, ``eval_episodes`` (what :meth:`evaluate` uses), ``checkpoint_interval``,
        ``num_envs``."""
        return self._native.training

    @property
    def clock(self) -> float:
        """Seconds since the block began (the curve's clock)."""
        return self._native.clock()

    # -- environments ---------------------------------------------------------------------------

    def make_env(self, index: int = 0, **kwargs: Any) -> A2PerfEnv:
        """The run's environment as a Gymnasium environment. Every ``reset()`` without a seed
        takes the next episode seed of training environment ``index`` of this run (the streams
        the built-in algorithms' environments use); ``kwargs`` are :class:`A2PerfEnv`'s binding
        options (``illegal_action``, ``illegal_action_reward``)."""
        if not isinstance(index, int) or isinstance(index, bool) or index < 0:
            raise ValueError(f"index must be a non-negative integer, got {index!r}")
        return A2PerfEnv(
            self.env_id, episode_seeds=(self.seed, index), **kwargs, **self.env_params
        )

    def make_vec(self, num_envs: int, **kwargs: Any) -> A2PerfVectorEnv:
        """``num_envs`` copies of the run's environment stepped in Rust threads
        (:class:`A2PerfVectorEnv`); environment ``i`` draws its episodes (autoresets included)
        from training stream ``i`` of this run. ``kwargs``: ``autoreset_mode``, ``copy``,
        ``illegal_action``, ``illegal_action_reward``."""
        return A2PerfVectorEnv(
            self.env_id, num_envs, episode_seeds=self.seed, **kwargs, **self.env_params
        )

    # -- what the agent reports -----------------------------------------------------------------

    def log_evaluation(
        self, env_steps: int, mean_return: float, std_return: float = 0.0
    ) -> None:
        """Records an evaluation point of the training curve (``curve.csv``, ``curve.json``,
        rewritten at once), with the run's clock. Steps must increase; returns must be finite.
        The reliability metrics are computed from these points."""
        self._native.log_evaluation(int(env_steps), float(mean_return), float(std_return))

    def evaluate(self, env_steps: int, policy: Callable[..., Any]) -> tuple[float, float]:
        """Evaluates ``policy`` as the built-in algorithms are evaluated during training
        (``training.eval_episodes`` greedy episodes in Rust, on the same evaluation seeds at every
        point), records the point at ``env_steps`` and returns ``(mean, std)``."""
        with_info = _takes_info(policy)
        return self._native.evaluate(int(env_steps), policy, with_info)

    def save_checkpoint(self, step: int, path: PathLike) -> Path:
        """Registers the agent's checkpoint file ``path`` (any format: it is copied as is) taken
        after ``step`` environment steps, as ``checkpoints/step_<step>.ckpt`` of the run, where
        :func:`collect` finds it. Returns the stored path."""
        return Path(self._native.save_checkpoint(int(step), os.fspath(path)))

    def __repr__(self) -> str:
        return f"TrainingRun({str(self.run_dir)!r})"


def infer(
    run_dir: PathLike,
    policy: Callable[..., Any],
    episodes: int | None = None,
    *,
    observation_source: str | None = None,
    timing_samples: int | None = None,
) -> dict[str, Any]:
    """The inference benchmark of a complete :class:`TrainingRun`, ``policy`` being its final
    policy: greedy rollouts in the Rust environment (``episodes``, default the run's
    ``inference.rollouts``: 100), every call timed in milliseconds with the pipeline's timer, the
    system meters over the rollouts. Writes ``inference.json`` (and ``inference_emissions.csv``)
    as ``a2perf infer`` does and returns its contents. ``observation_source="random"`` also times
    calls on random observation-space samples, as the original harness did."""
    with_info = _takes_info(policy)
    return json.loads(
        _native.infer(
            os.fspath(run_dir),
            policy,
            with_info,
            episodes=episodes,
            observation_source=observation_source,
            timing_samples=timing_samples,
        )
    )


def generalize(
    run_dir: PathLike, policy: Callable[..., Any], episodes: int | None = None
) -> dict[str, Any]:
    """Greedy returns of ``policy`` on every task of the run's generalization suite and their
    sum (the paper's generalization score). Writes ``generalization.json`` as ``a2perf
    generalize`` does and returns its contents. The callable meets each task's own observations
    (whose shapes may differ from the training task's)."""
    with_info = _takes_info(policy)
    return json.loads(
        _native.generalize(os.fspath(run_dir), policy, with_info, episodes=episodes)
    )


def collect(
    run_dirs: PathLike | Iterable[PathLike],
    load_policy: Callable[[str], Callable[..., Any]],
    out: PathLike | None = None,
    *,
    eval_episodes: int = 100,
    dataset_episodes: int = 100,
    cost: str = "measured",
    one_sigma: bool = False,
) -> dict[str, Any]:
    """``a2perf collect`` over run directories (or directories holding them): every checkpoint
    evaluated, expertise levels assigned, and novice/intermediate/expert offline datasets with
    their training sample cost written under ``out`` (default: ``datasets/`` beside the first
    run). The checkpoints of :class:`TrainingRun` runs are loaded by
    ``load_policy(path) -> policy``; built-in runs' by the benchmark. Returns the datasets and
    evaluations."""
    if isinstance(run_dirs, (str, os.PathLike)):
        run_dirs = [run_dirs]

    def loader(path: str) -> tuple[Callable[..., Any], bool]:
        policy = load_policy(path)
        return policy, _takes_info(policy, f"load_policy({path!r}) returned a policy that")

    if not callable(load_policy):
        raise TypeError(
            f"load_policy must be callable (path -> policy), got {type(load_policy).__name__}"
        )
    return json.loads(
        _native.collect(
            [os.fspath(d) for d in run_dirs],
            loader,
            None if out is None else os.fspath(out),
            eval_episodes=eval_episodes,
            dataset_episodes=dataset_episodes,
            cost=cost,
            one_sigma=one_sigma,
        )
    )


def report(
    dirs: PathLike | Iterable[PathLike],
    out: PathLike,
    *,
    bootstrap_reps: int | None = None,
    paper: PathLike | None = None,
) -> dict[str, Any]:
    """``a2perf report DIRS -o OUT``: every complete run below ``dirs`` — Python agents' and
    built-in ones' alike — in one set of tables (``report.md``, ``report.tex``,
    ``metrics.csv``), the page ``index.html``, radar plots, training curves and
    ``leaderboard.json``; runs left out (failed, interrupted, duplicate seeds) are listed with
    the reason. ``paper`` (e.g. ``docs/paper/tables.json``, as ``--paper``) sets the paper's
    figures beside ours with verdicts, checks its findings and writes ``comparison.json``.
    Returns ``report.json``."""
    if isinstance(dirs, (str, os.PathLike)):
        dirs = [dirs]
    return json.loads(
        _native.report(
            [os.fspath(d) for d in dirs],
            os.fspath(out),
            bootstrap_reps=bootstrap_reps,
            paper=None if paper is None else os.fspath(paper),
        )
    )
