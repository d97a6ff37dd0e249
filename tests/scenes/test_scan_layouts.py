"""Real-scan file layouts load with the right orientation and colours.

No real scan ships with the project, so each test writes a small file with a dataset's layout
from a procedural scene (an open variant, as scans are) into a temporary folder:

* ScanNet: ``scene0000_00/scene0000_00_vh_clean_2.ply``, binary PLY, float x/y/z and uchar
  red/green/blue/alpha per vertex, triangle faces, z-up, coordinates not centred;
* Replica: ``room_0/mesh.ply`` beside ``textures/``, float x/y/z, nx/ny/nz and uchar
  red/green/blue per vertex, quad faces, z-up;
* MP3D / HM3D: a textured ``.glb``, y-up.
"""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import trimesh
from PIL import Image

import naruto_gym  # noqa: F401
from naruto_gym.scenes.catalogue import catalogue_entry
from naruto_gym.scenes.mesh_scene import dataset_up_axis, load_scene
from naruto_gym.scenes.open_scans import open_scan_variant

SCANNET_OFFSET = np.array([1.3, 2.7, 0.0])  # ScanNet scans sit in the sensor's world frame


@pytest.fixture(scope="module")
def room_scan():
    """(vertices, faces, per-vertex RGB) of an open scan of the two-room scene."""
    layout = catalogue_entry("two_rooms").layout()
    scene = open_scan_variant(layout, "no_ceiling+holes", fragments=False)
    mesh = scene.to_trimesh()  # per-vertex colours (the corners of a vertex agree here)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces), mesh.visual.vertex_colors[:, :3]


