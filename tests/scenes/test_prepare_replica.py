"""``scripts/prepare_replica.py`` on a small fixture of the Replica release's layout.

The test writes, in a temporary folder, what NICE-SLAM's release holds for two scenes (a box
room as the mesh, a few poses inside it, a few tiny RGB-D frames, a culled mesh for one of
them), prepares it, and reads the result the way the benchmarks do. The real data is never
used.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from PIL import Image

from naruto_agent.benchmark import build_specs, run_episode
from naruto_agent.cli_args import field_docs
from naruto_gym.scenes.catalogue import resolve_scene
from naruto_gym.scenes.mesh_scene import dataset_up_axis
from tests.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "prepare_replica.py"
CAMERA = {"w": 16, "h": 12, "fx": 8.0, "fy": 8.0, "cx": 7.5, "cy": 5.5, "scale": 6553.5}
ROOM = np.array([4.0, 5.0, 3.0])  # the box room's extents (m), from the origin


def _load_script():
    return load_script(SCRIPT, "prepare_replica")


prepare_replica = _load_script()


def _poses(count: int) -> np.ndarray:
    """Camera-to-world poses 5 cm apart along the room's middle (within the env's step
    limit), looking along +x (OpenCV axes)."""
    poses = np.tile(np.eye(4), (count, 1, 1))
    poses[:, :3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    poses[:, :3, 3] = np.column_stack([1.0 + 0.05 * np.arange(count), np.full(count, 2.5),
                                       np.full(count, 1.5)])
    return poses


def write_release(root: Path, scenes=("office0", "room0"), poses: int = 4) -> Path:
    """NICE-SLAM's Replica layout under ``root/Replica``; ``root/cull_replica_mesh`` holds
    office0's culled mesh."""
    source = root / "Replica"
    source.mkdir(parents=True)
    (source / "cam_params.json").write_text(json.dumps({"camera": CAMERA}))
    box = trimesh.creation.box(extents=ROOM)
    box.apply_translation(ROOM / 2)
    box.invert()  # a closed room: its normals face the free space inside
    (root / "cull_replica_mesh").mkdir()
    box.export(root / "cull_replica_mesh" / "office0.ply")
    for name in scenes:
        box.export(source / f"{name}_mesh.ply")
        (source / name / "results").mkdir(parents=True)
        np.savetxt(source / name / "traj.txt", _poses(poses).reshape(poses, 16))
        for index in range(poses):
            Image.new("RGB", (CAMERA["w"], CAMERA["h"]), (90, 120, 150)).save(
                source / name / "results" / f"frame{index:06d}.jpg")
            Image.fromarray(np.full((CAMERA["h"], CAMERA["w"]), 13107, np.uint16)).save(
                source / name / "results" / f"depth{index:06d}.png")
    return source


def run_prepare(source: Path, out: Path, *flags: str) -> int:
    return prepare_replica.main(["--source", str(source), "--output-dir", str(out),
                                 "--scenes", "office0", "room0", *flags])


def test_prepares_the_layout_the_benchmarks_read(tmp_path, capsys):
    source = write_release(tmp_path)
    out = tmp_path / "prepared"
    assert run_prepare(source, out) == 0
    printed = capsys.readouterr().out
    assert "| office0 |" in printed and "| room0 |" in printed

    office = out / "replica_office0"
    assert {p.name for p in office.iterdir()} == {
        "mesh.ply", "traj.txt", "cam_params.json", "frames", "mesh_culled.ply"}
    assert not (out / "replica_room0" / "mesh_culled.ply").exists()  # none in the release
    assert (office / "mesh.ply").is_symlink()
    assert len(list((office / "frames").glob("depth*.png"))) == 4
    assert json.loads((office / "cam_params.json").read_text())["camera"] == CAMERA
    np.testing.assert_allclose(np.loadtxt(office / "traj.txt").reshape(-1, 4, 4), _poses(4))

    report = json.loads((out / "replica_scenes.json").read_text())
    assert report["scenes"]["office0"]["poses"] == 4
    assert report["scenes"]["office0"]["trajectory_length_m"] == pytest.approx(0.15)
    assert report["scenes"]["office0"]["triangles"] == 12
    assert report["scenes"]["office0"]["culled_mesh"] is True
    assert report["scenes"]["room0"]["frames"] == 4

    # up_axis="auto" knows the prepared folder and the release's own mesh names (z-up).
    assert dataset_up_axis(office / "mesh.ply") == "z"
    assert dataset_up_axis(source / "room0_mesh.ply") == "z"
    scene = resolve_scene(str(office / "mesh.ply"), "auto")
    np.testing.assert_allclose(scene.extents, ROOM)

    # The harness: the label is the folder's name, and the passive policy replays traj.txt.
    specs = build_specs([str(office / "mesh.ply")], ["passive"], [0], 3)
    assert specs[0].scene_label == "replica_office0"
    assert specs[0].policy_kwargs["trajectory"] == str((office / "traj.txt").resolve())


def test_copies_instead_of_linking(tmp_path):
    source = write_release(tmp_path)
    assert run_prepare(source, tmp_path / "out", "--copy", "--no-check-frames") == 0
    mesh = tmp_path / "out" / "replica_office0" / "mesh.ply"
    assert mesh.is_file() and not mesh.is_symlink()
    # A second run replaces what the first wrote.
    assert run_prepare(source, tmp_path / "out") == 0
    assert mesh.is_symlink()


