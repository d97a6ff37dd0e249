"""Loading meshes: formats, colour sources, up axis, clear errors."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from naruto_gym.geometry.sorted_search import searchsorted_right
from naruto_gym.scenes import Scene, make_random_scene
from naruto_gym.scenes.mesh_scene import load_scene, sample_mesh_surface, scene_from_trimesh
from tests.conftest import SAMPLE_MESHES


def _coloured_box() -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    colours = np.zeros((len(box.vertices), 4), np.uint8)
    colours[:, 0] = 255
    colours[:, 3] = 255
    box.visual.vertex_colors = colours
    return box


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".glb"])
def test_formats_round_trip_geometry(tmp_path, suffix):
    path = tmp_path / f"box{suffix}"
    _coloured_box().export(path)
    scene = load_scene(path)
    np.testing.assert_allclose(scene.extents, [1.0, 2.0, 3.0], atol=1e-6)
    assert len(scene.faces) == 12


def test_vertex_colour_is_interpolated():
    scene = scene_from_trimesh(_coloured_box())
    rgb = scene.colour_at(np.array([0, 5]), np.array([[0.2, 0.3], [0.5, 0.5]], np.float32))
    np.testing.assert_array_equal(rgb, [[255, 0, 0], [255, 0, 0]])
    assert scene.colour_at(np.array([-1]), np.zeros((1, 2), np.float32)).tolist() == [[0, 0, 0]]


def test_face_colours():
    box = trimesh.creation.box()
    box.visual.face_colors = np.tile([10, 200, 30, 255], (12, 1))
    scene = scene_from_trimesh(box)
    assert scene.colour_at(np.array([3]), np.array([[0.1, 0.1]], np.float32)).tolist() == [
        [10, 200, 30]
    ]


def test_texture_is_sampled_at_hit_uv():
    # A 2 x 2 texture: left half red, right half blue; a quad mapped onto it.
    image = np.zeros((2, 2, 3), np.uint8)
    image[:, 0] = [255, 0, 0]
    image[:, 1] = [0, 0, 255]
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    material = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(image))
    mesh = trimesh.Trimesh(
        vertices, faces, visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
        process=False,
    )
    scene = scene_from_trimesh(mesh)
    # Triangle 0 = (v0, v1, v2); (u, v) = (0.9, 0.05) is near v1 (uv x = 0.95): blue.
    near_right = scene.colour_at(np.array([0]), np.array([[0.9, 0.05]], np.float32))
    # Triangle 1 = (v0, v2, v3); near v3 (uv x = 0.05): red.
    near_left = scene.colour_at(np.array([1]), np.array([[0.05, 0.9]], np.float32))
    assert near_right.tolist() == [[0, 0, 255]]
    assert near_left.tolist() == [[255, 0, 0]]


def test_y_up_is_rotated_to_z_up():
    box = trimesh.creation.box(extents=(1.0, 3.0, 2.0))  # tall along y
    scene = scene_from_trimesh(box, up_axis="y")
    np.testing.assert_allclose(scene.extents, [1.0, 2.0, 3.0], atol=1e-9)


def test_errors_are_clear(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_scene(tmp_path / "missing.ply")
    broken = tmp_path / "broken.ply"
    broken.write_bytes(b"ply\nformat nonsense\n\x00\x01")
    with pytest.raises(ValueError, match="could not read|no triangles"):
        load_scene(broken)
    points = tmp_path / "points.ply"
    trimesh.PointCloud(np.random.default_rng(0).random((10, 3))).export(points)
    with pytest.raises(ValueError, match="no triangles"):
        load_scene(points)
    with pytest.raises(ValueError, match="up_axis"):
        scene_from_trimesh(trimesh.creation.box(), up_axis="w")


@pytest.mark.parametrize("name", sorted(SAMPLE_MESHES))
def test_sample_meshes_load(shared_scenes, name):
    relative, up_axis = SAMPLE_MESHES[name]
    scene = load_scene(shared_scenes / relative, up_axis=up_axis)
    assert len(scene.faces) > 50
    assert scene.extents[2] < scene.extents[:2].max()  # z-up rooms are wider than tall
    samples = scene.sample_surface(1000, seed=0)
    assert samples.shape == (1000, 3)


def test_scene_samples_its_surface_with_the_one_area_uniform_sampler():
    scene = scene_from_trimesh(trimesh.creation.box(extents=(1.0, 2.0, 3.0)))
    samples = scene.sample_surface(6000, seed=4)
    np.testing.assert_array_equal(
        samples, sample_mesh_surface(scene.vertices, scene.faces, 6000, seed=4)
    )
    assert not np.array_equal(samples, scene.sample_surface(6000, seed=5))
    # Every point lies on the box, and the faces are hit in proportion to their area.
    on_face = np.isclose(np.abs(samples), [0.5, 1.0, 1.5], atol=1e-9)
    assert on_face.any(axis=1).all()
    area_share = np.array([2 * 3, 1 * 3, 1 * 2]) / 11.0
    np.testing.assert_allclose(on_face.mean(axis=0), area_share, atol=0.02)
    flat = scene_from_trimesh(trimesh.Trimesh(np.zeros((3, 3)), [[0, 1, 2]], process=False))
    with pytest.raises(ValueError, match="zero total area"):
        flat.sample_surface(10)


def test_heights_alone_are_the_samples_third_coordinate():
    scene = make_random_scene(3, "room")
    points = sample_mesh_surface(scene.vertices, scene.faces, 5000, seed=2)
    heights = sample_mesh_surface(scene.vertices, scene.faces, 5000, seed=2, axes=[2])
    assert heights.shape == (5000, 1)
    np.testing.assert_array_equal(heights[:, 0], points[:, 2])


@pytest.mark.parametrize("kind", ["uniform", "skewed", "plateaus", "repeated", "tiny"])
def test_area_draw_search_is_numpys_searchsorted(kind):
    rng = np.random.default_rng(len(kind))
    for count in (1, 2, 7, 300, 2500):
        weights = {
            "uniform": rng.random(count),
            "skewed": rng.random(count) ** 8,  # a few huge triangles among many tiny ones
            "plateaus": np.where(rng.random(count) < 0.9, 0.0, rng.random(count)),
            "repeated": np.round(rng.random(count) * 3),
            "tiny": rng.exponential(size=count) * 1e-12,
        }[kind]
        values = np.cumsum(weights)
        keys = np.concatenate([
            rng.random(4000) * values[-1], values, np.nextafter(values, np.inf),
            np.nextafter(values, -np.inf), [-1.0, 0.0, np.inf, -np.inf, np.nan, 2 * values[-1]],
        ])
        np.testing.assert_array_equal(
            searchsorted_right(values, keys), np.searchsorted(values, keys, side="right")
        )
    with pytest.raises(ValueError, match="non-empty 1-D"):
        searchsorted_right(np.array([]), np.array([0.5]))


def test_flat_triangles_take_their_colour_as_the_interpolation_would():
    """Hits on a triangle whose corners share a colour get it without interpolating: the
    same bytes as the interpolation, at corners, edges, just outside and deep inside."""
    from naruto_gym.sensors.kernels import interpolate_corner_colours

    rng = np.random.default_rng(3)
    count = 500
    colours = rng.integers(0, 256, (count, 3, 3)).astype(np.uint8)
    colours[: count // 2] = colours[: count // 2, :1]  # half of them flat
    colours[0] = 0
    colours[1] = 255
    scene = Scene(rng.normal(size=(count * 3, 3)), np.arange(count * 3).reshape(count, 3), colours)
    hits = 20000
    triangle_ids = rng.integers(-1, count, hits).astype(np.int32)
    uv = rng.uniform(-1e-6, 1.0 + 1e-6, (hits, 2)).astype(np.float32)
    uv[::7] = rng.choice([0.0, 1.0, 0.5], (len(uv[::7]), 2)).astype(np.float32)
    rgb = scene.colour_at(triangle_ids, uv)
    interpolated = np.empty_like(rgb)
    nothing_flat = np.zeros_like(scene._flat_colours)
    interpolate_corner_colours(triangle_ids, uv, scene._corner_colours_f, nothing_flat,
                               interpolated)
    np.testing.assert_array_equal(rgb, interpolated)
    flat = (triangle_ids >= 0) & (triangle_ids < count // 2)
    np.testing.assert_array_equal(rgb[flat], colours[triangle_ids[flat], 0])
    assert (rgb[triangle_ids < 0] == 0).all()


def test_a_y_up_file_loaded_z_up_gets_a_warning(tmp_path) -> None:
    """A y-up mesh read with the default up axis lies on its side: say so and how to fix it."""
    import warnings

    import trimesh

    from naruto_gym.scenes import resolve_scene
    from naruto_gym.scenes.mesh_scene import load_scene

    scene = resolve_scene("two_rooms")
    x, y, z = scene.vertices.T
    path = tmp_path / "y_up.ply"
    trimesh.Trimesh(np.stack([x, z, -y], axis=1), scene.faces, process=False).export(path)
    with pytest.warns(UserWarning, match="up_axis='y'"):
        load_scene(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        upright = load_scene(path, up_axis="y")
        z_up = tmp_path / "z_up.ply"
        trimesh.Trimesh(scene.vertices, scene.faces, process=False).export(z_up)
        load_scene(z_up)
    np.testing.assert_allclose(np.ptp(upright.vertices, axis=0), np.ptp(scene.vertices, axis=0),
                               atol=1e-9)
