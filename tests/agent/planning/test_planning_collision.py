"""Segment collision checks: 2 cm samples, free where SDF > radius, counted from the start."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.planning import SdfVolume, free_steps_along_segment, segment_is_free
from naruto_agent.planning.collision import guaranteed_margin_m, samples_per_step


@pytest.fixture(scope="module")
def wall_at_x1() -> SdfVolume:
    """Free space x < 1, a wall at x = 1: the SDF is 1 - x (exact under trilinear lookup)."""
    return SdfVolume.from_function(
        lambda p: 1.0 - p[:, 0], np.array([[-1.0, -1.0, -1.0], [3.0, 1.0, 1.0]]), 0.1
    )


def test_counts_whole_free_steps_up_to_the_wall(wall_at_x1):
    start = np.array([0.0, 0.0, 0.0])
    # Free while 1 - x > 0.05, i.e. x < 0.95: steps ending at 0.1 ... 0.9 are free.
    assert free_steps_along_segment(wall_at_x1, start, np.array([2.0, 0, 0])) == 9
    # A larger radius stops earlier: x < 0.75 -> 7 steps.
    assert free_steps_along_segment(wall_at_x1, start, np.array([2.0, 0, 0]),
                                    clearance_m=0.25) == 7
    # Segments away from the wall are free for all their whole steps (floor of length / step).
    assert free_steps_along_segment(wall_at_x1, start, np.array([-0.95, 0, 0])) == 9
    assert free_steps_along_segment(wall_at_x1, start, np.array([0.05, 0, 0])) == 0
    assert free_steps_along_segment(wall_at_x1, start, np.array([2.0, 0, 0]), max_steps=4) == 4


def test_counts_from_the_start_side():
    # Free everywhere except a slab 0.3 < x < 0.4; beyond it everything is free again.
    def slab(points):
        return np.maximum(np.abs(points[:, 0] - 0.35) - 0.05, 0.0) + 0.0 - 0.01

    volume = SdfVolume.from_function(slab, np.array([[-1.0, -1, -1], [2.0, 1, 1]]), 0.05)
    start, end = np.array([0.0, 0, 0]), np.array([1.5, 0, 0])
    steps = free_steps_along_segment(volume, start, end, clearance_m=0.0)
    # Steps before the slab are free; the many free steps after it do not count.
    assert steps == 2
    assert free_steps_along_segment(volume, end, start, clearance_m=0.0) == 10
    assert not segment_is_free(volume, start, end, clearance_m=0.0)
    assert segment_is_free(volume, start, np.array([0.2, 0, 0]), clearance_m=0.0)


def test_sampling_catches_an_obstacle_between_step_ends():
    # A slab 3 cm thick around x = 0.05, between the step ends x = 0.0 and x = 0.1, which
    # are both free: only the samples inside the step can see it.
    def slab(points):
        return np.abs(points[:, 0] - 0.05) - 0.015

    bounds = np.array([[-0.3, -0.1, -0.1], [0.4, 0.1, 0.1]])
    volume = SdfVolume.from_function(slab, bounds, 0.005)
    start, end = np.array([-0.2, 0, 0]), np.array([0.3, 0, 0])
    assert np.all(volume.sample(np.array([[0.0, 0, 0], [0.1, 0, 0]])) > 0.0)
    assert free_steps_along_segment(volume, start, end, clearance_m=0.0) == 2
    assert samples_per_step(0.1, 0.02) == 5
    assert samples_per_step(0.1, 0.03) == 4  # never further apart than asked


def test_guaranteed_margin_value():
    assert guaranteed_margin_m(0.1, 0.02) == pytest.approx(np.sqrt(3) / 2 * 0.1 + 0.01)


def test_rejects_bad_steps(wall_at_x1):
    with pytest.raises(ValueError, match="positive"):
        free_steps_along_segment(wall_at_x1, np.zeros(3), np.ones(3), step_m=0.0)


def test_planner_move_checker_agrees_with_the_public_check(room_sdf):
    from naruto_agent.planning import PlannerConfig
    from naruto_agent.planning.rrt import _MoveChecker

    config = PlannerConfig()
    checker = _MoveChecker(room_sdf, config)
    rng = np.random.default_rng(7)
    bounds = room_sdf.bounds
    for _ in range(200):
        start, end = rng.uniform(bounds[0], bounds[1], size=(2, 3))
        length = np.linalg.norm(end - start)
        steps = int(length / 0.1 + 1e-9)
        expected = free_steps_along_segment(room_sdf, start, end)
        assert checker.free_steps(start, (end - start) / length, steps) == expected
