"""How the harness's scores are made: the culled ground truth where a scene folder holds one,
the reference map fused at the leaderboard's camera whatever the policy sees, the notes on
settings that differ from the leaderboard's, and the release's reading of the table."""

from __future__ import annotations

import json

import numpy as np
import trimesh

from naruto_agent.benchmark import EpisodeSpec, load_records, run_episode, summarise
from naruto_agent.benchmark.checks import leaderboard_differences
from naruto_agent.benchmark.cli import main
from naruto_agent.benchmark.tables import markdown_table, protocol_lines, record_leaderboard
from naruto_gym.scenes import resolve_scene

# A short walk, few samples: what the tests compare is exact, not the size of the scores.
SHORT = {"eval_points": 0, "eval_samples": 3000, "checkpoint_samples": 2000}
CLI_SHORT = [
    "--policies", "random", "--seeds", "0", "--max-episode-steps", "3", "--workers", "0",
    "--eval-points", "0", "--eval-samples", "3000", "--no-plots", "--no-progress",
]  # fmt: skip


def _replica_like_folder(tmp_path):
    """A scene folder laid out as prepare_replica.py writes it: mesh.ply and mesh_culled.ply
    (the room without its ceiling)."""
    scene = resolve_scene("replica_like_room")
    folder = tmp_path / "replica_room"
    folder.mkdir()
    trimesh.Trimesh(scene.vertices, scene.faces, process=False).export(folder / "mesh.ply")
    top = scene.vertices[:, 2].max()
    keep = scene.vertices[scene.faces][:, :, 2].min(axis=1) < top - 0.05
    trimesh.Trimesh(scene.vertices, scene.faces[keep], process=False).export(
        folder / "mesh_culled.ply"
    )
    return folder / "mesh.ply"


def test_a_run_scores_against_the_culled_ground_truth_and_says_so(tmp_path, capsys):
    mesh = _replica_like_folder(tmp_path)
    culled_dir, full_dir = tmp_path / "culled", tmp_path / "full"
    assert main(["--scenes", str(mesh), *CLI_SHORT, "--output-dir", str(culled_dir)]) == 0
    assert "Ground truth: culled ground truth (mesh_culled.ply): replica_room." in (
        capsys.readouterr().out
    )
    args = ["--scenes", str(mesh), *CLI_SHORT, "--ground-truth", "full"]
    assert main([*args, "--output-dir", str(full_dir)]) == 0
    (culled,), (full,) = load_records(culled_dir), load_records(full_dir)
    assert culled["ground_truth"]["protocol"] == "culled ground truth"
    assert full["ground_truth"] == {
        "protocol": "full mesh", "path": None, "up_axis": None, "label": "full mesh"
    }  # fmt: skip
    assert culled["trajectory"] == full["trajectory"]
    # The same map, measured against less surface.
    assert culled["metrics"]["completion_ratio_pct"] != full["metrics"]["completion_ratio_pct"]
    assert culled["metrics"]["accuracy_cm"] != full["metrics"]["accuracy_cm"]
    assert "Ground truth: full mesh: replica_room." in (full_dir / "results.md").read_text()


def test_the_same_walk_scores_the_same_whatever_the_policys_camera():
    records = [
        run_episode(
            EpisodeSpec(
                scene="two_rooms", policy="random", seed=1, steps=5, image_scale=scale, **SHORT
            )  # fmt: skip
        )
        for scale in (0.1, 0.2, 0.25)
    ]
    assert records[0]["trajectory"] == records[1]["trajectory"] == records[2]["trajectory"]
    assert records[0]["camera"]["width"] == 120 and records[2]["camera"]["width"] == 300
    for record in records:
        assert record["reference_camera"]["width"] == 300
    keys = ("completion_ratio_pct", "observable_completion_ratio_pct", "accuracy_cm", "mad_cm")
    for key in keys:
        values = {record["metrics"][key] for record in records}
        assert len(values) == 1, (key, values)
    assert records[0]["metrics"]["completion_ratio_pct"] > 0.0


def test_settings_other_than_the_leaderboards_are_named_and_judged():
    spec = EpisodeSpec(scene="two_rooms", policy="random", seed=0, steps=5, image_scale=0.1)
    found = leaderboard_differences(spec.as_dict())
    assert found == {
        "differences": ["image_scale 0.1 (leaderboard: 0.25)"], "scores_comparable": True
    }  # fmt: skip
    assert leaderboard_differences(EpisodeSpec("two_rooms", "random", 0, 5).as_dict()) == {
        "differences": [], "scores_comparable": True
    }  # fmt: skip
    fewer = EpisodeSpec("two_rooms", "random", 0, 5, eval_samples=3000, reference_image_scale=0.1)
    found = leaderboard_differences(fewer.as_dict())
    assert not found["scores_comparable"] and len(found["differences"]) == 2
    # A record made before the reference camera existed fused its map from the policy's frames.
    old = {"config": spec.as_dict(), "episode_id": "two_rooms/random/seed0", "scene": "two_rooms"}
    assert record_leaderboard(old)["scores_comparable"] is False
    (line,) = [line for line in protocol_lines([old]) if line.startswith("Note")]
    assert "do not compare with the leaderboard" in line


def test_a_run_at_another_camera_prints_the_note(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["--scenes", "two_rooms", *CLI_SHORT, "--image-scale", "0.1",
                 "--output-dir", str(out)]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert "note: settings differ from the leaderboard's: image_scale 0.1 (leaderboard: 0.25)" in (
        printed
    )
    (record,) = load_records(out)
    assert "image_scale 0.1 (leaderboard: 0.25)" in record["leaderboard"]["differences"]
    assert "Note (1 episodes)" in (out / "results.md").read_text()


def test_the_table_gives_the_releases_reading_beside_ours(tmp_path):
    record = run_episode(EpisodeSpec("two_rooms", "random", 0, 4, **SHORT))
    rows = summarise([record])
    plain, both = markdown_table(rows), markdown_table(rows, release_reading=True)
    assert "Release comp. ratio (%)" not in plain
    header, _, values = both.splitlines()
    titles = [cell.strip() for cell in header.strip("|").split("|")]
    cells = [cell.strip() for cell in values.strip("|").split("|")]
    metrics = record["metrics"]
    read = {title: cells[titles.index(title)].split(" ± ")[0] for title in titles[5:]}
    read = {title: float(value) for title, value in read.items() if value != "-"}
    assert read["Release acc. (cm)"] == round(metrics["completion_cm"], 2)
    assert read["Release comp. (cm)"] == round(metrics["accuracy_cm"], 2)
    assert read["Release comp. ratio (%)"] == round(metrics["precision_pct"], 1)
    assert read["Comp. ratio (%)"] == round(metrics["completion_ratio_pct"], 1)
    assert not np.isclose(metrics["precision_pct"], metrics["completion_ratio_pct"])
    json.dumps(rows)  # the summary stays plain JSON
