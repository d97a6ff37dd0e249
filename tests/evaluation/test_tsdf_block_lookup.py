"""Which planner-grid points a set of fused blocks can change: the grid box form equals the
per-point test."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_gym.evaluation.tsdf_mapper import TsdfFusionMapper


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_grid_boxes_equal_the_per_point_test(seed) -> None:
    rng = np.random.default_rng(seed)
    mapper = TsdfFusionMapper(voxel_size_m=0.02, truncation_m=0.06, device="cpu",
                              block_resolution=8)
    origin = np.array([-0.35, -0.12, -0.05]) + rng.uniform(0, 0.05, 3)
    spacing = 0.1
    shape = (40, 30, 20)
    axes = [origin[a] + spacing * np.arange(shape[a]) for a in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    blocks = np.unique(rng.integers(-2, 20, size=(25, 3)), axis=0)
    exact = mapper.points_near_blocks(points, blocks)
    boxes = mapper.grid_near_blocks(origin, spacing, shape, blocks).reshape(-1)
    assert exact.any() and not exact.all()
    assert np.array_equal(boxes, exact)
    assert not mapper.grid_near_blocks(origin, spacing, shape, np.zeros((0, 3))).any()


@pytest.mark.parametrize("seed", [0, 1])
def test_grid_cells_near_blocks_equal_the_per_point_test(seed) -> None:
    """A point's cell box (the voxels the behind-surface bound reads) or its interpolation
    corners reach into a block: the box form equals a per-point test."""
    rng = np.random.default_rng(seed)
    mapper = TsdfFusionMapper(voxel_size_m=0.02, truncation_m=0.06, device="cpu",
                              block_resolution=8)
    origin = np.array([-0.35, -0.12, -0.05]) + rng.uniform(0, 0.05, 3)
    spacing, half, shape = 0.1, 0.05, (30, 20, 15)
    axes = [origin[a] + spacing * np.arange(shape[a]) for a in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    blocks = np.unique(rng.integers(-2, 12, size=(15, 3)), axis=0)
    first = np.floor_divide(np.ceil((points - half) / 0.02).astype(np.int64), 8)
    last = np.floor_divide(np.floor((points + half) / 0.02).astype(np.int64), 8)
    in_box = np.zeros(len(points), bool)
    for block in blocks:
        in_box |= np.all((first <= block) & (block <= last), axis=1)
    corners = mapper.points_near_blocks(points, blocks)
    exact = in_box | corners
    boxes = mapper.grid_cells_near_blocks(origin, spacing, shape, blocks, half).reshape(-1)
    assert not exact.all() and (in_box & ~corners).any()
    assert np.array_equal(boxes, exact)
