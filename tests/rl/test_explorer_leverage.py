"""explorer_leverage.py: every candidate of a decision is walked on a copy of the stack, the
copies leave the episode as it was, and a rerun with the same settings resumes."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("stable_baselines3")

from naruto_agent.cli_args import parse_dataclass_args  # noqa: E402
from tests.scripts import load_script  # noqa: E402

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "explorer_leverage.py"


@pytest.fixture(scope="module")
def leverage():
    yield load_script(SCRIPT, "explorer_leverage_under_test")
    del sys.modules["explorer_leverage_under_test"]


def test_every_candidate_is_walked_on_a_copy_and_a_rerun_resumes(leverage, tmp_path):
    output = tmp_path / "leverage.json"
    argv = ["--scenes", "procedural:small:0", "--max-episode-steps", "40",
            "--horizons", "5", "20", "--output-file", str(output)]  # fmt: skip
    result = leverage.main(parse_dataclass_args(leverage.Args, argv))
    episode = result["episodes"]["procedural:small:0/seed0"]
    assert episode["done"] and [d["decision"] for d in episode["decisions"]] == [0, 1]
    for decision in episode["decisions"]:
        assert decision["candidates"] >= 2
        for horizon in ("5", "20"):
            assert len(decision["gains"][horizon]) == decision["candidates"]
        # The episode walked the model's choice for K = 20 steps after the copies had run:
        # the same coverage as the copy that walked that candidate.
        slot = decision["chosen_slot"]
        assert decision["realised"] == pytest.approx(decision["gains"]["20"][slot], abs=1e-5)
        assert min(decision["gains"]["20"]) >= 0.0
    spread = result["summary"]["horizons"]["20"]["best_minus_worst"]
    assert spread["n"] == 2 and spread["mean"] >= 0.0
    assert spread["p90"] >= spread["median"] >= 0.0
    assert (
        result["summary"]["groups"]["procedural:small:*"]["horizons"]
        == result["summary"]["horizons"]
    )
    assert "| best - worst | " in leverage.leverage_table(result["summary"])

    before = output.read_text()
    again = leverage.main(parse_dataclass_args(leverage.Args, argv))
    assert again["summary"] == result["summary"] and json.loads(before) == json.loads(
        output.read_text()
    )
    # Cut short after its first decision: the rerun plays the episode again and measures the
    # second one alone, as the first run did.
    cut = json.loads(before)
    cut["episodes"]["procedural:small:0/seed0"].update(done=False, decisions=[
        episode["decisions"][0]])  # fmt: skip
    output.write_text(json.dumps(cut))
    resumed = leverage.main(parse_dataclass_args(leverage.Args, argv))
    assert resumed["summary"] == result["summary"]
    with pytest.raises(ValueError, match="other settings"):
        leverage.main(
            parse_dataclass_args(
                leverage.Args, [*argv[:-2], "--decision-every", "2", "--output-file", str(output)]
            )
        )
