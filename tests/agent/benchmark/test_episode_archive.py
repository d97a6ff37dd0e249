"""The episode archive: compact copies of a suite run's records that the leaderboard is made
from as from the run itself, so that a run spread over sessions loses nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from naruto_agent.benchmark.cli import main
from naruto_agent.benchmark.efficiency import episode_efficiency
from naruto_agent.benchmark.episode_archive import (
    EPISODES_FILE,
    archive_run,
    compact_record,
    load_episodes,
)
from naruto_agent.benchmark.episode_archive import main as archive_main
from naruto_agent.benchmark.leaderboard import leaderboard_markdown
from naruto_agent.benchmark.records import load_records

pytest.importorskip("naruto_gym.scenes.suite")

TINY = [
    "--suite", "test", "--size-class", "small", "--suite-limit", "2", "--seeds", "0",
    "--max-episode-steps", "6", "--image-scale", "0.1", "--eval-points", "2",
    "--eval-samples", "2000", "--checkpoint-samples", "2000", "--eval-samples-per-m2", "0",
    "--env-kwargs", '{"panorama_shape": [16, 32], "coverage_samples": 2000}',
    "--no-plots", "--no-progress", "--workers", "0",
]  # fmt: skip


def _tables(page: str) -> str:
    """The page's class tables and paired differences (from the first class to the curves)."""
    return page[page.index("## small"):page.index("## Curves")]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two tiny suite runs of the same scenes, as two sessions would make them: random in
    one folder, passive in another."""
    root = tmp_path_factory.mktemp("suite")
    for policy in ("random", "passive"):
        assert main([*TINY, "--policies", policy, "--output-dir", str(root / policy)]) == 0
    return root / "random", root / "passive"


def test_a_compact_copy_keeps_what_the_leaderboard_reads_without_the_trajectory(runs):
    record = load_records(runs[0])[0]
    copy = compact_record(record)
    assert "trajectory" not in copy and "coverage_curve" not in copy
    steps = [0, *(point["step"] for point in record["completion_curve"])]
    assert [step for step, _ in copy["checkpoint_path_m"]] == steps  # not one per step
    assert episode_efficiency(copy) == episode_efficiency(record)
    with pytest.raises(ValueError, match="levels"):
        episode_efficiency(copy, thresholds_pct=(50,))
    with pytest.raises(ValueError, match="run it again"):
        compact_record({**record, "status": "failed", "error": "boom"})


def test_the_leaderboard_of_an_archive_is_the_leaderboard_of_its_runs(runs, tmp_path):
    """Two runs archived one after the other (two sessions) give the page that one folder
    holding both runs' records gives; archiving a run again replaces its copies."""
    archive, together = tmp_path / "archive", tmp_path / "together"
    assert archive_run(runs[0], archive) == (2, 2)
    assert archive_run(runs[1], archive) == (2, 2)
    assert archive_run(runs[0], archive) == (2, 0)
    assert len(json.loads((archive / EPISODES_FILE).read_text())) == 4
    for run in runs:  # one folder with both runs' full records
        for path in (run / "records").glob("*/*/*.json"):
            target = together / path.relative_to(run)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(path.read_text())
        (together / "suite.json").write_text((run / "suite.json").read_text())
    from_archive = leaderboard_markdown(archive, tmp_path / "img_a")
    from_records = leaderboard_markdown(together, tmp_path / "img_r")
    assert _tables(from_archive) == _tables(from_records)
    assert "| random |" in from_archive and "| passive |" in from_archive
    manifest = json.loads((archive / "suite.json").read_text())
    assert len(manifest["runs"]) == 2  # each run's command and machine, once
    assert {episode["policy"] for episode in load_episodes(archive)} == {"random", "passive"}


def test_archiving_a_folder_without_a_suite_run_says_what_to_give(tmp_path, capsys):
    assert archive_main([str(tmp_path / "nothing"), str(tmp_path / "archive")]) == 2
    assert "naruto-benchmark --suite" in capsys.readouterr().err
    assert not (tmp_path / "archive").exists()
