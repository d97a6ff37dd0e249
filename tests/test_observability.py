"""Observable surface: what some free viewpoint inside the scene can see."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from naruto_gym.evaluation.metrics import reconstruction_metrics
from naruto_gym.observability import (
    ObservableSurface,
    inside_free_space_many,
    is_inside_free_space,
    sample_free_positions,
    visible_from_any,
    visible_from_any_per_viewpoint,
)
from naruto_gym.observability_kernels import (
    cone_hides,
    segment_crosses_triangle,
    shadow_cone,
    shadow_holds_ball,
)
from naruto_gym.scenes.mesh_scene import scene_from_trimesh
from naruto_gym.sensors.raycaster import RayCaster


def _box(centre, extents) -> trimesh.Trimesh:
    transform = np.eye(4)
    transform[:3, 3] = centre
    return trimesh.creation.box(extents=extents, transform=transform)


def _walled_room_with_cube():
    """A 4 x 4 x 2.5 m room of 0.2 m thick solid slabs, a 0.5 m cube standing on the floor."""
    slabs = [
        _box((0, 0, -0.1), (4.4, 4.4, 0.2)),
        _box((0, 0, 2.6), (4.4, 4.4, 0.2)),
        _box((2.1, 0, 1.25), (0.2, 4.4, 2.5)),
        _box((-2.1, 0, 1.25), (0.2, 4.4, 2.5)),
        _box((0, 2.1, 1.25), (4.4, 0.2, 2.5)),
        _box((0, -2.1, 1.25), (4.4, 0.2, 2.5)),
        _box((0.5, 0.5, 0.25), (0.5, 0.5, 0.5)),
    ]
    return scene_from_trimesh(trimesh.util.concatenate(slabs))


def _observable():
    scene = _walled_room_with_cube()
    caster = RayCaster(scene.vertices, scene.faces)
    return scene, caster, ObservableSurface(caster, scene.face_normals, scene.bounds, 64)


def test_free_positions_are_inside_the_room_and_clear():
    scene, caster, _ = _observable()
    positions = sample_free_positions(
        caster, scene.face_normals, scene.bounds, 50, 0.1, np.random.default_rng(0)
    )
    assert len(positions) == 50
    assert np.all(np.abs(positions[:, :2]) < 2.0)
    assert np.all((positions[:, 2] > 0.0) & (positions[:, 2] < 2.5))
    assert np.all(caster.unsigned_distance(positions) >= 0.1)


def test_inner_faces_observable_outer_faces_and_cube_bottom_not():
    _, _, observable = _observable()
    points = np.array(
        [
            [1.99, 0.3, 1.0],  # inner face of the +x wall
            [2.2, 0.3, 1.0],  # outer face of the +x wall
            [0.3, -0.4, 2.5],  # ceiling, seen from below
            [0.3, -0.4, 2.7],  # top of the ceiling slab
            [0.5, 0.5, 0.5],  # top of the cube
            [0.5, 0.6, 0.0],  # floor under the cube (its bottom)
        ]
    )
    assert observable.mask(points).tolist() == [True, False, True, False, True, False]


def test_visible_from_any_respects_occlusion_and_range():
    wall = _box((0, 0, 0), (0.1, 2.0, 2.0))
    caster = RayCaster(wall.vertices, wall.faces)
    points = np.array([[0.05, 0.0, 0.0], [-0.05, 0.0, 0.0], [0.05, 0.9, 0.0]])
    viewpoint = np.array([[3.0, 0.0, 0.0]])
    assert visible_from_any(caster, points, viewpoint).tolist() == [True, False, True]
    assert visible_from_any(caster, points, viewpoint, max_range_m=2.0).tolist() == [
        False,
        False,
        False,
    ]


def test_metrics_report_completion_over_observable_surface():
    scene, _, observable = _observable()
    # A reconstruction of exactly the observable part: standard completion ratio stays far
    # below 100 % (outer faces are missing), the observable one is about 100 %.
    samples = scene.sample_surface(300_000, seed=3)
    reconstruction = samples[observable.mask(samples)]
    metrics = reconstruction_metrics(
        reconstruction, scene, num_samples=40_000, observable_mask=observable.mask
    )
    assert metrics.completion_ratio_pct < 75.0
    assert metrics.observable_completion_ratio_pct > 97.0
    assert 20.0 < metrics.observable_share_pct < 75.0


class _CountingCaster(RayCaster):
    """A real caster that also counts the rays it casts."""

    rays = 0

    def cast_packed(self, rays: np.ndarray):
        self.rays += len(rays)
        return super().cast_packed(rays)


@pytest.mark.parametrize("scene_name", ["replica_like_room", "two_rooms", "procedural:room:7"])
def test_visible_from_any_equals_the_per_viewpoint_loop(scene_name):
    from naruto_gym.scenes.catalogue import resolve_scene

    scene = resolve_scene(scene_name)
    caster = _CountingCaster(scene.vertices, scene.faces)
    viewpoints = sample_free_positions(
        caster, scene.face_normals, scene.bounds, 96, 0.1, np.random.default_rng(1)
    )
    points = scene.sample_surface(6000, seed=2)
    caster.rays = 0
    fast = visible_from_any(caster, points, viewpoints)
    certified_rays = caster.rays
    caster.rays = 0
    reference = visible_from_any_per_viewpoint(caster, points, viewpoints)
    assert np.array_equal(fast, reference)
    assert 0.2 < fast.mean() < 0.9  # both kinds of points are present
    # Remembered blockers spare most rays (those of the points nobody sees, above all).
    assert certified_rays < caster.rays / 4
    # Range limit, tolerance, viewpoints tested one by one or in balls: the same mask.
    for kwargs in ({"max_range_m": 2.5}, {"tolerance_m": 0.1}, {"ball_size": 1},
                   {"ball_size": 4, "blocker_slots": 1}):
        assert np.array_equal(
            visible_from_any(caster, points, viewpoints, **kwargs),
            visible_from_any_per_viewpoint(
                caster, points, viewpoints,
                **{k: v for k, v in kwargs.items() if k in ("max_range_m", "tolerance_m")},
            ),
        )


def test_visible_from_any_agrees_where_a_hit_lies_at_the_tolerance():
    # A 2 cm thick panel on a wall, points on its back, each straight behind a viewpoint: the
    # panel's front lies exactly the tolerance in front of them, so casts end within rounding
    # of the tolerance; such pairs are re-cast forward, as the per-viewpoint loop casts them.
    panel = trimesh.util.concatenate([
        _box((0.0, 0.0, 0.0), (0.02, 1.0, 1.0)),
        _box((-0.11, 0.0, 0.0), (0.2, 3.0, 3.0)),
    ])
    caster = RayCaster(panel.vertices, panel.faces)
    rng = np.random.default_rng(0)
    across = rng.uniform(-0.45, 0.45, (64, 2))
    points = np.column_stack([np.full(64, -0.01), across])
    viewpoints = np.column_stack([rng.uniform(0.5, 3.0, 64), across])
    for tolerance in (0.02, 0.0199, 0.0201):
        assert np.array_equal(
            visible_from_any(caster, points, viewpoints, tolerance_m=tolerance),
            visible_from_any_per_viewpoint(caster, points, viewpoints, tolerance_m=tolerance),
        )
    assert visible_from_any(caster, points, viewpoints, tolerance_m=0.0201).all()
    assert not visible_from_any(caster, points, viewpoints, tolerance_m=0.0199).any()


def test_segment_crosses_triangle_only_well_inside():
    triangles = np.array([[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]])

    def crosses(origin, delta, margin=1e-5):
        return segment_crosses_triangle(*origin, *delta, triangles, 0, margin)

    assert crosses((0.2, 0.2, 1.0), (0.0, 0.0, -2.0))
    assert crosses((0.2, 0.2, -1.0), (0.0, 0.0, 2.0))  # from behind too
    assert not crosses((0.2, 0.2, 1.0), (0.0, 0.0, -0.9))  # stops short of it
    assert not crosses((0.2, 0.2, 1.0), (0.0, 0.0, -1.0))  # ends on it: not well inside
    assert not crosses((0.6, 0.6, 1.0), (0.0, 0.0, -2.0))  # beside it
    assert not crosses((0.0, 0.5, 1.0), (0.0, 0.0, -2.0))  # on its edge
    assert not crosses((0.2, 0.2, 1.0), (1.0, 0.0, 0.0))  # parallel


def test_visible_from_any_rejects_bad_blocker_slots():
    wall = _box((0, 0, 0), (0.1, 2.0, 2.0))
    caster = RayCaster(wall.vertices, wall.faces)
    with pytest.raises(ValueError, match="blocker_slots and ball_size"):
        visible_from_any(caster, np.zeros((1, 3)), np.ones((1, 3)), blocker_slots=0)


def test_shadow_holds_ball_only_inside_the_cone_beyond_the_triangle():
    # A large triangle in the plane z = 0, the point 0.5 m below it.
    triangles = np.array([[[-4.0, -4.0, 0.0], [4.0, -4.0, 0.0], [0.0, 4.0, 0.0]]])
    normals = np.array([[0.0, 0.0, 1.0]])
    offsets = np.zeros(1)

    def hidden(centre, radius, point=(0.0, 0.0, -0.5), tolerance=0.02):
        return shadow_holds_ball(
            *point, triangles, normals, offsets, 0, *centre, radius, tolerance
        )

    assert hidden((0.0, 0.0, 2.0), 0.5)
    assert not hidden((0.0, 0.0, 2.0), 2.5)  # reaches below the plane
    assert not hidden((0.0, 0.0, -2.0), 0.1)  # on the point's side
    assert not hidden((12.0, 0.0, 2.0), 0.5)  # outside the cone through the triangle
    assert not hidden((0.0, 0.0, 2.0), 0.5, point=(0.0, 0.0, -0.01))  # within the tolerance


def _inside_one_point(caster, normals, position, share):
    """The whole-sphere free-space test of one point, written out (the reference)."""
    from naruto_gym.sensors.panorama import EquirectangularCamera

    directions = EquirectangularCamera(16, 32).ray_directions
    hits = caster.cast(np.asarray(position, np.float32), directions)
    hit = hits.hit_mask
    if 1.0 - hit.mean() > share or not hit.any():
        return False
    facing = np.einsum("ij,ij->i", normals[hits.triangle_ids[hit]], directions[hit]) < 0
    return bool(facing.mean() >= 0.9)


def test_batched_free_space_test_and_sampling_match_the_one_point_test():
    from naruto_gym.scenes.catalogue import resolve_scene

    scene = resolve_scene("replica_like_room:no_ceiling+holes")
    caster = RayCaster(scene.vertices, scene.faces)
    normals = scene.face_normals
    points = np.random.default_rng(1).uniform(scene.bounds[0], scene.bounds[1], (200, 3))
    for share in (0.5, 0.2):
        expected = [_inside_one_point(caster, normals, p, share) for p in points]
        assert inside_free_space_many(caster, normals, points, share).tolist() == expected
        assert inside_free_space_many(caster, normals, points, share, chunk=7).tolist() == expected
        assert [is_inside_free_space(caster, normals, p, share) for p in points] == expected
        assert 0 < sum(expected) < len(expected)
        # Sampling with the batched test (the default) keeps the one-point test's positions.
        one_by_one = sample_free_positions(
            caster, normals, scene.bounds, 40, 0.1, np.random.default_rng(4), share,
            is_inside=lambda p, s=share: _inside_one_point(caster, normals, p, s),
        )
        batched = sample_free_positions(
            caster, normals, scene.bounds, 40, 0.1, np.random.default_rng(4), share
        )
        np.testing.assert_array_equal(batched, one_by_one)


def test_sampling_with_a_batched_test_keeps_the_first_accepted_candidates():
    scene, caster, _ = _observable()
    low_half = (lambda p: p[2] < 1.0, lambda ps: np.asarray(ps)[:, 2] < 1.0)
    for count in (1, 7, 50):
        one_by_one = sample_free_positions(
            caster, scene.face_normals, scene.bounds, count, 0.1, np.random.default_rng(2),
            is_inside=low_half[0],
        )
        batched = sample_free_positions(
            caster, scene.face_normals, scene.bounds, count, 0.1, np.random.default_rng(2),
            is_inside=low_half[0], is_inside_many=low_half[1],
        )
        assert len(batched) == count
        np.testing.assert_array_equal(batched, one_by_one)
        assert np.all(batched[:, 2] < 1.0)


def test_precomputed_shadow_cone_agrees_with_the_ball_test_and_the_segment_test():
    rng = np.random.default_rng(3)
    triangles = rng.uniform(-1.0, 1.0, (300, 3, 3))
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    offsets = np.einsum("ij,ij->i", normals, triangles[:, 0])
    cone = np.empty((4, 4))
    hidden_count = 0
    for face in range(len(triangles)):
        point = rng.uniform(-2.0, 2.0, 3)
        usable = shadow_cone(*point, triangles, normals, offsets, face, 0.02, cone)
        for viewpoint in rng.uniform(-4.0, 4.0, (20, 3)):
            by_ball = shadow_holds_ball(
                *point, triangles, normals, offsets, face, *viewpoint, 0.0, 0.02
            )
            hidden = usable and cone_hides(cone, *point, *viewpoint)
            assert hidden == by_ball
            if hidden:
                # The segment from the viewpoint to 2 cm short of the point crosses it.
                offset = point - viewpoint
                distance = np.linalg.norm(offset)
                delta = offset / distance * (distance - 0.02)
                assert segment_crosses_triangle(*viewpoint, *delta, triangles, face, 1e-6)
                hidden_count += 1
    assert hidden_count > 50


def test_visible_from_any_in_chunks_of_points_gives_the_same_mask(monkeypatch):
    import naruto_gym.observability as observability

    scene, caster, observable = _observable()
    points = scene.sample_surface(3000, seed=5)
    whole = visible_from_any(caster, points, observable.viewpoints)
    monkeypatch.setattr(observability, "_POINTS_PER_CHUNK", 701)
    np.testing.assert_array_equal(visible_from_any(caster, points, observable.viewpoints), whole)
    assert 0.2 < whole.mean() < 0.9
