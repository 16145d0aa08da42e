"""Bad input gets a Python exception naming the problem (never a Rust panic, never a hang)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

from a2perf_rs import A2PerfEnv, metrics
from a2perf_rs.circuit import PlacementCost
from conftest import shared

DOG = "a2perf/QuadrupedLocomotion-DogPace-v0"


def test_unknown_parameter_is_a_type_error_with_a_did_you_mean() -> None:
    with pytest.raises(TypeError, match=r"unknown parameter `motion_fil`.*did you mean `motion_file`"):
        gym.make(DOG, motion_fil="x.txt")
    with pytest.raises(TypeError, match=r"unknown parameter `num_website`.*num_websites"):
        gym.make("a2perf/WebNavigation-Difficulty-01-v0", num_website=3)


def test_mistyped_parameters() -> None:
    with pytest.raises(TypeError, match=r"parameter `episode_steps`: expected integer"):
        gym.make(DOG, episode_steps="long")
    with pytest.raises(TypeError, match=r"parameter `randomize`"):
        gym.make(DOG, randomize=3)
    with pytest.raises(ValueError, match=r"`tst` is not one of test, train.*did you mean `test`"):
        gym.make(DOG, mode="tst")
    with pytest.raises(TypeError, match="unsupported type"):
        gym.make(DOG, episode_steps=object())


def test_missing_or_malformed_files(tmp_path: Path) -> None:
    with pytest.raises((TypeError, ValueError), match="netlist_file"):
        gym.make("a2perf/CircuitTraining-ToyMacro-v0")
    with pytest.raises(FileNotFoundError, match="nope.pb.txt"):
        gym.make("a2perf/CircuitTraining-ToyMacro-v0", netlist_file=str(tmp_path / "nope.pb.txt"))
    bad = tmp_path / "bad.pb.txt"
    bad.write_text('node {\n  name: "M0"\n  attr { key: "type" value { placeholder: \n')
    with pytest.raises(ValueError, match="bad.pb.txt"):
        gym.make("a2perf/CircuitTraining-ToyMacro-v0", netlist_file=str(bad))
    clip = tmp_path / "clip.txt"
    clip.write_text("this is not a motion clip")
    with pytest.raises(ValueError, match="clip.txt"):
        gym.make(DOG, motion_file=str(clip))
    with pytest.raises(FileNotFoundError, match="missing.txt"):
        gym.make(DOG, motion_file=tmp_path / "missing.txt")


def test_bad_box_actions() -> None:
    env = A2PerfEnv("QuadrupedLocomotion-DogPace-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \[11\], expected \[12\]"):
        env.step(np.zeros(11, np.float32))
    with pytest.raises(ValueError, match=r"shape \[1, 12\]"):
        env.step(np.zeros((1, 12)))
    with pytest.raises(TypeError, match="dtype"):
        env.step(np.array(["a"] * 12))
    with pytest.raises(TypeError, match="dtype"):
        env.step(np.ones(12, dtype=bool))
    with pytest.raises(ValueError, match="outside the action space"):
        env.step(np.full(12, 50.0))
    with pytest.raises(ValueError, match="finite"):
        env.step(np.full(12, np.nan))
    # Still usable after refused actions: float64 and lists are converted.
    env.step(np.zeros(12))
    env.step([0.0] * 12)


def test_bad_discrete_actions() -> None:
    env = A2PerfEnv("CircuitTraining-Synthetic-Small-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"outside Discrete\(256\)"):
        env.step(256)
    with pytest.raises(ValueError, match=r"action -1 is outside"):
        env.step(-1)
    with pytest.raises(TypeError, match="not float"):
        env.step(3.0)
    with pytest.raises(TypeError, match="not bool"):
        env.step(True)
    with pytest.raises(TypeError, match="one integer"):
        env.step(np.array([1, 2]))
    with pytest.raises(TypeError, match="one integer"):
        env.step("3")
    _, info = env.reset(seed=0)
    env.step(np.int64(np.flatnonzero(info["action_mask"])[0]))


def test_bad_seeds() -> None:
    env = A2PerfEnv("QuadrupedLocomotion-DogPace-v0")
    with pytest.raises(Exception, match="(?i)seed"):
        env.reset(seed=-1)
    env.reset(seed=0)


def test_bad_placement_cost_input(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="missing.pb.txt"):
        PlacementCost(tmp_path / "missing.pb.txt")
    bad = tmp_path / "netlist.pb.txt"
    bad.write_text("node { name: ")
    with pytest.raises(ValueError, match="netlist.pb.txt:1"):
        PlacementCost(bad)
    garbage = tmp_path / "g.pb.txt.gz"
    garbage.write_bytes(b"\x1f\x8b not really gzip")
    with pytest.raises((ValueError, OSError), match="g.pb.txt.gz"):
        PlacementCost(garbage)
    root = shared("circuit", "toy_macro_stdcell")
    with pytest.raises(FileNotFoundError, match="none.plc"):
        PlacementCost(root / "netlist.pb.txt", tmp_path / "none.plc")
    plc_bad = tmp_path / "bad.plc"
    plc_bad.write_text("0 1.0 2.0 N 0\n999999 1 2 N 0\n")
    with pytest.raises(ValueError, match="bad.plc"):
        PlacementCost(root / "netlist.pb.txt", plc_bad)
    plc = PlacementCost(root / "netlist.pb.txt", root / "initial.plc", soft_macro_rule="type_case")
    with pytest.raises(IndexError, match="out of range"):
        plc.get_node_location(10**6)
    with pytest.raises(IndexError, match="out of range"):
        plc.update_node_coords(-1, 0.0, 0.0)
    pin = next(i for i in range(plc.num_nodes()) if plc.get_node_type(i) in ("MACRO_PIN", "macro_pin"))
    with pytest.raises(ValueError, match="pin"):
        plc.update_node_coords(pin, 1.0, 1.0)
    with pytest.raises(ValueError, match="finite"):
        plc.update_node_coords(0, float("nan"), 1.0)
    with pytest.raises(ValueError, match="positive"):
        plc.set_canvas_size(-1.0, 10.0)
    with pytest.raises(ValueError, match="at least 1"):
        plc.set_placement_grid(0, 5)
    with pytest.raises(ValueError, match="orientation"):
        plc.update_macro_orientation(plc.get_hard_macro_indices()[0], "Q")
    with pytest.raises(ValueError, match="soft_macro_rule"):
        PlacementCost(root / "netlist.pb.txt", soft_macro_rule="prefix")
    with pytest.raises(IndexError, match="outside"):
        plc.place_node(plc.get_hard_macro_indices()[0], 10**6)
    # Refused calls leave it usable.
    assert plc.get_cost() > 0


def test_bad_metric_input() -> None:
    with pytest.raises(ValueError, match="missing column 'value'"):
        metrics.reliability(pd.DataFrame({"run": ["a"], "step": [0]}))
    dup = pd.DataFrame({"run": ["a", "a", "a"], "step": [0, 1, 1], "value": [1.0, 2.0, 3.0]})
    with pytest.raises(ValueError, match=r"curves:2: run `a` has step 1 twice"):
        metrics.reliability(dup)
    with pytest.raises(ValueError, match="not finite"):
        metrics.reliability(np.array([[0.0, np.inf, 1.0]] * 3))
    with pytest.raises(TypeError, match="numbers"):
        metrics.reliability([["a", "b"]])
    with pytest.raises(ValueError, match="did you mean `iqm`"):
        metrics.aggregates(np.ones((3, 2)), ("iqn",))
    with pytest.raises(ValueError, match="runs × tasks"):
        metrics.iqm(np.ones(3))
    with pytest.raises(ValueError, match="reps"):
        metrics.iqm_ci(np.ones((3, 2)), reps=0)
    with pytest.raises(ValueError, match="unknown rl-reliability-metrics class"):
        metrics.evaluate("IqrOverRuns", np.ones((3, 5)))
    with pytest.raises(TypeError, match="unexpected parameters"):
        metrics.evaluate("IqrWithinRuns", np.ones((3, 5)), windowsize=3)
    with pytest.raises(ValueError, match="definition"):
        metrics.reliability(np.ones((3, 50)), definition="a2pref")
    scores = pd.DataFrame(
        {"algorithm": ["A", "A"], "task": ["t1", "t2"], "run": ["0", "1"], "score": [1.0, 2.0]}
    )
    with pytest.raises(ValueError, match="no score for task"):
        metrics.iqm_ci(scores, reps=100)
