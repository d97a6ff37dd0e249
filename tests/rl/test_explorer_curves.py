"""explorer_curves.py bins training runs' learning curves by env steps, each rollout weighted
by its episodes, and compares them over the bins every run reached."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from naruto_agent.cli_args import parse_dataclass_args
from tests.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "explorer_curves.py"
HEADER = "env_steps,hours,env_steps_per_s,episodes,final_coverage,refusals_per_100_steps\n"


@pytest.fixture(scope="module")
def curves():
    yield load_script(SCRIPT, "explorer_curves_under_test")
    del sys.modules["explorer_curves_under_test"]


def _run(folder: Path, rows: list[tuple[int, int, str]]) -> str:
    folder.mkdir()
    lines = [f"{steps},0.1,100,{episodes},{coverage},0.0\n" for steps, episodes, coverage in rows]
    (folder / "learning_curve.csv").write_text(HEADER + "".join(lines))
    return str(folder)


def test_bins_weigh_rollouts_by_their_episodes_and_compare_common_bins(curves, tmp_path):
    first = _run(tmp_path / "a", [(50, 1, "0.5"), (90, 3, "0.9"), (120, 0, ""), (150, 2, "0.6")])
    second = _run(tmp_path / "b", [(60, 2, "0.7"), (140, 2, "0.8"), (260, 2, "0.9")])
    binned = curves.binned(Path(first) / "learning_curve.csv", 100)
    assert binned[0] == pytest.approx((0.8, 4)) and binned[100] == pytest.approx((0.6, 2))
    args = parse_dataclass_args(
        curves.Args,
        ["--runs", first, second, "--labels", "f32", "b16", "--bin-steps", "100",
         "--output-file", str(tmp_path / "out" / "curves.md")],
    )  # fmt: skip
    text = curves.main(args)
    assert "| 0-100 | 80.0 | 70.0 |" in text and "| 100-200 | 60.0 | 80.0 |" in text
    assert "200-300" not in text  # only the bins every run reached
    assert "| mean of the bins | 70.0 | 75.0 |" in text
    assert (tmp_path / "out" / "curves.png").is_file()
    with pytest.raises(SystemExit, match="one per run"):
        curves.main(parse_dataclass_args(curves.Args, ["--runs", first, "--labels", "a", "b"]))
    with pytest.raises(SystemExit, match="learning_curve.csv"):
        curves.main(parse_dataclass_args(curves.Args, ["--runs", str(tmp_path)]))


def test_the_critic_table_bins_ppo_updates_by_env_steps(curves, tmp_path):
    """progress.csv counts decisions: the learning curve beside it gives env steps per
    decision; a run without progress.csv has no critic table."""
    run = Path(_run(tmp_path / "a", [(100, 1, "0.5"), (200, 1, "0.6"), (300, 1, "0.7")]))
    (run / "progress.csv").write_text(
        "time/total_timesteps,train/explained_variance,train/value_loss\n"
        "5,,\n10,-0.0001,300\n15,0.5,100\n"
    )  # 15 decisions for 300 env steps: 20 env steps each
    bins = curves.binned_updates(run / "progress.csv", run / "learning_curve.csv", 250)
    assert bins[0] == pytest.approx((-0.0001, 300.0)) and bins[250] == pytest.approx((0.5, 100.0))
    other = _run(tmp_path / "b", [(100, 1, "0.5")])
    text = curves.main(parse_dataclass_args(
        curves.Args, ["--runs", str(run), other, "--bin-steps", "250",
                      "--output-file", str(tmp_path / "out" / "curves.md")]))
    assert "| 0-250 | 0.00 | 300 |" in text and "| 250-500 | 0.50 | 100 |" in text
    assert "b explained variance" not in text
    assert curves.main(parse_dataclass_args(
        curves.Args, ["--runs", other, "--output-file", str(tmp_path / "o2" / "c.md")])
    ).count("explained variance") == 0
