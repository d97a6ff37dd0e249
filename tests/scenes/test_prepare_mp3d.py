"""``scripts/prepare_mp3d.py`` on a small fixture standing in for the MP3D layout.

The test writes, in a temporary folder, what the habitat task and the scans hold for one or
two scenes: a generated two-room house stored y-up as ``<scene>.glb`` and as the scan's
``mesh.obj``. It prepares them, checks that every problem is listed before anything is
written, and runs a short benchmark episode on the prepared folder, scored against the
``.obj``. The real data is never used.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from naruto_agent.benchmark import build_specs, run_episode
from naruto_gym.evaluation import find_ground_truth
from naruto_gym.scenes.catalogue import resolve_scene
from tests.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
prepare_mp3d = load_script(ROOT / "scripts" / "prepare_mp3d.py", "prepare_mp3d")
SCENES = ("GdvgFV5R1Z5", "gZ6f7yhEvPG")


def y_up_house() -> trimesh.Trimesh:
    """The catalogue's two-room house, stored y-up as MP3D's files are: (x, y, z) z-up is
    (x, z, -y) y-up."""
    scene = resolve_scene("two_rooms")
    return trimesh.Trimesh(scene.vertices[:, [0, 2, 1]] * [1.0, 1.0, -1.0], scene.faces,
                           process=False)  # fmt: skip


def write_layout(root: Path, scenes=SCENES, scan_folder: str = "") -> tuple[Path, Path]:
    """``root/mp3d/<scene>/<scene>.glb`` and ``root/scans/<scene>/mesh.obj`` (or the .obj
    under ``matterport_mesh/`` with ``scan_folder``)."""
    house = y_up_house()
    for name in scenes:
        (root / "mp3d" / name).mkdir(parents=True)
        house.export(root / "mp3d" / name / f"{name}.glb")
        folder = root / "scans" / name / scan_folder
        folder.mkdir(parents=True)
        house.export(folder / ("house_mesh.obj" if scan_folder else "mesh.obj"))
    return root / "mp3d", root / "scans"


def _args(habitat: Path, scans: Path, out: Path, **changes) -> object:
    settings = {"scenes": list(SCENES), **changes}
    return prepare_mp3d.Args(habitat_dir=str(habitat), scans_dir=str(scans),
                             output_dir=str(out), **settings)  # fmt: skip


def test_prepared_scenes_are_scored_against_the_house_mesh(tmp_path):
    habitat, scans = write_layout(tmp_path / "data", scan_folder="matterport_mesh/abc")
    out = tmp_path / "prepared"
    report = prepare_mp3d.prepare(_args(habitat, scans, out))
    assert set(report["scenes"]) == set(SCENES) and report["steps"] == 5000
    folder = out / f"mp3d_{SCENES[0]}"
    assert (folder / "mesh.glb").resolve() == (habitat / SCENES[0] / f"{SCENES[0]}.glb").resolve()
    assert json.loads((folder / "ground_truth.json").read_text()) == {
        "mesh": "house.obj", "up_axis": "y"
    }  # fmt: skip
    truth = find_ground_truth(folder / "mesh.glb", "y")
    assert truth.label == "full mesh (house.obj)"
    assert json.loads((out / "mp3d_scenes.json").read_text())["scenes"][SCENES[1]]["folder"]
    # A short episode on the prepared folder: the .glb is the scene, the .obj the ground truth.
    (spec,) = build_specs([f"{folder / 'mesh.glb'}@y"], ["random"], [0], 3, image_scale=0.1,
                          eval_points=0, eval_samples=2000)  # fmt: skip
    record = run_episode(spec)
    assert record["scene"] == f"mp3d_{SCENES[0]}"
    assert record["ground_truth"]["label"] == "full mesh (house.obj)"
    assert record["metrics"]["completion_ratio_pct"] > 0.0
    assert record["metrics"]["mad_cm"] is not None


def test_every_problem_is_listed_and_nothing_is_written(tmp_path):
    habitat, scans = write_layout(tmp_path / "data")
    (habitat / SCENES[1] / f"{SCENES[1]}.glb").unlink()  # a missing .glb
    broken = scans / SCENES[0] / "mesh.obj"
    broken.write_text("not a mesh\n")  # an unreadable house mesh
    out = tmp_path / "prepared"
    with pytest.raises(prepare_mp3d.Mp3dLayoutError) as caught:
        prepare_mp3d.prepare(_args(habitat, scans, out))
    lines = str(caught.value).splitlines()
    assert len(lines) == 2
    assert lines[0].startswith(f"{SCENES[0]}: ") and "mesh.obj" in lines[0]
    assert lines[1].startswith(f"{SCENES[1]}: ") and "is missing" in lines[1]
    assert not out.exists()


def test_a_wrong_up_axis_is_named_with_the_flag_to_pass(tmp_path):
    habitat, scans = write_layout(tmp_path / "data", scenes=SCENES[:1])
    args = _args(habitat, scans, tmp_path / "out", glb_up_axis="z", scenes=list(SCENES[:1]))
    with pytest.raises(prepare_mp3d.Mp3dLayoutError, match="lies on its side.*--glb-up-axis y"):
        prepare_mp3d.prepare(args)
    bad = _args("", str(tmp_path / "nowhere"), tmp_path / "out", obj_up_axis="w")
    with pytest.raises(prepare_mp3d.Mp3dLayoutError) as caught:
        prepare_mp3d.prepare(bad)
    assert str(caught.value).splitlines() == [
        "pass --habitat-dir",
        f"--scans-dir {tmp_path / 'nowhere'} is not a folder",
        "--obj-up-axis 'w' is not one of y, z, x, -y, -z, -x",
    ]


def test_houses_that_do_not_line_up_are_refused(tmp_path):
    habitat, scans = write_layout(tmp_path / "data", scenes=SCENES[:1])
    moved = y_up_house()
    moved.apply_translation([20.0, 0.0, 0.0])
    moved.export(scans / SCENES[0] / "mesh.obj")
    with pytest.raises(prepare_mp3d.Mp3dLayoutError, match="do not line up"):
        prepare_mp3d.prepare(_args(habitat, scans, tmp_path / "out", scenes=list(SCENES[:1])))


def test_the_command_line_prints_the_table_or_the_problems(tmp_path, capsys):
    habitat, scans = write_layout(tmp_path / "data", scenes=SCENES[:1])
    argv = ["--habitat-dir", str(habitat), "--scans-dir", str(scans), "--scenes", SCENES[0],
            "--output-dir", str(tmp_path / "out")]  # fmt: skip
    assert prepare_mp3d.main(argv) == 0
    assert f"| {SCENES[0]} |" in capsys.readouterr().out
    assert prepare_mp3d.main([*argv[:-2], "--scenes", "nosuchscene"]) == 2
    assert "nothing written" in capsys.readouterr().err


def test_a_house_stands_upright_only_with_its_up_axis():
    upright = resolve_scene("two_rooms")
    on_its_side = y_up_house()
    assert prepare_mp3d.upright_share(upright.vertices, upright.faces) > prepare_mp3d.UPRIGHT_SHARE
    share = prepare_mp3d.upright_share(np.asarray(on_its_side.vertices), on_its_side.faces)
    assert share < prepare_mp3d.UPRIGHT_SHARE
