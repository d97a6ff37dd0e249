"""SdfVolume: grid geometry, trilinear lookup, and signed distances built from meshes."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.planning import SdfVolume
from tests.agent.planning.planning_scenes import (
    HOLLOW_BOX_CENTRE,
    ROOM_MAX,
    ROOM_MIN,
    SOLID_BOX_CENTRE,
    room_mesh,
)


def linear(points: np.ndarray) -> np.ndarray:
    return 0.3 * points[:, 0] - 1.2 * points[:, 1] + 2.0 * points[:, 2] + 0.5


def test_axis_order_is_x_y_z_and_origin_is_voxel_zero():
    volume = SdfVolume.from_function(
        lambda p: p[:, 0] + 10 * p[:, 1] + 100 * p[:, 2],
        np.array([[1.0, 2.0, 3.0], [1.5, 2.3, 3.2]]),
        voxel_size=0.1,
    )
    assert volume.shape == (6, 4, 3)
    np.testing.assert_allclose(volume.origin, [1.0, 2.0, 3.0])
    # values[i, j, k] belongs to origin + voxel_size * (i, j, k).
    expected = (1.0 + 0.1 * 2) + 10 * (2.0 + 0.1 * 1) + 100 * (3.0 + 0.1 * 2)
    assert volume.values[2, 1, 2] == pytest.approx(expected, rel=1e-6)
    np.testing.assert_allclose(volume.bounds, [[1.0, 2.0, 3.0], [1.5, 2.3, 3.2]], atol=1e-12)


def test_world_voxel_round_trip_and_grid_points():
    volume = SdfVolume(np.zeros((4, 5, 6), np.float32), np.array([-1.0, 0.5, 2.0]), 0.25)
    points = np.random.default_rng(0).uniform(-3, 3, size=(50, 3))
    np.testing.assert_allclose(volume.voxel_to_world(volume.world_to_voxel(points)), points)
    grid = volume.grid_points()
    assert grid.shape == (4 * 5 * 6, 3)
    np.testing.assert_allclose(volume.world_to_voxel(grid[7]), np.unravel_index(7, (4, 5, 6)))


def test_trilinear_is_exact_for_linear_functions_and_at_voxel_centres():
    bounds = np.array([[-1.0, 0.0, 0.5], [1.0, 2.0, 1.5]])
    volume = SdfVolume.from_function(linear, bounds, voxel_size=0.1)
    points = np.random.default_rng(1).uniform(bounds[0], bounds[1], size=(2000, 3))
    np.testing.assert_allclose(volume.sample(points), linear(points), atol=1e-5)
    curved = SdfVolume.from_function(lambda p: np.sin(3 * p).sum(axis=1), bounds, 0.1)
    np.testing.assert_allclose(curved.sample(curved.grid_points()), curved.values.ravel(),
                               atol=1e-6)
    # Upper faces interpolate inside the last cell instead of reading past the grid.
    corner = volume.bounds[1]
    assert volume.sample(corner)[0] == pytest.approx(linear(corner[None])[0], abs=1e-5)


def test_points_outside_read_outside_value():
    volume = SdfVolume.from_function(linear, np.array([[0.0, 0, 0], [1, 1, 1]]), 0.1)
    points = np.array([[0.5, 0.5, 0.5], [1.2, 0.5, 0.5], [0.5, -0.01, 0.5]])
    np.testing.assert_array_equal(volume.contains(points), [True, False, False])
    values = volume.sample(points)
    assert values[1] == -1.0 and values[2] == -1.0
    assert volume.sample(points, outside_value=7.0)[1] == 7.0


def test_bad_input_raises_value_error():
    with pytest.raises(ValueError, match="3-D"):
        SdfVolume(np.zeros((4, 4)), np.zeros(3), 0.1)
    with pytest.raises(ValueError, match="voxel_size"):
        SdfVolume(np.zeros((4, 4, 4)), np.zeros(3), 0.0)
    with pytest.raises(ValueError, match="origin"):
        SdfVolume(np.zeros((4, 4, 4)), np.zeros(2), 0.1)
    with pytest.raises(ValueError, match="faces"):
        SdfVolume.from_mesh(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="one value per point"):
        SdfVolume.from_function(lambda p: np.zeros(3), np.array([[0.0, 0, 0], [1, 1, 1]]))


def test_mesh_sdf_signs_and_distances(room_sdf, room_caster):
    free_points = np.array([[-1.0, 0.0, 1.2], [1.0, 0.0, 2.2], [-1.8, 1.2, 0.3]])
    occupied = np.array(
        [
            [0.0, -1.0, 1.0],  # inside the internal wall
            SOLID_BOX_CENTRE,  # inside the solid cabinet
            [ROOM_MAX[0] + 0.15, 0.0, 1.0],  # beyond the room's walls
            [0.0, 0.0, ROOM_MIN[2] - 0.15],  # under the floor
        ]
    )
    assert np.all(room_sdf.sample(free_points) > 0.2)
    assert np.all(room_sdf.sample(occupied) < 0.0)
    # The free pocket inside the hollow box is free space too (just unreachable).
    assert room_sdf.sample(HOLLOW_BOX_CENTRE)[0] > 0.2
    # At voxel centres the magnitude is the exact distance to the mesh.
    grid = room_sdf.grid_points()
    picks = np.random.default_rng(2).choice(len(grid), 500, replace=False)
    np.testing.assert_allclose(
        np.abs(room_sdf.values.ravel()[picks]), room_caster.unsigned_distance(grid[picks]),
        atol=1e-5,
    )


def test_mesh_sdf_tolerates_a_hole_in_the_room():
    mesh = room_mesh(doorway=True, furniture=False)
    # Punch a hole: drop two ceiling triangles of the room box (the first 12 faces).
    ceiling = np.flatnonzero(
        np.all(mesh.vertices[mesh.faces[:12]][:, :, 2] > ROOM_MAX[2] - 1e-6, axis=1)
    )
    assert len(ceiling) == 2
    keep = np.setdiff1d(np.arange(len(mesh.faces)), ceiling)
    volume = SdfVolume.from_mesh(mesh.vertices, mesh.faces[keep], voxel_size=0.1)
    assert np.all(volume.sample(np.array([[-1.0, 0.5, 1.0], [1.0, -0.5, 1.5]])) > 0.2)
    assert volume.sample(np.array([[ROOM_MAX[0] + 0.15, 0.0, 1.0]]))[0] < 0.0


def test_replica_cameras_are_in_free_space(replica_dir):
    from naruto_gym.scenes.mesh_scene import load_scene

    volume = SdfVolume.from_mesh(load_scene(replica_dir / "mesh.ply"), voxel_size=0.1)
    poses = np.loadtxt(replica_dir / "traj.txt").reshape(-1, 4, 4)
    distances = volume.sample(poses[::10, :3, 3])
    # The human-made scan trajectory stays in the room: the SDF says free almost everywhere.
    assert np.mean(distances > 0.0) > 0.98
    # And the walls are where the mesh says: a point 0.3 m beyond the bounds is not free.
    assert volume.sample(volume.bounds[1] - 0.01)[0] < 0.0
