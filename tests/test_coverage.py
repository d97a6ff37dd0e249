"""The coverage kernel: culling by sample cells marks the samples the numpy reference sees."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import naruto_gym  # noqa: F401  (registers the ids)
from naruto_gym.coverage import (
    COVERAGE_TOLERANCE_M,
    mark_visible_in_cells,
    sample_cells,
    visible_samples,
)
from naruto_gym.sensors.pinhole import PinholeCamera


def test_sample_cells_hold_every_sample_once_within_their_radius():
    rng = np.random.default_rng(0)
    samples = rng.uniform(-2.0, 3.0, (5000, 3))
    cells = sample_cells(samples, cell_m=0.7)
    assert np.array_equal(np.sort(cells.order), np.arange(len(samples)))
    assert cells.starts[0] == 0 and cells.starts[-1] == len(samples)
    for cell in range(len(cells.radii)):
        members = samples[cells.order[cells.starts[cell]:cells.starts[cell + 1]]]
        assert len(members) > 0
        distance = np.linalg.norm(members - cells.centres[cell], axis=1)
        assert distance.max() <= cells.radii[cell] + 1e-12
        assert np.ptp(np.floor((members - samples.min(axis=0)) / 0.7), axis=0).max() == 0
    with pytest.raises(ValueError, match="cell_m"):
        sample_cells(samples, cell_m=0.0)


@pytest.mark.parametrize("scene", ["replica_like_room", "apartment"])
@pytest.mark.parametrize("camera", [PinholeCamera(64, 64, 32, 32, 31.5, 31.5),
                                    PinholeCamera(40, 24, 30, 30, 19.5, 11.5)])
def test_culling_by_cells_marks_what_the_numpy_reference_sees(scene, camera):
    env = gym.make("NarutoRecon-v0", scene=scene, camera=camera, panorama_shape=None,
                   coverage_samples=4000).unwrapped
    coverage = env.coverage
    rng = np.random.default_rng(1)
    seen = np.zeros(len(coverage.samples_world), bool)
    unseen = coverage.cell_sizes.copy()
    for episode in range(25):
        env.reset(seed=int(rng.integers(1 << 30)))
        pose = env.unwrapped.pose
        if episode % 2:  # any rotation, not only the start poses' upright ones
            pose[:3, :3] = Rotation.random(random_state=episode).as_matrix()
        _, depth = env.renderer.render(pose)
        expected = visible_samples(coverage.samples_world, pose, camera, depth,
                                   coverage.max_range_m, COVERAGE_TOLERANCE_M)
        fresh = np.zeros_like(seen)
        added = mark_visible_in_cells(coverage.samples_world, *coverage.cells, fresh,
                                      coverage.cell_sizes.copy(), pose, coverage.intrinsics,
                                      depth, coverage.max_range_m, COVERAGE_TOLERANCE_M)
        assert np.array_equal(fresh, expected) and added == expected.sum()
        # With samples already seen: only the new ones count, and whole cells seen before
        # are skipped (their counts reach 0).
        before = seen.copy()
        added = mark_visible_in_cells(
            coverage.samples_world, *coverage.cells, seen, unseen, pose, coverage.intrinsics,
            depth, coverage.max_range_m, COVERAGE_TOLERANCE_M)
        assert added == (expected & ~before).sum()
        assert np.array_equal(seen, before | expected)
        order, starts = coverage.cells[0], coverage.cells[1]
        np.testing.assert_array_equal(unseen, [
            (~seen[order[a:b]]).sum() for a, b in zip(starts[:-1], starts[1:], strict=True)
        ])
    assert (unseen == 0).any()
    assert 0 < seen.sum() < len(seen)
    env.close()
