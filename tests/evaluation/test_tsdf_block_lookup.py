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
