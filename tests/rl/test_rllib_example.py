"""The RLlib example runs a PPO iteration on a local Ray instance (skipped without RLlib)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

pytest.importorskip("ray.rllib.algorithms.ppo", reason="needs naruto-gym[ray] (Ray + RLlib)")

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "rllib_ppo.py"


@pytest.mark.slow
def test_rllib_ppo_example_trains_one_iteration():
    spec = importlib.util.spec_from_file_location("rllib_ppo", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    sys.modules["rllib_ppo"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    env = module.make_env({"size": 8, "episode_steps": 5})
    observation, _ = env.reset(seed=0)
    assert env.observation_space.contains(observation)
    results = module.main(module.Args(iterations=1, size=8, episode_steps=20,
                                      train_batch_size=60, num_envs_per_env_runner=1))
    assert results[0]["env_runners"]["num_env_steps_sampled_lifetime"] >= 60
