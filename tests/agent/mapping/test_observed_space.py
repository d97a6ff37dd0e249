"""What the agent has measured of space: frontier, support from below, the scan's top."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.mapping.observed_space import ObservedSpace, ObservedSpaceConfig
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.sensors.pinhole import PinholeCamera

BOUNDS = np.array([[0.0, 0.0, 0.0], [4.0, 4.0, 3.0]])


def _space(**config) -> ObservedSpace:
    space = ObservedSpace(BOUNDS, ObservedSpaceConfig(**config))
    return space


def _mark(space: ObservedSpace, occupied: np.ndarray | None = None,
          free: np.ndarray | None = None) -> None:
    """Set voxel states directly (boolean (nx, ny, nz) masks)."""
    grid = space.grid
    for mask, value in ((occupied, 3.0), (free, -2.0)):
        if mask is not None:
            grid.log_odds[mask] = value
            grid.observed[mask] = True
    space.configure()  # drop cached frontier and support


def _floor_room() -> tuple[ObservedSpace, np.ndarray]:
    """A measured floor under x < 2 m only (a scan that ends there); free air above the
    whole grid up to 2 m, unknown above."""
    space = _space()
    shape = space.grid.shape
    floor = np.zeros(shape, bool)
    floor[:20, :, 0] = True
    free = np.zeros(shape, bool)
    free[:, :, 1:20] = True
    _mark(space, occupied=floor, free=free)
    return space, floor


def test_support_needs_measured_surface_below_within_reach() -> None:
    space, _ = _floor_room()
    supported = space.supported()
    centre = space.cells_of(np.array([[1.0, 2.0, 1.0]]))[0][0]
    assert supported[tuple(centre)]
    # Within support_reach_m (0.3 m) past the floor's edge: still supported.
    near_edge = space.cells_of(np.array([[2.2, 2.0, 1.0]]))[0][0]
    assert supported[tuple(near_edge)]
    # Beyond it (no scanned floor under the point): not supported, at any height.
    outside = space.cells_of(np.array([[3.0, 2.0, 0.5], [3.0, 2.0, 1.5]]))[0]
    assert not supported[tuple(outside.T)].any()
    # Too far above the surface (support_below_m = 3 m) is not supported either.
    tall = _space(support_below_m=1.0)
    _mark(tall, occupied=np.pad(np.ones((40, 40, 1), bool), ((0, 0), (0, 0), (0, 29))))
    cells = tall.cells_of(np.array([[1.0, 1.0, 0.5], [1.0, 1.0, 1.5]]))[0]
    assert tall.supported()[tuple(cells.T)].tolist() == [True, False]


def test_frontier_outside_the_scan_is_dropped_unless_switched_off() -> None:
    space, _ = _floor_room()
    frontier = space.frontier()
    points = space.grid.cell_to_world(np.argwhere(frontier))
    # The frontier at the top of the free air (z 2 m) exists only over the floor.
    assert len(points) > 0 and points[:, 0].max() < 2.0 + 0.3 + 0.1
    space.configure(support_below_m=None)
    everywhere = space.grid.cell_to_world(np.argwhere(space.frontier()))
    assert everywhere[:, 0].max() > 3.5
    assert space.supported().all()


def test_scan_top_is_the_height_under_the_occupied_voxels() -> None:
    space = _space()
    assert space.scan_top_z() == float("inf")
    occupied = np.zeros(space.grid.shape, bool)
    occupied[:, :, 0] = True  # floor
    occupied[0, :, :25] = True  # a wall up to 2.5 m
    _mark(space, occupied=occupied)
    assert space.scan_top_z() == pytest.approx(2.5, abs=0.11)


def test_invalid_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="support_below_m"):
        ObservedSpaceConfig(support_below_m=0.0)
    with pytest.raises(ValueError, match="top_quantile"):
        ObservedSpaceConfig(top_quantile=1.5)


def test_frontier_looked_at_without_being_resolved_loses_variance() -> None:
    """A wall 2.5 m ahead, seen 4 times: the frontier at the edges of the view within the
    look range falls to half the initial variance; frontier farther away keeps it."""
    space = _space(support_below_m=None, look_weight=0.25, look_range_m=2.0)
    camera = PinholeCamera(32, 32, 16.0, 16.0, 15.5, 15.5)
    eye = np.array([1.0, 2.0, 1.5])
    pose = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, 0.0]), eye)
    depth = np.full((32, 32), 2.5, np.float32)
    for _ in range(4):
        space.integrate_depth(depth, pose, camera)
    variance = space.frontier_variance(3.0)
    frontier = space.frontier()
    assert frontier.any() and np.all(variance[~frontier] == 0.0)
    cells = np.argwhere(frontier)
    distance = np.linalg.norm(space.grid.cell_to_world(cells) - eye, axis=1)
    values = variance[tuple(cells.T)]
    # Behind the camera nothing was looked at: the initial variance.
    assert np.all(values[distance > 2.2] == pytest.approx(3.0))
    looked = values < 3.0
    assert looked.any() and np.all(distance[looked] <= 2.0 + 0.1)
    assert values.min() == pytest.approx(1.5)  # 3 / (1 + 0.25 * 4)
    # Switched off, the frontier stays at the initial variance.
    still = _space(support_below_m=None, look_weight=0.0)
    for _ in range(4):
        still.integrate_depth(depth, pose, camera)
    assert np.all(still.frontier_variance(3.0)[still.frontier()] == 3.0)


@pytest.mark.parametrize("behind_m", [0.15, -0.1])
def test_voxels_just_behind_the_measured_surface_are_looked_at(behind_m: float) -> None:
    """A wall 1.5 m ahead: voxels up to ``look_behind_surface_m`` behind it count a look
    (the frontier under and behind a surface is seen with the surface), farther ones not;
    -0.1 requires a clear line of sight, one voxel in front of the surface."""
    space = _space(support_below_m=None, look_weight=0.25, look_range_m=2.0,
                   look_behind_surface_m=behind_m)
    camera = PinholeCamera(32, 32, 16.0, 16.0, 15.5, 15.5)
    eye = np.array([1.0, 2.05, 1.55])
    pose = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, 0.0]), eye)
    space.integrate_depth(np.full((32, 32), 1.5, np.float32), pose, camera)
    # The voxels straight ahead along the optical axis, by depth of their centres.
    ahead = np.array([[x, 2.05, 1.55] for x in np.arange(1.25, 2.95, 0.1)])
    row = space.grid.world_to_cell(ahead)
    depth = space.grid.cell_to_world(row)[:, 0] - eye[0]
    looks = space.looks[tuple(row.T)]
    assert np.all(looks[depth < 1.4] == 1.0)  # well in front of the wall
    assert np.all(looks[depth > 1.5 + 0.2] == 0.0)  # deep behind it
    just_behind = (depth > 1.5) & (depth < 1.5 + behind_m)
    assert just_behind.any() == (behind_m > 0)
    assert np.all(looks[just_behind] == 1.0)
    assert np.all(looks[(depth > 1.5 + max(behind_m, 0.0)) | (depth > 1.4) & (behind_m < 0)]
                  == 0.0)


def test_added_looks_lower_the_frontier_variance_of_those_voxels_only() -> None:
    space, _ = _floor_room()
    frontier = np.argwhere(space.frontier())
    chosen = space.grid.cell_to_world(frontier[:5])
    space.add_looks(np.vstack([chosen, [[50.0, 50.0, 50.0]]]), 4.0)  # one point outside
    variance = space.frontier_variance(3.0)
    assert np.allclose(variance[tuple(frontier[:5].T)], 1.5)  # 3 / (1 + 0.25 * 4)
    assert np.allclose(variance[tuple(frontier[5:].T)], 3.0)
    assert space.looks.sum() == pytest.approx(20.0)
