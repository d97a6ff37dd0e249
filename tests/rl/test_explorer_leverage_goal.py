"""explorer_leverage.py on the decision at every goal: each candidate's copy walks its goal
to the end (the episode's own walk of the chosen one gains the same), then the nearest
candidates, for every horizon."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from naruto_agent.cli_args import parse_dataclass_args  # noqa: E402
from tests.scripts import load_script  # noqa: E402

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "explorer_leverage.py"


@pytest.fixture(scope="module")
def leverage():
    yield load_script(SCRIPT, "explorer_leverage_goal_under_test")
    del sys.modules["explorer_leverage_goal_under_test"]


def test_each_candidate_is_walked_to_its_goal_and_on_for_every_horizon(leverage, tmp_path):
    argv = ["--scenes", "procedural:small:0", "--max-episode-steps", "80", "--decision", "goal",
            "--advance", "random", "--horizons", "5", "20",
            "--output-file", str(tmp_path / "goal.json")]  # fmt: skip
    result = leverage.main(parse_dataclass_args(leverage.Args, argv))
    decisions = result["episodes"]["procedural:small:0/seed0"]["decisions"]
    assert len(decisions) >= 2 and result["settings"]["walker"]["decision"] == "goal"
    lengths = set()
    for decision in decisions:
        count, slot = decision["candidates"], decision["chosen_slot"]
        assert all(len(decision["gains"][h]) == count for h in ("5", "20", "goal"))
        assert len(decision["goal_steps"]) == count
        # What the choice saw, for a ranker's data: every candidate's row and surroundings.
        assert len(decision["table"]) == count and len(decision["surroundings"]) == count
        # The episode walked the chosen goal as its copy did: same steps, same gain.
        assert decision["realised_steps"] == decision["goal_steps"][slot]
        assert decision["realised"] == pytest.approx(decision["gains"]["goal"][slot], abs=1e-5)
        lengths.update(decision["goal_steps"])
    assert len(lengths) > 1  # a decision lasts as long as its goal
    summary = result["summary"]
    assert summary["horizons"]["goal"]["best_minus_worst"]["n"] == len(decisions)
    assert summary["goal_steps"]["mean"] > 0
    assert "until the next decision" in leverage.leverage_table(summary)
    with pytest.raises(ValueError, match="--advance"):
        leverage.main(parse_dataclass_args(leverage.Args, [*argv, "--advance", "best"]))


def test_the_rollout_advance_walks_the_measured_best(leverage, tmp_path):
    argv = ["--scenes", "procedural:small:0", "--max-episode-steps", "60", "--decision", "goal",
            "--advance", "rollout", "--horizons", "5", "10",
            "--output-file", str(tmp_path / "rollout.json")]  # fmt: skip
    result = leverage.main(parse_dataclass_args(leverage.Args, argv))
    decisions = result["episodes"]["procedural:small:0/seed0"]["decisions"]
    assert any(d["chosen_slot"] != 0 for d in decisions)  # not the nearest throughout
    for decision in decisions:
        pairs = zip(decision["gains"]["5"], decision["gains"]["10"], strict=True)
        areas = [g5 * 5 / 2 + (g5 + g10) * 5 / 2 for g5, g10 in pairs]  # trapezoids from 0
        assert areas[decision["chosen_slot"]] == pytest.approx(max(areas))
        assert decision["realised"] == pytest.approx(
            decision["gains"]["goal"][decision["chosen_slot"]], abs=1e-5
        )
    with pytest.raises(ValueError, match="decision-every"):
        leverage.main(parse_dataclass_args(leverage.Args, [*argv, "--decision-every", "2"]))
