"""explorer_curves.py draws the training seeds of one recipe as one curve (mean and spread
per bin, the critic's explained variance too), reference levels as rows and lines, and says
what to do about bad input."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from naruto_agent.cli_args import parse_dataclass_args
from tests.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "explorer_curves.py"
GOAL_HEADER = (
    "env_steps,decisions,minutes,episodes,final_coverage,mean_coverage,"
    "env_steps_per_decision,refusals_per_100_steps\n"
)  # train_goal_explorer.py's columns


@pytest.fixture(scope="module")
def curves():
    yield load_script(SCRIPT, "explorer_curves_seeds_under_test")
    del sys.modules["explorer_curves_seeds_under_test"]


def _seed(folder: Path, means: list[float], explained: list[float] | None = None) -> str:
    """A goal-explorer run: a rollout of one episode at env steps 50, 150, ... with these
    mean coverages; ``explained`` gives the first rollouts a PPO update (10 env steps a
    decision)."""
    folder.mkdir(parents=True)
    rows = [
        f"{50 + 100 * k},{5 + 10 * k},1.0,1,{mean + 0.2:.2f},{mean},10,0.0\n"
        for k, mean in enumerate(means)
    ]
    (folder / "learning_curve.csv").write_text(GOAL_HEADER + "".join(rows))
    if explained is not None:
        updates = [
            f"{5 + 10 * k},{explained[k]},{100 * (k + 1)}\n"
            if k < len(explained)
            else f"{5 + 10 * k},,\n"
            for k in range(len(means))
        ]  # a rollout without an update leaves its statistics empty
        (folder / "progress.csv").write_text(
            "time/total_timesteps,train/explained_variance,train/value_loss\n" + "".join(updates)
        )
    return str(folder)


def _args(curves, argv: list[str]):
    return parse_dataclass_args(curves.Args, argv)


def test_seeds_of_one_label_make_one_curve_with_its_spread_and_references(curves, tmp_path):
    seeds = [
        _seed(tmp_path / "goal" / f"seed{k}", [0.5 + 0.1 * k, 0.6 + 0.1 * k], explained)
        for k, explained in enumerate([[0.1, 0.4], [0.3, 0.6], [0.5]])
    ]
    pair = [_seed(tmp_path / "twin" / f"seed{k}", [0.5 + 0.2 * k, 0.5]) for k in range(2)]
    check = tmp_path / "check.json"
    check.write_text(json.dumps({"table": {
        "largest candidate": {"final": [0.8, 0.9], "auc": [0.6, 0.64], "mean_auc": 0.62},
        "nearest candidate": {"final": [0.7, 0.9], "auc": [0.5, 0.6], "mean_auc": 0.55},
    }}))  # fmt: skip
    output = tmp_path / "out" / "curves.md"
    text = curves.main(_args(curves, [
        "--runs", *seeds, *pair, "--labels", "goal", "goal", "goal", "twin", "twin",
        "--metric", "mean_coverage", "--bin-steps", "100", "--reference", "untrained=0.536",
        "--reference-file", str(check), "--reference-policies", "largest candidate",
        "--output-file", str(output),
    ]))  # fmt: skip
    # three seeds: mean ± sample sd (0.5, 0.6, 0.7 -> 60.0 ± 10.0); two: mean (min to max)
    assert "goal mean coverage over the steps (%), mean ± sd of 3 seeds" in text
    assert "twin mean coverage over the steps (%), mean (min to max) of 2 seeds" in text
    assert "| 0-100 | 60.0 ± 10.0 | 60.0 (50.0 to 70.0) |" in text
    assert "| 100-200 | 70.0 ± 10.0 | 50.0 (50.0 to 50.0) |" in text
    assert "| mean of the bins | 65.0 ± 10.0 | 55.0 (50.0 to 60.0) |" in text
    # reference levels: one row each, the level in every column; the file's area for this metric
    assert "| untrained (reference) | 53.6 | 53.6 |" in text
    assert "| largest candidate (reference) | 62.0 | 62.0 |" in text
    assert "nearest candidate" not in text
    # the critic: the seeds with updates in a bin (three in the first, two in the second)
    assert "goal explained variance, mean ± sd of 3 seeds" in text
    assert "| 0-100 | 0.30 ± 0.20 | 100 |" in text
    assert "| 100-200 | 0.50 (0.40 to 0.60) | 200 |" in text
    assert "twin explained variance" not in text
    assert output.read_text() == text and output.with_suffix(".png").stat().st_size > 0
    assert curves.spread([0.5, 0.6, 0.7]) == pytest.approx((0.6, 0.5, 0.7))
    assert curves.spread([0.2, 0.8]) == pytest.approx((0.5, 0.2, 0.8))


def test_the_final_coverage_of_the_reference_file_follows_the_metric(curves, tmp_path):
    check = tmp_path / "check.json"
    check.write_text(json.dumps({"table": {"frontier": {"final": [0.8, 0.9], "auc": [0.5]}}}))
    levels = curves.file_references(check, "final_coverage", [])
    assert levels == pytest.approx({"frontier": 0.85})


@pytest.mark.parametrize(
    ("reference", "message"),
    [
        ("untrained", "not NAME=VALUE"),
        ("=0.5", "not NAME=VALUE"),
        ("untrained=high", "not a number"),
        ("untrained=53.6", "a percentage\\? write 0.536"),
    ],
)
def test_a_malformed_reference_says_how_to_write_it(curves, tmp_path, reference, message):
    run = _seed(tmp_path / "a", [0.5])
    with pytest.raises(SystemExit, match=message):
        curves.main(_args(curves, ["--runs", run, "--reference", reference]))


def test_bad_runs_and_reference_files_name_what_is_wrong(curves, tmp_path):
    run = _seed(tmp_path / "a", [0.5])
    out = ["--output-file", str(tmp_path / "out" / "c.md")]
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit, match="empty/learning_curve.csv not found.*train_goal"):
        curves.main(_args(curves, ["--runs", str(tmp_path / "empty"), *out]))
    with pytest.raises(SystemExit, match="run folder .*missing not found"):
        curves.main(_args(curves, ["--runs", str(tmp_path / "missing"), *out]))
    with pytest.raises(SystemExit, match="names 'a' twice"):
        curves.main(_args(curves, ["--runs", run, "--reference", "a=0.5", "a=0.6", *out]))
    with pytest.raises(SystemExit, match="--metric .coverage.: use one of final_coverage"):
        curves.main(_args(curves, ["--runs", run, "--metric", "coverage", *out]))
    older = tmp_path / "older"
    older.mkdir()
    (older / "learning_curve.csv").write_text("env_steps,episodes,final_coverage\n50,1,0.7\n")
    with pytest.raises(SystemExit, match="has no mean_coverage column"):
        curves.main(_args(curves, ["--runs", str(older), "--metric", "mean_coverage", *out]))
    late = _seed(tmp_path / "late", [0.5, 0.5, 0.5])
    (tmp_path / "late" / "learning_curve.csv").write_text(GOAL_HEADER + "350,1,1,1,0.7,0.5,10,0\n")
    with pytest.raises(SystemExit, match="share no bin.*larger --bin-steps"):
        curves.main(_args(curves, ["--runs", run, late, "--bin-steps", "100", *out]))
    leverage = tmp_path / "leverage.json"
    leverage.write_text(json.dumps({"summary": {}}))
    with pytest.raises(SystemExit, match="no table of policies.*explorer_scripted_check"):
        curves.main(_args(curves, ["--runs", run, "--reference-file", str(leverage), *out]))
    check = tmp_path / "check.json"
    check.write_text(json.dumps({"table": {"frontier": {"final": [0.8], "auc": [0.5]}}}))
    with pytest.raises(SystemExit, match="ahead candidate not in .*it has frontier"):
        curves.main(_args(curves, ["--runs", run, "--reference-file", str(check),
                                   "--reference-policies", "ahead candidate", *out]))  # fmt: skip
    with pytest.raises(SystemExit, match="give both"):
        curves.main(_args(curves, ["--runs", run, "--reference-policies", "frontier", *out]))
