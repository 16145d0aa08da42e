"""An A2Perf participant folder run by the harness: the child side of ``a2perf submit``, and
what the participant's code can ask about its task.

A participant folder holds ``train.py`` (``train(**participant_args)``), ``inference.py``
(``load_policy(env, **participant_args)`` — or the template's ``load_model(env)`` —,
``preprocess_observation(observation)`` and ``infer_once(policy, preprocessed_observation)``) and
``requirements.txt``. ``a2perf submit`` runs each phase in a child process (:func:`main`,
``train|infer|generalize``) with the folder first on ``sys.path`` (and the working directory of
``train`` and ``load_policy``); the task is in the environment variable ``A2PERF_SUBMISSION``
(JSON), so that any process the participant starts sees it too. Inside the folder's code::

    from a2perf_rs import submission

    task = submission.task()          # env_id, env_params, seed, run_dir, files_dir, training …
    env = submission.make_env()       # the task's environment, seeded like a built-in agent's
    run = submission.training_run()   # during train(): the TrainingRun the harness opened
    run.log_evaluation(steps, mean, std)

A folder that ignores all of this still trains; the original's ``ROOT_DIR`` is set to the run
directory as well. See ``docs/submissions.md``.
"""

from __future__ import annotations

import ast
import contextlib
import importlib
import inspect
import json
import os
import shutil
import sys
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

from . import _native
from .envs import A2PerfEnv
from .harness import TrainingRun, _runtime

__all__ = ["ENV_VAR", "SubmissionError", "Task", "make_env", "task", "training_run"]

#: The environment variable through which ``a2perf submit`` hands the task to its children.
ENV_VAR = "A2PERF_SUBMISSION"

#: The functions ``inference.py`` must define (one of the first pair).
_LOADERS = ("load_policy", "load_model")


class SubmissionError(Exception):
    """The participant folder does not have the shape the harness needs (a missing file or
    function, a function with an unusable signature)."""


@dataclass(frozen=True)
class Task:
    """What the harness asks of the participant's code."""

    #: The environment id (``a2perf list``).
    env_id: str
    #: Every environment parameter in force.
    env_params: dict[str, Any]
    #: The run's seed.
    seed: int
    #: The run directory (also ``$ROOT_DIR``, the original's name).
    run_dir: Path
    #: Where the participant's own files go (checkpoints for ``load_policy``): inside the run
    #: directory, so that they belong to the run.
    files_dir: Path
    #: The training settings: ``total_env_steps`` (the budget), ``eval_interval``,
    #: ``eval_episodes``, ``checkpoint_interval``, ``num_envs``.
    training: dict[str, int]
    #: ``--participant-args``, values as strings (as the original passes them).
    participant_args: dict[str, str]


def _spec() -> dict[str, Any]:
    raw = os.environ.get(ENV_VAR)
    if raw is None:
        raise RuntimeError(
            f"${ENV_VAR} is not set: this code is not being run by `a2perf submit` (run the "
            "folder with `a2perf submit <participant_dir> <config>`)"
        )
    return json.loads(raw)


def task() -> Task:
    """The task of the submission being run (``RuntimeError`` outside ``a2perf submit``)."""
    s = _spec()
    return Task(
        env_id=s["env_id"],
        env_params=dict(s["env_params"]),
        seed=int(s["seed"]),
        run_dir=Path(s["run_dir"]),
        files_dir=Path(s["files_dir"]),
        training=dict(s["training"]),
        participant_args=dict(s["participant_args"]),
    )


_ACTIVE: TrainingRun | None = None


def training_run() -> TrainingRun:
    """The :class:`TrainingRun` the harness opened around ``train()`` (its meters are running):
    log evaluations (``log_evaluation``, or ``evaluate`` with the built-in protocol) and
    register checkpoints through it. ``RuntimeError`` outside the training phase."""
    if _ACTIVE is None:
        raise RuntimeError(
            "no training run: a2perf_rs.submission.training_run() is available inside train() "
            "when `a2perf submit` runs it"
        )
    return _ACTIVE


def make_env(index: int = 0, **kwargs: Any) -> A2PerfEnv:
    """The task's environment. Inside ``train()`` every ``reset()`` without a seed takes the
    next episode seed of training environment ``index`` (as :meth:`TrainingRun.make_env`);
    elsewhere it is unseeded. ``kwargs``: :class:`A2PerfEnv`'s binding options."""
    if _ACTIVE is not None:
        return _ACTIVE.make_env(index, **kwargs)
    t = task()
    with _cwd(_spec()["cwd"]):
        return A2PerfEnv(t.env_id, **kwargs, **t.env_params)


