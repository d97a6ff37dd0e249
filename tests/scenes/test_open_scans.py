"""Open-scan variants: exact box subtraction, the openings, determinism, scene names."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
import trimesh

from naruto_gym.scenes.catalogue import catalogue_entry, load_catalogue_scene, resolve_scene
from naruto_gym.scenes.mesh_scene import Scene, scene_from_trimesh
from naruto_gym.scenes.open_scans import (
    building_envelope,
    faces_on_box_planes,
    fragment_boxes,
    open_scan_variant,
    opening_boxes,
    parse_openings,
    subtract_boxes,
)
from naruto_gym.sensors.raycaster import RayCaster


def _area(scene: Scene) -> float:
    triangles = scene.vertices[scene.faces]
    cross = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    return float(0.5 * np.linalg.norm(cross, axis=1).sum())


def _gradient_quad() -> Scene:
    """A 2 x 2 m quad in z = 0 whose red channel grows with x (0 at x = 0, 200 at x = 2)."""
    vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)
    colours = np.zeros((4, 4), np.uint8)
    colours[:, 0] = (vertices[:, 0] * 100).astype(np.uint8)
    colours[:, 3] = 255
    mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], vertex_colors=colours, process=False)
    return scene_from_trimesh(mesh, name="quad")


def test_subtract_box_removes_exactly_the_inside_area():
    quad = _gradient_quad()
    cut = subtract_boxes(quad, [[[0.5, 0.5, -1], [1.5, 1.5, 1]]])
    assert _area(cut) == pytest.approx(3.0, abs=1e-9)
    centroids = cut.vertices[cut.faces].mean(axis=1)
    inside = np.all((centroids[:, :2] > 0.5) & (centroids[:, :2] < 1.5), axis=1)
    assert not inside.any()
    # Two overlapping boxes remove their union; a box beside the mesh removes nothing.
    both = subtract_boxes(quad, [[[0, 0, -1], [1, 1, 1]], [[0.5, 0.5, -1], [1.5, 1.5, 1]]])
    assert _area(both) == pytest.approx(4.0 - 1.75, abs=1e-9)
    untouched = subtract_boxes(quad, [[[3, 3, -1], [4, 4, 1]]])
    np.testing.assert_array_equal(untouched.faces, quad.faces)


def test_subtract_box_interpolates_colours_at_new_corners():
    cut = subtract_boxes(_gradient_quad(), [[[0.5, -1, -1], [1.5, 3, 1]]])
    corners = cut.vertices[cut.faces].reshape(-1, 3)
    red = cut.corner_colours.reshape(-1, 3)[:, 0].astype(float)
    np.testing.assert_allclose(red, corners[:, 0] * 100, atol=1.0)
    assert np.isclose(corners[:, 0], 0.5).any() and np.isclose(corners[:, 0], 1.5).any()


def test_subtract_boxes_rejects_bad_boxes_and_total_removal():
    quad = _gradient_quad()
    with pytest.raises(ValueError, match="low < high"):
        subtract_boxes(quad, [[[1, 1, 1], [0, 2, 2]]])
    with pytest.raises(ValueError, match="every triangle"):
        subtract_boxes(quad, [[[-1, -1, -1], [3, 3, 1]]])


@pytest.fixture(scope="module")
def room():
    entry = catalogue_entry("replica_like_room")
    return entry.layout(), load_catalogue_scene("replica_like_room")


def _cast(scene: Scene, origins, directions) -> np.ndarray:
    caster = RayCaster(scene.vertices, scene.faces)
    directions = np.asarray(directions, np.float64)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return caster.cast_distance(np.asarray(origins, np.float32), directions.astype(np.float32))


def test_no_ceiling_opens_only_the_top(room):
    layout, closed = room
    width, depth, height = layout.size
    opened = open_scan_variant(layout, "no_ceiling", scene=closed)
    up = np.tile([[0.0, 0.0, 1.0]], (3, 1))
    points = [[1.0, 1.0, 1.5], [1.5, 3.8, 1.5], [4.0, 3.0, 2.0]]  # not under the fragment
    assert np.all(np.isfinite(_cast(closed, points, up)))
    assert np.all(np.isinf(_cast(opened, points, up)))
    # Walls and floor are still there.
    sideways = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, -1]]
    centre = np.tile([[width / 2, depth / 2, 1.2]], (5, 1))
    assert np.all(np.isfinite(_cast(opened, centre, sideways)))


def test_holes_and_missing_wall_let_rays_out(room):
    layout, closed = room
    opened = open_scan_variant(layout, "no_ceiling+holes+missing_wall", scene=closed)
    boxes = opening_boxes(layout, "no_ceiling+holes+missing_wall")
    assert len(boxes) == 5  # ceiling, floor hole, two wall holes, one wall
    caster_closed = RayCaster(closed.vertices, closed.faces)
    caster_open = RayCaster(opened.vertices, opened.faces)
    centre_of_room = np.array([2.5, 2.5, 1.5])
    for low, high in boxes[1:]:
        centre = (low + high) / 2
        # Look at the opening from 1 m outside the building, along its thin axis: the closed
        # scene stops the ray at its outer shell, the open one lets it into the room.
        axis = int(np.argmin(high - low))
        inward = np.zeros(3)
        inward[axis] = np.sign(centre_of_room[axis] - centre[axis])
        start = centre - inward * 1.0
        hit_open = caster_open.cast_distance(start[None], inward[None])[0]
        hit_closed = caster_closed.cast_distance(start[None], inward[None])[0]
        assert hit_closed < 1.01
        assert hit_open > 1.2, f"opening {low}..{high} does not open"


def test_variants_are_deterministic_and_keep_the_shipped_mesh(room):
    layout, closed = room
    digest_before = hashlib.sha256(closed.vertices.tobytes() + closed.faces.tobytes()).hexdigest()
    first = open_scan_variant(layout, "no_ceiling+holes", scene=closed, seed=3)
    second = open_scan_variant(layout, "no_ceiling+holes", scene=closed, seed=3)
    np.testing.assert_array_equal(first.vertices, second.vertices)
    np.testing.assert_array_equal(first.faces, second.faces)
    np.testing.assert_array_equal(first.corner_colours, second.corner_colours)
    other = open_scan_variant(layout, "no_ceiling+holes", scene=closed, seed=4)
    assert not np.array_equal(opening_boxes(layout, "holes", 3), opening_boxes(layout, "holes", 4))
    assert len(other.faces) != len(first.faces) or not np.array_equal(other.vertices,
                                                                        first.vertices)
    after = hashlib.sha256(closed.vertices.tobytes() + closed.faces.tobytes()).hexdigest()
    assert after == digest_before


def test_scan_drops_the_outer_shell_and_fragments_widen_the_bounds(room):
    layout, closed = room
    envelope = building_envelope(layout)
    np.testing.assert_allclose(closed.bounds, envelope, atol=1e-4)
    reference = open_scan_variant(layout, "fragments", scene=closed)
    assert faces_on_box_planes(closed, envelope).sum() > 0
    assert faces_on_box_planes(reference, envelope).sum() == 0
    fragments = fragment_boxes(layout)
    assert len(fragments) == 6
    assert np.all(reference.bounds[0] < envelope[0] - 1.0)
    assert np.all(reference.bounds[1] > envelope[1] + 1.0)
    # Seen from outside, a wall is now a single surface facing the room: its back shows.
    caster = RayCaster(reference.vertices, reference.faces)
    hits = caster.cast(np.array([[-0.6, 2.5, 1.2]], np.float32), np.array([[1, 0, 0]], np.float32))
    normal = reference.face_normals[hits.triangle_ids[0]]
    assert normal[0] > 0.9  # facing +x, into the room, away from this outside point


def test_parse_openings():
    assert parse_openings("holes+no_ceiling") == ("no_ceiling", "floor_hole", "wall_holes")
    assert parse_openings(["missing_wall"]) == ("missing_wall",)
    assert parse_openings("fragments") == ()
    with pytest.raises(ValueError, match="unknown scan opening 'roof'"):
        parse_openings("no_ceiling+roof")


def test_resolve_scene_names():
    scene = resolve_scene("two_rooms:no_ceiling+missing_wall")
    assert scene.name == "two_rooms:no_ceiling+missing_wall"
    assert resolve_scene("two_rooms:fragments").name == "two_rooms:fragments"
    with pytest.raises(ValueError, match="names no opening"):
        resolve_scene("two_rooms:")
    with pytest.raises(ValueError, match="unknown scan opening"):
        resolve_scene("two_rooms:attic")


def test_textured_scene_keeps_texture_coordinates():
    image = np.zeros((2, 2, 3), np.uint8)
    image[:, 1] = (0, 0, 255)
    image[:, 0] = (255, 0, 0)
    from PIL import Image

    vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], float)
    uv = vertices[:, :2] / 2.0
    material = trimesh.visual.material.SimpleMaterial(image=Image.fromarray(image))
    mesh = trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material))
    scene = scene_from_trimesh(mesh)
    cut = subtract_boxes(scene, [[[0.5, -1, -1], [1.5, 3, 1]]])
    assert cut.corner_uvs is not None and len(cut.face_texture_ids) == len(cut.faces)
    corners = cut.vertices[cut.faces].reshape(-1, 3)
    np.testing.assert_allclose(cut.corner_uvs.reshape(-1, 2), corners[:, :2] / 2.0, atol=1e-6)
