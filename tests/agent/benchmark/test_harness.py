"""Benchmark harness: specs, atomic records, resuming, failures, reports, Ray backend."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from naruto_agent.benchmark import (
    EpisodeSpec,
    build_specs,
    load_records,
    markdown_table,
    parse_scene,
    pending_specs,
    run_episode,
    run_local,
    run_ray,
    summarise,
    write_json_atomic,
)
from naruto_agent.benchmark.cli import parse_args, write_reports
from naruto_agent.benchmark.plots import plot_curves
from naruto_agent.episode_loop import eval_point_steps
from naruto_gym.utils.threads import available_cpus

# Tiny episodes: a small camera, few coverage samples, few evaluation samples.
TINY = {
    "image_scale": 0.1,
    "eval_points": 1,
    "eval_samples": 4000,
    "checkpoint_samples": 2000,
    "env_kwargs": {"panorama_shape": [16, 32], "coverage_samples": 2000},
}


def tiny_specs(steps: int = 6) -> list[EpisodeSpec]:
    good = build_specs(["two_rooms"], ["random", "frontier"], [0], steps, **TINY)
    broken = build_specs(["no_such_dir/missing.ply"], ["random"], [0], steps, **TINY)
    return good + broken


# -- specs -------------------------------------------------------------------------------
def test_parse_scene_and_labels():
    assert parse_scene("apartment").label == "apartment"
    spec = parse_scene("../shared/scenes/scenenet_room89/mesh.obj@y")
    assert spec.up_axis == "y" and spec.label == "scenenet_room89"
    with pytest.raises(ValueError, match="up axis"):
        parse_scene("room.obj@w")


def test_build_specs_is_scene_major_with_distinct_ids_and_stable_hashes():
    specs = build_specs(["two_rooms", "apartment"], ["random", "frontier"], [0, 1, 2], 50)
    assert len(specs) == 12
    assert len({spec.episode_id for spec in specs}) == 12
    assert specs[0].episode_id == "two_rooms/random/seed0"
    again = build_specs(["two_rooms"], ["random"], [0], 50)[0]
    assert again.config_hash == specs[0].config_hash
    assert build_specs(["two_rooms"], ["random"], [0], 51)[0].config_hash != again.config_hash
    with pytest.raises(ValueError, match="distinct"):
        build_specs(["two_rooms"], ["random"], [1, 1], 50)


def test_passive_gets_the_trajectory_beside_a_mesh(replica_dir):
    spec = build_specs([str(replica_dir / "mesh.ply")], ["passive", "random"], [0], 10)
    assert spec[0].policy_kwargs["trajectory"].endswith("traj.txt")
    assert spec[1].policy_kwargs == {}
    assert spec[0].scene_label == "replica_office0"


def test_eval_point_steps():
    assert eval_point_steps(100, 3) == [25, 50, 75]
    assert eval_point_steps(100, 0) == []
    assert eval_point_steps(1, 4) == []


# -- records -----------------------------------------------------------------------------
def test_atomic_write_keeps_the_old_record_when_writing_fails(tmp_path):
    path = tmp_path / "a" / "seed0.json"
    write_json_atomic(path, {"value": np.float32(1.5), "bad": float("nan"), "arr": np.arange(3)})
    assert json.loads(path.read_text()) == {"value": 1.5, "bad": None, "arr": [0, 1, 2]}
    with pytest.raises(TypeError):
        write_json_atomic(path, {"value": object()})
    assert json.loads(path.read_text())["value"] == 1.5  # untouched
    assert [p.name for p in path.parent.iterdir()] == ["seed0.json"]  # no temporary left


# -- tables and plots ----------------------------------------------------------------------
def _fake_record(policy: str, seed: int, coverage: float, status: str = "ok") -> dict:
    return {
        "episode_id": f"room/{policy}/seed{seed}",
        "status": status,
        "scene": "room",
        "policy": policy,
        "seed": seed,
        "steps_run": 4,
        "coverage_final": coverage,
        "coverage_curve": list(np.linspace(0.0, coverage, 5)),
        "completion_curve": [
            {"step": 2, "completion_ratio_pct": 10.0 * coverage},
            {"step": 4, "completion_ratio_pct": 20.0 * coverage},
        ],
        "metrics": {"completion_ratio_pct": 50.0 + seed, "accuracy_cm": 1.0, "mad_cm": 2.0 + seed},
        "path_length_m": 1.0,
        "collisions": seed,
        "stalled_steps": 10 * seed,
        "time_per_step_ms": {"policy": 1.0, "env": 2.0, "mapping": 3.0},
    }


def test_summary_table_and_curve_plot(tmp_path):
    records = [_fake_record("a", seed, 0.2 + 0.1 * seed) for seed in range(3)]
    records.append(_fake_record("b", 0, 0.5))
    records.append({**_fake_record("b", 1, 0.0), "status": "failed", "error": "boom"})
    rows = summarise(records)
    row_a = next(row for row in rows if row["policy"] == "a")
    assert row_a["coverage_pct"]["mean"] == pytest.approx(30.0)
    assert row_a["coverage_pct"]["std"] == pytest.approx(10.0)  # sample std over seeds
    row_b = next(row for row in rows if row["policy"] == "b")
    assert row_b["failed"] == 1 and row_b["seeds"] == [0]
    table = markdown_table(rows)
    assert "30.0 ± 10.0" in table and "MAD (cm)" in table and "3.00 ± 1.00" in table
    header, _, line_a, line_b = table.strip().split("\n")
    failed_column = header.split(" | ").index("Failed")
    stalled_column = header.split(" | ").index("Stalled steps")
    assert line_a.split(" | ")[stalled_column] == "10.0 ± 10.0"
    assert line_a.split(" | ")[failed_column] == "0" and line_b.split(" | ")[failed_column] == "1"
    path = plot_curves(records, tmp_path / "curves.png")
    assert path is not None and path.stat().st_size > 1000


def test_cli_arguments_come_from_the_dataclass():
    args = parse_args(
        ["--scenes", "a", "b", "--seeds", "3", "4", "--max-episode-steps", "7", "--no-plots"]
    )
    assert args.scenes == ["a", "b"] and args.seeds == [3, 4] and args.max_episode_steps == 7
    assert args.plots is False and args.ray_address is None and args.image_scale == 0.25


# -- running -------------------------------------------------------------------------------
def _states(out_dir: Path) -> dict[str, tuple[str, float]]:
    return {
        record["episode_id"]: (record["status"], record.get("wall_time_s", 0.0))
        for record in load_records(out_dir)
    }


@pytest.mark.slow
def test_local_run_records_failures_resumes_and_reports(tmp_path):
    specs = tiny_specs()
    failed = run_local(specs, tmp_path, workers=2, progress=False)
    assert failed == 1
    records = {record["episode_id"]: record for record in load_records(tmp_path)}
    assert set(records) == {spec.episode_id for spec in specs}
    broken = records["missing/random/seed0"]
    assert broken["status"] == "failed" and "missing.ply" in broken["error"]
    assert "Traceback" in broken["traceback"]
    good = records["two_rooms/frontier/seed0"]
    assert good["status"] == "ok" and good["steps_run"] == 6
    assert len(good["coverage_curve"]) == 7 and len(good["trajectory"]) == 7
    assert good["metrics"]["completion_ratio_pct"] is not None
    assert [point["step"] for point in good["completion_curve"]] == [3, 6]
    assert set(good["time_per_step_ms"]) == {"policy", "env", "mapping"}
    assert good["own_map_metrics"] is None  # frontier builds no map of surfaces
    assert good["stalled_steps"] >= 0 and isinstance(good["stall_recoveries"], list)

    # A rerun only retries the failed episode; finished records stay untouched.
    paths = {spec.episode_id: spec.record_path(tmp_path) for spec in specs}
    stamps = {key: os.stat(path).st_mtime_ns for key, path in paths.items()}
    todo = pending_specs(specs, tmp_path)
    assert [spec.episode_id for spec in todo] == ["missing/random/seed0"]
    run_local(todo, tmp_path, workers=0, progress=False)
    kept = "two_rooms/frontier/seed0"
    assert os.stat(paths[kept]).st_mtime_ns == stamps[kept]

    summary = write_reports(tmp_path, plots=True)
    assert summary["episodes"] == 3
    table = (tmp_path / "results.md").read_text()
    assert "two_rooms" in table and "frontier" in table
    assert (tmp_path / "curves.png").stat().st_size > 1000
    assert (tmp_path / "trajectories_two_rooms.png").stat().st_size > 1000


def test_a_policy_with_its_own_map_is_scored_on_it_too():
    spec = build_specs(["two_rooms"], ["naruto"], [0], 30, **TINY)[0]
    record = run_episode(spec)
    own, reference = record["own_map_metrics"], record["metrics"]
    assert own["completion_ratio_pct"] > 0 and own["mad_cm"] > 0
    assert own["num_gt_samples"] == reference["num_gt_samples"] == TINY["eval_samples"]
    assert own["mad_cm"] != reference["mad_cm"]  # its own SDF, not the reference map's
    table = markdown_table(summarise([record]))
    assert "Own map MAD (cm)" in table and f"{own['mad_cm']:.2f} ± 0.00" in table


@pytest.mark.slow
def test_ray_backend_gives_the_same_records(tmp_path):
    ray = pytest.importorskip("ray")
    specs = tiny_specs(steps=4)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        failed = run_ray(specs, tmp_path / "ray", progress=False)
    finally:
        ray.shutdown()
    assert failed == 1
    run_local(specs, tmp_path / "local", workers=0, progress=False)
    by_ray = {r["episode_id"]: r for r in load_records(tmp_path / "ray")}
    local = {r["episode_id"]: r for r in load_records(tmp_path / "local")}
    assert set(by_ray) == set(local)
    for key, record in local.items():
        assert by_ray[key]["status"] == record["status"]
        if record["status"] == "ok":
            assert by_ray[key]["coverage_curve"] == record["coverage_curve"]
            assert by_ray[key]["trajectory"] == record["trajectory"]
            assert by_ray[key]["config_hash"] == record["config_hash"]


def test_sample_density_is_a_setting_of_the_record():
    """Records scored at another sample density are out of date (their figures differ)."""
    dense = EpisodeSpec(scene="replica_like_room", policy="random", seed=0, steps=5)
    published = EpisodeSpec(scene="replica_like_room", policy="random", seed=0, steps=5,
                            eval_samples_per_m2=0.0)
    assert dense.eval_samples_per_m2 == 2000.0
    assert dense.config_hash != published.config_hash
    with pytest.raises(ValueError, match="eval_samples_per_m2"):
        EpisodeSpec(scene="replica_like_room", policy="random", seed=0, steps=5,
                    eval_samples_per_m2=-1.0)


def _report_worker_threads(spec: dict) -> dict:
    """An episode function for :func:`run_local` that records its worker's thread setting."""
    return {"status": "ok", "omp_num_threads": os.environ.get("OMP_NUM_THREADS")}


@pytest.mark.parametrize("preset", [None, "3"])
def test_local_workers_share_the_cpus_unless_the_user_set_threads(tmp_path, monkeypatch, preset):
    """N workers each starting a thread pool of every CPU contend for the cores (some torch
    operations then run a hundred times slower); each gets its share, or what the user set."""
    if preset is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", preset)
    specs = [EpisodeSpec(scene="replica_like_room", policy="random", seed=seed, steps=1)
             for seed in range(2)]
    assert run_local(specs, tmp_path, workers=2, progress=False,
                     episode_fn=_report_worker_threads) == 0
    seen = {json.loads(spec.record_path(tmp_path).read_text())["omp_num_threads"]
            for spec in specs}
    assert seen == {preset or str(max(1, available_cpus() // 2))}
