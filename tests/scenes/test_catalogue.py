"""The shipped scene catalogue: names, files, metadata, resolution and regeneration."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from naruto_gym.scenes import (
    DEFAULT_SCENE,
    available_scenes,
    load_catalogue_scene,
    resolve_scene,
    scene_info,
    scene_path,
)
from naruto_gym.scenes.catalogue import (
    ASSETS_DIR_ENV,
    CACHE_DIR_ENV,
    CATALOGUE_FILE,
    assets_dir,
    cache_dir,
    catalogue_document,
)
from naruto_gym.scenes.procedural import save_scene_ply
from naruto_gym.sensors.raycaster import RayCaster

SHIPPED = ["replica_like_room", "apartment", "two_rooms"]


def test_catalogue_lists_the_shipped_scenes():
    assert available_scenes()[: len(SHIPPED)] == SHIPPED
    assert DEFAULT_SCENE == "replica_like_room" == available_scenes()[0]


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_file_matches_its_record(name):
    path = scene_path(name)
    assert path.parent == assets_dir() and path.is_file()
    info = scene_info(name)
    data = path.read_bytes()
    assert len(data) == info["file_bytes"] < 3_000_000
    assert hashlib.sha256(data).hexdigest() == info["sha256"]
    scene = load_catalogue_scene(name)
    assert scene.name == name
    assert len(scene.faces) == info["triangles"]
    np.testing.assert_allclose(scene.extents, info["extents_m"], atol=2e-3)
    # Per-vertex colours survived the file: many distinct colours, not a grey default.
    assert len(np.unique(scene.corner_colours.reshape(-1, 3), axis=0)) > 50


def test_catalogue_json_is_in_sync_with_the_generator():
    """The shipped files must be what the generator makes now (else rerun
    scripts/generate_scenes.py)."""
    shipped = json.loads((assets_dir() / CATALOGUE_FILE).read_text(encoding="utf-8"))
    assert shipped == catalogue_document()


def test_sizes_match_the_descriptions():
    room = scene_info("replica_like_room")
    assert room["generator"]["size"] == [5.0, 5.0, 3.0] and len(room["rooms"]) == 1
    apartment = scene_info("apartment")
    assert len(apartment["rooms"]) >= 4
    assert max(apartment["extents_m"][:2]) >= 10.0
    assert len(apartment["doorways"]) >= len(apartment["rooms"]) - 1


@pytest.mark.parametrize("name", SHIPPED)
def test_start_and_free_points_are_clear_and_inside(name):
    info = scene_info(name)
    scene = load_catalogue_scene(name)
    caster = RayCaster(scene.vertices, scene.faces)
    points = np.array([info["start_position"], *info["free_points"]], dtype=np.float64)
    assert len(info["free_points"]) == len(info["rooms"])
    assert np.all(caster.unsigned_distance(points) >= 0.3)
    directions = np.random.default_rng(1).normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    for point in points:
        assert caster.cast(point, directions).hit_mask.all()


def test_unknown_name_lists_the_catalogue():
    with pytest.raises(ValueError, match="replica_like_room.*apartment"):
        resolve_scene("no_such_scene")
    with pytest.raises(ValueError, match="available catalogue scenes"):
        scene_path("no_such_scene")
    with pytest.raises(ValueError, match="available catalogue scenes"):
        scene_info("no_such_scene")
    with pytest.raises(ValueError, match="Scene"):
        resolve_scene(42)  # type: ignore[arg-type]


def test_resolve_scene_accepts_names_paths_and_scenes(tmp_path):
    by_name = resolve_scene("two_rooms")
    assert by_name.name == "two_rooms"
    assert resolve_scene(by_name) is by_name
    by_path = resolve_scene(str(scene_path("two_rooms")))
    np.testing.assert_array_equal(by_path.faces, by_name.faces)
    # A y-up copy of the file is rotated back to z-up by the up_axis setting.
    rotated = by_name.vertices @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]).T
    from naruto_gym.scenes.mesh_scene import Scene

    y_up = Scene(rotated, by_name.faces, by_name.corner_colours)
    path = save_scene_ply(y_up, tmp_path / "y_up.ply")
    restored = resolve_scene(path, up_axis="y")
    np.testing.assert_allclose(restored.vertices, by_name.vertices, atol=1e-5)
    with pytest.raises(FileNotFoundError):
        resolve_scene(tmp_path / "missing.ply")


def test_missing_asset_is_regenerated_into_the_cache(tmp_path, monkeypatch):
    expected = scene_info("two_rooms")
    monkeypatch.setenv(ASSETS_DIR_ENV, str(tmp_path / "no_assets"))
    monkeypatch.setenv(CACHE_DIR_ENV, str(tmp_path / "cache"))
    path = scene_path("two_rooms")
    assert path == cache_dir() / "two_rooms.ply"
    assert path.is_relative_to(tmp_path / "cache")
    assert hashlib.sha256(path.read_bytes()).hexdigest() == expected["sha256"]
    modified = path.stat().st_mtime_ns
    assert scene_path("two_rooms").stat().st_mtime_ns == modified  # reused, not rewritten
    # Without catalogue.json the metadata is computed from the generator, identically.
    assert scene_info("two_rooms") == expected
    assert load_catalogue_scene("two_rooms").name == "two_rooms"


def test_regeneration_warns_when_the_shipped_record_disagrees(tmp_path, monkeypatch):
    record = scene_info("two_rooms") | {"sha256": "0" * 64}
    assets = tmp_path / "assets"
    assets.mkdir()
    (assets / CATALOGUE_FILE).write_text(json.dumps({"scenes": [record]}), encoding="utf-8")
    monkeypatch.setenv(ASSETS_DIR_ENV, str(assets))
    monkeypatch.setenv(CACHE_DIR_ENV, str(tmp_path / "cache"))
    with pytest.warns(UserWarning, match="generate_scenes.py"):
        scene_path("two_rooms")
