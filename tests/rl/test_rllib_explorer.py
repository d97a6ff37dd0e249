"""The explorer's env creator for RLlib: the egocentric map and goal actions on one env,
flattened for RLlib's default model; and (where RLlib imports) a PPO iteration on it."""

from __future__ import annotations

import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from naruto_gym.rl.explorer_env import make_rllib_explorer_env
from naruto_gym.sensors.pinhole import PinholeCamera

ROOT = Path(__file__).resolve().parents[2]
CONFIG = {
    "scene": "procedural:room:3",
    "camera": PinholeCamera(16, 16, 8, 8, 7.5, 7.5),
    "image_scale": 1.0,
    "coverage_samples": 1000,
    "max_episode_steps": 20,
    "steps_per_goal": 5,
    "num_candidates": 4,
}


def test_the_creator_gives_flat_float_observations_and_goal_actions():
    env = make_rllib_explorer_env(CONFIG)
    try:
        observation, _ = env.reset(seed=0)
        assert observation.dtype == np.float32 and observation.ndim == 1
        assert env.observation_space.contains(observation)
        assert env.action_space == gym.spaces.Discrete(4 + 10)
        steps = 0
        truncated = False
        while not truncated:
            observation, _, _, truncated, info = env.step(env.action_space.sample())
            steps += info["primitive_steps"]
        assert steps == 20
    finally:
        env.close()
    with pytest.raises(ValueError, match="scene"):
        make_rllib_explorer_env({key: v for key, v in CONFIG.items() if key != "scene"})
    with pytest.raises(ValueError, match="num_candidates"):
        make_rllib_explorer_env({**CONFIG, "goal_grid": 4})


@pytest.mark.slow
def test_rllib_ppo_trains_on_the_explorer_wrappers(monkeypatch):
    pytest.importorskip("ray.rllib.algorithms.ppo", reason="needs naruto-gym[ray] (RLlib)")
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.tune.registry import register_env

    monkeypatch.setenv(
        "PYTHONPATH", os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    )
    register_env("NarutoExplorer-test", make_rllib_explorer_env)
    ray.init(num_cpus=2, include_dashboard=False, ignore_reinit_error=True, log_to_driver=False)
    try:
        config = (
            PPOConfig()
            .environment("NarutoExplorer-test", env_config=CONFIG)
            .env_runners(
                num_env_runners=0,
                num_envs_per_env_runner=2,
                gym_env_vectorize_mode="sync",
                rollout_fragment_length="auto",
            )
            .training(train_batch_size_per_learner=16, minibatch_size=8, num_epochs=1)
            .debugging(seed=0)
        )
        algorithm = config.build_algo()
        try:
            result = algorithm.train()
        finally:
            algorithm.stop()
    finally:
        ray.shutdown()
    runners = result["env_runners"]
    assert runners["num_env_steps_sampled_lifetime"] >= 16  # goal actions, 5 env steps each
    assert runners["num_episodes_lifetime"] >= 2  # episodes of 4 goals
