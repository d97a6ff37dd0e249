"""Uncertainty-aware goal search on a synthetic map: two rooms split by a wall."""

from __future__ import annotations

import numpy as np
import pytest

from naruto_agent.naruto import (
    GoalSearchConfig,
    candidate_goals,
    safe_goal_mask,
    search_goals,
    select_targets,
    uncertainty_aware_goal_search,
    visibility,
)
from naruto_agent.planning import FreeSpaceComponents, SdfVolume

# A 6 x 4 x 3 m box, split at x = 3 by a 0.2 m thick wall from floor to ceiling.
ROOM = np.array([[0.0, 0.0, 0.0], [6.0, 4.0, 3.0]])
WALL_X = (2.9, 3.1)


def room_sdf(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    to_box = np.minimum(points - ROOM[0], ROOM[1] - points).min(axis=1)
    # Signed distance to the wall slab (positive outside it).
    to_wall = np.maximum(WALL_X[0] - points[:, 0], points[:, 0] - WALL_X[1])
    return np.minimum(to_box, to_wall)


@pytest.fixture(scope="module")
def sdf() -> SdfVolume:
    return SdfVolume.from_function(room_sdf, ROOM, voxel_size=0.1)


def uncertainty_at(sdf: SdfVolume, points_and_values: list[tuple[tuple, float]]) -> SdfVolume:
    """An uncertainty volume that is 0 except at the voxels nearest to the given points."""
    values = np.zeros(sdf.shape, dtype=np.float32)
    for point, value in points_and_values:
        index = np.rint(sdf.world_to_voxel(np.asarray(point))).astype(int)
        values[tuple(index)] = value
    return SdfVolume(values, sdf.origin, sdf.voxel_size)


def test_candidate_goals_grid_spacing_and_heights():
    goals = candidate_goals(ROOM)
    xs, ys, zs = (np.unique(np.round(goals[:, axis], 6)) for axis in range(3))
    assert np.allclose(np.diff(xs), 0.2) and np.allclose(np.diff(ys), 0.2)
    assert np.allclose(np.diff(zs), 1.0) and len(zs) == 4  # 0, 1, 2, 3 in a 3 m box
    assert len(goals) == len(xs) * len(ys) * len(zs)
    # Centred: equal slack at both ends of every axis.
    for axis, values in enumerate((xs, ys, zs)):
        assert np.isclose(values[0] - ROOM[0, axis], ROOM[1, axis] - values[-1])


def test_safe_goals_keep_8cm_at_the_goal_and_its_neighbours(sdf):
    goals = np.array([
        [1.5, 2.0, 1.5],   # open space
        [2.8, 2.0, 1.5],   # 10 cm from the wall: its +x neighbour is inside the wall
        [1.5, 2.0, 0.15],  # 15 cm above the floor: the neighbour below is 5 cm above it
        [1.5, 2.0, 0.2],   # neighbour below at 10 cm: safe
        [3.0, 2.0, 1.5],   # inside the wall
        [-0.5, 2.0, 1.5],  # outside the volume
    ])
    assert safe_goal_mask(sdf, goals).tolist() == [True, False, False, True, False, False]


def test_safe_test_accepts_a_float32_truncation_of_exactly_8cm():
    # A TSDF stores its 8 cm truncation as float32(0.08), a hair below 0.08.
    flat = SdfVolume(np.full((5, 5, 5), 0.08, np.float32), np.zeros(3), 0.1)
    assert safe_goal_mask(flat, np.array([[0.2, 0.2, 0.2]]), 0.08).all()


def test_visibility_respects_range_and_walls(sdf):
    goal = np.array([[1.5, 2.0, 1.5]])
    targets = np.array([
        [0.0 + 0.02, 2.0, 1.5],  # back wall of the same room, 1.48 m away: seen
        [2.9 - 0.02, 2.0, 1.5],  # near face of the partition, 1.38 m: seen
        [3.1 + 0.02, 2.0, 1.5],  # far face of the partition, behind it: not seen
        [1.5, 2.0, 1.1],         # 0.4 m away: closer than the 0.5 m minimum range
        [1.5, 4.0 - 0.02, 0.0 + 0.02],  # 2.6 m away: beyond the 2 m range
        [1.5, 3.98, 1.5],        # side wall, 1.98 m: seen
    ])
    assert visibility(sdf, goal, targets).tolist() == [[True, True, False, False, False, True]]
    # The right room sees the far face of the partition.
    assert visibility(sdf, np.array([[4.5, 2.0, 1.5]]), targets[2:3]).tolist() == [[True]]


def test_search_picks_the_goal_that_sees_the_most_uncertainty(sdf):
    # A bright cluster on the right room's back wall, weaker targets in the left room.
    cluster = [((5.98, y, z), 3.0) for y in (1.5, 2.0, 2.5) for z in (1.0, 1.5, 2.0)]
    left = [((0.02, 2.0, 1.5), 1.0), ((1.5, 3.98, 1.5), 1.0), ((2.88, 1.0, 1.0), 1.0)]
    uncertainty = uncertainty_at(sdf, cluster + left)
    config = GoalSearchConfig(top_k=3)
    result = search_goals(sdf, uncertainty, np.random.default_rng(0), config)
    assert result.found and len(result.targets) == 12
    # The best goal is in the right room, within range of the cluster, and safe.
    assert result.goal[0] > 3.1 and 0.5 < 6.0 - result.goal[0] < 2.0
    assert safe_goal_mask(sdf, result.goal[None]).all()
    assert result.score == pytest.approx(27.0)  # sees all nine cluster targets
    # Branch and bound gives the brute-force answer: score every safe goal.
    goals = candidate_goals(sdf.bounds, config)
    goals = goals[safe_goal_mask(sdf, goals)]
    scores = visibility(sdf, goals, result.targets, config) @ result.target_uncertainty
    assert result.score == pytest.approx(scores.max())
    assert np.allclose(result.goal_scores, np.sort(scores)[::-1][:3])
    assert result.diagnostics["evaluated_goals"] < len(goals)  # it pruned
    # Views: visible targets, most uncertain first, at most num_views.
    assert 1 <= len(result.views) <= config.num_views
    assert np.all(np.diff(result.view_uncertainty) <= 0)
    assert visibility(sdf, result.goal[None], result.views, config).all()
    # Every target each goal sees, the views among them; their uncertainty is the score.
    for goal, score, seen in zip(result.goals, result.goal_scores, result.goal_visible,
                                 strict=True):
        row = visibility(sdf, goal[None], result.targets, config)[0]
        assert np.array_equal(seen, result.targets[row])
        assert result.target_uncertainty[row].sum() == pytest.approx(score)
    assert all(any(np.array_equal(view, point) for point in result.goal_visible[0])
               for view in result.views)


def test_a_target_behind_the_wall_only_counts_from_its_own_side(sdf):
    # One very uncertain target on the far (right) face of the partition.
    uncertainty = uncertainty_at(sdf, [((3.12, 2.0, 1.5), 5.0)])
    result = search_goals(sdf, uncertainty, np.random.default_rng(0))
    assert result.found and result.goal[0] > WALL_X[1]


def test_targets_are_the_most_uncertain_voxels_and_a_seeded_subset(sdf):
    rng = np.random.default_rng(0)
    values = np.zeros(sdf.shape, np.float32)
    index = rng.choice(values.size, 500, replace=False)
    values.reshape(-1)[index] = rng.uniform(0.1, 1.0, 500)
    uncertainty = SdfVolume(values, sdf.origin, sdf.voxel_size)
    points, chosen = select_targets(uncertainty, np.random.default_rng(1), 100, 30)
    assert len(points) == 30
    assert chosen.min() >= np.sort(values.reshape(-1))[-100]
    again, _ = select_targets(uncertainty, np.random.default_rng(1), 100, 30)
    other, _ = select_targets(uncertainty, np.random.default_rng(2), 100, 30)
    assert np.array_equal(points, again) and not np.array_equal(points, other)


def _box_sdf(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Signed distance to a solid box, negative inside."""
    q = np.abs(points - (lo + hi) / 2) - (hi - lo) / 2
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def test_fallback_masks_the_uncertainty_with_reachable_voxels():
    # A closed hollow cupboard (10 cm walls, 0.3 m cavity) in the left room whose cavity is
    # very uncertain: no goal outside sees into it and no safe goal fits inside.
    lo, hi = np.array([1.0, 1.5, 1.0]), np.array([1.5, 2.0, 1.5])

    def sdf_with_cupboard(points):
        shell = np.maximum(_box_sdf(points, lo, hi), -_box_sdf(points, lo + 0.1, hi - 0.1))
        return np.minimum(room_sdf(points), shell)

    sdf = SdfVolume.from_function(sdf_with_cupboard, ROOM, voxel_size=0.1)
    hidden = [((1.25, 1.75, 1.25), 5.0)]
    # Both rooms' back walls are uncertain too (less so).
    walls = [((x, y, z), 1.0) for x in (0.0, 6.0) for y in np.arange(0.3, 3.8, 0.1)
             for z in np.arange(0.3, 2.8, 0.1)]
    uncertainty = uncertainty_at(sdf, hidden + walls)
    config = GoalSearchConfig(top_uncertain=1)  # only the hidden voxel is a target at first
    start = np.array([0.5, 0.5, 1.5])
    first = search_goals(sdf, uncertainty, np.random.default_rng(0), config)
    assert not first.found
    assert np.allclose(first.targets, [[1.25, 1.75, 1.25]], atol=0.06)  # in the cavity
    result = uncertainty_aware_goal_search(
        sdf, uncertainty, start, np.random.default_rng(0), config
    )
    assert result.used_reachable_mask and result.found
    assert result.diagnostics["reachable_voxels"] > 0
    # The target now is a reachable one: on the left room's back wall (the right room lies
    # behind the partition, out of the tree's reach), and the goal is in the left room.
    assert len(result.targets) == 1 and result.targets[0, 0] == pytest.approx(0.0)
    assert result.goal[0] < WALL_X[0]


def test_same_seed_same_result_and_bad_input(sdf):
    uncertainty = uncertainty_at(sdf, [((0.02, y, 1.5), 1.0 + y) for y in np.arange(0.5, 3.6, 0.2)])
    config = GoalSearchConfig(target_subset=5)
    a = search_goals(sdf, uncertainty, np.random.default_rng(7), config)
    b = search_goals(sdf, uncertainty, np.random.default_rng(7), config)
    assert np.array_equal(a.goal, b.goal) and np.array_equal(a.views, b.views)
    other = SdfVolume(np.zeros((3, 3, 3), np.float32), sdf.origin, sdf.voxel_size)
    with pytest.raises(ValueError, match="share one grid"):
        search_goals(sdf, other, np.random.default_rng(0))
    with pytest.raises(ValueError, match="min_range_m"):
        GoalSearchConfig(min_range_m=3.0)
    with pytest.raises(ValueError, match="top_k"):
        GoalSearchConfig(top_k=0)


def test_explore_first_prefers_the_most_uncertain_tier_then_falls_back(sdf):
    """Many half-uncertain surfaces near the agent (left room) against a few voxels at the
    largest uncertainty far away (right room): with a distance discount the published
    search takes the near ones; explore-first takes the far tier, and all targets again when
    no allowed goal sees that tier."""
    near = [((0.02, y, z), 1.5) for y in np.arange(1.0, 3.01, 0.1) for z in (1.0, 1.5, 2.0)]
    far = [((5.98, y, 1.5), 3.0) for y in (1.8, 2.0, 2.2)]
    uncertainty = uncertainty_at(sdf, near + far)
    start = np.array([1.0, 2.0, 1.5])
    published = GoalSearchConfig(distance_discount_m=3.0)
    first = GoalSearchConfig(distance_discount_m=3.0, explore_first_share=0.75,
                             explore_first_min_voxels=3)
    rng = np.random.default_rng(0)
    assert uncertainty_aware_goal_search(sdf, uncertainty, start, rng, published).goal[0] < 2.9
    chosen = uncertainty_aware_goal_search(sdf, uncertainty, start, rng, first)
    assert chosen.goal[0] > 3.1 and chosen.diagnostics.get("explore_first") == 1.0
    assert np.all(chosen.target_uncertainty == 3.0)
    # Too few voxels in the tier: the published search.
    few = GoalSearchConfig(distance_discount_m=3.0, explore_first_share=0.75,
                           explore_first_min_voxels=4)
    assert uncertainty_aware_goal_search(sdf, uncertainty, start, rng, few).goal[0] < 2.9
    # Goals only in the left room: nothing sees the tier, all targets are searched.
    left_only = np.zeros(sdf.shape, bool)
    left_only[: int(2.8 / sdf.voxel_size)] = True
    fallback = uncertainty_aware_goal_search(sdf, uncertainty, start, rng, first,
                                             goal_mask=left_only)
    assert fallback.found and fallback.goal[0] < 2.9 and "explore_first" not in fallback.diagnostics
    with pytest.raises(ValueError, match="explore_first_share"):
        GoalSearchConfig(explore_first_share=1.5)


def test_discount_by_travel_prefers_goals_near_by_the_way_there():
    """Two equal clusters: one across the partition (near in a straight line, far through
    the door), one farther in the agent's own room. The straight-distance discount picks
    the first, the travel-distance discount the second."""
    door_y = (3.2, 4.0)

    def with_door(points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64)
        to_box = np.minimum(points - ROOM[0], ROOM[1] - points).min(axis=1)
        to_wall = np.maximum(WALL_X[0] - points[:, 0], points[:, 0] - WALL_X[1])
        to_wall = np.maximum(to_wall, points[:, 1] - door_y[0])  # the door: y above 3.2
        return np.minimum(to_box, to_wall)

    sdf = SdfVolume.from_function(with_door, ROOM, voxel_size=0.1)
    across = [((3.12, y, z), 2.0) for y in (0.4, 0.6, 0.8) for z in (1.0, 1.5, 2.0)]
    own_room = [((0.02, y, z), 2.0) for y in (3.2, 3.4, 3.6) for z in (1.0, 1.5, 2.0)]
    uncertainty = uncertainty_at(sdf, across + own_room)
    start = np.array([2.5, 0.6, 1.5])
    travel = FreeSpaceComponents.from_sdf(sdf, 0.05).travel_distances(start)
    straight = GoalSearchConfig(distance_discount_m=3.0)
    by_travel = GoalSearchConfig(distance_discount_m=3.0, discount_by_travel=True)
    rng = np.random.default_rng(0)
    assert search_goals(sdf, uncertainty, rng, straight, origin=start,
                        travel=travel).goal[0] > WALL_X[1]
    chosen = search_goals(sdf, uncertainty, rng, by_travel, origin=start, travel=travel)
    assert chosen.goal[0] < WALL_X[0]
    # Without a travel volume the setting falls back to the straight distance.
    assert search_goals(sdf, uncertainty, rng, by_travel, origin=start).goal[0] > WALL_X[1]
    with pytest.raises(ValueError, match="travel volume shape"):
        search_goals(sdf, uncertainty, rng, by_travel, origin=start, travel=travel[1:])
