"""The goal lookahead (each candidate walked on a copy of the stack) and the rollout check
built on it: the copies leave the episode as it was, the nearest candidate's curve is the
nearest choice's own episode, and the rollout choice takes the best curve."""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import numpy as np
import pytest

from naruto_agent.cli_args import parse_dataclass_args
from naruto_gym.rl.goal_lookahead import gain_area, gain_at, lookahead_curves
from tests.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "goal_rollout_check.py"
SCENE = "procedural:small:0"


@pytest.fixture(scope="module")
def rollout():
    yield load_script(SCRIPT, "goal_rollout_check_under_test")
    del sys.modules["goal_rollout_check_under_test"]


def test_gains_hold_the_last_value_and_average_over_the_horizon():
    curve = np.array([0.0, 0.1, 0.3])
    assert gain_at(curve, 0) == 0.0 and gain_at(curve, 2) == 0.1 and gain_at(curve, 9) == 0.3
    assert gain_at(np.array([]), 5) == 0.0
    assert gain_area(curve, 4) == pytest.approx((0.0 + 0.1 + 0.3 + 0.3) / 4)
    with pytest.raises(ValueError, match="horizon"):
        gain_area(curve, 0)


def test_the_nearest_curve_is_the_nearest_choice_episode(rollout):
    horizon = 30
    stack = rollout.make_stack(SCENE, horizon)
    observation, info = stack.reset(seed=1)
    count = int((observation["candidates"][:, 0] > 0).sum())
    curves, to_decision = lookahead_curves(stack, count, float(info["coverage"]), horizon)
    assert len(curves) == len(to_decision) == count >= 1
    assert all(len(curve) == horizon for curve in curves)  # the episode ends at the horizon
    played = rollout.play(SCENE, horizon, 1, "nearest", None)
    expected = float(info["coverage"]) + gain_area(curves[0], horizon)
    assert played["area"] == pytest.approx(expected, abs=2e-5)
    stack.close()


def test_copies_leave_the_episode_as_it_was_and_the_rollout_takes_the_best(rollout):
    horizon = 40
    stack = rollout.make_stack(SCENE, 200)
    observation, info = stack.reset(seed=0)
    for _ in range(6):  # a few goals in: candidates that differ
        observation, _, _, _, info = stack.step(0)
    table, coverage = observation["candidates"], float(info["coverage"])
    count = int((table[:, 0] > 0).sum())
    assert count >= 2
    reference = copy.deepcopy(stack)
    curves, _ = lookahead_curves(stack, count, coverage, horizon)
    again, _ = lookahead_curves(stack, count, coverage, horizon)
    assert all(np.array_equal(a, b) for a, b in zip(curves, again, strict=True))
    areas = [gain_area(curve, horizon) for curve in curves]
    assert len({round(area, 6) for area in areas}) > 1
    slot = rollout.choose(f"rollout-{horizon}", stack, table, coverage, None)
    assert slot == int(np.argmax(areas))
    # The episode goes on as if nothing had been walked.
    for action in (slot, 0):
        ours, theirs = stack.step(action), reference.step(action)
        assert ours[4]["coverage"] == theirs[4]["coverage"]
        assert np.array_equal(ours[0]["pose"], theirs[0]["pose"])
    stack.close()
    reference.close()


def test_the_check_pairs_choices_resumes_and_refuses_unknown_ones(rollout, tmp_path):
    argv = ["--size-classes", "small", "--variants", "closed", "--scenes-per-group", "1",
            "--seeds", "0", "--max-episode-steps", "25", "--choices", "nearest",
            "rollout-10", "goal-ranker", "--output-dir", str(tmp_path)]  # fmt: skip
    result = rollout.main(parse_dataclass_args(rollout.Args, argv))
    assert len(result["episodes"]) == 3
    assert all(0.0 < e["area"] <= e["final"] <= 1.0 for e in result["episodes"].values())
    paired = result["summary"]["all"]["paired"]
    assert set(paired) == {"rollout-10", "goal-ranker"}
    assert "rollout-10 - nearest" in (tmp_path / "rollout.md").read_text()
    again = rollout.main(parse_dataclass_args(rollout.Args, argv))  # resumed: nothing replayed
    assert again["episodes"] == result["episodes"]
    with pytest.raises(ValueError, match="other settings"):
        rollout.main(parse_dataclass_args(rollout.Args, [*argv, "--max-episode-steps", "30"]))
    with pytest.raises(ValueError, match="rollout-H"):
        rollout.main(parse_dataclass_args(rollout.Args, [*argv, "--choices", "rollout-x"]))
