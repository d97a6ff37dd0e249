"""The shared stall recovery (naruto_agent.policies.stall_recovery): which way out it chooses,
what it remembers, and the places a depth panorama offers."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.policies.stall_recovery import (
    ReachablePlaces,
    StallRecovery,
    StallRecoveryConfig,
    panorama_places,
)
from naruto_gym.sensors.panorama import EquirectangularCamera


def _line(xs, y=0.0, z=1.0) -> ReachablePlaces:
    points = np.array([[x, y, z] for x in xs], np.float64).reshape(-1, 3)
    return ReachablePlaces(points, np.abs(points[:, 0]))


def test_the_way_out_lies_past_the_stay_and_farthest_from_the_trail():
    recovery = StallRecovery()
    for x in np.arange(0.0, 2.01, 0.1):  # the trail: from x = 0 to 2 m
        recovery.record(np.array([x, 0.0, 1.0]))
    places = _line([-1.5, -0.8, 0.3, 2.3, 2.9])
    # Staying around x = 0: the places within 0.6 m (0.3) are inside the stay; of the others
    # -1.5 lies 1.5 m from the trail, 2.9 only 0.9 m.
    index = recovery.way_out(places, np.array([[0.0, 0.0, 1.0]]), 0.6)
    assert index == 0 and np.allclose(recovery.goal, places.points[0])


def test_a_refused_way_out_is_not_chosen_again_and_arrival_ends_the_walk():
    recovery = StallRecovery()
    recovery.record(np.zeros(3))
    places = _line([-2.0, 1.5])
    stay = np.zeros((1, 3))
    assert recovery.way_out(places, stay, 0.6) == 0
    recovery.record(np.array([-0.1, 0.0, 0.0]), refused=True)  # the env refused a move
    assert recovery.goal is None
    assert recovery.way_out(places, stay, 0.6) == 1  # not -2.0 again
    recovery.record(np.array([1.4, 0.0, 1.0]))  # within arrival_m of it: reached
    assert recovery.goal is None
    assert recovery.way_out(places, stay, 0.6) == 1  # a reached way out did not fail


def test_a_way_out_still_walked_at_the_next_stall_failed():
    recovery = StallRecovery()
    places = _line([-2.0, 1.5])
    assert recovery.way_out(places, np.zeros((1, 3)), 0.6) == 0
    assert recovery.way_out(places, np.zeros((1, 3)), 0.6) == 1
    assert recovery.way_out(places, np.zeros((1, 3)), 0.6) is None  # both failed now


def test_a_way_out_the_agent_gets_no_nearer_to_in_the_stay_failed_and_the_next_is_due():
    """Two steps without getting nearer (a held move, then the policy's own rules) while
    still in the stay: the way out failed, the next is due, and it lies elsewhere."""
    recovery = StallRecovery()
    recovery.record(np.zeros(3))
    places, stay = _line([-2.0, 1.5], z=0.0), np.zeros((1, 3))
    assert recovery.way_out(places, stay, 0.6) == 0
    recovery.record(np.array([-0.1, 0.0, 0.0]))  # nearer: progress
    recovery.record(np.array([-0.1, 0.0, 0.0]))  # held: idle 1
    assert recovery.goal is not None and not recovery.walk_failed
    recovery.record(np.array([0.0, 0.0, 0.0]))  # back: idle 2
    assert recovery.goal is None and recovery.walk_failed
    assert recovery.way_out(places, stay, 0.6) == 1 and not recovery.walk_failed


def test_a_declined_way_out_is_not_chosen_again_and_is_no_failed_walk():
    recovery = StallRecovery()
    places, stay = _line([-2.0, 1.5], z=0.0), np.zeros((1, 3))
    assert recovery.way_out(places, stay, 0.6) == 0
    recovery.decline()
    assert recovery.goal is None and not recovery.walk_failed
    assert recovery.way_out(places, stay, 0.6) == 1


def test_past_the_stay_a_refused_or_idle_way_out_ends_without_failing():
    """Once the agent is past the stay the way out has done its work: a refusal or idle
    steps there end the walk (the policy's own rules go on); it may be chosen again."""
    places, stay = _line([-2.0, 1.5], z=0.0), np.zeros((1, 3))
    for refused in (True, False):
        recovery = StallRecovery()
        recovery.record(np.zeros(3))
        assert recovery.way_out(places, stay, 0.6) == 0
        recovery.record(np.array([-0.8, 0.0, 0.0]))
        for _ in range(1 if refused else recovery.config.max_idle_steps):
            recovery.record(np.array([-0.8, 0.0, 0.0]), refused=refused)
        assert recovery.goal is None and not recovery.walk_failed
        assert recovery.way_out(_line([-2.0], z=0.0), stay, 0.6) == 0  # it did not fail
    # A move the policy's own checks held (it calls fail()) past the stay: the same.
    recovery.record(np.array([-0.8, 0.0, 0.0]))
    recovery.fail()
    assert recovery.goal is None and not recovery.walk_failed


def test_no_place_past_the_stay_or_within_reach_means_no_way_out():
    recovery = StallRecovery(StallRecoveryConfig(max_path_m=1.0))
    places = _line([0.2, 1.5])  # within the stay, and beyond max_path_m
    stay = np.array([[0.0, 0.0, 1.0]])
    assert recovery.way_out(places, stay, 0.6) is None
    assert recovery.goal is None
    assert recovery.way_out(_line([]), stay, 0.6) is None


@pytest.mark.parametrize(
    ("field", "value"),
    [("max_path_m", 0.0), ("failed_radius_m", -1.0), ("arrival_m", 0.0), ("trail_points", 0),
     ("max_idle_steps", 0), ("min_progress_m", 0.0), ("max_failed_ways_out", 0),
     ("max_declined", 0)],
)
def test_bad_settings_are_refused_with_the_field_named(field, value):
    with pytest.raises(ValueError, match=field):
        StallRecoveryConfig(**{field: value})


def test_places_need_one_path_length_each():
    with pytest.raises(ValueError, match="one path length per place"):
        ReachablePlaces(np.zeros((3, 3)), np.zeros(2))


def _box_panorama(position, low, high, shape=(32, 64)) -> np.ndarray:
    """The radial distances from ``position`` to the walls of an axis-aligned box."""
    rays = EquirectangularCamera(height=shape[0], width=shape[1]).ray_directions.astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        to_high = (high - position) / rays
        to_low = (low - position) / rays
    exits = np.where(to_high > 0, to_high, to_low)
    return exits.min(axis=1).reshape(shape)


def test_panorama_places_keep_a_margin_from_the_walls_and_change_height_where_there_is_room():
    """In a 4 x 4 x 2.5 m box, from its middle at 1.2 m: places along every heading up to the
    walls less the margin and a step, and at heights up and down 0.5 m (room above and
    below); none outside the bounds given (above 1.5 m, or past x = 3 m)."""
    position = np.array([2.0, 2.0, 1.2])
    panorama = _box_panorama(position, np.zeros(3), np.array([4.0, 4.0, 2.5]))
    places = panorama_places(panorama, position, 0.1, bounds=np.array([[0, 0, 0], [3.25, 4, 1.5]]))
    assert len(places) > 0
    assert np.all(places.points[:, :2] > 0.25) and np.all(places.points[:, 0] <= 3.0)
    assert np.all(places.points[:, 1] < 3.75)
    heights = np.unique(np.round(places.points[:, 2] - position[2], 2))
    np.testing.assert_allclose(heights, [-0.5, -0.25, 0.0, 0.25])  # 1.7 m is above 1.5
    np.testing.assert_allclose(
        places.path_m,
        np.abs(places.points[:, 2] - position[2])
        + np.linalg.norm(places.points[:, :2] - position[:2], axis=1),
    )


def test_a_height_with_no_room_above_offers_no_climb():
    position = np.array([2.0, 2.0, 1.2])
    panorama = _box_panorama(position, np.zeros(3), np.array([4.0, 4.0, 1.5]))  # 0.3 m above
    places = panorama_places(panorama, position, 0.1)
    assert np.all(places.points[:, 2] <= position[2] + 1e-9)
