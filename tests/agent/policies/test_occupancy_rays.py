"""The compiled ray walk of OccupancyGrid gives exactly what the vectorised walk gave."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.mapping.occupancy import OccupancyGrid


def _vectorised_integrate_rays(grid: OccupancyGrid, origin, directions, ranges) -> None:
    """The former numpy implementation, kept as the test's oracle."""
    origin = np.asarray(origin, np.float64).reshape(3)
    directions = np.asarray(directions, np.float64).reshape(-1, 3)
    ranges = np.asarray(ranges, np.float64).reshape(-1)
    valid = np.isfinite(ranges) & (ranges > 0.0)
    hit = valid & (ranges <= grid.max_range_m)
    free_length = np.where(hit, ranges - grid.voxel_size_m, grid.max_range_m)
    free_length = np.where(valid | (ranges == 0.0), free_length, 0.0)
    spacing = grid.voxel_size_m / 2.0
    steps = np.arange(1, int(np.ceil(grid.max_range_m / spacing)) + 1) * spacing
    keep = steps[None, :] <= free_length[:, None]
    ray_index, step_index = np.nonzero(keep)
    points = origin + directions[ray_index] * steps[step_index, None]
    free_cells = grid.world_to_cell(points)
    free_cells = free_cells[grid.in_grid(free_cells)]
    free_flat = np.unique(grid._flat(free_cells)) if len(free_cells) else np.zeros(0, np.int64)
    hit_points = origin + directions[hit] * ranges[hit, None]
    hit_cells = grid.world_to_cell(hit_points)
    hit_cells = hit_cells[grid.in_grid(hit_cells)]
    hit_flat = np.unique(grid._flat(hit_cells)) if len(hit_cells) else np.zeros(0, np.int64)
    free_flat = np.setdiff1d(free_flat, hit_flat, assume_unique=True)
    log_odds = grid.log_odds.reshape(-1)
    observed = grid.observed.reshape(-1)
    log_odds[free_flat] = np.maximum(log_odds[free_flat] + grid.miss_log_odds, grid.clamp[0])
    log_odds[hit_flat] = np.minimum(log_odds[hit_flat] + grid.hit_log_odds, grid.clamp[1])
    observed[free_flat] = True
    observed[hit_flat] = True


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_compiled_walk_matches_the_vectorised_one(seed) -> None:
    rng = np.random.default_rng(seed)
    bounds = np.array([[-0.3, 0.1, -0.05], [4.2, 3.7, 2.9]])
    compiled = OccupancyGrid(bounds, 0.1, 5.0)
    reference = OccupancyGrid(bounds, 0.1, 5.0)
    for _ in range(12):
        origin = rng.uniform(bounds[0] - 0.5, bounds[1] + 0.5)  # sometimes outside the grid
        directions = rng.normal(size=(700, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        ranges = rng.uniform(0.0, 7.0, size=700)  # some beyond max_range_m
        ranges[rng.random(700) < 0.1] = 0.0  # no hit
        ranges[rng.random(700) < 0.03] = -1.0  # invalid
        ranges[rng.random(700) < 0.03] = np.nan
        ranges[rng.random(700) < 0.03] = np.inf
        ranges[rng.random(700) < 0.03] = 0.04  # shorter than a voxel
        compiled.integrate_rays(origin, directions, ranges)
        _vectorised_integrate_rays(reference, origin, directions, ranges)
        assert np.array_equal(compiled.observed, reference.observed)
        assert np.array_equal(compiled.log_odds, reference.log_odds)
    # Voxels saturate at the clamps after repeated frames, exactly as before.
    assert compiled.log_odds.min() == pytest.approx(compiled.clamp[0])
    assert compiled.log_odds.max() > compiled.occupied_threshold


def test_mismatched_rays_are_refused() -> None:
    grid = OccupancyGrid(np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]), 0.1, 2.0)
    with pytest.raises(ValueError, match="ranges"):
        grid.integrate_rays(np.zeros(3), np.ones((3, 3)), np.ones(2))
