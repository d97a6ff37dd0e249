"""The per-scene runtime both envs build on, and the settings they share."""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
import pytest
from gymnasium.utils import seeding

from naruto_gym import NarutoReconEnv
from naruto_gym.envs.scene_runtime import SceneRuntime
from naruto_gym.envs.settings import EnvSettings
from naruto_gym.vector import NarutoReconVectorEnv

SMALL = {"action_mode": "discrete", "image_scale": 0.05, "coverage_samples": 2000,
         "panorama_shape": (8, 16)}


def test_settings_defaults_are_the_env_keywords_defaults():
    """EnvSettings holds the env's keywords: the same names and defaults as the signature."""
    parameters = inspect.signature(NarutoReconEnv.__init__).parameters
    for field in dataclasses.fields(EnvSettings):
        assert parameters[field.name].default == field.default, field.name
    with pytest.raises(ValueError, match="action_mode"):
        EnvSettings(action_mode="teleport")
    with pytest.raises(ValueError, match="image_scale"):
        EnvSettings(image_scale=0.0)


def test_env_and_batched_env_start_from_the_runtime_sampler():
    """The single env's start pose is its runtime's draw from the env's generator, and the
    batched env's agents draw from the same sampler of their shared runtime."""
    env = NarutoReconEnv(**SMALL)
    observation, _ = env.reset(seed=11)
    runtime = SceneRuntime.load(None, EnvSettings(**SMALL))
    expected = runtime.sample_start_pose(seeding.np_random(11)[0])
    np.testing.assert_array_equal(env.pose, expected)
    np.testing.assert_array_equal(observation["pose"], expected.astype(np.float32))
    vector = NarutoReconVectorEnv(2, pinhole_backend="raycast", **SMALL)
    observations, _ = vector.reset(seed=[11, 12])
    np.testing.assert_array_equal(vector.poses[0], expected)
    runtimes = vector.scene_runtimes
    assert runtimes[0] is runtimes[1]
    assert runtimes[0].coverage is runtimes[1].coverage
    far = np.eye(4)
    far[0, 3] = 1e3
    with pytest.raises(ValueError, match="outside the scene bounds"):
        runtime.check_start_pose(far)
    vector.close()
