"""Meshes as users bring them, broken or odd: the env is made and resets and steps, or one
clear error (``ValueError``, ``FileNotFoundError``, or ``RuntimeError`` for a scene with no
room for the agent) says what is wrong; nothing hangs."""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest
import trimesh
from hypothesis import given
from hypothesis import strategies as st

from naruto_gym.envs.naruto_recon_env import NarutoReconEnv
from naruto_gym.geometry.transforms import make_pose
from naruto_gym.scenes.mesh_scene import Scene
from tests.property.scenes import CHEAP, room_mesh, small_room, write_ascii_ply, write_mesh

#: The longest a reset may take on any of these meshes (seconds; a reset that searches
#: forever for a start would exceed it).
RESET_SECONDS = 60.0


def _middle_pose(env: NarutoReconEnv) -> np.ndarray:
    return make_pose(np.eye(3), env.bounds.mean(axis=0))


def _runs_or_says_why(scene, **settings) -> str:
    """Make an env of ``scene``, reset (a drawn start, else a pose at the middle of the
    bounds) and step three times. Returns "ran", or the error's message when one of the
    clear errors was raised."""
    try:
        env = NarutoReconEnv(scene, **{**CHEAP, **settings})
    except (ValueError, FileNotFoundError) as error:
        return str(error)
    started = time.perf_counter()
    try:
        try:
            env.reset(seed=0)
        except RuntimeError as error:
            assert "no free start position" in str(error) and "reset(options" in str(error)
            env.reset(seed=0, options={"pose": _middle_pose(env)})  # the same env goes on
    except ValueError as error:  # no viewpoint for the observable surface: said, not searched
        assert "observable_only=False" in str(error) and env.settings.observable_only
        return str(error)
    finally:
        assert time.perf_counter() - started < RESET_SECONDS
    for _ in range(3):
        observation, reward, _, _, _ = env.step(env.action_space.sample())
        assert env.observation_space.contains(observation) and np.isfinite(reward)
    return "ran"


def _box_room(size: float = 3.0) -> trimesh.Trimesh:
    return trimesh.creation.box((size, size, size * 0.8))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_vertex_that_is_not_finite_is_refused_by_name(tmp_path, bad):
    """One NaN or infinite vertex in a PLY is refused when the scene loads, naming the
    vertex, rather than failing deep inside the env."""
    box = _box_room()
    box.vertices[0] = bad
    path = write_mesh(box, tmp_path / "nan.ply")
    with pytest.raises(ValueError, match="NaN or infinite coordinates"):
        NarutoReconEnv(str(path))
    vertices = np.array(box.vertices)
    path = write_ascii_ply(tmp_path / "one_nan.ply", vertices, box.faces)
    with pytest.raises(ValueError, match="vertex 0"):
        NarutoReconEnv(str(path))


def test_faces_that_index_past_the_vertices_are_refused(tmp_path):
    box = _box_room()
    faces = np.array(box.faces)
    faces[3, 1] = len(box.vertices) + 5
    path = write_ascii_ply(tmp_path / "past.ply", np.array(box.vertices), faces)
    message = _runs_or_says_why(str(path))
    assert "face indices" in message or "could not read" in message
    with pytest.raises(ValueError, match="face indices lie outside"):
        Scene(box.vertices, faces, np.zeros((len(faces), 3, 3)))


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"", "could not read"),
        (b"ply\nformat ascii 1.0\n", "could not read|no triangles"),
        (b"\x00\x01garbage" * 10, "could not read"),
    ],
)
def test_empty_and_garbled_files_are_refused(tmp_path, content, expected):
    path = tmp_path / "broken.ply"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=expected):
        NarutoReconEnv(str(path))


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".glb"])
@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9])
def test_truncated_files_are_refused_or_read(tmp_path, suffix, keep):
    """A file cut short is refused with a clear error, or (a text format cut at a line)
    read as what is left of it."""
    whole = write_mesh(room_mesh(), tmp_path / f"whole{suffix}")
    data = whole.read_bytes()
    path = tmp_path / f"cut{suffix}"
    path.write_bytes(data[: int(len(data) * keep)])
    message = _runs_or_says_why(str(path))
    assert message == "ran" or any(
        word in message
        for word in ("could not read", "no triangles", "face indices", "NaN", "zero area")
    ), message


def test_a_point_cloud_is_refused(tmp_path):
    points = trimesh.PointCloud(np.random.default_rng(0).random((50, 3)))
    path = tmp_path / "points.ply"
    points.export(path)
    with pytest.raises(ValueError, match="no triangles|could not read"):
        NarutoReconEnv(str(path))


@pytest.mark.parametrize("name", ["room.xyz", "room.fbx", "room.txt", "room"])
def test_unknown_formats_are_refused(tmp_path, name):
    path = tmp_path / name
    path.write_text("1 2 3\n4 5 6\n")
    with pytest.raises((ValueError, FileNotFoundError)):
        NarutoReconEnv(str(path))


