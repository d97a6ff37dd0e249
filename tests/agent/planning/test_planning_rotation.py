"""Rotation planning: look-at, greedy view order, SLERP steps never above the limit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from naruto_agent.planning import (
    look_at_rotation,
    order_views_greedily,
    plan_rotations,
    slerp_rotations,
)
from naruto_agent.planning.rotation import image_view_test
from naruto_gym.geometry.transforms import rotation_angle_between


def step_angles_deg(start: np.ndarray, rotations: np.ndarray) -> np.ndarray:
    chain = np.concatenate([start[None], rotations])
    return np.degrees(
        [rotation_angle_between(a, b) for a, b in zip(chain[:-1], chain[1:], strict=True)]
    )


def yawed(degrees: float) -> np.ndarray:
    """Look-at rotation of a camera at the origin looking horizontally at this yaw."""
    yaw = math.radians(degrees)
    return look_at_rotation(np.zeros(3), np.array([math.cos(yaw), math.sin(yaw), 0.0]))


def test_look_at_points_the_optical_axis_at_the_target_with_image_down_world_down():
    eye, target = np.array([1.0, 2.0, 1.5]), np.array([3.0, -1.0, 0.5])
    rotation = look_at_rotation(eye, target)
    forward = (target - eye) / np.linalg.norm(target - eye)
    np.testing.assert_allclose(rotation[:, 2], forward, atol=1e-12)
    assert rotation[2, 1] < 0.0  # camera y (image down) has a world-down component
    assert abs(rotation[2, 0]) < 1e-12  # no roll: camera x stays horizontal
    np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)


@pytest.mark.parametrize(("angle_deg", "expected_steps"), [(95.0, 10), (30.0, 3), (4.0, 1)])
def test_slerp_uses_ceil_so_no_step_exceeds_the_limit(angle_deg, expected_steps):
    start, end = yawed(0.0), yawed(angle_deg)
    rotations = slerp_rotations(start, end, max_step_deg=10.0)
    # floor(95 / 10) = 9 steps would make each step 10.6 degrees; ceil gives 10.
    assert len(rotations) == expected_steps
    steps = step_angles_deg(start, rotations)
    assert steps.max() <= 10.0 + 1e-6
    np.testing.assert_allclose(steps, angle_deg / expected_steps, atol=1e-6)
    np.testing.assert_array_equal(rotations[-1], end)


def test_slerp_of_no_turn_is_one_step_at_the_end_and_large_turns_stay_bounded():
    rotation = yawed(20.0)
    np.testing.assert_array_equal(slerp_rotations(rotation, rotation), rotation[None])
    rng = np.random.default_rng(0)
    for _ in range(20):
        start, end = Rotation.random(2, random_state=rng).as_matrix()
        limit = float(rng.uniform(2.0, 30.0))
        rotations = slerp_rotations(start, end, max_step_deg=limit)
        assert step_angles_deg(start, rotations).max() <= limit + 1e-6
        np.testing.assert_array_equal(rotations[-1], end)


def test_greedy_order_takes_the_smallest_turn_each_time():
    views = np.stack([yawed(50.0), yawed(10.0), yawed(-25.0), yawed(30.0)])
    # From 0: 10 (10 deg), then 30 (20), then 50 (20), then -25 (75).
    np.testing.assert_array_equal(order_views_greedily(yawed(0.0), views), [1, 3, 0, 2])


def test_plan_rotations_visits_every_target_in_bounded_steps():
    rng = np.random.default_rng(4)
    eye = np.array([0.5, -0.3, 1.2])
    targets = eye + rng.normal(size=(10, 3))
    current = yawed(70.0)
    plan = plan_rotations(current, eye, targets, max_step_deg=10.0)
    assert sorted(plan.order.tolist()) == list(range(10))
    assert step_angles_deg(current, plan.rotations).max() <= 10.0 + 1e-6
    last = targets[plan.order[-1]]
    np.testing.assert_array_equal(plan.rotations[-1], look_at_rotation(eye, last))
    for target_index, arrival in zip(plan.order, plan.arrivals, strict=True):
        np.testing.assert_array_equal(
            plan.rotations[arrival], look_at_rotation(eye, targets[target_index])
        )
    # Greedy ordering never turns more in total than visiting in the given order, here.
    given = plan_rotations(current, eye, targets, max_step_deg=10.0, greedy=False)
    assert len(plan.rotations) <= len(given.rotations)
    np.testing.assert_array_equal(given.order, np.arange(10))


def test_rotation_input_errors():
    with pytest.raises(ValueError, match="max_step_deg"):
        slerp_rotations(np.eye(3), np.eye(3), max_step_deg=0.0)
    with pytest.raises(ValueError, match="rotation"):
        slerp_rotations(np.eye(3) * 2.0, np.eye(3))
    with pytest.raises(ValueError, match="coincide"):
        plan_rotations(np.eye(3), np.zeros(3), np.zeros((1, 3)))
    assert len(plan_rotations(np.eye(3), np.zeros(3), np.zeros((0, 3))).rotations) == 0


def test_views_already_in_the_image_are_not_turned_to():
    eye = np.zeros(3)
    in_view = image_view_test(64, 64, 32.0, 32.0, 31.5, 31.5, margin=0.1)
    current = look_at_rotation(eye, np.array([1.0, 0.0, 0.0]))
    ahead = [np.array([2.0, 0.1, 0.05]), np.array([2.0, -0.2, 0.0])]  # in the image now
    behind = [np.array([-2.0, 0.0, 0.0]), np.array([-2.0, 0.3, 0.0])]  # one turn sees both
    side = np.array([0.0, 2.0, 0.0])  # seen on the way round to the back
    targets = np.stack(ahead + behind + [side])
    full = plan_rotations(current, eye, targets, max_step_deg=10.0)
    plan = plan_rotations(current, eye, targets, max_step_deg=10.0, in_view=in_view)
    assert len(full.order) == 5
    assert {0, 1} <= set(plan.skipped.tolist())
    assert len(plan.order) + len(plan.skipped) == 5 and len(plan.order) <= 2
    assert len(plan.rotations) < len(full.rotations)
    # Every target is in the image of some rotation of the plan (or of the start).
    seen = in_view(eye, np.concatenate([current[None], plan.rotations]), targets).any(axis=0)
    assert seen.all()
    # Steps stay within the limit.
    previous = current
    for rotation in plan.rotations:
        assert np.degrees(rotation_angle_between(previous, rotation)) <= 10.0 + 1e-6
        previous = rotation
    # All in view already: nothing to turn.
    assert len(plan_rotations(current, eye, np.stack(ahead), in_view=in_view).rotations) == 0