def _write_ply(path: Path, vertex_fields: dict[str, np.ndarray], faces: np.ndarray) -> None:
    """A binary little-endian PLY with the given per-vertex properties and polygon faces."""
    types = {np.dtype("float32"): ("float", "<f4"), np.dtype("uint8"): ("uchar", "u1")}
    names = list(vertex_fields)
    dtype = [(name, types[vertex_fields[name].dtype][1]) for name in names]
    vertices = np.zeros(len(next(iter(vertex_fields.values()))), dtype=dtype)
    for name in names:
        vertices[name] = vertex_fields[name]
    corners = faces.shape[1]
    face_records = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", (corners,))])
    face_records["n"] = corners
    face_records["i"] = faces
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {len(vertices)}"]
    header += [f"property {types[vertex_fields[n].dtype][0]} {n}" for n in names]
    header += [f"element face {len(faces)}", "property list uchar int vertex_indices",
               "end_header"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(("\n".join(header) + "\n").encode() + vertices.tobytes()
                     + face_records.tobytes())


def test_scannet_layout(tmp_path, room_scan):
    vertices, faces, rgb = room_scan
    shifted = vertices + SCANNET_OFFSET
    path = tmp_path / "scene0000_00" / "scene0000_00_vh_clean_2.ply"
    fields = {axis: shifted[:, i].astype(np.float32) for i, axis in enumerate("xyz")}
    for i, channel in enumerate(("red", "green", "blue")):
        fields[channel] = rgb[:, i].astype(np.uint8)
    fields["alpha"] = np.full(len(vertices), 255, np.uint8)
    _write_ply(path, fields, faces)

    assert dataset_up_axis(path) == "z"
    scene = load_scene(path, up_axis="auto")
    np.testing.assert_allclose(scene.vertices, shifted, atol=1e-5)  # z-up, not re-centred
    np.testing.assert_array_equal(scene.corner_colours, rgb[faces])
    # The env takes it as users pass it; the start lies inside the scanned rooms.
    env = gym.make("NarutoRecon-v0", scene=str(path), up_axis="auto", image_scale=0.05,
                   coverage_samples=500).unwrapped
    observation, _ = env.reset(seed=0)
    start = observation["pose"][:3, 3] - SCANNET_OFFSET
    width, depth, height = catalogue_entry("two_rooms").size
    assert 0 < start[0] < width and 0 < start[1] < depth and 0 < start[2] < height
    observation, _, _, _, info = env.step(env.action_space.sample())
    assert observation["rgb"].any() and info["collision_reason"] != "escape"


def _quads(faces: np.ndarray) -> np.ndarray:
    """Quads (a, b, c, d) from the triangle pairs (a, b, c), (a, c, d) the generator emits."""
    first, second = faces[:-1], faces[1:]
    pairs = (first[:, 0] == second[:, 0]) & (first[:, 2] == second[:, 1])
    index = np.flatnonzero(pairs)
    index = index[np.concatenate([[True], np.diff(index) > 1])]  # no overlapping pairs
    return np.column_stack([first[index], second[index, 2]])


def test_replica_layout_with_quads_and_normals(tmp_path, room_scan):
    vertices, faces, rgb = room_scan
    quads = _quads(faces)
    assert len(quads) > 100
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    normals = np.asarray(mesh.vertex_normals, np.float32)
    path = tmp_path / "room_0" / "mesh.ply"
    fields = {axis: vertices[:, i].astype(np.float32) for i, axis in enumerate("xyz")}
    fields |= {name: normals[:, i] for i, name in enumerate(("nx", "ny", "nz"))}
    for i, channel in enumerate(("red", "green", "blue")):
        fields[channel] = rgb[:, i].astype(np.uint8)
    _write_ply(path, fields, quads)
    with pytest.raises(ValueError, match="up_axis"):
        dataset_up_axis(path)  # a bare mesh.ply is not recognised ...
    (path.parent / "textures").mkdir()
    assert dataset_up_axis(path) == "z"  # ... beside Replica's textures/ folder it is

    scene = load_scene(path, up_axis="auto")
    assert len(scene.faces) == 2 * len(quads)
    quad_area = trimesh.Trimesh(vertices, np.concatenate([quads[:, :3], quads[:, [0, 2, 3]]]),
                                process=False).area
    assert trimesh.Trimesh(scene.vertices, scene.faces, process=False).area == pytest.approx(
        quad_area, rel=1e-6
    )
    np.testing.assert_array_equal(scene.corner_colours, rgb[scene.faces])
    assert scene.bounds[1, 2] - scene.bounds[0, 2] < 3.0  # z is up: the rooms' height


def test_mp3d_style_textured_glb_is_y_up(tmp_path, room_scan):
    vertices, faces, _ = room_scan
    layout = catalogue_entry("two_rooms").layout()
    scene = open_scan_variant(layout, "no_ceiling", fragments=False)
    face_rgb = scene.corner_colours.mean(axis=1).round().astype(np.uint8)
    palette, face_texel = np.unique(face_rgb, axis=0, return_inverse=True)
    texture = palette[None, :, :]  # a 1 x K texture, one texel per face colour
    corners = scene.vertices[scene.faces].reshape(-1, 3)
    uv = np.column_stack([(face_texel.repeat(3) + 0.5) / len(palette), np.full(len(corners), 0.5)])
    # Stored y-up: file (x, y, z) = world (x, z, -y).
    stored = np.column_stack([corners[:, 0], corners[:, 2], -corners[:, 1]])
    material = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(texture))
    mesh = trimesh.Trimesh(stored, np.arange(len(corners)).reshape(-1, 3), process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material))
    path = tmp_path / "17DRP5sb8fy" / "17DRP5sb8fy.glb"
    path.parent.mkdir()
    mesh.export(path)

    with pytest.raises(ValueError, match="'y' for y-up glTF"):
        load_scene(path, up_axis="auto")  # never guessed
    loaded = load_scene(path, up_axis="y")
    np.testing.assert_allclose(loaded.vertices[loaded.faces].reshape(-1, 3), corners, atol=1e-5)
    assert loaded.textures, "the texture must be kept for hit-time lookups"
    centre = np.full((len(loaded.faces), 2), 1.0 / 3.0, np.float32)
    colours = loaded.colour_at(np.arange(len(loaded.faces)), centre)
    np.testing.assert_array_equal(colours, face_rgb)
    # The same file read as z-up stands on its side: its "height" is the rooms' depth.
    with pytest.warns(UserWarning, match="looks y-up"):
        sideways = load_scene(path, up_axis="z")
    assert sideways.extents[2] == pytest.approx(loaded.extents[1], abs=1e-4)


def test_auto_up_axis_refuses_unknown_layouts(tmp_path):
    box = trimesh.creation.box()
    for name in ("room.ply", "scene0000_00.ply", "mesh.obj"):
        path = tmp_path / name
        box.export(path)
        with pytest.raises(ValueError, match="pass the axis that points up"):
            load_scene(path, up_axis="auto")


@pytest.mark.parametrize("axis", ["x", "-x", "-y", "-z"])
def test_every_up_axis_turns_that_axis_to_plus_z(tmp_path, axis):
    from naruto_gym.scenes.mesh_scene import scene_from_trimesh

    tall = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    tall.vertices[tall.vertices[:, 2] > 0, 2] += 1.0  # a box tall along +z, top at z = 1.5
    index, sign = "xyz".index(axis[-1]), (-1.0 if axis.startswith("-") else 1.0)
    rotation = trimesh.geometry.align_vectors([0, 0, 1], np.eye(3)[index] * sign)
    stored = tall.copy()
    stored.apply_transform(rotation)  # the file's up axis is `axis`
    scene = scene_from_trimesh(stored, up_axis=axis)
    np.testing.assert_allclose(scene.bounds, tall.bounds, atol=1e-9)