def _break_trajectory(source: Path) -> None:
    path = source / "office0" / "traj.txt"
    lines = path.read_text().splitlines()
    lines[2] = " ".join(lines[2].split()[:15])
    path.write_text("\n".join(lines) + "\n")


def _skew_trajectory(source: Path) -> None:
    poses = _poses(4)
    poses[1, :3, :3] *= 2.0
    np.savetxt(source / "office0" / "traj.txt", poses.reshape(4, 16))


def _move_trajectory(source: Path) -> None:
    poses = _poses(4)
    poses[:, 2, 3] += 20.0  # above the room: a mesh of another scene, or a y-up one
    np.savetxt(source / "office0" / "traj.txt", poses.reshape(4, 16))


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda s: (s / "cam_params.json").unlink(), "cam_params.json is missing"),
        (lambda s: (s / "cam_params.json").write_text("{}"), "is not a cam_params.json"),
        (lambda s: (s / "cam_params.json").write_text('{"camera": {"w": 16}}'),
         "camera entries ['h', 'fx', 'fy', 'cx', 'cy', 'scale'] are missing"),
        (lambda s: (s / "office0" / "traj.txt").unlink(), "office0/traj.txt is missing"),
        (_break_trajectory, "office0/traj.txt line 3: expected 16 finite numbers"),
        (_skew_trajectory, "office0/traj.txt line 2: not a rigid camera-to-world transform"),
        (_move_trajectory, "0 % of the camera positions of traj.txt lie inside the mesh"),
        (lambda s: (s / "office0_mesh.ply").unlink(), "office0_mesh.ply is missing"),
        (lambda s: (s / "office0_mesh.ply").write_text("not a mesh"), "office0_mesh.ply is not"),
        (lambda s: (s / "office0" / "results" / "depth000003.png").unlink(),
         "4 frame*.jpg and 3 depth*.png for 4 poses"),
        (lambda s: Image.new("RGB", (8, 6)).save(s / "office0" / "results" / "frame000000.jpg"),
         "frame000000.jpg is 6 x 8 (H x W); cam_params.json says 12 x 16"),
        (lambda s: (s / "room0" / "traj.txt").rename(s / "room0" / "poses.txt"),
         "room0: "),
    ],
)
def test_a_missing_or_malformed_file_is_named_and_nothing_is_written(
    tmp_path, capsys, damage, message
):
    source = write_release(tmp_path)
    damage(source)
    assert run_prepare(source, tmp_path / "out") == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert not (tmp_path / "out").exists()


def test_missing_scene_folders_and_unknown_names(tmp_path, capsys):
    source = write_release(tmp_path, scenes=("office0",))
    assert run_prepare(source, tmp_path / "out") == 2
    assert f"scenes found in {source}: ['office0']" in capsys.readouterr().err
    assert prepare_replica.main(["--source", str(source), "--scenes", "office9"]) == 2
    assert "unknown scenes ['office9']" in capsys.readouterr().err
    assert prepare_replica.main([]) == 2
    assert "pass --source" in capsys.readouterr().err


def test_help_describes_every_option():
    result = subprocess.run([sys.executable, str(SCRIPT), "--help"], capture_output=True,
                            text=True, timeout=120, cwd=ROOT,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 0, result.stderr
    assert "Reads the Replica release as NICE-SLAM prepared it" in result.stdout
    documented = field_docs(prepare_replica.Args)
    assert set(documented) == set(prepare_replica.Args.__dataclass_fields__)


def test_the_prepared_scene_runs_in_the_harness(tmp_path):
    source = write_release(tmp_path, scenes=("office0", "room0"), poses=4)
    assert run_prepare(source, tmp_path / "out") == 0
    mesh = tmp_path / "out" / "replica_office0" / "mesh.ply"
    spec = build_specs([str(mesh)], ["passive"], [0], 3, image_scale=0.02, reconstruct=False,
                       env_kwargs={"panorama_shape": [8, 16], "coverage_samples": 500})[0]
    record = run_episode(spec)
    assert record["status"] == "ok" and record["steps_run"] == 3
    positions = np.array(record["trajectory"])
    np.testing.assert_allclose(positions, _poses(4)[:, :3, 3], atol=1e-3)  # traj.txt replayed


def test_replica_passive_replays_a_prepared_scene(tmp_path, capsys):
    source = write_release(tmp_path, scenes=("office0", "room0"), poses=4)
    assert run_prepare(source, tmp_path / "out") == 0
    module = load_script(ROOT / "benchmarks" / "replica_passive.py", "replica_passive")
    report = module.main(["--scene-dir", str(tmp_path / "out" / "replica_room0"),
                          "--num-samples", "2000", "--output-file", str(tmp_path / "room0.json")])
    assert report["scene"] == "replica_room0" and report["frames"] == 4
    assert report["image"] == "12 x 16"  # the scene's own camera (cam_params.json)
    assert report["poses_not_reached"] == 0
    assert report["published_passive_coslam"] is None  # published for office0 only
    assert json.loads((tmp_path / "room0.json").read_text())["scene"] == "replica_room0"
    assert "| Replica replica_room0, traj.txt (4 frames)" in capsys.readouterr().out
