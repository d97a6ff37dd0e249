"""The egocentric map: built from depth and poses only, rotated to the agent's heading, for
the single env and the batched env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from naruto_gym.rl.egocentric_map import (
    MAP_CHANNELS,
    EgocentricMapBuilder,
    EgocentricMapObservation,
    VectorEgocentricMapObservation,
)
from naruto_gym.sensors.panorama import EquirectangularCamera
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import NarutoReconVectorEnv

CAMERA = PinholeCamera(16, 16, 8, 8, 7.5, 7.5)
PANORAMA = (32, 64)
OCC, FREE, SEEN, FRONTIER, TRAIL = range(5)
ENV = {
    "scene": "procedural:room",
    "action_mode": "discrete",
    "camera": CAMERA,
    "panorama_shape": PANORAMA,
    "coverage_samples": 1000,
}


def _facing(yaw: float, z: float = 1.0) -> np.ndarray:
    """Camera-to-world pose at (0, 0, z) looking horizontally at ``yaw`` (camera y down)."""
    forward = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    right = np.cross(down, forward)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, down, forward], axis=1)
    pose[2, 3] = z
    return pose


def _observation(pose: np.ndarray, panorama: np.ndarray) -> dict[str, np.ndarray]:
    return {
        "pose": pose[None],
        "panorama": panorama[None].astype(np.float32),
        "depth": np.zeros((1, 16, 16), np.float32),
    }


def _wall_ahead_panorama(distance: float) -> np.ndarray:
    """A world-aligned panorama that sees only a wall ``distance`` metres along +x."""
    camera = EquirectangularCamera(*PANORAMA)
    directions = camera.ray_directions.reshape(*PANORAMA, 3)
    along = directions[..., 0]
    panorama = np.where(along > 0.2, distance / np.maximum(along, 1e-6), 0.0)
    return np.where(panorama < 9.0, panorama, 0.0)


def test_a_round_room_gives_an_obstacle_ring_with_free_space_inside():
    builder = EgocentricMapBuilder(1, CAMERA, PANORAMA, panorama_stride=1)
    pose = _facing(0.0)
    builder.reset(np.array([0]), pose[None])
    panorama = np.full(PANORAMA, 1.0)  # a sphere of radius 1 m around the agent
    builder.update(_observation(pose, panorama))
    near = builder.observe(_observation(pose, panorama))["map"][0, :5]
    centre = near.shape[1] // 2
    rows, columns = np.nonzero(near[OCC])
    radii = np.hypot(rows + 0.5 - centre, columns + 0.5 - centre)
    assert len(radii) > 20 and np.all(np.abs(radii - 10) < 2)  # 1 m of 0.1 m cells
    free_rows, free_columns = np.nonzero(near[FREE])
    assert np.hypot(free_rows + 0.5 - centre, free_columns + 0.5 - centre).max() < 10
    middle = (slice(None), slice(centre - 1, centre + 1), slice(centre - 1, centre + 1))
    assert near[FREE][middle[1:]].all() and near[TRAIL][middle[1:]].any()  # where it stands
    assert not near[FREE][near[OCC] > 0].any()  # an obstacle is never free


def test_obstacles_and_free_space_restart_when_the_agent_changes_height():
    builder = EgocentricMapBuilder(1, CAMERA, PANORAMA, panorama_stride=1)
    pose = _facing(0.0, z=2.3)
    builder.reset(np.array([0]), pose[None])
    builder.update(_observation(pose, np.full(PANORAMA, 1.0)))  # a ring 1 m around it
    seen_before = builder.grids[0, 2].copy()
    assert builder.grids[0, 0].any() and builder.slice_restarts[0] == 0
    lower = _facing(0.0, z=2.3 - 0.1)  # within half the band: the same slice
    builder.update(_observation(lower, np.full(PANORAMA, 1.0)))
    assert builder.slice_restarts[0] == 0 and builder.grids[0, 0].any()
    lowest = _facing(0.0, z=2.3 - 0.3)  # half the band and more below where it started
    builder.update(_observation(lowest, np.full(PANORAMA, 0.0)))  # sees nothing there
    assert builder.slice_restarts[0] == 1
    assert not builder.grids[0, 0].any() and not builder.coarse[0, 0].any()  # obstacles gone
    np.testing.assert_array_equal(builder.grids[0, 2], seen_before)  # seen surface kept
    assert builder.grids[0, 3].any()  # and the trail
    builder.mark_blocked(0, 0.35, 0.05)  # a move the env refused led there
    i, j = np.floor((np.array([0.35, 0.05]) - builder.origins[0]) / 0.1).astype(int)
    assert builder.grids[0, 0, i, j] and not builder.grids[0, 1, i, j]
    assert builder.coarse[0, 0, i // 4, j // 4]


def test_the_crop_turns_with_the_agent_heading():
    panorama = _wall_ahead_panorama(1.0)  # a wall 1 m along world +x
    for yaw, side in ((0.0, "ahead"), (np.pi / 2, "right")):
        builder = EgocentricMapBuilder(1, CAMERA, PANORAMA, panorama_stride=1)
        pose = _facing(yaw)
        builder.reset(np.array([0]), pose[None])
        builder.update(_observation(pose, panorama))
        occupied = builder.observe(_observation(pose, panorama))["map"][0, OCC]
        rows, columns = np.nonzero(occupied)
        centre = occupied.shape[0] // 2
        if side == "ahead":  # up the image
            assert np.all(rows < centre) and np.abs(columns - centre).max() > 3
        else:  # facing +y, world +x is on the agent's right
            assert np.all(columns >= centre) and np.abs(rows - centre).max() > 3


def test_frontier_lies_between_free_and_unknown_cells():
    builder = EgocentricMapBuilder(1, CAMERA, PANORAMA, panorama_stride=1)
    pose = _facing(0.0)
    builder.reset(np.array([0]), pose[None])
    panorama = _wall_ahead_panorama(2.0)
    builder.update(_observation(pose, panorama))
    near = builder.observe(_observation(pose, panorama))["map"][0]
    assert near[FRONTIER].any()
    assert np.all(near[FREE][near[FRONTIER] > 0])  # frontier cells are free cells
    # The wall 2 m ahead lies beyond the near crop (1.6 m), inside the far one (6.4 m).
    far = near[len(MAP_CHANNELS) :]
    assert not near[OCC].any() and far[OCC].any()
    assert np.all(np.nonzero(far[OCC])[0] < far.shape[1] // 2)


def test_the_map_needs_the_panorama_and_a_reset():
    with pytest.raises(ValueError, match="panorama_shape"):
        EgocentricMapBuilder(1, CAMERA, None)
    builder = EgocentricMapBuilder(1, CAMERA, PANORAMA)
    with pytest.raises(RuntimeError, match="reset"):
        builder.update(_observation(_facing(0.0), np.ones(PANORAMA)))


def test_single_env_wrapper_observations_fit_their_space():
    env = EgocentricMapObservation(
        gym.make("NarutoRecon-v0", **{**ENV, "scene": "procedural:room:3"})
    )
    try:
        observation, _ = env.reset(seed=0)
        assert env.observation_space.contains(observation)
        assert set(observation) == {"map", "panorama", "pose"}
        # At the start: at the origin, camera right = start frame -y, camera down = -z.
        np.testing.assert_allclose(observation["pose"], [0, 0, 0, 0, -1, 0, 0, 0, -1], atol=1e-5)
        for _ in range(3):
            observation, *_ = env.step(0)
        assert env.observation_space.contains(observation)
        assert observation["map"][FREE].any() and observation["map"][OCC].any()
    finally:
        env.close()


def test_batched_env_maps_the_final_observation_and_restarts_the_map():
    env = VectorEgocentricMapObservation(
        NarutoReconVectorEnv(2, max_episode_steps=3, autoreset_mode="SameStep", **ENV)
    )
    try:
        observations, _ = env.reset(seed=0)
        assert env.single_observation_space.contains(
            {key: value[0] for key, value in observations.items()}
        )
        for _ in range(3):
            observations, _, _, truncated, infos = env.step(np.array([0, 6]))
        assert truncated.all()
        final = infos["final_obs"][0]
        assert set(final) == {"map", "panorama", "pose"}
        assert np.linalg.norm(final["pose"][:3]) > 0.05  # the last pose of the old episode
        np.testing.assert_allclose(observations["pose"][:, :3], 0.0, atol=1e-5)  # new start
        assert env.map_builder.steps.tolist() == [1, 1]
    finally:
        env.close()


def test_a_batch_split_between_threads_builds_the_maps_of_one_agent_at_a_time():
    """Agents are updated in parts, one compiled call per part in threads: the same maps as
    updating each agent alone, also for a subset of the agents given out of order."""
    env = NarutoReconVectorEnv(5, max_episode_steps=50, **ENV)
    observations, _ = env.reset(seed=3)
    batched = EgocentricMapBuilder(5, CAMERA, PANORAMA, threads=3)
    alone = EgocentricMapBuilder(5, CAMERA, PANORAMA, threads=1)
    for builder in (batched, alone):
        builder.reset(np.arange(5), observations["pose"])
    rng = np.random.default_rng(3)
    for step in range(12):
        observations, *_ = env.step(rng.integers(0, 8, 5))
        envs = np.arange(5) if step % 3 else np.array([4, 1, 2])
        batched.update({key: value[envs] for key, value in observations.items()}, envs)
        for i in envs:
            alone.update({key: value[[i]] for key, value in observations.items()}, np.array([i]))
    assert np.array_equal(batched.grids, alone.grids)
    assert np.array_equal(batched.coarse, alone.coarse)
    assert np.array_equal(batched.steps, alone.steps) and np.array_equal(batched.poses, alone.poses)
    assert batched.grids.any()
    env.close()
