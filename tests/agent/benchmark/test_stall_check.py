"""The stall check's verdicts: stays over the bound, and NARUTO against frontier per scene."""

from __future__ import annotations

from pathlib import Path

from tests.scripts import load_script

SCRIPT = Path(__file__).resolve().parents[3] / "benchmarks" / "stall_check.py"


def _script():
    return load_script(SCRIPT, "stall_check")


def _episode(policy: str, seed: int, path_m: float, coverage: float, stay: int = 10) -> dict:
    return {
        "scene": "two_rooms:no_ceiling+holes",
        "policy": policy,
        "seed": seed,
        "steps": 300,
        "image_scale": 0.125,
        "longest_stay_steps": stay,
        "coverage": coverage,
        "path_m": path_m,
        "stall_events": {},
    }


def test_a_scene_is_judged_on_the_mean_of_its_seeds():
    check = _script()
    episodes = [
        _episode("naruto", 0, 15.0, 0.78),  # behind on seed 0
        _episode("frontier", 0, 16.0, 0.87),
        _episode("naruto", 1, 18.0, 0.89),  # ahead on seed 1
        _episode("frontier", 1, 17.0, 0.84),
    ]
    (row,) = check.summary(episodes)["naruto_vs_frontier"]
    assert row["seeds"] == [0, 1]
    assert row["naruto_path_m"] == 16.5 and row["frontier_path_m"] == 16.5
    assert row["holds"]  # a mean path as long as frontier's
    assert row["seeds_holding"] == 1
    assert "episode by episode on 1 of 2" in check.table(episodes)


def test_a_scene_behind_on_both_means_does_not_hold():
    check = _script()
    episodes = [
        _episode("naruto", 0, 15.0, 0.78),
        _episode("frontier", 0, 16.0, 0.87),
        _episode("naruto", 1, 16.9, 0.85),  # a longer path on this seed alone
        _episode("frontier", 1, 16.5, 0.86),
        _episode("random", 1, 30.0, 0.60, stay=31),  # no frontier pair: not compared
    ]
    summary = check.summary(episodes)
    (row,) = summary["naruto_vs_frontier"]
    assert not row["holds"] and row["seeds_holding"] == 1
    assert summary["stays_over_limit"] == ["random@two_rooms:no_ceiling+holes#1: 31"]
    assert "does not hold" in check.table(episodes)


def _write_episodes(folder: str, first_seed: int, count: int) -> None:
    """One of two runs side by side: writes its episodes one at a time, as the script does."""
    check = _script()
    path = Path(folder) / check.RESULT_FILE
    for seed in range(first_seed, first_seed + count):
        check._write(path, check.Args(), [_episode("naruto", seed, 10.0, 0.5)])


def test_runs_side_by_side_keep_each_others_episodes(tmp_path):
    """Each write reads the file, adds its episode and writes it back; two runs at once (a
    process per seed) must not drop each other's episodes in between."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    runs = [
        context.Process(target=_write_episodes, args=(str(tmp_path), first, 60))
        for first in (0, 1000)
    ]
    for run in runs:
        run.start()
    for run in runs:
        run.join(timeout=120)
    assert [run.exitcode for run in runs] == [0, 0]
    seeds = {episode["seed"] for episode in _script()._read(tmp_path / "stall_check.json")}
    assert seeds == set(range(60)) | set(range(1000, 1060))