def test_a_mesh_with_no_area_is_refused():
    with pytest.raises(ValueError, match="zero area"):
        NarutoReconEnv(Scene(np.zeros((3, 3)), [[0, 1, 2]], np.zeros((1, 3, 3))))


def test_a_y_up_file_without_up_axis_warns(tmp_path):
    mesh = room_mesh()
    mesh.vertices = mesh.vertices[:, [0, 2, 1]] * [1.0, 1.0, -1.0]  # z-up to y-up
    path = write_mesh(mesh, tmp_path / "y_up.ply")
    with pytest.warns(UserWarning, match="up_axis='y'"):
        NarutoReconEnv(str(path))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _runs_or_says_why(str(path), up_axis="y") == "ran"


def test_no_room_for_the_agent_is_said_not_searched_forever():
    """A closed 20 cm box: no point has 0.3 m of free space around it."""
    box = trimesh.creation.box((0.2, 0.2, 0.2))
    scene = Scene(box.vertices, box.faces[:, ::-1], np.zeros((12, 3, 3)))
    env = NarutoReconEnv(scene, **CHEAP)
    started = time.perf_counter()
    with pytest.raises(RuntimeError, match="no free start position"):
        env.reset(seed=0)
    with pytest.raises(ValueError, match="too small for the agent.*observable_only=False"):
        env.reset(seed=0, options={"pose": _middle_pose(env)})
    assert time.perf_counter() - started < RESET_SECONDS
    env = NarutoReconEnv(scene, **CHEAP, observable_only=False)
    started = time.perf_counter()
    with pytest.raises(RuntimeError, match="no free start position.*start_clearance_m"):
        env.reset(seed=0)
    assert time.perf_counter() - started < RESET_SECONDS
    env.reset(seed=0, options={"pose": _middle_pose(env)})
    env.step(env.action_space.sample())


def _defects(mesh: trimesh.Trimesh, defect: str, rng: np.random.Generator) -> Scene:
    vertices, faces = np.array(mesh.vertices), np.array(mesh.faces)
    if defect == "degenerate":
        faces = np.concatenate([faces, np.repeat(faces[:5, :1], 3, axis=1)])
    elif defect == "duplicate":
        faces = np.concatenate([faces, faces[rng.integers(0, len(faces), 50)]])
    elif defect == "open_shell":
        top = vertices[faces].mean(axis=1)[:, 2] > vertices[:, 2].max() - 0.05
        faces = faces[~top]
    elif defect == "disconnected":
        far = vertices + [np.ptp(vertices[:, 0]) * 3.0, 0.0, 0.0]
        vertices, faces = (
            np.concatenate([vertices, far]),
            np.concatenate([faces, faces + len(vertices)]),
        )
    elif defect == "single_triangle":
        vertices, faces = vertices[faces[0]], np.array([[0, 1, 2]])
    elif defect == "unused_vertices":
        vertices = np.concatenate([vertices, rng.random((20, 3)) * 100.0])
    return Scene(vertices, faces, np.full((len(faces), 3, 3), 180), name=defect)


@given(
    defect=st.sampled_from(
        [
            "none",
            "degenerate",
            "duplicate",
            "open_shell",
            "disconnected",
            "single_triangle",
            "unused_vertices",
        ]
    ),
    log_scale=st.floats(-3.0, 3.6),  # a room of 3 mm to about 12 km
)
def test_odd_but_valid_meshes_at_any_scale_run(defect, log_scale):
    scale = 10.0**log_scale
    scene = _defects(room_mesh(scale), defect, np.random.default_rng(0))
    if _runs_or_says_why(scene) != "ran":  # no room for the observable surface's viewpoints
        assert _runs_or_says_why(scene, observable_only=False) == "ran"


@pytest.mark.parametrize("scale", [1e-3 / 3.0, 10_000 / 3.0])
def test_scenes_of_one_millimetre_and_ten_kilometres_run(scale):
    """The room (3 m) scaled to 1 mm and to 10 km."""
    scene = Scene(room_mesh(scale).vertices, small_room().faces, small_room().corner_colours)
    if scale < 1.0:
        assert "too small for the agent" in _runs_or_says_why(scene)
        assert _runs_or_says_why(scene, observable_only=False) == "ran"
    else:
        assert _runs_or_says_why(scene) == "ran"


def test_a_room_300_m_wide_gets_a_lattice_of_bounded_memory():
    """The scanned-space lattice (a byte per corner) of the room scaled 100 times stays
    within its corner bound (at 5 cm it would need hundreds of GiB)."""
    from naruto_gym.motion.scanned_space import MAX_LATTICE_CORNERS

    scene = Scene(room_mesh(100.0).vertices, small_room().faces, small_room().corner_colours)
    assert _runs_or_says_why(scene) == "ran"
    env = NarutoReconEnv(scene, **CHEAP)
    lattice = env.collision.scanned_space
    assert np.prod(lattice.shape) <= MAX_LATTICE_CORNERS
