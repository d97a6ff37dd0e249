"""Observable surface: what some free viewpoint inside the scene can see."""

from __future__ import annotations

import numpy as np
import trimesh

from naruto_gym.evaluation.metrics import reconstruction_metrics
from naruto_gym.observability import ObservableSurface, sample_free_positions, visible_from_any
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
