"""The depth occupancy grid and the frontier policy built on it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import naruto_gym  # noqa: F401
from naruto_agent.policies import EnvContext, FrontierPolicy, OccupancyGrid, RandomPolicy
from naruto_gym.geometry.transforms import look_at_rotation, make_pose
from naruto_gym.sensors.pinhole import PinholeCamera


def _wall_frame(distance: float = 2.0):
    """A camera at (1, 2.5, 1.5) looking along +x at a flat wall ``distance`` away."""
    camera = PinholeCamera().scaled(0.1)
    eye = np.array([1.0, 2.5, 1.5])
    pose = make_pose(look_at_rotation(eye, eye + [1.0, 0.0, 0.0]), eye)
    depth = np.full((camera.height, camera.width), distance, np.float32)  # z-depth of a plane
    return camera, pose, depth


def test_depth_marks_free_space_up_to_the_wall_and_the_wall_occupied():
    grid = OccupancyGrid(np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 3.0]]), pixel_stride=2)
    camera, pose, depth = _wall_frame(2.0)
    grid.integrate(depth, pose, camera)
    centre = grid.world_to_cell(np.array([[1.5, 2.5, 1.5], [2.5, 2.5, 1.5], [3.05, 2.5, 1.5]]))
    assert grid.free[tuple(centre[0])] and grid.free[tuple(centre[1])]
    assert grid.occupied[tuple(centre[2])]
    behind = grid.world_to_cell(np.array([[4.0, 2.5, 1.5], [0.3, 2.5, 1.5]]))
    assert grid.unknown[tuple(behind[0])] and grid.unknown[tuple(behind[1])]
    # Frontier: free cells on the side edges of the view cone border unknown space.
    frontier = grid.frontier()
    assert frontier.any() and not (frontier & ~grid.free).any()


def test_grid_path_planning_goes_around_an_obstacle():
    grid = OccupancyGrid(np.array([[0.0, 0.0, 0.0], [3.0, 3.0, 0.3]]), voxel_size_m=0.1)
    grid.observed[:] = True
    grid.log_odds[:] = -1.0  # all free
    grid.log_odds[10:20, 0:25, :] = 2.0  # a wall with a gap at y >= 2.5
    traversable = grid.traversable(inflation_voxels=1)
    plan = grid.plan_from(np.array([5, 5, 1]), traversable)
    goal = np.array([25, 5, 1])
    assert np.isfinite(plan.costs[tuple(goal)])
    path = grid.trace_path(plan, goal)
    assert np.all(traversable[tuple(path[1:].T)])
    assert path[:, 1].max() >= 26  # went through the gap beyond the inflated wall end
    assert plan.costs[tuple(goal)] > 4.0  # longer than the 2 m straight line


def test_frontier_policy_rejects_bad_settings():
    with pytest.raises(ValueError):
        FrontierPolicy(look_around_headings=0)
    with pytest.raises(RuntimeError, match="reset"):
        FrontierPolicy().act({"pose": np.eye(4), "depth": np.zeros((2, 2))})


def _coverage(policy, steps: int, seed: int) -> float:
    env = gym.make(
        "NarutoRecon-v0",
        scene="two_rooms",
        image_scale=0.15,
        panorama_shape=(16, 32),
        coverage_samples=4000,
        max_episode_steps=steps,
    )
    policy.bind(EnvContext.from_env(env, max_episode_steps=steps))
    observation, info = env.reset(seed=seed)
    policy.reset(observation, info, seed=seed)
    for _ in range(steps):
        observation, _, _, truncated, info = env.step(policy.act(observation, info))
        if truncated:
            break
    env.close()
    return info["coverage"]


@pytest.mark.slow
def test_frontier_covers_more_than_random_in_a_short_episode():
    # Same starts; two seeds summed, so one lucky random walk cannot decide it.
    steps = 200
    frontier = sum(_coverage(FrontierPolicy(), steps, seed) for seed in (0, 1))
    random = sum(_coverage(RandomPolicy(), steps, seed) for seed in (0, 1))
    assert frontier > random + 0.05, (frontier, random)


def test_frontier_plans_again_after_a_bump_even_when_the_env_moved_it_part_way():
    """A refused move may still move the agent up to the obstacle; the same path then bumped
    again on the next step (``replica_like_room``, seed 1, steps 32 and 33)."""
    policy = FrontierPolicy()
    env = gym.make("NarutoRecon-v0", scene="replica_like_room", image_scale=0.1,
                   coverage_samples=500, max_episode_steps=100)
    policy.bind(EnvContext.from_env(env, max_episode_steps=100))
    observation, info = env.reset(seed=0)
    policy.reset(observation, info, seed=0)
    for _ in range(100):
        observation, _, _, _, info = env.step(policy.act(observation, info))
        if policy.state == "move" and policy._last_target is not None:
            break
    assert policy.state == "move"
    position = observation["pose"][:3, 3]
    target = position + np.array([0.08, 0.06, 0.0])  # the move the env stopped short of
    policy._last_target = target.copy()
    plans = policy.plans
    bumped = dict(info, collided=True, collision_reason="surface")
    policy._last_position = position - 0.01  # it did move this step
    policy.act(observation, bumped)
    assert policy.plans == plans + 1
    direction = (target - position) / np.linalg.norm(target - position)
    bump = position + direction * (policy.context.agent_radius_m + 0.05)
    assert policy.grid.occupied[tuple(policy.grid.world_to_cell(bump[None])[0])]
    env.close()