# -- the harness side -------------------------------------------------------------------------


def _defines(path: Path, names: tuple[str, ...]) -> set[str]:
    """The module-level functions of ``path`` among ``names``, read from its syntax tree (no
    code runs): a training that would end with an unusable ``inference.py`` is refused first."""
    try:
        tree = ast.parse(path.read_text(), str(path))
    except SyntaxError as e:
        raise SubmissionError(f"{path}: syntax error at line {e.lineno}: {e.msg}") from None
    found = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name in names:
            found.add(node.name)
        elif isinstance(node, ast.Assign):  # `infer_once = some_callable`
            found.update(t.id for t in node.targets if isinstance(t, ast.Name) and t.id in names)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):  # `from x import load_policy`
            found.update(
                (a.asname or a.name) for a in node.names if (a.asname or a.name) in names
            )
    return found


def check_folder(folder: Path) -> None:
    """Refuses a folder without ``train.py`` defining ``train``, or without ``inference.py``
    defining ``load_policy`` (or ``load_model``), ``preprocess_observation`` and ``infer_once``."""
    wanted = {
        "train.py": (("train",), ()),
        "inference.py": (("preprocess_observation", "infer_once"), _LOADERS),
    }
    for name, (required, one_of) in wanted.items():
        path = folder / name
        if not path.is_file():
            raise SubmissionError(f"{folder}: no {name} (a participant folder needs {name})")
        found = _defines(path, required + one_of)
        missing = [f for f in required if f not in found]
        if one_of and not found.intersection(one_of):
            missing.append(" or ".join(one_of))
        if missing:
            raise SubmissionError(f"{path}: defines no {', '.join(missing)}")


def _import(folder: Path, module: str, function: str | tuple[str, ...]) -> Callable[..., Any]:
    names = (function,) if isinstance(function, str) else function
    mod = importlib.import_module(module)
    for name in names:
        f = getattr(mod, name, None)
        if f is not None:
            if not callable(f):
                raise SubmissionError(f"{folder / (module + '.py')}: `{name}` is not callable")
            return f
    raise SubmissionError(f"{folder / (module + '.py')}: defines no {' or '.join(names)}")


def _parameters(f: Callable[..., Any]) -> dict[str, inspect.Parameter]:
    try:
        return dict(inspect.signature(f).parameters)
    except (TypeError, ValueError):
        return {}


def _accepts(params: dict[str, inspect.Parameter], name: str) -> bool:
    return name in params or any(p.kind == p.VAR_KEYWORD for p in params.values())


def load_submission_policy(folder: Path, args: dict[str, str], env: A2PerfEnv) -> Any:
    """``inference.py``'s policy for ``env``, bound to its ``preprocess_observation`` and
    ``infer_once`` as the harness calls them (a ``_native.SubmissionPolicy``)."""
    loader = _import(folder, "inference", _LOADERS)
    preprocess = _import(folder, "inference", "preprocess_observation")
    infer_once = _import(folder, "inference", "infer_once")
    # The template's load_model(env) takes no participant arguments.
    policy = loader(env, **args) if loader.__name__ != "load_model" else loader(env)
    infer_params = _parameters(infer_once)
    keywords = {"policy", "preprocessed_observation"} <= set(infer_params)
    pre_params = _parameters(preprocess)
    extra = {}
    if "time_step_spec" in pre_params:  # the original harness passes it
        extra["time_step_spec"] = getattr(policy, "time_step_spec", None)
    with_info = "info" in pre_params
    return _native.SubmissionPolicy(policy, preprocess, infer_once, keywords, with_info, extra)


def _not_code(directory: str, names: list[str]) -> set[str]:
    """What a copy of the participant folder leaves out: its venv, hidden files, caches."""
    return {n for n in names if n.startswith(".") or n in ("__pycache__", "venv")}


@contextlib.contextmanager
def _cwd(path: str | Path) -> Iterator[None]:
    before = os.getcwd()
    os.chdir(path)
    try:
        yield
    finally:
        os.chdir(before)


