"""``naruto-benchmark --suite``: flags, class budgets, a tiny real run that resumes after a kill,
its statistics and the leaderboard page made from it."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from naruto_agent.benchmark.cli import episode_specs, main, parse_args
from naruto_agent.benchmark.leaderboard import leaderboard_markdown
from naruto_agent.benchmark.records import load_records, read_record
from naruto_agent.benchmark.suite import group_of, read_manifest, select_scenes

suite = pytest.importorskip("naruto_gym.scenes.suite")
ROOT = Path(__file__).resolve().parents[3]

TINY = [
    "--seeds",
    "0",
    "--max-episode-steps",
    "4",
    "--image-scale",
    "0.1",
    "--eval-points",
    "1",
    "--eval-samples",
    "2000",
    "--checkpoint-samples",
    "2000",
    "--eval-samples-per-m2",
    "0",
    "--env-kwargs",
    '{"panorama_shape": [16, 32], "coverage_samples": 2000}',
    "--no-plots",
    "--no-progress",
]


def _suite_flags(selection: str, output_dir: Path) -> list[str]:
    """The flags of a test-split run of random, seed 0, on ``selection`` (flags as one
    string) into ``output_dir``."""
    return [
        *f"--suite test {selection} --policies random --seeds 0".split(),
        "--output-dir",
        str(output_dir),
    ]


def test_suite_flags_parse_and_default_to_the_class_budgets(tmp_path):
    args = parse_args(
        _suite_flags("--size-class small flat --variant closed --suite-limit 2", tmp_path)
    )
    assert args.suite == "test" and args.size_class == ["small", "flat"]
    assert args.suite_limit == 2 and args.max_episode_steps is None and args.eval_points is None
    specs = episode_specs(args, [])
    chosen = select_scenes("test", ["small", "flat"], "closed", 2)
    assert [spec.scene for spec in specs] == [entry.scene for entry in chosen]
    assert [spec.steps for spec in specs] == [entry.budget for entry in chosen]
    assert all(spec.eval_points == 9 for spec in specs)
    manifest = read_manifest(tmp_path)
    assert manifest["suite_version"] == suite.SUITE_VERSION
    assert {entry["size_class"] for entry in manifest["scenes"].values()} == {"small", "flat"}
    # a folder of another split or suite version is not mixed into
    with pytest.raises(ValueError, match="split"):
        episode_specs(
            parse_args(
                ["--suite", "train", "--size-class", "small", "--output-dir", str(tmp_path)]
            ),
            [],
        )
    manifest["suite_version"] = "0"
    (tmp_path / "suite.json").write_text(json.dumps(manifest))
    with pytest.raises(ValueError, match="suite version 0"):
        episode_specs(args, [])
    # --scenes runs keep their defaults
    plain = parse_args(["--scenes", "two_rooms", "--policies", "random", "--seeds", "0"])
    assert [spec.steps for spec in episode_specs(plain)] == [500]


def test_the_test_split_is_fixed_and_disjoint_from_training():
    for size_class in suite.SIZE_CLASSES:
        test = select_scenes("test", [size_class])
        assert len(test) >= 8
        assert not {entry.seed for entry in test} & set(suite.train_seeds(size_class))


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--suite", "validation"], "unknown suite split"),
        (["--suite", "test", "--size-class", "castle"], "unknown size class"),
        (["--suite", "test", "--variant", "roofless"], "unknown variant"),
        (["--suite", "test", "--suite-limit", "-1"], "limit"),
    ],
)
def test_bad_suite_flags_say_what_is_wrong(argv, message, tmp_path, capsys):
    assert main([*argv, "--policies", "random", "--output-dir", str(tmp_path)]) == 2
    assert message in capsys.readouterr().err


def test_the_earlier_class_name_is_refused_with_the_name_to_use(tmp_path, capsys):
    # "apartment" also names the procedural:apartment scenes: never taken as the flat class.
    with pytest.raises(SystemExit) as stopped:
        main(_suite_flags("--size-class small apartment", tmp_path))
    assert stopped.value.code == 2
    assert "size class 'apartment' was renamed: use --size-class flat" in capsys.readouterr().err
    assert not (tmp_path / "suite.json").exists()
    with pytest.raises(ValueError, match="renamed: use --size-class flat"):
        select_scenes("test", ["apartment"])


def _under_the_earlier_class_name(manifest: dict) -> dict:
    """``manifest`` as a run recorded before the size class ``apartment`` was ``flat``."""
    text = json.dumps(manifest).replace("--size-class flat", "--size-class apartment")
    earlier = json.loads(text)
    for entry in earlier["scenes"].values():
        if entry["size_class"] == "flat":
            entry["size_class"] = "apartment"
    return earlier


def test_archived_runs_under_the_earlier_class_name_read_as_flat(tmp_path):
    """A manifest recorded under the class name ``apartment`` (the leaderboard's, as such a
    run wrote it) reads as ``flat``, commands included, and a run into its folder joins it."""
    archived = _under_the_earlier_class_name(
        read_record(ROOT / "benchmarks/results/leaderboard/suite.json")
    )
    assert "apartment" in {entry["size_class"] for entry in archived["scenes"].values()}
    folder = tmp_path / "archive"
    folder.mkdir()
    (folder / "suite.json").write_text(json.dumps(archived))
    manifest = read_manifest(folder)
    assert {entry["size_class"] for entry in manifest["scenes"].values()} == {
        "small",
        "flat",
        "house",
        "external",
    }
    flat = {label for label, entry in manifest["scenes"].items() if entry["size_class"] == "flat"}
    assert flat == {
        label for label, entry in archived["scenes"].items() if entry["size_class"] == "apartment"
    }
    assert not any("apartment" in run["command"] for run in manifest["runs"])
    assert group_of({"scene": sorted(flat)[0]}, manifest) in {"flat", "flat (open)"}
    # a run into a folder of an archived run joins its class
    (tmp_path / "suite.json").write_text(json.dumps(archived))
    args = parse_args(_suite_flags("--size-class flat --suite-limit 1", tmp_path))
    episode_specs(args, [])
    merged = read_record(tmp_path / "suite.json")
    assert "apartment" not in {entry["size_class"] for entry in merged["scenes"].values()}
    assert len(merged["scenes"]) == len(archived["scenes"])


def _command(out_dir: Path) -> list[str]:
    return [
        "--suite",
        "test",
        "--size-class",
        "small",
        "--suite-limit",
        "2",
        "--policies",
        "random",
        "frontier",
        "--workers",
        "0",
        *TINY,
        "--output-dir",
        str(out_dir),
    ]


def test_a_tiny_suite_run_resumes_after_a_kill_and_makes_the_leaderboard(tmp_path):
    out_dir = tmp_path / "suite"
    process = subprocess.Popen(
        [sys.executable, "-m", "naruto_agent.benchmark.cli", *_command(out_dir)],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 600
    try:
        while not list((out_dir / "records").glob("*/*/*.json")):
            assert process.poll() is None, "the run ended before its first record"
            assert time.monotonic() < deadline, "no record after 10 minutes"
            time.sleep(0.2)
        process.send_signal(signal.SIGKILL)
    finally:
        process.wait(timeout=60)
    kept = {path: path.read_text() for path in (out_dir / "records").glob("*/*/*.json")}
    assert 1 <= len(kept) < 4
    assert main(_command(out_dir)) == 0
    records = load_records(out_dir)
    assert len(records) == 4 and all(r["status"] == "ok" for r in records)
    assert {path: path.read_text() for path in kept} == kept  # finished ones were not rerun
    statistics = json.loads((out_dir / "statistics.json").read_text())
    assert set(statistics["classes"]) == {"small"}
    assert set(statistics["classes"]["small"]) == {"random", "frontier"}
    assert statistics["classes"]["small"]["random"]["episodes"] == 2
    page = leaderboard_markdown(out_dir, tmp_path / "img")
    assert "## small" in page and "--suite test" in page
    assert "**Not in this run**: flat (8 test scenes of 800 steps), house" in page
    assert (tmp_path / "img" / "leaderboard_curves.png").is_file()


def test_a_suite_runs_on_ray_unchanged(tmp_path):
    ray = pytest.importorskip("ray")
    argv = [
        "--suite",
        "test",
        "--size-class",
        "small",
        "--suite-limit",
        "1",
        "--policies",
        "random",
        *TINY,
        "--output-dir",
        str(tmp_path / "ray"),
    ]
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    try:
        assert main([*argv, "--ray-address", "auto"]) == 0
    finally:
        ray.shutdown()
    assert main([*argv[:-1], str(tmp_path / "local"), "--workers", "0"]) == 0
    by_ray, local = load_records(tmp_path / "ray"), load_records(tmp_path / "local")
    assert [r["episode_id"] for r in by_ray] == [r["episode_id"] for r in local]
    assert by_ray[0]["trajectory"] == local[0]["trajectory"]
    assert read_manifest(tmp_path / "ray")["scenes"] == read_manifest(tmp_path / "local")["scenes"]
