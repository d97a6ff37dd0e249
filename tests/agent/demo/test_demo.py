"""The main command: a short NARUTO run writes every output, and each reads back correctly."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import trimesh
from PIL import Image

from naruto_agent.demo import main, parse_args, run_demo
from naruto_agent.demo.map_picture import UNMAPPED_RGB
from naruto_agent.demo.outputs import CURVE_COLUMNS
from naruto_agent.demo.viewer import TRACE_NAMES, plotly_available, read_figure, read_viewer
from naruto_agent.recording import rerun_available
from naruto_gym.scenes.catalogue import resolve_scene

STEPS = 12
# Tiny frames and cheap scoring: the point is every output, not the numbers.
FAST = [
    "--image-scale",
    "0.1",
    "--checkpoint-samples",
    "5000",
    "--eval-samples",
    "20000",
    "--no-progress",
]


@pytest.fixture(scope="module")
def naruto_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    returned = main(
        [
            "--max-episode-steps",
            str(STEPS),
            "--output-dir",
            str(out),
            "--gif-frames",
            "6",
            "--gif-width",
            "160",
            "--eval-points",
            "1",
            "--map-snapshots",
            "3",
            *FAST,
        ]
    )
    assert returned is None  # a console script exits with status 0
    return out, json.loads((out / "metrics.json").read_text())


def test_metrics_json_holds_the_scores(naruto_run):
    _, written = naruto_run
    assert written["policy"] == "naruto" and written["steps"] == STEPS
    assert "own map" in written["map"]
    for key in (
        "accuracy_cm",
        "completion_cm",
        "completion_ratio_pct",
        "observable_completion_ratio_pct",
        "coverage_pct",
        "path_length_m",
    ):
        assert isinstance(written[key], float) and written[key] >= 0, key
    assert 0 < written["completion_ratio_pct"] <= written["observable_completion_ratio_pct"] <= 100
    assert written["collisions"] == sum(written["collision_reasons"].values())
    assert written["time_per_step_ms"]["total"] > 0
    assert written["image_size"] == [68, 120]  # H x W, as the docs write frame sizes
    assert set(written["outputs"]) == {
        "reconstruction.ply",
        "metrics.json",
        "curves.csv",
        "curves.png",
        "trajectory.png",
        "episode.gif",
        *(["viewer.html"] if plotly_available() else []),
        *(["episode.rrd"] if rerun_available() else []),
    }


def test_printed_summary_names_the_scores(naruto_run, capsys):
    out, metrics = naruto_run
    from naruto_agent.demo.outputs import summary_text

    text = summary_text(metrics, out)
    for words in (
        "accuracy",
        "completion ratio",
        "observable completion ratio",
        "coverage",
        "path length",
        "collisions",
        "time per step",
    ):
        assert words in text
    assert f"{metrics['completion_ratio_pct']:.2f} %" in text
    # The observable figures come first, together; the whole-surface ones are labelled so
    # and say what they count; no line mixes the two surfaces.
    lines = text.splitlines()
    assert lines[1].startswith(
        f"  observable completion ratio {metrics['observable_completion_ratio_pct']:.2f} % "
        f"| observable completion {metrics['observable_completion_cm']:.2f} cm"
    )
    assert "whole-surface" not in lines[1]
    assert lines[2].startswith(
        f"  whole-surface completion ratio {metrics['completion_ratio_pct']:.2f} % "
        f"| whole-surface completion {metrics['completion_cm']:.2f} cm"
    )
    assert "outer faces of walls" in lines[2] and "observable" not in lines[2]
    assert f"accuracy {metrics['accuracy_cm']:.2f} cm" in lines[3]
    assert text.index("observable completion ratio") < text.index("whole-surface")
    assert "68 x 120 (H x W) frames" in text  # height first, as the docs write "170 x 300"


def test_ply_is_the_scored_mesh_inside_the_scene(naruto_run):
    out, metrics = naruto_run
    mesh = trimesh.load(out / "reconstruction.ply", process=False)
    assert len(mesh.faces) == metrics["mesh_faces"] > 0
    bounds = resolve_scene("replica_like_room").bounds
    assert np.all(mesh.bounds[0] >= bounds[0] - 0.1) and np.all(mesh.bounds[1] <= bounds[1] + 0.1)
    assert mesh.visual.kind == "vertex"  # the map keeps the frames' colours


def test_curves_csv_has_a_row_per_step_and_scores_at_checkpoints(naruto_run):
    out, metrics = naruto_run
    with open(out / "curves.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == CURVE_COLUMNS
    assert [int(row["step"]) for row in rows] == list(range(STEPS + 1))
    coverage = [float(row["coverage_pct"]) for row in rows]
    assert coverage == sorted(coverage)  # coverage never drops
    assert coverage[-1] == pytest.approx(metrics["coverage_pct"], abs=1e-3)
    scored = [int(row["step"]) for row in rows if row["completion_ratio_pct"]]
    assert scored == [STEPS // 2, STEPS]  # one checkpoint, then the last step
    assert 0 < float(rows[-1]["completion_ratio_pct"]) <= 100
    assert Image.open(out / "curves.png").size[0] > 0


def test_gif_holds_the_subsampled_frames(naruto_run):
    out, _ = naruto_run
    with Image.open(out / "episode.gif") as gif:
        assert gif.n_frames == STEPS // 2 + 1  # steps 0, 2, ..., 12
        assert gif.size[0] == 160
        gif.seek(gif.n_frames - 1)
        last = np.asarray(gif.convert("RGB"))
    assert last.std() > 0  # a picture, not a blank frame
    # The agent's map from above is the right-hand panel: part mapped, part not yet.
    right = last[:, -last.shape[1] // 5 :].reshape(-1, 3).astype(int)
    unmapped = np.all(np.abs(right - UNMAPPED_RGB) <= 12, axis=1)
    assert 0.05 < unmapped.mean() < 0.95


def test_trajectory_picture_is_written(naruto_run):
    out, _ = naruto_run
    with Image.open(out / "trajectory.png") as picture:
        assert picture.size[0] > 300 and picture.size[1] > 300


def test_viewer_page_holds_the_episode(naruto_run):
    pytest.importorskip("plotly", reason="the viewer extra (plotly) is not installed")
    out, metrics = naruto_run
    text = (out / "viewer.html").read_text()
    assert "<script src=" not in text  # self-contained: nothing fetched when it opens
    traces = read_viewer(out / "viewer.html")
    assert tuple(traces) == TRACE_NAMES
    recon = traces["reconstruction"]
    vertices = np.stack([recon["x"], recon["y"], recon["z"]], axis=1)
    faces = np.stack([recon["i"], recon["j"], recon["k"]], axis=1)
    assert 0 < len(faces) <= min(metrics["mesh_faces"], 120_000)
    assert faces.min() >= 0 and faces.max() < len(vertices)
    trajectory = traces["trajectory"]
    positions = np.stack([trajectory["x"], trajectory["y"], trajectory["z"]], axis=1)
    assert len(positions) == STEPS + 1
    path = np.linalg.norm(np.diff(positions, axis=0), axis=1).sum()
    assert path == pytest.approx(metrics["path_length_m"], abs=2e-3)
    # The outline's walls span the ground truth's bounding box.
    outline = traces["ground truth outline"]
    bounds = resolve_scene("replica_like_room").bounds
    assert np.nanmin(outline["x"]) == pytest.approx(bounds[0, 0], abs=6e-3)  # cm in the page
    assert np.nanmax(outline["z"]) == pytest.approx(bounds[1, 2], abs=6e-3)
    # Every frustum is 8 segments of 3 entries (start, end, break); first apex = start pose.
    frustums = traces["camera frustums"]
    assert len(frustums["x"]) % 24 == 0 and len(frustums["x"]) > 0
    assert np.allclose([frustums[a][0] for a in "xyz"], positions[0], atol=6e-3)
    # The first view looks from inside the scene's box; a slider runs over the steps.
    layout = read_figure(out / "viewer.html")["layout"]
    eye, ratio = layout["scene"]["camera"]["eye"], layout["scene"]["aspectratio"]
    assert all(abs(eye[axis]) < 0.5 * ratio[axis] for axis in "xyz")
    labels = [step["label"] for step in layout["sliders"][0]["steps"]]
    assert labels == [str(step) for step in range(STEPS + 1)]


def test_recording_replays_the_episode_with_the_map_growing(naruto_run):
    pytest.importorskip("rerun", reason="the viewer extra (rerun-sdk) is not installed")
    from naruto_agent.recording import read_recording

    out, metrics = naruto_run
    contents = read_recording(out / "episode.rrd")
    every_step = list(range(STEPS + 1))
    for entity in ("world/camera", "world/camera/rgb", "metrics/coverage (%)"):
        assert contents.steps[entity] == every_step, entity
    # A policy layer is logged at the start and again whenever it changed.
    for entity in ("world/policy/frontier", "world/policy/goals chosen"):
        assert contents.steps[entity][0] == 0 and set(contents.steps[entity]) <= set(every_step)
    assert contents.steps["world/map"][0] == 0 and contents.steps["world/map"][-1] == STEPS
    assert len(contents.steps["world/map"]) > 2
    assert contents.steps["metrics/completion ratio (%)"][-1] == STEPS
    assert "world/policy/uncertain surfaces" in contents.steps
    assert contents.steps["world/ground_truth"] == []
    # The last map is the scored mesh, simplified.
    assert 0 < len(contents.map_faces) <= min(metrics["mesh_faces"], 30_000)
    bounds = resolve_scene("replica_like_room").bounds
    assert np.all(contents.map_vertices >= bounds[0] - 0.1)
    assert np.all(contents.map_vertices <= bounds[1] + 0.1)


def test_frontier_policy_runs_and_is_scored_on_the_reference_map(tmp_path):
    metrics = run_demo(
        parse_args(
            [
                "--policy",
                "frontier",
                "--max-episode-steps",
                "8",
                "--output-dir",
                str(tmp_path),
                "--gif-frames",
                "0",
                "--eval-points",
                "0",
                "--no-viewer",
                *FAST,
            ]
        )
    )
    assert metrics["policy"] == "frontier" and metrics["steps"] == 8
    assert "reference TSDF" in metrics["map"]
    assert metrics["completion_ratio_pct"] > 0
    assert not (tmp_path / "episode.gif").exists() and not (tmp_path / "viewer.html").exists()
    rows = (tmp_path / "curves.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 9


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--policy", "nope"], "unknown policy 'nope'"),
        (["--policy", "json:dumps"], "is not a naruto_agent.policies.Policy subclass"),
        (["--scene", "no_such_room"], "unknown scene 'no_such_room'"),
        (["--max-episode-steps", "0"], "--max-episode-steps must be at least 1"),
        (["--steps", "10"], "--steps was renamed: use --max-episode-steps"),
        (["--out", "somewhere"], "--out was renamed: use --output-dir"),
        (["--checkpoints", "2"], "--checkpoints was renamed: use --eval-points"),
        (["--policy", "random", "--policy-kwargs", "[1]"], "must be a JSON object"),
    ],
)
def test_bad_input_ends_with_a_clear_error(flags, message, tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main([*flags, "--output-dir", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # nothing written