class _SubmissionRun(TrainingRun):
    """The run handed to the participant's code, which runs in its folder: the harness's own
    work (making environments, evaluating) happens in the directory `a2perf submit` was started
    from, against which the config's relative paths (netlists, motion files) resolve."""

    def make_env(self, index: int = 0, **kwargs: Any) -> A2PerfEnv:
        with _cwd(_spec()["cwd"]):
            return super().make_env(index, **kwargs)

    def make_vec(self, num_envs: int, **kwargs: Any) -> Any:
        with _cwd(_spec()["cwd"]):
            return super().make_vec(num_envs, **kwargs)

    def evaluate(self, env_steps: int, policy: Callable[..., Any]) -> tuple[float, float]:
        with _cwd(_spec()["cwd"]):
            return super().evaluate(env_steps, policy)


def _train(spec: dict[str, Any], folder: Path) -> None:
    global _ACTIVE
    args = spec["participant_args"]
    run = _SubmissionRun(
        spec["output"],
        algorithm=spec["algorithm"],
        seed=int(spec["seed"]),
        hyperparameters=args,
        experiment=spec["experiment"],
        config=spec["config"],
        set=spec["set"],
    )
    if os.path.realpath(run.run_dir) != os.path.realpath(spec["run_dir"]):
        raise RuntimeError(
            f"the harness planned {spec['run_dir']} but the package plans {run.run_dir}: the "
            "a2perf binary and the a2perf_rs package are of different versions"
        )
    run._harness = spec["harness"]
    with run:
        _ACTIVE = run
        try:
            # The code that ran belongs to the run (bundles carry it).
            shutil.copytree(folder, spec["code_dir"], ignore=_not_code, dirs_exist_ok=True)
            Path(spec["files_dir"]).mkdir(parents=True, exist_ok=True)
            with _cwd(folder):
                # Imported under the meters: what train.py imports is part of the job.
                train = _import(folder, "train", "train")
                train(**args)
            if run._native.evaluations() == 0:
                # A folder that logs nothing gets one point: its final policy evaluated by the
                # built-in protocol, at the budget (the harness cannot count its steps).
                env = run.make_env()
                with _cwd(folder):
                    policy = load_submission_policy(folder, args, env)
                steps = run.training["total_env_steps"]
                mean, std = run._native.evaluate(steps, policy, False)
                print(f"train() logged no evaluation: final policy {mean:.4f} ± {std:.4f} "
                      f"(recorded at the budget, step {steps})")
        finally:
            _ACTIVE = None


def _infer(spec: dict[str, Any], folder: Path, phase: str) -> None:
    run_dir = spec["run_dir"]
    t = task()
    env = A2PerfEnv(t.env_id, **t.env_params)
    with _cwd(folder):
        policy = load_submission_policy(folder, spec["participant_args"], env)
    if phase == "infer":
        _native.infer(run_dir, policy, False, episodes=spec.get("episodes"))
    else:
        _native.generalize(run_dir, policy, False, episodes=spec.get("generalization_episodes"))


def main(argv: list[str] | None = None) -> int:
    """One phase (``check``, ``train``, ``infer`` or ``generalize``, the one argument) of the
    submission in ``$A2PERF_SUBMISSION``; ``a2perf submit`` runs it as ``python -c "import sys,
    a2perf_rs.submission as s; sys.exit(s.main())" <phase>``. Exit code 0 on success; 2 when the folder is unusable; 1 when
    the participant's code raised (its traceback on stderr; a training run is marked failed,
    nothing written before is removed)."""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1 or argv[0] not in ("check", "train", "infer", "generalize"):
        print("usage: a2perf_rs.submission.main(['check|train|infer|generalize']) "
              f"(with ${ENV_VAR} set by `a2perf submit`)", file=sys.stderr)
        return 2
    phase = argv[0]
    spec = _spec()
    folder = Path(spec["participant_dir"]).resolve()
    try:
        check_folder(folder)
        if phase == "check":
            return 0
        # train() and load_policy() run in the folder (the original's working directory); the
        # harness's own work in the directory `a2perf submit` was started from.
        sys.path.insert(0, str(folder))
        if phase == "train":
            _train(spec, folder)
        else:
            _infer(spec, folder, phase)
    except SubmissionError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{phase}: interrupted", file=sys.stderr)
        return 130
    except BaseException:  # the participant's code: its traceback is what the user needs
        traceback.print_exc()
        return 1
    return 0

