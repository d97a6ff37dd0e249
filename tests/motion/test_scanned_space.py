"""The scanned space and the escape rules on small synthetic scans (no ceiling, a floor hole)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_gym.motion.collision import CollisionChecker
from naruto_gym.motion.scanned_space import (
    ScannedSpace,
    ScannedSpaceConfig,
    cap_directions,
    support_directions,
    surface_top,
)
from naruto_gym.scenes.mesh_scene import face_normals_of
from naruto_gym.sensors.panorama import EquirectangularCamera, no_hit_share, render_panorama
from naruto_gym.sensors.raycaster import RayCaster

# Generous bounds, as a scan whose stray fragments reach far beyond the room.
WIDE_BOUNDS = np.array([[-3.0, -3.0, -1.0], [3.0, 3.0, 5.0]])


def _box(low, high) -> trimesh.Trimesh:
    return trimesh.creation.box(bounds=np.array([low, high], float))


def _open_top_room(floor_hole: bool = False) -> trimesh.Trimesh:
    """A 4 x 4 m room with 2 m solid walls and no ceiling; optionally a 1 x 1 m floor hole."""
    if floor_hole:
        floor = [_box((-2, -2, -0.1), (-0.5, 2, 0)), _box((0.5, -2, -0.1), (2, 2, 0)),
                 _box((-0.5, -2, -0.1), (0.5, -0.5, 0)), _box((-0.5, 0.5, -0.1), (0.5, 2, 0))]
    else:
        floor = [_box((-2, -2, -0.1), (2, 2, 0))]
    walls = [_box((-2.1, -2.1, -0.1), (-2, 2.1, 2)), _box((2, -2.1, -0.1), (2.1, 2.1, 2)),
             _box((-2, -2.1, -0.1), (2, -2, 2)), _box((-2, 2, -0.1), (2, 2.1, 2))]
    return trimesh.util.concatenate(floor + walls)


def _space(mesh: trimesh.Trimesh, bounds=WIDE_BOUNDS) -> ScannedSpace:
    caster = RayCaster(mesh.vertices, mesh.faces)
    return ScannedSpace(caster, face_normals_of(mesh.vertices, mesh.faces), bounds)


@pytest.fixture(scope="module")
def room() -> ScannedSpace:
    return _space(_open_top_room())


def _interior_grid() -> np.ndarray:
    axes = [np.linspace(-1.7, 1.7, 6), np.linspace(-1.7, 1.7, 6), np.linspace(0.2, 1.8, 5)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def test_cap_directions_are_unit_inside_the_cap_and_uniform():
    directions = cap_directions(400, 60.0, np.array([0.0, 0.0, -1.0]))
    assert directions.shape == (400, 3)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-6)
    assert np.all(-directions[:, 2] >= np.cos(np.deg2rad(60.0)) - 1e-6)
    # Uniform in solid angle: half of the cap's solid angle lies within 41.4 degrees.
    within = -directions[:, 2] >= 0.75
    assert within.mean() == pytest.approx(0.5, abs=0.02)
    assert np.linalg.norm(directions[:, :2].mean(axis=0)) < 0.02


def test_surface_top_ignores_small_fragments_high_above():
    room = _open_top_room()
    fragment = _box((0, 0, 4.0), (0.2, 0.2, 4.2))
    mesh = trimesh.util.concatenate([room, fragment])
    top = surface_top(mesh.vertices, mesh.faces, 0.99)
    assert 1.8 < top <= 2.0


def test_open_top_room_interior_is_inside_everywhere(room):
    points = _interior_grid()
    assert room.evaluate(points).all()
    assert room.contains_many(points).all()


@pytest.mark.parametrize(
    "point, why",
    [
        ((0.0, 0.0, 2.6), "above the walls"),
        ((0.0, 1.0, 4.0), "far above the room"),
        ((2.6, 0.0, 1.0), "outside a wall"),
        ((-2.8, -2.8, 0.5), "outside a corner"),
        ((0.0, 0.0, -0.5), "under the floor"),
        ((2.05, 0.0, 1.0), "inside a wall"),
    ],
)
def test_points_outside_the_scan(room, point, why):
    assert not room.is_inside(np.array(point)), why
    if why != "inside a wall":  # the per-step test leaves solids to the collision check
        assert not room.evaluate(np.array(point))[0], why
        assert not room.contains(np.array(point)), why


def test_floor_hole_is_inside_from_high_up_but_not_down_in_it():
    space = _space(_open_top_room(floor_hole=True))
    assert space.contains(np.array([0.0, 0.0, 1.5]))
    assert space.contains(np.array([0.0, 1.2, 0.3]))  # low, beside the hole
    assert not space.contains(np.array([0.0, 0.0, 0.15]))  # sinking into the hole
    assert not space.contains(np.array([0.0, 0.0, -0.5]))  # through it


def test_lattice_agrees_with_exact_test_away_from_the_boundary(room):
    rng = np.random.default_rng(0)
    points = rng.uniform(WIDE_BOUNDS[0], WIDE_BOUNDS[1], size=(400, 3))
    # Keep points at least 0.25 m from the room's boundary (walls, floor, top): there the
    # lattice's 0.1 m interpolation cannot disagree with the exact test.
    inner = np.all(np.abs(points[:, :2]) < 1.75, axis=1) & (points[:, 2] > 0.25) & (
        points[:, 2] < room.top_m - 0.25
    )
    outer = (np.any(np.abs(points[:, :2]) > 2.35, axis=1)) | (points[:, 2] > room.top_m + 0.25)
    chosen = points[inner | outer]
    np.testing.assert_array_equal(room.contains_many(chosen), room.evaluate(chosen))
    assert room.contains_many(points[inner]).all()
    assert not room.contains_many(points[outer]).any()


def _count_casts(raycaster: RayCaster, calls: list[int]) -> None:
    """Append the ray count of every cast (first hits or any hit: all rays go through these
    two) to ``calls``."""
    for name in ("cast_packed", "hits_any_packed"):
        query = getattr(raycaster, name)
        setattr(raycaster, name,
                lambda rays, query=query: calls.append(len(rays)) or query(rays))


def test_a_visited_cell_is_answered_without_casting():
    space = _space(_open_top_room())
    calls = []
    _count_casts(space.raycaster, calls)
    position = np.array([0.31, -0.42, 1.23])
    assert space.contains(position)
    assert len(calls) == 1
    for _ in range(5):
        assert space.contains(position + 0.01)  # same cell
    assert len(calls) == 1
    assert 0 < space.evaluated_share < 0.0001


def test_fill_evaluates_the_whole_lattice():
    mesh = _open_top_room()
    small = ScannedSpace(
        RayCaster(mesh.vertices, mesh.faces), face_normals_of(mesh.vertices, mesh.faces),
        np.array([[-2.1, -2.1, -0.1], [2.1, 2.1, 2.0]]), ScannedSpaceConfig(voxel_m=0.2),
    )
    small.fill()
    assert small.evaluated_share == 1.0
    assert small.contains(np.array([0.0, 0.0, 1.0]))


def test_config_is_validated():
    with pytest.raises(ValueError, match="voxel_m"):
        ScannedSpaceConfig(voxel_m=0)
    with pytest.raises(ValueError, match="max_empty_sectors"):
        ScannedSpaceConfig(max_empty_sectors=8)
    with pytest.raises(ValueError, match="support_half_angle_deg"):
        ScannedSpaceConfig(support_half_angle_deg=120)


# -- the escape rules in the collision checker -------------------------------------------
def _checker(rule: str, mesh: trimesh.Trimesh | None = None) -> CollisionChecker:
    mesh = mesh if mesh is not None else _open_top_room()
    caster = RayCaster(mesh.vertices, mesh.faces)
    return CollisionChecker(caster, WIDE_BOUNDS, 0.05, escape_rule=rule)


def test_scanned_space_rule_keeps_the_agent_in_and_lets_it_roam():
    checker = _checker("scanned_space")
    position = np.array([0.0, 0.3, 1.0])
    for _ in range(60):  # fly up: stopped at the top of the walls
        result = checker.move(position, position + np.array([0.0, 0.0, 0.1]))
        position = result.position
    assert result.collided and result.reason == "escape"
    assert 1.8 < position[2] <= checker.scanned_space.top_m
    # Everywhere in the room, at any height up to the walls' top, moves are allowed.
    rng = np.random.default_rng(1)
    for start in _interior_grid():
        step = rng.normal(size=3)
        result = checker.move(start, start + 0.1 * step / np.linalg.norm(step))
        assert result.reason != "escape", start


def test_agent_placed_outside_may_only_come_back():
    checker = _checker("scanned_space")
    outside = np.array([2.6, 0.0, 1.0])  # beyond the east wall, on no floor
    further = checker.move(outside, outside + np.array([0.1, 0.0, 0.0]))
    assert further.collided and further.reason == "escape"
    np.testing.assert_allclose(further.position, outside)
    back = checker.move(outside, outside + np.array([-0.1, 0.0, 0.0]))
    assert not back.collided


def _floor_scan() -> trimesh.Trimesh:
    """A scan of a floor with a tall box on it and nothing else (like habitat-sim's test room)."""
    return trimesh.util.concatenate(
        [_box((-4, -4, -0.1), (4, 4, 0)), _box((2.5, 2.5, 0), (3.5, 3.5, 3))]
    )


@pytest.mark.parametrize(
    "mesh, walls", [(_open_top_room(), True), (_floor_scan(), False)], ids=["room", "floor"]
)
def test_published_rule_refuses_by_the_whole_sphere_share(mesh, walls):
    checker = _checker("published", mesh)
    scanned = _checker("scanned_space", mesh)
    camera = EquirectangularCamera(32, 64)
    refused = 0
    for start in _interior_grid():
        end = start + np.array([0.0, 0.05, 0.0])
        share = no_hit_share(render_panorama(checker.raycaster, camera, end))
        result = checker.move(start, end)
        assert (result.reason == "escape") == (share > 0.5)
        refused += result.reason == "escape"
        assert scanned.move(start, end).reason != "escape"
    if not walls:  # nothing above and nothing around: the published rule refuses most moves
        assert refused >= 0.8 * len(_interior_grid()), refused


def test_escape_settings_are_validated():
    caster = RayCaster(_open_top_room().vertices, _open_top_room().faces)
    with pytest.raises(ValueError, match="escape_rule"):
        CollisionChecker(caster, WIDE_BOUNDS, escape_rule="walls")
    with pytest.raises(ValueError, match="escape_no_hit_threshold"):
        CollisionChecker(caster, WIDE_BOUNDS, escape_no_hit_threshold=1.5)
    off = CollisionChecker(caster, WIDE_BOUNDS, escape_no_hit_threshold=None)
    assert off.escape_rule == "off"
    assert not off.sees_escape(np.array([0.0, 0.0, 4.5]))


def test_batched_query_answers_as_the_point_query_with_one_cast_per_batch():
    """contains_many (what the batched env asks every step) gives contains' answers, near
    walls, floor, the hole and the top too, and probes all new corners in one cast."""
    mesh = _open_top_room(floor_hole=True)
    one_by_one, batched = _space(mesh), _space(mesh)
    rng = np.random.default_rng(1)
    points = np.concatenate([
        rng.uniform(WIDE_BOUNDS[0], WIDE_BOUNDS[1], size=(300, 3)),
        rng.uniform([-2.05, -2.05, -0.05], [2.05, 2.05, 2.3], size=(300, 3)),  # near surfaces
        rng.uniform([-0.6, -0.6, -0.3], [0.6, 0.6, 0.4], size=(100, 3)),  # at the hole
    ])
    clearances = batched.raycaster.unsigned_distance(points)
    expected = np.array([one_by_one.contains(p, float(c)) for p, c in
                         zip(points, clearances, strict=True)])
    assert 0.2 < expected.mean() < 0.8  # both answers are well represented
    calls = []
    _count_casts(batched.raycaster, calls)
    np.testing.assert_array_equal(batched.contains_many(points, clearances), expected)
    # New corners in one staged probe (steepest ring, then the rest where needed), corner-less
    # points in one more.
    assert len(calls) <= 4
    np.testing.assert_array_equal(batched.contains_many(points), expected)
    np.testing.assert_array_equal(batched._empty >= 0, one_by_one._empty >= 0)
    # One point at a time (an agent alone in its scene), with and without its clearance.
    single = _space(mesh)
    for point, clearance, answer in zip(points[::7], clearances[::7], expected[::7], strict=True):
        assert single.contains_many(point[None], np.array([clearance])).tolist() == [answer]
        assert single.contains_many(point[None]).tolist() == [answer]


def test_staged_support_count_equals_the_full_probe():
    """empty_sectors casts the steepest ring first and the rest only where it leaves a sector
    empty; the counts are the full probe's, over floor, hole, edges and outside."""
    space = _space(_open_top_room(floor_hole=True))
    rng = np.random.default_rng(2)
    points = np.concatenate([
        rng.uniform(WIDE_BOUNDS[0], WIDE_BOUNDS[1], size=(400, 3)),
        rng.uniform([-0.7, -0.7, -0.2], [0.7, 0.7, 0.6], size=(200, 3)),  # the hole
        rng.uniform([1.8, -2.2, 0.0], [2.4, 2.2, 1.0], size=(200, 3)),  # a wall's line
    ])
    full = space.probe(points)[0]
    np.testing.assert_array_equal(space.empty_sectors(points), full)
    assert (full == 0).mean() > 0.2 and (full > 0).mean() > 0.2
    assert len(np.unique(full)) > 3


def test_start_test_of_many_points_answers_as_one_by_one():
    """is_inside_many (viewpoints and start poses, drawn in batches) is is_inside per point:
    supported and facing, over the floor, the hole, outside and inside the walls."""
    space = _space(_open_top_room(floor_hole=True))
    rng = np.random.default_rng(3)
    points = np.concatenate([
        rng.uniform(WIDE_BOUNDS[0], WIDE_BOUNDS[1], size=(300, 3)),
        rng.uniform([-2.1, -2.1, -0.1], [2.1, 2.1, 2.2], size=(300, 3)),  # walls' insides too
    ])
    expected = np.array([space.is_inside(p) for p in points])
    assert 0.2 < expected.mean() < 0.8
    np.testing.assert_array_equal(space.is_inside_many(points), expected)
    checker = CollisionChecker(space.raycaster, WIDE_BOUNDS, escape_no_hit_threshold=0.5)
    np.testing.assert_array_equal(checker.start_test_many()(points), expected)
    published = CollisionChecker(space.raycaster, WIDE_BOUNDS, escape_no_hit_threshold=0.5,
                                 escape_rule="published")
    one_by_one = np.array([published.start_test()(p) for p in points])
    np.testing.assert_array_equal(published.start_test_many()(points), one_by_one)


def test_sectors_seen_are_those_of_the_rays_that_hit():
    """A sector is seen when any of its rays hit, ring by ring: the reshape that reads them
    agrees with the sector labels of ``support_directions``, for the first ring alone, the
    other rings, and all of them."""
    space = _space(_open_top_room(floor_hole=True))
    _, sectors = support_directions(space.config)
    per_ring = space.config.support_sectors * space.config.rays_per_sector
    rng = np.random.default_rng(4)
    for labels in (sectors[:per_ring], sectors[per_ring:], sectors):
        hit = rng.random((50, len(labels))) < 0.03
        expected = np.stack([hit[:, labels == s].any(axis=1)
                             for s in range(space.config.support_sectors)], axis=1)
        np.testing.assert_array_equal(space._seen_sectors(hit), expected)
        assert expected.any() and not expected.all()
