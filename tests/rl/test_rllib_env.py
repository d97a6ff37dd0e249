"""``make_rllib_env``: the env creator RLlib's env runners call, one env or the batched env
(no Ray needed: RLlib calls it as a plain Gymnasium entry point / vector entry point)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from naruto_gym.rl.rllib_env import make_rllib_env
from naruto_gym.sensors.pinhole import PinholeCamera
from naruto_gym.vector import BatchedEnvBase

CONFIG = {
    "size": 8,
    "action_mode": "discrete",
    "panorama_shape": None,
    "camera": PinholeCamera(16, 16, 8, 8, 7.5, 7.5),
    "coverage_samples": 1000,
    "max_episode_steps": 3,
}


def test_with_num_envs_it_is_the_batched_env_with_flat_float_observations():
    envs = make_rllib_env({**CONFIG, "num_envs": 3})
    try:
        assert isinstance(envs, gym.vector.VectorEnv)
        assert isinstance(envs.unwrapped, BatchedEnvBase)
        assert envs.num_envs == 3
        observations, _ = envs.reset(seed=0)
        assert observations.dtype == np.float32 and observations.ndim == 2
        assert envs.single_observation_space.contains(observations[0])
        # NextStep autoreset, as RLlib's env runner expects: episodes of 3 steps.
        for _ in range(4):
            observations, rewards, terminated, truncated, _ = envs.step(envs.action_space.sample())
        assert observations.shape == (3, envs.single_observation_space.shape[0])
        assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        # Learning wants throughput: frames rasterized where cheaper unless told otherwise.
        assert envs.unwrapped.settings.pinhole_backend == "auto"
    finally:
        envs.close()
    reference = make_rllib_env({**CONFIG, "num_envs": 2, "pinhole_backend": "raycast"})
    assert reference.unwrapped.settings.pinhole_backend == "raycast"
    reference.close()


def test_without_num_envs_it_is_one_env_with_the_same_observation_space():
    env = make_rllib_env(CONFIG)
    envs = make_rllib_env({**CONFIG, "num_envs": 2})
    try:
        assert isinstance(env, gym.Env)
        assert env.observation_space == envs.single_observation_space
        observation, _ = env.reset(seed=0)
        assert env.observation_space.contains(observation)
        parts = gym.spaces.utils.unflatten(env.env.observation_space, observation)
        assert set(parts) == {"rgb", "depth", "pose"}
        assert 0.0 <= parts["rgb"].min() and parts["rgb"].max() <= 1.0  # colours scaled
    finally:
        env.close()
        envs.close()


def test_without_flatten_the_learning_dict_is_kept():
    envs = make_rllib_env({**CONFIG, "num_envs": 2, "flatten": False, "depth": "uint8"})
    try:
        assert isinstance(envs.single_observation_space, gym.spaces.Dict)
        assert envs.single_observation_space["rgb"].shape == (8, 8, 3)
        assert envs.single_observation_space["depth"].dtype == np.uint8
    finally:
        envs.close()


def test_a_config_that_is_not_a_mapping_is_refused():
    with pytest.raises(TypeError, match="env_config"):
        make_rllib_env(["size", 8])


def test_the_env_config_of_the_rl_page_gives_the_batched_env_on_a_scene_stream():
    config = {
        "size": 16,
        "action_mode": "discrete",
        "panorama_shape": None,
        "image_scale": 0.05,
        "scene": "procedural:room",
        "max_episode_steps": 250,
        "coverage_samples": 1000,
        "num_envs": 2,
    }  # docs/rl.md#rllib, fewer samples
    envs = make_rllib_env(config)
    try:
        observations, _ = envs.reset(seed=0)
        assert isinstance(envs.unwrapped, BatchedEnvBase)
        assert observations.shape == (2, 16 * 16 * 4 + 9)  # rgb, depth, flat pose
    finally:
        envs.close()
