"""The external track's scans (:mod:`naruto_gym.scenes.external`): which files of a folder are
scenes, their up axis and checks, their budgets, and every problem of a folder at once."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from naruto_gym.scenes.external import (
    SAMPLE_SCANS,
    external_scans,
    external_suite_scenes,
    find_scans,
    scan_budget,
)
from naruto_gym.scenes.mesh_scene import load_scene, rotation_to_z_up
from naruto_gym.scenes.procedural import generate_layout
from naruto_gym.scenes.scan_checks import check_up_axis, file_axis, likely_up_axis
from tests.conftest import SAMPLE_MESHES, SHARED_SCENES


def write_room(path: Path, up_axis: str = "z", seed: int = 0, size=(3.0, 2.5, 2.4)) -> Path:
    """A furnished generated room written to ``path`` with ``up_axis`` pointing up in the
    file (z-up scene vertices turned into the file's axes)."""
    scene = generate_layout(seed, size, 1).to_scene("room")
    vertices = scene.vertices @ rotation_to_z_up(up_axis)  # the inverse of reading it
    path.parent.mkdir(parents=True, exist_ok=True)
    trimesh.Trimesh(vertices, scene.faces, process=False).export(path)
    return path


@pytest.mark.parametrize("up_axis", ["z", "y", "-y", "x", "-z"])
def test_the_geometry_shows_the_up_axis_of_a_room(up_axis, tmp_path):
    path = write_room(tmp_path / "room.ply", up_axis)
    raw = load_scene(path, up_axis="z")
    assert likely_up_axis(raw.vertices, raw.faces) == file_axis("z", up_axis)
    right = load_scene(path, up_axis=up_axis)
    assert likely_up_axis(right.vertices, right.faces) == "z"
    check_up_axis(right.vertices, right.faces, "room", up_axis)


def test_a_room_read_with_the_wrong_up_axis_is_refused_naming_the_right_one(tmp_path):
    path = write_room(tmp_path / "room.glb", "y")
    wrong = load_scene(path, up_axis="z")
    with pytest.raises(ValueError, match=r"on its side.*Pass up_axis='y'"):
        check_up_axis(wrong.vertices, wrong.faces, "room.glb", "z")
    upside_down = load_scene(path, up_axis="-y")
    with pytest.raises(ValueError, match=r"upside down.*Pass up_axis='y'"):
        check_up_axis(upside_down.vertices, upside_down.faces, "room.glb", "-y")


def test_budgets_follow_the_footprint_through_the_generated_classes():
    assert scan_budget(10.0) == 250  # a ScanNet room
    assert scan_budget(50.0) == 400 and scan_budget(110.0) == 800 and scan_budget(275.0) == 1500
    assert scan_budget(1000.0) == 1500
    budgets = [scan_budget(area) for area in range(0, 400, 10)]
    assert budgets == sorted(budgets)


def test_a_folder_of_scans_is_checked_and_each_gets_its_axis_and_budget(tmp_path):
    write_room(tmp_path / "scannet" / "scene0000_00_vh_clean_2.ply", "z", seed=1)
    write_room(tmp_path / "mp3d" / "house.glb", "y", seed=2, size=(8.0, 6.0, 2.6))
    write_room(tmp_path / "scannet" / "scene0000_00_vh_clean_2.labels.ply", "z")  # not a scene
    (tmp_path / "notes.txt").write_text("not a mesh")
    assert [path.name for path in find_scans(tmp_path)] == [
        "house.glb",
        "scene0000_00_vh_clean_2.ply",
    ]
    scans = external_scans(tmp_path)
    assert [(scan.path.name, scan.up_axis) for scan in scans] == [
        ("house.glb", "y"),
        ("scene0000_00_vh_clean_2.ply", "z"),
    ]
    house, room = scans
    assert house.budget > room.budget
    np.testing.assert_allclose(house.extents_m[:2], (8.0, 6.0), atol=0.5)
    scenes = external_suite_scenes(scans)
    assert [scene.scene for scene in scenes] == [f"{house.path}@y", f"{room.path}@z"]
    assert {scene.size_class for scene in scenes} == {"external"}
    # a given up axis wins over the geometry, and is checked
    with pytest.raises(ValueError, match="house.glb.*on its side"):
        external_scans(tmp_path, up_axis="z")


def test_every_file_that_is_not_a_scan_is_named_at_once(tmp_path):
    write_room(tmp_path / "good.ply")
    (tmp_path / "broken.ply").write_text("ply\nthis is not a mesh\n")
    cup = trimesh.creation.box((0.1, 0.1, 0.12))
    cup.export(tmp_path / "cup.obj")
    big = write_room(tmp_path / "in_mm.ply")
    mesh = trimesh.load(big, process=False)
    mesh.vertices *= 1000.0
    mesh.export(big)
    with pytest.raises(ValueError) as error:
        external_scans(tmp_path)
    message = str(error.value)
    assert "3 of the 4 mesh files" in message
    assert "broken.ply" in message and "cup.obj" in message and "not a scan of a room" in message
    assert "in_mm.ply" in message and "mesh_units='mm'" in message
    assert "good.ply" not in message.split("fix or remove them:")[1]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda root: root / "absent", "does not exist"),
        (lambda root: root, "holds no mesh file"),
    ],
)
def test_a_folder_without_scans_says_what_to_give(make, message, tmp_path):
    with pytest.raises(ValueError, match=message):
        external_scans(make(tmp_path))


@pytest.mark.skipif(not SHARED_SCENES.is_dir(), reason="../shared/scenes is absent")
def test_the_sample_scans_pass_their_checks_with_the_known_up_axes():
    scans = external_scans(SHARED_SCENES)
    found = {scan.path.relative_to(SHARED_SCENES).as_posix(): scan.up_axis for scan in scans}
    assert found == {name: axis for name, axis in SAMPLE_SCANS.items() if name in found}
    assert {path: axis for path, axis in SAMPLE_MESHES.values()} == SAMPLE_SCANS
    assert all(200 <= scan.budget <= 1500 for scan in scans)
