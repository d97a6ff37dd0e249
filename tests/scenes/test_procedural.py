"""The procedural scene generator: determinism, sizes, closed rooms, doorways, free space."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from naruto_gym.scenes.catalogue import available_scenes, catalogue_entry
from naruto_gym.scenes.mesh_scene import Scene, load_scene
from naruto_gym.scenes.procedural import (
    FLOOR_THICKNESS_M,
    SceneLayout,
    generate_apartment,
    generate_layout,
    generate_room,
    make_random_scene,
    random_layout,
    save_scene_ply,
    scene_to_ply_bytes,
)
from naruto_gym.sensors.raycaster import RayCaster
from tests.scenes.layout_checks import (
    FURNITURE_EXCLUDED,
    assert_doorways_open,
    assert_furniture_clear,
    assert_rooms_joined,
)
from tests.scenes.layout_checks import reachable_rooms as _reachable_rooms


def _digest(scene: Scene) -> str:
    return hashlib.sha256(scene_to_ply_bytes(scene)).hexdigest()


def _unit_directions(count: int, seed: int) -> np.ndarray:
    directions = np.random.default_rng(seed).normal(size=(count, 3))
    return directions / np.linalg.norm(directions, axis=1, keepdims=True)


# ---------------------------------------------------------------------------------------
def test_same_seed_gives_byte_identical_mesh():
    assert scene_to_ply_bytes(generate_room(3)) == scene_to_ply_bytes(generate_room(3))
    first = generate_apartment(5, num_rooms=4, size=(10.0, 8.0, 2.7))
    second = generate_apartment(5, num_rooms=4, size=(10.0, 8.0, 2.7))
    assert scene_to_ply_bytes(first) == scene_to_ply_bytes(second)


def test_different_seeds_give_different_scenes():
    digests = {_digest(generate_room(seed)) for seed in range(4)}
    assert len(digests) == 4
    layouts = [generate_layout(seed, (12.0, 9.0, 2.8), 5) for seed in (0, 1)]
    assert [r.cell for r in layouts[0].rooms] != [r.cell for r in layouts[1].rooms]


@pytest.mark.parametrize("size", [(5.0, 5.0, 3.0), (4.2, 6.3, 2.6)])
def test_room_extents_match_requested_size(size):
    layout = generate_layout(2, size, 1)
    scene = layout.to_scene()
    t = layout.wall_thickness
    expected = np.array(size) + np.array([2 * t, 2 * t, 2 * FLOOR_THICKNESS_M])
    np.testing.assert_allclose(scene.extents, expected, atol=1e-4)
    # The free interior starts at the origin: floor at z = 0, inner wall faces at 0 and W.
    np.testing.assert_allclose(scene.bounds[0], [-t, -t, -FLOOR_THICKNESS_M], atol=1e-4)
    assert 1_000 <= len(scene.faces) <= 50_000


def test_apartment_has_rooms_doorways_and_size():
    layout = generate_layout(12, (12.0, 9.0, 2.8), 6)
    scene = layout.to_scene()
    assert len(layout.rooms) == 6
    assert max(scene.extents[:2]) >= 10.0
    assert len(scene.faces) <= 50_000
    # The cells tile the footprint exactly.
    assert sum(room.cell.area for room in layout.rooms) == pytest.approx(12.0 * 9.0)
    assert_rooms_joined(layout)


def _layouts_under_test() -> list[tuple[str, SceneLayout]]:
    cases = [(f"catalogue:{name}", catalogue_entry(name).layout()) for name in available_scenes()]
    cases += [(f"random_apartment:{seed}", random_layout(seed, "apartment")) for seed in (3, 8)]
    cases += [(f"random_room:{seed}", random_layout(seed, "room")) for seed in (4,)]
    return cases


@pytest.fixture(scope="module", params=_layouts_under_test(), ids=lambda case: case[0])
def built(request):
    _, layout = request.param
    scene = layout.to_scene()
    return layout, scene, RayCaster(scene.vertices, scene.faces)


def test_doorways_are_open(built):
    layout, _, caster = built
    assert_doorways_open(layout, caster)


def test_every_room_is_reachable_from_the_start(built):
    layout, _, caster = built
    reached = _reachable_rooms(layout, caster, z=1.5)
    assert reached == list(range(len(layout.rooms)))


def test_rooms_are_closed(built):
    layout, scene, caster = built
    directions = _unit_directions(3000, seed=0)
    lower, upper = scene.bounds[0] - 1e-3, scene.bounds[1] + 1e-3
    for point in [layout.start_position, *layout.room_points]:
        hits = caster.cast(np.asarray(point), directions)
        assert hits.hit_mask.all(), f"a ray escaped from {point}"
        ends = np.asarray(point) + directions * hits.distance[:, None]
        assert np.all((ends >= lower) & (ends <= upper))


def test_start_and_room_points_are_clear(built):
    layout, _, caster = built
    points = np.array([layout.start_position, *layout.room_points])
    assert np.all(caster.unsigned_distance(points) >= 0.3)
    assert layout.start_position in layout.room_points


def test_furniture_keeps_gaps_and_leaves_doorways_free(built):
    layout, _, _ = built
    assert_furniture_clear(layout)


def test_colours_are_varied():
    scene = generate_room(0)
    colours = scene.corner_colours.reshape(-1, 3)
    distinct = np.unique(colours // 16, axis=0)
    assert len(distinct) >= 40
    # Hue spread: red-, green- and blue-dominant surfaces all exist.
    dominant = np.argmax(colours.astype(int) - colours.mean(axis=1, keepdims=True), axis=1)
    saturated = colours.max(axis=1).astype(int) - colours.min(axis=1) > 60
    assert set(np.unique(dominant[saturated])) == {0, 1, 2}


def test_furniture_density_zero_leaves_only_decorations():
    layout = generate_layout(1, (5.0, 5.0, 3.0), 1, furniture_density=0.0)
    assert {o.kind for o in layout.objects} <= FURNITURE_EXCLUDED


@pytest.mark.parametrize("kind", ["room", "apartment"])
def test_make_random_scene(kind):
    scenes = [make_random_scene(seed, kind) for seed in (0, 1)]
    assert _digest(scenes[0]) != _digest(scenes[1])
    assert _digest(scenes[0]) == _digest(make_random_scene(0, kind))
    for seed, scene in enumerate(scenes):
        assert scene.name == f"{kind}_{seed}"
        if kind == "apartment":
            assert len(random_layout(seed, kind).rooms) >= 4
            assert max(scene.extents[:2]) >= 10.0
        else:
            assert 4.0 <= scene.extents[0] <= 7.5


def test_ply_round_trip(tmp_path):
    scene = generate_room(6, (4.0, 4.0, 2.6))
    path = save_scene_ply(scene, tmp_path / "nested" / "room.ply")
    loaded = load_scene(path)
    np.testing.assert_array_equal(loaded.vertices, scene.vertices)
    np.testing.assert_array_equal(loaded.faces, scene.faces)
    np.testing.assert_array_equal(loaded.corner_colours, scene.corner_colours)
    assert not list(tmp_path.rglob("*.tmp"))


def test_ply_splits_vertices_whose_corners_disagree(tmp_path):
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    colours = np.array([[[255, 0, 0]] * 3, [[0, 0, 255]] * 3], dtype=np.uint8)
    scene = Scene(vertices, faces, colours)
    loaded = load_scene(save_scene_ply(scene, tmp_path / "two.ply"))
    assert len(loaded.vertices) == 6
    np.testing.assert_array_equal(loaded.vertices[loaded.faces], vertices[faces])
    np.testing.assert_array_equal(loaded.corner_colours, colours)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"seed": -1}, "seed"),
        ({"seed": 1.5}, "seed"),
        ({"size": (1.0, 5.0, 3.0)}, "at least 2 m"),
        ({"size": (5.0, 5.0)}, "three positive"),
        ({"size": (5.0, 5.0, 2.0)}, "door_height"),
        ({"num_rooms": 0}, "num_rooms"),
        ({"size": (5.0, 5.0, 3.0), "num_rooms": 5}, "cannot split"),
        ({"furniture_density": -1.0}, "furniture_density"),
    ],
)
def test_bad_settings_raise_clear_errors(kwargs, message):
    arguments = {"seed": 0, "size": (5.0, 5.0, 3.0), "num_rooms": 1} | kwargs
    with pytest.raises(ValueError, match=message):
        generate_layout(**arguments)


def test_bad_kind_and_room_count_raise():
    with pytest.raises(ValueError, match="kind"):
        make_random_scene(0, "castle")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="num_rooms >= 2"):
        generate_apartment(0, num_rooms=1)


def test_flat_shading_matches_the_array_shading_bit_for_bit():
    from naruto_gym.scenes.procedural.mesh_builder import flat_shade, shade

    rng = np.random.default_rng(0)
    normals = _unit_directions(300, 1)
    normals[:6] = np.concatenate([np.eye(3), -np.eye(3)])
    for normal in normals:
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        assert flat_shade(colour, normal) == tuple(shade(colour, normal[None])[0])
