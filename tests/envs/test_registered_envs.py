"""Every registered env through the checkers, determinism, rendering, pickling, vector envs."""

from __future__ import annotations

import pickle
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import naruto_gym  # noqa: F401

NARUTO_ENV_IDS = sorted(
    env_id
    for env_id, spec in gym.registry.items()
    if str(spec.entry_point).startswith("naruto_gym")
)
# Small frames keep the checkers fast; the full-size default is covered by the Replica fixture.
SMALL = {"image_scale": 0.1, "coverage_samples": 2000}


def test_expected_ids_are_registered():
    assert {"NarutoRecon-v0", "NarutoReconApartment-v0", "NarutoReconDiscrete-v0"} <= set(
        NARUTO_ENV_IDS
    )
    assert gym.spec("NarutoRecon-v0").max_episode_steps == 2000


@pytest.mark.parametrize("env_id", NARUTO_ENV_IDS)
def test_gymnasium_env_checker(env_id):
    env = gym.make(env_id, **SMALL)
    check_env(env.unwrapped, skip_render_check=False)
    env.close()


@pytest.mark.parametrize("env_id", NARUTO_ENV_IDS)
def test_stable_baselines3_env_checker(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id, **SMALL)
    # Warnings about large non-image boxes are acceptable; errors are not.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sb3_checker.check_env(env.unwrapped, warn=True)
    env.close()


def _rollout(env: gym.Env, seed: int, steps: int) -> list[dict]:
    observation, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    trace = [observation]
    for _ in range(steps):
        observation, reward, terminated, truncated, info = env.step(env.action_space.sample())
        trace.append({**observation, "reward": np.array(reward), "cov": info["coverage"]})
    return trace


@pytest.mark.parametrize("env_id", NARUTO_ENV_IDS)
def test_same_seed_same_rollout(env_id):
    first = _rollout(gym.make(env_id, **SMALL), seed=7, steps=8)
    second = _rollout(gym.make(env_id, **SMALL), seed=7, steps=8)
    for a, b in zip(first, second, strict=True):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    third = _rollout(gym.make(env_id, **SMALL), seed=8, steps=0)
    assert not np.array_equal(first[0]["pose"], third[0]["pose"])


@pytest.mark.parametrize("env_id", NARUTO_ENV_IDS)
def test_render_rgb_array(env_id):
    env = gym.make(env_id, render_mode="rgb_array", **SMALL)
    env.reset(seed=0)
    env.step(env.action_space.sample())
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert frame.shape[0] >= 100 and frame.shape[1] > frame.shape[0]
    assert frame.std() > 10  # a picture, not a blank canvas
    env.close()


@pytest.mark.parametrize("env_id", NARUTO_ENV_IDS)
def test_pickle_round_trip(env_id):
    env = gym.make(env_id, **SMALL)
    env.reset(seed=3)
    clone = pickle.loads(pickle.dumps(env))
    action = env.action_space.sample()
    a = env.step(action)[0]
    b = clone.step(action)[0]
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])


ASYNC_FORK_SCRIPT = """
import gymnasium as gym
import naruto_gym
envs = gym.make_vec("NarutoRecon-v0", num_envs=4, vectorization_mode="async",
                    vector_kwargs={"context": "fork"}, image_scale=0.1, coverage_samples=2000)
observations, infos = envs.reset(seed=0)
assert observations["rgb"].shape[0] == 4
for _ in range(3):
    observations, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
assert rewards.shape == (4,)
envs.close()
print("stepped")
"""


def test_async_vector_env_with_fork_in_a_fresh_process():
    # The parent only constructs envs (nothing native) before forking: the children are safe.
    result = subprocess.run([sys.executable, "-c", ASYNC_FORK_SCRIPT], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "stepped" in result.stdout


def test_fork_after_ray_casting_is_refused_instead_of_hanging():
    # This test process has cast rays (earlier tests, and the reset below): a forked worker
    # could hang in Open3D's thread pool, so it refuses with what to do.
    env = gym.make("NarutoRecon-v0", **SMALL)
    env.reset(seed=0)
    envs = gym.make_vec("NarutoRecon-v0", num_envs=2, vectorization_mode="async",
                        vector_kwargs={"context": "fork"}, **SMALL)
    with pytest.raises(RuntimeError, match="spawn"):
        envs.reset(seed=0)
    envs.close()
    # The process's own env still works.
    env.step(env.action_space.sample())
    env.close()


def test_async_vector_env_with_spawn_context():
    envs = gym.make_vec(
        "NarutoReconDiscrete-v0",
        num_envs=2,
        vectorization_mode="async",
        vector_kwargs={"context": "spawn"},
        coverage_samples=2000,
    )
    envs.reset(seed=1)
    envs.step(envs.action_space.sample())
    envs.close()
