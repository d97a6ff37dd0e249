"""Mesh units: a room in millimetres or centimetres is refused with the unit that rescales it,
and accepted once rescaled; real scans and plausible rooms in metres, tiny or huge, load."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.scenes import available_scenes, load_scene, resolve_scene
from naruto_gym.scenes.units import MAX_SCENE_SIDE_M, check_metric_size
from naruto_gym.vector.vector_env import NarutoReconVectorEnv
from tests.conftest import SAMPLE_MESHES, require_shared_scenes
from tests.property.scenes import CHEAP

#: The issue's room: 6 x 4 x 2.7 m.
ROOM_M = (6.0, 4.0, 2.7)


def _room(extents: tuple[float, float, float], scale: float = 1.0) -> trimesh.Trimesh:
    """A closed box room, its inward faces outward-flipped, with a pillar (a furnished room's
    surface), in metres times ``scale``."""
    room = trimesh.creation.box(extents=extents)
    room.invert()
    pillar = trimesh.creation.box(extents=(0.4, 0.4, extents[2] * 0.6))
    pillar.apply_translation((extents[0] * 0.25, 0.0, -extents[2] * 0.2))
    mesh = trimesh.util.concatenate([room, pillar])
    mesh.apply_translation(-mesh.bounds[0])
    mesh.apply_scale(scale)
    return mesh


def _write(tmp_path, mesh: trimesh.Trimesh, name: str) -> str:
    path = tmp_path / f"{name}.ply"
    mesh.export(path)
    return str(path)


@pytest.mark.parametrize(("scale", "unit"), [(1000.0, "mm"), (100.0, "cm")])
def test_a_room_in_millimetres_or_centimetres_is_refused_with_the_unit(tmp_path, scale, unit):
    path = _write(tmp_path, _room(ROOM_M, scale), f"room_{unit}")
    with pytest.raises(ValueError, match=f"mesh_units='{unit}'") as error:
        load_scene(path)
    message = str(error.value)
    assert {"mm": "millimetres", "cm": "centimetres"}[unit] in message
    assert "4.0 m across in metres" in message  # the second-longest side, rescaled
    for make in (resolve_scene, lambda p: NarutoReconEnv(p, **CHEAP)):
        with pytest.raises(ValueError, match=f"mesh_units='{unit}'"):
            make(path)


@pytest.mark.parametrize(("scale", "unit"), [(1000.0, "mm"), (100.0, "cm")])
def test_the_rescaled_room_loads_in_metres(tmp_path, scale, unit):
    path = _write(tmp_path, _room(ROOM_M, scale), f"room_{unit}")
    scene = load_scene(path, mesh_units=unit)
    np.testing.assert_allclose(np.sort(scene.extents), np.sort(ROOM_M), rtol=1e-6)
    assert np.sort(resolve_scene(path, mesh_units=unit).extents)[1] == pytest.approx(4.0)
    env = NarutoReconEnv(path, mesh_units=unit, **CHEAP)
    np.testing.assert_allclose(np.sort(env.scene.extents), np.sort(ROOM_M), rtol=1e-6)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()


def test_the_batched_env_rescales_and_refuses_alike(tmp_path):
    path = _write(tmp_path, _room(ROOM_M, 1000.0), "room_mm")
    with pytest.raises(ValueError, match="mesh_units='mm'"):
        NarutoReconVectorEnv(2, scene=path, **CHEAP)
    env = NarutoReconVectorEnv(2, scene=path, mesh_units="mm", **CHEAP)
    try:
        env.reset(seed=0)
        assert np.sort(env.scene_runtimes[0].scene.extents)[1] == pytest.approx(4.0)
    finally:
        env.close()


def test_a_unit_is_applied_as_given_and_an_unknown_unit_is_refused(tmp_path):
    """'mm' on a metre file gives a 6 mm room, which loads (a tiny scene is not refused);
    an unknown unit is refused, by name."""
    path = _write(tmp_path, _room(ROOM_M), "room_m")
    assert np.sort(load_scene(path, mesh_units="mm").extents)[1] == pytest.approx(0.004)
    with pytest.raises(ValueError, match="mesh_units must be one of"):
        load_scene(path, mesh_units="inch")
    with pytest.raises(ValueError, match="mesh_units"):
        NarutoReconEnv(path, mesh_units="metres", **CHEAP)


@pytest.mark.parametrize(
    "extents",
    [
        (1.0, 1.2, 0.8),  # a box scanned on a table
        ROOM_M,
        (60.0, 40.0, 8.0),  # a sports hall
        (99.0, 95.0, 12.0),  # the largest space the size test passes
        (400.0, 3.0, 2.5),  # a long corridor: one long side only
    ],
)
def test_plausible_rooms_in_metres_load(tmp_path, extents):
    path = _write(tmp_path, _room(extents), "room")
    np.testing.assert_allclose(np.sort(load_scene(path).extents), np.sort(extents), rtol=1e-6)


def test_a_huge_dense_scan_in_metres_loads():
    """A 300 x 200 m space whose triangles are those of a scan (centimetres): metres."""
    floor = trimesh.creation.box(extents=(300.0, 200.0, 0.1))
    clutter = [
        trimesh.creation.icosphere(subdivisions=2, radius=0.05).apply_translation((x, y, 0.5))
        for x in np.linspace(-140, 140, 20)
        for y in np.linspace(-90, 90, 20)
    ]
    mesh = trimesh.util.concatenate([floor, *clutter])
    assert MAX_SCENE_SIDE_M < 200.0
    check_metric_size(mesh.vertices, mesh.faces, "a dense scan")


def test_a_huge_coarse_space_is_refused_but_a_scene_object_is_taken_as_is(tmp_path):
    mesh = _room((300.0, 200.0, 10.0))
    with pytest.raises(ValueError, match="scene_from_trimesh"):
        load_scene(_write(tmp_path, mesh, "hangar"))
    from naruto_gym.scenes import scene_from_trimesh

    scene = scene_from_trimesh(mesh)
    assert resolve_scene(scene) is scene


@pytest.mark.parametrize("name", available_scenes())
def test_catalogue_scenes_are_in_metres(name):
    scene = resolve_scene(name)
    check_metric_size(scene.vertices, scene.faces, name)


@pytest.mark.parametrize("kind", ["room", "small", "apartment", "house"])
def test_procedural_scenes_are_in_metres(kind):
    scene = resolve_scene(f"procedural:{kind}:3")
    check_metric_size(scene.vertices, scene.faces, kind)


@pytest.mark.parametrize("name", sorted(SAMPLE_MESHES))
def test_real_scans_in_metres_load_and_read_as_millimetres_are_refused(tmp_path, name):
    relative, up_axis = SAMPLE_MESHES[name]
    path = require_shared_scenes() / relative
    scene = load_scene(path, up_axis=up_axis)
    mesh = trimesh.Trimesh(scene.vertices * 1000.0, scene.faces, process=False)
    with pytest.raises(ValueError, match="mesh_units='mm'"):
        load_scene(_write(tmp_path, mesh, f"{name}_mm"))


def test_the_demo_refuses_a_millimetre_mesh_and_runs_it_with_mesh_units(tmp_path, capsys):
    """``naruto-demo --scene room_mm.ply`` says what is wrong and which flag fixes it; with
    that flag the same file runs."""
    from naruto_agent.demo import main

    path = _write(tmp_path, _room(ROOM_M, 1000.0), "room_mm")
    with pytest.raises(SystemExit) as exit_info:
        main(["--scene", path, "--output-dir", str(tmp_path / "refused")])
    assert exit_info.value.code == 2
    error = capsys.readouterr().err
    assert "likely in millimetres" in error and "--mesh-units" in error
    assert not (tmp_path / "refused").exists()
    flags = ["--policy", "random", "--max-episode-steps", "3", "--eval-points", "0",
             "--gif-frames", "0", "--no-record", "--no-viewer", "--image-scale", "0.1",
             "--eval-samples", "2000"]
    main(["--scene", path, "--mesh-units", "mm", *flags, "--output-dir", str(tmp_path / "ok")])
    assert (tmp_path / "ok").is_dir()
